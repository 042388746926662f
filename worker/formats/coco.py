"""COCO keypoints JSON: one image per view and frame, the hand's 21 keypoints, objects as masks.

Pure: arrays in, one JSON document out through a binary file object. Nothing here reads the
database or storage.

Input, per image (one camera view of one frame), passed to :meth:`CocoWriter.add_image`:

- ``file_name`` (str), ``width``, ``height`` (int, pixels): the frame the labels refer to.
- ``seg``: optional (height, width) uint8 segmentation as DexYCB stores it: 0 background, an
  object's YCB class id (1..21, :data:`worker.formats.dexycb.YCB_CLASSES`), 255 the hand
  (:data:`worker.formats.dexycb.HAND_SEG_VALUE`).
- ``hand``: optional :class:`HandKeypoints`: ``xy`` (21, 2) float image pixels in DexYCB joint
  order (:data:`worker.hand.joints.JOINT_NAMES`), NaN where the joint carries no label;
  ``visible`` (21,) bool, True where the joint is seen, False where it is labelled but occluded
  (ignored where ``xy`` is NaN). A joint outside the image counts as not labelled (v = 0).
  Pixels follow the project's convention (x right, y down, the
  centre of the top-left pixel at (0, 0)), which is also COCO's for keypoints.
- ``extra``: optional JSON-serialisable fields copied into the image record (sequence, camera
  serial, frame index, ...).
- ``objects``: optional {object value in ``seg``: fields} copied into that object's annotation
  (the export's pose flag, confidence and provenance); an ``iscrowd`` there replaces the 0.

The writer's ``label_source`` says where the keypoints came from: ``"annotated_2d"`` (the crowd's
2D labels or their consensus) or ``"projected_3d"`` (the solved 3D joints projected into the
view); it is recorded in ``info.label_source``.

Output (COCO's data format, keypoint detection):

- ``categories``: the hand (id :data:`HAND_CATEGORY_ID` = 255, the hand's value in ``seg``) with
  ``keypoints`` = the 21 joint names and ``skeleton`` = the 20 bones as 1-based index pairs
  (parent, child); every YCB class as an object category whose id is its value in ``seg``.
- hand annotation: ``keypoints`` = 63 numbers x, y, v with v = 2 labelled and visible, 1 labelled
  but occluded, 0 not labelled (then x = y = 0); ``num_keypoints`` = count of v > 0; ``bbox``
  [x, y, w, h] and ``area`` from the hand's mask (``seg == 255``) when ``seg`` is given and the
  mask is not empty (bbox as ``pycocotools.mask.toBbox``, area = pixel count, ``segmentation`` =
  the mask's RLE), otherwise from the labelled keypoints (their min/max box, area = w * h, as
  ``COCO.loadRes`` computes it for keypoint results; no ``segmentation``); ``iscrowd`` 0 unless
  ``hand.extra`` sets it. An image with ``hand`` None gets no hand annotation.
- object annotation per object value present in ``seg``: ``segmentation`` = compressed COCO RLE
  (``{"size": [h, w], "counts": str}``), ``bbox`` and ``area`` from the mask, ``iscrowd`` 0, and
  ``num_keypoints`` 0 so that COCOeval with ``iouType="keypoints"`` skips objects (it reads
  ``num_keypoints`` of every ground-truth annotation of the evaluated categories).

OKS sigmas. COCOeval's keypoint similarity needs one sigma per keypoint
(``params.kpt_oks_sigmas``). The export recommends :data:`HAND_OKS_SIGMAS`, the hand sigmas of
COCO-WholeBody (Jin et al., ECCV 2020): they were measured per joint from redundant human
annotation, exactly as COCO measured its body sigmas, for the same 21 joints in the same order
(wrist; thumb to little finger, base to tip), and they are the values hand keypoint code
(xtcocotools, mmpose) already uses, so AP figures stay comparable with published ones. They are
written into the hand category (``sigmas``) and ``info.oks_sigmas``. One caveat: COCO-WholeBody
normalises by the whole person's area, whereas here ``area`` is the hand's own; the sigmas are
therefore strict for hands: at 640x480 a DexYCB hand's mask covers about 2,500 to 5,000 px
(scale s = sqrt(area) of 50 to 70 px), so OKS reaches 0.5 at 2 to 6 px of error, one to three
times the 2 px per-axis noise of a careful annotator. A looser metric scales all sigmas by one
factor. Evaluate with ``params.catIds = [HAND_CATEGORY_ID]``.

Memory: images and annotations are spooled to temporary files as they arrive and copied into the
output by :meth:`CocoWriter.close`, so memory does not grow with the number of images.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import IO, Any, Literal

import numpy as np

from worker.formats.dexycb import HAND_SEG_VALUE, YCB_CLASSES
from worker.formats.writer import StreamWriter
from worker.hand.joints import JOINT_NAMES, JOINT_PARENTS, NUM_JOINTS

LabelSource = Literal["annotated_2d", "projected_3d"]

HAND_CATEGORY_ID = HAND_SEG_VALUE
# COCO-WholeBody's per-joint hand sigmas, in DexYCB joint order (see the module docstring).
HAND_OKS_SIGMAS: tuple[float, ...] = (
    0.029, 0.022, 0.035, 0.037, 0.047, 0.026, 0.025, 0.024, 0.035, 0.018, 0.024,
    0.022, 0.026, 0.017, 0.021, 0.021, 0.032, 0.020, 0.019, 0.022, 0.031,
)
# (parent, child) bones, 1-based as COCO's skeleton field.
HAND_SKELETON: tuple[tuple[int, int], ...] = tuple(
    (parent + 1, child + 1) for child, parent in enumerate(JOINT_PARENTS) if parent >= 0)
_KEYPOINT_DECIMALS = 3  # 0.001 px: far below any labelling precision


@dataclass(frozen=True)
class HandKeypoints:
    """One hand's 2D keypoints in one image.

    xy: (21, 2) float image pixels in DexYCB joint order; NaN where the joint has no label.
    visible: (21,) bool; True = seen, False = labelled but occluded; ignored where xy is NaN.
    side: "right" or "left", written as ``hand_side`` when given.
    extra: JSON-serialisable fields copied into the annotation (assignment, worker, QC outcome).
    """

    xy: np.ndarray
    visible: np.ndarray
    side: Literal["right", "left"] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)


def encode_rle(mask: np.ndarray) -> dict[str, Any]:
    """Compressed COCO RLE of a (H, W) mask (nonzero = inside): ``{"size": [H, W], "counts"}``.

    Runs alternate outside/inside over the column-major flattened mask, starting with the
    outside run (possibly 0). ``counts`` is COCO's string form: each run, minus the run two
    before it from the fourth run on, as a signed variable-length number in 5-bit groups, each
    group offset by 48 into printable ASCII, 0x20 marking that another group follows.
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must have shape (H, W), got {mask.shape}")
    flat = mask.ravel(order="F") != 0
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    runs = np.diff(np.concatenate([[0], changes, [flat.size]])).tolist()
    if flat.size and flat[0]:
        runs.insert(0, 0)
    chars: list[str] = []
    for i, run in enumerate(runs):
        value = run - runs[i - 2] if i > 2 else run
        more = True
        while more:
            group = value & 0x1F
            value >>= 5
            more = value != -1 if group & 0x10 else value != 0
            chars.append(chr(group + 48 + (0x20 if more else 0)))
    return {"size": [int(mask.shape[0]), int(mask.shape[1])], "counts": "".join(chars)}


def mask_bbox(mask: np.ndarray) -> list[float]:
    """[x, y, w, h] of a nonempty (H, W) mask as pycocotools' toBbox: w = max x - min x + 1."""
    ys, xs = np.nonzero(mask)
    x0, y0 = int(xs.min()), int(ys.min())
    return [float(x0), float(y0), float(xs.max() - x0 + 1), float(ys.max() - y0 + 1)]


def hand_keypoints_field(hand: HandKeypoints, width: int, height: int
                         ) -> tuple[list[float], int]:
    """COCO's flat [x1, y1, v1, ...] (63 numbers) and ``num_keypoints`` of one hand in a
    (width, height) image; a joint outside the image (a projected joint can be) is unlabelled."""
    xy = np.asarray(hand.xy, dtype=np.float64)
    visible = np.asarray(hand.visible, dtype=bool)
    if xy.shape != (NUM_JOINTS, 2):
        raise ValueError(f"hand.xy must have shape ({NUM_JOINTS}, 2), got {xy.shape}")
    if visible.shape != (NUM_JOINTS,):
        raise ValueError(f"hand.visible must have shape ({NUM_JOINTS},), got {visible.shape}")
    with np.errstate(invalid="ignore"):
        # The image covers [-0.5, width - 0.5) x [-0.5, height - 0.5): pixel centres at integers.
        inside = (xy >= -0.5).all(axis=1) & (xy[:, 0] < width - 0.5) & (xy[:, 1] < height - 0.5)
    labelled = np.asarray(np.isfinite(xy).all(axis=1) & inside, dtype=bool)
    v = np.where(labelled, np.where(visible, 2, 1), 0)
    xy = np.where(labelled[:, None], np.round(xy, _KEYPOINT_DECIMALS), 0.0)
    flat = np.concatenate([xy, v[:, None]], axis=1).ravel().tolist()
    return [float(a) if i % 3 < 2 else int(a) for i, a in enumerate(flat)], int(labelled.sum())


def _keypoint_box(keypoints: list[float]) -> list[float]:
    """[x, y, w, h] of the labelled keypoints (min/max, as COCO.loadRes for keypoint results)."""
    pts = np.asarray(keypoints, dtype=np.float64).reshape(-1, 3)
    pts = pts[pts[:, 2] > 0]
    x0, y0 = pts[:, :2].min(axis=0)
    x1, y1 = pts[:, :2].max(axis=0)
    return [float(x0), float(y0), float(x1 - x0), float(y1 - y0)]


def categories(object_classes: Mapping[int, str] = YCB_CLASSES) -> list[dict[str, Any]]:
    """COCO categories: the hand (with keypoints, skeleton and OKS sigmas), then the objects."""
    hand = {"id": HAND_CATEGORY_ID, "name": "hand", "supercategory": "hand",
            "keypoints": list(JOINT_NAMES), "skeleton": [list(b) for b in HAND_SKELETON],
            "sigmas": list(HAND_OKS_SIGMAS)}
    objects = [{"id": int(k), "name": name, "supercategory": "object"}
               for k, name in sorted(object_classes.items())]
    return [hand, *objects]


class CocoWriter(StreamWriter):
    """Streams a COCO keypoints document into ``out`` (a binary file object opened for writing).

    Use as a context manager, or call :meth:`close` once after the last :meth:`add_image`; the
    JSON is written to ``out`` only then (``out`` itself is not closed). ``info`` adds fields to
    the document's ``info``; ``object_classes`` maps seg values to object names.
    """

    def __init__(self, out: IO[bytes], *, label_source: LabelSource,
                 info: Mapping[str, Any] | None = None,
                 object_classes: Mapping[int, str] = YCB_CLASSES) -> None:
        if label_source not in ("annotated_2d", "projected_3d"):
            raise ValueError(f"label_source must be 'annotated_2d' or 'projected_3d', got "
                             f"{label_source!r}")
        if HAND_CATEGORY_ID in object_classes:
            raise ValueError(f"object_classes must not use the hand's id {HAND_CATEGORY_ID}")
        self._out = out
        self._info = {"description": "dexlabel hand and object labels", **(info or {}),
                      "label_source": label_source, "oks_sigmas": list(HAND_OKS_SIGMAS)}
        self._object_classes = dict(object_classes)
        # The spools live as long as the writer, across calls, so no with-block can own them;
        # close() (or leaving the writer's own with-block) closes and deletes them.
        self._images: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115
        self._annotations: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115
        self._image_count = 0
        self._annotation_count = 0
        self._closed = False

    def add_image(self, file_name: str, width: int, height: int, *,
                  seg: np.ndarray | None = None, hand: HandKeypoints | None = None,
                  extra: Mapping[str, Any] | None = None,
                  objects: Mapping[int, Mapping[str, Any]] | None = None) -> int:
        """Record one view-frame image with its labels; returns its COCO image id (1-based)."""
        if self._closed:
            raise RuntimeError("the COCO writer is closed")
        if width <= 0 or height <= 0:
            raise ValueError(f"width and height must be positive, got {width} x {height}")
        if seg is not None:
            seg = np.asarray(seg)
            if seg.shape != (height, width) or seg.dtype != np.uint8:
                raise ValueError(f"seg must be ({height}, {width}) uint8, got {seg.shape} "
                                 f"{seg.dtype}")
            unknown = set(np.unique(seg).tolist()) - {0, HAND_SEG_VALUE, *self._object_classes}
            if unknown:
                raise ValueError(f"seg holds values that are no object class: {sorted(unknown)}")
        self._image_count += 1
        image_id = self._image_count
        record = {**(extra or {}), "id": image_id, "file_name": file_name, "width": int(width),
                  "height": int(height)}
        self._spool(self._images, record)
        if hand is not None:
            hand_mask = None if seg is None else seg == HAND_SEG_VALUE
            self._add_hand(image_id, hand, hand_mask, width, height)
        if seg is not None:
            for value in np.unique(seg).tolist():
                if value not in (0, HAND_SEG_VALUE):
                    self._add_object(image_id, value, seg == value, (objects or {}).get(value))
        return image_id

    def _add_hand(self, image_id: int, hand: HandKeypoints, mask: np.ndarray | None,
                  width: int, height: int) -> None:
        keypoints, num_keypoints = hand_keypoints_field(hand, width, height)
        record: dict[str, Any] = {"iscrowd": 0, **hand.extra, "category_id": HAND_CATEGORY_ID,
                                  "keypoints": keypoints, "num_keypoints": num_keypoints}
        if hand.side is not None:
            record["hand_side"] = hand.side
        if mask is not None and mask.any():
            record.update(segmentation=encode_rle(mask), bbox=mask_bbox(mask),
                          area=float(np.count_nonzero(mask)))
        elif num_keypoints > 0:
            box = _keypoint_box(keypoints)
            record.update(bbox=box, area=box[2] * box[3])
        else:
            return  # neither a mask nor a labelled joint: nothing locates the hand
        self._add_annotation(image_id, record)

    def _add_object(self, image_id: int, value: int, mask: np.ndarray,
                    extra: Mapping[str, Any] | None) -> None:
        self._add_annotation(image_id, {
            "iscrowd": 0, **(extra or {}), "category_id": int(value),
            "segmentation": encode_rle(mask), "bbox": mask_bbox(mask),
            "area": float(np.count_nonzero(mask)), "num_keypoints": 0})

    def _add_annotation(self, image_id: int, record: dict[str, Any]) -> None:
        self._annotation_count += 1
        record.update(id=self._annotation_count, image_id=image_id)
        self._spool(self._annotations, record)

    def _spool(self, spool: IO[bytes], record: Mapping[str, Any]) -> None:
        # Each record is written with a leading comma except the first, ready to splice in.
        prefix = b"," if spool.tell() else b""
        spool.write(prefix + json.dumps(record, separators=(",", ":")).encode())

    def close(self) -> None:
        """Write the whole JSON document to ``out`` and drop the spool files."""
        if self._closed:
            return
        head = {"info": self._info, "licenses": [],
                "categories": categories(self._object_classes)}
        out = self._out
        out.write(json.dumps(head, separators=(",", ":"))[:-1].encode())
        for name, spool in (("images", self._images), ("annotations", self._annotations)):
            out.write(f',"{name}":['.encode())
            spool.seek(0)
            shutil.copyfileobj(spool, out)
            out.write(b"]")
        out.write(b"}")
        self._discard()

    def _discard(self) -> None:
        self._closed = True
        self._images.close()
        self._annotations.close()
