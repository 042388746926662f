"""Simple meshable stand-ins for YCB objects: boxes and cylinders with textured UV atlases.

Every object model lives in its own frame: origin at the centre of its bounding box, z up when the
object rests on the table in its usual way, metres. Textures are BGR uint8 images with OBJ UV
conventions (v up). Each face carries distinct coloured marks near its corners (dots, crosses,
squares, rings) so a crowd worker can pick and track landmarks, as the DexYCB protocol asks.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.formats.dexycb import YCB_CLASSES
from worker.geometry.mesh_io import Mesh

TEXTURE_SIZE = 512
CYLINDER_SEGMENTS = 48


@dataclass(frozen=True)
class ObjectSpec:
    """A YCB object approximated by a primitive.

    Attributes:
        ycb_id: index into ``YCB_CLASSES`` (also the object's segmentation value).
        kind: ``"box"`` (size = x, y, z extents) or ``"cylinder"`` (size = radius, radius, height).
        size: (3,) metres.
        color: base BGR colour of the printed packaging.
        accent: BGR colour of stripes and the label band.
    """

    ycb_id: int
    kind: str
    size: tuple[float, float, float]
    color: tuple[int, int, int]
    accent: tuple[int, int, int]

    @property
    def name(self) -> str:
        return YCB_CLASSES[self.ycb_id]

    @property
    def half_extents(self) -> np.ndarray:
        """(3,) half sizes of the axis-aligned bounding box in the model frame, metres."""
        if self.kind == "cylinder":
            return np.array([self.size[0], self.size[0], self.size[2] / 2.0])
        return np.asarray(self.size, dtype=np.float64) / 2.0


# Approximate YCB dimensions (metres); flat packs (pudding, gelatin) lie on their largest face.
CATALOGUE: dict[int, ObjectSpec] = {
    1: ObjectSpec(1, "cylinder", (0.051, 0.051, 0.139), (150, 90, 40), (40, 170, 230)),
    2: ObjectSpec(2, "box", (0.060, 0.158, 0.210), (40, 40, 200), (40, 200, 240)),
    3: ObjectSpec(3, "box", (0.038, 0.089, 0.175), (60, 210, 235), (200, 120, 40)),
    4: ObjectSpec(4, "cylinder", (0.033, 0.033, 0.101), (50, 50, 210), (235, 235, 235)),
    6: ObjectSpec(6, "cylinder", (0.0425, 0.0425, 0.033), (70, 190, 220), (170, 90, 30)),
    7: ObjectSpec(7, "box", (0.110, 0.089, 0.035), (50, 90, 140), (220, 220, 220)),
    8: ObjectSpec(8, "box", (0.085, 0.073, 0.028), (60, 40, 190), (230, 230, 230)),
    9: ObjectSpec(9, "box", (0.050, 0.097, 0.082), (150, 70, 30), (60, 200, 240)),
    16: ObjectSpec(16, "box", (0.085, 0.085, 0.200), (110, 170, 210), (60, 110, 160)),
    21: ObjectSpec(21, "box", (0.050, 0.075, 0.050), (60, 60, 220), (90, 90, 240)),
}

# Landmark palette (BGR): saturated, mutually distinct colours.
_MARK_COLORS: list[tuple[int, int, int]] = [
    (0, 0, 255), (0, 200, 0), (255, 80, 0), (0, 230, 255), (255, 0, 255), (255, 255, 0),
    (0, 128, 255), (128, 0, 128), (255, 255, 255), (20, 20, 20), (0, 90, 0), (180, 105, 255),
]  # fmt: skip

# Box faces as (normal axis, sign, in-plane u axis, in-plane v axis) with u x v = outward normal,
# so quads (-,-), (+,-), (+,+), (-,+) are counter-clockwise seen from outside.
_BOX_FACES = [
    (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])),
    (np.array([-1.0, 0, 0]), np.array([0, -1.0, 0]), np.array([0, 0, 1.0])),
    (np.array([0, 1.0, 0]), np.array([-1.0, 0, 0]), np.array([0, 0, 1.0])),
    (np.array([0, -1.0, 0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
    (np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
    (np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, -1.0, 0])),
]
_CELL_MARGIN = 0.01  # UV inset of each atlas cell, so texture lookups never bleed across cells


def _atlas_cell(index: int) -> tuple[float, float, float, float]:
    """UV rectangle (u0, v0, u1, v1) of cell ``index`` in a 3 x 2 atlas (row 0 at the top)."""
    col, row = index % 3, index // 3
    u0, v1 = col / 3.0, 1.0 - row / 2.0
    u1, v0 = (col + 1) / 3.0, 1.0 - (row + 1) / 2.0
    m = _CELL_MARGIN
    return u0 + m, v0 + m, u1 - m, v1 - m


def box_mesh(size: tuple[float, float, float]) -> Mesh:
    """Closed box (8 vertices, 12 triangles) centred at the origin; size (3,) metres.

    Each face maps to its own cell of a 3 x 2 texture atlas, upright for the side faces.
    """
    half = np.asarray(size, dtype=np.float64) / 2.0
    signs = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)]) * 2.0 - 1.0
    vertices = signs * half
    faces, face_uvs, uvs = [], [], []
    for index, (normal, u_axis, v_axis) in enumerate(_BOX_FACES):
        u0, v0, u1, v1 = _atlas_cell(index)
        quad = []
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            corner = np.sign(normal + su * u_axis + sv * v_axis)
            quad.append(int(np.flatnonzero((signs == corner).all(axis=1))[0]))
            uvs.append([u0 if su < 0 else u1, v0 if sv < 0 else v1])
        t = 4 * index
        faces += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
        face_uvs += [[t, t + 1, t + 2], [t, t + 2, t + 3]]
    return Mesh(vertices, np.array(faces, np.int64), np.array(uvs), np.array(face_uvs, np.int64))


def cylinder_mesh(radius: float, height: float, segments: int = CYLINDER_SEGMENTS) -> Mesh:
    """Closed cylinder about z centred at the origin (metres).

    Vertices: ``segments`` bottom ring, ``segments`` top ring, bottom centre, top centre.
    UVs: the side unrolls over the top two thirds of the texture (u around from +x, CCW seen
    from above; v up); the caps are discs in the bottom third (bottom cap left, top cap right).
    """
    n = segments
    theta = 2.0 * np.pi * np.arange(n) / n
    ring = np.stack([radius * np.cos(theta), radius * np.sin(theta)], axis=1)
    bottom = np.column_stack([ring, np.full(n, -height / 2.0)])
    top = np.column_stack([ring, np.full(n, height / 2.0)])
    vertices = np.vstack([bottom, top, [[0, 0, -height / 2.0], [0, 0, height / 2.0]]])
    j = np.arange(n)
    k = (j + 1) % n
    side = np.concatenate([np.stack([j, k, n + k], 1), np.stack([j, n + k, n + j], 1)])
    caps = np.concatenate([np.stack([np.full(n, 2 * n), k, j], 1),
                           np.stack([np.full(n, 2 * n + 1), n + j, n + k], 1)])
    side_v0, side_v1 = 1.0 / 3.0 + _CELL_MARGIN, 1.0 - _CELL_MARGIN
    col = np.arange(n + 1) / n
    side_uv = np.concatenate([np.column_stack([col, np.full(n + 1, side_v0)]),
                              np.column_stack([col, np.full(n + 1, side_v1)])])
    cap_r = 1.0 / 6.0 - _CELL_MARGIN
    disc = np.column_stack([np.cos(theta), np.sin(theta)]) * cap_r
    centres = np.array([[0.25, 1.0 / 6.0], [0.75, 1.0 / 6.0]])
    cap_uv = np.vstack([centres[0] + disc, centres[1] + disc, centres])
    uvs = np.vstack([side_uv, cap_uv])
    o = 2 * (n + 1)  # first cap uv index
    jj = np.arange(n)
    side_t = np.concatenate([np.stack([jj, jj + 1, n + 1 + jj + 1], 1),
                             np.stack([jj, n + 1 + jj + 1, n + 1 + jj], 1)])
    cap_t = np.concatenate([np.stack([np.full(n, o + 2 * n), o + k, o + j], 1),
                            np.stack([np.full(n, o + 2 * n + 1), o + n + j, o + n + k], 1)])
    faces = np.concatenate([side, caps]).astype(np.int64)
    return Mesh(vertices, faces, uvs, np.concatenate([side_t, cap_t]).astype(np.int64))


def object_mesh(spec: ObjectSpec) -> Mesh:
    """The model-frame mesh of a catalogue object (metres)."""
    if spec.kind == "cylinder":
        return cylinder_mesh(spec.size[0], spec.size[2])
    return box_mesh(spec.size)


def _draw_mark(img: np.ndarray, centre: tuple[int, int], kind: int,
               color: tuple[int, int, int], radius: int) -> None:
    """Draw one landmark glyph (dot, cross, square or ring) with a dark outline for contrast."""
    x, y = centre
    r = radius
    if kind == 0:
        cv2.circle(img, centre, r + 2, (15, 15, 15), -1, cv2.LINE_AA)
        cv2.circle(img, centre, r, color, -1, cv2.LINE_AA)
    elif kind == 1:
        for thick, col in ((r // 2 + 3, (15, 15, 15)), (r // 2, color)):
            cv2.line(img, (x - r, y - r), (x + r, y + r), col, thick, cv2.LINE_AA)
            cv2.line(img, (x - r, y + r), (x + r, y - r), col, thick, cv2.LINE_AA)
    elif kind == 2:
        cv2.rectangle(img, (x - r - 2, y - r - 2), (x + r + 2, y + r + 2), (15, 15, 15), -1)
        cv2.rectangle(img, (x - r, y - r), (x + r, y + r), color, -1)
    else:
        cv2.circle(img, centre, r, (15, 15, 15), r // 2 + 3, cv2.LINE_AA)
        cv2.circle(img, centre, r, color, r // 2, cv2.LINE_AA)


def _uv_rect_to_px(rect: tuple[float, float, float, float], size: int) -> tuple[int, ...]:
    u0, v0, u1, v1 = rect
    return (int(u0 * size), int((1 - v1) * size), int(u1 * size), int((1 - v0) * size))


def _paint_panel(img: np.ndarray, box: tuple[int, ...], spec: ObjectSpec, panel: int) -> None:
    """Packaging print on one rectangular panel: stripes, a label band and 4 corner marks."""
    x0, y0, x1, y1 = box
    w, h = x1 - x0, y1 - y0
    cv2.rectangle(img, (x0, y0 + h // 6), (x1, y0 + h // 6 + h // 10), spec.accent, -1)
    for s in range(3):
        yy = y1 - h // 5 + s * (h // 20)
        cv2.line(img, (x0, yy), (x1, yy), spec.accent, max(2, h // 60))
    label = spec.name.split("_", 1)[1].replace("_", " ")[:14]
    scale = max(0.3, w / 260.0)
    cv2.putText(img, label, (x0 + w // 12, y0 + h // 2), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (245, 245, 245), max(1, int(2 * scale)), cv2.LINE_AA)
    r = max(4, min(w, h) // 14)
    inset_x, inset_y = max(r + 4, w // 7), max(r + 4, h // 7)
    corners = [(x0 + inset_x, y0 + inset_y), (x1 - inset_x, y0 + inset_y),
               (x1 - inset_x, y1 - inset_y), (x0 + inset_x, y1 - inset_y)]
    for c, centre in enumerate(corners):
        color = _MARK_COLORS[(3 * panel + c) % len(_MARK_COLORS)]
        _draw_mark(img, centre, (panel + c) % 4, color, r)


def object_texture(spec: ObjectSpec, size: int = TEXTURE_SIZE) -> np.ndarray:
    """Paint the (size, size, 3) BGR uint8 texture atlas of a catalogue object."""
    img = np.empty((size, size, 3), np.uint8)
    img[:] = spec.color
    if spec.kind == "box":
        for index in range(6):
            _paint_panel(img, _uv_rect_to_px(_atlas_cell(index), size), spec, index)
        return img
    side = (0.0, 1.0 / 3.0 + _CELL_MARGIN, 1.0, 1.0 - _CELL_MARGIN)
    x0, y0, x1, y1 = _uv_rect_to_px(side, size)
    for quarter in range(4):  # four panels around the can, each with its own corner marks
        _paint_panel(img, (x0 + quarter * (x1 - x0) // 4, y0,
                           x0 + (quarter + 1) * (x1 - x0) // 4, y1), spec, quarter)
    for c, cu in enumerate((0.25, 0.75)):
        centre = (int(cu * size), int((1 - 1 / 6) * size))
        cv2.circle(img, centre, size // 7, spec.accent, size // 40)
        _draw_mark(img, centre, 1 + c, _MARK_COLORS[(8 + c) % len(_MARK_COLORS)], size // 30)
    return img
