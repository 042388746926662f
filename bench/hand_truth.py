"""Per-frame hand error of a stored solve result against a synthetic capture's ground truth.

Reads a solve result npz (backend.solve.results) and the capture it was solved from (the
DexYCB layout `dexlabel synth` writes, with labels_%06d.npz per camera and frame), and
prints per frame the MPJPE (mm, world frame) of the solved hand joints, whether the frame is
labelled and flagged (`hand_flags`, "" = trusted; results without it read as all trusted),
then one JSON summary line: mean, median and max error over trusted frames, the trusted
frames over 5 mm, frames flagged and the share of camera-frames the export labels (a trusted
hand frame is labelled in every view).

    python bench/hand_truth.py RESULT.npz CAPTURE_DIR
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.captures.layout import read_sequence  # noqa: E402
from backend.solve.results import decode_result  # noqa: E402

LIMIT_MM = 5.0


def truth_joints(capture: Path) -> tuple[np.ndarray, int]:
    """(F, 21, 3) true joints in the world (master camera) frame, metres; number of views."""
    seq_dir = next(p for p in capture.glob("*/*") if (p / "meta.yml").is_file())
    plan = read_sequence(seq_dir)
    master = next(c for c in plan.cameras if np.allclose(np.array(c.extrinsics), np.eye(3, 4)))
    out = np.stack([np.load(seq_dir / master.serial / f"labels_{f:06d}.npz")["joint_3d"][0]
                    for f in range(plan.num_frames)])
    return out, len(plan.cameras)


def compare(arrays: dict[str, np.ndarray], truth: np.ndarray) -> tuple[list[dict], dict]:
    """Per-frame rows and the summary (see the module docstring)."""
    joints = arrays["hand_joints"]
    frames = min(len(joints), len(truth))
    flags = arrays.get("hand_flags", np.full(frames, "", dtype=str))
    labelled = arrays["labelled"].astype(bool)
    error = np.linalg.norm(joints[:frames] - truth[:frames], axis=-1).mean(axis=1) * 1000.0
    rows = [{"frame": f, "mpjpe_mm": round(float(error[f]), 2), "labelled": bool(labelled[f]),
             "flag": str(flags[f])} for f in range(frames)]
    trusted = labelled[:frames] & (flags[:frames] == "") & np.isfinite(error)
    kept = error[trusted]
    every = error[np.isfinite(error)]
    summary = {
        "frames": frames, "trusted_frames": int(trusted.sum()),
        "flagged_frames": int((labelled[:frames] & (flags[:frames] != "")).sum()),
        "mean_mm_trusted": round(float(kept.mean()), 2) if kept.size else None,
        "median_mm_trusted": round(float(np.median(kept)), 2) if kept.size else None,
        "max_mm_trusted": round(float(kept.max()), 2) if kept.size else None,
        "trusted_over_5mm": int((kept > LIMIT_MM).sum()),
        "mean_mm_all": round(float(every.mean()), 2) if every.size else None,
        "max_mm_all": round(float(every.max()), 2) if every.size else None,
        "camera_frames_labelled": round(float(trusted.mean()), 3),
    }
    return rows, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result", type=Path, help="a solve run's result.npz")
    parser.add_argument("capture", type=Path, help="the synthetic capture folder")
    args = parser.parse_args()
    arrays = decode_result(args.result.read_bytes())
    truth, _ = truth_joints(args.capture)
    rows, summary = compare(arrays, truth)
    for row in rows:
        print(json.dumps(row))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
