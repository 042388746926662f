"""Triangle meshes: reading OBJ and PLY object models, writing textured OBJ. PLY files are parsed
by :mod:`worker.geometry.mesh_ply`.

Vertices are in the model's own frame (metres for every object model in a capture). Texture
coordinates follow the OBJ convention: ``u`` to the right, ``v`` up, so the texel row of ``v`` in
an image of height ``h`` is ``(1 - v) * (h - 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.geometry.mesh_ply import read_ply


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 positions, metres in the model frame.
        faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside.
        uvs: (T, 2) float64 texture coordinates or None.
        face_uvs: (F, 3) int64 indices into ``uvs`` per face corner; None iff ``uvs`` is None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None = None
    face_uvs: np.ndarray | None = None

    def __post_init__(self) -> None:
        v, f = np.asarray(self.vertices), np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must have shape (F, 3), got {f.shape}")
        if (self.uvs is None) != (self.face_uvs is None):
            raise ValueError("uvs and face_uvs must be given together")
        if self.face_uvs is not None and np.asarray(self.face_uvs).shape != f.shape:
            raise ValueError(
                f"face_uvs must have the faces' shape {f.shape}, got {np.shape(self.face_uvs)}"
            )


def read_mesh(path: str | Path) -> Mesh:
    """Read an OBJ or PLY file (chosen by suffix) into a :class:`Mesh`.

    OBJ: ``v``, ``vt`` and ``f`` records with ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn`` corners,
    negative (relative) indices, and polygons fan-triangulated; other records are ignored.
    PLY: ``ascii`` or ``binary_little_endian``/``binary_big_endian``, vertex ``x y z`` (optional
    ``s t`` / ``u v`` texture coordinates) and face ``vertex_indices`` lists.

    Raises:
        ValueError: naming the file (and line, for text input) on malformed or empty input.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        return _read_obj(path)
    if suffix == ".ply":
        vertices, faces, uvs = read_ply(path)
        if uvs is None:
            return Mesh(vertices, faces)
        # PLY texture coordinates are per vertex: each corner's index is its vertex's.
        return Mesh(vertices, faces, uvs, faces.copy())
    raise ValueError(f"{path}: unsupported mesh format {suffix!r} (expected .obj or .ply)")


def _parse_floats(path: Path, lineno: int, fields: list[str], count: int) -> list[float]:
    if len(fields) < count:
        raise ValueError(f"{path}:{lineno}: expected {count} numbers, got {len(fields)}")
    try:
        return [float(x) for x in fields[:count]]
    except ValueError:
        raise ValueError(f"{path}:{lineno}: not a number in {' '.join(fields)!r}") from None


def _resolve_index(path: Path, lineno: int, token: str, count: int, what: str) -> int:
    try:
        idx = int(token)
    except ValueError:
        raise ValueError(f"{path}:{lineno}: bad {what} index {token!r}") from None
    resolved = idx - 1 if idx > 0 else count + idx
    if idx == 0 or not 0 <= resolved < count:
        raise ValueError(f"{path}:{lineno}: {what} index {idx} out of range (have {count})")
    return resolved


def _parse_face(
    path: Path, lineno: int, fields: list[str], n_v: int, n_vt: int
) -> tuple[list[int], list[int] | None]:
    if len(fields) < 3:
        raise ValueError(f"{path}:{lineno}: a face needs at least 3 corners, got {len(fields)}")
    corners, tex = [], []
    for field in fields:
        parts = field.split("/")
        if len(parts) > 3:
            raise ValueError(f"{path}:{lineno}: bad face corner {field!r}")
        corners.append(_resolve_index(path, lineno, parts[0], n_v, "vertex"))
        if len(parts) >= 2 and parts[1]:
            tex.append(_resolve_index(path, lineno, parts[1], n_vt, "texture"))
    if tex and len(tex) != len(corners):
        raise ValueError(f"{path}:{lineno}: texture indices on some corners only")
    return corners, (tex or None)


def _read_obj(path: Path) -> Mesh:
    verts: list[list[float]] = []
    uvs: list[list[float]] = []
    faces: list[list[int]] = []
    face_uvs: list[list[int]] = []
    untextured_line = textured_line = 0
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a text OBJ file ({exc.reason})") from None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        fields = raw.split("#", 1)[0].split()
        if not fields:
            continue
        key, rest = fields[0], fields[1:]
        if key == "v":
            verts.append(_parse_floats(path, lineno, rest, 3))
        elif key == "vt":
            uv = _parse_floats(path, lineno, rest, max(1, min(len(rest), 2)))
            uvs.append(uv + [0.0] * (2 - len(uv)))
        elif key == "f":
            corners, tex = _parse_face(path, lineno, rest, len(verts), len(uvs))
            if tex is None:
                untextured_line = untextured_line or lineno
            else:
                textured_line = textured_line or lineno
            if untextured_line and textured_line:
                raise ValueError(
                    f"{path}:{max(untextured_line, textured_line)}: faces mix corners with and "
                    "without texture coordinates"
                )
            for k in range(1, len(corners) - 1):
                faces.append([corners[0], corners[k], corners[k + 1]])
                if tex is not None:
                    face_uvs.append([tex[0], tex[k], tex[k + 1]])
    if not verts or not faces:
        raise ValueError(f"{path}: no {'vertices' if not verts else 'faces'} found")
    if textured_line:
        return Mesh(
            np.array(verts, dtype=np.float64),
            np.array(faces, dtype=np.int64),
            np.array(uvs, dtype=np.float64),
            np.array(face_uvs, dtype=np.int64),
        )
    return Mesh(np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64))


def _fmt_row(row: np.ndarray) -> str:
    # repr gives the shortest text that reads back to the same float64, so writing is exact
    # and deterministic.
    return " ".join(repr(float(x)) for x in row)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit normals at the vertices: the area-weighted mean of their faces' normals
    (+z for a vertex no face uses)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # length: 2 x area
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, f[:, corner], face_n)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    unused = length[:, 0] == 0
    normals[unused] = (0.0, 0.0, 1.0)
    length[unused] = 1.0
    return normals / length


def write_obj(
    path: str | Path, mesh: Mesh, mtl_name: str | None = None, material: str = "material_0"
) -> None:
    """Write ``mesh`` as an OBJ: one group, ``vn`` vertex normals (:func:`vertex_normals`) with
    the normal index of every corner equal to its vertex index, 1-based ``v/vt/vn`` faces when
    textured (``v//vn`` otherwise), as DexYCB's YCB models are written and its loader expects.

    Args:
        path: output file.
        mesh: the mesh; vertices are written exactly (shortest round-trip decimal).
        mtl_name: file name of a material library next to ``path`` (``mtllib`` record), or None.
        material: the material to use from that library (``usemtl`` record).
    """
    lines = ["# dexlabel mesh"]
    if mtl_name is not None:
        lines.append(f"mtllib {mtl_name}")
    lines += [f"v {_fmt_row(v)}" for v in np.asarray(mesh.vertices, dtype=np.float64)]
    if mesh.uvs is not None:
        lines += [f"vt {_fmt_row(t)}" for t in np.asarray(mesh.uvs, dtype=np.float64)]
    lines += [f"vn {_fmt_row(n)}" for n in vertex_normals(mesh.vertices, mesh.faces)]
    if mtl_name is not None:
        lines.append(f"usemtl {material}")
    faces = np.asarray(mesh.faces, dtype=np.int64) + 1
    if mesh.face_uvs is None:
        lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in faces.tolist()]
    else:
        tex = np.asarray(mesh.face_uvs, dtype=np.int64) + 1
        lines += [
            f"f {a}/{ta}/{a} {b}/{tb}/{b} {c}/{tc}/{c}"
            for (a, b, c), (ta, tb, tc) in zip(faces.tolist(), tex.tolist(), strict=True)
        ]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_mtl(path: str | Path, texture_name: str, material: str = "material_0") -> None:
    """Write a one-material library whose diffuse map is ``texture_name`` (a file next to it)."""
    text = (
        f"newmtl {material}\n"
        "Ka 1.0 1.0 1.0\nKd 1.0 1.0 1.0\nKs 0.0 0.0 0.0\nd 1.0\nillum 1\n"
        f"map_Kd {texture_name}\n"
    )
    Path(path).write_text(text, encoding="utf-8")
