"""BOP: per scene (one sequence seen by one camera) the camera, object poses, visibility and masks.

Pure: arrays in, file contents out through a :data:`FileSink` callback ``sink(path, data)`` that
receives a relative POSIX path and the file's bytes (the export maps it onto a zip or tar
member, or a file). Nothing here reads the database or storage.

Layout written (BOP's dataset format, ``docs/bop_datasets_format.md`` of bop_toolkit)::

    models/models_info.json          write_models: per obj_id min_x/y/z, size_x/y/z, diameter (mm)
                                     and symmetries_continuous / symmetries_discrete where the
                                     mesh has them (worker.formats.symmetry)
    models/obj_OOOOOO.ply            write_models: the mesh in mm (binary PLY)
    test_targets_bop19.json          write_targets: the instances to score (see ``notes``)
    <split>/SSSSSS/scene_camera.json BopSceneWriter.close: per image cam_K, depth_scale,
                                     cam_R_w2c, cam_t_w2c (mm)
    <split>/SSSSSS/scene_gt.json     per image a list of obj_id, cam_R_m2c, cam_t_m2c (mm)
    <split>/SSSSSS/scene_gt_info.json  per image and ground truth bbox_obj, bbox_visib,
                                     px_count_all, px_count_valid, px_count_visib, visib_fract,
                                     and our ``dexlabel`` note (pose_valid, pose_confidence,
                                     pose_flag, provenance) where one is given
    <split>/SSSSSS/mask/IIIIII_GGGGGG.png       full silhouette (0/255), as if nothing occluded it
    <split>/SSSSSS/mask_visib/IIIIII_GGGGGG.png the visible part (0/255)
    <split>/SSSSSS/depth/IIIIII.png  (when a depth image is given) uint16
    <split>/SSSSSS/rgb/IIIIII.<ext>  (when colour bytes are given) as given

S = scene id, I = image id, G = the ground truth's index in the image's scene_gt list, O = object
id, all 6-digit zero-padded; JSON keys are the ids as plain decimal strings. Rotations are
9 values row-major; translations 3 values in millimetres; bboxes [x, y, w, h] in pixels with
w = max x - min x as bop_toolkit's ``calc_2d_bbox``, [-1, -1, -1, -1] when empty.

Input (units and frames as the rest of the project: metres, OpenCV camera frame, pixels x right,
y down, the centre of the top-left pixel at (0, 0)):

- :class:`ObjectModel`: ``obj_id`` (int, DexYCB's YCB class id, 1..21, which is also its value in
  ``seg``; BOP's YCB-Video uses the same ids), ``vertices`` (N, 3) float metres in the object
  frame, ``faces`` (M, 3) int vertex indices.
- :class:`SceneCamera`: ``K`` (3, 3) pinhole intrinsics in pixels, ``T_cam_to_world`` (3, 4)
  metres (x_world = R x_cam + t), ``width``, ``height`` in pixels, ``depth_scale`` (millimetres
  per depth unit; 1.0 for DexYCB's uint16 millimetre depth). The camera is static over the
  scene. The images, ``seg`` and depth must be pinhole images for that K: undistort them first
  where the camera has lens distortion.
- per image, :meth:`BopSceneWriter.add_image`: ``im_id`` (int >= 0, the frame index), ``seg``
  (height, width) uint8 (0 background, object ids, 255 hand), ``object_poses`` a sequence of
  (obj_id, (3, 4) object-to-world pose in metres), optional ``depth`` (height, width) uint16 in
  depth units (0 = no measurement), optional ``rgb`` encoded image bytes, optional ``notes``
  (per posed object a JSON object). Every posed object is kept in scene_gt; one whose note says
  ``pose_valid`` false (a pose the solve flagged) is left out of the scene's test targets, so
  BOP's evaluation does not score estimates against it, as it skips instances less than 10 %
  visible.

Inside, poses become ``T_m2c = inv(T_cam_to_world) o T_obj_to_world`` and ``T_w2c`` with
translations in mm. The full silhouette is each object's mesh alone rasterised with K and its
pose (the same pixel-centre rasteriser that renders the synthetic captures, so a mask and a
synthetic ``seg`` agree pixel for pixel); as in bop_toolkit's calc_gt_info it is drawn on a
canvas reaching one image size beyond each border, so ``px_count_all`` and ``bbox_obj`` include
the part outside the frame. The visible mask is ``seg == obj_id`` within the full silhouette
(so visib_fract <= 1 even where a labelled ``seg`` overshoots the mesh by a pixel).
``px_count_valid`` counts silhouette pixels inside the image with depth > 0; without a depth
image every silhouette pixel inside the image counts as valid.

Memory: a scene writer holds its scene's three JSON documents (a few kB per image) and nothing
else; masks go to the sink as they are made.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from worker.geometry.raster import NEAR_PLANE, rasterize
from worker.geometry.transforms import compose_poses, invert_pose

FileSink = Callable[[str, bytes], None]

MM_PER_M = 1000.0
# Our fields in a scene_gt_info entry (BOP readers keep unknown keys).
NOTES_KEY = "dexlabel"
# bop_toolkit's enumerate_test_targets default: an instance is a target from 10 % visible on.
TARGET_MIN_VISIB_FRACT = 0.1
TARGETS_FILE = "test_targets_bop19.json"
EMPTY_BOX = [-1, -1, -1, -1]
_DIAMETER_BLOCK = 2048  # points per block of the pairwise-distance search, bounds its memory


@dataclass(frozen=True)
class ObjectModel:
    """An object mesh: vertices (N, 3) metres in the object frame, faces (M, 3) int."""

    obj_id: int
    vertices: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class SceneCamera:
    """A static pinhole camera: K (3, 3) px, T_cam_to_world (3, 4) metres, image size px,
    depth_scale millimetres per depth unit."""

    K: np.ndarray
    T_cam_to_world: np.ndarray
    width: int
    height: int
    depth_scale: float = 1.0


def _checked_model(model: ObjectModel) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(model.vertices, dtype=np.float64)
    faces = np.asarray(model.faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not len(vertices):
        raise ValueError(f"object {model.obj_id}: vertices must have shape (N, 3) with N > 0, "
                         f"got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"object {model.obj_id}: faces must have shape (M, 3), got "
                         f"{faces.shape}")
    return vertices, faces


def _diameter(points: np.ndarray) -> float:
    """Largest distance between two of the points (N, 3); searched over their convex hull."""
    # Flat or tiny point sets have no hull: then every point is searched.
    with contextlib.suppress(QhullError, ValueError):
        points = points[ConvexHull(points).vertices]
    best = 0.0
    for start in range(0, len(points), _DIAMETER_BLOCK):
        block = points[start:start + _DIAMETER_BLOCK]
        d2 = ((block[:, None, :] - points[None, :, :]) ** 2).sum(axis=-1)
        best = max(best, float(d2.max()))
    return float(np.sqrt(best))


def model_info(model: ObjectModel) -> dict[str, float]:
    """BOP's models_info entry of one mesh: min_x/y/z, size_x/y/z and diameter, millimetres."""
    vertices, _ = _checked_model(model)
    mm = vertices * MM_PER_M
    low, size = mm.min(axis=0), mm.max(axis=0) - mm.min(axis=0)
    info = {f"min_{a}": float(low[i]) for i, a in enumerate("xyz")}
    info.update({f"size_{a}": float(size[i]) for i, a in enumerate("xyz")})
    info["diameter"] = _diameter(mm)
    return info


def model_ply(model: ObjectModel) -> bytes:
    """The mesh as a binary little-endian PLY in millimetres (vertex x y z; face index list)."""
    vertices, faces = _checked_model(model)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode()
    face_rows = np.empty(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    face_rows["n"] = 3
    face_rows["idx"] = faces
    return header + (vertices * MM_PER_M).astype("<f4").tobytes() + face_rows.tobytes()


def write_models(sink: FileSink, models: Iterable[ObjectModel], folder: str = "models") -> None:
    """Write ``<folder>/models_info.json`` (with each model's symmetries, see
    :mod:`worker.formats.symmetry`) and ``<folder>/obj_OOOOOO.ply`` for every model."""
    from worker.formats.symmetry import bop_symmetries

    infos: dict[str, dict[str, Any]] = {}
    for model in sorted(models, key=lambda m: m.obj_id):
        infos[str(model.obj_id)] = {**model_info(model),
                                    **bop_symmetries(*_checked_model(model))}
        sink(f"{folder}/obj_{model.obj_id:06d}.ply", model_ply(model))
    sink(f"{folder}/models_info.json", _json_bytes(infos))


def write_targets(sink: FileSink, targets: Iterable[Mapping[str, int]]) -> None:
    """``test_targets_bop19.json``: a JSON list of {scene_id, im_id, obj_id, inst_count}."""
    rows = sorted(targets, key=lambda t: (t["scene_id"], t["im_id"], t["obj_id"]))
    sink(TARGETS_FILE, ("[\n" + ",\n".join(json.dumps(dict(t)) for t in rows)
                        + "\n]\n").encode())


def _json_bytes(document: Mapping[str, Any]) -> bytes:
    """A JSON object with one line per key (an image or object id), as bop_toolkit writes."""
    lines = [f"{json.dumps(str(k))}: {json.dumps(v)}" for k, v in document.items()]
    return ("{\n" + ",\n".join(lines) + "\n}\n").encode()


def _png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode a {image.shape} {image.dtype} image as PNG")
    return data.tobytes()


def _box(mask: np.ndarray, dx: int = 0, dy: int = 0) -> list[int]:
    """[x, y, w, h] of a mask's pixels (w = max - min, as bop_toolkit), offset by (dx, dy)."""
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return list(EMPTY_BOX)
    return [int(xs.min()) + dx, int(ys.min()) + dy, int(xs.max() - xs.min()),
            int(ys.max() - ys.min())]


@dataclass(frozen=True)
class Silhouette:
    """An object's full silhouette: ``inside`` (H, W) bool within the image; ``count`` and
    ``box`` ([x, y, w, h], image pixels) over the canvas that reaches one image size beyond
    each border."""

    inside: np.ndarray
    count: int
    box: list[int]


def silhouette(vertices_cam: np.ndarray, faces: np.ndarray, K: np.ndarray, width: int,
               height: int) -> Silhouette:
    """Rasterise a mesh alone: vertices (N, 3) metres in the camera frame, K (3, 3) px."""
    inside = np.zeros((height, width), dtype=bool)
    front = vertices_cam[:, 2] > NEAR_PLANE
    if not front.any():
        return Silhouette(inside, 0, list(EMPTY_BOX))
    seen = vertices_cam[front]
    uv = seen @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    # The canvas covers the projected mesh, clipped to [-W, 2W) x [-H, 2H).
    x0 = max(int(np.floor(uv[:, 0].min())), -width)
    y0 = max(int(np.floor(uv[:, 1].min())), -height)
    x1 = min(int(np.ceil(uv[:, 0].max())), 2 * width - 1)
    y1 = min(int(np.ceil(uv[:, 1].max())), 2 * height - 1)
    if x1 < x0 or y1 < y0:
        return Silhouette(inside, 0, list(EMPTY_BOX))
    shifted = np.array(K, dtype=np.float64)
    shifted[0, 2] -= x0
    shifted[1, 2] -= y0
    canvas = rasterize(vertices_cam, faces, shifted, x1 - x0 + 1, y1 - y0 + 1).tri >= 0
    # The part of the canvas inside the image.
    ix0, iy0 = max(x0, 0), max(y0, 0)
    ix1, iy1 = min(x1 + 1, width), min(y1 + 1, height)
    if ix1 > ix0 and iy1 > iy0:
        inside[iy0:iy1, ix0:ix1] = canvas[iy0 - y0:iy1 - y0, ix0 - x0:ix1 - x0]
    return Silhouette(inside, int(canvas.sum()), _box(canvas, x0, y0))


def _flat(matrix: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(matrix).ravel()]


class BopSceneWriter:
    """Writes one BOP scene (one sequence x one camera) image by image into ``sink``.

    Files go under ``<split>/<scene_id:06d>/``. Call :meth:`add_image` per frame, then
    :meth:`close` once to write the scene's three JSON files (masks and images are written as
    they come). ``models`` maps obj_id to its mesh; every posed object must have one.
    """

    def __init__(self, sink: FileSink, scene_id: int, camera: SceneCamera,
                 models: Mapping[int, ObjectModel], *, split: str = "test",
                 rgb_ext: str = ".jpg") -> None:
        if scene_id < 0:
            raise ValueError(f"scene_id must be >= 0, got {scene_id}")
        K = np.asarray(camera.K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"camera.K must have shape (3, 3), got {K.shape}")
        w2c = invert_pose(np.asarray(camera.T_cam_to_world, dtype=np.float64))
        if w2c.shape != (3, 4):
            raise ValueError(f"camera.T_cam_to_world must have shape (3, 4), got {w2c.shape}")
        self._sink = sink
        self._root = f"{split}/{scene_id:06d}"
        self._camera = camera
        self._K = K
        self._w2c = w2c
        self._models = {k: _checked_model(m) for k, m in models.items()}
        self._rgb_ext = rgb_ext
        self._scene_camera: dict[str, Any] = {}
        self._scene_gt: dict[str, Any] = {}
        self._scene_gt_info: dict[str, Any] = {}
        self._scene_id = int(scene_id)
        # BOP's test targets of this scene: trusted instances visible enough to be scored.
        self.targets: list[dict[str, int]] = []
        self._closed = False

    def add_image(self, im_id: int, seg: np.ndarray,
                  object_poses: Sequence[tuple[int, np.ndarray]], *,
                  depth: np.ndarray | None = None, rgb: bytes | None = None,
                  notes: Sequence[Mapping[str, Any]] | None = None) -> None:
        """Record image ``im_id``: its seg, the posed objects, optional depth and colour.

        notes: per posed object, JSON fields written under :data:`NOTES_KEY` in its
        scene_gt_info entry; a note with ``pose_valid`` false keeps the instance in scene_gt
        and out of :attr:`targets`.
        """
        key, seg, depth = self._checked_image(im_id, seg, object_poses, depth)
        self._scene_camera[key] = {
            "cam_K": _flat(self._K), "depth_scale": float(self._camera.depth_scale),
            "cam_R_w2c": _flat(self._w2c[:, :3]), "cam_t_w2c": _flat(self._w2c[:, 3] * MM_PER_M)}
        if notes is not None and len(notes) != len(object_poses):
            raise ValueError(f"notes must have one entry per posed object ({len(object_poses)}), "
                             f"got {len(notes)}")
        self._scene_gt[key], self._scene_gt_info[key] = self._instances(
            im_id, object_poses, seg, depth, notes)
        if depth is not None:
            self._sink(f"{self._root}/depth/{im_id:06d}.png", _png(depth))
        if rgb is not None:
            self._sink(f"{self._root}/rgb/{im_id:06d}{self._rgb_ext}", rgb)

    def _checked_image(self, im_id: int, seg: np.ndarray,
                       object_poses: Sequence[tuple[int, np.ndarray]], depth: np.ndarray | None
                       ) -> tuple[str, np.ndarray, np.ndarray | None]:
        """The image's key in the scene files, its seg (H, W) uint8 and depth (H, W) uint16 or
        None, once the writer is open, the id new and the arrays and object ids are as BOP's."""
        if self._closed:
            raise RuntimeError("the BOP scene writer is closed")
        size = (self._camera.height, self._camera.width)
        key = str(int(im_id))
        if im_id < 0 or key in self._scene_gt:
            raise ValueError(f"im_id must be a new id >= 0, got {im_id}")
        seg = np.asarray(seg)
        if seg.shape != size or seg.dtype != np.uint8:
            raise ValueError(f"seg must be {size} uint8, got {seg.shape} {seg.dtype}")
        if depth is not None:
            depth = np.asarray(depth)
            if depth.shape != size or depth.dtype != np.uint16:
                raise ValueError(f"depth must be {size} uint16, got {depth.shape} {depth.dtype}")
        ids = [int(obj_id) for obj_id, _ in object_poses]
        if len(set(ids)) != len(ids):
            raise ValueError(f"each object may appear once per image, got ids {ids}")
        return key, seg, depth

    def _instances(self, im_id: int, object_poses: Sequence[tuple[int, np.ndarray]],
                   seg: np.ndarray, depth: np.ndarray | None,
                   notes: Sequence[Mapping[str, Any]] | None
                   ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """The image's scene_gt and scene_gt_info entries, one per posed object (its masks
        written); its trusted instances visible enough to be scored join :attr:`targets`."""
        gts, infos = [], []
        counts: dict[int, int] = {}
        for gt_id, (obj_id, pose) in enumerate(object_poses):
            gt, info = self._ground_truth(im_id, gt_id, int(obj_id), pose, seg, depth)
            note = dict(notes[gt_id]) if notes is not None else {}
            if note:
                info[NOTES_KEY] = note
            if note.get("pose_valid", True) and info["visib_fract"] >= TARGET_MIN_VISIB_FRACT:
                counts[int(obj_id)] = counts.get(int(obj_id), 0) + 1
            gts.append(gt)
            infos.append(info)
        self.targets.extend({"scene_id": self._scene_id, "im_id": int(im_id), "obj_id": obj_id,
                             "inst_count": n} for obj_id, n in sorted(counts.items()))
        return gts, infos

    def _ground_truth(self, im_id: int, gt_id: int, obj_id: int, pose: np.ndarray,
                      seg: np.ndarray, depth: np.ndarray | None
                      ) -> tuple[dict[str, Any], dict[str, Any]]:
        if obj_id not in self._models:
            raise ValueError(f"object {obj_id} has no model; models: {sorted(self._models)}")
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3, 4):
            raise ValueError(f"object {obj_id}: pose must have shape (3, 4), got {pose.shape}")
        m2c = compose_poses(self._w2c, pose)
        vertices, faces = self._models[obj_id]
        vertices_cam = vertices @ m2c[:, :3].T + m2c[:, 3]
        full = silhouette(vertices_cam, faces, self._K, self._camera.width, self._camera.height)
        visible = (seg == obj_id) & full.inside
        px_visib = int(visible.sum())
        px_valid = int(full.inside.sum()) if depth is None else int(
            np.count_nonzero(depth[full.inside]))
        name = f"{im_id:06d}_{gt_id:06d}.png"
        self._sink(f"{self._root}/mask/{name}", _png(full.inside.astype(np.uint8) * 255))
        self._sink(f"{self._root}/mask_visib/{name}", _png(visible.astype(np.uint8) * 255))
        gt = {"obj_id": obj_id, "cam_R_m2c": _flat(m2c[:, :3]),
              "cam_t_m2c": _flat(m2c[:, 3] * MM_PER_M)}
        info = {"bbox_obj": full.box, "bbox_visib": _box(visible), "px_count_all": full.count,
                "px_count_valid": px_valid, "px_count_visib": px_visib,
                "visib_fract": px_visib / full.count if full.count else 0.0}
        return gt, info

    def close(self) -> None:
        """Write scene_camera.json, scene_gt.json and scene_gt_info.json."""
        if self._closed:
            return
        self._closed = True
        for name, document in (("scene_camera", self._scene_camera),
                               ("scene_gt", self._scene_gt),
                               ("scene_gt_info", self._scene_gt_info)):
            ordered = dict(sorted(document.items(), key=lambda item: int(item[0])))
            self._sink(f"{self._root}/{name}.json", _json_bytes(ordered))

