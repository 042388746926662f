"""Triangle meshes: reading OBJ and PLY object models, writing textured OBJ.

Vertices are in the model's own frame (metres for every object model in a capture). Texture
coordinates follow the OBJ convention: ``u`` to the right, ``v`` up, so the texel row of ``v`` in
an image of height ``h`` is ``(1 - v) * (h - 1)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


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
        return _read_ply(path)
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


# PLY scalar type names (both spellings of the format) -> numpy type codes without byte order.
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))


@dataclass
class _PlyElement:
    name: str
    count: int
    # (name, scalar type code, list count type code or None)
    props: list[tuple[str, str, str | None]]


# One column per property: a float array for a scalar property; for a list property, an (N, n)
# float array when every row's list has the same length, else one sequence per row.
_Column = np.ndarray | list[Any]
_Columns = Mapping[str, _Column]


def _ply_type(path: Path, lineno: int, name: str) -> str:
    if name not in _PLY_TYPES:
        raise ValueError(f"{path}:{lineno}: unknown PLY type {name!r}")
    return _PLY_TYPES[name]


def _parse_ply_header(path: Path, data: bytes) -> tuple[str, list[_PlyElement], int, int]:
    """Return (format, elements, byte offset of the body, number of header lines)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file (missing 'ply' magic or 'end_header')")
    body = data.index(b"\n", end) + 1 if b"\n" in data[end:] else len(data)
    lines = data[:body].decode("ascii", errors="replace").splitlines()
    fmt, elements = "", []
    for lineno, line in enumerate(lines, start=1):
        f = line.split()
        if not f or f[0] in ("ply", "comment", "obj_info", "end_header"):
            continue
        if f[0] == "format" and len(f) >= 2:
            fmt = f[1]
        elif f[0] == "element" and len(f) == 3 and f[2].isdigit():
            elements.append(_PlyElement(f[1], int(f[2]), []))
        elif f[0] == "property" and elements and len(f) == 3:
            elements[-1].props.append((f[2], _ply_type(path, lineno, f[1]), None))
        elif f[0] == "property" and elements and len(f) == 5 and f[1] == "list":
            count_t = _ply_type(path, lineno, f[2])
            elements[-1].props.append((f[4], _ply_type(path, lineno, f[3]), count_t))
        else:
            raise ValueError(f"{path}:{lineno}: malformed PLY header line {line!r}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ValueError(f"{path}: unsupported PLY format {fmt!r}")
    return fmt, elements, body, len(lines)


def _ascii_rows(
    path: Path, element: _PlyElement, lines: list[str], start: int, first_line: int
) -> tuple[_Columns, int]:
    """Parse ``element.count`` ascii rows from ``lines[start:]``; returns (columns, next start)."""
    cols: dict[str, list[Any]] = {p[0]: [] for p in element.props}
    for i in range(element.count):
        lineno = first_line + start + i
        if start + i >= len(lines):
            raise ValueError(f"{path}:{lineno}: file ends inside element {element.name!r}")
        tokens, pos = lines[start + i].split(), 0
        try:
            for name, _, count_t in element.props:
                if count_t is None:
                    cols[name].append(float(tokens[pos]))
                    pos += 1
                else:
                    n = int(tokens[pos])
                    cols[name].append([float(t) for t in tokens[pos + 1: pos + 1 + n]])
                    if len(cols[name][-1]) != n:
                        raise IndexError
                    pos += 1 + n
        except (ValueError, IndexError):
            raise ValueError(f"{path}:{lineno}: malformed {element.name} row") from None
    return cols, start + element.count


def _binary_rows(
    path: Path, element: _PlyElement, data: bytes, offset: int, order: str
) -> tuple[_Columns, int]:
    """Parse a binary element; returns (columns, offset after it).

    Fast path: every list is as long as in the first row (all triangles, say), so the element
    is one structured array. Otherwise the rows are walked one by one.
    """
    fields: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    pos = offset
    for name, typ, count_t in element.props:
        if count_t is None:
            fields.append((name, order + typ))
            pos += np.dtype(typ).itemsize
            continue
        if pos + np.dtype(count_t).itemsize > len(data):
            raise ValueError(f"{path}: file ends inside element {element.name!r}")
        n = int(np.frombuffer(data, order + count_t, 1, pos)[0]) if element.count else 0
        fields += [(f"{name}#n", order + count_t), (name, order + typ, (n,))]
        pos += np.dtype(count_t).itemsize + n * np.dtype(typ).itemsize
    dtype = np.dtype(fields)
    end = offset + dtype.itemsize * element.count
    if end <= len(data):
        rows = np.frombuffer(data, dtype, element.count, offset)
        if all(count_t is None or np.all(rows[f"{name}#n"] == rows.dtype[name].shape[0])
               for name, _, count_t in element.props):
            return {p[0]: rows[p[0]].astype(np.float64) for p in element.props}, end
    return _binary_rows_walk(path, element, data, offset, order)


def _binary_rows_walk(
    path: Path, element: _PlyElement, data: bytes, offset: int, order: str
) -> tuple[_Columns, int]:
    """Row-by-row parse of a binary element with lists of varying length."""
    cols: dict[str, list[Any]] = {p[0]: [] for p in element.props}
    pos = offset
    try:
        for _ in range(element.count):
            for name, typ, count_t in element.props:
                size = np.dtype(typ).itemsize
                if count_t is None:
                    cols[name].append(float(np.frombuffer(data, order + typ, 1, pos)[0]))
                    pos += size
                    continue
                n = int(np.frombuffer(data, order + count_t, 1, pos)[0])
                pos += np.dtype(count_t).itemsize
                cols[name].append(np.frombuffer(data, order + typ, n, pos).astype(np.float64))
                pos += n * size
    except ValueError:  # np.frombuffer: the buffer is shorter than asked for
        raise ValueError(f"{path}: file ends inside element {element.name!r}") from None
    scalars = {p[0] for p in element.props if p[2] is None}
    return {k: (np.asarray(v) if k in scalars else v) for k, v in cols.items()}, pos


def _triangulate(path: Path, polys: _Column, n_verts: int) -> np.ndarray:
    """Fan-triangulate polygons (a list of index lists, or an (F, n) array) -> (F', 3) int64."""
    if len(polys) == 0:
        raise ValueError(f"{path}: PLY has no faces")
    if len({len(p) for p in polys}) == 1:
        groups = [np.asarray(polys, dtype=np.float64).reshape(len(polys), -1)]
    else:
        groups = [np.asarray([p], dtype=np.float64) for p in polys]
    tris = []
    for poly in groups:
        if poly.shape[1] < 3 or np.any(poly != np.round(poly)):
            raise ValueError(f"{path}: a face has fewer than 3 corners or non-integer indices")
        poly = poly.astype(np.int64)
        if poly.min() < 0 or poly.max() >= n_verts:
            raise ValueError(f"{path}: a face indexes a missing vertex (have {n_verts})")
        fan = [poly[:, [0, k, k + 1]] for k in range(1, poly.shape[1] - 1)]
        tris.append(np.stack(fan, axis=1).reshape(-1, 3))
    return np.concatenate(tris)


def _read_ply(path: Path) -> Mesh:
    data = path.read_bytes()
    fmt, elements, offset, n_header = _parse_ply_header(path, data)
    found: dict[str, _Columns] = {}
    lines = data[offset:].decode("ascii", errors="replace").splitlines() if fmt == "ascii" else []
    start = 0
    for element in elements:
        if fmt == "ascii":
            cols, start = _ascii_rows(path, element, lines, start, n_header + 1)
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            cols, offset = _binary_rows(path, element, data, offset, order)
        found[element.name] = cols
    vertex, face = found.get("vertex"), found.get("face")
    if not vertex or not all(k in vertex for k in "xyz"):
        raise ValueError(f"{path}: PLY has no vertex element with x, y, z")
    verts = np.stack([np.asarray(vertex[k], dtype=np.float64) for k in "xyz"], axis=1)
    if not face or not ({"vertex_indices", "vertex_index"} & face.keys()):
        raise ValueError(f"{path}: PLY has no face element with vertex_indices")
    indices = face["vertex_indices"] if "vertex_indices" in face else face["vertex_index"]
    faces = _triangulate(path, indices, len(verts))
    for u_name, v_name in _UV_NAMES:
        if u_name in vertex and v_name in vertex:
            uvs = np.stack([np.asarray(vertex[u_name]), np.asarray(vertex[v_name])], axis=1)
            return Mesh(verts, faces, uvs.astype(np.float64), faces.copy())
    return Mesh(verts, faces)
