"""worker.solver.suggest: a view's suggestions from the hand model fitted to one or two other
views' labels and depth.

On a rendered synthetic capture (seed 5, 4 views x 12 frames at 320x240, lens distortion on
every other camera, depth maps with sensor noise and dropouts), careful simulated labels of
views 1 (and 2) suggest view 0, compared with its ground truth.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from backend.captures.layout import find_sequence_dirs, read_sequence
from tests.worker.quality.test_qc_visibility import CaptureTruth
from worker.assist.prefill import ViewWork, view_work
from worker.solver.suggest import fit_hand_joints, fit_object_points, fitted_prefill, lift_labels
from worker.synth.annotators import annotate

TARGET = 0


class Scene(CaptureTruth):
    """The capture's truth plus its hand's side and shape."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self.plan = read_sequence(find_sequence_dirs(root)[0])
        self.root = root
        hand = self.plan.hands[0]
        self.side = hand.side
        self.betas = np.asarray(hand.betas or np.zeros(10), float)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("suggest-capture")
    generate_capture(root, seed=5, frames=12, views=4, objects=1, width=320, height=240,
                     workers=1)
    return Scene(root)


def _careful(scene: Scene, views: list[int], seed: int = 0) -> list[ViewWork]:
    """Careful simulated workers' labels of ``views`` (2 px per axis), as stored tracks."""
    rng, frames = np.random.default_rng(seed), scene.xy.shape[1]
    out = []
    for v in views:
        cam = scene.cameras[v]
        work = annotate(scene.xy[v], scene.visible[v], (cam.width, cam.height), "careful",
                        rng)
        out.append(view_work(v, enumerate(work.tracks), frames, 21))
    return out


def _fit(scene: Scene, work: list[ViewWork]) -> np.ndarray:
    views = sorted({w.view for w in work})
    return fit_hand_joints(scene.cameras, work, {v: scene.depth[v] for v in views},
                           scene.side, scene.betas)


@pytest.fixture(scope="module")
def fitted(scene: Scene) -> dict[int, tuple[list[ViewWork], np.ndarray, float]]:
    """Per count of accepted views (1: view 1; 2: views 1 and 2): the work, the fitted
    joints and the seconds the fit took."""
    out = {}
    for views in ([1], [1, 2]):
        work = _careful(scene, views)
        tick = time.perf_counter()
        joints = _fit(scene, work)
        out[len(views)] = (work, joints, time.perf_counter() - tick)
    return out


def _errors(scene: Scene, found) -> np.ndarray:
    shown = np.isfinite(found.xy).all(axis=-1) & ~(found.known & ~found.visible)
    visible = scene.visible[TARGET]
    return np.linalg.norm(found.xy - scene.xy[TARGET], axis=-1)[shown & visible]


class TestFittedSuggestions:
    # Measured here: 1 view median 5.3 px, 90th percentile 23.8 px; 2 views 1.5 and 3.6 px.
    @pytest.mark.parametrize(("count", "median_px", "p90_px"), [(1, 8.0, 35.0), (2, 2.5, 6.0)])
    def test_suggestions_lie_near_the_truth(self, scene, fitted, count, median_px, p90_px):
        work, joints, _ = fitted[count]
        found = fitted_prefill(scene.cameras, work, TARGET, joints, scene.depth[TARGET])
        errors = _errors(scene, found)
        assert errors.size > 0.8 * scene.visible[TARGET].sum()
        assert np.median(errors) < median_px and np.percentile(errors, 90) < p90_px
        assert (found.views[np.isfinite(joints).all(axis=-1)] == count).all()

    def test_fitted_joints_lie_near_the_true_joints(self, scene, fitted):
        # Measured: median 11 mm from one view (depth along its rays is the weak direction),
        # 3.7 mm from two.
        for count, bound_mm in ((1, 18.0), (2, 6.0)):
            joints = fitted[count][1]
            mm = np.linalg.norm(joints - scene.joints, axis=-1) * 1000.0
            assert np.isfinite(mm).mean() > 0.9 and np.nanmedian(mm) < bound_mm

    def test_a_fit_takes_seconds(self, fitted):
        # Measured: 28 s (1 view) and 12 s (2 views) for 12 frames with the 2 cores loaded
        # about 4 times over.
        assert all(fitted[c][2] < 60.0 for c in (1, 2))

    def test_truly_occluded_joints_are_proposed_occluded_from_depth(self, scene, fitted):
        work, joints, _ = fitted[1]
        found = fitted_prefill(scene.cameras, work, TARGET, joints, scene.depth[TARGET])
        hidden = ~scene.visible[TARGET] & np.isfinite(scene.xy[TARGET]).all(axis=-1)
        proposed = found.known & ~found.visible
        # Measured: all 31 caught; 6 % of the visible joints proposed occluded.
        assert hidden.sum() > 10 and proposed[hidden].mean() >= 0.8
        assert proposed[scene.visible[TARGET]].mean() < 0.15

    def test_a_surface_in_front_of_the_hand_makes_the_joints_occluded(self, scene, fitted):
        work, joints, _ = fitted[1]
        wall = np.full_like(scene.depth[TARGET], 150)  # 15 cm from the camera, everywhere
        found = fitted_prefill(scene.cameras, work, TARGET, joints, wall)
        fitted_cells = np.isfinite(joints).all(axis=-1)
        assert fitted_cells.sum() > 100
        occluded = (found.known & ~found.visible)[fitted_cells]
        # Measured: 251 of 252 (worker.assist.visibility.surface_check's rule decides).
        assert occluded.mean() > 0.98
        # Where the depth map has no reading the visibility is left unknown.
        blind = fitted_prefill(scene.cameras, work, TARGET, joints,
                               np.zeros_like(scene.depth[TARGET]))
        inside = np.isfinite(blind.xy).all(axis=-1)
        assert inside.sum() > 100 and not blind.known[inside].any()


class TestPrefilledLabelsAreNotEvidence:
    def test_a_view_of_prefilled_keyframes_lifts_and_fits_nothing(self, scene):
        frames = scene.xy.shape[1]
        rows = [[[f, *scene.xy[1, f, p].tolist(), 1, "prefilled"] for f in range(frames)]
                for p in range(21)]
        echo = view_work(1, enumerate(rows), frames, 21)
        _, ok = lift_labels(scene.cameras, [echo], scene.depth)
        assert not ok.any()
        assert np.isnan(_fit(scene, [echo])).all()

    def test_prefilled_labels_beside_decided_ones_do_not_move_the_fit(self, scene, fitted):
        work, joints, _ = fitted[1]
        frames = scene.xy.shape[1]
        # Another worker of view 2 took shifted suggestions unchanged.
        rows = [[[f, *(scene.xy[2, f, p] + 25.0).tolist(), 1, "prefilled"]
                 for f in range(frames)] for p in range(21)]
        echo = view_work(2, enumerate(rows), frames, 21)
        with_echo = _fit(scene, [*work, echo])
        np.testing.assert_allclose(with_echo, joints, atol=1e-9)


class TestFittedObjectSuggestions:
    def test_one_views_landmarks_are_carried_into_another_by_the_fitted_poses(self, scene):
        """View 1's two landmarks, mapped onto the mesh, carried into view 0 by the poses
        fitted to them and view 1's depth; compared with the same surface points under the
        true poses."""
        from backend.captures.truth import CaptureTruth as Truth
        from worker.geometry.mesh_io import read_mesh

        truth, rng, frames = Truth(scene.root), np.random.default_rng(4), scene.xy.shape[1]
        obj = scene.plan.objects[0]
        xy, visible = truth.object_points(scene.plan.cameras[1].serial, 0, frames, rng)
        cam = scene.cameras[1]
        tracks = annotate(xy, visible, (cam.width, cam.height), "careful", rng).tracks
        work = [view_work(1, enumerate(tracks), frames, 2)]
        mesh = read_mesh(obj.mesh_path)
        world, local = fit_object_points(scene.cameras, work, {1: scene.depth[1]},
                                         np.asarray(mesh.vertices, float),
                                         np.asarray(mesh.faces), np.asarray(obj.initial_pose))
        assert np.isfinite(local).all()
        poses = truth.object_poses()[0]
        true_world = np.einsum("fij,pj->fpi", poses[:, :, :3], local) + poses[:, None, :, 3]
        found = fitted_prefill(scene.cameras, work, TARGET, world, scene.depth[TARGET])
        shown = np.isfinite(found.xy).all(axis=-1) & found.known & found.visible
        errors = np.linalg.norm(found.xy - scene.cameras[TARGET].project(true_world), axis=-1)
        # Measured: 12 suggested visible; median under 0.01 px (the frames where the object
        # still rests at its given pose), 90th percentile 52 px (two landmarks in one view pin
        # a moving object poorly: BENCHMARKS.md "Suggestions by accepted views").
        assert shown.sum() >= 8
        assert np.median(errors[shown]) < 1.0
