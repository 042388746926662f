from __future__ import annotations

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel
from worker.hand import JOINT_NAMES, builtin_hand_model
from worker.overlay import (
    DARKEN,
    FLAGGED_COLOUR,
    HAND_PART_COLOURS,
    OBJECT_COLOURS,
    OverlayMesh,
    caption,
    hand_part_of_vertices,
    object_mesh,
    render_overlay,
    residual_plot,
    short_joint_labels,
)

W, H = 160, 120


def _camera(dist=None) -> CameraModel:
    K = np.array([[150.0, 0, 80.0], [0, 150.0, 60.0], [0, 0, 1.0]])
    return CameraModel(K=K, dist=dist, T_cam_to_world=np.hstack([np.eye(3), np.zeros((3, 1))]),
                       width=W, height=H)


def _cube(half: float) -> tuple[np.ndarray, np.ndarray]:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return corners * half, faces


def _pose(x: float, y: float, z: float) -> np.ndarray:
    return np.hstack([np.eye(3), [[x], [y], [z]]])


def _image() -> np.ndarray:
    return np.random.default_rng(0).integers(60, 200, (H, W, 3), dtype=np.uint8)


def test_overlay_darkens_the_frame_and_draws_the_object_only_where_it_projects() -> None:
    image, camera = _image(), _camera()
    verts, faces = _cube(0.05)
    out = render_overlay(image, camera, [object_mesh(verts, faces, _pose(0, 0, 1.0), 0)])
    dark = (image.astype(np.float32) * DARKEN).astype(np.uint8)
    assert out.shape == image.shape and out.dtype == np.uint8
    # The cube's front face spans 150 * 0.05 / 0.95 = 7.9 px either side of the centre.
    changed = np.any(out.astype(int) != dark.astype(int), axis=2)
    ys, xs = np.nonzero(changed)
    assert abs(xs.mean() - 80) < 1.0 and abs(ys.mean() - 60) < 1.0
    assert 6 <= xs.max() - 80 <= 9 and 6 <= 80 - xs.min() <= 9
    assert (out[0:30, 0:30] == dark[0:30, 0:30]).all()
    centre = out[60, 80].astype(float)
    blue_dominant = np.argmax(OBJECT_COLOURS[0])
    assert np.argmax(centre) == blue_dominant


def test_a_flagged_object_is_drawn_in_the_flag_colour_and_its_reason_written() -> None:
    vertices, faces = _cube(0.05)
    own = object_mesh(vertices, faces, _pose(0, 0, 0.5), 1)
    flagged = object_mesh(vertices, faces, _pose(0, 0, 0.5), 1, flagged=True)
    assert (own.colours == OBJECT_COLOURS[1]).all() and (flagged.colours == FLAGGED_COLOUR).all()
    picture = render_overlay(_image(), _camera(), [flagged])
    centre = picture[H // 2, W // 2].astype(float)
    assert centre[2] > centre[0] + 40 and centre[2] > centre[1] + 40  # red (BGR) dominates
    written = caption(picture, ["not trusted: grasped object 'box' seen by 1 view"])
    assert written.shape == picture.shape and (written[:24] != picture[:24]).any()
    assert (written[40:] == picture[40:]).all()


def test_the_nearer_mesh_hides_the_farther_one() -> None:
    image, camera = _image(), _camera()
    verts, faces = _cube(0.05)
    near = object_mesh(verts * 0.4, faces, _pose(0, 0, 0.8), 1)
    far = object_mesh(verts, faces, _pose(0, 0, 1.2), 0)
    for order in ([near, far], [far, near]):
        out = render_overlay(image, camera, order).astype(float)
        near_colour = OBJECT_COLOURS[1]
        # Yellowish (B low) in the middle from the near cube; the far cube's edge is bluish.
        assert np.argmin(out[60, 80]) == np.argmin(near_colour)
        assert np.argmax(out[60, 80 + 5]) == np.argmax(OBJECT_COLOURS[0])


def test_lens_distortion_moves_the_drawing_where_the_lens_projects() -> None:
    image = _image()
    dist = np.array([1.0, 0.0, 0.0, 0.0, 0.0])
    verts, faces = _cube(0.02)
    centre_world = np.array([0.3, 0.2, 1.0])
    mesh = object_mesh(verts, faces, _pose(*centre_world), 0)
    plain = render_overlay(image, _camera(), [mesh])
    lens = render_overlay(image, _camera(dist), [mesh])
    dark = (image.astype(np.float32) * DARKEN).astype(np.uint8)
    expected = _camera(dist).project(centre_world[None])[0]
    for out, where in ((lens, expected), (plain, _camera().project(centre_world[None])[0])):
        ys, xs = np.nonzero(np.any(out != dark, axis=2))
        assert abs(xs.mean() - where[0]) < 1.5 and abs(ys.mean() - where[1]) < 1.5
    assert expected[0] - _camera().project(centre_world[None])[0][0] > 3.0


def test_hand_parts_cover_the_palm_and_all_five_fingers() -> None:
    model = builtin_hand_model("right")
    parts = hand_part_of_vertices(model.weights)
    assert parts.shape == (model.v_template.shape[0],)
    assert set(np.unique(parts)) == set(range(len(HAND_PART_COLOURS)))
    tips = np.asarray(model.tip_vertex_ids)
    assert parts[tips].tolist() == [1, 2, 3, 4, 5]


def test_meshes_behind_the_camera_or_none_leave_just_the_darkened_frame() -> None:
    image, camera = _image(), _camera()
    verts, faces = _cube(0.05)
    dark = (image.astype(np.float32) * DARKEN).astype(np.uint8)
    behind = object_mesh(verts, faces, _pose(0, 0, -1.0), 0)
    assert (render_overlay(image, camera, [behind]) == dark).all()
    empty = OverlayMesh(np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, 3)))
    assert (render_overlay(image, camera, [empty]) == dark).all()


def test_wireframe_draws_the_cube_s_outline_and_visible_edges_one_pixel_wide() -> None:
    image, camera = _image(), _camera()
    verts, faces = _cube(0.05)
    mesh = object_mesh(verts, faces, _pose(0, 0, 1.0), 0)
    dark = (image.astype(np.float32) * DARKEN).astype(np.uint8)
    solid = np.any(render_overlay(image, camera, [mesh]) != dark, axis=2)
    out = render_overlay(image, camera, [mesh], style="wireframe")
    wire = np.any(out != dark, axis=2)
    # Only the front face shows: a square 8 px either side of (80, 60) split by a diagonal.
    assert wire.sum() < 0.6 * solid.sum() and (wire <= solid).all()
    ys, xs = np.nonzero(solid)
    top, left, bottom, right = ys.min(), xs.min(), ys.max(), xs.max()
    assert wire[top, left:right + 1].all() and wire[bottom, left:right + 1].all()
    assert wire[top:bottom + 1, left].all() and wire[top:bottom + 1, right].all()
    inside = wire[top + 2:bottom - 1, left + 2:right - 1]
    assert 0 < inside.sum() <= 2 * inside.shape[0]  # the diagonal, about one pixel per row
    # Lines take the object's own colour at full opacity by default.
    assert (out[top, left + 4] == OBJECT_COLOURS[0].astype(np.uint8)).all()
    # Between the lines the frame is untouched.
    hollow = solid & ~wire
    assert hollow.sum() > wire.sum() and (out[hollow] == dark[hollow]).all()


def test_blend_lets_the_frame_through_by_its_alpha_and_alpha_zero_draws_nothing() -> None:
    image, camera = _image(), _camera()
    verts, faces = _cube(0.05)
    mesh = object_mesh(verts, faces, _pose(0, 0, 1.0), 0)
    dark = (image.astype(np.float32) * DARKEN).astype(np.uint8)
    solid = render_overlay(image, camera, [mesh]).astype(float)
    half = render_overlay(image, camera, [mesh], style="blend").astype(float)
    assert (render_overlay(image, camera, [mesh], style="blend", alpha=0.0) == dark).all()
    drawn = np.any(solid != dark, axis=2)
    # blend = 0.5 shade + 0.5 frame, solid = 0.85 shade + 0.15 frame: same shade from both.
    shade_solid = (solid[drawn] - 0.15 * dark[drawn]) / 0.85
    shade_half = (half[drawn] - 0.5 * dark[drawn]) / 0.5
    assert np.abs(shade_solid - shade_half).max() < 3.0
    for style, alpha in (("outline", None), ("solid", 1.5)):
        with pytest.raises(ValueError, match=r"style must be one of|alpha must be within"):
            render_overlay(image, camera, [mesh], style=style, alpha=alpha)  # type: ignore[arg-type]


def test_overlay_refuses_an_image_of_the_wrong_size() -> None:
    with pytest.raises(ValueError, match=r"\(120, 160, 3\) uint8, got \(100, 160, 3\)"):
        render_overlay(np.zeros((100, 160, 3), np.uint8), _camera(), [])


def test_residual_bars_are_as_tall_as_the_error_and_missing_ones_are_not_drawn() -> None:
    errors = np.full((2, 21), np.nan)
    errors[0, 0] = 10.0  # the axis top is 10 px: a full-height bar
    errors[1, 0] = 5.0
    plot = residual_plot(errors, ["cam0", "cam1"], short_joint_labels(JOINT_NAMES),
                         width=1000, height=380)
    assert plot.shape == (380, 1000, 3) and plot.dtype == np.uint8
    # Background and grid lines are grey levels 255 and 225; bars are coloured.
    white = np.all(plot == 255, axis=2) | np.all(plot == 225, axis=2)
    # Plot box: x 56..984 (group width ~44.2 px), y 40..316.
    column_v0, column_v1 = 56 + 8, 56 + 28
    full = np.flatnonzero(~white[:, column_v0])
    half = np.flatnonzero(~white[:, column_v1])
    assert abs(full[(full > 35) & (full < 317)].min() - 40) <= 2
    assert abs(half[(half > 35) & (half < 317)].min() - 178) <= 2
    # Joint 5 has no labels: only axis lines and the grey tick in its column.
    column = plot[45:312, 56 + int(44.2 * 5) + 10]
    assert (np.all(column == 255, axis=1) | np.all(column == 225, axis=1)).all()


def test_residual_plot_refuses_a_mismatched_error_array() -> None:
    with pytest.raises(ValueError, match=r"\(3, 21\), got \(2, 21\)"):
        residual_plot(np.zeros((2, 21)), ["a", "b", "c"], short_joint_labels(JOINT_NAMES))


def test_short_joint_labels_name_finger_and_joint() -> None:
    labels = short_joint_labels(JOINT_NAMES)
    assert labels[:6] == ["W", "T1", "T2", "T3", "T4", "I1"] and labels[-1] == "L4"
