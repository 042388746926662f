"""Benchmark of the 3D solver on a synthetic capture with simulated crowd labels.

Generates (once, cached) the default synthetic capture (seed 7: 8 views, 72 frames, 1 hand,
3 objects), reads its calibration, models, depth and ground truth, simulates annotations
(hand keypoints = ground-truth joint_2d + Gaussian noise, visibility from the ground-truth
segmentation; 2 landmarks per object per view on ground-truth mesh vertices, projected), and
solves with both optimisers. Each run happens in its own process so that its time and peak
memory are its own. Prints one JSON object on its last line.

    python bench/solve.py [--frames N] [--paper-frames M] [--sigma 3] [--gross 0.05]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import resource
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.captures.layout import read_sequence  # noqa: E402
from worker.geometry.cameras import CameraModel, intrinsics_matrix  # noqa: E402
from worker.geometry.mesh_io import read_mesh  # noqa: E402
from worker.hand.joints import JOINT_NAMES, TIP_NAMES  # noqa: E402
from worker.synth.annotators import hand_visibility, mesh_landmarks  # noqa: E402
from worker.synth.capture import generate_capture  # noqa: E402

SEED = 7
TIPS = [JOINT_NAMES.index(t) for t in TIP_NAMES]


def capture_dir(work: Path) -> Path:
    """The cached default capture under `work`, generated on first use."""
    out = work / f"synth_seed{SEED}"
    if not out.is_dir():
        generate_capture(out, seed=SEED)
    return out


def build_cache(capture: Path, cache: Path) -> None:
    """Read the capture once into arrays the runs share: depth (V, F, H, W) uint16 as .npy and
    everything else (cameras, meshes, truth, label visibility) in truth.npz."""
    seq_dir = next(p for p in capture.glob("*/*") if (p / "meta.yml").is_file())
    plan = read_sequence(seq_dir)
    meta = yaml.safe_load((seq_dir / "meta.yml").read_text())
    frames, views = plan.num_frames, len(plan.cameras)
    cams = [CameraModel(intrinsics_matrix(c.fx, c.fy, c.ppx, c.ppy), np.array(c.distortion),
                        np.array(c.extrinsics), c.width, c.height) for c in plan.cameras]
    depth = np.zeros((views, frames, cams[0].height, cams[0].width), np.uint16)
    joint_2d = np.zeros((views, frames, 21, 2))
    segs = np.zeros((views, frames, cams[0].height, cams[0].width), np.uint8)
    pose_y = np.zeros((frames, len(plan.objects), 3, 4))
    joints_world = np.zeros((frames, 21, 3))
    for v, cam in enumerate(plan.cameras):
        for f in range(frames):
            folder = seq_dir / cam.serial
            depth[v, f] = cv2.imread(str(folder / f"aligned_depth_to_color_{f:06d}.png"),
                                     cv2.IMREAD_ANYDEPTH)
            with np.load(folder / f"labels_{f:06d}.npz") as lab:
                joint_2d[v, f] = lab["joint_2d"][0]
                segs[v, f] = lab["seg"]
                if v == 0:  # the master camera's frame is the world frame
                    joints_world[f] = lab["joint_3d"][0]
                    pose_y[f] = lab["pose_y"]
    assert np.allclose(cams[0].T_cam_to_world, np.eye(3, 4))
    with np.load(seq_dir / "pose.npz") as npz:
        pose_m = npz["pose_m"][:, 0].astype(np.float64)
    np.save(cache / "depth.npy", depth)
    arrays = {"K": np.stack([c.K for c in cams]), "dist": np.stack([c.dist for c in cams]),
              "T": np.stack([c.T_cam_to_world for c in cams]), "joint_2d": joint_2d,
              "hand_visible": np.stack([hand_visibility(joint_2d[v], segs[v])
                                        for v in range(views)]),
              "joints_world": joints_world, "pose_y": pose_y, "pose_m": pose_m,
              "betas": np.array(plan.hands[0].betas), "ycb_ids": np.array(meta["ycb_ids"]),
              "size": np.array([cams[0].width, cams[0].height])}
    rng = np.random.default_rng(SEED)
    for o, obj in enumerate(plan.objects):
        mesh = read_mesh(obj.mesh_path)
        vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int)
        arrays[f"obj{o}_vertices"], arrays[f"obj{o}_faces"] = vertices, faces
        arrays[f"obj{o}_initial"] = np.array(obj.initial_pose)
        arrays[f"obj{o}_marks"], arrays[f"obj{o}_markvis"] = _pick_landmarks(
            cams, segs, int(meta["ycb_ids"][o]), vertices, faces, pose_y[:, o], rng)
    np.savez(cache / "truth.npz", **arrays)


def _pick_landmarks(cams, segs, value, vertices, faces, poses, rng):
    """Per view, 2 vertices visible where the object first shows; (V, 2) ids, (V, 2, F) vis."""
    views, frames = segs.shape[:2]
    ids = np.full((views, 2), -1)
    vis = np.zeros((views, 2, frames), bool)
    for v, cam in enumerate(cams):
        _, seen, ids[v] = mesh_landmarks(cam, segs[v], value, vertices, faces, poses, rng)
        vis[v] = seen.T
    return ids, vis


def load_inputs(cache: Path, frames: int, sigma: float, gross: float, seed: int):
    """SolveInputs with simulated labels for the first `frames` frames, plus ground truth."""
    from worker.solver import HandTarget, Landmark, ObjectTarget, SolveInputs

    t = dict(np.load(cache / "truth.npz"))
    depth = np.load(cache / "depth.npy", mmap_mode="r")
    width, height = (int(x) for x in t["size"])
    cams = [CameraModel(K, d, T, width, height) for K, d, T in zip(t["K"], t["dist"], t["T"],
                                                                    strict=True)]
    rng = np.random.default_rng(seed)
    keypoints = t["joint_2d"][:, :frames] + rng.normal(0.0, sigma, t["joint_2d"][:, :frames].shape)
    visible = t["hand_visible"][:, :frames].copy()
    keypoints = _corrupt(keypoints, visible, gross, width, height, rng)
    hand = HandTarget("right", t["betas"], keypoints, visible)
    objects = []
    for o in range(len(t["ycb_ids"])):
        verts, poses = t[f"obj{o}_vertices"], t["pose_y"][:frames, o]
        marks = []
        for v, cam in enumerate(cams):
            for k, vid in enumerate(t[f"obj{o}_marks"][v]):
                if vid < 0:
                    continue
                world = np.einsum("fij,j->fi", poses[:, :, :3], verts[vid]) + poses[:, :, 3]
                xy = cam.project(world) + rng.normal(0.0, sigma, (frames, 2))
                vis = t[f"obj{o}_markvis"][v, k, :frames].copy()
                xy = _corrupt(xy, vis, gross, width, height, rng)
                xy[~vis] = np.nan
                marks.append(Landmark(v, xy, vis))
        objects.append(ObjectTarget(str(o), verts, t[f"obj{o}_faces"], t[f"obj{o}_initial"],
                                    marks))
    inputs = SolveInputs(cams, frames, hand, objects, [depth[v, :frames] for v in range(len(cams))])
    truth = {"joints": t["joints_world"][:frames], "pose_y": t["pose_y"][:frames]}
    return inputs, truth


def _corrupt(xy, visible, fraction, width, height, rng):
    """Replace `fraction` of the visible labels in xy (..., 2) by uniform random pixels."""
    if fraction <= 0:
        return xy
    xy = xy.copy()
    hit = visible & (rng.random(visible.shape) < fraction)
    xy[hit] = rng.uniform([0, 0], [width, height], (int(hit.sum()), 2))
    return xy


def _add_mm(vertices: np.ndarray, solved: np.ndarray, truth: np.ndarray) -> float:
    """Mean over frames and vertices of the distance between the posed models, mm."""
    a = np.einsum("fij,nj->fni", solved[:, :, :3], vertices) + solved[:, None, :, 3]
    b = np.einsum("fij,nj->fni", truth[:, :, :3], vertices) + truth[:, None, :, 3]
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1000.0)


def run_config(cache: str, frames: int, sigma: float, gross: float, optimiser: str,
               device: str, seed: int, threads: int) -> dict:
    """One solve in this process: accuracy against ground truth, time, peak memory."""
    import torch

    from worker.solver import SolveSettings, solve
    from worker.solver.triangulate import triangulate

    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    inputs, truth = load_inputs(Path(cache), frames, sigma, gross, seed)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    start = time.perf_counter()
    result = solve(inputs, SolveSettings(optimiser=optimiser, device=device))
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    lab = result.labelled
    err = np.linalg.norm(result.hand_joints[lab] - truth["joints"][lab], axis=-1) * 1000.0
    tri, ok = triangulate(inputs.cameras, inputs.hand.keypoints, inputs.hand.visible, None)
    tri_err = np.linalg.norm(tri - truth["joints"], axis=-1)[ok & lab[:, None]] * 1000.0
    tri_r, ok_r = triangulate(inputs.cameras, inputs.hand.keypoints, inputs.hand.visible, 8.0)
    tri_r_err = np.linalg.norm(tri_r - truth["joints"], axis=-1)[ok_r & lab[:, None]] * 1000.0
    tips = result.kpt_error_px[:, :, TIPS]
    add = [_add_mm(o.vertices, result.object_poses[i], truth["pose_y"][:, i])
           for i, o in enumerate(inputs.objects)]
    return {
        "optimiser": optimiser, "frames": frames, "gross_fraction": gross, "threads": threads,
        "labelled_frames": int(lab.sum()),
        "mpjpe_mm": float(err.mean()),
        "triangulation_mpjpe_mm": float(tri_err.mean()),
        "triangulation_robust_mpjpe_mm": float(tri_r_err.mean()),
        "object_add_mm": [round(a, 3) for a in add], "object_add_mm_mean": float(np.mean(add)),
        "fingertip_reproj_px_mean_std": {
            n: [float(np.nanmean(tips[:, :, k])), float(np.nanstd(tips[:, :, k]))]
            for k, n in enumerate(TIP_NAMES)},
        "fingertip_reproj_px_mean": float(np.nanmean(tips)),
        "depth_rms_mm_mean": float(np.nanmean(result.depth_rms_mm)),
        "seconds": seconds, "seconds_per_frame": seconds / frames,
        "peak_rss_mb": peak, "rss_before_solve_mb": before,
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
    }


def _child(queue, kwargs) -> None:
    queue.put(run_config(**kwargs))


def in_process(**kwargs) -> dict:
    """run_config in a fresh spawned process (own timing and peak memory)."""
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue, kwargs))
    proc.start()
    out = queue.get()
    proc.join()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="/tmp/dexlabel_bench", help="cache folder")
    parser.add_argument("--frames", type=int, default=72, help="frames for the default runs")
    parser.add_argument("--paper-frames", type=int, default=8,
                        help="frames (from 0) the paper optimiser is timed on")
    parser.add_argument("--sigma", type=float, default=3.0, help="label noise, px")
    parser.add_argument("--gross", type=float, default=0.05, help="gross-error fraction")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch intra-op threads (1 suits a small shared machine)")
    parser.add_argument("--skip-paper", action="store_true")
    args = parser.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    capture = capture_dir(work)
    cache = work / f"arrays_seed{SEED}"
    if not (cache / "truth.npz").is_file():
        cache.mkdir(exist_ok=True)
        build_cache(capture, cache)
    common = {"cache": str(cache), "sigma": args.sigma, "device": args.device, "seed": args.seed,
              "threads": args.threads}
    runs = {"default_clean": in_process(frames=args.frames, gross=0.0, optimiser="default",
                                        **common)}
    runs["default_gross"] = in_process(frames=args.frames, gross=args.gross,
                                       optimiser="default", **common)
    summary = {"capture": str(capture), "sigma_px": args.sigma, "runs": runs}
    if not args.skip_paper:
        m = args.paper_frames
        runs["paper_subset"] = in_process(frames=m, gross=0.0, optimiser="paper", **common)
        runs["default_subset"] = in_process(frames=m, gross=0.0, optimiser="default", **common)
        summary["paper_seconds_per_frame"] = runs["paper_subset"]["seconds_per_frame"]
        summary["paper_seconds_extrapolated_72"] = runs["paper_subset"]["seconds_per_frame"] * 72
        summary["paper_timing_note"] = (f"paper optimiser timed on frames 0..{m - 1} and "
                                        "extrapolated linearly (it solves frames one by one)")
        summary["speed_ratio_paper_over_default"] = (
            runs["paper_subset"]["seconds_per_frame"] / runs["default_clean"]["seconds_per_frame"])
        summary["speed_ratio_same_frames"] = (
            runs["paper_subset"]["seconds_per_frame"]
            / runs["default_subset"]["seconds_per_frame"])
        summary["same_frames_accuracy"] = {
            name: {"mpjpe_mm": runs[f"{name}_subset"]["mpjpe_mm"],
                   "object_add_mm_mean": runs[f"{name}_subset"]["object_add_mm_mean"]}
            for name in ("paper", "default")}
    clean = runs["default_clean"]["mpjpe_mm"]
    summary["gross_over_clean_mpjpe"] = runs["default_gross"]["mpjpe_mm"] / clean
    summary["default_total_seconds"] = runs["default_clean"]["seconds"]
    summary["targets"] = {
        "mpjpe_le_5mm": runs["default_clean"]["mpjpe_mm"] <= 5.0,
        "mpjpe_below_triangulation": (runs["default_clean"]["mpjpe_mm"]
                                      < runs["default_clean"]["triangulation_mpjpe_mm"]),
        "add_le_5mm": max(runs["default_clean"]["object_add_mm"]) <= 5.0,
        "gross_within_1_5x": summary["gross_over_clean_mpjpe"] <= 1.5,
        "default_capture_under_60s": runs["default_clean"]["seconds"] < 60.0,
    }
    if "speed_ratio_paper_over_default" in summary:
        summary["targets"]["speed_ratio_ge_10x"] = summary["speed_ratio_paper_over_default"] >= 10
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
