"""API shapes of tasks, assignments and track saves."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, ValidatorFunctionWrapHandler, WrapValidator

from backend.validation import Count, Finite

# Where a task's work stands (backend.progress derives it from its assignments, HITs and QC).
TaskState = Literal["open", "published", "submitted", "in review", "accepted"]
TASK_STATES: tuple[TaskState, ...] = get_args(TaskState)

# A keyframe row: [frame, x, y, visible01] or [frame, x, y, visible01, source]; x and y in image
# pixels or null when occluded; source (provenance) one of "placed" (the default, what a 4-element
# row means), "tracked", "prefilled", "edited" (worker.tracks.keyframes.SOURCES), stored and read
# back only when it is not "placed". Its form and every value in it are checked once, against the
# task's clip and image (worker.tracks.validate.validate_keyframes: a frame in the clip, a position
# in the image, a known source), so a value out of any bound is refused there by name.
KeyframeRow = list[Any]
# Generous bounds: a clip of up to 2000 frames, every frame keyed, 64 points.
MAX_KEYFRAMES_PER_TRACK = 2000
MAX_POINTS = 64
MAX_SAVE_BYTES = 1_000_000


def _rows_as_sent(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
    """A track's keyframes as parsed, when it is a list of at most MAX_KEYFRAMES_PER_TRACK
    lists (what the page sends), without pydantic copying each of a save's ~1,500 rows; any
    other value goes through the declared type, which names the problem as before."""
    if type(value) is list and len(value) <= MAX_KEYFRAMES_PER_TRACK:
        for row in value:
            if type(row) is not list:
                return handler(value)
        return value
    return handler(value)


class TrackIn(BaseModel):
    point: int = Field(ge=0, lt=MAX_POINTS)
    keyframes: Annotated[list[KeyframeRow], WrapValidator(_rows_as_sent)] = Field(
        max_length=MAX_KEYFRAMES_PER_TRACK)


class TracksSave(BaseModel):
    """A whole-assignment save: based on ``version``, replacing every track."""

    model_config = ConfigDict(extra="forbid")

    version: Count
    tracks: list[TrackIn] = Field(max_length=MAX_POINTS)
    edit_count: int = Field(default=0, ge=0, le=10_000_000)
    working_time_s: float = Field(default=0.0, ge=0, le=7 * 24 * 3600, allow_inf_nan=False)


class SaveResult(BaseModel):
    version: int
    status: str


class TaskRead(BaseModel):
    id: int
    kind: Literal["hand", "object"]
    sequence_id: int
    serial: str
    # What a worker calls the view and the target: "camera 3 of 8" (view_number 3, num_views 8,
    # in the sequence's camera order), "right hand". view_serials: every view's serial in that
    # order, so the page can name any view it mentions (epipolar lines) by its number.
    view_number: int
    num_views: int
    view_serials: list[str]
    target: str
    target_key: str
    num_points: int
    num_frames: int
    width: int
    height: int
    fps: float
    point_names: list[str]
    point_colors: list[str]
    skeleton: list[list[int]]
    highlight: dict[str, Any] | None
    # Derived from the task's work: open, published, submitted, in review or accepted.
    status: TaskState


class TracksPayload(BaseModel):
    version: int
    tracks: list[TrackIn]


class AssignmentRead(BaseModel):
    id: int
    external_id: str
    worker_id: str
    status: str
    version: int
    edit_count: int
    working_time_s: float
    tracks: TracksPayload | None


class FramesLinks(BaseModel):
    bundle_url: str
    manifest_url: str


class AnnotateTaskRead(BaseModel):
    mode: Literal["edit", "preview", "submitted", "review"]
    task: TaskRead
    frames: FramesLinks
    assignment: AssignmentRead | None


class StartRequest(BaseModel):
    task_token: str = Field(min_length=10, max_length=4096)
    assignment_id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    hit_id: str | None = Field(default=None, max_length=64)
    worker_id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")


class TokenRead(BaseModel):
    token: str


class AssignmentCreate(BaseModel):
    worker_id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")


class AssignmentLink(BaseModel):
    assignment_id: int
    external_id: str
    token: str
    page_url: str


class PreviewLink(BaseModel):
    token: str
    page_url: str


class ReadonlyLink(BaseModel):
    """The annotation page showing an assignment's saved tracks read-only: ``url`` is relative
    to the server and carries its token in the fragment; the token expires at ``expires_at``."""

    url: str
    expires_at: datetime


class HighlightUpdate(BaseModel):
    box: list[Finite] = Field(min_length=4, max_length=4, description="x0, y0, x1, y1 image px")
