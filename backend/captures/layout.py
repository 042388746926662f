"""Reading a capture in the DexYCB raw layout into a validated plan, before anything is written.

Layout (paths relative to the capture root)::

    calibration/intrinsics/<serial>_<W>x<H>.yml     color: {fx, fy, ppx, ppy[, width, height,
                                                    coeffs]}
    calibration/extrinsics_<name>/extrinsics.yml    extrinsics: {<serial>: 12 floats},
                                                    master: <serial>
    calibration/mano_<calib>/mano.yml               betas: 10 floats
    models/<ycb name>/textured_simple.obj           (or any .obj / .ply in that folder)
    <subject>/<sequence>/meta.yml                   serials, num_frames, ycb_ids, ycb_grasp_ind,
                                                    mano_sides, mano_calib, extrinsics
    <subject>/<sequence>/<serial>/color_%06d.jpg, aligned_depth_to_color_%06d.png (uint16 mm)
    <subject>/<sequence>/<serial>.mp4|.avi|.mov|.mkv  (instead of the folder: colour only)
    <subject>/<sequence>/pose.npz                   optional; pose_y[0] gives initial object poses

Extrinsics are camera-to-world (the master frame), 3x4 row-major, metres. Every colour and depth
frame is decoded in full, not only its header. Every problem raises InvalidCapture naming the
file (relative to the root) and the field or frame at fault.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from backend.captures.frame_files import attach_frames
from backend.captures.plans import CameraPlan, HandPlan, ObjectPlan, SequencePlan
from backend.captures.reader import CaptureReader, CaptureRoots
from backend.config import get_settings
from backend.errors import InvalidCapture
from worker.formats import dexycb
from worker.formats.dexycb import YCB_CLASSES

# The longest import path taken (Linux's PATH_MAX).
MAX_PATH_CHARS = 4096
MESH_SUFFIXES = dexycb.MODEL_SUFFIXES


def find_sequence_dirs(path: Path) -> list[Path]:
    """The sequence folders (holding meta.yml) under ``path``, or ``path`` itself."""
    try:
        path = path.resolve()
        if not path.exists():
            raise InvalidCapture(str(path), "path does not exist")
        if (path / dexycb.META_FILE).is_file():
            return [path]
        found = sorted(p.parent for p in path.glob(dexycb.META_GLOB))
    except OSError as exc:  # a name too long for the file system, a folder it may not read
        raise InvalidCapture(str(path), f"cannot be read ({exc.strerror or exc})") from exc
    if not found:
        raise InvalidCapture(str(path), "no <subject>/<sequence>/meta.yml found under this folder")
    return found


def capture_root_of(seq_dir: Path) -> Path:
    return seq_dir.parent.parent


def read_sequence(seq_dir: Path, roots: CaptureRoots | None = None) -> SequencePlan:
    """Parse and check one sequence and everything it refers to; touches nothing. With
    ``roots`` (an HTTP import), every file and folder it opens must lie inside them."""
    root = capture_root_of(seq_dir)
    rd = CaptureReader(root, roots)
    rd.inside(seq_dir)
    meta_path = seq_dir / dexycb.META_FILE
    meta = rd.yaml(meta_path)
    serials = [str(s) for s in rd.field(meta, meta_path, dexycb.META_SERIALS, list)]
    if not serials or len(set(serials)) != len(serials):
        raise rd.fail(meta_path, "field 'serials' must list distinct camera serials")
    num_frames = meta.get(dexycb.META_NUM_FRAMES)
    if num_frames is not None and (not isinstance(num_frames, int) or num_frames <= 0):
        raise rd.fail(meta_path,
                      f"field 'num_frames' must be a positive integer, got {num_frames!r}")
    extr_name = str(rd.field(meta, meta_path, dexycb.META_EXTRINSICS, (str, int)))
    extrinsics, master = _read_extrinsics(rd, root, extr_name, serials)
    cameras = [_read_camera(rd, root, seq_dir, s, extrinsics[s]) for s in serials]
    num_frames = attach_frames(rd, seq_dir, cameras, num_frames)
    objects = _read_objects(rd, root, seq_dir, meta, meta_path, num_frames)
    hands = _read_hands(rd, root, meta, meta_path)
    return SequencePlan(
        root=root, seq_dir=seq_dir, subject=seq_dir.parent.name, name=seq_dir.name,
        num_frames=num_frames, master_serial=master, cameras=cameras, objects=objects,
        hands=hands, fingerprint=rd.digest.hexdigest(),
    )


def _read_extrinsics(
    rd: CaptureReader, root: Path, name: str, serials: list[str]
) -> tuple[dict[str, list[list[float]]], str | None]:
    path = root / dexycb.extrinsics_file(name)
    doc = rd.yaml(path)
    table = rd.field(doc, path, dexycb.EXTRINSICS, dict)
    table = {str(k): v for k, v in table.items()}
    out: dict[str, list[list[float]]] = {}
    for serial in serials:
        if serial not in table:
            raise rd.fail(path, f"field 'extrinsics.{serial}' is missing")
        flat = rd.numbers(table[serial], path, f"extrinsics.{serial}", 12)
        mat = np.asarray(flat).reshape(3, 4)
        if abs(np.linalg.det(mat[:, :3]) - 1.0) > 1e-3:
            raise rd.fail(path, f"field 'extrinsics.{serial}' rotation part is not a rotation")
        out[serial] = mat.tolist()
    master = doc.get(dexycb.MASTER)
    return out, None if master is None else str(master)


def _read_camera(
    rd: CaptureReader, root: Path, seq_dir: Path, serial: str, extrinsics: list[list[float]]
) -> CameraPlan:
    candidates = sorted((root / dexycb.INTRINSICS_DIR).glob(dexycb.intrinsics_glob(serial)))
    if not candidates:
        raise rd.fail(root / dexycb.intrinsics_file(serial, dexycb.IMAGE_WIDTH,
                                                    dexycb.IMAGE_HEIGHT), "file is missing")
    path = candidates[0]
    doc = rd.yaml(path)
    color = rd.field(doc, path, dexycb.COLOR, dict)
    vals = {k: rd.numbers([rd.field(color, path, k, (int, float))], path, f"color.{k}", 1)[0]
            for k in dexycb.INTRINSIC_KEYS}
    size_w, size_h = (dexycb.intrinsics_size(path.stem)
                      or (dexycb.IMAGE_WIDTH, dexycb.IMAGE_HEIGHT))
    width, height = (int(rd.numbers([color.get(k, default)], path, f"color.{k}", 1)[0])
                     for k, default in (("width", size_w), ("height", size_h)))
    if width <= 0 or height <= 0:
        raise rd.fail(path, f"image size must be positive, got {width}x{height}")
    _check_frame_size(rd, path, width, height)
    coeffs = color.get("coeffs", [0.0] * 5)
    dist = rd.numbers(coeffs, path, "color.coeffs", len(coeffs) if isinstance(coeffs, list) else 5)
    if len(dist) not in (4, 5, 8):
        raise rd.fail(path, f"field 'color.coeffs' must hold 4, 5 or 8 numbers, got {len(dist)}")
    if vals["fx"] <= 0 or vals["fy"] <= 0:
        raise rd.fail(path, "fields 'color.fx' and 'color.fy' must be positive")
    return CameraPlan(serial=serial, width=width, height=height, fx=vals["fx"], fy=vals["fy"],
                      ppx=vals["ppx"], ppy=vals["ppy"], distortion=dist, extrinsics=extrinsics)


def _check_frame_size(rd: CaptureReader, path: Path, width: int, height: int) -> None:
    """Refuse frames over the size limit before one is read: every frame's header must then
    match the intrinsics' size (frame_files), so none larger is ever decoded."""
    settings = get_settings()
    if width > settings.max_frame_width or height > settings.max_frame_height:
        raise rd.fail(path, f"frames of {width}x{height} are larger than an import takes "
                            f"({settings.max_frame_width}x{settings.max_frame_height}: "
                            "DEXLABEL_MAX_FRAME_WIDTH, DEXLABEL_MAX_FRAME_HEIGHT)")


def _read_objects(
    rd: CaptureReader, root: Path, seq_dir: Path, meta: dict[str, Any], meta_path: Path,
    num_frames: int,
) -> list[ObjectPlan]:
    from worker.geometry.mesh_io import read_mesh

    ycb_ids = rd.field(meta, meta_path, dexycb.META_YCB_IDS, list)
    grasp = meta.get(dexycb.META_GRASP_IND)
    if grasp is not None and (not isinstance(grasp, int) or not 0 <= grasp < len(ycb_ids)):
        raise rd.fail(meta_path, f"field 'ycb_grasp_ind' must index ycb_ids, got {grasp!r}")
    poses = _initial_poses(rd, seq_dir / dexycb.POSE_FILE, len(ycb_ids), num_frames)
    out = []
    for i, ycb_id in enumerate(ycb_ids):
        if not isinstance(ycb_id, int) or ycb_id not in YCB_CLASSES:
            raise rd.fail(meta_path, f"field 'ycb_ids[{i}]' is not a known YCB id: {ycb_id!r}")
        name = YCB_CLASSES[ycb_id]
        folder = root / dexycb.model_dir(name)
        if folder.is_dir():
            rd.inside(folder)
        meshes = sorted(p for p in folder.glob("*") if p.suffix.lower() in MESH_SUFFIXES)
        preferred = folder / dexycb.MODEL_OBJ
        mesh_path = preferred if preferred.is_file() else (meshes[0] if meshes else preferred)
        if not mesh_path.is_file():
            raise rd.fail(preferred, f"object model of {name} is missing")
        try:
            mesh = read_mesh(rd.inside(mesh_path))
        except (ValueError, OSError) as exc:
            raise rd.fail(mesh_path, f"unreadable mesh: {exc}") from None
        rd.digest.update(rd.rel(mesh_path).encode() + mesh_path.read_bytes())
        out.append(ObjectPlan(
            index=i, ycb_id=ycb_id, name=name, mesh_path=mesh_path,
            model_files=sorted(rd.inside(p) for p in folder.iterdir() if p.is_file()),
            num_vertices=len(mesh.vertices), num_faces=len(mesh.faces),
            grasped=grasp == i, initial_pose=None if poses is None else poses[i],
        ))
    return out


def _initial_poses(
    rd: CaptureReader, path: Path, num_objects: int, num_frames: int
) -> list[list[list[float]]] | None:
    """Object-to-world 3x4 poses at frame 0 from pose.npz (qx, qy, qz, qw, tx, ty, tz)."""
    from scipy.spatial.transform import Rotation

    if not path.is_file():
        return None
    try:
        with np.load(rd.inside(path)) as npz:
            pose_y = np.asarray(npz[dexycb.POSE_Y], dtype=np.float64)
    except KeyError:
        raise rd.fail(path, "field 'pose_y' is missing") from None
    except (OSError, ValueError) as exc:
        raise rd.fail(path, f"not a readable npz file: {exc}") from None
    if pose_y.ndim != 3 or pose_y.shape[1:] != (num_objects, 7) or pose_y.shape[0] < 1:
        raise rd.fail(path, f"field 'pose_y' must have shape [frames, {num_objects}, 7], "
                            f"got {list(pose_y.shape)}")
    out = []
    for q in pose_y[0]:
        rot = Rotation.from_quat(q[:4]).as_matrix()
        out.append(np.concatenate([rot, q[4:, None]], axis=1).tolist())
    return out


def _read_hands(rd: CaptureReader, root: Path, meta: dict[str, Any],
                meta_path: Path) -> list[HandPlan]:
    sides = meta.get(dexycb.META_MANO_SIDES) or []
    calibs = meta.get(dexycb.META_MANO_CALIB) or []
    if not isinstance(sides, list) or not isinstance(calibs, list):
        raise rd.fail(meta_path, "fields 'mano_sides' and 'mano_calib' must be lists")
    hands = []
    for i, side in enumerate(sides):
        if side not in ("right", "left"):
            raise rd.fail(meta_path,
                          f"field 'mano_sides[{i}]' must be 'right' or 'left', got {side!r}")
        calib = str(calibs[i]) if i < len(calibs) else None
        betas = None
        if calib is not None:
            path = root / dexycb.mano_file(calib)
            betas = rd.numbers(rd.field(rd.yaml(path), path, dexycb.BETAS, list), path,
                               dexycb.BETAS, 10)
        hands.append(HandPlan(index=i, side=side, calib_name=calib, betas=betas))
    return hands
