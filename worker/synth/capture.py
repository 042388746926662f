"""Synthetic DexYCB-layout captures with exact ground truth: ``generate_capture``.

Layout written under OUT (the DexYCB raw layout; ``WxH`` is the image size, 640x480 by default)::

    calibration/intrinsics/<serial>_<W>x<H>.yml    color/depth: fx fy ppx ppy width height coeffs
    calibration/extrinsics_<extr>/extrinsics.yml   extrinsics: {serial: 12 floats}, master
    calibration/mano_<calib>/mano.yml              betas: 10 floats
    models/<ycb name>/textured_simple.obj (+ .obj.mtl, texture_map.png)
    <subject>/<sequence>/meta.yml, pose.npz, <serial>/{color,aligned_depth_to_color,labels}_*

Frames. The scene is built in a table frame (z up, origin on the table top), but the capture's
world frame is the **master camera's frame**, as in DexYCB and as dexlabel's design states: the
master's extrinsics are the identity and every other camera's are camera-to-master. ``pose.npz``
(``pose_y`` object-to-world, ``pose_m``) is in that world frame; labels are in each camera's frame.
The master is the first serial. Extrinsics are camera-to-world 3x4, row-major, metres.

Names: subject ``synth-subject-01``, sequence ``synth_<seed:06d>``, extrinsics
``synth_<seed:06d>``, MANO calibration ``synth_<seed:06d>_synth-subject-01_right``, serials from
``worker.synth.scene.make_serials``. The same seed gives byte-identical files.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np

from worker.formats.dexycb import HAND_SEG_VALUE
from worker.geometry.transforms import (
    compose_poses,
    invert_pose,
    transform_points,
    transform_pose_m,
)
from worker.synth.forearm import forearm_meshes
from worker.synth.grasp import build_shaped_hand, plan_grasp
from worker.synth.layout import (
    LabelSet,
    camera_labels,
    write_calibration,
    write_models,
    write_sequence_files,
)
from worker.synth.motion import build_trajectory, make_keyframes
from worker.synth.render import DEFAULT_LIGHTING, varied_lighting
from worker.synth.scene import build_meshes, make_cameras, make_serials, place_objects
from worker.synth.shapes import CATALOGUE
from worker.synth.views import ViewJob, run_view_job

SUBJECT = "synth-subject-01"
_LIGHT_STREAM = 1  # the varied light's generator: default_rng([seed, _LIGHT_STREAM])


@dataclass(frozen=True)
class SynthSummary:
    """What :func:`generate_capture` wrote.

    Attributes:
        root: the capture folder (OUT). subject, sequence: names under it.
        serials: camera serials, master first. num_frames: frames per camera.
        ycb_ids: object class ids in meta.yml order (the grasped one is meta's ycb_grasp_ind).
    """

    root: Path
    subject: str
    sequence: str
    serials: list[str]
    num_frames: int
    ycb_ids: list[int]


def _check_args(seed: int, frames: int, views: int, objects: int, width: int, height: int
                ) -> None:
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if frames < 2:
        raise ValueError(f"frames must be >= 2, got {frames}")
    if views < 1:
        raise ValueError(f"views must be >= 1, got {views}")
    if not 1 <= objects <= len(CATALOGUE):
        raise ValueError(f"objects must be in [1, {len(CATALOGUE)}], got {objects}")
    if width < 32 or height < 32:
        raise ValueError(f"image size must be at least 32x32, got {width}x{height}")


def _target_yaw(rng: np.random.Generator, ycb_id: int, finger_yaw: float) -> float:
    """Yaw of the grasped object: a box turns its thin side towards the palm (side grasp) or
    its x axis along the fingers (top grasp); cans are symmetric anyway."""
    spec = CATALOGUE[ycb_id]
    jitter = rng.uniform(-0.12, 0.12)
    if spec.size[2] < 0.06:
        return np.pi / 2.0 - finger_yaw + jitter
    palm_normal_yaw = np.arctan2(np.sin(finger_yaw), -np.cos(finger_yaw))
    thin_axis_is_x = spec.size[0] <= spec.size[1]
    return palm_normal_yaw + (0.0 if thin_axis_is_x else -np.pi / 2.0) + jitter


def _worker_count(views: int, workers: int | None) -> int:
    if workers is not None:
        return max(1, min(workers, views))
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(views, cores or 1))


def _single_threaded() -> None:
    """Worker processes already run in parallel; OpenCV's own threads would only contend."""
    cv2.setNumThreads(1)


def _render_all(jobs: list[ViewJob], workers: int) -> None:
    if workers == 1:
        for job in jobs:
            run_view_job(job, HAND_SEG_VALUE)
        return
    # spawn, not fork: the parent's OpenCV and torch thread pools do not survive a fork (the
    # children hang). As with any spawn pool, a calling script needs a __main__ guard.
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn"),
                             initializer=_single_threaded) as pool:
        list(pool.map(run_view_job, jobs, [HAND_SEG_VALUE] * len(jobs)))


def generate_capture(out: Path, *, seed: int = 0, frames: int = 72, views: int = 8,
                     objects: int = 3, width: int = 640, height: int = 480,
                     workers: int | None = None, forearm: bool = False,
                     varied_light: bool = False) -> SynthSummary:
    """Write a synthetic capture of a right hand grasping and lifting one of ``objects`` objects.

    Args:
        out: capture folder to create; must not exist yet or be empty. Files are written to a
            sibling ``.partial`` folder first and moved into place only when complete.
        seed: scene seed (>= 0); the same seed gives byte-identical files.
        frames, views, objects: frames per camera (>= 2), cameras, objects on the table.
        width, height: image size, pixels (intrinsics scale with the width).
        workers: processes rendering views in parallel (default: the CPUs available); more
            than one starts a spawn pool, so a calling script needs ``if __name__ == "__main__"``.
        forearm: also draw a forearm and sleeve from the wrist (worker.synth.forearm), closer to
            real footage; the truth is unchanged and the default renders stay as they were.
        varied_light: light the scene with a room's light drawn from the seed
            (worker.synth.render.varied_lighting: more ambient, the lamp anywhere above)
            instead of the fixed default; drawn apart from the scene, which stays the same.

    Returns:
        A :class:`SynthSummary` of what was written.
    """
    _check_args(seed, frames, views, objects, width, height)
    out = Path(out).resolve()
    with written_whole(out) as partial:
        return _generate(partial, out, seed, frames, views, objects, width, height, workers,
                         forearm, varied_light)


@contextmanager
def written_whole(out: Path) -> Iterator[Path]:
    """A sibling ``.partial`` folder to write the folder ``out`` into, moved into place when the
    block ends and removed on any error, so ``out`` is never half-written. ``out`` must not
    exist or be an empty folder (FileExistsError otherwise)."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out} exists and is not an empty folder")
    partial = out.with_name(out.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    try:
        yield partial
        if out.exists():
            out.rmdir()
        partial.rename(out)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise


def _generate(tmp: Path, out: Path, seed: int, frames: int, views: int, objects: int,
              width: int, height: int, workers: int | None, forearm: bool,
              varied_light: bool) -> SynthSummary:
    rng = np.random.default_rng(seed)
    serials = make_serials(seed, views)
    cams = make_cameras(rng, serials, width, height)
    ycb_ids = [int(i) for i in rng.choice(sorted(CATALOGUE), objects, replace=False)]
    grasp_ind = int(rng.integers(objects))
    rig = build_shaped_hand(rng.normal(0.0, 0.6, 10))
    finger_yaw = float(rng.uniform(-0.35, 0.35))
    placed = place_objects(rng, ycb_ids, grasp_ind,
                           _target_yaw(rng, ycb_ids[grasp_ind], finger_yaw))
    grasp = plan_grasp(rig, placed[grasp_ind], finger_yaw)
    keys = make_keyframes(rng, rig, grasp)
    start = np.stack([p.T_obj_to_table for p in placed])
    traj = build_trajectory(rig, keys, start, grasp_ind, frames)
    hand_vertices, joints = rig.evaluate(traj.pose_m)

    # World = master camera frame.
    table_to_world = invert_pose(cams[0].T_cam_to_table)
    extrinsics = [compose_poses(table_to_world, c.T_cam_to_table) for c in cams]
    extrinsics[0] = np.eye(3, 4)
    world = LabelSet(
        pose_y=compose_poses(table_to_world, traj.object_poses),
        pose_m=transform_pose_m(traj.pose_m, table_to_world, rig.root),
        joints=transform_points(table_to_world, joints),
    )
    names = {"subject": SUBJECT, "sequence": f"synth_{seed:06d}",
             "extrinsics": f"synth_{seed:06d}",
             "mano_calib": f"synth_{seed:06d}_{SUBJECT}_right"}
    write_calibration(tmp, cams, extrinsics, names, rig.betas, width, height)
    table, object_meshes, textures, skin = build_meshes(rng, [p.spec for p in placed])
    write_models(tmp, [p.spec for p in placed], textures[1:])
    seq_dir = write_sequence_files(tmp, names, serials, ycb_ids, grasp_ind, world, frames)
    arm = tuple(forearm_meshes(joints, skin)) if forearm else ()
    # A generator of its own, so that the scene drawn from ``rng`` is the same either way.
    lighting = (varied_lighting(np.random.default_rng([seed, _LIGHT_STREAM])) if varied_light
                else DEFAULT_LIGHTING)
    jobs = []
    for v, cam in enumerate(cams):
        (seq_dir / cam.serial).mkdir()
        jobs.append(ViewJob(
            seed, v, seq_dir / cam.serial, cam, width, height, table, object_meshes,
            traj.object_poses, hand_vertices, np.asarray(rig.model.faces), skin,
            camera_labels(world, extrinsics[v], cam, rig.root), textures, arm, lighting))
    _render_all(jobs, _worker_count(views, workers))
    return SynthSummary(out, names["subject"], names["sequence"], serials, frames, ycb_ids)
