"""Rig faults injected into a synthetic capture: a perturbed copy for the product to read.

The copy keeps the ground truth exactly (``pose.npz`` and every ``labels_%06d.npz`` are the
source's bytes) while the product's inputs carry the fault:

    extrinsics:DEG,MM   every camera but the master: its camera-to-world pose turned by DEG
                        degrees about a random axis through its centre and its centre moved by
                        MM millimetres in a random direction (extrinsics.yml)
    late:N              N cameras (not the master) one frame late: their colour and depth
                        frame f shows the scene of frame f - 1 (frame 0 shows frame 0)
    depth-scale:S       every camera's depth reads (1 + S) times the truth (uint16 mm)
    depth-shift:LO-HI   every camera's depth image moved against its colour image by a whole
                        pixel offset (dx, dy) of length within [LO, HI] px, random direction
    betas[:SIGMA]       the subject's hand shape in the calibration (mano.yml) replaced by
                        another subject's: betas drawn from N(0, SIGMA^2), SIGMA 0.6 as the
                        synthetic subjects are drawn

Random choices come from ``seed`` (and the fault's place in the list): the same source, faults
and seed give the same copy. What was done is written to ``fault.yml`` at the copy's root
(``FAULT_FILE``): the faults, the seed, per camera its rotation (deg), translation (mm), frame
lag, depth scale and depth shift (px), the true extrinsics (camera-to-world 3x4, metres) and the
true betas. A crowd simulated on the copy labels what its images show: ``shown_frames`` says
which truth frame each image frame of a view shows, ``true_extrinsics`` where the cameras are.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from worker.formats import dexycb
from worker.formats.files import encode_image, write_yaml
from worker.geometry.transforms import axis_angle_to_matrix
from worker.synth.capture import written_whole

FAULT_FILE = "fault.yml"
KINDS = ("extrinsics", "late", "depth-scale", "depth-shift", "betas")
# Spread of the synthetic subjects' shape coefficients (worker.synth.capture draws N(0, 0.6)).
BETAS_SIGMA = 0.6


@dataclass(frozen=True)
class Fault:
    """One fault: kind (one of KINDS) and its numbers (see the module's table)."""

    kind: str
    args: tuple[float, ...] = ()

    @property
    def name(self) -> str:
        """The fault as written on a command line, e.g. ``extrinsics:0.5,5``."""
        if not self.args:
            return self.kind
        sep = "-" if self.kind == "depth-shift" else ","
        return f"{self.kind}:{sep.join(f'{a:g}' for a in self.args)}"


_ARITY = {"extrinsics": (2,), "late": (1,), "depth-scale": (1,), "depth-shift": (1, 2),
          "betas": (0, 1)}


def parse_fault(text: str) -> Fault:
    """``"extrinsics:0.5,5"`` -> Fault("extrinsics", (0.5, 5.0)); ValueError naming the problem."""
    kind, _, rest = text.strip().partition(":")
    if kind not in KINDS:
        raise ValueError(f"unknown fault {kind!r}; known: {', '.join(KINDS)}")
    parts = [p for p in rest.replace("-" if kind == "depth-shift" else ",", ",").split(",")
             if p.strip()]
    try:
        args = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"fault {text!r}: its parameters must be numbers") from None
    if len(args) not in _ARITY[kind]:
        raise ValueError(f"fault {text!r}: {kind} takes {' or '.join(map(str, _ARITY[kind]))} "
                         f"number(s), got {len(args)}")
    if kind == "depth-shift" and len(args) == 1:
        args = (args[0], args[0])
    _check(kind, args, text)
    return Fault(kind, args)


def _check(kind: str, args: tuple[float, ...], text: str) -> None:
    bad = (kind == "extrinsics" and (min(args) < 0 or args[0] > 45)) \
        or (kind == "late" and (args[0] < 1 or args[0] != int(args[0]))) \
        or (kind == "depth-scale" and not -0.5 < args[0] < 0.5) \
        or (kind == "depth-shift" and not 0 <= args[0] <= args[1] <= 50) \
        or (kind == "betas" and bool(args) and not 0 < args[0] <= 5)
    if bad:
        raise ValueError(f"fault {text!r}: parameters out of range (extrinsics DEG in [0, 45] "
                         "and MM >= 0; late a whole number >= 1; depth-scale in (-0.5, 0.5); "
                         "depth-shift 0 <= LO <= HI <= 50 px; betas SIGMA in (0, 5])")


def split_fault_names(values: Iterable[str]) -> list[str]:
    """Fault names from command-line values, each one fault or a comma list of them: a part
    that is only a number belongs to the fault before it (``extrinsics:0.2,2,late:1`` is two
    names); ``none`` (no fault) is kept as a name."""
    names: list[str] = []
    for value in values:
        for part in (p.strip() for p in value.split(",")):
            if not part:
                continue
            if names and _is_number(part):
                names[-1] += f",{part}"
            else:
                names.append(part)
    return names


def parse_faults(values: Iterable[str]) -> list[Fault]:
    """Faults from command-line values (see ``split_fault_names``); ``none`` is skipped."""
    return [parse_fault(n) for n in split_fault_names(values) if n != "none"]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


@dataclass
class _Copy:
    """A copy being written: its root, sequence folder, serials (master first) and record."""

    root: Path
    seq_dir: Path
    serials: list[str]
    master: str
    frames: int
    record: dict[str, Any] = field(default_factory=dict)

    def camera(self, serial: str) -> dict[str, Any]:
        cameras: dict[str, dict[str, Any]] = self.record.setdefault("cameras", {})
        return cameras.setdefault(serial, {})


def _replace_file(path: Path, write: Any) -> None:
    """Write a new file at ``path`` without touching the inode it may share with the source
    (the copy hard-links unchanged files)."""
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    os.replace(tmp, path)


def _link_tree(src: Path, dst: Path) -> None:
    def link(a: str, b: str) -> None:
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)

    shutil.copytree(src, dst, copy_function=link)


def _extrinsics(copy: _Copy, deg: float, mm: float, rng: np.random.Generator) -> None:
    meta = yaml.safe_load((copy.seq_dir / dexycb.META_FILE).read_text())
    path = copy.root / dexycb.extrinsics_file(meta[dexycb.META_EXTRINSICS])
    doc = yaml.safe_load(path.read_text())
    table = doc[dexycb.EXTRINSICS]
    for serial in copy.serials:
        if serial == copy.master:
            continue
        pose = np.asarray(table[serial], np.float64).reshape(3, 4)
        axis = rng.normal(size=3)
        turn = axis_angle_to_matrix(axis / np.linalg.norm(axis) * np.deg2rad(deg))
        move = rng.normal(size=3)
        move *= mm / 1000.0 / np.linalg.norm(move)
        # Turned about the camera's own centre, which then moves by ``move`` (world frame).
        pose = np.concatenate([turn @ pose[:, :3], (pose[:, 3] + move)[:, None]], axis=1)
        table[serial] = [float(x) for x in pose.reshape(-1)]
        cam = copy.camera(serial)
        cam["rotation_deg"] = cam.get("rotation_deg", 0.0) + float(deg)
        cam["translation_mm"] = [round(float(x) * 1000.0, 6) for x in move]
    _replace_file(path, lambda p: write_yaml(p, doc))


def _late(copy: _Copy, count: int, rng: np.random.Generator) -> None:
    others = [s for s in copy.serials if s != copy.master]
    if count > len(others):
        raise ValueError(f"late:{count}: the capture has only {len(others)} cameras besides "
                         "the master")
    for serial in sorted(rng.choice(others, count, replace=False).tolist()):
        folder = copy.seq_dir / serial
        # From the last frame back, each frame takes its predecessor's files (still intact).
        for f in range(copy.frames - 1, 0, -1):
            for name in (dexycb.color_file, dexycb.depth_file):
                src = folder / name(f - 1)
                if src.exists():
                    _replace_file(folder / name(f), lambda p, s=src: os.link(s, p))
        cam = copy.camera(serial)
        cam["lag_frames"] = int(cam.get("lag_frames", 0)) + 1


def _depth_files(copy: _Copy, serial: str) -> list[Path]:
    folder = copy.seq_dir / serial
    return [folder / dexycb.depth_file(f) for f in range(copy.frames)
            if (folder / dexycb.depth_file(f)).exists()]


def _rewrite_depth(path: Path, change: Any) -> None:
    depth = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH)
    if depth is None:
        raise ValueError(f"{path}: not a readable depth image")
    changed = change(depth)
    _replace_file(path, lambda p: p.write_bytes(encode_image(".png", changed)))


def scale_depth(depth_mm: np.ndarray, factor: float) -> np.ndarray:
    """(H, W) uint16 mm times ``factor``, rounded; 0 (no depth) stays 0."""
    out = np.rint(depth_mm.astype(np.float64) * factor)
    return np.clip(out, 0, np.iinfo(np.uint16).max).astype(np.uint16)


def shift_image(image: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """(H, W) image with its content moved by (dx, dy) whole px (x right, y down); 0 where
    nothing moved in."""
    out = np.zeros_like(image)
    h, w = image.shape[:2]
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[yd, xd] = image[ys, xs]
    return out


def _depth_scale(copy: _Copy, scale: float) -> None:
    for serial in copy.serials:
        for path in _depth_files(copy, serial):
            _rewrite_depth(path, lambda d: scale_depth(d, 1.0 + scale))
        cam = copy.camera(serial)
        cam["depth_scale"] = float(cam.get("depth_scale", 1.0)) * (1.0 + scale)


def _offsets(lo: float, hi: float) -> list[tuple[int, int]]:
    reach = int(np.ceil(hi))
    return [(dx, dy) for dx in range(-reach, reach + 1) for dy in range(-reach, reach + 1)
            if lo <= np.hypot(dx, dy) <= hi]


def _depth_shift(copy: _Copy, lo: float, hi: float, rng: np.random.Generator) -> None:
    offsets = _offsets(lo, hi)
    if not offsets:
        raise ValueError(f"depth-shift:{lo:g}-{hi:g}: no whole-pixel offset has a length in "
                         "that range")
    for serial in copy.serials:
        dx, dy = offsets[int(rng.integers(len(offsets)))]
        for path in _depth_files(copy, serial):
            _rewrite_depth(path, lambda d, a=dx, b=dy: shift_image(d, a, b))
        cam = copy.camera(serial)
        cam["depth_shift_px"] = [int(dx), int(dy)]


def _betas(copy: _Copy, sigma: float, rng: np.random.Generator) -> None:
    meta = yaml.safe_load((copy.seq_dir / dexycb.META_FILE).read_text())
    for calib in meta.get(dexycb.META_MANO_CALIB) or []:
        path = copy.root / dexycb.mano_file(calib)
        true = yaml.safe_load(path.read_text())[dexycb.BETAS]
        copy.record.setdefault("true_betas", {})[calib] = [float(b) for b in true]
        wrong = rng.normal(0.0, sigma, len(true))
        _replace_file(path, lambda p, b=wrong: write_yaml(p, dexycb.mano_doc(b)))


def _apply(copy: _Copy, fault: Fault, rng: np.random.Generator) -> None:
    if fault.kind == "extrinsics":
        _extrinsics(copy, fault.args[0], fault.args[1], rng)
    elif fault.kind == "late":
        _late(copy, int(fault.args[0]), rng)
    elif fault.kind == "depth-scale":
        _depth_scale(copy, fault.args[0])
    elif fault.kind == "depth-shift":
        _depth_shift(copy, fault.args[0], fault.args[1], rng)
    else:
        _betas(copy, fault.args[0] if fault.args else BETAS_SIGMA, rng)


def _open_copy(root: Path) -> _Copy:
    seq_dirs = sorted(p.parent for p in root.glob(dexycb.META_GLOB))
    if len(seq_dirs) != 1:
        raise ValueError(f"{root}: expected one sequence (*/*/meta.yml), found {len(seq_dirs)}")
    meta = yaml.safe_load((seq_dirs[0] / dexycb.META_FILE).read_text())
    extr = yaml.safe_load((root / dexycb.extrinsics_file(meta[dexycb.META_EXTRINSICS]))
                          .read_text())
    serials = [str(s) for s in meta[dexycb.META_SERIALS]]
    return _Copy(root, seq_dirs[0], serials, str(extr.get(dexycb.MASTER, serials[0])),
                 int(meta[dexycb.META_NUM_FRAMES]),
                 {"true_extrinsics": {s: [float(x) for x in extr[dexycb.EXTRINSICS][s]]
                                      for s in serials}})


def inject_faults(src: Path, out: Path, faults: Sequence[Fault], seed: int = 0) -> dict[str, Any]:
    """Write a copy of the synthetic capture ``src`` at ``out`` with ``faults`` applied.

    Args:
        src: a capture as ``generate_capture`` writes it (one sequence).
        out: folder to create; must not exist or be empty. Written to a sibling ``.partial``
            folder and moved into place when complete. Unchanged files are hard links.
        faults: applied in order (``parse_faults``); an empty list gives a plain copy.
        seed: seed of every random choice (>= 0).

    Returns:
        The record also written to ``out/fault.yml`` (see the module's docstring).
    """
    src, out = Path(src).resolve(), Path(out).resolve()
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if (src / FAULT_FILE).exists():
        raise ValueError(f"{src} already has faults ({FAULT_FILE}); inject into a clean capture")
    with written_whole(out) as partial:
        _link_tree(src, partial)
        copy = _open_copy(partial)
        copy.record.update(faults=[f.name for f in faults], seed=int(seed), source=str(src))
        for i, fault in enumerate(faults):
            _apply(copy, fault, np.random.default_rng([seed, i]))
        write_yaml(partial / FAULT_FILE, copy.record)
    return copy.record


def read_record(root: Path) -> dict[str, Any] | None:
    """The fault record of a capture (``fault.yml``), or None for a capture without faults."""
    path = Path(root) / FAULT_FILE
    if not path.is_file():
        return None
    doc = yaml.safe_load(path.read_text())
    return doc if isinstance(doc, dict) else None


def shown_frames(root: Path, serial: str, frames: int) -> np.ndarray:
    """(F,) int: the truth frame each image frame of view ``serial`` shows (a late camera's
    frame f shows f - lag, never before 0); 0..F-1 for a capture without faults."""
    record = read_record(root) or {}
    lag = int(record.get("cameras", {}).get(serial, {}).get("lag_frames", 0))
    return np.maximum(np.arange(frames) - lag, 0)


def true_extrinsics(root: Path) -> dict[str, np.ndarray] | None:
    """{serial: (3, 4) true camera-to-world, metres} of a capture with faults, else None."""
    record = read_record(root)
    if record is None:
        return None
    return {s: np.asarray(v, np.float64).reshape(3, 4)
            for s, v in record.get("true_extrinsics", {}).items()}
