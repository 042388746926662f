"""The solve problem as tensors: labels, weights, meshes and depth matches of a frame batch.

Both optimisers build their residuals from here, so the energy they minimise is the same
(see `energies`). World frame, metres; pixels; depth residuals in mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import torch

from worker.hand import HandLayer, builtin_hand_model
from worker.hand.params import check_side
from worker.hand.posing import SubjectHand
from worker.solver.depth import DepthClouds, Matches, crop_to_boxes, match_points, subsample
from worker.solver.energies import DepthData, HandData, ObjectData
from worker.solver.mesh_query import AABBTree
from worker.solver.projection import Rig
from worker.solver.surface import surface_samples
from worker.solver.types import SolveInputs, SolveSettings


@dataclass
class MappedLandmarks:
    """One object's landmarks that have a vertex: views (L,), vertex ids (L,), xy (F, L, 2) px,
    gamma (F, L) bool (labelled visible with a finite position). With no landmark (L = 0), xy
    and gamma are empty and have no frames either."""

    views: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))
    gamma: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))


def labelled_frames(gamma: np.ndarray, min_views: int, min_joints: int
                    ) -> tuple[np.ndarray, list[str | None]]:
    """(F,) bool and reasons: a frame counts if >= min_joints joints are labelled visible in
    >= min_views views each. gamma: (V, F, 21) bool."""
    seen = gamma.sum(axis=0) >= min_views  # (F, 21)
    count = seen.sum(axis=1)
    ok = count >= min_joints
    reasons = [None if good else f"only {int(c)} joints are labelled visible in at least "
               f"{min_views} views (need {min_joints})" for good, c in zip(ok, count, strict=True)]
    return ok, reasons


class Problem:
    """Everything the optimisers share, prepared once from the inputs."""

    def __init__(self, inputs: SolveInputs, settings: SolveSettings) -> None:
        self.settings = settings
        self.cameras = inputs.cameras
        self.num_frames = int(inputs.num_frames)
        self.device = torch.device(settings.device)
        self.rig = Rig(inputs.cameras, device=self.device)
        self.hand = inputs.hand
        self.objects = inputs.objects
        self.object_vertices = [np.asarray(o.vertices, np.float64) for o in inputs.objects]
        self.object_faces = [np.asarray(o.faces, np.int64) for o in inputs.objects]
        self.object_trees = [AABBTree.build(v, f)
                             for v, f in zip(self.object_vertices, self.object_faces, strict=True)]
        self.object_tensors = [self.tensor(v) for v in self.object_vertices]
        # (O, 3, 4) object-to-world at frame 0; (0, 3, 4) without objects.
        self.initial_poses = np.zeros((0, 3, 4))
        if inputs.objects:
            self.initial_poses = np.stack([np.asarray(o.initial_pose, np.float64)
                                           for o in inputs.objects])
        self.clouds = DepthClouds(inputs.cameras, inputs.depth, settings.depth_stride) \
            if settings.use_depth else None
        # Per view (F, H, W) uint16 mm for the surface checks; None without any depth.
        self.depth_images = list(inputs.depth) if settings.use_depth and any(
            d is not None for d in inputs.depth) else None
        self.object_samples = [surface_samples(v, f, seed=settings.seed)
                               for v, f in zip(self.object_vertices, self.object_faces,
                                               strict=True)]
        self.workspace = self._workspace()
        self._setup_hand(inputs)

    def add_landmark_point(self, index: int, point: np.ndarray) -> int:
        """Append a landmark's surface point (3,) in object `index`'s frame, metres, as an extra
        vertex of that object (no face uses it); its vertex id."""
        self.object_vertices[index] = np.vstack([self.object_vertices[index], point[None]])
        self.object_tensors[index] = self.tensor(self.object_vertices[index])
        return len(self.object_vertices[index]) - 1

    def tensor(self, array: npt.ArrayLike) -> torch.Tensor:
        return torch.as_tensor(np.asarray(array, dtype=np.float64), device=self.device)

    def require_subject(self) -> SubjectHand:
        """The subject's hand; ValueError when the sequence has no hand."""
        if self.subject is None:
            raise ValueError("this sequence has no hand to solve for")
        return self.subject

    def _setup_hand(self, inputs: SolveInputs) -> None:
        self.subject: SubjectHand | None = None
        self.reasons: list[str | None]
        self.hand_tree: AABBTree | None = None
        if self.hand is None:
            self.labelled = np.zeros(self.num_frames, dtype=bool)
            self.reasons = ["no hand in this sequence"] * self.num_frames
            return
        model = inputs.hand_model or builtin_hand_model(check_side(self.hand.side))
        self.layer = HandLayer(model, device=self.device)
        self.betas = np.asarray(self.hand.betas, dtype=np.float64)
        self.subject = SubjectHand(self.layer, self.tensor(self.betas))
        self.hand_faces = np.asarray(model.faces, dtype=np.int64)
        self.keypoints = np.asarray(self.hand.keypoints, dtype=np.float64)
        self.gamma = np.asarray(self.hand.visible, bool) & np.isfinite(self.keypoints).all(-1)
        self.labelled, self.reasons = labelled_frames(
            self.gamma, self.settings.min_views, self.settings.min_joints)

    def _workspace(self) -> tuple[np.ndarray, np.ndarray] | None:
        """World box (lo, hi) around the objects' initial placement, grown by workspace_margin."""
        if not self.objects:
            return None
        points = np.concatenate([v @ p[:, :3].T + p[:, 3] for v, p in
                                 zip(self.object_vertices, self.initial_poses, strict=True)])
        margin = self.settings.workspace_margin
        return points.min(0) - margin, points.max(0) + margin

    # ---- keypoint data -------------------------------------------------------------------
    def hand_data(self, frames: np.ndarray, robust: np.ndarray | None,
                  depth: DepthData | None) -> HandData:
        """HandData of frames (B,); robust: (B, V, 21) extra weights or None."""
        gamma = np.moveaxis(self.gamma[:, frames], 0, 1).astype(np.float64)  # (B, V, 21)
        total = np.maximum(gamma.sum(axis=(1, 2), keepdims=True), 1.0)
        weight = self.settings.w_kpt * gamma / total
        if robust is not None:
            weight = weight * robust
        keypoints = np.nan_to_num(np.moveaxis(self.keypoints[:, frames], 0, 1))
        return HandData(self.tensor(keypoints), self.tensor(np.sqrt(weight)),
                        float(np.sqrt(self.settings.w_reg)), depth)

    def object_data(self, index: int, frames: np.ndarray, base: np.ndarray,
                    marks: MappedLandmarks, robust: np.ndarray | None,
                    depth: DepthData | None) -> ObjectData:
        """ObjectData of object `index` for frames (B,), base poses (B, 3, 4)."""
        count = len(marks.views)
        if count:
            gamma = marks.gamma[frames].astype(np.float64)
            total = np.maximum(gamma.sum(axis=1, keepdims=True), 1.0)
            weight = self.settings.w_kpt * gamma / total
            if robust is not None:
                weight = weight * robust
            xy = np.nan_to_num(marks.xy[frames])
        else:
            weight, xy = np.zeros((len(frames), 0)), np.zeros((len(frames), 0, 2))
        return ObjectData(
            self.object_tensors[index], self.tensor(base),
            torch.as_tensor(marks.views, device=self.device),
            torch.as_tensor(marks.vertices, device=self.device),
            self.tensor(xy), self.tensor(np.sqrt(weight)), depth, self.rig)

    # ---- depth -----------------------------------------------------------------------------
    def match_depth(self, frame: int, hand_vertices: np.ndarray | None,
                    object_poses: np.ndarray) -> Matches | None:
        """Depth points of `frame` matched to the union of meshes posed as given.

        hand_vertices: (N, 3) world or None (hand absent); object_poses: (O, 3, 4).
        Mesh index: 0..O-1 the objects, O the hand.
        """
        if not self.clouds:
            return None
        points = self.clouds.points(frame)
        if self.workspace is not None:
            points = crop_to_boxes(points, [self.workspace], 0.0)
        trees = list(self.object_trees)
        boxes = [_world_box(t, p) for t, p in zip(trees, object_poses, strict=True)]
        poses: list[np.ndarray | None] = list(object_poses)
        if hand_vertices is not None:
            # The hand's tree is refitted from the last one built: its topology never changes.
            self.hand_tree = AABBTree.build(hand_vertices, self.hand_faces) \
                if self.hand_tree is None else self.hand_tree.refit(hand_vertices)
            trees.append(self.hand_tree)
            poses.append(None)
            boxes.append((hand_vertices.min(0), hand_vertices.max(0)))
        margin = self.settings.depth_margin
        points = crop_to_boxes(points, boxes, margin)
        rng = np.random.default_rng((self.settings.seed, frame))
        points = subsample(points, self.settings.max_depth_points, rng)
        return match_points(points, trees, poses, margin)

    def depth_data(self, mesh: int, matches: list[Matches | None], faces: np.ndarray,
                   robust_mm: float | None = None) -> DepthData | None:
        """DepthData for mesh `mesh` over a batch of frames' matches (padded), or None.

        robust_mm: Cauchy scale (mm) of a reweighting by each match's distance, so that a
        point of another surface (an object point beside a finger) barely pulls this mesh.
        """
        picked = []
        for m in matches:
            if m is None:
                picked.append((np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3)),
                               np.zeros(0), 1))
                continue
            sel = m.mesh == mesh
            weight = np.ones(int(sel.sum()))
            if robust_mm:
                weight = 1.0 / (1.0 + (m.dist[sel] * 1000.0 / robust_mm) ** 2)
            picked.append((m.points[sel], faces[m.face[sel]], m.bary[sel], weight,
                           max(len(m.mesh), 1)))
        size = max(len(p[0]) for p in picked)
        if size == 0 or self.settings.w_depth <= 0:
            return None
        # Each frame touches its own few vertices; only those are posed (padded per frame).
        frame_ids = [np.unique(p[1]) for p in picked]
        width = max(max(len(i) for i in frame_ids), 1)
        batch = len(picked)
        ids = np.zeros((batch, width), np.int64)
        points, corners = np.zeros((batch, size, 3)), np.zeros((batch, size, 3), np.int64)
        bary, sqrt_w = np.zeros((batch, size, 3)), np.zeros((batch, size))
        for b, (pts, cor, bar, weight, total) in enumerate(picked):
            n = len(pts)
            ids[b, :len(frame_ids[b])] = frame_ids[b]
            points[b, :n], bary[b, :n] = pts, bar
            corners[b, :n] = np.searchsorted(frame_ids[b], cor)
            sqrt_w[b, :n] = np.sqrt(self.settings.w_depth * weight / total)
        # Strictly inside the triangle, away from its edges by a relative hair.
        interior = (bary > 1e-6).all(axis=-1) & (sqrt_w > 0)
        return DepthData(self.tensor(points), torch.as_tensor(ids, device=self.device),
                         torch.as_tensor(corners, device=self.device), self.tensor(bary),
                         self.tensor(sqrt_w), torch.as_tensor(interior, device=self.device))


def _world_box(tree: AABBTree, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World AABB of a mesh given its object-frame tree and pose (3, 4)."""
    lo, hi = tree.lo[0], tree.hi[0]
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    world = corners @ pose[:, :3].T + pose[:, 3]
    return world.min(0), world.max(0)
