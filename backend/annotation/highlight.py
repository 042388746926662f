"""The outline of an object in one view at its initial pose, for object tasks.

The outline is in image px of the view. It holds at the clip's first frame (frame 0: the
sequence's frames are the clip's, and the initial pose is the object's pose there); the page
refuses a landmark placed off it on that frame and QC masks frame 0 with it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from backend.captures.models import Camera, SceneObject
from backend.captures.service import object_label
from backend.storage import Storage
from worker.geometry.cameras import project_points
from worker.geometry.mesh_io import read_mesh

# The frame of the clip where the outline holds (the initial pose's frame).
OUTLINE_FRAME = 0


def object_highlight(storage: Storage, obj: SceneObject, camera: Camera) -> dict[str, Any] | None:
    """{"polygon": [[x, y], ...], "frame": 0, "label": "mug"}: the convex hull (image px) of
    the object's projected mesh at its initial pose, the clip frame it holds for, and the name
    the page calls the object by.

    None when the object has no initial pose or lies entirely outside the image; an admin
    can then draw a box instead.
    """
    if obj.initial_pose is None:
        return None
    suffix = Path(obj.mesh_key).suffix
    with tempfile.NamedTemporaryFile(suffix=suffix) as fh:
        fh.write(storage.get_bytes(obj.mesh_key))
        fh.flush()
        vertices = read_mesh(Path(fh.name)).vertices
    pose = np.asarray(obj.initial_pose, dtype=np.float64)
    world = vertices @ pose[:, :3].T + pose[:, 3]
    K = np.array([[camera.fx, 0, camera.ppx], [0, camera.fy, camera.ppy], [0, 0, 1.0]])
    T = np.asarray(camera.extrinsics, dtype=np.float64)
    dist = np.zeros(5)
    coeffs = np.asarray(camera.distortion, dtype=np.float64)[:5]
    dist[: len(coeffs)] = coeffs
    pixels = project_points(world, K, T, dist)
    hull = cv2.convexHull(pixels.astype(np.float32)).reshape(-1, 2)
    hull[:, 0] = np.clip(hull[:, 0], 0, camera.width - 1)
    hull[:, 1] = np.clip(hull[:, 1], 0, camera.height - 1)
    if cv2.contourArea(hull) < 4.0:
        return None
    return {"polygon": [[round(float(x), 2), round(float(y), 2)] for x, y in hull],
            "frame": OUTLINE_FRAME, "label": object_label(obj.name)}
