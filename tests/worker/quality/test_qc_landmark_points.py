"""worker.quality.landmark_points and the landmark rules of the decision: two landmarks of one
object are distinct points of its surface, in plain view.

The scene is tests/worker/quality/test_qc_anchored.py's: a 10 cm box in front of one camera
(640x480), sliding and turning, or standing still at its first pose; labels through the simulated
annotators' keyframes and interpolation.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_anchored import FRAMES, HALF, box, label, poses
from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.anchored import score_anchored
from worker.quality.decide import QCThresholds, decide, learn_thresholds
from worker.quality.landmark_points import (
    facing,
    separation_mm,
    shown_fraction,
    surface_normal,
)
from worker.quality.solved_scene import SolvedObjects
from worker.synth.annotators import (
    LANDMARK_SEPARATION_M,
    OBJECT_PROFILES,
    PROFILES,
    annotate,
    distinct_points,
    draw_profiles,
)

# Two points on the side facing the camera (y = -HALF), object frame, 55 mm apart.
POINTS = np.array([[-0.02, -HALF, 0.01], [0.025, -HALF, -0.02]])


def camera() -> CameraModel:
    return CameraModel(intrinsics_matrix(615.0, 615.0, 320.0, 240.0), None,
                       look_at(np.array([0.1, -0.6, 0.25]), np.zeros(3),
                               np.array([0.0, 0.0, 1.0])), 640, 480)


@pytest.fixture(scope="module", params=["moving", "static"])
def scene(request: pytest.FixtureRequest) -> SolvedObjects:
    vertices, faces = box()
    moving = poses()
    chosen = moving if request.param == "moving" else np.repeat(moving[:, :1], FRAMES, axis=1)
    return SolvedObjects([vertices], [faces], chosen)


class TestSeparation:
    def test_least_distance_between_points_in_millimetres(self):
        points = [np.zeros(3), np.array([0.03, 0.0, 0.0]), np.array([0.0, 0.01, 0.0])]
        assert separation_mm(points) == pytest.approx(10.0)

    def test_fewer_than_two_points_have_no_separation(self):
        assert separation_mm([np.zeros(3)]) is None and separation_mm([]) is None


class TestSurfaceNormal:
    def test_a_point_on_a_box_side_takes_that_sides_normal(self):
        vertices, faces = box()
        normal = surface_normal(np.array([0.01, -HALF, 0.02]), vertices, faces)
        assert abs(normal @ [0.0, -1.0, 0.0]) == pytest.approx(1.0)


class TestFacing:
    def test_a_side_faced_square_on_reads_one_and_edge_on_near_zero(self):
        vertices, faces = box()
        # The camera looks straight at the y = -HALF side from 0.6 m.
        square = CameraModel(intrinsics_matrix(615.0, 615.0, 320.0, 240.0), None,
                             look_at(np.array([0.0, -0.6, 0.0]), np.zeros(3),
                                     np.array([0.0, 0.0, 1.0])), 640, 480)
        still = np.repeat(np.eye(3, 4)[None, None], 4, axis=1)
        scene = SolvedObjects([vertices], [faces], still)
        front, side = np.array([0.0, -HALF, 0.0]), np.array([HALF, -0.045, 0.0])
        shown = np.ones(4, bool)
        assert facing(square, front, np.repeat(front[None], 4, 0), shown, scene, 0) \
            == pytest.approx(1.0, abs=1e-6)
        # The x = +HALF side seen from straight ahead: edge-on.
        assert facing(square, side, np.repeat(side[None], 4, 0), shown, scene, 0) < 0.1

    def test_a_point_never_shown_has_no_facing(self):
        vertices, faces = box()
        scene = SolvedObjects([vertices], [faces], poses())
        world = np.zeros((FRAMES, 3))
        assert facing(camera(), POINTS[0], world, np.zeros(FRAMES, bool), scene, 0) is None


class TestShownFraction:
    def test_the_least_shown_anchored_landmark_counts(self):
        shown = np.array([[1, 1], [1, 0], [1, 0], [1, 1]], bool)
        known = np.array([True, True, True, False])
        both = shown_fraction(shown, known, np.array([True, True]))
        assert both == pytest.approx(1 / 3, abs=1e-4)
        assert shown_fraction(shown, known, np.array([True, False])) == 1.0
        assert shown_fraction(shown, known, np.array([False, False])) is None


class TestScoreAnchoredSeparation:
    def test_careful_landmarks_are_distinct_points_in_plain_view(self, scene):
        qc = score_anchored(camera(), label(camera(), scene, POINTS, "careful"), scene, 0)
        assert qc.metrics["landmark_separation_mm"] == pytest.approx(
            1000.0 * np.linalg.norm(POINTS[1] - POINTS[0]), abs=4.0)
        assert qc.metrics["anchored_facing"] > 0.8
        assert qc.metrics["anchored_shown_fraction"] == 1.0

    def test_two_landmarks_on_one_spot_follow_the_object_but_mark_one_point(self, scene):
        qc = score_anchored(camera(), label(camera(), scene, POINTS, "same_spot", 5), scene, 0)
        # As close to their anchor as careful work: the track alone cannot tell.
        assert qc.metrics["anchored_median_px"] < 3.0
        assert qc.metrics["landmark_separation_mm"] < 5.0


class TestDecision:
    def test_thresholds_hold_the_minimum_separation_setting(self):
        thresholds = learn_thresholds([], QCThresholds(landmark_min_separation_mm=22.0))
        assert thresholds["landmark_separation_mm.reject_below"] == 22.0
        assert learn_thresholds([])["landmark_separation_mm.reject_below"] == 15.0

    def test_one_spot_is_rejected_and_careful_work_approved(self, scene):
        thresholds = learn_thresholds([])
        names = ["landmark 1", "landmark 2"]
        careful = score_anchored(camera(), label(camera(), scene, POINTS, "careful"), scene, 0)
        assert decide(careful, thresholds, names).outcome == "approve"
        one_spot = score_anchored(camera(), label(camera(), scene, POINTS, "same_spot", 5),
                                  scene, 0)
        decision = decide(one_spot, thresholds, names)
        assert decision.outcome == "reject"
        assert any(r.startswith("landmark_separation_mm") for r in decision.reasons)
        assert "at least 15 mm apart" in decision.feedback


class TestSimulatedObjectWorkers:
    def test_careful_workers_pick_points_well_apart_where_the_view_allows(self):
        grid = np.array([[x, 0.0, z] for x in np.linspace(-0.05, 0.05, 11)
                         for z in np.linspace(-0.05, 0.05, 11)])
        rng = np.random.default_rng(0)
        for _ in range(20):
            ids = distinct_points(grid, np.arange(len(grid)), 2, LANDMARK_SEPARATION_M, rng)
            assert np.linalg.norm(grid[ids[0]] - grid[ids[1]]) >= LANDMARK_SEPARATION_M

    def test_a_small_side_gives_the_farthest_point_there_is(self):
        points = np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 0.0], [0.012, 0.0, 0.0]])
        ids = distinct_points(points, np.arange(3), 2, LANDMARK_SEPARATION_M,
                              np.random.default_rng(1))
        assert sorted(ids.tolist()) in ([0, 2], [1, 2]) or ids[0] == 2

    def test_same_spot_puts_both_landmarks_on_the_first_ones_track(self):
        xy = np.stack([np.linspace([100.0, 100.0], [200.0, 150.0], 24),
                       np.linspace([300.0, 200.0], [320.0, 260.0], 24)], axis=1)
        work = annotate(xy, np.ones((24, 2), bool), (640, 480), "same_spot",
                        np.random.default_rng(2))
        first, second = (np.array([row[1:3] for row in t], float) for t in work.tracks)
        assert np.linalg.norm(first - second, axis=1).max() < 15.0
        assert np.linalg.norm(second - xy[[row[0] for row in work.tracks[1]], 0],
                              axis=1).max() < 10.0

    def test_object_crowds_draw_one_spot_work_and_hand_crowds_do_not(self):
        rng = np.random.default_rng(3)
        assert "same_spot" in set(draw_profiles(400, "mixed", rng, "object"))
        assert set(draw_profiles(400, "mixed", rng)) == set(PROFILES)
        assert set(OBJECT_PROFILES) - set(PROFILES) == {"same_spot"}


def test_careful_workers_pick_distinct_points_in_plain_view_on_a_rendered_box():
    import cv2

    from backend.captures.truth import surface_points
    from worker.synth.annotators import PLAIN_VIEW_COS, mesh_landmarks, vertex_normals

    cam = camera()
    vertices, faces = surface_points(*box())
    still = np.repeat(np.eye(3, 4)[None], 3, axis=0)
    hull = cv2.convexHull(cam.project(vertices).astype(np.float32)).astype(np.int32)
    seg = np.zeros((3, 480, 640), np.uint8)
    for frame in seg:
        cv2.fillConvexPoly(frame, hull, 7)
    normals = vertex_normals(vertices, faces)
    towards = cam.T_cam_to_world[:, 3] - vertices
    cosine = np.einsum("ni,ni->n", normals, towards) / np.linalg.norm(towards, axis=1)
    for seed in range(10):
        _, visible, ids = mesh_landmarks(cam, seg, 7, vertices, faces, still,
                                         np.random.default_rng(seed))
        assert visible.all()
        assert (cosine[ids] >= PLAIN_VIEW_COS).all(), cosine[ids]
        assert np.linalg.norm(vertices[ids[0]] - vertices[ids[1]]) >= LANDMARK_SEPARATION_M
