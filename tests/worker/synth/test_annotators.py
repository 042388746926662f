"""Simulated annotators: each profile's defining error, measured against a synthetic view."""

from __future__ import annotations

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix
from worker.synth.annotators import (
    LITTLE,
    PROFILES,
    RING,
    annotate,
    draw_profiles,
    follow_path,
    hand_visibility,
    mesh_landmarks,
    swap_window,
)
from worker.tracks.interpolate import dense_points

FRAMES, WIDTH, HEIGHT = 72, 640, 480
SIZE = (WIDTH, HEIGHT)


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """21 joints on a 5x5-ish grid moving 2 px right per frame, all visible: (F, 21, 2), (F, 21)."""
    grid = np.stack(np.meshgrid(np.arange(5), np.arange(5)), -1).reshape(-1, 2)[:21] * 25.0
    xy = grid[None] + np.array([150.0, 150.0]) + np.arange(FRAMES)[:, None, None] * [2.0, 0.0]
    return xy, np.ones((FRAMES, 21), dtype=bool)


def _rows(work) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(point index, frame, [x, y, visible]) of every keyframe row."""
    points, frames, values = [], [], []
    for p, rows in enumerate(work.tracks):
        for f, x, y, v in rows:
            points.append(p)
            frames.append(f)
            values.append([x, y, v])
    return np.array(points), np.array(frames), np.array(values, dtype=float)


def _errors(work, xy: np.ndarray) -> np.ndarray:
    points, frames, values = _rows(work)
    return np.linalg.norm(values[:, :2] - xy[frames, points], axis=1)


# The median of |N(0, sigma^2 I_2)| is sigma * sqrt(2 ln 2) ~ 1.18 sigma.
@pytest.mark.parametrize(("profile", "sigma"), [("careful", 2.0), ("sloppy", 8.0)])
def test_noise_profiles_have_their_median_error(profile: str, sigma: float) -> None:
    xy, vis = _scene()
    errors = _errors(annotate(xy, vis, SIZE, profile, np.random.default_rng(1)), xy)
    assert errors.size > 21 * 18
    assert abs(np.median(errors) / np.sqrt(2 * np.log(2)) - sigma) < 0.2 * sigma


def test_keyframes_every_fourth_frame_plus_last_inside_image() -> None:
    xy, vis = _scene()
    work = annotate(xy, vis, SIZE, "careful", np.random.default_rng(2))
    assert len(work.tracks) == 21
    assert [row[0] for row in work.tracks[0]] == [*range(0, FRAMES, 4), FRAMES - 1]
    _, _, values = _rows(annotate(xy * 10, vis, SIZE, "sloppy", np.random.default_rng(2)))
    assert values[:, 0].min() >= 0 and values[:, 0].max() < WIDTH
    assert values[:, 1].min() >= 0 and values[:, 1].max() < HEIGHT


def test_swapper_exchanges_ring_and_little_in_its_window_only() -> None:
    xy, vis = _scene()
    work = annotate(xy, vis, SIZE, "swapper", np.random.default_rng(3))
    lo, hi = swap_window(FRAMES)
    assert (lo, hi) == (20, 45)
    points, frames, values = _rows(work)
    inside = (frames >= lo) & (frames <= hi)
    for ring, little in zip(RING, LITTLE, strict=True):
        sel = (points == ring) & inside
        assert sel.sum() >= 7
        assert np.median(np.linalg.norm(values[sel, :2] - xy[frames[sel], little], axis=1)) < 4
        out = (points == ring) & ~inside
        assert np.median(np.linalg.norm(values[out, :2] - xy[frames[out], ring], axis=1)) < 4
    wrist = points == 0
    assert np.median(np.linalg.norm(values[wrist, :2] - xy[frames[wrist], 0], axis=1)) < 4


def test_lazy_worker_copies_one_frame_so_nothing_moves() -> None:
    xy, vis = _scene()
    points, _, values = _rows(annotate(xy, vis, SIZE, "lazy", np.random.default_rng(4)))
    for p in range(21):
        assert np.ptp(values[points == p, :2], axis=0).max() == 0
    assert np.ptp(xy[:, 0, 0]) > 100  # while the true hand moves


def test_spammer_is_far_off() -> None:
    xy, vis = _scene()
    errors = _errors(annotate(xy, vis, SIZE, "spammer", np.random.default_rng(5)), xy)
    assert np.median(errors) > 100


def test_occluder_marks_visible_joints_occluded_over_long_spans() -> None:
    xy, vis = _scene()
    _, _, careful = _rows(annotate(xy, vis, SIZE, "careful", np.random.default_rng(6)))
    assert careful[:, 2].min() == 1
    work = annotate(xy, vis, SIZE, "occluder", np.random.default_rng(6))
    for rows in work.tracks:
        hidden = [f for f, _, _, v in rows if v == 0]
        assert hidden and hidden[-1] - hidden[0] >= 0.5 * FRAMES


@pytest.mark.parametrize("profile", PROFILES)
def test_same_seed_same_tracks(profile: str) -> None:
    xy, vis = _scene()
    first = annotate(xy, vis, SIZE, profile, np.random.default_rng(7))
    again = annotate(xy, vis, SIZE, profile, np.random.default_rng(7))
    other = annotate(xy, vis, SIZE, profile, np.random.default_rng(8))
    assert first == again and first.profile == profile
    assert first.tracks != other.tracks


def test_mixed_draws_half_careful_and_every_profile() -> None:
    names = draw_profiles(2000, "mixed", np.random.default_rng(9))
    assert set(names) == set(PROFILES)
    assert abs(names.count("careful") / 2000 - 0.5) < 0.05
    assert draw_profiles(3, "lazy", np.random.default_rng(0)) == ["lazy"] * 3
    with pytest.raises(ValueError, match="unknown profile"):
        draw_profiles(1, "perfect", np.random.default_rng(0))


def test_visibility_hand_and_background_visible_object_covered() -> None:
    seg = np.zeros((1, 40, 40), dtype=np.uint8)
    seg[0, 0:20, 0:20] = 255
    seg[0, 20:40, 20:40] = 7
    joints = np.array([[[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [-5.0, 10.0]]])
    assert hand_visibility(joints, seg).tolist() == [[True, True, False, False]]
    with pytest.raises(ValueError, match=r"\(F, P, 2\)"):
        hand_visibility(joints[0], seg)


def _box() -> tuple[np.ndarray, np.ndarray]:
    """A 10 cm cube's 8 corners and 12 triangles, outward facing, object frame in metres."""
    v = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (-0.05, 0.05)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(faces)


def _cube_view(frames: int) -> tuple[CameraModel, np.ndarray, np.ndarray]:
    """A camera, the cube's poses sliding 1 cm per frame, and its (F, H, W) silhouette."""
    camera = CameraModel(intrinsics_matrix(300.0, 300.0, 80.0, 60.0), None, np.eye(3, 4), 160, 120)
    poses = np.stack([np.hstack([np.eye(3), [[0.01 * f], [0.0], [0.6]]]) for f in range(frames)])
    v, _ = _box()
    seg = np.zeros((frames, 120, 160), np.uint8)
    for f in range(frames):
        px = camera.project(v + poses[f, :, 3])
        lo, hi = np.floor(px.min(0)).astype(int), np.ceil(px.max(0)).astype(int)
        seg[f, lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] = 4
    return camera, poses, seg


def test_mesh_landmarks_are_visible_vertices_carried_by_the_true_motion() -> None:
    camera, poses, seg = _cube_view(4)
    v, faces = _box()
    xy, visible, ids = mesh_landmarks(camera, seg, 4, v, faces, poses, np.random.default_rng(0))
    assert xy.shape == (4, 2, 2) and visible.all() and len(set(ids.tolist())) == 2
    assert (v[ids][:, 2] < 0).all()  # corners on the face towards the camera
    truth = np.stack([camera.project(v[ids] + poses[f, :, 3]) for f in range(4)])
    assert np.allclose(xy, truth)


def test_mesh_landmarks_wait_for_a_frame_that_shows_points_far_apart() -> None:
    # Frame 0 shows only the cube's left edge (two front corners 10 cm apart); from frame 1 on
    # the whole front face, whose diagonal corners are 14 cm apart. Asked for 12 cm, the worker
    # picks a diagonal pair on frame 1 and labels it back to frame 0, where one of the two is
    # hidden; on frame 0 alone it would have taken the 10 cm pair.
    camera, poses, seg = _cube_view(4)
    seg[0, :, 81:] = 0
    v, faces = _box()
    xy, visible, ids = mesh_landmarks(camera, seg, 4, v, faces, poses, np.random.default_rng(0),
                                      separation_m=0.12)
    assert np.linalg.norm(v[ids[0]] - v[ids[1]]) > 0.12
    assert (v[ids][:, 2] < 0).all()
    assert np.isfinite(xy).all()
    assert visible[1:].all() and visible[0].sum() == 1
    _, _, first_ids = mesh_landmarks(camera, seg[:1], 4, v, faces, poses[:1],
                                     np.random.default_rng(0), separation_m=0.12)
    assert np.linalg.norm(v[first_ids[0]] - v[first_ids[1]]) == pytest.approx(0.1)


def test_mesh_landmarks_take_the_spots_the_suggestions_mark() -> None:
    camera, poses, seg = _cube_view(4)
    v, faces = _box()
    _, _, own = mesh_landmarks(camera, seg, 4, v, faces, poses, np.random.default_rng(0))
    # The page suggests two other corners of the face the camera sees, one frame's suggestion
    # 15 px off (a check cell): the worker follows those corners, not its own pick.
    other = [i for i in range(len(v)) if v[i, 2] < 0 and i not in own.tolist()][:2]
    suggested = np.stack([camera.project(v[other] + poses[f, :, 3]) for f in range(4)])
    suggested[2, 0] += [15.0, 0.0]
    xy, visible, ids = mesh_landmarks(camera, seg, 4, v, faces, poses,
                                      np.random.default_rng(0),
                                      shown=(suggested, np.ones((4, 2), bool)))
    assert ids.tolist() == other and visible.all()
    assert np.allclose(xy, np.stack([camera.project(v[other] + poses[f, :, 3])
                                     for f in range(4)]))
    # Suggestions that mark no spot (far from every corner) leave the worker its own pick.
    _, _, ids = mesh_landmarks(camera, seg, 4, v, faces, poses, np.random.default_rng(0),
                               shown=(suggested + 40.0, np.ones((4, 2), bool)))
    assert ids.tolist() == own.tolist()


def test_object_never_shown_is_marked_occluded_without_positions() -> None:
    camera, poses, _ = _cube_view(5)
    v, faces = _box()
    seg = np.zeros((5, 120, 160), np.uint8)
    points, visible, ids = mesh_landmarks(camera, seg, 9, v, faces, poses,
                                          np.random.default_rng(0))
    assert np.isnan(points).all() and not visible.any() and (ids == -1).all()
    work = annotate(points, visible, (160, 120), "careful", np.random.default_rng(0))
    assert work.tracks[0] == [[0, None, None, 0], [4, None, None, 0]]


def _circling(frames: int = 24, radius: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """21 joints circling once in ``frames`` frames (a fast hand): (F, 21, 2), (F, 21)."""
    angle = 2 * np.pi * np.arange(frames) / frames
    centre = np.array([320.0, 240.0]) + np.arange(21)[:, None] * [3.0, 0.0]
    xy = centre[None] + radius * np.stack([np.cos(angle), np.sin(angle)], -1)[:, None, :]
    return xy, np.ones((frames, 21), dtype=bool)


def _interpolation_errors(work, xy: np.ndarray) -> np.ndarray:
    """(F, P) px distance of the worker's interpolated track from the truth."""
    dense, _ = dense_points(enumerate(work.tracks), xy.shape[0], xy.shape[1])
    return np.linalg.norm(dense - xy, axis=-1)


def test_follow_path_keys_until_the_line_follows_the_path() -> None:
    xy, vis = _circling()
    keys = follow_path(xy[:, 0], vis[:, 0], [0, 23], tolerance_px=2.0)
    dense = np.stack([np.interp(np.arange(24), keys, xy[keys, 0, k]) for k in (0, 1)], -1)
    assert np.linalg.norm(dense - xy[:, 0], axis=1).max() <= 2.0
    # A straight path needs nothing more than its ends.
    line = np.stack([np.arange(24.0), np.zeros(24)], -1)
    assert follow_path(line, np.ones(24, bool), [0, 23]) == [0, 23]


def test_careful_worker_walks_a_fast_path_and_sloppy_keys_every_fourth() -> None:
    xy, vis = _circling()
    careful = annotate(xy, vis, SIZE, "careful", np.random.default_rng(11))
    errors = _interpolation_errors(careful, xy)
    # Keyed every 4th frame, the chord of a 60 deg arc of 60 px leaves 8 px in between.
    assert np.median(errors) < 3.0 and np.percentile(errors, 95) < 6.0
    sloppy = annotate(xy, vis, SIZE, "sloppy", np.random.default_rng(11))
    assert [row[0] for row in sloppy.tracks[0]] == [*range(0, 24, 4), 23]


def test_keys_added_where_the_path_bends_do_not_shake_against_their_neighbours() -> None:
    xy, vis = _circling()
    shakes = []
    for seed in range(10):
        work = annotate(xy, vis, SIZE, "careful", np.random.default_rng(seed))
        noise = dense_points(enumerate(work.tracks), 24, 21)[0] - xy
        shakes.append(noise[2:] - 2 * noise[1:-1] + noise[:-2])
        assert 0.8 < np.abs(noise).mean() < 2.5
    # Independent 2 px noise on every frame would shake by sqrt(6) * 2 = 4.9 px per axis.
    assert np.std(shakes) < 3.0
