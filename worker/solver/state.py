"""The solver's current estimate of a sequence, and the diagnostics computed from it.

World frame, metres; errors in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from worker.solver.depth import Matches
from worker.solver.mapping import HandAt
from worker.solver.problem import MappedLandmarks, Problem
from worker.solver.triangulate import reprojection_px


def hand_vertices_world(problem: Problem, pose_m: np.ndarray) -> np.ndarray:
    """(B, V, 3) world vertices of the subject's hand for pose_m (B, 51)."""
    with torch.no_grad():
        _, vertices = problem.require_subject().pose(problem.tensor(pose_m))
    return vertices.cpu().numpy()


@dataclass
class ObjectMotion:
    """One object's motion over F frames: rest (F,) bool, at its initial pose; held (F,) bool,
    moving with the hand; prior (F, 3, 4) object-to-world the hand's grip predicts (NaN where
    none); grip (3, 4) the object's pose in the palm's frame while held (None: no hand)."""

    rest: np.ndarray
    held: np.ndarray
    prior: np.ndarray
    grip: np.ndarray | None = None


@dataclass
class SolveState:
    """hand_pose: (F, 51) pose_m (meaningful on hand_frames only); hand_frames: (B,) labelled
    frame ids; object_poses: (O, F, 3, 4) object-to-world; landmarks: per object, per landmark
    vertex id (-1 unmapped); tables: per object the mapped landmarks as arrays; motion: per
    object where it rests and where it is held (the default optimiser's; empty otherwise)."""

    hand_pose: np.ndarray
    hand_frames: np.ndarray
    object_poses: np.ndarray
    landmarks: list[list[int]]
    tables: list[MappedLandmarks]
    matches: list[Matches | None] | None = None
    motion: list[ObjectMotion] = field(default_factory=list)

    @classmethod
    def empty(cls, problem: Problem) -> SolveState:
        frames = problem.num_frames
        count = len(problem.objects)
        poses = np.zeros((count, frames, 3, 4))
        if count:
            poses[:] = problem.initial_poses[:, None]
        return cls(np.zeros((frames, 51)), np.flatnonzero(problem.labelled), poses,
                   [[-1] * len(o.landmarks) for o in problem.objects],
                   [MappedLandmarks() for _ in problem.objects])

    def joints(self, problem: Problem) -> np.ndarray:
        """(B, 21, 3) joints of the labelled frames, world metres."""
        with torch.no_grad():
            pose = problem.tensor(self.hand_pose[self.hand_frames])
            joints, _ = problem.require_subject().pose(pose, pose.new_zeros(0).long())
        return joints.cpu().numpy()

    def hand_errors(self, problem: Problem) -> np.ndarray:
        """(V, B, 21) reprojection error px of the labelled frames' joints, NaN where the joint
        is not labelled visible."""
        frames = self.hand_frames
        errors = reprojection_px(problem.cameras, self.joints(problem),
                                 problem.keypoints[:, frames])
        return np.where(problem.gamma[:, frames], errors, np.nan)

    def landmark_errors(self, problem: Problem, index: int, marks: MappedLandmarks
                        ) -> np.ndarray:
        """(F, L) reprojection error px of object `index`'s mapped landmarks, NaN if unseen."""
        poses = self.object_poses[index]
        model = problem.object_vertices[index][marks.vertices]  # (L, 3)
        world = np.einsum("fij,lj->fli", poses[:, :, :3], model) + poses[:, None, :, 3]
        errors = np.stack([reprojection_px([problem.cameras[v]], world[:, k],
                                           marks.xy[:, k][None])[0]
                           for k, v in enumerate(marks.views)], axis=1)
        return np.where(marks.gamma, errors, np.nan)

    def hand_at(self, problem: Problem) -> HandAt:
        """frame -> (V, 3) world hand vertices where the frame is labelled, else None."""
        labelled = {int(f) for f in self.hand_frames}
        cache: dict[int, np.ndarray] = {}

        def at(frame: int) -> np.ndarray | None:
            if problem.subject is None or frame not in labelled:
                return None
            if frame not in cache:
                cache[frame] = hand_vertices_world(problem, self.hand_pose[frame][None])[0]
            return cache[frame]

        return at

    def match_all(self, problem: Problem) -> list[Matches | None]:
        """Depth matches of every frame against the current meshes."""
        hand = None
        if problem.subject is not None and len(self.hand_frames):
            hand = dict(zip(self.hand_frames.tolist(),
                            hand_vertices_world(problem, self.hand_pose[self.hand_frames]),
                            strict=True))
        out = []
        for f in range(problem.num_frames):
            verts = hand.get(f) if hand is not None else None
            out.append(problem.match_depth(f, verts, self.object_poses[:, f]))
        return out

    def depth_rms_mm(self, problem: Problem) -> np.ndarray:
        """(F,) RMS distance, mm, of each frame's matched depth points to the point their match
        names on the final meshes (an upper bound of the true distance, without re-matching);
        NaN where a frame has no matches."""
        matches = self.matches if self.matches is not None else self.match_all(problem)
        hand = {}
        if problem.subject is not None and len(self.hand_frames):
            hand = dict(zip(self.hand_frames.tolist(),
                            hand_vertices_world(problem, self.hand_pose[self.hand_frames]),
                            strict=True))
        out = np.full(problem.num_frames, np.nan)
        for f, m in enumerate(matches):
            if m is None or not len(m.mesh):
                continue
            meshes = [(v @ p[:, :3].T + p[:, 3], faces) for v, faces, p in zip(
                problem.object_vertices, problem.object_faces, self.object_poses[:, f],
                strict=True)]
            if f in hand:
                meshes.append((hand[f], problem.hand_faces))
            near = np.zeros_like(m.points)
            for i, (verts, faces) in enumerate(meshes):
                sel = m.mesh == i
                near[sel] = np.einsum("ni,nij->nj", m.bary[sel], verts[faces[m.face[sel]]])
            out[f] = float(np.sqrt(np.mean(((m.points - near) ** 2).sum(1))) * 1000.0)
        return out
