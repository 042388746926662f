"""worker.geometry.mesh_io: OBJ round trip, OBJ corner forms, PLY ascii/binary, clear errors."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from worker.geometry.mesh_io import Mesh, read_mesh, write_obj
from worker.synth.shapes import box_mesh, cylinder_mesh

QUAD_OBJ = """# a unit square made of one quad and a triangle fan
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0.5 0.5 1.0 1.0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
f -5/1 -3/3 -1/2
"""


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


class TestObj:
    def test_round_trip_is_exact(self, tmp_path):
        mesh = cylinder_mesh(0.033, 0.101, segments=16)
        write_obj(tmp_path / "can.obj", mesh, mtl_name="can.obj.mtl")
        back = read_mesh(tmp_path / "can.obj")
        np.testing.assert_array_equal(back.vertices, mesh.vertices)
        np.testing.assert_array_equal(back.faces, mesh.faces)
        np.testing.assert_array_equal(back.uvs, mesh.uvs)
        np.testing.assert_array_equal(back.face_uvs, mesh.face_uvs)
        assert "mtllib can.obj.mtl" in (tmp_path / "can.obj").read_text()

    def test_untextured_round_trip(self, tmp_path):
        box = box_mesh((0.1, 0.2, 0.3))
        write_obj(tmp_path / "box.obj", Mesh(box.vertices, box.faces))
        back = read_mesh(tmp_path / "box.obj")
        assert back.uvs is None and back.face_uvs is None
        np.testing.assert_array_equal(back.faces, box.faces)

    def test_polygons_fan_triangulate_and_relative_indices_resolve(self, tmp_path):
        mesh = read_mesh(_write(tmp_path / "quad.obj", QUAD_OBJ))
        assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
        np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 4]])
        np.testing.assert_array_equal(mesh.face_uvs, [[0, 1, 2], [0, 2, 3], [0, 2, 1]])
        np.testing.assert_array_equal(mesh.vertices[4], [0.5, 0.5, 1.0])

    def test_vertex_normal_only_corners(self, tmp_path):
        mesh = read_mesh(_write(tmp_path / "n.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\n"
                                "f 1//1 2//1 3//1\n"))
        assert mesh.uvs is None
        np.testing.assert_array_equal(mesh.faces, [[0, 1, 2]])

    @pytest.mark.parametrize(
        ("text", "message"),
        [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", r"bad\.obj:4: vertex index 7 out of range"),
            ("v 0 0 0\nv 1 zero 0\n", r"bad\.obj:2: not a number"),
            ("v 0 0 0\nv 1 0\n", r"bad\.obj:2: expected 3 numbers"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"bad\.obj:4: a face needs at least 3"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", r"bad\.obj:4: vertex index 0"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 2 3\n",
             r"bad\.obj:6: faces mix"),
            ("# nothing\n", r"bad\.obj: no vertices"),
        ],
    )
    def test_malformed_obj_names_file_and_line(self, tmp_path, text, message):
        with pytest.raises(ValueError, match=message):
            read_mesh(_write(tmp_path / "bad.obj", text))

    def test_unknown_suffix(self, tmp_path):
        with pytest.raises(ValueError, match=r"unsupported mesh format '\.stl'"):
            read_mesh(_write(tmp_path / "m.stl", "solid"))


PLY_HEADER = """ply
format {fmt} 1.0
comment made for a test
element vertex 4
property float x
property float y
property float z
property float s
property float t
element face 2
property list uchar int vertex_indices
end_header
"""
PLY_VERTS = [(0, 0, 0, 0, 0), (1, 0, 0, 1, 0), (1, 1, 0, 1, 1), (0, 1, 0.5, 0, 1)]


def _ascii_vertices() -> str:
    return "".join(" ".join(str(x) for x in v) + "\n" for v in PLY_VERTS)


class TestPly:
    def test_ascii_with_a_quad(self, tmp_path):
        body = _ascii_vertices() + "4 0 1 2 3\n3 0 2 3\n"
        mesh = read_mesh(_write(tmp_path / "a.ply", PLY_HEADER.format(fmt="ascii") + body))
        np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 3]])
        np.testing.assert_array_equal(mesh.vertices[3], [0, 1, 0.5])
        np.testing.assert_array_equal(mesh.uvs[2], [1, 1])

    def test_binary_little_endian(self, tmp_path):
        header = PLY_HEADER.format(fmt="binary_little_endian")
        body = b"".join(struct.pack("<5f", *v) for v in PLY_VERTS)
        body += struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B3i", 3, 0, 2, 3)
        path = tmp_path / "b.ply"
        path.write_bytes(header.encode() + body)
        mesh = read_mesh(path)
        np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
        np.testing.assert_allclose(mesh.vertices, np.array(PLY_VERTS)[:, :3])

    def test_binary_with_mixed_polygons(self, tmp_path):
        body = b"".join(struct.pack(">5f", *v) for v in PLY_VERTS)
        body += struct.pack(">B4i", 4, 0, 1, 2, 3) + struct.pack(">B3i", 3, 0, 2, 3)
        path = tmp_path / "m.ply"
        path.write_bytes(PLY_HEADER.format(fmt="binary_big_endian").encode() + body)
        np.testing.assert_array_equal(read_mesh(path).faces, [[0, 1, 2], [0, 2, 3], [0, 2, 3]])

    def test_truncated_binary_is_reported(self, tmp_path):
        path = tmp_path / "t.ply"
        path.write_bytes(PLY_HEADER.format(fmt="binary_little_endian").encode() + b"\0" * 10)
        with pytest.raises(ValueError, match=r"t\.ply: file ends inside element 'vertex'"):
            read_mesh(path)

    def test_bad_ascii_row_names_the_line(self, tmp_path):
        body = "0 0 0 0 0\n1 0 0 1 0\n1 1 zero 1 1\n0 1 0 0 1\n3 0 1 2\n3 0 2 3\n"
        with pytest.raises(ValueError, match=r"c\.ply:15: malformed vertex row"):
            read_mesh(_write(tmp_path / "c.ply", PLY_HEADER.format(fmt="ascii") + body))

    def test_face_index_out_of_range(self, tmp_path):
        body = _ascii_vertices() + "3 0 1 9\n3 0 2 3\n"
        with pytest.raises(ValueError, match=r"d\.ply: a face indexes a missing vertex"):
            read_mesh(_write(tmp_path / "d.ply", PLY_HEADER.format(fmt="ascii") + body))
