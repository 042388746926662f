"""Energy terms, their gradients, the closest-point queries behind E_depth, and the LM core."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.worker.solver.test_solver_scene import box, cameras, pose
from worker.geometry.cameras import project_points
from worker.hand import HandLayer, builtin_hand_model
from worker.hand.posing import SubjectHand
from worker.solver.energies import (
    DepthData,
    HandData,
    ObjectData,
    energy,
    hand_residuals,
    object_residuals,
)
from worker.solver.lm import jacobian, levenberg_marquardt
from worker.solver.mesh_query import AABBTree, closest_on_triangles
from worker.solver.projection import Rig

pytestmark = pytest.mark.usefixtures("one_torch_thread")

RNG_SEED = 3


def t64(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64))


@pytest.fixture(scope="module")
def subject():
    layer = HandLayer(builtin_hand_model("right"))
    return SubjectHand(layer, t64(np.random.default_rng(0).normal(0, 0.5, 10)))


class TestClosestPoints:
    def test_triangle_closest_point_beats_dense_sampling(self):
        rng = np.random.default_rng(RNG_SEED)
        tri = rng.normal(0, 1, (40, 3, 3))
        points = rng.normal(0, 1.5, (40, 3))
        bary = closest_on_triangles(points, tri)
        got = np.linalg.norm(points - np.einsum("ni,nij->nj", bary, tri), axis=1)
        s, t = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
        keep = s + t <= 1
        w = np.stack([1 - s[keep] - t[keep], s[keep], t[keep]], axis=1)
        samples = np.einsum("ki,nij->nkj", w, tri)
        sampled = np.linalg.norm(samples - points[:, None], axis=2).min(axis=1)
        assert np.all(got <= sampled + 1e-12)
        assert np.all(sampled - got < 0.02)  # the sampling grid's resolution
        assert np.allclose(bary.sum(1), 1.0) and (bary >= 0).all()

    def test_tree_query_equals_brute_force(self):
        vertices, faces = box()
        rng = np.random.default_rng(RNG_SEED)
        points = rng.normal(0, 0.05, (300, 3))
        dist, face, bary = AABBTree.build(vertices, faces).closest(points)
        tri = vertices[faces]
        brute = np.array([np.linalg.norm(p - np.einsum(
            "ni,nij->nj", closest_on_triangles(np.repeat(p[None], len(faces), 0), tri), tri),
            axis=1).min() for p in points])
        assert np.allclose(dist, brute, atol=1e-12)
        near = np.einsum("ni,nij->nj", bary, tri[face])
        assert np.allclose(np.linalg.norm(points - near, axis=1), dist)


    def test_a_refitted_tree_answers_as_a_new_one(self, subject):
        """The hand's tree built at one pose and refitted to others: the same distances and
        closest points as a tree built there (faces may differ only where they tie)."""
        rng = np.random.default_rng(RNG_SEED)
        faces = subject.faces.numpy()
        poses = t64(rng.normal(0, 0.3, (3, 51)))
        _, verts = subject.pose(poses)
        first = AABBTree.build(verts[0].numpy(), faces)
        for k in (1, 2):
            vertices = verts[k].numpy()
            points = vertices[rng.integers(0, len(vertices), 400)] \
                + rng.normal(0, 0.008, (400, 3))
            moved, new = first.refit(vertices), AABBTree.build(vertices, faces)
            assert np.allclose(moved.lo[0], vertices.min(0)) and np.allclose(
                moved.hi[0], vertices.max(0))
            dist, face, bary = moved.closest(points)
            want, want_face, want_bary = new.closest(points)
            assert np.allclose(dist, want, rtol=0.0, atol=1e-15)
            near = np.einsum("ni,nij->nj", bary, vertices[faces[face]])
            assert np.allclose(near, np.einsum("ni,nij->nj", want_bary,
                                               vertices[faces[want_face]]), atol=1e-12)


def _depth_data(points: np.ndarray, corners: np.ndarray, bary: np.ndarray) -> DepthData:
    ids = np.unique(corners)
    interior = torch.as_tensor((bary > 1e-6).all(axis=1)[None])
    return DepthData(t64(points[None]), torch.as_tensor(ids)[None], torch.as_tensor(
        np.searchsorted(ids, corners)[None]), t64(bary[None]), t64(np.full((1, len(points)), 0.1)),
        interior)


class TestHandEnergy:
    def test_keypoint_energy_is_the_visibility_weighted_mean_squared_error(self, subject):
        cams = cameras(3)
        rng = np.random.default_rng(RNG_SEED)
        pose_m = np.concatenate([[0.2, -0.3, 0.1], rng.normal(0, 0.3, 45), [0.0, 0.0, 0.02]])
        joints, _ = subject.pose(t64(pose_m[None]))
        target = np.stack([project_points(joints[0].numpy(), c.K, c.T_cam_to_world, c.dist)
                           for c in cams]) + rng.normal(0, 4.0, (3, 21, 2))
        gamma = rng.random((3, 21)) < 0.7
        data = HandData(t64(target[None]), t64(np.sqrt(gamma / gamma.sum())[None]), 0.0, None)
        got = energy(hand_residuals(subject, Rig(cams), t64(pose_m[None]), data)).item()
        projected = np.stack([project_points(joints[0].numpy(), c.K, c.T_cam_to_world, c.dist)
                              for c in cams])
        expected = (gamma * ((projected - target) ** 2).sum(-1)).sum() / gamma.sum()
        assert got == pytest.approx(expected, rel=1e-10)
        assert expected > 1.0

    def test_gradients_of_every_term_match_finite_differences(self, subject):
        cams = cameras(2)
        rng = np.random.default_rng(RNG_SEED)
        faces = subject.faces.numpy()[:6]
        data = HandData(
            t64(rng.uniform(40, 120, (1, 2, 21, 2))), t64(rng.random((1, 2, 21))), 0.3,
            _depth_data(rng.normal(0, 0.05, (6, 3)), faces, rng.dirichlet(np.ones(3), 6)),
            smooth_target=t64(rng.normal(0, 0.05, (1, 21, 3))), sqrt_smooth=t64([0.2]),
            pose_target=t64(rng.normal(0, 0.3, (1, 45))), sqrt_pose_smooth=t64([1.5]))
        pose_m = t64(np.concatenate([[0.2, -0.3, 0.1], rng.normal(0, 0.3, 45),
                                     [0.0, 0.0, 0.02]])[None]).requires_grad_(True)
        rig = Rig(cams)
        assert torch.autograd.gradcheck(lambda p: hand_residuals(subject, rig, p, data),
                                        (pose_m,), eps=1e-6, atol=1e-4)

    def test_reg_term_is_the_squared_norm_of_the_pca_coefficients(self, subject):
        data = HandData(torch.zeros(1, 1, 21, 2, dtype=torch.float64),
                        torch.zeros(1, 1, 21, dtype=torch.float64), 0.5, None)
        pose_m = torch.zeros(1, 51, dtype=torch.float64)
        pose_m[0, 3:48] = torch.linspace(-1, 1, 45, dtype=torch.float64)
        got = energy(hand_residuals(subject, Rig(cameras(1)), pose_m, data)).item()
        assert got == pytest.approx(0.25 * float((pose_m[0, 3:48] ** 2).sum()))


class TestObjectEnergy:
    def _data(self, rng, with_depth: bool = True) -> ObjectData:
        vertices, faces = box()
        cams = cameras(3)
        base = pose([0.1, 0.2, -0.3], [0.01, 0.0, 0.02])
        ids = np.array([0, 5, 9, 13])
        depth = None
        if with_depth:
            depth = _depth_data(rng.normal(0, 0.05, (8, 3)), faces[:8],
                                rng.dirichlet(np.ones(3), 8))
        return ObjectData(t64(vertices), t64(base[None]), torch.tensor([0, 1, 2, 1]),
                          torch.as_tensor(ids), t64(rng.uniform(40, 120, (1, 4, 2))),
                          t64(rng.random((1, 4))), depth, Rig(cams))

    def test_gradients_match_finite_differences(self):
        data = self._data(np.random.default_rng(RNG_SEED))
        delta = t64(np.random.default_rng(1).normal(0, 0.05, (1, 6))).requires_grad_(True)
        assert torch.autograd.gradcheck(lambda d: object_residuals(d, data), (delta,),
                                        eps=1e-6, atol=1e-4)

    def test_depth_gradient_is_the_gradient_of_the_true_squared_distance(self):
        """With matches fixed at the current pose, d/dt of E_depth equals the derivative of the
        re-queried mean squared distance (the closest point moves, the gradient does not care)."""
        vertices, faces = box()
        rng = np.random.default_rng(RNG_SEED)
        points = rng.normal(0, 0.03, (50, 3)) + np.array([0.0, 0.0, 0.05])
        tree = AABBTree.build(vertices, faces)
        _dist, face, bary = tree.closest(points)
        depth = _depth_data(points, faces[face], bary)
        none = torch.zeros(0, dtype=torch.long)
        data = ObjectData(t64(vertices), t64(np.eye(3, 4)[None]), none, none,
                          torch.zeros(1, 0, 2, dtype=torch.float64),
                          torch.zeros(1, 0, dtype=torch.float64), depth, Rig(cameras(1)))
        delta = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
        energy(object_residuals(delta, data)).sum().backward()
        step = 1e-7

        def true_energy(shift: np.ndarray) -> float:
            d, _, _ = tree.closest(points - shift)
            return float((0.01 * (d * 1000.0) ** 2).sum())

        numeric = [(true_energy(step * e) - true_energy(-step * e)) / (2 * step)
                   for e in np.eye(3)]
        assert np.allclose(delta.grad[0, 3:].numpy(), numeric, rtol=1e-4, atol=1e-3)
        assert np.abs(numeric).max() > 1.0


    def test_closed_form_jacobian_equals_autodiff(self):
        """object_jacobian against autodiff of object_residuals: landmarks in views with and
        without distortion at a rotated increment (exact), and depth rows where each point
        lies along its triangle's normal, as right after matching (exact there too)."""
        from worker.solver.jacobians import object_jacobian

        rng = np.random.default_rng(RNG_SEED)
        vertices, faces = box()
        base = pose([0.1, 0.2, -0.3], [0.01, 0.0, 0.02])
        landmarks = self._data(rng, with_depth=False)
        delta = t64(rng.normal(0, 0.05, (1, 6)))
        expected = jacobian(lambda d: object_residuals(d, landmarks), delta)
        assert torch.allclose(object_jacobian(delta, landmarks), expected, rtol=0.0,
                              atol=1e-9 * expected.abs().max())
        tri = vertices[faces[:8]] @ base[:, :3].T + base[:, 3]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        bary = rng.dirichlet(np.ones(3), 8)
        points = np.einsum("ni,nij->nj", bary, tri) + rng.normal(0, 0.004, (8, 1)) * normal
        with_depth = ObjectData(landmarks.vertices, landmarks.base, landmarks.views,
                                landmarks.vertex_ids, landmarks.xy, landmarks.sqrt_w,
                                _depth_data(points, faces[:8], bary), landmarks.rig)
        zero = torch.zeros(1, 6, dtype=torch.float64)
        expected = jacobian(lambda d: object_residuals(d, with_depth), zero)
        got = object_jacobian(zero, with_depth)
        assert got.shape == expected.shape
        assert torch.allclose(got, expected, rtol=0.0, atol=1e-9 * expected.abs().max())


class TestLevenbergMarquardt:
    def test_jacobian_matches_autograd_per_frame(self, subject):
        x = t64(np.random.default_rng(RNG_SEED).normal(0, 0.3, (3, 51)))

        def fn(p):
            return subject.pose(p, torch.arange(0, 778, 50))[1].flatten(1)

        jac = jacobian(fn, x)
        for b in range(3):
            ref = torch.autograd.functional.jacobian(lambda p: fn(p[None])[0], x[b])
            assert torch.allclose(jac[b], ref, atol=1e-12)

    def test_fits_each_frame_independently(self, subject):
        rng = np.random.default_rng(RNG_SEED)
        truth = t64(rng.normal(0, 0.3, (4, 51)))
        target, _ = subject.pose(truth, torch.zeros(0, dtype=torch.long))

        def residuals(p):
            joints, _ = subject.pose(p, torch.zeros(0, dtype=torch.long))
            return ((joints - target) * 1000.0).flatten(1)

        start = truth + t64(rng.normal(0, 0.05, (4, 51)))
        fitted, cost = levenberg_marquardt(residuals, start, 15)
        joints, _ = subject.pose(fitted, torch.zeros(0, dtype=torch.long))
        assert (joints - target).abs().max() < 1e-6
        assert cost.max() < 1e-6


class TestProjectionDerivative:
    def test_closed_form_equals_autodiff_of_the_projection(self):
        """Every view's pixels against each point's position: distortion with all five
        coefficients, a skewed K, and a point behind one camera (its depth clamped)."""
        rng = np.random.default_rng(RNG_SEED)
        cams = cameras(4)
        cams[1].dist[:] = [0.08, -0.05, 0.004, -0.003, 0.02]
        cams[2].K[0, 1] = 0.7
        rig = Rig(cams)
        points = t64(rng.normal(0, 0.08, (2, 21, 3)))
        points[1, 0] = t64(cams[0].T_cam_to_world[:, 3] * 1.5)  # behind the first camera
        got = rig.project_derivative(points)
        expected = torch.func.jacrev(lambda p: rig.project(p).sum(0))(points)
        # (V, N, 2) over (B, N, 3): each pixel depends on its own point only.
        diagonal = torch.stack([expected[:, n, :, :, n, :] for n in range(21)], dim=1)
        expected = diagonal.permute(3, 0, 1, 2, 4)  # (B, V, N, 2, 3)
        assert got.shape == (2, 4, 21, 2, 3)
        assert torch.allclose(got, expected, rtol=1e-10, atol=1e-9)
        assert got[1, 0, 0, :, :].abs().max() > 0  # clamped: only z's column drops


class TestHandJacobian:
    def test_chain_rule_jacobian_equals_autodiff_of_the_residuals(self, subject):
        """Exact where depth matches sit on edges (point-to-point rows) and where a point lies
        along its triangle's normal, as it does right after matching."""
        rng = np.random.default_rng(RNG_SEED)
        cams = cameras(3)
        pose_m = t64(np.concatenate([[0.2, -0.3, 0.1], rng.normal(0, 0.3, 45),
                                     [0.0, 0.0, 0.02]])[None])
        faces = subject.faces.numpy()[::97][:8]
        _, verts = subject.pose(pose_m)
        tri = verts[0].numpy()[faces]
        bary = rng.dirichlet(np.ones(3), len(faces))
        bary[:3, 0] = 0.0  # three matches on an edge
        bary[:3] /= bary[:3].sum(1, keepdims=True)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        points = np.einsum("ni,nij->nj", bary, tri) + rng.normal(0, 0.004, (len(faces), 1)) * normal
        points[:3] += rng.normal(0, 0.003, (3, 3))
        data = HandData(t64(rng.uniform(40, 120, (1, 3, 21, 2))), t64(rng.random((1, 3, 21))),
                        0.3, _depth_data(points, faces, bary),
                        smooth_target=t64(rng.normal(0, 0.05, (1, 21, 3))),
                        sqrt_smooth=t64([0.2]), pose_target=t64(rng.normal(0, 0.3, (1, 45))),
                        sqrt_pose_smooth=t64([1.5]))
        assert data.depth.interior[0, 3:].all() and not data.depth.interior[0, :3].any()
        rig = Rig(cams)
        from worker.solver.jacobians import hand_jacobian

        got = hand_jacobian(subject, rig, pose_m, data)
        expected = jacobian(lambda p: hand_residuals(subject, rig, p, data), pose_m)
        assert got.shape == expected.shape
        assert torch.allclose(got, expected, atol=1e-8 * expected.abs().max())
