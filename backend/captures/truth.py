"""A synthetic capture's ground truth, read from its own label files: the points a careful
worker would place in each view (hand joints, object landmarks) and the true object poses.
The simulated crowd labels from it; training clips take gold tracks from it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from backend.captures.layout import read_sequence
from backend.captures.plans import SequencePlan
from backend.errors import NotFound
from worker.formats import dexycb
from worker.geometry.cameras import CameraModel, intrinsics_matrix
from worker.geometry.mesh_io import read_mesh
from worker.synth.annotators import hand_visibility, mesh_landmarks

# Centroid splits of an object's mesh before landmarks are picked (see surface_points).
SURFACE_LEVELS = 2


def surface_points(vertices: np.ndarray, faces: np.ndarray,
                   levels: int = SURFACE_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """The same surface with a point added at each triangle's centroid (split in three),
    ``levels`` times: (N', 3) vertices and (M', 3) faces.

    A person picks landmarks anywhere on the object, not only at mesh vertices; on a coarse
    mesh (the synthetic box has 8 corners, each on the silhouette in most views) the corners
    alone rarely give two clearly visible landmarks. Centroids inherit their face's normal.
    """
    for _ in range(levels):
        centroids = vertices[faces].mean(axis=1)
        ids = np.arange(len(vertices), len(vertices) + len(faces))
        a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
        faces = np.concatenate([np.stack([a, b, ids], 1), np.stack([b, c, ids], 1),
                                np.stack([c, a, ids], 1)])
        vertices = np.concatenate([vertices, centroids])
    return vertices, faces


class CaptureTruth:
    """Ground truth of a synthetic capture's views, read once per view (serial)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self._views: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._plans: dict[Path, SequencePlan] = {}

    def _folder(self, serial: str) -> Path:
        found = sorted(p for p in self.root.glob(f"*/*/{serial}") if p.is_dir())
        if not found:
            raise NotFound(f"the capture at {self.root} has no view {serial!r}")
        return found[0]

    def _labels(self, serial: str, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, 21, 2) joint_2d px, (F, H, W) seg and (F, O, 3, 4) object-to-camera pose_y of
        one view, each label file read once."""
        if serial not in self._views:
            folder = self._folder(serial)
            joints, segs, poses = [], [], []
            for f in range(frames):
                with np.load(folder / dexycb.labels_file(f)) as labels:
                    joints.append(labels[dexycb.JOINT_2D][0].astype(np.float64))
                    segs.append(labels[dexycb.SEG])
                    poses.append(labels[dexycb.POSE_Y].astype(np.float64))
            self._views[serial] = (np.stack(joints), np.stack(segs), np.stack(poses))
        return self._views[serial]

    def _shown(self, serial: str, frames: int) -> np.ndarray:
        """(F,) the truth frame each of the view's image frames shows: a camera of a capture
        with rig faults may be late (worker.synth.faults); workers label what they see."""
        from worker.synth.faults import shown_frames

        return shown_frames(self.root, serial, frames)

    def view(self, serial: str, frames: int) -> tuple[np.ndarray, np.ndarray]:
        """(F, 21, 2) joint_2d px and (F, H, W) seg of one view, as its images show them."""
        joint_2d, seg, _ = self._labels(serial, frames)
        shown = self._shown(serial, frames)
        return joint_2d[shown], seg[shown]

    def _plan(self, folder: Path) -> SequencePlan:
        if folder not in self._plans:
            self._plans[folder] = read_sequence(folder)
        return self._plans[folder]

    def object_points(self, serial: str, index: int, frames: int, rng: np.random.Generator,
                      suggested: tuple[np.ndarray, np.ndarray] | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Two landmarks on object ``index`` in one view: surface points visible where it first
        shows, followed through its true poses as the view's images show them; (F, 2, 2) px
        and (F, 2) visibility. suggested: the landmarks the page suggests ((F, 2, 2) px, (F, 2)
        shown visible), whose spots a person takes (worker.synth.annotators.mesh_landmarks)."""
        plan = self._plan(self._folder(serial).parent)
        cam = next(c for c in plan.cameras if c.serial == serial)
        # The view's own camera frame as the world: the labels' pose_y are object-to-camera.
        camera = CameraModel(intrinsics_matrix(cam.fx, cam.fy, cam.ppx, cam.ppy),
                             np.asarray(cam.distortion), np.eye(3, 4), cam.width, cam.height)
        mesh = read_mesh(plan.objects[index].mesh_path)
        _, seg, poses = self._labels(serial, frames)
        shown = self._shown(serial, frames)
        seg, poses = seg[shown], poses[shown]
        vertices, faces = surface_points(np.asarray(mesh.vertices, float),
                                         np.asarray(mesh.faces, int))
        xy, visible, _ = mesh_landmarks(camera, seg, int(plan.objects[index].ycb_id), vertices,
                                        faces, poses[:, index], rng, shown=suggested)
        return xy, visible

    def object_poses(self) -> np.ndarray:
        """(O, F, 3, 4) true object-to-world poses of the capture's (first) sequence, metres,
        from its first view's labels (object-to-camera) and that camera's extrinsics."""
        seq_dir = min(p.parent for p in self.root.glob(f"*/*/{dexycb.META_FILE}"))
        plan = self._plan(seq_dir)
        camera = plan.cameras[0]
        _, _, in_cam = self._labels(camera.serial, plan.num_frames)
        to_world = np.asarray(camera.extrinsics, dtype=np.float64)
        rot = np.einsum("ij,fojk->ofik", to_world[:, :3], in_cam[..., :3])
        trans = np.einsum("ij,foj->ofi", to_world[:, :3], in_cam[..., 3]) + to_world[:, 3]
        return np.concatenate([rot, trans[..., None]], axis=-1)

    def points(self, task: dict, rng: np.random.Generator,
               suggested: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """The task's true points (F, P, 2) px and visibility (F, P); suggested: an object task's
        suggested landmarks, as object_points takes them."""
        if task["kind"] == "hand":
            joint_2d, seg = self.view(task["serial"], task["num_frames"])
            return joint_2d, hand_visibility(joint_2d, seg)
        return self.object_points(task["serial"], int(task["target_key"].split(":")[1]),
                                  task["num_frames"], rng, suggested)
