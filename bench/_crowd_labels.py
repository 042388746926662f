"""Hand labels through the simulated crowd's keyframe path, for bench/solve.py.

Instead of i.i.d. noise on every frame, each view is labelled by one simulated worker
(worker.synth.annotators: keyframes, linear interpolation in between), and, like the product's
solve (backend.solve.inputs), its interpolated stretches are checked against the view's own
images (worker.assist.stretches): contradicted positions are dropped and the evidence codes
go to the solve's hand confidence. ``every4`` keys every 4th frame whatever the motion (a worker
who does not follow it), image-checked; ``every4-unchecked`` is the whole path before
keyframes followed the motion: every 4th frame, no image check, every label trusted.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from worker.assist.stretches import check_stretches
from worker.synth.annotators import KEY_STEP, annotate, keyframe_indices
from worker.tracks.interpolate import dense_points

LABEL_MODES = ("noise", "crowd", "every4", "every4-unchecked")


def grey_view(view_dir: Path, frames: int) -> np.ndarray:
    """(F, H, W) uint8: a view's first ``frames`` colour frames in grey, as the proposals
    route tracks on them."""
    from worker.formats import dexycb

    return np.stack([cv2.imread(str(view_dir / dexycb.color_file(f)), cv2.IMREAD_GRAYSCALE)
                     for f in range(frames)])


def write_grey(capture: Path, cache: Path, serials: list[str]) -> None:
    """grey.npy (V, F, H, W) uint8 of a capture's colour frames, in the cache."""
    seq_dir = next(p for p in capture.glob("*/*") if (p / "meta.yml").is_file())
    views = []
    for serial in serials:
        files = sorted((seq_dir / serial).glob("color_*.jpg"))
        views.append(np.stack([cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files]))
    np.save(cache / "grey.npy", np.stack(views))


def _every4(xy: np.ndarray, visible: np.ndarray, size: tuple[int, int],
            rng: np.random.Generator) -> list[list[list[float | None]]]:
    """A careful worker's noise, keyed every KEY_STEP-th frame whatever the motion."""
    noisy = xy + rng.normal(0.0, 2.0, xy.shape)
    noisy[..., 0] = np.clip(noisy[..., 0], 0.0, size[0] - 1.0)
    noisy[..., 1] = np.clip(noisy[..., 1], 0.0, size[1] - 1.0)
    return [[[f, float(noisy[f, p, 0]), float(noisy[f, p, 1]), int(visible[f, p])]
             for f in keyframe_indices(xy.shape[0], KEY_STEP, visible[:, p])]
            for p in range(xy.shape[1])]


def crowd_hand(joint_2d: np.ndarray, visible: np.ndarray, grey: np.ndarray, mode: str,
               size: tuple[int, int], rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(V, F, 21, 2) px, (V, F, 21) visible and (V, F, 21) evidence codes (None unchecked)
    of one careful worker per view. joint_2d: (V, F, 21, 2) true px; grey: (V, F, H, W)."""
    views, frames = joint_2d.shape[:2]
    xy = np.full(joint_2d.shape, np.nan)
    seen = np.zeros(visible.shape, bool)
    evidence = np.zeros(visible.shape, np.int8)
    for v in range(views):
        if mode.startswith("every4"):
            tracks = _every4(joint_2d[v], visible[v], size, rng)
        else:
            tracks = annotate(joint_2d[v], visible[v], size, "careful", rng).tracks
        xy[v], seen[v] = dense_points(enumerate(tracks), frames, joint_2d.shape[2])
        if mode != "every4-unchecked":
            check = check_stretches(grey[v, :frames], tracks)
            xy[v][check.contradicted], seen[v][check.contradicted] = np.nan, False
            evidence[v] = check.evidence
    return xy, seen, None if mode == "every4-unchecked" else evidence
