"""A forearm for the synthetic hand (``dexlabel synth --forearm``): bare skin above the wrist,
then a sleeve up to the elbow, so that a render looks more like real footage, where a hand
never ends at the wrist. Detectors trained on real hands (MediaPipe's palm detector) look for
the arm as context.

The arm is a tapered tube of elliptical cross-section along the hand's wrist-to-forearm axis
(from the middle finger's MCP through the wrist), flattened across the palm like a real wrist.
It is not part of the hand's truth: the labels stay the MANO hand's, and the segmentation marks
the arm as background, as DexYCB's hand masks (rendered from the MANO mesh alone) do.

Table frame, metres; joints in the DexYCB order of worker.hand.joints.
"""

from __future__ import annotations

import numpy as np

from worker.hand.joints import JOINT_NAMES

SLEEVE_COLOR = (92.0, 70.0, 58.0)  # BGR, a dark blue-grey cloth
SKIN_LENGTH = 0.07  # bare forearm above the wrist, metres
SLEEVE_LENGTH = 0.2
# Half-widths of the wrist's cross-section (across the palm, through the palm), metres, and
# how much wider the arm is at the sleeve's far end.
WRIST_HALF_WIDTHS = (0.029, 0.02)
TAPER = 1.35
SLEEVE_MARGIN = 1.12  # the sleeve is this much wider than the arm under it
_RING = 24
_WRIST, _INDEX_MCP, _MIDDLE_MCP, _LITTLE_MCP = (
    JOINT_NAMES.index(n) for n in ("wrist", "index_mcp", "middle_mcp", "little_mcp"))


def _arm_frames(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, 3) unit forearm axis (wrist towards elbow), across-palm and through-palm axes."""
    axis = joints[:, _WRIST] - joints[:, _MIDDLE_MCP]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    across = joints[:, _INDEX_MCP] - joints[:, _LITTLE_MCP]
    across -= np.einsum("fc,fc->f", across, axis)[:, None] * axis
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    return axis, across, np.cross(axis, across)


def _tube(joints: np.ndarray, start: float, stop: float, scale0: float, scale1: float,
          rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (F, rings * _RING, 3) and faces of the tube from ``start`` to ``stop`` metres
    along the forearm axis, its cross-section the wrist's scaled from ``scale0`` to ``scale1``."""
    axis, across, through = _arm_frames(np.asarray(joints, np.float64))
    t = np.linspace(0.0, 1.0, rings)
    along = start + (stop - start) * t  # (R,)
    scale = scale0 + (scale1 - scale0) * t
    angle = np.linspace(0.0, 2.0 * np.pi, _RING, endpoint=False)
    cu = np.cos(angle)[None, :] * scale[:, None] * WRIST_HALF_WIDTHS[0]  # (R, S)
    cv = np.sin(angle)[None, :] * scale[:, None] * WRIST_HALF_WIDTHS[1]
    wrist = joints[:, _WRIST]
    verts = (wrist[:, None, None] + along[None, :, None, None] * axis[:, None, None]
             + cu[None, ..., None] * across[:, None, None] + cv[None, ..., None]
             * through[:, None, None])
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(_RING), indexing="ij")
    a = (r * _RING + s).ravel()
    b = (r * _RING + (s + 1) % _RING).ravel()
    c, d = b + _RING, a + _RING
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return verts.reshape(len(joints), rings * _RING, 3), faces


def forearm_meshes(joints: np.ndarray, skin: tuple[float, float, float]
                   ) -> list[tuple[np.ndarray, np.ndarray, tuple[float, float, float]]]:
    """The bare forearm and its sleeve at every frame: [(vertices (F, V, 3), faces (M, 3),
    BGR colour)], from the hand's joints (F, 21, 3) in the table frame."""
    joints = np.asarray(joints, np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (len(JOINT_NAMES), 3):
        raise ValueError(f"expected (F, {len(JOINT_NAMES)}, 3) joints, got {joints.shape}")
    skin_end = 1.0 + (TAPER - 1.0) * SKIN_LENGTH / (SKIN_LENGTH + SLEEVE_LENGTH)
    # The bare arm starts a little inside the hand's mesh so that no gap shows at the wrist.
    bare = _tube(joints, -0.01, SKIN_LENGTH + 0.005, 1.0, skin_end, 6)
    sleeve = _tube(joints, SKIN_LENGTH, SKIN_LENGTH + SLEEVE_LENGTH,
                   skin_end * SLEEVE_MARGIN, TAPER * SLEEVE_MARGIN, 8)
    return [(*bare, skin), (*sleeve, SLEEVE_COLOR)]
