"""Annotation: tasks (sequence x view x target), assignments (one worker's go at a task), tracks,
and training clips (tasks whose labels are known).

Track keyframes are stored in image pixels (x right, y down) with a frame index, as compact
rows ``[frame, x, y, visible]`` (x and y may be null on an occluded keyframe).
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    CheckConstraint,
    Float,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.captures.models import Camera, Sequence
from backend.db import Base, TimestampMixin, UTCDateTime, one_of, parent_key


class Task(TimestampMixin, Base):
    __tablename__ = "tasks"
    __table_args__ = (
        UniqueConstraint("camera_id", "target_key"),
        one_of("kind", ("hand", "object")),
        CheckConstraint("num_points > 0", name="num_points_positive"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    # Indexed: a sequence's tasks are read by every progress, QC and solve query.
    sequence_id: Mapped[int] = parent_key("sequences.id", index=True)
    camera_id: Mapped[int] = parent_key("cameras.id")
    kind: Mapped[str] = mapped_column(String(8))
    # "hand:<index>" or "object:<index>": the target within the sequence.
    target_key: Mapped[str] = mapped_column(String(32))
    hand_id: Mapped[int | None] = parent_key("hands.id")
    object_id: Mapped[int | None] = parent_key("scene_objects.id")
    num_points: Mapped[int] = mapped_column(Integer)
    # Object tasks: {"polygon": [[x, y], ...]} from the projected initial pose, or {"box": [...]}.
    highlight: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    sequence: Mapped[Sequence] = relationship()
    camera: Mapped[Camera] = relationship()
    # Module-qualified targets: other domains (the marketplace) have classes of the same name.
    assignments: Mapped[list[Assignment]] = relationship(
        "backend.annotation.models.Assignment", back_populates="task"
    )


class Assignment(TimestampMixin, Base):
    """One worker's labels for one task, saved in versions (optimistic concurrency)."""

    __tablename__ = "assignments"
    __table_args__ = (
        # A task's work, and its work in one state (the approved labels, the submitted work).
        Index("ix_assignments_task_id_status", "task_id", "status"),
        CheckConstraint("version >= 0", name="version_nonnegative"),
        # "closed": work an admin closed while it was still being done (its labels kept).
        one_of("status", ("working", "submitted", "approved", "rejected", "closed")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = parent_key("tasks.id")
    worker_id: Mapped[str] = mapped_column(String(64))
    # The crowd provider's id of this take (MTurk's AssignmentId, a Prolific submission; or one
    # we made for a direct link); unique everywhere. ``hit_id`` is the provider's unit id and
    # ``worker_id`` its worker id: opaque strings of the provider named in ``provider``.
    external_id: Mapped[str] = mapped_column(String(64), unique=True)
    hit_id: Mapped[str | None] = mapped_column(String(64))
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")
    status: Mapped[str] = mapped_column(String(16), default="working")
    version: Mapped[int] = mapped_column(Integer, default=0)
    edit_count: Mapped[int] = mapped_column(Integer, default=0)
    working_time_s: Mapped[float] = mapped_column(Float, default=0.0)
    saved_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    submitted_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    task: Mapped[Task] = relationship("backend.annotation.models.Task",
                                      back_populates="assignments")
    tracks: Mapped[list[Track]] = relationship(
        "backend.annotation.models.Track", back_populates="assignment",
        cascade="all, delete-orphan", order_by="backend.annotation.models.Track.point_index",
    )


class Track(Base):
    __tablename__ = "tracks"
    __table_args__ = (UniqueConstraint("assignment_id", "point_index"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    assignment_id: Mapped[int] = parent_key("assignments.id")
    point_index: Mapped[int] = mapped_column(Integer)
    keyframes: Mapped[list[list[Any]]] = mapped_column(JSON)

    assignment: Mapped[Assignment] = relationship(
        "backend.annotation.models.Assignment", back_populates="tracks"
    )


class TrainingClip(TimestampMixin, Base):
    """A task whose labels are known (gold): new workers label it to earn the qualification."""

    __tablename__ = "training_clips"

    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = parent_key("tasks.id", unique=True)
    # "truth" (a synthetic capture's ground truth) or "assignment:<id>" (accepted labels).
    source: Mapped[str] = mapped_column(String(64))
    # P tracks of keyframe rows [frame, x, y, visible01], as the annotation page saves them.
    tracks: Mapped[list[Any]] = mapped_column(JSON)
    note: Mapped[str | None] = mapped_column(Text)
