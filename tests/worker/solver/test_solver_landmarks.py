"""Landmark-to-vertex mapping by back-projection onto the visible surface."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.solver.test_solver_scene import box, cameras, pose
from worker.solver.landmarks import back_project, back_project_point, camera_ray, map_landmark
from worker.solver.mesh_query import ray_hits


def _posed(vertices, faces, p):
    return vertices @ p[:, :3].T + p[:, 3], faces


def _front_vertices(camera, vertices, faces, count):
    """Vertices the camera sees first along their own ray (not on a silhouette edge)."""
    centre = camera.T_cam_to_world[:, 3]
    out = []
    for vid in range(len(vertices)):
        direction = vertices[vid] - centre
        distance = np.linalg.norm(direction)
        hits = ray_hits(centre, direction / distance, vertices[faces])
        if np.isfinite(hits).any() and abs(hits.min() - distance) < 1e-9:
            out.append(vid)
    assert len(out) >= count
    return out[:count]


class TestBackProjection:
    def test_projected_vertex_maps_back_to_itself_through_distortion(self):
        cams = cameras(4)
        vertices, faces = _posed(*box(), pose([0.2, -0.1, 0.3], [0.01, -0.02, 0.0]))
        checked = 0
        for camera in cams:
            for vid in _front_vertices(camera, vertices, faces, 6):
                xy = camera.project(vertices[vid])
                assert back_project(camera, xy, (vertices, faces), []) == vid
                checked += 1
        assert checked == 24

    def test_ray_passes_through_the_pixel(self):
        camera = cameras(2)[1]  # a distorted camera
        point = np.array([0.01, 0.02, 0.03])
        origin, direction = camera_ray(camera, camera.project(point))
        offset = point - origin
        assert np.linalg.norm(offset - (offset @ direction) * direction) < 1e-9

    def test_occluded_landmark_is_not_mapped_to_the_hidden_object(self):
        camera = cameras(1)[0]
        target = _posed(*box(), pose([0, 0, 0], [0, 0, 0]))
        centre = camera.T_cam_to_world[:, 3]
        blocker = _posed(*box((0.05, 0.05, 0.05)), pose([0, 0, 0], 0.5 * centre))
        vid = _front_vertices(camera, *target, 1)[0]
        xy = camera.project(target[0][vid])
        assert back_project(camera, xy, target, [blocker]) == -1
        assert back_project(camera, xy, target, []) == vid

    def test_label_just_off_the_silhouette_still_maps_to_the_near_corner(self):
        camera = cameras(1)[0]
        vertices, faces = _posed(*box(steps=1), pose([0.3, 0.2, 0.1], [0, 0, 0]))
        projected = camera.project(vertices)
        corner = int(np.argmax(projected[:, 0]))  # the right-most corner is on the silhouette
        xy = projected[corner] + np.array([0.3, 0.0])
        assert back_project(camera, xy, (vertices, faces), []) == corner


class TestMapLandmark:
    def test_uses_the_first_visible_frame_with_a_known_pose(self):
        camera = cameras(1)[0]
        model, faces = box()
        poses = [pose([0, 0, 0.1 * f], [0.01 * f, 0, 0]) for f in range(4)]
        posed = [_posed(model, faces, p) for p in poses]
        vid = _front_vertices(camera, *posed[2], 1)[0]
        xy = np.full((4, 2), np.nan)
        xy[2:] = [camera.project(posed[f][0][vid]) for f in (2, 3)]
        visible = np.array([False, False, True, True])
        asked = []

        def scene_at(frame):
            asked.append(frame)
            return posed[frame], []

        point, frame = map_landmark(camera, xy, visible, scene_at)
        assert frame == 2 and np.allclose(point, posed[2][0][vid], atol=1e-9)
        assert asked == [2]

    @pytest.mark.parametrize("known", [None, 3])
    def test_skips_frames_without_a_trusted_pose(self, known):
        camera = cameras(1)[0]
        model, faces = box()
        posed = _posed(model, faces, pose([0, 0, 0], [0, 0, 0]))
        vid = _front_vertices(camera, *posed, 1)[0]
        xy = np.repeat(camera.project(posed[0][vid])[None], 4, axis=0)
        point, frame = map_landmark(camera, xy, np.ones(4, bool),
                                    lambda f: (posed, []) if f == known else None)
        if known is None:
            assert (point, frame) == (None, -1)
        else:
            assert frame == 3 and np.allclose(point, posed[0][vid], atol=1e-9)


class TestSurfacePoint:
    def test_a_landmark_inside_a_face_maps_to_the_hit_point_not_a_corner(self):
        camera = cameras(1)[0]
        model, faces = box()
        posed = _posed(model, faces, pose([0, 0, 0], [0, 0, 0]))
        vid = _front_vertices(camera, *posed, 1)[0]
        # A point on the segment from a front corner towards the box's centre, on its surface.
        centre_ray = camera_ray(camera, camera.project(posed[0].mean(axis=0)))
        xy = 0.5 * camera.project(posed[0][vid]) + 0.5 * camera.project(
            centre_ray[0] + 0.5 * centre_ray[1])
        point = back_project_point(camera, xy, posed, [])
        assert point is not None and np.allclose(camera.project(point), xy, atol=1e-6)
        corners = np.linalg.norm(posed[0] - point, axis=1)
        assert corners.min() > 1e-3  # a corner would be the paper's vertex, millimetres away
