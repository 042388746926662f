"""Our MANO layer against smplx's independent MANO implementation (smplx 0.1.28).

smplx reads the model from a MANO pickle in the official key layout; we write one from the
built-in open hand with `save_mano_pickle` and run both layers on the same parameters.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch

from worker.hand import HandLayer, builtin_hand_model, load_mano_pickle, save_mano_pickle
from worker.hand.model import mano_file_name

smplx = pytest.importorskip("smplx", reason="smplx is in the test extras")

TOL_M = 1e-6
BATCH = 4


def _smplx_mano(folder, side: str, **kwargs):
    model = smplx.MANO(str(folder), is_rhand=side == "right", dtype=torch.float64,
                       batch_size=BATCH, **kwargs)
    if side == "left":
        # The official left file's shapedirs x-column has the wrong sign; smplx's users flip it
        # after loading (as our loader does), so both sides read the same file the same way.
        model.shapedirs[:, 0, :] *= -1.0
    return model


@pytest.fixture(scope="module", params=["right", "left"])
def side_and_folder(request, tmp_path_factory):
    side = request.param
    folder = tmp_path_factory.mktemp(f"mano_{side}")
    save_mano_pickle(builtin_hand_model(side), folder / mano_file_name(side))
    return side, folder


def _parameters(seed: int, pose_width: int):
    rng = np.random.default_rng(seed)
    tensor = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    return (tensor(rng.normal(0, 0.6, (BATCH, 3))), tensor(rng.normal(0, 0.5, (BATCH, pose_width))),
            tensor(rng.normal(0, 1.0, (BATCH, 10))), tensor(rng.normal(0, 0.2, (BATCH, 3))))


@pytest.mark.parametrize("components", [12, 44])
def test_pca_pose_matches_smplx(side_and_folder, components):
    side, folder = side_and_folder
    theirs = _smplx_mano(folder, side, use_pca=True, num_pca_comps=components,
                         flat_hand_mean=False)
    ours = HandLayer(load_mano_pickle(folder / mano_file_name(side)), use_pca=True)
    orient, coeffs, betas, transl = _parameters(1, components)
    padded = torch.cat((coeffs, coeffs.new_zeros(BATCH, 45 - components)), dim=1)
    expected = theirs(betas=betas, global_orient=orient, hand_pose=coeffs, transl=transl)
    got = ours(orient, padded, betas, transl)
    assert (got.vertices - expected.vertices).abs().max() < TOL_M
    assert (got.skeleton - expected.joints).abs().max() < TOL_M
    assert expected.vertices.abs().max() > 0.05  # a real hand, not an empty comparison


@pytest.mark.parametrize("flat", [False, True])
def test_full_axis_angle_pose_matches_smplx(side_and_folder, flat):
    side, folder = side_and_folder
    theirs = _smplx_mano(folder, side, use_pca=False, flat_hand_mean=flat)
    ours = HandLayer(load_mano_pickle(folder / mano_file_name(side)), use_pca=False,
                     flat_hand_mean=flat)
    orient, pose, betas, transl = _parameters(2, 45)
    expected = theirs(betas=betas, global_orient=orient, hand_pose=pose, transl=transl)
    got = ours(orient, pose, betas, transl)
    assert (got.vertices - expected.vertices).abs().max() < TOL_M
    assert (got.skeleton - expected.joints).abs().max() < TOL_M


def test_pose_m_layout_matches_smplx_on_a_chumpy_style_file(tmp_path, monkeypatch):
    # Whether or not chumpy is installed, make importing it fail while the file is read.
    for name in ("chumpy", "chumpy.ch"):
        monkeypatch.setitem(sys.modules, name, None)
    plain, styled = tmp_path / "plain", tmp_path / "styled"
    plain.mkdir()
    styled.mkdir()
    model = builtin_hand_model("right")
    save_mano_pickle(model, plain / "MANO_RIGHT.pkl")
    save_mano_pickle(model, styled / "MANO_RIGHT.pkl", chumpy_style=True)
    assert b"chumpy.ch\nCh" in (styled / "MANO_RIGHT.pkl").read_bytes()
    loaded = load_mano_pickle(styled / "MANO_RIGHT.pkl")
    theirs = _smplx_mano(plain, "right", use_pca=True, num_pca_comps=44, flat_hand_mean=False)
    orient, coeffs, betas, transl = _parameters(3, 44)
    pose_m = torch.cat((orient, coeffs, coeffs.new_zeros(BATCH, 1), transl), dim=1)
    got = HandLayer(loaded).from_pose_m(pose_m, betas)
    expected = theirs(betas=betas, global_orient=orient, hand_pose=coeffs, transl=transl)
    assert (got.vertices - expected.vertices).abs().max() < TOL_M
