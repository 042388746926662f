"""worker.quality.anchored: object landmarks judged against the solved object.

The scene: a 10 cm box sliding and turning 0.6 m in front of one camera (640x480), two
landmarks on its camera-facing side, labelled through the same keyframes and interpolation
as the annotation page by the simulated annotator profiles.
"""

from __future__ import annotations

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.anchored import anchor, merge_anchored, score_anchored
from worker.quality.bounds import kind_bounds
from worker.quality.decide import QCThresholds, decide, learn_thresholds
from worker.quality.metrics import AssignmentQC
from worker.quality.object_views import ray_hits
from worker.quality.solved_scene import SolvedObjects
from worker.quality.view_labels import ViewLabels
from worker.synth.annotators import annotate
from worker.tracks.interpolate import dense_track

FRAMES, WIDTH, HEIGHT = 36, 640, 480
HALF = 0.05


def box() -> tuple[np.ndarray, np.ndarray]:
    """A 10 cm cube centred on its origin: (8, 3) vertices m, (12, 3) faces."""
    v = np.array([[x, y, z] for x in (-HALF, HALF) for y in (-HALF, HALF) for z in (-HALF, HALF)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, faces


def poses(frames: int = FRAMES) -> np.ndarray:
    """(1, F, 3, 4) the box sliding 8 cm along x and turning 20 degrees about z."""
    out = np.zeros((1, frames, 3, 4))
    for f, t in enumerate(np.linspace(0.0, 1.0, frames)):
        a = np.deg2rad(20.0) * t
        out[0, f, :, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
        out[0, f, :, 3] = [-0.04 + 0.08 * t, 0.0, 0.0]
    return out


@pytest.fixture(scope="module")
def scene() -> tuple[CameraModel, SolvedObjects, np.ndarray]:
    camera = CameraModel(intrinsics_matrix(615.0, 615.0, 320.0, 240.0), None,
                         look_at(np.array([0.1, -0.6, 0.25]), np.zeros(3),
                                 np.array([0.0, 0.0, 1.0])), WIDTH, HEIGHT)
    vertices, faces = box()
    solved = SolvedObjects([vertices], [faces], poses())
    # Two points on the side facing the camera (y = -HALF), object frame.
    points = np.array([[-0.02, -HALF, 0.01], [0.025, -HALF, -0.02]])
    return camera, solved, points


def truth_track(camera: CameraModel, solved: SolvedObjects, points: np.ndarray) -> np.ndarray:
    pose = solved.poses[0]
    world = np.einsum("fij,pj->fpi", pose[:, :, :3], points) + pose[:, None, :, 3]
    return camera.project(world)


def label(camera, solved, points, profile: str, seed: int = 0) -> ViewLabels:
    xy = truth_track(camera, solved, points)
    work = annotate(xy, np.ones(xy.shape[:2], bool), (WIDTH, HEIGHT), profile,
                    np.random.default_rng(seed))
    dense = [dense_track(track, FRAMES) for track in work.tracks]
    return ViewLabels(profile, 0, np.stack([d.xy for d in dense], axis=1),
                      np.stack([d.visible for d in dense], axis=1), 90.0)


class TestRayHits:
    def test_a_ray_through_the_box_hits_its_near_face(self):
        vertices, faces = box()
        dist, face = ray_hits(np.array([0.0, -1.0, 0.0]), np.array([[0.0, 1.0, 0.0]]),
                              vertices[faces])
        assert dist[0] == pytest.approx(1.0 - HALF) and face[0] >= 0

    def test_a_ray_beside_the_box_misses(self):
        vertices, faces = box()
        dist, face = ray_hits(np.array([0.2, -1.0, 0.0]), np.array([[0.0, 1.0, 0.0]]),
                              vertices[faces])
        assert np.isinf(dist[0]) and face[0] == -1


class TestAnchor:
    def test_a_careful_track_is_anchored_to_its_surface_point(self, scene):
        camera, solved, points = scene
        lab = label(camera, solved, points, "careful")
        found = anchor(camera, lab.xy[:, 0], lab.visible[:, 0], solved, 0)
        assert found is not None and np.linalg.norm(found - points[0]) < 0.004


class TestScoreAnchored:
    def test_careful_work_follows_its_anchored_points(self, scene):
        camera, solved, points = scene
        qc = score_anchored(camera, label(camera, solved, points, "careful"), solved, 0)
        assert qc.metrics["anchored_median_px"] < 3.0 and qc.metrics["anchored_p90_px"] < 6.0
        assert qc.metrics["anchored_visible_occluded"] == 0.0
        assert qc.metrics["anchored_fraction"] == 1.0 and not qc.provisional

    def test_a_landmark_clicked_on_every_frame_is_not_reviewed_for_its_click_noise(
            self, scene):
        # Careful clicks on every frame (2 px per axis, i.i.d.) shake about 6.9 px/frame^2
        # against the anchored points from the clicks alone: the objects' bounds let that
        # through, the hands' would not.
        camera, solved, points = scene
        truth = truth_track(camera, solved, points)
        reports = []
        for seed in range(8):
            xy = truth + np.random.default_rng(seed).normal(0.0, 2.0, truth.shape)
            reports.append(score_anchored(camera, ViewLabels(f"c{seed}", 0, xy, np.ones(
                xy.shape[:2], bool), 90.0), solved, 0))
        shake = [qc.metrics["jitter_px"] for qc in reports]
        assert all(5.5 < s < 8.0 for s in shake), shake
        rows = [qc.metrics for qc in reports]
        names = ["a", "b"]
        objects = learn_thresholds(rows, QCThresholds(bounds=kind_bounds("object")))
        assert all(decide(qc, objects, names).outcome == "approve" for qc in reports)
        hands = learn_thresholds(rows, QCThresholds(bounds=kind_bounds("hand")))
        assert any(decide(qc, hands, names).outcome == "review" for qc in reports)

    def test_a_track_taken_from_tracking_within_a_careful_tolerance_is_not_reviewed(
            self, scene):
        # A careful worker takes a tracked position it judges within 6 px of the point and
        # corrects beyond: its track, on the point where it was keyed, slides up to that far
        # towards the end of the clip. A slide twice as far (an unchecked tracker) asks for a
        # look.
        camera, solved, points = scene
        truth = truth_track(camera, solved, points)
        slide = np.clip((np.arange(FRAMES) - 0.6 * FRAMES) / (0.1 * FRAMES), 0.0, 1.0)
        names = ["a", "b"]
        outcomes = {}
        for reach in (6.0, 12.0):
            xy = truth + reach * slide[:, None, None] * np.array([0.6, 0.8])
            qc = score_anchored(camera, ViewLabels(f"s{reach}", 0, xy, np.ones(
                xy.shape[:2], bool), 90.0), solved, 0)
            thresholds = learn_thresholds([qc.metrics], QCThresholds(
                bounds=kind_bounds("object")))
            outcomes[reach] = (qc.metrics["anchored_drift_px"],
                               decide(qc, thresholds, names).outcome)
        assert outcomes[6.0][0] > 5.0 and outcomes[6.0][1] == "approve", outcomes
        assert outcomes[12.0][0] > 10.0 and outcomes[12.0][1] == "review", outcomes

    def test_sloppy_work_is_several_pixels_off(self, scene):
        camera, solved, points = scene
        careful = score_anchored(camera, label(camera, solved, points, "careful"), solved, 0)
        sloppy = score_anchored(camera, label(camera, solved, points, "sloppy", 1), solved, 0)
        assert sloppy.metrics["anchored_median_px"] > 4.0
        assert sloppy.metrics["anchored_median_px"] > 2.0 * careful.metrics["anchored_median_px"]

    def test_swapped_landmarks_put_the_swap_window_far_off(self, scene):
        camera, solved, points = scene
        qc = score_anchored(camera, label(camera, solved, points, "swapper", 2), solved, 0)
        assert qc.metrics["anchored_p90_px"] > 25.0
        assert any(i["about"] == "anchored" for i in qc.issues)

    def test_a_frozen_track_drifts_off_a_moving_object(self, scene):
        camera, solved, points = scene
        qc = score_anchored(camera, label(camera, solved, points, "lazy", 3), solved, 0)
        assert qc.metrics["anchored_p90_px"] > 20.0

    def test_points_marked_occluded_while_in_view_are_counted(self, scene):
        camera, solved, points = scene
        qc = score_anchored(camera, label(camera, solved, points, "occluder", 4), solved, 0)
        assert qc.metrics["anchored_visible_occluded"] > 0.5

    def test_random_clicks_off_the_object_cannot_be_anchored(self, scene):
        camera, solved, points = scene
        lab = label(camera, solved, points, "careful")
        lab.xy[:] = [[5.0, 5.0], [630.0, 470.0]]
        qc = score_anchored(camera, lab, solved, 0)
        assert qc.metrics["anchored_fraction"] == 0.0 and qc.metrics["anchored_median_px"] is None

    def test_a_point_behind_another_object_is_hidden(self, scene):
        camera, solved, points = scene
        vertices, faces = box()
        # A 30 cm box halfway between the camera and the first one, all clip long.
        wall = np.zeros((1, FRAMES, 3, 4))
        wall[0, :, :, :3] = np.eye(3)
        wall[0, :, :, 3] = [0.03, -0.18, 0.075]
        both = SolvedObjects([vertices, vertices * 3.0], [faces, faces],
                             np.concatenate([solved.poses, wall]))
        qc = score_anchored(camera, label(camera, solved, points, "careful"), both, 0)
        assert qc.metrics["anchored_hidden_visible"] == pytest.approx(1.0)

    def test_a_landmark_shown_where_the_other_is_while_hidden_is_far_off(self, scene):
        camera, solved, points = scene
        vertices, faces = box()
        # The wall of the test above, there for frames 10-20 only (unknown elsewhere).
        wall = np.full((1, FRAMES, 3, 4), np.nan)
        wall[0, 10:21, :, :3] = np.eye(3)
        wall[0, 10:21, :, 3] = [0.03, -0.18, 0.075]
        both = SolvedObjects([vertices, vertices * 3.0], [faces, faces],
                             np.concatenate([solved.poses, wall]))
        careful = label(camera, solved, points, "careful")
        careful.visible[10:21] = False
        before = score_anchored(camera, careful, both, 0)
        # Behind the wall the two are swapped: the first shown where the second is.
        careful.xy[10:21, 0] = careful.xy[10:21, 1]
        careful.visible[10:21, 0] = True
        swapped = score_anchored(camera, careful, both, 0)
        assert before.metrics["anchored_p90_px"] < 6.0
        assert swapped.metrics["anchored_p90_px"] > 25.0

    def test_frames_without_a_solved_pose_judge_nothing(self, scene):
        camera, solved, points = scene
        unsolved = SolvedObjects(solved.vertices, solved.faces, np.full_like(solved.poses, np.nan))
        qc = score_anchored(camera, label(camera, solved, points, "careful"), unsolved, 0)
        assert qc.provisional and qc.metrics["anchored_median_px"] is None

    def test_bad_scene_shape_raises_naming_it(self, scene):
        camera, solved, points = scene
        short = SolvedObjects(solved.vertices, solved.faces, solved.poses[:, :5])
        with pytest.raises(ValueError, match=r"\(O=1, F=36, 3, 4\)"):
            score_anchored(camera, label(camera, solved, points, "careful"), short, 0)


def test_merge_replaces_motion_and_outline_guesses_once_the_label_is_anchored():
    before = AssignmentQC("k", 0, {"moved_with_object": 0.01, "jump_fraction": 0.2,
                                   "outlier_fraction": 0.5, "completeness": 1.0}, [], [],
                          issues=[{"point": 0, "frames": [3, 4], "about": "jump"},
                                  {"point": 1, "frames": [0, 0], "about": "silhouette"}])
    anchored = AssignmentQC("k", 0, {"anchored_median_px": 1.5}, [1.5, 1.5], [1.5])
    merged = merge_anchored(before, anchored, 7)
    assert merged.metrics["moved_with_object"] is None and merged.metrics["jump_fraction"] is None
    assert merged.metrics["outlier_fraction"] is None
    assert merged.metrics["completeness"] == 1.0 and merged.metrics["solve_run"] == 7.0
    assert merged.issues == [] and merged.per_joint == [1.5, 1.5]
