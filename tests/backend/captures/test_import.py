from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from sqlalchemy import func, select

from backend.captures.flows import import_path
from backend.captures.models import Camera, Frame, Hand, SceneObject, Sequence, Subject
from backend.db import session_scope
from backend.errors import Conflict, InvalidCapture
from backend.storage import LocalStorage, get_storage
from tests.backend.captures import capture_edits as edit


def _counts() -> dict[str, int]:
    with session_scope() as s:
        return {m.__tablename__: s.scalar(select(func.count()).select_from(m))
                for m in (Subject, Sequence, Camera, Frame, SceneObject, Hand)}


def _stored_files(env: dict) -> list[Path]:
    root = Path(env["DEXLABEL_STORAGE_URL"])
    return sorted(p for p in root.rglob("*") if p.is_file()) if root.exists() else []


def test_import_creates_one_sequence_with_its_cameras_frames_objects_and_hand(
    app_env: dict, small_capture: Path
) -> None:
    results = import_path(small_capture)
    assert [r.created for r in results] == [True]
    assert _counts() == {"subjects": 1, "sequences": 1, "cameras": 3, "frames": 18,
                         "scene_objects": 2, "hands": 1}
    with session_scope() as s:
        seq = s.scalars(select(Sequence)).one()
        meta = edit.meta(small_capture)
        assert [c.serial for c in seq.cameras] == [str(x) for x in meta["serials"]]
        assert [o.ycb_id for o in seq.objects] == meta["ycb_ids"]
        assert sum(o.grasped for o in seq.objects) == 1
        assert all(o.initial_pose is not None and len(o.initial_pose) == 3 for o in seq.objects)
        assert seq.hands[0].side == "right" and len(seq.hands[0].betas) == 10
        frame = seq.cameras[0].frames[0]
        original = edit.sequence_dir(small_capture) / seq.cameras[0].serial / "color_000000.jpg"
        assert get_storage().get_bytes(frame.color_key) == original.read_bytes()


def test_reimporting_the_same_capture_changes_nothing(app_env: dict, small_capture: Path) -> None:
    import_path(small_capture)
    before, files_before = _counts(), _stored_files(app_env)
    results = import_path(small_capture)
    assert [r.created for r in results] == [False]
    assert _counts() == before
    assert _stored_files(app_env) == files_before


def test_same_name_with_different_content_is_a_conflict(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    import_path(small_capture)
    changed = edit.copy_capture(small_capture, tmp_path / "changed")
    serial = str(edit.meta(changed)["serials"][0])
    edit.set_extrinsics(changed, serial, [1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0])
    with pytest.raises(Conflict, match="already imported with different content"):
        import_path(changed)
    assert _counts()["sequences"] == 1


def _assert_refused(app_env: dict, capture: Path, file_part: str, problem: str) -> None:
    with pytest.raises(InvalidCapture) as info:
        import_path(capture)
    assert file_part in info.value.path
    assert problem in info.value.detail
    assert all(n == 0 for n in _counts().values())
    assert _stored_files(app_env) == []


def test_missing_frame_is_refused_naming_the_file(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][1])
    (edit.sequence_dir(cap) / serial / "color_000004.jpg").unlink()
    _assert_refused(app_env, cap, f"{serial}/color_000004.jpg", "frame 4 is missing")


def test_corrupt_yaml_is_refused_naming_the_file(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    (edit.sequence_dir(cap) / "meta.yml").write_text("serials: [1, 2\nnum_frames: : 3\n")
    _assert_refused(app_env, cap, "meta.yml", "not valid YAML")


def test_extrinsics_of_the_wrong_shape_are_refused_naming_file_and_field(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][2])
    edit.set_extrinsics(cap, serial, [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    _assert_refused(app_env, cap, "extrinsics.yml", f"extrinsics.{serial}")


def test_a_non_16_bit_depth_map_is_refused(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][0])
    path = edit.sequence_dir(cap) / serial / "aligned_depth_to_color_000002.png"
    depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(path), (depth // 256).astype("uint8"))
    _assert_refused(app_env, cap, "aligned_depth_to_color_000002.png", "16-bit")


def test_missing_hand_calibration_is_refused(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    calib = edit.meta(cap)["mano_calib"][0]
    (cap / "calibration" / f"mano_{calib}" / "mano.yml").unlink()
    _assert_refused(app_env, cap, "mano.yml", "missing")


@pytest.fixture(scope="module")
def tiny_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthetic capture of small frames (2 views x 3 frames of 160x120); read-only."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("tiny-capture")
    generate_capture(root, seed=5, frames=3, views=2, objects=1, width=160, height=120,
                     workers=1)
    return root


def truncate(path: Path, keep: float = 0.6) -> None:
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * keep)])


def corrupt(path: Path) -> None:
    """Flip the bytes in the middle of a file, past its header."""
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 8] = bytes(b ^ 0xFF for b in data[middle:middle + 8])
    path.write_bytes(bytes(data))


def test_a_truncated_jpeg_is_refused_naming_the_file(
    app_env: dict, tiny_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(tiny_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][1])
    truncate(edit.sequence_dir(cap) / serial / "color_000001.jpg")
    _assert_refused(app_env, cap, f"{serial}/color_000001.jpg", "JPEG image does not decode")


def test_a_corrupt_depth_png_is_refused_naming_the_file(
    app_env: dict, tiny_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(tiny_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][0])
    corrupt(edit.sequence_dir(cap) / serial / "aligned_depth_to_color_000002.png")
    _assert_refused(app_env, cap, f"{serial}/aligned_depth_to_color_000002.png",
                    "PNG depth image does not decode")


def test_a_truncated_depth_png_is_refused_naming_the_file(
    app_env: dict, tiny_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(tiny_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][1])
    truncate(edit.sequence_dir(cap) / serial / "aligned_depth_to_color_000000.png", 0.5)
    _assert_refused(app_env, cap, f"{serial}/aligned_depth_to_color_000000.png",
                    "PNG depth image does not decode")


class _FailingStorage(LocalStorage):
    """Local storage whose 10th write fails, as a full disk or a dropped S3 link would."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self.writes = 0

    def put_bytes(self, key: str, data: bytes, content_type: str = "") -> None:
        self.writes += 1
        if self.writes == 10:
            raise OSError("disk full")
        super().put_bytes(key, data, content_type)


def test_a_storage_failure_midway_leaves_no_rows_and_no_files(
    app_env: dict, small_capture: Path
) -> None:
    storage = _FailingStorage(Path(app_env["DEXLABEL_STORAGE_URL"]))
    with pytest.raises(OSError, match="disk full"):
        import_path(small_capture, storage=storage)
    assert all(n == 0 for n in _counts().values())
    assert _stored_files(app_env) == []


def test_one_video_per_camera_imports_decoded_frames(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    seq_dir = edit.sequence_dir(cap)
    for serial in edit.meta(cap)["serials"]:
        folder = seq_dir / str(serial)
        images = [cv2.imread(str(p)) for p in sorted(folder.glob("color_*.jpg"))]
        h, w = images[0].shape[:2]
        writer = cv2.VideoWriter(str(seq_dir / f"{serial}.avi"),
                                 cv2.VideoWriter_fourcc(*"MJPG"), 30, (w, h))
        for img in images:
            writer.write(img)
        writer.release()
        for p in folder.iterdir():
            p.unlink()
        folder.rmdir()
    (seq_dir / "pose.npz").unlink()
    import_path(cap)
    counts = _counts()
    assert counts["frames"] == 18 and counts["sequences"] == 1
    with session_scope() as s:
        seq = s.scalars(select(Sequence)).one()
        assert seq.source_kind == "video"
        assert all(f.depth_key is None for c in seq.cameras for f in c.frames)
        assert all(o.initial_pose is None for o in seq.objects)
        data = get_storage().get_bytes(seq.cameras[0].frames[5].color_key)
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape[:2] == (h, w)


def test_video_with_fewer_frames_than_meta_is_refused(
    app_env: dict, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    seq_dir = edit.sequence_dir(cap)
    serial = str(edit.meta(cap)["serials"][0])
    folder = seq_dir / serial
    img = cv2.imread(str(folder / "color_000000.jpg"))
    writer = cv2.VideoWriter(str(seq_dir / f"{serial}.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30,
                             (img.shape[1], img.shape[0]))
    for _ in range(3):
        writer.write(img)
    writer.release()
    for p in folder.iterdir():
        p.unlink()
    folder.rmdir()
    _assert_refused(app_env, cap, "meta.yml", "num_frames is 6")


@pytest.mark.parametrize(("path", "problem"), [
    ("captures/a\x00b", "must not contain a NUL character"),
    ("captures/" + "x" * 5000, "at most 4096 characters, this one has 5009"),
    ("captures/" + "y" * 3000, "path does not exist"),
])
def test_an_unusable_import_path_is_refused_naming_the_problem(
    app_env: dict, path: str, problem: str
) -> None:
    with pytest.raises(InvalidCapture) as info:
        import_path(path)
    assert problem in info.value.detail
    assert len(info.value.detail) < 400
