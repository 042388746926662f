"""Rig health under injected rig faults: hand MPJPE of the solve before and after adopting the
refined calibration, and the cameras the report names.

A synthetic capture (`--capture DIR`, read through bench/solve.py's cache) is labelled with
careful labels (bench/solve.py's load_inputs: the true 2D joints with `--sigma` px Gaussian
noise per frame; landmarks likewise) and one fault is applied to what the product sees, the
truth unchanged: `ext0.2_2` / `ext0.5_5` (every camera but the master rotated by 0.2 / 0.5
degrees about a random axis and moved 2 / 5 mm), `late1` / `late2` (cameras 1 / 1-2 one frame
late: labels, landmarks and depth), `scale` (camera 3's depth 1 % long), `shift` (camera 5's,
or the last one's with fewer than 6, depth moved 3 px right, 2 px down against colour),
`betas` (the subject's hand shape replaced by betas drawn from N(0, 0.6^2), another
subject's) or `none`. The rig is estimated from the
faulty inputs (worker.rig.estimate_rig, with three colour frames per view), its corrections
applied as an adopted version would be (backend/solve/calibrated.py), the hand shape checked
against the labels' bones (worker.hand.calibrate.check_shape: the fitted betas are adopted
where the shape is named off), and both are solved.
One JSON object per run on the last line.

    python bench/rig_faults.py --capture DIR --fault late1 [--crowd-seed 11] [--cache DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from solve import build_cache, load_inputs  # noqa: E402

from backend.captures.layout import read_sequence  # noqa: E402
from worker.geometry.transforms import axis_angle_to_matrix, make_pose  # noqa: E402
from worker.hand.calibrate import check_shape, triangulate_joints  # noqa: E402
from worker.hand.model import load_hand_model  # noqa: E402
from worker.rig import apply_depth_correction, apply_time_offsets, estimate_rig  # noqa: E402
from worker.rig.common import shift_frames  # noqa: E402
from worker.solver import SolveSettings, solve  # noqa: E402

FAULTS = ("none", "ext0.2_2", "ext0.5_5", "late1", "late2", "scale", "shift", "betas")
# Another subject's hand shape: betas drawn from the shape space (worker.synth.faults' default).
BETAS_SIGMA = 0.6


def _perturb(cam, deg, mm, rng):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    move = rng.normal(size=3)
    move /= np.linalg.norm(move)
    rot = axis_angle_to_matrix(axis * np.radians(deg)) @ cam.T_cam_to_world[:, :3]
    return replace(cam, T_cam_to_world=make_pose(rot, cam.T_cam_to_world[:, 3] + move * mm / 1e3))


def _shift_views(inp, offsets):
    """Labels, landmarks and depth of each view re-indexed: out[t] = data[t + offset]."""
    kp, vis = apply_time_offsets(inp.hand.keypoints, inp.hand.visible, offsets)
    depth = [shift_frames(np.asarray(d), o, 0) if o else np.asarray(d)
             for d, o in zip(inp.depth, offsets, strict=True)]
    objects = [replace(o, landmarks=[replace(m, xy=shift_frames(m.xy, offsets[m.view]),
                                             visible=shift_frames(m.visible, offsets[m.view],
                                                                  False))
                                     for m in o.landmarks]) for o in inp.objects]
    return replace(inp, hand=replace(inp.hand, keypoints=kp, visible=vis), depth=depth,
                   objects=objects)


def _late_offsets(fault: str, views: int) -> list[int]:
    """Per view, the re-indexing a ``late`` fault applies (-1: one frame late), else 0."""
    late = range(1, 1 + int(fault[4:])) if fault.startswith("late") else range(0)
    return [-1 if v in late else 0 for v in range(views)]


def inject(inp, fault, rng):
    """The inputs the product sees under ``fault``."""
    views = len(inp.cameras)
    if fault.startswith("ext"):
        deg, mm = (float(x) for x in fault[3:].split("_"))
        return replace(inp, cameras=[inp.cameras[0]] + [_perturb(c, deg, mm, rng)
                                                        for c in inp.cameras[1:]])
    if fault.startswith("late"):
        return _shift_views(inp, _late_offsets(fault, views))
    if fault == "betas":
        betas = rng.normal(0.0, BETAS_SIGMA, np.shape(inp.hand.betas))
        return replace(inp, hand=replace(inp.hand, betas=betas))
    depth = [np.asarray(d) for d in inp.depth]
    if fault == "scale":
        depth[3] = np.clip(np.rint(depth[3] * 1.01), 0, 65535).astype(np.uint16)
    elif fault == "shift":
        view = min(5, views - 1)
        moved = np.zeros_like(depth[view])
        moved[:, 2:, 3:] = depth[view][:, :-2, :-3]
        depth[view] = moved
    return replace(inp, depth=depth)


def hand_errors(inputs, truth) -> dict:
    """Hand MPJPE (mm) of the default solve, its worst frame, the frames over 5 mm and how
    many of those the solve flags (result.hand_flags)."""
    result = solve(inputs, SolveSettings())
    lab = result.labelled
    per_frame = np.linalg.norm(result.hand_joints[lab] - truth["joints"][lab],
                               axis=-1).mean(axis=1) * 1000.0
    flags = np.asarray([result.hand_flags[f] if f < len(result.hand_flags) else None
                        for f in np.flatnonzero(lab)], dtype=object)
    over = per_frame > 5.0
    return {"mpjpe_mm": round(float(per_frame.mean()), 3),
            "worst_frame_mm": round(float(per_frame.max()), 3),
            "over_5mm": int(over.sum()),
            "over_5mm_flagged": int(sum(1 for f in flags[over] if f)),
            "flagged": int(sum(1 for f in flags if f))}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        epilog="One fault on an 8 x 24 capture takes 2-5 minutes here (two solves); a capture "
               "of 4 views x 12 frames (the smoke run's) about one.")
    parser.add_argument("--capture", type=Path, required=True)
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument("--fault", choices=FAULTS, required=True)
    parser.add_argument("--crowd-seed", type=int, default=11)
    parser.add_argument("--sigma", type=float, default=2.0)
    args = parser.parse_args()
    cache = args.cache or args.capture.with_name(args.capture.name + "_cache")
    cache.mkdir(parents=True, exist_ok=True)
    if not (cache / "truth.npz").exists():
        build_cache(args.capture, cache)
    frames = int(np.load(cache / "truth.npz")["joint_2d"].shape[1])
    inputs, truth = load_inputs(cache, frames, args.sigma, 0.0, args.crowd_seed)
    seq_dir = next(p for p in args.capture.glob("*/*") if (p / "meta.yml").is_file())
    picks = sorted({0, frames // 2, frames - 1})
    started = time.time()
    # A late camera is late in colour too: its frame f shows what the others show at f - 1.
    lag = _late_offsets(args.fault, len(inputs.cameras))
    color = [{f: cv2.imread(str(seq_dir / c.serial / f"color_{f + o:06d}.jpg")) for f in picks
              if 0 <= f + o < frames}
             for c, o in zip(read_sequence(seq_dir).cameras, lag, strict=True)]
    faulty = inject(inputs, args.fault, np.random.default_rng(1000 + args.crowd_seed))
    before = hand_errors(faulty, truth)
    out = {"fault": args.fault, "views": len(inputs.cameras), "frames": frames,
           "crowd_seed": args.crowd_seed, "mpjpe_faulty_mm": before.pop("mpjpe_mm"),
           "faulty": before}
    est = estimate_rig(faulty.cameras, faulty.hand.keypoints, faulty.hand.visible,
                       [np.asarray(d) for d in faulty.depth], color)
    offsets = [h.time_offset_frames for h in est.health]
    fixed = _shift_views(replace(faulty, cameras=est.cameras), offsets)
    fixed = replace(fixed, depth=[
        apply_depth_correction(np.asarray(d), 0, h.depth_scale or 1.0, h.depth_shift_px or (0, 0))
        for d, h in zip(fixed.depth, est.health, strict=True)])
    out["named"] = {h.view: h.faults for h in est.health if h.faults}
    shape = check_shape(triangulate_joints(est.cameras, fixed.hand.keypoints, fixed.hand.visible),
                        fixed.hand.betas, load_hand_model("right"))
    out["shape_bone_diff_mm"] = round(shape.median_diff_mm, 2)
    if shape.fault() is not None:
        out["named"]["hand"] = [shape.fault()]
        fixed = replace(fixed, hand=replace(fixed.hand, betas=shape.fit.betas))
    after = hand_errors(fixed, truth)
    out["mpjpe_refined_mm"] = after.pop("mpjpe_mm")
    out["refined"] = after
    out["seconds"] = round(time.time() - started, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
