"""A capture's assets as the worker packages take them: object meshes and depth maps read from
storage, and the hand model of a side."""

from __future__ import annotations

import tempfile
from pathlib import Path

import cv2
import numpy as np

from backend.captures.models import Camera, Frame
from backend.config import get_settings
from backend.storage import Storage
from worker.geometry.mesh_io import Mesh, read_mesh
from worker.hand import HandModel, load_hand_model
from worker.hand.params import check_side


def load_mesh(storage: Storage, key: str) -> Mesh:
    """An object model (OBJ or PLY, metres) from storage."""
    with tempfile.NamedTemporaryFile(suffix=Path(key).suffix) as fh:
        fh.write(storage.get_bytes(key))
        fh.flush()
        return read_mesh(Path(fh.name))


def load_depth(storage: Storage, camera: Camera, frames: list[Frame]) -> np.ndarray | None:
    """(F, H, W) uint16 millimetres of one view, or None when the view has no depth.

    Raises ValueError naming the file when a stored depth map is not an H x W uint16 PNG.
    """
    keys = [f.depth_key for f in frames if f.depth_key is not None]
    if not camera.has_depth or not frames or len(keys) < len(frames):
        return None
    maps = []
    for key in keys:
        data = np.frombuffer(storage.get_bytes(key), np.uint8)
        depth = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16 or depth.shape != (camera.height,
                                                                        camera.width):
            raise ValueError(f"depth map {key} is not a {camera.width}x"
                             f"{camera.height} uint16 PNG")
        maps.append(depth)
    return np.stack(maps)


def hand_model_for(side: str) -> HandModel:
    """The MANO model of ``side``: official pickles from DEXLABEL_MANO_DIR, else built in."""
    return load_hand_model(check_side(side), get_settings().mano_dir)
