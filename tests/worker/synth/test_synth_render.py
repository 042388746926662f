"""worker.synth building blocks: rasteriser, sensor model, writers, shapes, motion, grasp."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
import yaml

from worker.formats.files import npz_bytes, yaml_text
from worker.geometry.cameras import intrinsics_matrix, pixels_to_rays
from worker.geometry.raster import rasterize
from worker.synth.motion import minimum_jerk
from worker.synth.render import SceneMesh, TextureAtlas, combine, prepare_view, render_view
from worker.synth.scene import object_sdf, place_objects, table_mesh
from worker.synth.sensor import depth_sigma_m, simulate_depth
from worker.synth.shapes import CATALOGUE, box_mesh, cylinder_mesh

K = intrinsics_matrix(300.0, 300.0, 79.5, 59.5)
W, H = 160, 120


def _grid(nx: int, ny: int, size: float, z) -> tuple[np.ndarray, np.ndarray]:
    """A tessellated square at camera depth z(x, y) (metres), facing the camera."""
    xs, ys = np.meshgrid(np.linspace(-size, size, nx + 1), np.linspace(-size, size, ny + 1))
    verts = np.column_stack([xs.ravel(), ys.ravel(), z(xs.ravel(), ys.ravel())])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    a = (j * (nx + 1) + i).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + nx + 2], 1),
                            np.stack([a, a + nx + 2, a + nx + 1], 1)])
    return verts, faces


def _volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    tri = vertices[faces]
    return float(np.einsum("fi,fi->f", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


class TestRasterize:
    def test_tilted_plane_depth_is_exact(self):
        # Plane z = 1 + 0.3 x - 0.2 y (metres, camera frame), finely tessellated.
        verts, faces = _grid(7, 5, 0.5, lambda x, y: 1.0 + 0.3 * x - 0.2 * y)
        frags = rasterize(verts, faces, K, W, H)
        assert np.all(frags.tri >= 0)  # covers the whole image: no cracks between triangles
        ys, xs = np.mgrid[0:H, 0:W]
        rays = pixels_to_rays(np.stack([xs, ys], -1).astype(float), K)
        expected = 1.0 / (1.0 - 0.3 * rays[..., 0] + 0.2 * rays[..., 1])
        np.testing.assert_allclose(frags.depth, expected, atol=2e-7)

    def test_nearest_surface_wins(self):
        far, far_faces = _grid(2, 2, 1.0, lambda x, y: np.full_like(x, 2.0))
        near, near_faces = _grid(1, 1, 0.1, lambda x, y: np.full_like(x, 1.0))
        verts = np.vstack([far, near])
        faces = np.vstack([far_faces, near_faces + len(far)])
        frags = rasterize(verts, faces, K, W, H)
        assert frags.depth[H // 2, W // 2] == pytest.approx(1.0, abs=1e-6)
        assert frags.tri[H // 2, W // 2] >= len(far_faces)
        assert frags.depth[2, 2] == pytest.approx(2.0, abs=1e-6)
        np.testing.assert_allclose(frags.bary.sum(axis=1), 1.0, atol=1e-5)

    def test_triangles_behind_the_camera_are_dropped(self):
        verts = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 1.0, -1.0]])
        frags = rasterize(verts, np.array([[0, 1, 2]]), K, W, H)
        assert np.all(frags.tri == -1) and np.all(frags.depth == 0)

    def test_bad_shapes_are_named(self):
        with pytest.raises(ValueError, match=r"points_cam must have shape \(N, 3\), got \(4, 2\)"):
            rasterize(np.zeros((4, 2)), np.zeros((1, 3), int), K, W, H)


class TestRenderView:
    def test_seg_and_depth_come_from_the_same_surface_with_distortion(self):
        T = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 0.8]])  # looking down at z=0
        table = table_mesh()
        box = box_mesh((0.1, 0.1, 0.2))
        meshes = [
            SceneMesh(table.vertices, table.faces, np.tile([0, 0, 1.0], (len(table.faces), 3, 1)),
                      None, -1, (200.0, 200.0, 200.0), 0),
            SceneMesh(box.vertices + [0, 0, 0.1], box.faces,
                      np.zeros((len(box.faces), 3, 3)) + [0, 0, 1.0], None, -1, (0, 0, 255.0), 7),
        ]
        view = prepare_view(K, np.array([0.05, -0.02, 0.001, 0.0, 0.0]), T, W, H)
        color, depth, seg = render_view(combine(meshes), view, TextureAtlas.build(
            [np.zeros((4, 4, 3), np.uint8)]), np.random.default_rng(0))
        assert color.shape == (H, W, 3) and depth.dtype == np.uint16
        on_box = (seg == 7) & (depth > 0)
        on_table = (seg == 0) & (depth > 0)
        assert on_box.sum() > 100 and on_table.sum() > 1000
        assert np.median(depth[on_box]) == pytest.approx(600, abs=3)  # box top 0.2 m up
        assert np.median(depth[on_table]) == pytest.approx(800, abs=5)


class TestSensor:
    def test_noise_grows_with_depth_squared_and_zero_stays_zero(self):
        rng = np.random.default_rng(0)
        for z in (0.5, 1.0):
            depth = simulate_depth(np.full((200, 200), z), 615.0, rng).astype(float) / 1000.0
            valid = depth > 0
            assert valid.mean() > 0.9
            expected = depth_sigma_m(z, 615.0)
            assert np.std(depth[valid]) == pytest.approx(expected, rel=0.35, abs=4e-4)
        empty = simulate_depth(np.zeros((50, 50)), 615.0, rng)
        assert empty.dtype == np.uint16 and not empty.any()

    def test_depth_edges_lose_pixels(self):
        scene = np.full((100, 100), 1.0)
        scene[30:70, 30:70] = 0.6
        depth = simulate_depth(scene, 615.0, np.random.default_rng(1))
        edge_band = np.zeros((100, 100), bool)
        edge_band[28:72, 28:72] = True
        edge_band[32:68, 32:68] = False
        assert np.mean(depth[edge_band] == 0) > 0.2
        assert np.mean(depth[40:60, 40:60] == 0) < 0.1


class TestWriters:
    def test_npz_is_reproducible_and_loadable(self):
        arrays = {"b": np.arange(6, dtype=np.float32).reshape(2, 3), "a": np.eye(2, dtype=np.uint8)}
        data = npz_bytes(arrays)
        assert data == npz_bytes(dict(reversed(list(arrays.items()))))
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            assert [i.filename for i in archive.infolist()] == ["a.npy", "b.npy"]
            assert {i.date_time for i in archive.infolist()} == {(1980, 1, 1, 0, 0, 0)}
        loaded = np.load(io.BytesIO(data))
        np.testing.assert_array_equal(loaded["b"], arrays["b"])

    def test_yaml_floats_read_back_exactly(self):
        values = [0.1 + 0.2, 1e-17, -615.123456789, np.float64(2.5)]
        text = yaml_text({"z": values, "a": {"n": np.int64(3)}})
        assert text.index("a:") < text.index("z:")
        assert yaml.safe_load(text) == {"a": {"n": 3}, "z": [float(v) for v in values]}


class TestShapes:
    def test_primitives_are_closed_and_outward(self):
        box = box_mesh((0.1, 0.2, 0.3))
        assert _volume(box.vertices, box.faces) == pytest.approx(0.006, rel=1e-9)
        can = cylinder_mesh(0.05, 0.1, segments=64)
        assert _volume(can.vertices, can.faces) == pytest.approx(np.pi * 0.05**2 * 0.1, rel=0.01)

    def test_uvs_stay_inside_the_texture(self):
        for spec in CATALOGUE.values():
            mesh = box_mesh(spec.size) if spec.kind == "box" else cylinder_mesh(spec.size[0],
                                                                                spec.size[2])
            assert mesh.uvs.min() >= 0.0 and mesh.uvs.max() <= 1.0

    def test_sdf_signs(self):
        spec = CATALOGUE[4]  # soup can, radius 33 mm
        points = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.033, 0.0, 0.0]])
        np.testing.assert_allclose(object_sdf(spec, points), [-0.033, 0.017, 0.0], atol=1e-12)


class TestMotionAndScene:
    def test_minimum_jerk_starts_and_stops_at_rest(self):
        u = np.array([0.0, 1e-4, 0.5, 1.0 - 1e-4, 1.0])
        s = minimum_jerk(u)
        assert s[0] == 0.0 and s[-1] == 1.0 and s[2] == pytest.approx(0.5)
        assert s[1] < 1e-10 and 1.0 - s[3] < 1e-10

    def test_objects_rest_on_the_table_without_overlap(self):
        placed = place_objects(np.random.default_rng(0), [2, 3, 4, 21, 16], 2, 0.0)
        for obj in placed:
            assert obj.T_obj_to_table[2, 3] == pytest.approx(obj.spec.half_extents[2])
        centres = np.array([o.T_obj_to_table[:2, 3] for o in placed])
        radii = np.array([np.linalg.norm(o.spec.half_extents[:2]) for o in placed])
        gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) - radii[:, None] - radii
        assert np.all(gaps[~np.eye(len(placed), dtype=bool)] > 0)


def test_planned_grasp_touches_the_object_and_not_the_table():
    from worker.synth.grasp import build_shaped_hand, plan_grasp

    rig = build_shaped_hand(np.zeros(10))
    obj = place_objects(np.random.default_rng(2), [4], 0, 0.0)[0]
    grasp = plan_grasp(rig, obj, 0.1)
    root = grasp.anchor - grasp.rotation @ (rig.anchor - rig.root)
    verts, _ = rig.evaluate(rig.pose_m(grasp.rotation, root, grasp.closed_pose)[None])
    local = (verts[0] - obj.T_obj_to_table[:, 3]) @ obj.T_obj_to_table[:, :3]
    dist = object_sdf(obj.spec, local)
    assert dist.min() > -0.004  # no deep penetration
    assert (dist < 0.003).sum() > 20  # but plenty of contact
    assert verts[0][:, 2].min() > 0.0
