"""A finished run's outputs read back: frame JSON, hand vertices, overlay and residual PNGs."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.captures.assets import hand_model_for, load_mesh
from backend.captures.models import Camera, Frame, SceneObject
from backend.captures.service import camera_model, sequence_cameras
from backend.errors import Conflict, StorageError
from backend.solve.models import SolveRun
from backend.solve.results import decode_result, frame_payload, object_trust
from backend.solve.service import check_frame, resolve_view
from backend.storage import get_storage
from worker.hand.joints import JOINT_NAMES
from worker.overlay import (
    OverlayStyle,
    caption,
    hand_mesh,
    hand_part_of_vertices,
    object_mesh,
    render_overlay,
    residual_plot,
    short_joint_labels,
)


def run_arrays(run: SolveRun) -> dict[str, np.ndarray]:
    """The finished run's outputs (see backend.solve.results)."""
    if run.result_key is None:
        raise Conflict(f"solve run {run.id} is {run.status}; outputs exist once it is done")
    return decode_result(get_storage().get_bytes(run.result_key))


def solved_hand(arrays: dict[str, np.ndarray], frame: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The solved hand at ``frame``: vertices (N, 3) world metres, faces (M, 3), parts (N,).

    None where the frame is unlabelled or the run has no hand.
    """
    # Posing loads PyTorch: imported here, so that the API loads it only when a hand is shown.
    from worker.hand.layer import HandLayer
    from worker.hand.posing import posed_hand

    side = str(arrays["hand_side"])
    pose_m = arrays["hand_pose_m"][frame]
    if not side or not np.isfinite(pose_m).all() or arrays["betas"].size == 0:
        return None
    model = hand_model_for(side)
    layer = HandLayer(model)
    vertices, _ = posed_hand(layer, pose_m[None], np.asarray(arrays["betas"], dtype=np.float64))
    return (vertices[0], np.asarray(model.faces, dtype=np.int64),
            hand_part_of_vertices(model.weights))


def frame_outputs(run: SolveRun, frame: int, vertices: bool = False) -> dict[str, Any]:
    """One frame's outputs (JSON-ready); with the hand mesh when ``vertices``."""
    check_frame(run, frame)
    arrays = run_arrays(run)
    payload = frame_payload(arrays, frame)
    payload["run_id"] = run.id
    if vertices:
        hand = solved_hand(arrays, frame)
        payload["hand_vertices"] = None if hand is None else hand[0].tolist()
        payload["hand_faces"] = None if hand is None else hand[1].tolist()
    return payload


def _colour_frame(session: Session, camera: Camera, frame: int) -> np.ndarray:
    row = session.scalars(select(Frame).where(Frame.camera_id == camera.id,
                                              Frame.index == frame)).one()
    image = cv2.imdecode(np.frombuffer(get_storage().get_bytes(row.color_key), np.uint8),
                         cv2.IMREAD_COLOR)
    if image is None:
        raise StorageError(f"colour frame {row.color_key!r} could not be decoded")
    if image.shape[:2] != (camera.height, camera.width):
        image = cv2.resize(image, (camera.width, camera.height))
    return image


def overlay_png(session: Session, run: SolveRun, frame: int, view: str,
                style: OverlayStyle = "solid", alpha: float | None = None) -> bytes:
    """The solved meshes over the darkened colour frame of one view, as PNG bytes, drawn in
    ``style`` at opacity ``alpha`` (see worker.overlay.render_overlay)."""
    check_frame(run, frame)
    arrays = run_arrays(run)
    v = resolve_view(run, view, [str(s) for s in arrays["serials"]])
    camera = sequence_cameras(session, run.sequence_id)[v]
    meshes = []
    objects = list(session.scalars(select(SceneObject).where(
        SceneObject.sequence_id == run.sequence_id).order_by(SceneObject.index)))
    _, flags = object_trust(arrays)
    for o, obj in enumerate(objects[: arrays["object_poses"].shape[0]]):
        pose = arrays["object_poses"][o, frame]
        if np.isfinite(pose).all():
            mesh = load_mesh(get_storage(), obj.mesh_key)
            meshes.append(object_mesh(mesh.vertices, mesh.faces, pose, o,
                                      flagged=bool(flags[o, frame])))
    hand = solved_hand(arrays, frame)
    if hand is not None:
        meshes.append(hand_mesh(*hand))
    picture = render_overlay(_colour_frame(session, camera, frame), camera_model(camera), meshes,
                             style=style, alpha=alpha)
    # A flagged pose is drawn in the flag colour, and why it is not trusted is written on top.
    reasons = [f"not trusted: {flags[o, frame]}" for o in range(flags.shape[0])
               if flags[o, frame]]
    return _png(caption(picture, reasons) if reasons else picture)


def residuals_png(run: SolveRun, frame: int) -> bytes:
    """Bars of the frame's reprojection error per joint and view, as PNG bytes."""
    check_frame(run, frame)
    arrays = run_arrays(run)
    serials = [str(s) for s in arrays["serials"]]
    reason = str(arrays["reasons"][frame])
    title = f"run {run.id} frame {frame}: reprojection error per joint and view (px)"
    if reason:
        title += f" - {reason}"
    picture = residual_plot(arrays["kpt_error_px"][frame], serials,
                            short_joint_labels(JOINT_NAMES), title=title)
    return _png(picture)


def _png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return data.tobytes()
