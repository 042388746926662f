"""Pictures of a solve: meshes over a darkened colour frame, and per-frame residual bars.

The overlay follows figure 1 of the DexYCB paper: the camera image is darkened, the solved hand
(one colour per part: palm and each finger) and objects (one colour each) are z-buffered and
shaded with a headlight, so misaligned fingers show at a glance. Images are BGR uint8 as OpenCV
reads them; pixels x right, y down; meshes in world metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from worker.geometry.cameras import CameraModel, distort_normalized, world_to_camera
from worker.geometry.raster import rasterize
from worker.hand.joints import FINGER_NAMES, MANO_FINGER_START

# BGR part colours: palm, then thumb, index, middle, ring, little (as FINGER_NAMES).
HAND_PART_COLOURS = np.array([
    [200, 200, 200], [60, 60, 230], [40, 170, 250], [60, 210, 90], [230, 160, 40],
    [200, 70, 200]], dtype=np.float64)
OBJECT_COLOURS = np.array([
    [230, 220, 80], [90, 230, 230], [160, 120, 250], [120, 200, 160], [250, 140, 140],
    [140, 180, 250]], dtype=np.float64)
# An object pose the solve does not trust is drawn in this colour (BGR red), whatever its own.
FLAGGED_COLOUR = np.array([40, 40, 240], dtype=np.float64)
DARKEN = 0.45  # the image keeps 45 % of its brightness behind the meshes
MESH_ALPHA = 0.85  # a little of the image shows through, so edges stay readable
AMBIENT = 0.35  # shading floor: surfaces seen edge-on stay coloured, not black

# How the meshes are drawn: "solid" shaded surfaces; "blend" the same, half transparent, so
# the image's edges show under them; "wireframe" only the visible triangle edges, 1 px wide, in
# the mesh's colour, the image untouched in between.
OverlayStyle = Literal["solid", "blend", "wireframe"]
OVERLAY_STYLES: tuple[OverlayStyle, ...] = ("solid", "blend", "wireframe")
# Opacity of the drawn surface or line per style when none is given.
STYLE_ALPHA: dict[str, float] = {"solid": MESH_ALPHA, "blend": 0.5, "wireframe": 1.0}


@dataclass(frozen=True)
class OverlayMesh:
    """A mesh to draw: vertices (N, 3) world metres, faces (M, 3) int, colours (M, 3) BGR 0-255."""

    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray


def hand_part_of_vertices(weights: np.ndarray) -> np.ndarray:
    """Part (V,) of each hand vertex from skinning weights (V, 16) in MANO joint order.

    0 = palm (the wrist joint), 1..5 = the finger of FINGER_NAMES whose joints weigh most.
    """
    weights = np.asarray(weights, dtype=np.float64)
    if weights.ndim != 2 or weights.shape[1] != 16:
        raise ValueError(f"weights must have shape (V, 16), got {weights.shape}")
    part_of_joint = np.zeros(16, dtype=np.int64)
    for f, finger in enumerate(FINGER_NAMES):
        start = MANO_FINGER_START[finger]
        part_of_joint[start:start + 3] = f + 1
    return part_of_joint[np.argmax(weights, axis=1)]


def hand_mesh(vertices: np.ndarray, faces: np.ndarray, vertex_parts: np.ndarray) -> OverlayMesh:
    """The hand as an OverlayMesh; each face takes the part of its first corner."""
    faces = np.asarray(faces, dtype=np.int64)
    return OverlayMesh(np.asarray(vertices, dtype=np.float64), faces,
                       HAND_PART_COLOURS[np.asarray(vertex_parts)[faces[:, 0]]])


def object_mesh(vertices: np.ndarray, faces: np.ndarray, pose: np.ndarray,
                index: int, flagged: bool = False) -> OverlayMesh:
    """Object ``index``'s mesh (object frame, metres) moved by its (3, 4) object-to-world pose;
    in FLAGGED_COLOUR when the pose is flagged as not trusted."""
    pose = np.asarray(pose, dtype=np.float64)
    world = np.asarray(vertices, dtype=np.float64) @ pose[:, :3].T + pose[:, 3]
    faces = np.asarray(faces, dtype=np.int64)
    colour = FLAGGED_COLOUR if flagged else OBJECT_COLOURS[index % len(OBJECT_COLOURS)]
    return OverlayMesh(world, faces, np.broadcast_to(colour, (len(faces), 3)))


def _lens_camera_points(world: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Camera-frame points (N, 3) whose ideal pinhole projection lands where the real lens does.

    The distortion moves each vertex; triangles stay straight between them, which is accurate
    for triangles a few pixels wide, as the meshes' are.
    """
    cam = world_to_camera(world, camera.T_cam_to_world)
    z = cam[:, 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = distort_normalized(cam[:, :2] / z, camera.dist)
    return np.concatenate([xy * z, z], axis=1)


def _edge_pixels(tri: np.ndarray) -> np.ndarray:
    """(H, W) bool: drawn pixels on a visible triangle's edge or the silhouette, 1 px wide.

    tri: (H, W) winning triangle per pixel, -1 where nothing is drawn. Between two triangles
    the pixel left of or above the change is marked (one line, not two); at the silhouette the
    drawn pixel next to the background is, on every side.
    """
    drawn = tri >= 0
    edge = np.zeros_like(drawn)
    edge[:, :-1] |= tri[:, :-1] != tri[:, 1:]
    edge[:-1, :] |= tri[:-1, :] != tri[1:, :]
    edge[:, 1:] |= tri[:, :-1] < 0
    edge[1:, :] |= tri[:-1, :] < 0
    edge[:, [0, -1]] = True
    edge[[0, -1], :] = True
    return edge & drawn


def render_overlay(image: np.ndarray, camera: CameraModel, meshes: Sequence[OverlayMesh],
                   darken: float = DARKEN, style: OverlayStyle = "solid",
                   alpha: float | None = None) -> np.ndarray:
    """The meshes drawn over the darkened image (H, W, 3) BGR uint8 -> (H, W, 3) BGR uint8.

    style: see OverlayStyle; alpha: opacity 0..1 of what is drawn (None: STYLE_ALPHA[style]).
    """
    image = np.asarray(image)
    if image.shape != (camera.height, camera.width, 3) or image.dtype != np.uint8:
        raise ValueError(f"image must be ({camera.height}, {camera.width}, 3) uint8, got "
                         f"{image.shape} {image.dtype}")
    if style not in OVERLAY_STYLES:
        raise ValueError(f"style must be one of {', '.join(OVERLAY_STYLES)}, got {style!r}")
    opacity = STYLE_ALPHA[style] if alpha is None else float(alpha)
    if not 0.0 <= opacity <= 1.0:
        raise ValueError(f"alpha must be within 0..1, got {alpha}")
    out = image.astype(np.float32) * darken
    meshes = [m for m in meshes if len(m.faces)]
    if not meshes:
        return out.astype(np.uint8)
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    world = np.concatenate([m.vertices for m in meshes])
    faces = np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)])
    colours = np.concatenate([m.colours for m in meshes]).astype(np.float32)
    cam = _lens_camera_points(world, camera)
    frags = rasterize(cam, faces, camera.K, camera.width, camera.height)
    if not len(frags.pixels):
        return out.astype(np.uint8)
    flat = out.reshape(-1, 3)
    if style == "wireframe":
        pixels = np.flatnonzero(_edge_pixels(frags.tri))
        lines = colours[frags.tri.reshape(-1)[pixels]]
        flat[pixels] = opacity * lines + (1.0 - opacity) * flat[pixels]
        return np.clip(out, 0, 255).astype(np.uint8)
    tri = frags.tri.reshape(-1)[frags.pixels]
    a, b, c = (cam[faces[tri, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    centre = (a + b + c) / 3.0
    # Headlight: brightness from the angle between the surface and the line of sight.
    cosine = np.abs(np.einsum("pc,pc->p", normal, centre)) / np.maximum(
        np.linalg.norm(normal, axis=1) * np.linalg.norm(centre, axis=1), 1e-12)
    shade = (AMBIENT + (1.0 - AMBIENT) * cosine).astype(np.float32)
    drawn = colours[tri] * shade[:, None]
    flat[frags.pixels] = opacity * drawn + (1.0 - opacity) * flat[frags.pixels]
    return np.clip(out, 0, 255).astype(np.uint8)


# Residual plot layout, pixels.
_PLOT_MARGIN = (56, 40, 16, 64)  # left, top, right, bottom
def caption(image: np.ndarray, lines: Sequence[str],
            colour: np.ndarray = FLAGGED_COLOUR) -> np.ndarray:
    """``image`` (H, W, 3) BGR uint8 with ``lines`` written at its top left on a dark band."""
    out = image.copy()
    for k, line in enumerate(lines):
        y = 18 + 18 * k
        (width, _), _ = cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
        cv2.rectangle(out, (4, y - 13), (10 + width, y + 5), (0, 0, 0), cv2.FILLED)
        cv2.putText(out, line, (7, y), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    tuple(int(c) for c in colour), 1, cv2.LINE_AA)
    return out


_VIEW_COLOURS = np.array([
    [230, 120, 40], [40, 160, 250], [80, 200, 80], [60, 60, 220], [200, 100, 200],
    [40, 200, 220], [160, 160, 60], [140, 140, 140]], dtype=np.int64)
_NICE_STEPS = (1.0, 2.0, 5.0)


def _axis_top(largest: float, minimum: float = 5.0) -> float:
    """A round y-axis top (px) at or above ``largest``: 5, 10, 20, 50, 100, ..."""
    top = max(largest, minimum)
    scale = 10.0 ** np.floor(np.log10(top))
    for step in _NICE_STEPS + (10.0,):
        if step * scale >= top:
            return float(step * scale)
    return float(10.0 * scale)


def _plot_axes(canvas: np.ndarray, box: tuple[int, int, int, int], top: float,
               title: str) -> None:
    x0, y0, x1, y1 = box
    font = cv2.FONT_HERSHEY_SIMPLEX
    for k in range(5):
        value = top * k / 4
        y = round(y1 - (y1 - y0) * k / 4)
        cv2.line(canvas, (x0, y), (x1, y), (225, 225, 225), 1)
        cv2.putText(canvas, f"{value:g}", (4, y + 4), font, 0.38, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.line(canvas, (x0, y0), (x0, y1), (40, 40, 40), 1)
    cv2.line(canvas, (x0, y1), (x1, y1), (40, 40, 40), 1)
    cv2.putText(canvas, title, (x0, 22), font, 0.5, (20, 20, 20), 1, cv2.LINE_AA)
    cv2.putText(canvas, "px", (4, y0 - 8), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)


def residual_plot(errors_px: np.ndarray, view_labels: Sequence[str],
                  joint_labels: Sequence[str], *, title: str = "",
                  width: int = 1000, height: int = 380) -> np.ndarray:
    """Bars of reprojection error per joint (groups) and view (colours) -> (H, W, 3) BGR uint8.

    errors_px: (V, J) pixels, NaN where the joint is not labelled in that view (no bar; a
    grey tick marks it). The y axis is pixels from 0 to a round value at or above the largest.
    """
    errors = np.asarray(errors_px, dtype=np.float64)
    if errors.ndim != 2 or errors.shape != (len(view_labels), len(joint_labels)):
        raise ValueError(f"errors_px must have shape ({len(view_labels)}, {len(joint_labels)}),"
                         f" got {errors.shape}")
    canvas = np.full((height, width, 3), 255, dtype=np.uint8)
    left, top_m, right, bottom = _PLOT_MARGIN
    box = (left, top_m, width - right, height - bottom)
    finite = errors[np.isfinite(errors)]
    top = _axis_top(float(finite.max()) if finite.size else 0.0)
    _plot_axes(canvas, box, top, title)
    views, joints = errors.shape
    group = (box[2] - box[0]) / max(joints, 1)
    bar = max(1.0, group * 0.8 / max(views, 1))
    font = cv2.FONT_HERSHEY_SIMPLEX
    for j in range(joints):
        gx = box[0] + group * j + group * 0.1
        for v in range(views):
            xa = round(gx + bar * v)
            xb = max(xa, round(gx + bar * (v + 1)) - 1)
            value = errors[v, j]
            if not np.isfinite(value):
                cv2.line(canvas, (xa, box[3] - 2), (xb, box[3] - 2), (180, 180, 180), 1)
                continue
            y = round(box[3] - (box[3] - box[1]) * min(value, top) / top)
            colour = tuple(int(c) for c in _VIEW_COLOURS[v % len(_VIEW_COLOURS)])
            cv2.rectangle(canvas, (xa, y), (xb, box[3]), colour, cv2.FILLED)
        cv2.putText(canvas, str(joint_labels[j]), (int(gx), box[3] + 14), font, 0.32,
                    (40, 40, 40), 1, cv2.LINE_AA)
    for v, label in enumerate(view_labels):
        x = box[0] + 110 * v
        colour = tuple(int(c) for c in _VIEW_COLOURS[v % len(_VIEW_COLOURS)])
        cv2.rectangle(canvas, (x, height - 24), (x + 12, height - 12), colour, cv2.FILLED)
        cv2.putText(canvas, str(label)[:14], (x + 16, height - 13), font, 0.36, (30, 30, 30), 1,
                    cv2.LINE_AA)
    return canvas


def short_joint_labels(names: Sequence[str]) -> list[str]:
    """Compact labels for the x axis: "W", then finger initial and joint ("I1".."I4")."""
    out = []
    for name in names:
        if "_" not in name:
            out.append(name[:1].upper())
            continue
        finger, joint = name.split("_", 1)
        out.append(finger[:1].upper() + str(("mcp", "pip", "dip", "tip").index(joint) + 1))
    return out
