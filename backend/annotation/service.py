"""Annotation rules: creating tasks, starting assignments, versioned track saves, submit.

Services flush and never commit; the request is the unit of work.
"""

from __future__ import annotations

import secrets
from datetime import datetime, timedelta
from typing import Any, NamedTuple, cast

import msgspec
from sqlalchemy import (
    Table,
    bindparam,
    func,
    insert,
    inspect,
    select,
    text,
    update,
)
from sqlalchemy.orm import Session, selectinload
from sqlalchemy.orm.attributes import set_committed_value

from backend.annotation.highlight import object_highlight
from backend.annotation.models import Assignment, Task, Track
from backend.annotation.points import HAND_POINTS, OBJECT_POINTS, point_names
from backend.annotation.schemas import TracksSave
from backend.captures.models import Camera, Sequence
from backend.captures.service import get_sequence_or_raise
from backend.db import utcnow
from backend.errors import Conflict, DexlabelError, Forbidden, NotFound
from backend.storage import Storage
from worker.tracks.readiness import completeness
from worker.tracks.validate import checked_rows


class InvalidTracks(DexlabelError, status_code=422, code="invalid_tracks"):
    pass


class Incomplete(DexlabelError, status_code=422, code="incomplete"):
    pass


class StaleVersion(Conflict, code="conflict"):
    pass


def create_tasks(session: Session, storage: Storage, sequence_id: int) -> list[Task]:
    """One task per view and target (each hand, each object); existing ones are kept."""
    seq = get_sequence_or_raise(session, sequence_id)
    existing = {(t.camera_id, t.target_key): t for t in list_tasks(session, sequence_id)}
    tasks = []
    for camera in seq.cameras:
        for hand in seq.hands:
            key = f"hand:{hand.index}"
            hand_task = existing.get((camera.id, key)) or Task(
                sequence_id=seq.id, camera_id=camera.id, kind="hand", target_key=key,
                hand_id=hand.id, num_points=HAND_POINTS)
            tasks.append(hand_task)
        for obj in seq.objects:
            key = f"object:{obj.index}"
            task = existing.get((camera.id, key))
            if task is None:
                task = Task(sequence_id=seq.id, camera_id=camera.id, kind="object",
                            target_key=key, object_id=obj.id, num_points=OBJECT_POINTS,
                            highlight=object_highlight(storage, obj, camera))
            tasks.append(task)
    session.add_all(tasks)
    session.flush()
    return tasks


def list_tasks(session: Session, sequence_id: int | None = None, limit: int | None = None,
               offset: int = 0) -> list[Task]:
    """Tasks in id order (of one sequence), with their cameras and sequences loaded (each
    sequence's cameras, objects and hands too: the listing names a task's view and target);
    a page of them when ``limit`` is given."""
    # A task's camera is one of its sequence's, found among them without a statement of its own.
    sequence = selectinload(Task.sequence)
    stmt = (select(Task).options(sequence.selectinload(Sequence.cameras),
                                 sequence.selectinload(Sequence.objects),
                                 sequence.selectinload(Sequence.hands))
            .order_by(Task.id).offset(offset).limit(limit))
    if sequence_id is not None:
        stmt = stmt.where(Task.sequence_id == sequence_id)
    return list(session.scalars(stmt))


def get_task_or_raise(session: Session, task_id: int) -> Task:
    stmt = (select(Task).where(Task.id == task_id)
            .options(selectinload(Task.camera), selectinload(Task.sequence)))
    task = session.scalars(stmt).one_or_none()
    if task is None:
        raise NotFound(f"task {task_id} does not exist")
    return task


def set_highlight_box(session: Session, task: Task, box: list[float]) -> Task:
    x0, y0, x1, y1 = box
    if task.kind != "object":
        raise DexlabelError("only object tasks have a highlight")
    if not (0 <= x0 < x1 <= task.camera.width and 0 <= y0 < y1 <= task.camera.height):
        raise DexlabelError(
            f"box must satisfy 0 <= x0 < x1 <= {task.camera.width} and "
            f"0 <= y0 < y1 <= {task.camera.height}, got {box}")
    task.highlight = {"box": [float(v) for v in box]}
    session.flush()
    return task


def get_assignment_or_raise(session: Session, assignment_id: int) -> Assignment:
    """The assignment; its tracks load when first used (a save replaces them unread)."""
    stmt = select(Assignment).where(Assignment.id == assignment_id)
    assignment = session.scalars(stmt).one_or_none()
    if assignment is None:
        raise NotFound(f"assignment {assignment_id} does not exist")
    return assignment


def create_assignment(
    session: Session, task: Task, worker_id: str, external_id: str | None = None,
    hit_id: str | None = None,
) -> Assignment:
    assignment = Assignment(task_id=task.id, worker_id=worker_id, hit_id=hit_id,
                            external_id=external_id or f"DX{secrets.token_hex(12).upper()}")
    session.add(assignment)
    session.flush()
    return assignment


def require_open_slot(session: Session, hit_id: str, held: int, duration_s: int) -> None:
    """Refuse to open one more assignment of a HIT than workers hold on the marketplace.

    The marketplace counts ``held`` assignments of the HIT but cannot name their workers, so
    an assignment opened here is unconfirmed until it is submitted: every holder of the HIT's
    task token (a previewer) could open any number. Unconfirmed work opened within the HIT's
    assignment duration takes one slot each; older work the marketplace has taken back (it
    has expired) takes none.

    Raises:
        Forbidden: every held slot is taken by work already opened here.
    """
    since = utcnow() - timedelta(seconds=duration_s) if duration_s > 0 else None
    opened = select(func.count()).select_from(Assignment).where(
        Assignment.hit_id == hit_id, Assignment.status == "working")
    if since is not None:
        opened = opened.where(Assignment.created_at >= since)
    taken = session.scalar(opened) or 0
    if taken >= held:
        raise Forbidden(f"HIT {hit_id} has {held} assignment(s) held by workers and "
                        f"{taken} already opened here: no open slot for another (accept the "
                        "HIT on the marketplace first)")


def start_assignment(
    session: Session, task: Task, external_id: str, worker_id: str, hit_id: str | None
) -> Assignment:
    """The assignment a marketplace handed to ``worker_id``: found again, or created once."""
    stmt = select(Assignment).where(Assignment.external_id == external_id)
    assignment = session.scalars(stmt).one_or_none()
    if assignment is None:
        return create_assignment(session, task, worker_id, external_id, hit_id)
    if assignment.task_id != task.id or assignment.worker_id != worker_id:
        raise Forbidden(f"assignment {external_id} belongs to another task or worker")
    return assignment


def tracks_payload(assignment: Assignment) -> dict[str, Any] | None:
    if assignment.version == 0:
        return None
    return {"version": assignment.version,
            "tracks": [{"point": t.point_index, "keyframes": t.keyframes}
                       for t in assignment.tracks]}


class _Clip(NamedTuple):
    """What a save is checked against: the task's points, its clip and its view's image."""

    kind: str
    num_points: int
    num_frames: int
    width: int
    height: int


def clip_of(session: Session, task_id: int) -> _Clip:
    """The task's clip facts in one query (a save needs nothing else of the task)."""
    row = session.execute(
        select(Task.kind, Task.num_points, Sequence.num_frames, Camera.width, Camera.height)
        .join(Sequence, Sequence.id == Task.sequence_id)
        .join(Camera, Camera.id == Task.camera_id)
        .where(Task.id == task_id)).one_or_none()
    if row is None:
        raise NotFound(f"task {task_id} does not exist")
    return _Clip(*row)


_assignments, _tasks, _sequences, _cameras = (
    cast(Table, model.__table__) for model in (Assignment, Task, Sequence, Camera))
# What an autosave reads: the assignment's state and its task's clip facts, in one query
# without the ORM (no Assignment object is built).
_SAVE_READ = (
    select(_assignments.c.status, _tasks.c.kind, _tasks.c.num_points, _sequences.c.num_frames,
           _cameras.c.width, _cameras.c.height)
    .select_from(_assignments.join(_tasks, _tasks.c.id == _assignments.c.task_id)
                 .join(_sequences, _sequences.c.id == _tasks.c.sequence_id)
                 .join(_cameras, _cameras.c.id == _tasks.c.camera_id))
    .where(_assignments.c.id == bindparam("assignment")))


def autosave(session: Session, assignment_id: int, body: TracksSave) -> int:
    """Replace the assignment's tracks if ``body.version`` is current (see :func:`save_tracks`)
    and return the new version; the autosave's path, with no ORM object read or built."""
    row = session.execute(_SAVE_READ, {"assignment": assignment_id}).one_or_none()
    if row is None:
        raise NotFound(f"assignment {assignment_id} does not exist")
    version, _ = _replace_tracks(session, assignment_id, row[0], _Clip(*row[1:]), body)
    return version


def check_tracks(clip: _Clip, body: TracksSave) -> list[list[list[Any]]]:
    """Per point keyframe rows, validated against the task's clip and image; 422 otherwise."""
    problems, by_point = [], {}
    names = point_names(clip.kind)
    for track in body.tracks:
        name = names[track.point] if track.point < clip.num_points else None
        if name is None:
            problems.append(f"tracks: point {track.point} does not exist "
                            f"(this task has points 0-{clip.num_points - 1})")
            continue
        if track.point in by_point:
            problems.append(f"tracks: point {track.point} ({name}) appears twice")
            continue
        rows, issues = checked_rows(track.keyframes, clip.num_frames, clip.width, clip.height)
        problems.extend(f"{name}: {issue}" for issue in issues)
        if not issues:
            by_point[track.point] = rows
    if problems:
        raise InvalidTracks("; ".join(problems[:20]), problems=problems)
    return [by_point.get(p, []) for p in range(clip.num_points)]


_JSON_ENCODER = msgspec.json.Encoder()

# The save's statements, built once (a save is the most frequent request by far).
_BUMP_VERSION = (
    update(_assignments)
    .where(_assignments.c.id == bindparam("assignment"),
           _assignments.c.version == bindparam("base"), _assignments.c.status == "working")
    .values(version=_assignments.c.version + 1, edit_count=bindparam("edits"),
            working_time_s=bindparam("seconds"),
            saved_at=bindparam("at", type_=_assignments.c.saved_at.type))
    .returning(_assignments.c.version))


# An assignment's tracks from one JSON array of every point's rows (``rows``), in one UPDATE
# that returns the points it found: the database walks the array once (PostgreSQL's
# json_array_elements, SQLite's json_each) and each track row takes its point's element.
# (Taking each row's element with ``->`` or json_extract instead parses the whole ~30 KB
# document again for each of the 21 rows: about 6 ms of PostgreSQL's CPU per save against
# 1.3 ms.)
_TRACKS_UPDATE = {
    "postgresql": text(
        "UPDATE tracks SET keyframes = given.doc"
        " FROM json_array_elements(CAST(:rows AS json)) WITH ORDINALITY AS given(doc, n)"
        " WHERE tracks.assignment_id = :assignment AND tracks.point_index = given.n - 1"
        " RETURNING tracks.point_index"),
    "sqlite": text(
        "UPDATE tracks SET keyframes = given.value"
        " FROM json_each(:rows) AS given"
        " WHERE tracks.assignment_id = :assignment AND tracks.point_index = given.key"
        " RETURNING tracks.point_index"),
}


def save_tracks(session: Session, assignment: Assignment, body: TracksSave) -> Assignment:
    """Replace the assignment's tracks if ``body.version`` is current; bump the version.

    The stored keyframes are never read: every point's track is written in one UPDATE (and
    one INSERT of the points saved for the first time).
    """
    clip = clip_of(session, assignment.task_id)
    version, saved_at = _replace_tracks(session, assignment.id, assignment.status, clip, body)
    # The row as written, without reading it again.
    for field, value in (("version", version), ("edit_count", body.edit_count),
                         ("working_time_s", body.working_time_s), ("saved_at", saved_at)):
        set_committed_value(assignment, field, value)
    # Tracks this session loaded before hold the old keyframes: load them again when used.
    if "tracks" not in inspect(assignment).unloaded:
        for track in assignment.tracks:
            session.expire(track)
    session.expire(assignment, ["tracks"])
    return assignment


def _replace_tracks(session: Session, assignment_id: int, status: str, clip: _Clip,
                    body: TracksSave) -> tuple[int, datetime]:
    """Check the save against the clip, bump the version if ``body.version`` is current (409
    otherwise) and write the tracks: (the new version, when it was saved)."""
    if status != "working":
        raise Conflict(f"assignment is {status}; its labels can no longer change")
    rows = check_tracks(clip, body)
    # Compare-and-set on the version: of two tabs saving from one version, one wins.
    saved_at = utcnow()
    version = session.execute(_BUMP_VERSION, {
        "assignment": assignment_id, "base": body.version, "edits": body.edit_count,
        "seconds": body.working_time_s, "at": saved_at}).scalar_one_or_none()
    if version is None:
        row = session.execute(
            select(_assignments.c.status, _assignments.c.version)
            .where(_assignments.c.id == assignment_id)).one_or_none()
        if row is None:  # deleted since it was read (a forced delete of its sequence)
            raise NotFound(f"assignment {assignment_id} no longer exists (its sequence or "
                           "task was deleted); nothing was saved")
        status, current = row
        if status != "working":  # submitted from another tab meanwhile
            raise Conflict(f"assignment is {status}; its labels can no longer change")
        raise StaleVersion(
            f"these labels were saved from version {body.version}, but the assignment is at "
            f"version {current} (changed in another tab or window)",
            current_version=current,
        )
    _write_tracks(session, assignment_id, rows)
    return version, saved_at


def _write_tracks(session: Session, assignment_id: int, rows: list[list[list[Any]]]) -> None:
    """Every point's keyframes in one UPDATE and one INSERT of the points saved for the first
    time, if any: two round trips at most, and no read of the track ids first.

    The UPDATE sends the whole save as one JSON array (one parameter, serialised once) and
    each track row takes its own element, by point index, in the database (_TRACKS_UPDATE).
    An upsert would do it in one statement, but PostgreSQL draws a track id from the sequence
    for every row it tries, which would use up the 32-bit ids within weeks of a crowd's
    autosaves.
    """
    if not rows:
        return
    statement = _TRACKS_UPDATE[session.get_bind().dialect.name]
    # msgspec writes the ~3,000 floats of a full hand save about 8 times faster than the
    # standard library, with the same shortest round-trip form (the rows hold no NaN).
    found = set(session.execute(statement, {
        "assignment": assignment_id, "rows": _JSON_ENCODER.encode(rows).decode()}).scalars())
    added = [{"assignment_id": assignment_id, "point_index": p, "keyframes": kf}
             for p, kf in enumerate(rows) if p not in found]
    if added:
        session.execute(insert(Track), added)


def submit(session: Session, assignment: Assignment, body: TracksSave) -> Assignment:
    """Save, then accept the work only if every point is placed or occluded in every frame."""
    save_tracks(session, assignment, body)
    task = get_task_or_raise(session, assignment.task_id)
    tracks = [t.keyframes for t in sorted(assignment.tracks, key=lambda t: t.point_index)]
    report = completeness(tracks, task.sequence.num_frames, point_names(task.kind))
    if not report["complete"]:
        messages = [p["message"] for p in report["problems"]]
        raise Incomplete("not ready to submit: " + "; ".join(messages[:10]),
                         problems=report["problems"])
    assignment.status = "submitted"
    assignment.submitted_at = utcnow()
    session.flush()
    return assignment
