"""Input checks for `solve`: every problem is a ValueError that names the field and its shape."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from worker.hand.joints import NUM_JOINTS
from worker.solver.types import ObjectTarget, SolveInputs, SolveSettings


def _shape(name: str, array: npt.ArrayLike, expected: tuple[int | None, ...]) -> np.ndarray:
    array = np.asarray(array)
    ok = array.ndim == len(expected) and all(e is None or a == e
                                             for a, e in zip(array.shape, expected, strict=True))
    if not ok:
        want = "(" + ", ".join("*" if e is None else str(e) for e in expected) + ")"
        raise ValueError(f"{name} must have shape {want}, got {array.shape}")
    return array


def check_inputs(inputs: SolveInputs, settings: SolveSettings) -> None:
    """Raise ValueError on anything `solve` cannot use, naming the field and actual shape."""
    if settings.optimiser not in ("paper", "default"):
        raise ValueError(f"optimiser must be 'paper' or 'default', got {settings.optimiser!r}")
    views, frames = len(inputs.cameras), int(inputs.num_frames)
    if views < 1:
        raise ValueError("cameras must hold at least one camera")
    if frames < 1:
        raise ValueError(f"num_frames must be >= 1, got {inputs.num_frames}")
    if len(inputs.depth) != views:
        raise ValueError(f"depth must hold one entry per camera ({views}), got {len(inputs.depth)}")
    for v, (cam, images) in enumerate(zip(inputs.cameras, inputs.depth, strict=True)):
        if images is not None:
            _shape(f"depth[{v}]", images, (frames, cam.height, cam.width))
    if inputs.hand is None and not inputs.objects:
        raise ValueError("nothing to solve: no hand and no objects")
    if inputs.hand is not None:
        hand = inputs.hand
        if hand.side not in ("right", "left"):
            raise ValueError(f"hand.side must be 'right' or 'left', got {hand.side!r}")
        _shape("hand.betas", hand.betas, (10,))
        _shape("hand.keypoints", hand.keypoints, (views, frames, NUM_JOINTS, 2))
        _shape("hand.visible", hand.visible, (views, frames, NUM_JOINTS))
    for i, obj in enumerate(inputs.objects):
        _check_object(i, obj, views, frames)


def _check_object(i: int, obj: ObjectTarget, views: int, frames: int) -> None:
    name = f"objects[{i}] ({obj.name})"
    if obj.initial_pose is not None:
        _shape(f"{name}.initial_pose", obj.initial_pose, (3, 4))
    vertices = _shape(f"{name}.vertices", obj.vertices, (None, 3))
    faces = _shape(f"{name}.faces", obj.faces, (None, 3))
    if len(faces) == 0 or faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{name}.faces must index its {len(vertices)} vertices")
    for k, mark in enumerate(obj.landmarks):
        if not 0 <= mark.view < views:
            raise ValueError(f"{name}.landmarks[{k}].view must be in [0, {views}), got {mark.view}")
        _shape(f"{name}.landmarks[{k}].xy", mark.xy, (frames, 2))
        _shape(f"{name}.landmarks[{k}].visible", mark.visible, (frames,))
