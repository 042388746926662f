"""A capture read and checked, before anything is written: its sequence, cameras (with their
frames or video), objects and hands, as backend.captures.layout plans them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class FramePlan:
    index: int
    color_path: Path
    depth_path: Path | None


@dataclass
class CameraPlan:
    serial: str
    width: int
    height: int
    fx: float
    fy: float
    ppx: float
    ppy: float
    distortion: list[float]
    extrinsics: list[list[float]]
    frames: list[FramePlan] = field(default_factory=list)
    video_path: Path | None = None
    video_frames: list[bytes] = field(default_factory=list)  # JPEG bytes, decoded from video_path


@dataclass
class ObjectPlan:
    index: int
    ycb_id: int
    name: str
    mesh_path: Path
    model_files: list[Path]
    num_vertices: int
    num_faces: int
    grasped: bool
    initial_pose: list[list[float]] | None


@dataclass
class HandPlan:
    index: int
    side: str
    calib_name: str | None
    betas: list[float] | None


@dataclass
class SequencePlan:
    root: Path
    seq_dir: Path
    subject: str
    name: str
    num_frames: int
    master_serial: str | None
    cameras: list[CameraPlan]
    objects: list[ObjectPlan]
    hands: list[HandPlan]
    fingerprint: str

    @property
    def source_kind(self) -> str:
        return "video" if any(c.video_path for c in self.cameras) else "images"
