"""COCO keypoints export: read back with pycocotools, evaluated against itself, rules checked."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from worker.formats.coco import (
    HAND_CATEGORY_ID,
    HAND_OKS_SIGMAS,
    CocoWriter,
    HandKeypoints,
    encode_rle,
)
from worker.formats.dexycb import HAND_SEG_VALUE
from worker.hand.joints import JOINT_NAMES, JOINT_PARENTS

WIDTH, HEIGHT = 160, 120
MUG, BOX = 14, 2  # YCB class ids as seg values


def _hand_xy(rng: np.random.Generator) -> np.ndarray:
    """(21, 2) px: a fan of five fingers from a wrist near (60, 80), jittered."""
    wrist = np.array([60.0, 80.0])
    rows = [wrist]
    for finger in range(5):
        direction = np.array([np.cos(-2.6 + 0.35 * finger), np.sin(-2.6 + 0.35 * finger)])
        rows += [wrist + direction * (12.0 + 8.0 * k) for k in range(4)]
    return np.asarray(rows) + rng.normal(0.0, 0.5, (21, 2))


def _seg(hand_xy: np.ndarray) -> np.ndarray:
    """(H, W) uint8: a mug disc, a box partly covered by the hand, the hand's hull."""
    seg = np.zeros((HEIGHT, WIDTH), np.uint8)
    cv2.circle(seg, (125, 40), 15, MUG, -1)
    cv2.rectangle(seg, (20, 70), (70, 110), BOX, -1)
    hull = cv2.convexHull(np.round(hand_xy).astype(np.int32))
    cv2.fillConvexPoly(seg, hull, HAND_SEG_VALUE)
    return seg


def _write(images: list[dict[str, Any]], **kwargs: Any) -> dict[str, Any]:
    out = io.BytesIO()
    with CocoWriter(out, label_source=kwargs.pop("label_source", "annotated_2d"),
                    **kwargs) as writer:
        for image in images:
            writer.add_image(**image)
    document: dict[str, Any] = json.loads(out.getvalue())
    return document


def _sample_images(count: int = 6) -> list[dict[str, Any]]:
    """Images with masks, some joints unlabelled, some occluded; the last one without seg."""
    rng = np.random.default_rng(7)
    images = []
    for i in range(count):
        xy = _hand_xy(rng) + [i * 3.0, 0.0]
        visible = rng.random(21) > 0.3
        xy[rng.random(21) < 0.15] = np.nan
        seg = _seg(xy[np.isfinite(xy).all(axis=1)]) if i < count - 1 else None
        images.append({"file_name": f"view0/{i:06d}.jpg", "width": WIDTH, "height": HEIGHT,
                       "seg": seg, "hand": HandKeypoints(xy, visible, side="right"),
                       "extra": {"frame": i, "camera": "view0"}})
    return images


class TestEncodeRle:
    def test_counts_equal_pycocotools_encode(self) -> None:
        rng = np.random.default_rng(0)
        masks = [np.zeros((7, 5), np.uint8), np.ones((7, 5), np.uint8),
                 (rng.random((48, 33)) > 0.5).astype(np.uint8)]
        blob = np.zeros((120, 160), np.uint8)
        cv2.circle(blob, (80, 60), 40, 1, -1)
        masks.append(blob)
        for mask in masks:
            ours = encode_rle(mask)
            theirs = mask_utils.encode(np.asfortranarray(mask))
            assert ours["counts"] == theirs["counts"].decode()
            assert ours["size"] == list(theirs["size"])

    def test_decodes_to_the_input_mask(self) -> None:
        mask = (np.random.default_rng(1).random((31, 17)) > 0.7).astype(np.uint8)
        rle = encode_rle(mask)
        decoded = mask_utils.decode({"size": rle["size"], "counts": rle["counts"].encode()})
        np.testing.assert_array_equal(decoded, mask)

    def test_rejects_a_non_2d_mask(self) -> None:
        with pytest.raises(ValueError, match=r"\(H, W\).*\(2, 3, 4\)"):
            encode_rle(np.zeros((2, 3, 4)))


class TestCocoWriter:
    def test_pycocotools_self_evaluation_gives_ap_one(self, tmp_path: Path) -> None:
        document = _write(_sample_images())
        path = tmp_path / "coco.json"
        path.write_text(json.dumps(document))
        gt = COCO(str(path))
        hands = [dict(a, score=1.0) for a in gt.loadAnns(gt.getAnnIds(catIds=[HAND_CATEGORY_ID]))
                 if a["num_keypoints"] > 0]
        evaluation = COCOeval(gt, gt.loadRes(hands), iouType="keypoints")
        hand_category = gt.loadCats([HAND_CATEGORY_ID])[0]
        evaluation.params.kpt_oks_sigmas = np.asarray(hand_category["sigmas"])
        evaluation.params.catIds = [HAND_CATEGORY_ID]
        evaluation.evaluate()
        evaluation.accumulate()
        evaluation.summarize()
        assert evaluation.stats[0] == pytest.approx(1.0)

    def test_hand_category_names_joints_skeleton_and_sigmas(self) -> None:
        document = _write([])
        hand = next(c for c in document["categories"] if c["id"] == HAND_CATEGORY_ID)
        assert hand["keypoints"] == list(JOINT_NAMES)
        assert len(hand["skeleton"]) == 20
        assert all(1 <= a <= 21 and 1 <= b <= 21 for a, b in hand["skeleton"])
        assert sorted(b - 1 for _, b in hand["skeleton"]) == list(range(1, 21))
        assert all(JOINT_PARENTS[b - 1] == a - 1 for a, b in hand["skeleton"])
        assert hand["sigmas"] == list(HAND_OKS_SIGMAS) == document["info"]["oks_sigmas"]
        names = {c["id"]: c["name"] for c in document["categories"]}
        assert names[MUG] == "025_mug" and names[BOX] == "003_cracker_box"

    @pytest.mark.parametrize("source", ["annotated_2d", "projected_3d"])
    def test_info_records_the_label_source(self, source: str) -> None:
        assert _write([], label_source=source)["info"]["label_source"] == source

    def test_keypoint_visibility_and_count_rules(self) -> None:
        images = _sample_images()
        document = _write(images)
        hands = [a for a in document["annotations"] if a["category_id"] == HAND_CATEGORY_ID]
        assert len(hands) == len(images)
        for image, ann in zip(images, hands, strict=True):
            points = np.asarray(ann["keypoints"]).reshape(21, 3)
            labelled = np.isfinite(image["hand"].xy).all(axis=1)
            expected_v = np.where(labelled, np.where(image["hand"].visible, 2, 1), 0)
            np.testing.assert_array_equal(points[:, 2], expected_v)
            np.testing.assert_array_equal(points[~labelled, :2], 0.0)
            np.testing.assert_allclose(points[labelled, :2], image["hand"].xy[labelled],
                                       atol=1e-3)
            assert ann["num_keypoints"] == int(labelled.sum())
            assert ann["iscrowd"] == 0 and ann["hand_side"] == "right"

    def test_hand_box_and_area_come_from_the_mask(self) -> None:
        images = _sample_images(2)
        ann = _write(images[:1])["annotations"][0]
        mask = images[0]["seg"] == HAND_SEG_VALUE
        ys, xs = np.nonzero(mask)
        assert ann["bbox"] == [xs.min(), ys.min(), xs.max() - xs.min() + 1,
                               ys.max() - ys.min() + 1]
        assert ann["area"] == mask.sum()
        rle = {"size": ann["segmentation"]["size"],
               "counts": ann["segmentation"]["counts"].encode()}
        np.testing.assert_array_equal(mask_utils.decode(rle), mask)

    def test_hand_box_comes_from_labelled_keypoints_without_a_mask(self) -> None:
        xy = np.full((21, 2), np.nan)
        xy[[0, 4, 8]] = [[10.0, 20.0], [40.0, 25.0], [30.0, 60.0]]
        ann = _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT,
                       "hand": HandKeypoints(xy, np.ones(21, bool))}])["annotations"][0]
        assert ann["bbox"] == [10.0, 20.0, 30.0, 40.0]
        assert ann["area"] == 1200.0
        assert ann["num_keypoints"] == 3
        assert "segmentation" not in ann

    def test_a_joint_outside_the_image_is_not_labelled(self) -> None:
        xy = np.full((21, 2), 50.0)
        xy[3] = [WIDTH - 0.5, 10.0]
        xy[4] = [10.0, -0.6]
        ann = _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT,
                       "hand": HandKeypoints(xy, np.ones(21, bool))}])["annotations"][0]
        assert ann["keypoints"][9:15] == [0.0, 0.0, 0, 0.0, 0.0, 0]
        assert ann["num_keypoints"] == 19

    def test_an_unlocated_hand_gets_no_annotation(self) -> None:
        hand = HandKeypoints(np.full((21, 2), np.nan), np.zeros(21, bool))
        document = _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT,
                            "hand": hand}])
        assert document["annotations"] == [] and len(document["images"]) == 1

    def test_object_masks_decode_to_the_seg(self, tmp_path: Path) -> None:
        images = _sample_images(2)
        path = tmp_path / "coco.json"
        path.write_text(json.dumps(_write(images[:1])))
        coco = COCO(str(path))
        seg = images[0]["seg"]
        for category in (MUG, BOX):
            (ann,) = coco.loadAnns(coco.getAnnIds(catIds=[category]))
            np.testing.assert_array_equal(coco.annToMask(ann), seg == category)
            assert ann["area"] == (seg == category).sum()
            assert ann["iscrowd"] == 0 and ann["num_keypoints"] == 0
            assert mask_utils.toBbox(coco.annToRLE(ann)).tolist() == ann["bbox"]

    def test_a_flagged_object_stays_as_a_crowd_region_that_cocoeval_ignores(
            self, tmp_path: Path) -> None:
        images = _sample_images(2)[:1]
        flag = {"pose_valid": False, "pose_flag": "landmarks 14 px off", "iscrowd": 1}
        images[0]["objects"] = {BOX: flag, MUG: {"pose_valid": True, "pose_flag": None}}
        path = tmp_path / "coco.json"
        path.write_text(json.dumps(_write(images)))
        coco = COCO(str(path))
        (box,) = coco.loadAnns(coco.getAnnIds(catIds=[BOX]))
        (mug,) = coco.loadAnns(coco.getAnnIds(catIds=[MUG]))
        assert box["iscrowd"] == 1 and box["pose_flag"] == "landmarks 14 px off"
        assert mug["iscrowd"] == 0 and mug["pose_valid"] is True
        np.testing.assert_array_equal(coco.annToMask(box), images[0]["seg"] == BOX)
        # A detection on the flagged box is neither a hit nor a false positive; a missed
        # crowd region costs nothing: AP stays 1 with the mug alone detected.
        for detections in ([mug], [mug, box]):
            results = coco.loadRes([dict(a, score=1.0, iscrowd=0) for a in detections])
            evaluation = COCOeval(coco, results, iouType="segm")
            evaluation.params.catIds = [MUG, BOX]
            evaluation.evaluate()
            evaluation.accumulate()
            evaluation.summarize()
            assert evaluation.stats[0] == pytest.approx(1.0)

    def test_a_hand_flag_can_make_its_annotation_a_crowd_region(self) -> None:
        image = _sample_images(1)[0]
        hand = image["hand"]
        image["hand"] = HandKeypoints(hand.xy, hand.visible, side="right",
                                      extra={"iscrowd": 1, "hand_flag": "not pinned down"})
        (ann,) = [a for a in _write([image])["annotations"] if a["category_id"] == 255]
        assert ann["iscrowd"] == 1 and ann["hand_flag"] == "not pinned down"

    def test_images_keep_ids_names_and_extra_fields(self) -> None:
        document = _write(_sample_images(3))
        assert [i["id"] for i in document["images"]] == [1, 2, 3]
        assert document["images"][2]["file_name"] == "view0/000002.jpg"
        assert document["images"][2]["frame"] == 2
        ids = [a["id"] for a in document["annotations"]]
        assert ids == list(range(1, len(ids) + 1))

    def test_rejects_a_seg_of_the_wrong_shape(self) -> None:
        with pytest.raises(ValueError, match=r"seg must be \(120, 160\) uint8, got \(120, 161\)"):
            _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT,
                     "seg": np.zeros((HEIGHT, WIDTH + 1), np.uint8)}])

    def test_rejects_an_unknown_seg_value(self) -> None:
        seg = np.full((HEIGHT, WIDTH), 99, np.uint8)
        with pytest.raises(ValueError, match=r"\[99\]"):
            _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT, "seg": seg}])

    def test_rejects_keypoints_of_the_wrong_shape(self) -> None:
        hand = HandKeypoints(np.zeros((20, 2)), np.ones(20, bool))
        with pytest.raises(ValueError, match=r"\(21, 2\), got \(20, 2\)"):
            _write([{"file_name": "a.jpg", "width": WIDTH, "height": HEIGHT, "hand": hand}])

    def test_a_failed_export_writes_nothing(self) -> None:
        out = io.BytesIO()

        def interrupted_export() -> None:
            with CocoWriter(out, label_source="annotated_2d") as writer:
                writer.add_image("a.jpg", WIDTH, HEIGHT)
                raise RuntimeError("interrupted")

        with pytest.raises(RuntimeError, match="interrupted"):
            interrupted_export()
        assert out.getvalue() == b""


def test_a_synthetic_capture_evaluates_to_ap_one_against_itself(small_capture: Path,
                                                                tmp_path: Path) -> None:
    """Every view and frame of a synthetic capture: the projected joints and the rendered seg."""
    seq = next(small_capture.glob("*/*/meta.yml")).parent
    path = tmp_path / "coco.json"
    with path.open("wb") as out, CocoWriter(out, label_source="projected_3d") as writer:
        for label_path in sorted(seq.glob("*/labels_*.npz")):
            label = np.load(label_path)
            height, width = label["seg"].shape
            hand = HandKeypoints(label["joint_2d"][0].astype(np.float64), np.ones(21, bool))
            writer.add_image(f"{label_path.parent.name}/{label_path.stem}.jpg", width, height,
                             seg=label["seg"], hand=hand)
    gt = COCO(str(path))
    hands = [dict(a, score=1.0) for a in gt.loadAnns(gt.getAnnIds(catIds=[HAND_CATEGORY_ID]))]
    assert any(a["num_keypoints"] == 21 for a in hands)
    hands = [a for a in hands if a["num_keypoints"] > 0]
    evaluation = COCOeval(gt, gt.loadRes(hands), iouType="keypoints")
    evaluation.params.kpt_oks_sigmas = np.asarray(HAND_OKS_SIGMAS)
    evaluation.params.catIds = [HAND_CATEGORY_ID]
    evaluation.evaluate()
    evaluation.accumulate()
    evaluation.summarize()
    assert evaluation.stats[0] == pytest.approx(1.0)
