"""API shapes of captures; separate from the ORM models."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, ConfigDict, Field, field_validator

from backend.captures.layout import MAX_PATH_CHARS


class CameraRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    serial: str
    view_index: int
    width: int
    height: int
    fx: float
    fy: float
    ppx: float
    ppy: float
    distortion: list[float] = Field(description="OpenCV k1, k2, p1, p2, k3")
    extrinsics: list[list[float]] = Field(description="camera-to-world 3x4, metres")
    has_depth: bool


class ObjectRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    index: int
    ycb_id: int
    name: str
    grasped: bool
    num_vertices: int
    num_faces: int
    initial_pose: list[list[float]] | None = Field(description="object-to-world 3x4 at frame 0")


class HandRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    index: int
    side: str
    calib_name: str | None
    betas: list[float] | None


class SequenceRead(BaseModel):
    id: int
    subject: str
    name: str
    num_frames: int
    fps: float
    master_serial: str | None
    source_kind: str
    created_at: datetime
    cameras: list[CameraRead]
    objects: list[ObjectRead]
    hands: list[HandRead]


class ImportRequest(BaseModel):
    path: str = Field(min_length=1, max_length=MAX_PATH_CHARS,
                      description="capture root or sequence folder on the server, inside one of "
                                  "the folders of DEXLABEL_CAPTURE_ROOTS")

    @field_validator("path")
    @classmethod
    def _no_nul(cls, value: str) -> str:
        if "\x00" in value:
            raise ValueError("a path must not contain a NUL character")
        return value


class ImportResultRead(BaseModel):
    sequence_id: int
    subject: str
    name: str
    created: bool
    num_cameras: int
    num_frames: int
    repaired: int = Field(0, description="stored files of an already-imported sequence that "
                                         "were missing and are written again from the capture")


class SequenceDeletedRead(BaseModel):
    sequence_id: int
    subject: str
    name: str
    tasks: int = Field(description="its annotation tasks, deleted with it")
    assignments: int = Field(description="assignments of those tasks (any state), deleted")
    finished_assignments: int = Field(description="of which submitted or approved")
    files: int = Field(description="stored files removed (frames, models, thumbnails, solves)")


class FrameRef(BaseModel):
    index: int
    url: str
    bytes: int
    depth_url: str | None


class FramesManifest(BaseModel):
    sequence_id: int
    serial: str
    width: int
    height: int
    num_frames: int
    bundle_url: str = Field(description="all colour frames of the view in one response")
    frames: list[FrameRef]


class ViewTokenRead(BaseModel):
    token: str
    expires_in: int
