"""Renders closer to real footage, behind options of ``generate_capture``: ``forearm`` (an arm
from the wrist away from the fingers, worker.synth.forearm) and ``varied_light`` (a room's
light drawn from the seed); each drawn in the images while the truth stays the same."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from worker.formats import dexycb
from worker.hand.joints import JOINT_NAMES
from worker.synth import SynthSummary, generate_capture
from worker.synth.forearm import SKIN_LENGTH, SLEEVE_COLOR, SLEEVE_LENGTH, forearm_meshes
from worker.synth.render import (
    AMBIENT,
    DEFAULT_LIGHTING,
    DIFFUSE,
    LIGHT_DIR_SCENE,
    varied_lighting,
)

WRIST, MIDDLE_MCP = JOINT_NAMES.index("wrist"), JOINT_NAMES.index("middle_mcp")


def _joints() -> np.ndarray:
    """Two frames of a hand whose fingers point along +x from a wrist at (0.1, 0, 0.2)."""
    joints = np.zeros((2, 21, 3))
    joints[:, :, 0] = np.linspace(0.1, 0.28, 21)
    joints[:, :, 1] = np.tile(np.linspace(-0.03, 0.03, 21), (2, 1))
    joints[:, :, 2] = 0.2
    joints[:, WRIST] = [0.1, 0.0, 0.2]
    joints[1] += [0.0, 0.05, 0.0]
    return joints


def test_the_arm_runs_from_the_wrist_away_from_the_fingers():
    joints = _joints()
    (bare, bare_faces, skin), (sleeve, sleeve_faces, cloth) = forearm_meshes(joints,
                                                                            (1.0, 2.0, 3.0))
    assert skin == (1.0, 2.0, 3.0) and cloth == SLEEVE_COLOR
    assert bare.shape[0] == sleeve.shape[0] == 2
    assert bare_faces.max() < bare.shape[1] and sleeve_faces.max() < sleeve.shape[1]
    axis = joints[:, WRIST] - joints[:, MIDDLE_MCP]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    along = np.einsum("fvc,fc->fv", sleeve - joints[:, WRIST, None], axis)
    np.testing.assert_allclose(along.max(axis=1), SKIN_LENGTH + SLEEVE_LENGTH, atol=1e-9)
    np.testing.assert_allclose(along.min(axis=1), SKIN_LENGTH, atol=1e-9)
    # The bare arm starts at the wrist (a centimetre inside the hand) and is centred on it.
    ring = bare[:, :24]
    np.testing.assert_allclose(ring.mean(axis=1), joints[:, WRIST] - 0.01 * axis, atol=1e-9)


def test_joints_of_the_wrong_shape_are_refused():
    with pytest.raises(ValueError, match=r"\(2, 20, 3\)"):
        forearm_meshes(np.zeros((2, 20, 3)), (0.0, 0.0, 0.0))


def test_the_default_light_is_the_renderers_fixed_light():
    assert (DEFAULT_LIGHTING.ambient, DEFAULT_LIGHTING.diffuse) == (AMBIENT, DIFFUSE)
    np.testing.assert_array_equal(DEFAULT_LIGHTING.direction, LIGHT_DIR_SCENE)


def test_varied_light_stays_in_a_room_and_comes_from_above():
    lights = [varied_lighting(np.random.default_rng(k)) for k in range(50)]
    for light in lights:
        assert 0.45 <= light.ambient <= 0.65 and 0.4 <= light.diffuse <= 0.65
        assert np.linalg.norm(light.direction) == pytest.approx(1.0)
        assert light.direction[2] >= np.sin(np.deg2rad(35.0)) - 1e-12
    assert len({light.direction for light in lights}) == 50


def _changed_pixels(plain: SynthSummary, other: SynthSummary, same_seg: bool) -> int:
    """Pixels (over every view and frame) whose colour differs by more than 40 grey levels,
    after checking that both captures hold the same truth (and the same segmentation, or one
    with no new labels)."""
    changed = 0
    for serial in plain.serials:
        a = plain.root / plain.subject / plain.sequence / serial
        b = other.root / other.subject / other.sequence / serial
        for f in range(2):
            with np.load(a / dexycb.labels_file(f)) as la, np.load(b / dexycb.labels_file(f)) as lb:
                for key in (dexycb.JOINT_2D, dexycb.JOINT_3D, dexycb.POSE_Y, dexycb.POSE_M):
                    np.testing.assert_array_equal(la[key], lb[key])
                if same_seg:
                    np.testing.assert_array_equal(la[dexycb.SEG], lb[dexycb.SEG])
                # The arm is background in the segmentation: no new labels.
                assert set(np.unique(lb[dexycb.SEG])) <= set(np.unique(la[dexycb.SEG]))
            ca, cb = (cv2.imread(str(d / dexycb.color_file(f))) for d in (a, b))
            changed += int((np.abs(ca.astype(int) - cb.astype(int)).max(axis=2) > 40).sum())
    return changed


@pytest.mark.slow
def test_the_options_keep_the_truth_and_change_the_images(tmp_path: Path) -> None:
    small = {"seed": 61, "frames": 2, "views": 2, "objects": 1, "width": 320, "height": 240,
             "workers": 1}
    plain = generate_capture(tmp_path / "plain", **small)
    arm = generate_capture(tmp_path / "arm", forearm=True, **small)
    assert _changed_pixels(plain, arm, same_seg=False) > 500  # the arm shows in the images
    lit = generate_capture(tmp_path / "lit", varied_light=True, **small)
    assert _changed_pixels(plain, lit, same_seg=True) > 500
