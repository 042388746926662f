"""Captures: subjects, sequences, their calibrated cameras, objects, hands and frames.

Geometry conventions (written once, used everywhere): image pixels with x right and y down as
OpenCV projects; camera frames in metres with z forward; world = the capture's master frame.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    CheckConstraint,
    Float,
    ForeignKey,
    Integer,
    String,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.db import Base, TimestampMixin, one_of, parent_key


class Subject(TimestampMixin, Base):
    __tablename__ = "subjects"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)

    sequences: Mapped[list[Sequence]] = relationship(back_populates="subject")


class Sequence(TimestampMixin, Base):
    """One recorded grasp (a DexYCB sequence): all views over ``num_frames`` time steps."""

    __tablename__ = "sequences"
    __table_args__ = (
        UniqueConstraint("subject_id", "name"),
        CheckConstraint("num_frames > 0", name="num_frames_positive"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    subject_id: Mapped[int] = mapped_column(ForeignKey("subjects.id", ondelete="RESTRICT"))
    name: Mapped[str] = mapped_column(String(200))
    # Storage prefix of this sequence's files: captures/<storage_uid>/...
    storage_uid: Mapped[str] = mapped_column(String(64), unique=True)
    num_frames: Mapped[int] = mapped_column(Integer)
    fps: Mapped[float] = mapped_column(Float, default=30.0)
    master_serial: Mapped[str | None] = mapped_column(String(64))
    source_kind: Mapped[str] = mapped_column(String(16))  # "images" or "video"
    # sha256 over the capture's calibration, meta and frame files: re-import detection.
    fingerprint: Mapped[str] = mapped_column(String(64))

    subject: Mapped[Subject] = relationship(back_populates="sequences")
    cameras: Mapped[list[Camera]] = relationship(
        back_populates="sequence", cascade="all, delete-orphan", order_by="Camera.view_index"
    )
    objects: Mapped[list[SceneObject]] = relationship(
        back_populates="sequence", cascade="all, delete-orphan", order_by="SceneObject.index"
    )
    hands: Mapped[list[Hand]] = relationship(
        back_populates="sequence", cascade="all, delete-orphan", order_by="Hand.index"
    )


class Camera(Base):
    """One calibrated view of a sequence: pinhole intrinsics, OpenCV distortion, pose."""

    __tablename__ = "cameras"
    __table_args__ = (
        UniqueConstraint("sequence_id", "serial"),
        CheckConstraint("width > 0 AND height > 0", name="image_size_positive"),
        CheckConstraint("fx > 0 AND fy > 0", name="focal_positive"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id")
    serial: Mapped[str] = mapped_column(String(64))
    view_index: Mapped[int] = mapped_column(Integer)
    width: Mapped[int] = mapped_column(Integer)
    height: Mapped[int] = mapped_column(Integer)
    fx: Mapped[float] = mapped_column(Float)
    fy: Mapped[float] = mapped_column(Float)
    ppx: Mapped[float] = mapped_column(Float)
    ppy: Mapped[float] = mapped_column(Float)
    # OpenCV order k1, k2, p1, p2, k3 (zeros for the D415's rectified colour stream).
    distortion: Mapped[list[float]] = mapped_column(JSON)
    # Camera-to-world rigid transform, 3x4 row-major, metres.
    extrinsics: Mapped[list[list[float]]] = mapped_column(JSON)
    has_depth: Mapped[bool] = mapped_column(Boolean, default=True)

    sequence: Mapped[Sequence] = relationship(back_populates="cameras")
    frames: Mapped[list[Frame]] = relationship(
        back_populates="camera", cascade="all, delete-orphan", order_by="Frame.index"
    )


class SceneObject(Base):
    """An object on the table; the grasped one is the target of the sequence."""

    __tablename__ = "scene_objects"
    __table_args__ = (UniqueConstraint("sequence_id", "index"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id")
    index: Mapped[int] = mapped_column(Integer)
    ycb_id: Mapped[int] = mapped_column(Integer)
    name: Mapped[str] = mapped_column(String(200))
    mesh_key: Mapped[str] = mapped_column(String(500))
    num_vertices: Mapped[int] = mapped_column(Integer)
    num_faces: Mapped[int] = mapped_column(Integer)
    grasped: Mapped[bool] = mapped_column(Boolean, default=False)
    # Object-to-world 3x4 at the first frame, metres; None until one is given.
    initial_pose: Mapped[list[list[float]] | None] = mapped_column(JSON, nullable=True)

    sequence: Mapped[Sequence] = relationship(back_populates="objects")


class Hand(Base):
    __tablename__ = "hands"
    __table_args__ = (
        UniqueConstraint("sequence_id", "index"),
        one_of("side", ("right", "left")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id")
    index: Mapped[int] = mapped_column(Integer)
    side: Mapped[str] = mapped_column(String(8))
    calib_name: Mapped[str | None] = mapped_column(String(200))
    # MANO shape coefficients of the subject (10), fixed per subject.
    betas: Mapped[list[float] | None] = mapped_column(JSON, nullable=True)

    sequence: Mapped[Sequence] = relationship(back_populates="hands")


class Frame(Base):
    """One time step of one view: a colour image and (if captured) an aligned depth map."""

    __tablename__ = "frames"
    __table_args__ = (
        UniqueConstraint("camera_id", "index"),
        CheckConstraint("\"index\" >= 0", name="index_nonnegative"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    camera_id: Mapped[int] = parent_key("cameras.id")
    index: Mapped[int] = mapped_column(Integer)
    color_key: Mapped[str] = mapped_column(String(500))
    color_bytes: Mapped[int] = mapped_column(Integer)
    depth_key: Mapped[str | None] = mapped_column(String(500))
    thumb_key: Mapped[str | None] = mapped_column(String(500))
    # Filled by the frame-statistics job: brightness, sharpness, depth coverage.
    stats: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)

    camera: Mapped[Camera] = relationship(back_populates="frames")
