"""The hand model's parameters: joint tables, the built-in hand, and MANO pickle files."""

from __future__ import annotations

import importlib.util
import io
import pickle
import pickletools
import sys
from collections import Counter

import numpy as np
import pytest
import scipy.sparse

from worker.hand import (
    FINGER_NAMES,
    JOINT_NAMES,
    JOINT_PARENTS,
    TIP_NAMES,
    HandModel,
    builtin_hand_model,
    load_hand_model,
    load_mano_pickle,
    save_mano_pickle,
)
from worker.hand.joints import MANO_JOINT_NAMES, SKELETON_TO_DEXYCB
from worker.hand.loft import signed_volume

ARRAY_FIELDS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table",
                "hands_components", "hands_mean", "faces", "tip_vertex_ids")


def assert_same_model(a: HandModel, b: HandModel) -> None:
    assert a.side == b.side
    for name in ARRAY_FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


class TestJointTables:
    def test_joint_names_follow_dexycb_order(self):
        assert len(JOINT_NAMES) == 21
        assert FINGER_NAMES == ("thumb", "index", "middle", "ring", "little")
        assert JOINT_NAMES[:5] == ("wrist", "thumb_mcp", "thumb_pip", "thumb_dip", "thumb_tip")
        assert JOINT_NAMES[17:] == ("little_mcp", "little_pip", "little_dip", "little_tip")
        assert tuple(JOINT_NAMES[4::4]) == TIP_NAMES

    def test_joint_parents_chain_each_finger_to_the_wrist(self):
        assert JOINT_PARENTS[0] == -1
        for f in range(5):
            first = 1 + 4 * f
            assert JOINT_PARENTS[first] == 0
            assert JOINT_PARENTS[first + 1:first + 4] == (first, first + 1, first + 2)

    def test_skeleton_order_maps_to_dexycb_names(self):
        names = MANO_JOINT_NAMES + TIP_NAMES
        assert tuple(names[i] for i in SKELETON_TO_DEXYCB) == JOINT_NAMES
        assert SKELETON_TO_DEXYCB[:5] == (0, 13, 14, 15, 16)


class TestBuiltinModel:
    def test_parameters_have_mano_shapes_and_dtypes(self):
        m = builtin_hand_model("right")
        v = m.num_vertices
        assert 700 <= v <= 1000
        expected = {"v_template": (v, 3), "shapedirs": (v, 3, 10), "posedirs": (v, 3, 135),
                    "J_regressor": (16, v), "weights": (v, 16), "kintree_table": (2, 16),
                    "hands_components": (45, 45), "hands_mean": (45,), "tip_vertex_ids": (5,)}
        for name, shape in expected.items():
            assert getattr(m, name).shape == shape, name
        for name in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights",
                     "hands_components", "hands_mean"):
            assert getattr(m, name).dtype == np.float64, name
        assert m.faces.dtype == np.int64 and m.faces.shape[1] == 3
        assert m.faces.min() >= 0 and m.faces.max() < v
        assert m.kintree_table[0].tolist() == [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14]

    @pytest.mark.parametrize("side", ["right", "left"])
    def test_mesh_is_closed_and_faces_outward(self, side):
        m = builtin_hand_model(side)
        f = m.faces
        edges = Counter(map(tuple, np.concatenate((f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]))))
        # Closed and consistently wound: every directed edge once, its reverse once.
        assert all(count == 1 and edges[(b, a)] == 1 for (a, b), count in edges.items())
        assert len({tuple(sorted(t)) for t in f.tolist()}) == len(f)
        assert signed_volume(m.v_template, f) > 2e-4  # > 200 cm^3

    def test_weights_and_regressor_are_partitions_of_unity(self):
        m = builtin_hand_model("right")
        np.testing.assert_allclose(m.weights.sum(1), 1.0, atol=1e-12)
        np.testing.assert_allclose(m.J_regressor.sum(1), 1.0, atol=1e-12)
        assert m.weights.min() >= 0.0 and m.J_regressor.min() >= 0.0

    def test_rest_skeleton_has_adult_proportions(self):
        m = builtin_hand_model("right")
        joints = m.rest_joints()
        np.testing.assert_allclose(joints[0], 0.0, atol=1e-12)  # wrist at the origin
        palm = np.linalg.norm(joints[4])  # wrist to middle knuckle
        middle_tip = m.v_template[m.tip_vertex_ids[2]]
        assert 0.08 <= palm <= 0.095
        assert 0.17 <= np.linalg.norm(middle_tip) <= 0.20
        for finger_joints in ((1, 2, 3), (4, 5, 6), (10, 11, 12), (7, 8, 9)):
            a, b, c = joints[list(finger_joints)]
            proximal, middle = np.linalg.norm(b - a), np.linalg.norm(c - b)
            assert 0.03 <= proximal <= 0.05 and 0.5 < middle / proximal < 0.7

    def test_pose_basis_is_orthonormal_and_mean_is_relaxed(self):
        m = builtin_hand_model("right")
        c = m.hands_components
        np.testing.assert_allclose(c @ c.T, np.eye(45), atol=1e-12)
        mean = m.hands_mean.reshape(15, 3)
        # Fingers of the right hand flex about +z: the relaxed hand is gently curled.
        assert np.all((mean[:12, 2] > 0.1) & (mean[:12, 2] < 0.6))

    def test_shape_modes_are_orthogonal(self):
        s = builtin_hand_model("right").shapedirs.reshape(-1, 10)
        gram = s.T @ s
        np.testing.assert_allclose(gram - np.diag(np.diag(gram)), 0.0, atol=1e-12)
        assert np.all(np.diag(gram) > 0)

    def test_model_is_cached_and_read_only(self):
        m = builtin_hand_model("right")
        assert builtin_hand_model("right") is m
        with pytest.raises(ValueError, match="read-only"):
            m.v_template[0, 0] = 1.0

    def test_left_model_is_the_mirror_image(self):
        right, left = builtin_hand_model("right"), builtin_hand_model("left")
        assert left.side == "left"
        np.testing.assert_array_equal(left.v_template, right.v_template * [-1, 1, 1])
        np.testing.assert_array_equal(left.shapedirs[:, 0], -right.shapedirs[:, 0])
        np.testing.assert_array_equal(left.faces, right.faces[:, [0, 2, 1]])
        np.testing.assert_array_equal(left.hands_mean.reshape(15, 3),
                                      right.hands_mean.reshape(15, 3) * [1, -1, -1])

    def test_unknown_side_is_refused(self):
        with pytest.raises(ValueError, match="'middle'"):
            builtin_hand_model("middle")


def _globals_in(path) -> set[str]:
    return {arg for op, arg, _ in pickletools.genops(path.read_bytes()) if op.name == "GLOBAL"}


class TestManoPickle:
    def test_chumpy_is_absent_from_this_environment(self):
        if importlib.util.find_spec("chumpy") is not None:
            pytest.skip("chumpy is installed here, so the round trips below prove less")
        with pytest.raises(ImportError):
            importlib.import_module("chumpy")

    @pytest.mark.parametrize("side", ["right", "left"])
    def test_chumpy_style_round_trip_without_chumpy(self, tmp_path, side):
        model = builtin_hand_model(side)
        path = tmp_path / f"MANO_{side.upper()}.pkl"
        save_mano_pickle(model, path, chumpy_style=True)
        assert "chumpy.ch Ch" in _globals_in(path)
        assert_same_model(load_mano_pickle(path), model)
        assert "chumpy" not in sys.modules  # the loader never imports it

    def test_plain_file_has_the_official_key_layout(self, tmp_path):
        model = builtin_hand_model("right")
        path = tmp_path / "MANO_RIGHT.pkl"
        save_mano_pickle(model, path)
        with path.open("rb") as f:
            data = pickle.load(f, encoding="latin1")
        for key in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights",
                    "kintree_table", "hands_components", "hands_mean", "hands_coeffs", "f", "J"):
            assert key in data, key
        assert isinstance(data["J_regressor"], scipy.sparse.csc_matrix)
        assert data["f"].dtype == np.uint32 and data["kintree_table"][0, 0] == 4294967295
        np.testing.assert_allclose(data["J"], model.rest_joints())
        assert_same_model(load_mano_pickle(path), model)

    def test_left_file_uses_the_official_shapedirs_sign(self, tmp_path):
        left = builtin_hand_model("left")
        path = tmp_path / "MANO_LEFT.pkl"
        save_mano_pickle(left, path, chumpy_style=True)
        raw = load_mano_pickle(path, fix_left_shapedirs=False)
        np.testing.assert_array_equal(raw.shapedirs[:, 0], -left.shapedirs[:, 0])
        np.testing.assert_array_equal(raw.shapedirs[:, 1:], left.shapedirs[:, 1:])
        np.testing.assert_array_equal(load_mano_pickle(path).shapedirs, left.shapedirs)

    def test_python2_era_module_paths_load(self, tmp_path):
        model = builtin_hand_model("right")
        path = tmp_path / "MANO_RIGHT.pkl"
        save_mano_pickle(model, path, chumpy_style=True)
        legacy = path.read_bytes()
        legacy = legacy.replace(b"cnumpy._core.multiarray\n", b"cnumpy.core.multiarray\n")
        legacy = legacy.replace(b"cscipy.sparse._csc\n", b"cscipy.sparse.csc\n")
        assert legacy != path.read_bytes()
        path.write_bytes(legacy)
        assert_same_model(load_mano_pickle(path), model)

    def test_foreign_globals_are_refused(self, tmp_path):
        path = tmp_path / "MANO_RIGHT.pkl"
        path.write_bytes(b"cos\nsystem\n(S'echo owned'\ntR.")
        with pytest.raises(pickle.UnpicklingError, match=r"os\.system"):
            load_mano_pickle(path)

    def test_side_comes_from_argument_entry_or_file_name(self, tmp_path):
        buffer = io.BytesIO()
        pickle.dump({"v_template": np.zeros((3, 3))}, buffer, protocol=2)
        unnamed = tmp_path / "hand.pkl"
        unnamed.write_bytes(buffer.getvalue())
        with pytest.raises(ValueError, match="side"):
            load_mano_pickle(unnamed)
        path = tmp_path / "any_name.pkl"
        save_mano_pickle(builtin_hand_model("left"), path)
        assert load_mano_pickle(path).side == "left"


class TestLoadHandModel:
    def test_without_a_directory_it_is_the_builtin(self):
        assert load_hand_model("left") is builtin_hand_model("left")

    def test_reads_the_official_file_name_from_the_directory(self, tmp_path):
        model = builtin_hand_model("right")
        save_mano_pickle(model, tmp_path / "MANO_RIGHT.pkl", chumpy_style=True)
        assert_same_model(load_hand_model("right", tmp_path), model)

    def test_missing_file_is_named(self, tmp_path):
        with pytest.raises(FileNotFoundError, match=r"MANO_LEFT\.pkl"):
            load_hand_model("left", str(tmp_path))
