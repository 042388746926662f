"""The differentiable hand layer: MANO semantics, joint order, handedness, pose_m, gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from worker.hand import (
    JOINT_NAMES,
    HandLayer,
    builtin_hand_model,
    load_mano_pickle,
    save_mano_pickle,
)
from worker.hand.builtin import builtin_joint_axes, mirror_axis_angle
from worker.hand.lbs import axis_angle_to_matrix, axis_angle_to_matrix_derivative
from worker.hand.posing import SubjectHand

F64 = torch.float64
MIRROR = np.array([-1.0, 1.0, 1.0])


def t(array) -> torch.Tensor:
    return torch.as_tensor(np.array(array), dtype=F64)


def random_inputs(seed: int, batch: int = 3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "global_orient": rng.normal(0.0, 0.8, (batch, 3)),
        "hand_pose": rng.normal(0.0, 0.8, (batch, 45)),
        "betas": rng.normal(0.0, 1.0, (batch, 10)),
        "transl": rng.normal(0.0, 0.3, (batch, 3)),
    }


def reference_skinning(model, full_pose, betas, transl):
    """Textbook MANO forward pass for one hand, in numpy, for comparison (metres)."""
    v_shaped = model.v_template + model.shapedirs @ betas
    rest = model.J_regressor @ v_shaped
    rot = Rotation.from_rotvec(full_pose.reshape(16, 3)).as_matrix()
    v_posed = v_shaped + model.posedirs @ (rot[1:] - np.eye(3)).ravel()
    world = np.zeros((16, 4, 4))
    for j, parent in enumerate(model.parents):
        local = np.eye(4)
        local[:3, :3] = rot[j]
        local[:3, 3] = rest[j] - (rest[parent] if parent >= 0 else 0.0)
        world[j] = local if parent < 0 else world[parent] @ local
    skin = world.copy()
    skin[:, :3, 3] -= np.einsum("jab,jb->ja", world[:, :3, :3], rest)
    blended = np.einsum("vj,jab->vab", model.weights, skin)
    vertices = np.einsum("vab,vb->va", blended[:, :3, :3], v_posed) + blended[:, :3, 3]
    return vertices + transl, world[:, :3, 3] + transl


@pytest.fixture(scope="module")
def right_layer() -> HandLayer:
    return HandLayer(builtin_hand_model("right"))


class TestAxisAngle:
    def test_matches_scipy_and_is_identity_at_zero(self):
        rng = np.random.default_rng(0)
        vectors = np.vstack((rng.normal(0.0, 1.5, (20, 3)), [[0.0, 0.0, 0.0], [1e-5, -2e-5, 0.0]]))
        expected = Rotation.from_rotvec(vectors).as_matrix()
        np.testing.assert_allclose(axis_angle_to_matrix(t(vectors)).numpy(), expected, atol=1e-14)

    def test_gradient_is_finite_and_correct_at_zero(self):
        for point in ([0.0, 0.0, 0.0], [1e-4, 0.0, -2e-4], [0.3, -1.2, 2.0]):
            x = t([point]).requires_grad_(True)
            assert torch.autograd.gradcheck(axis_angle_to_matrix, (x,))

    def test_closed_form_derivative_equals_autodiff_at_every_scale(self):
        # Large angles, the closed forms near the series' threshold, the series, and zero.
        rng = np.random.default_rng(1)
        for scale in (2.0, 0.3, 0.011, 0.009, 1e-4, 1e-9, 0.0):
            vectors = t(rng.normal(0.0, 1.0, (12, 3)) * scale)
            full = torch.func.jacfwd(axis_angle_to_matrix)(vectors)  # (12, 3, 3, 12, 3)
            expected = torch.stack([full[n, :, :, n, :] for n in range(12)])
            got = axis_angle_to_matrix_derivative(vectors)
            assert torch.allclose(got, expected, rtol=0.0, atol=1e-12), scale

    def test_rejects_wrong_last_dimension(self):
        with pytest.raises(ValueError, match=r"\(2, 4\)"):
            axis_angle_to_matrix(torch.zeros(2, 4))


class TestForward:
    def test_output_shapes_and_dtype(self, right_layer):
        out = right_layer(**{k: t(v) for k, v in random_inputs(1, batch=2).items()})
        v = builtin_hand_model("right").num_vertices
        assert out.vertices.shape == (2, v, 3) and out.vertices.dtype == F64
        assert out.joints.shape == (2, 21, 3)
        assert out.skeleton.shape == (2, 16, 3)
        assert out.full_pose.shape == (2, 48)

    def test_equals_textbook_mano_skinning(self, right_layer):
        model = builtin_hand_model("right")
        inputs = random_inputs(2)
        out = right_layer(**{k: t(v) for k, v in inputs.items()})
        for b in range(3):
            full_pose = out.full_pose[b].numpy()
            hand = inputs["hand_pose"][b] @ model.hands_components + model.hands_mean
            np.testing.assert_allclose(full_pose, np.r_[inputs["global_orient"][b], hand])
            vertices, skeleton = reference_skinning(model, full_pose, inputs["betas"][b],
                                                    inputs["transl"][b])
            np.testing.assert_allclose(out.vertices[b].numpy(), vertices, atol=1e-12)
            np.testing.assert_allclose(out.skeleton[b].numpy(), skeleton, atol=1e-12)

    def test_joints_are_skeleton_in_dexycb_order_plus_tips(self, right_layer):
        out = right_layer(**{k: t(v) for k, v in random_inputs(3).items()})
        tips = torch.as_tensor(builtin_hand_model("right").tip_vertex_ids.copy())
        assert torch.equal(out.joints[:, 0], out.skeleton[:, 0])
        assert torch.equal(out.joints[:, 1:4], out.skeleton[:, 13:16])  # thumb
        assert torch.equal(out.joints[:, 5:8], out.skeleton[:, 1:4])  # index
        assert torch.equal(out.joints[:, 13:16], out.skeleton[:, 10:13])  # ring
        assert torch.equal(out.joints[:, 17:20], out.skeleton[:, 7:10])  # little
        assert torch.equal(out.joints[:, 4::4], out.vertices[:, tips])

    def test_flat_zero_pose_puts_each_tip_farthest_along_its_finger(self):
        layer = HandLayer(builtin_hand_model("right"), flat_hand_mean=True)
        joints = layer(torch.zeros(1, 3, dtype=F64), torch.zeros(1, 45, dtype=F64)).joints[0]
        distance = joints.norm(dim=1).numpy()
        for f in range(5):
            chain = distance[1 + 4 * f:5 + 4 * f]
            assert np.all(np.diff(chain) > 0.01), JOINT_NAMES[1 + 4 * f]

    def test_pca_coefficients_equal_their_axis_angle(self, right_layer):
        model = builtin_hand_model("right")
        axis_angle = HandLayer(model, use_pca=False)
        inputs = {k: t(v) for k, v in random_inputs(4).items()}
        pca_out = right_layer(**inputs)
        inputs["hand_pose"] = inputs["hand_pose"] @ t(model.hands_components)
        torch.testing.assert_close(axis_angle(**inputs).vertices, pca_out.vertices)

    def test_translation_adds_to_everything(self, right_layer):
        inputs = {k: t(v) for k, v in random_inputs(5).items()}
        moved = right_layer(**inputs)
        inputs["transl"] = torch.zeros_like(inputs["transl"])
        still = right_layer(**inputs)
        shift = t(random_inputs(5)["transl"])[:, None]
        torch.testing.assert_close(moved.vertices, still.vertices + shift)
        torch.testing.assert_close(moved.joints, still.joints + shift)

    def test_betas_change_bone_lengths(self, right_layer):
        zeros = torch.zeros(1, 3, dtype=F64), torch.zeros(1, 45, dtype=F64)

        def bones(betas) -> np.ndarray:
            joints = right_layer(*zeros, t([betas])).joints[0].numpy()
            return np.array([np.linalg.norm(joints[i] - joints[p])
                             for i, p in enumerate((-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11,
                                                    0, 13, 14, 15, 0, 17, 18, 19)) if p >= 0])

        base = bones(np.zeros(10))
        bigger = bones(np.r_[2.0, np.zeros(9)])  # mode 0: overall size
        assert np.all(bigger > base * 1.04)
        longer_fingers = bones(np.r_[0.0, 0.0, 2.0, np.zeros(7)])  # mode 2: finger length
        phalanges = [i for i in range(20) if i % 4 != 0]
        assert np.all(longer_fingers[phalanges] > base[phalanges] * 1.02)


class TestHandedness:
    @pytest.mark.parametrize("side", ["right", "left"])
    def test_index_flexion_bends_towards_the_palm_only(self, side):
        layer = HandLayer(builtin_hand_model(side), flat_hand_mean=True, use_pca=False)
        flex = builtin_joint_axes(side)[:, 0]  # (15, 3) flexion axes
        zero = torch.zeros(1, 3, dtype=F64)
        rest = layer(zero, torch.zeros(1, 45, dtype=F64)).joints[0].numpy()
        pose = np.zeros((15, 3))
        pose[0:3] = 0.5 * flex[0:3]  # MANO joints 1-3: the index finger
        bent = layer(zero, t(pose.reshape(1, 45))).joints[0].numpy()
        wrist, index_mcp, little_mcp = rest[0], rest[5], rest[17]
        # For a right hand (index_mcp - wrist) x (little_mcp - wrist) points out of the palm.
        normal = np.cross(index_mcp - wrist, little_mcp - wrist) * (1 if side == "right" else -1)
        normal /= np.linalg.norm(normal)
        assert (bent[8] - rest[8]) @ normal > 0.04
        if side == "right":
            np.testing.assert_allclose(flex[0:12, 2], 1.0, atol=0.03)  # fingers flex about +z
        others = [4, 12, 16, 20]
        np.testing.assert_allclose(bent[others], rest[others], atol=1e-12)

    def test_left_output_mirrors_right_output(self):
        left, right = HandLayer(builtin_hand_model("left")), HandLayer(builtin_hand_model("right"))
        inputs = random_inputs(6)
        r = right(**{k: t(v) for k, v in inputs.items()})
        mirrored = dict(inputs, global_orient=mirror_axis_angle(inputs["global_orient"]),
                        transl=inputs["transl"] * MIRROR)
        lo = left(**{k: t(v) for k, v in mirrored.items()})
        np.testing.assert_allclose(lo.vertices.numpy(), r.vertices.numpy() * MIRROR, atol=1e-12)
        np.testing.assert_allclose(lo.joints.numpy(), r.joints.numpy() * MIRROR, atol=1e-12)


class TestPoseM:
    def test_pose_m_is_forward_with_dexycb_layout(self, right_layer):
        inputs = random_inputs(7)
        pose_m = np.hstack((inputs["global_orient"], inputs["hand_pose"], inputs["transl"]))
        betas = inputs["betas"][0]
        via_pose_m = right_layer.from_pose_m(t(pose_m), t(betas))
        direct = right_layer(t(inputs["global_orient"]), t(inputs["hand_pose"]),
                             t(np.tile(betas, (3, 1))), t(inputs["transl"]))
        torch.testing.assert_close(via_pose_m.vertices, direct.vertices)
        torch.testing.assert_close(via_pose_m.joints, direct.joints)

    def test_needs_a_pca_layer_with_the_mean(self):
        layer = HandLayer(builtin_hand_model("right"), flat_hand_mean=True)
        with pytest.raises(ValueError, match="flat_hand_mean"):
            layer.from_pose_m(torch.zeros(1, 51, dtype=F64), torch.zeros(10, dtype=F64))

    def test_bad_shapes_are_named(self, right_layer):
        with pytest.raises(ValueError, match=r"pose_m must have shape \(B, 51\), got \(1, 48\)"):
            right_layer.from_pose_m(torch.zeros(1, 48), torch.zeros(10))
        with pytest.raises(ValueError, match=r"hand_pose must have shape \(2, 45\), got \(2, 44\)"):
            right_layer(torch.zeros(2, 3), torch.zeros(2, 44))
        with pytest.raises(ValueError, match=r"betas must have shape \(2, 10\), got \(10,\)"):
            right_layer(torch.zeros(2, 3), torch.zeros(2, 45), torch.zeros(10))


class TestPoseJacobian:
    @pytest.mark.parametrize("side", ["right", "left"])
    def test_closed_form_equals_autodiff_of_joints_and_vertices(self, side):
        """SubjectHand.pose_jacobian against forward-mode autodiff of SubjectHand.pose: three
        frames (one at the zero full pose, where every joint's rotation is the identity), a
        different set of vertices per frame."""
        layer = HandLayer(builtin_hand_model(side))
        rng = np.random.default_rng(2)
        subject = SubjectHand(layer, t(rng.normal(0.0, 0.8, 10)))
        pose = t(rng.normal(0.0, 0.4, (3, 51)))
        pose[1, :3] = 0.0
        pose[1, 3:48] = -torch.linalg.solve(layer.hands_components.T, layer.pose_mean[3:])
        ids = torch.as_tensor(rng.integers(0, 778, (3, 40)))

        def forward(p):
            joints, vertices = subject.pose(p, ids)
            return torch.cat((joints.flatten(1), vertices.flatten(1)), 1)

        assert layer.full_pose(pose[1:2, :3], pose[1:2, 3:48]).abs().max() < 1e-12
        from worker.solver.lm import jacobian

        expected = jacobian(forward, pose)  # (3, 63 + 120, 51)
        joints, vertices, d_joints, d_vertices = subject.pose_jacobian(pose, ids)
        assert torch.allclose(torch.cat((joints.flatten(1), vertices.flatten(1)), 1),
                              forward(pose), atol=1e-14)
        got = torch.cat((d_joints.flatten(1, 2), d_vertices.flatten(1, 2)), 1)
        assert got.shape == expected.shape
        assert torch.allclose(got, expected, rtol=0.0, atol=1e-12)


class TestLayerPlumbing:
    def test_gradients_flow_to_every_input(self):
        layer = HandLayer(builtin_hand_model("right"))
        inputs = [t(v).requires_grad_(True) for v in random_inputs(8, batch=2).values()]

        def posed(*args):
            out = layer(*args)
            return out.vertices, out.joints

        assert torch.autograd.gradcheck(posed, tuple(inputs), fast_mode=True)

    def test_float32_layer_runs_a_loaded_pickle_like_the_builtin(self, tmp_path):
        path = tmp_path / "MANO_RIGHT.pkl"
        save_mano_pickle(builtin_hand_model("right"), path, chumpy_style=True)
        loaded = HandLayer(load_mano_pickle(path), dtype=torch.float32)
        builtin = HandLayer(builtin_hand_model("right"))
        inputs = random_inputs(9)
        out32 = loaded(**{k: torch.as_tensor(v, dtype=torch.float32) for k, v in inputs.items()})
        out64 = builtin(**{k: t(v) for k, v in inputs.items()})
        assert out32.vertices.dtype == torch.float32
        np.testing.assert_allclose(out32.vertices.numpy(), out64.vertices.numpy(), atol=1e-5)
