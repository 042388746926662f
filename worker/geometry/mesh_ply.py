"""Reading PLY meshes (``ascii``, ``binary_little_endian``, ``binary_big_endian``) into arrays;
:func:`worker.geometry.mesh_io.read_mesh` makes them a Mesh.

Vertex ``x y z`` (metres in the model frame), optional per-vertex ``s t`` / ``u v`` texture
coordinates (OBJ convention: ``v`` up) and face ``vertex_indices`` lists.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

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


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A PLY mesh as arrays: vertices (V, 3) float64, faces (F, 3) int64 (polygons
    fan-triangulated) and per-vertex texture coordinates (V, 2) float64 or None.

    Raises:
        ValueError: naming the file (and line, for ascii input) on malformed or empty input.
    """
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
            return verts, faces, uvs.astype(np.float64)
    return verts, faces, None
