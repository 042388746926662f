"""Landmark mapping over a sequence: which frames' poses are trusted, and the result as
`MappedLandmarks` tables for the energies. A mapped landmark is a surface point of its object,
kept as an extra vertex of the object (after the mesh's own, referenced by no face). See
`landmarks` for the ray casting itself."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from worker.solver.landmarks import Scene, map_landmark
from worker.solver.problem import MappedLandmarks, Problem

PosesAt = Callable[[int], np.ndarray | None]  # frame -> (O, 3, 4) trusted poses, or None
HandAt = Callable[[int], np.ndarray | None]  # frame -> (N, 3) hand vertices, or None


def map_landmarks(problem: Problem, state: list[list[int]], poses_at: PosesAt,
                  hand_at: HandAt) -> list[list[int]]:
    """Fill in the vertex id of every landmark still at -1 in `state` (per object, per landmark)
    whose first visible frames have trusted poses (a new extra vertex at its surface point);
    the others stay -1 for a later call."""
    meshes = list(zip(problem.object_vertices, problem.object_faces, strict=True))
    out = [list(s) for s in state]
    for o, obj in enumerate(problem.objects):
        for k, mark in enumerate(obj.landmarks):
            if out[o][k] >= 0:
                continue

            def scene_at(frame: int, o: int = o) -> Scene | None:
                poses = poses_at(frame)
                if poses is None:
                    return None
                posed = [(v @ p[:, :3].T + p[:, 3], f)
                         for (v, f), p in zip(meshes, poses, strict=True)]
                occluders = posed[:o] + posed[o + 1:]
                hand = hand_at(frame)
                if hand is not None:
                    occluders.append((hand, problem.hand_faces))
                return posed[o], occluders

            point, frame = map_landmark(problem.cameras[mark.view], np.asarray(mark.xy, float),
                                        np.asarray(mark.visible, bool), scene_at)
            # A point was found at `frame` only if scene_at had poses there.
            poses = poses_at(frame) if point is not None else None
            if point is not None and poses is not None:
                pose = poses[o]
                out[o][k] = problem.add_landmark_point(o, (point - pose[:, 3]) @ pose[:, :3])
    return out


def mapped_table(problem: Problem, index: int, vertices: list[int]) -> MappedLandmarks:
    """The mapped landmarks of object `index` (vertex >= 0) as arrays."""
    marks = problem.objects[index].landmarks
    keep = [k for k, v in enumerate(vertices) if v >= 0]
    if not keep:
        return MappedLandmarks()
    xy = np.stack([np.asarray(marks[k].xy, np.float64) for k in keep], axis=1)  # (F, L, 2)
    gamma = np.stack([np.asarray(marks[k].visible, bool) for k in keep], axis=1)
    gamma &= np.isfinite(xy).all(-1)
    return MappedLandmarks(np.array([marks[k].view for k in keep], np.int64),
                           np.array([vertices[k] for k in keep], np.int64), xy, gamma)
