"""The solved scene that object-landmark QC checks labels against (worker.quality.anchored,
worker.quality.landmark_points): each object's mesh in its own frame and its solved poses.

Object frame and world in metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SolvedObjects:
    """The solved scene: per object vertices (N, 3) and faces (M, 3) in its own frame
    (metres), and poses (O, F, 3, 4) object-to-world (NaN where unsolved)."""

    vertices: Sequence[np.ndarray]
    faces: Sequence[np.ndarray]
    poses: np.ndarray

    def triangles(self, index: int, frame: int) -> np.ndarray:
        """(M, 3, 3) world triangles of object ``index`` at ``frame`` (NaN if unsolved)."""
        pose = self.poses[index, frame]
        return (self.vertices[index] @ pose[:, :3].T + pose[:, 3])[self.faces[index]]
