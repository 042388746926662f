"""Check of a DexYCB export against a synthetic capture's ground truth.

Reads an export (a folder or a .zip/.tar written by ``dexlabel export --format dexycb``) and the
synthetic capture it came from (``dexlabel synth`` or the demo's ``<var>/demo-capture``), both
in the DexYCB layout, and compares per sequence, camera and frame:

- hand: ``joint_3d`` error in mm (mean over the 21 joints, camera frame) and ``joint_2d`` error
  in px (the truth's joints projected with the export's pinhole K, as the export computes it)
  on every labelled camera-frame; frames the export leaves unlabelled while the truth has a
  hand, with the reason from ``meta.yml``'s ``label_flags``; the share of camera-frames with a
  hand in the truth that the export labels; labelled frames beyond ``--max-mm``.
- objects: ADD (mm, mean distance of the model's vertices under the exported and the true
  pose) of every ``pose_y`` row, split by ``pose_y_valid`` (trusted / flagged).
- cross-camera consistency: every ``pose_y`` row is a rotation (orthonormal, det +1) and the
  rows of one object and frame, taken to the world through each camera's extrinsics, agree
  (largest spread in mm of the model's vertices and in degrees).

Prints one JSON object on its last line.

    python bench/export_truth.py --export OUT --truth CAPTURE [--max-mm 5]
    python bench/export_truth.py --demo 24,4,2 [--seed 7] [--fault extrinsics:0.5,5]

``--demo FRAMES,VIEWS,OBJECTS`` walks the README's path in a new instance folder first: a
capture written by ``dexlabel synth --seed`` (with ``--fault`` when given), then
``dexlabel demo --no-serve`` (the simulated crowd's keyframe path, QC and the solve), then
``dexlabel export --all --format dexycb``, and checks that export against the capture's truth.
Length here: the README's small demo (24,4,2) takes about 2-4 minutes on 2 quiet cores;
``--demo 12,3,1`` about one.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _demo_path import dexlabel, run_demo, unpacked  # noqa: E402

from worker.formats import dexycb, dexycb_flags  # noqa: E402
from worker.geometry.mesh_io import read_mesh  # noqa: E402


def _yaml(path: Path) -> dict[str, Any]:
    with path.open() as f:
        loaded: dict[str, Any] = yaml.safe_load(f)
    return loaded


def _K(root: Path, serial: str) -> np.ndarray:
    entry = _yaml(next((root / dexycb.INTRINSICS_DIR).glob(f"{serial}_*.yml")))[dexycb.COLOR]
    return np.array([[entry["fx"], 0, entry["ppx"]], [0, entry["fy"], entry["ppy"]], [0, 0, 1]])


def _stats(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "median": None, "max": None}
    array = np.asarray(values)
    return {"mean": round(float(array.mean()), 3), "median": round(float(np.median(array)), 3),
            "max": round(float(array.max()), 3)}


def _hand(out_label: Any, truth_label: Any, K: np.ndarray, acc: dict[str, Any], frame: int,
          max_mm: float) -> None:
    truth = truth_label[dexycb.JOINT_3D][0].astype(np.float64)
    if (truth == dexycb.NO_LABEL).all():
        return
    acc["truth_frames"] += 1
    joint_3d = out_label[dexycb.JOINT_3D][0].astype(np.float64)
    if (joint_3d == dexycb.NO_LABEL).all():
        acc["unlabelled"].add(frame)
        return
    acc["labelled"] += 1
    error_mm = float(np.linalg.norm(joint_3d - truth, axis=1).mean() * 1000)
    acc["mm"].append(error_mm)
    acc["per_frame"].setdefault(frame, []).append(error_mm)
    uvw = truth @ K.T
    error_px = np.linalg.norm(out_label[dexycb.JOINT_2D][0] - uvw[:, :2] / uvw[:, 2:], axis=1)
    acc["px"].append(float(error_px.mean()))
    if error_mm > max_mm:
        acc["over"].add(frame)


# An object row trusted but further than this (ADD, mm) from the truth is listed by frame.
OBJECT_LIMIT_MM = 10.0


def _objects(out_label: Any, truth_label: Any, models: list[np.ndarray],
             acc: dict[str, Any], T: np.ndarray, frame: int) -> None:
    pose_y = out_label[dexycb.POSE_Y].astype(np.float64)
    valid = out_label.get(dexycb_flags.POSE_Y_VALID, np.ones(len(pose_y), np.uint8))
    truth = truth_label[dexycb.POSE_Y].astype(np.float64)
    for o, (pose, true, vertices) in enumerate(zip(pose_y, truth, models, strict=True)):
        R = pose[:, :3]
        acc["rotation_error"] = max(acc["rotation_error"],
                                    float(np.abs(R @ R.T - np.eye(3)).max()),
                                    abs(float(np.linalg.det(R)) - 1.0))
        moved = vertices @ R.T + pose[:, 3]
        add = float(np.linalg.norm(moved - (vertices @ true[:, :3].T + true[:, 3]), axis=1).mean())
        key = "trusted" if valid[o] else "flagged"
        acc["add"][o][key].append(add * 1000)
        if valid[o] and add * 1000 > acc["trusted_limit_mm"]:
            acc["trusted_over"][o].add(frame)
        world = np.concatenate([T[:, :3] @ R, (T[:, :3] @ pose[:, 3] + T[:, 3])[:, None]], axis=1)
        acc["world"].setdefault((o, frame), []).append((world, moved @ T[:, :3].T + T[:, 3]))


def _sequence(out: Path, truth: Path, seq: str, max_mm: float) -> dict[str, Any]:
    meta = _yaml(out / seq / dexycb.META_FILE)
    extrinsics = _yaml(out / dexycb.extrinsics_file(meta[dexycb.META_EXTRINSICS]))
    names = [dexycb.YCB_CLASSES[i] for i in meta[dexycb.META_YCB_IDS]]
    models = [read_mesh(out / dexycb.model_dir(n) / dexycb.MODEL_OBJ).vertices for n in names]
    hand: dict[str, Any] = {"truth_frames": 0, "labelled": 0, "mm": [], "px": [], "per_frame": {},
                            "unlabelled": set(), "over": set()}
    objects: dict[str, Any] = {"add": [{"trusted": [], "flagged": []} for _ in names],
                               "world": {}, "rotation_error": 0.0,
                               "trusted_over": [set() for _ in names],
                               "trusted_limit_mm": OBJECT_LIMIT_MM}
    for serial in meta[dexycb.META_SERIALS]:
        K = _K(out, serial)
        T = np.asarray(extrinsics[dexycb.EXTRINSICS][serial], dtype=np.float64).reshape(3, 4)
        for f in range(int(meta[dexycb.META_NUM_FRAMES])):
            name = dexycb.labels_file(f)
            with np.load(out / seq / serial / name) as got, \
                    np.load(truth / seq / serial / name) as true:
                got_d, true_d = dict(got), dict(true)
            _hand(got_d, true_d, K, hand, f, max_mm)
            _objects(got_d, true_d, models, objects, T, f)
    flags = (meta.get(dexycb_flags.META_LABEL_FLAGS) or {}).get("hand") or {}
    spread_mm, spread_deg = 0.0, 0.0
    for rows in objects["world"].values():
        stack = np.stack([pose for pose, _ in rows])
        spread_mm = max(spread_mm, float(np.linalg.norm(
            np.stack([v for _, v in rows]) - np.stack([v for _, v in rows]).mean(0),
            axis=-1).max()))
        for other in stack[1:]:
            # The angle between two rotations from their Frobenius distance (stable near 0).
            d = np.linalg.norm(other[:, :3] - stack[0][:, :3]) / (2 * np.sqrt(2))
            spread_deg = max(spread_deg, float(np.degrees(2 * np.arcsin(min(d, 1.0)))))
    per_frame = {f: round(float(np.mean(v)), 3) for f, v in sorted(hand["per_frame"].items())}
    return {
        "sequence": seq,
        "hand_mm": _stats(hand["mm"]), "hand_px": _stats(hand["px"]),
        "hand_frame_mm": per_frame,
        "labelled_share": round(hand["labelled"] / max(hand["truth_frames"], 1), 4),
        "unlabelled_frames": {int(f): flags.get(f, flags.get(str(f)))
                              for f in sorted(hand["unlabelled"])},
        "labelled_frames_over_max": sorted(int(f) for f in hand["over"]),
        "object_add_mm": {n: {k: _stats(v) | {"rows": len(v)} for k, v in add.items()}
                          for n, add in zip(names, objects["add"], strict=True)},
        # Frames where a trusted (pose_y_valid) row is more than OBJECT_LIMIT_MM ADD off.
        "object_trusted_frames_over": {n: sorted(int(f) for f in over) for n, over in
                                       zip(names, objects["trusted_over"], strict=True)},
        "pose_y_rotation_error": round(objects["rotation_error"], 6),
        "cross_camera_spread_mm": round(spread_mm * 1000, 4),
        "cross_camera_spread_deg": round(spread_deg, 4),
    }


def _demo(spec: str, seed: int, fault: str | None, scratch: Path) -> tuple[Path, Path]:
    """(export folder, truth capture) of the README's demo path in a new instance folder."""
    var = scratch / "var"
    truth = run_demo(spec, seed, fault, var)
    out = scratch / "export"
    dexlabel(var, "export", "--all", "--format", "dexycb", "--out", str(out))
    return out, truth


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="--export/--truth reads in seconds; --demo 24,4,2 takes 2-4 minutes here, "
               "--demo 12,3,1 about one.")
    parser.add_argument("--export", type=Path, help="a DexYCB export (folder, .zip or .tar)")
    parser.add_argument("--truth", type=Path, help="the synthetic capture it came from")
    parser.add_argument("--demo", help="FRAMES,VIEWS,OBJECTS: run the README's demo path first")
    parser.add_argument("--seed", type=int, default=7, help="--demo: the capture's seed")
    parser.add_argument("--fault", help="--demo: a rig fault for dexlabel synth --fault")
    parser.add_argument("--max-mm", type=float, default=5.0)
    parser.add_argument("--keep", type=Path, default=None,
                        help="--demo: run it in this folder and keep it (instance, export)")
    args = parser.parse_args()
    if args.demo is None and (args.export is None or args.truth is None):
        parser.error("give --export and --truth, or --demo FRAMES,VIEWS,OBJECTS")
    with tempfile.TemporaryDirectory() as scratch:
        if args.demo is not None:
            args.export, args.truth = _demo(args.demo, args.seed, args.fault,
                                            args.keep or Path(scratch) / "demo")
        out = unpacked(args.export, Path(scratch))
        sequences = sorted(str(p.parent.relative_to(out)) for p in out.glob(dexycb.META_GLOB))
        if not sequences:
            sys.exit(f"{args.export}: no {dexycb.META_FILE} in the DexYCB layout")
        results = [_sequence(out, args.truth, seq, args.max_mm) for seq in sequences]
    for r in results:
        print(f"{r['sequence']}: hand {r['hand_mm']['mean']} mm mean, {r['hand_mm']['max']} max, "
              f"{r['labelled_share']:.1%} of camera-frames labelled, "
              f"{len(r['labelled_frames_over_max'])} labelled frames over {args.max_mm} mm")
    # The figures the acceptance reads, over every sequence: the worst labelled share, the mean
    # hand error of labelled frames, and labelled frames beyond --max-mm.
    summary = {"hand_mm_mean": max((r["hand_mm"]["mean"] or 0.0) for r in results),
               "labelled_share_min": min(r["labelled_share"] for r in results),
               "labelled_frames_over_max": sum(len(r["labelled_frames_over_max"])
                                               for r in results),
               "cross_camera_spread_mm": max(r["cross_camera_spread_mm"] for r in results),
               "object_trusted_frames_over": sum(len(f) for r in results
                                                 for f in r["object_trusted_frames_over"].values())}
    print(json.dumps({"max_mm": args.max_mm, "demo": args.demo, "seed": args.seed,
                      "fault": args.fault, "summary": summary, "sequences": results}))


if __name__ == "__main__":
    main()
