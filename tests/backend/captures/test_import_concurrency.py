"""Imports of the same capture at once (two admins, two `dexlabel import` runs, a retried HTTP
request): the import that loses the race never touches the files of the one that won, every
frame of the committed sequence stays readable, and a re-import restores stored files that went
missing."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import pytest
from sqlalchemy import func, select

from backend.captures.flows import import_path
from backend.captures.models import Frame, SceneObject, Sequence
from backend.captures.service import ImportResult
from backend.db import session_scope
from backend.storage import LocalStorage, Storage, get_storage
from tests.backend.captures import capture_edits as edit

WAIT_S = 60


class _GatedStorage(LocalStorage):
    """Local storage (one root shared by every import) that makes an import's first write wait
    until the other import has reached its first write too, so both have seen "not imported
    yet"; the held import then waits for ``release`` before writing anything."""

    def __init__(self, root: Path, both_writing: threading.Barrier,
                 release: threading.Event | None = None, fail_at_write: int = 0) -> None:
        super().__init__(root)
        self.both_writing, self.release = both_writing, release
        self.fail_at_write = fail_at_write
        self.lock = threading.Lock()
        self.writes = 0

    def put_bytes(self, key: str, data: bytes, content_type: str = "") -> None:
        with self.lock:
            self.writes += 1
            if self.writes == 1:
                self.both_writing.wait(WAIT_S)
                if self.release is not None and not self.release.wait(WAIT_S):
                    raise TimeoutError("the other import did not finish")
            if self.writes == self.fail_at_write:
                raise OSError("connection reset")
        super().put_bytes(key, data, content_type)


def _run(target: Callable[[], list[ImportResult]]) -> tuple[threading.Thread, dict]:
    outcome: dict = {}

    def work() -> None:
        try:
            outcome["results"] = target()
        except BaseException as exc:  # the test looks at what each import did
            outcome["error"] = exc

    thread = threading.Thread(target=work)
    thread.start()
    return thread, outcome


def _assert_every_file_of_the_sequence_is_readable(storage: Storage, capture: Path) -> None:
    seq_dir = edit.sequence_dir(capture)
    with session_scope() as s:
        seq = s.scalars(select(Sequence)).one()
        for camera in seq.cameras:
            assert len(camera.frames) == seq.num_frames
            for frame in camera.frames:
                source = seq_dir / camera.serial
                assert storage.get_bytes(frame.color_key) == (
                    source / f"color_{frame.index:06d}.jpg").read_bytes()
                assert frame.depth_key is not None
                assert storage.get_bytes(frame.depth_key) == (
                    source / f"aligned_depth_to_color_{frame.index:06d}.png").read_bytes()
        for obj in seq.objects:
            assert storage.get_bytes(obj.mesh_key)


def _sequence_count() -> int:
    with session_scope() as s:
        return int(s.scalar(select(func.count()).select_from(Sequence)) or 0)


@pytest.mark.parametrize("held", [0, 1], ids=["first-started-commits-last",
                                               "second-started-commits-last"])
def test_two_imports_of_a_new_capture_at_once_leave_every_frame_readable(
    app_env: dict, small_capture: Path, held: int
) -> None:
    root = Path(app_env["DEXLABEL_STORAGE_URL"])
    both_writing = threading.Barrier(2)
    winner_done = threading.Event()
    storages = [_GatedStorage(root, both_writing, winner_done if i == held else None)
                for i in range(2)]

    def winner() -> list[ImportResult]:
        try:
            return import_path(small_capture, storage=storages[1 - held])
        finally:
            winner_done.set()

    def loser() -> list[ImportResult]:
        return import_path(small_capture, storage=storages[held])

    started = [_run(winner), _run(loser)] if held == 1 else [_run(loser), _run(winner)]
    for thread, _ in started:
        thread.join(WAIT_S * 3)
        assert not thread.is_alive()
    assert _sequence_count() == 1
    _assert_every_file_of_the_sequence_is_readable(get_storage(), small_capture)
    outcomes = [outcome for _, outcome in started]
    assert [o.get("error") for o in outcomes] == [None, None]
    created = sorted(o["results"][0].created for o in outcomes)
    assert created == [False, True]
    assert len({o["results"][0].sequence_id for o in outcomes}) == 1


def test_an_import_failing_beside_another_leaves_the_others_files_alone(
    app_env: dict, small_capture: Path
) -> None:
    root = Path(app_env["DEXLABEL_STORAGE_URL"])
    both_writing = threading.Barrier(2)
    winner_done = threading.Event()
    failing = _GatedStorage(root, both_writing, winner_done, fail_at_write=5)
    healthy = _GatedStorage(root, both_writing)

    def winner() -> list[ImportResult]:
        try:
            return import_path(small_capture, storage=healthy)
        finally:
            winner_done.set()

    (t1, won), (t2, lost) = _run(winner), _run(lambda: import_path(small_capture,
                                                                    storage=failing))
    t1.join(WAIT_S * 3)
    t2.join(WAIT_S * 3)
    assert _sequence_count() == 1
    _assert_every_file_of_the_sequence_is_readable(get_storage(), small_capture)
    assert won.get("error") is None and won["results"][0].created
    assert isinstance(lost.get("error"), OSError)


def test_a_reimport_restores_stored_files_that_went_missing(
    app_env: dict, small_capture: Path
) -> None:
    storage = get_storage()
    first = import_path(small_capture)[0]
    with session_scope() as s:
        frames = list(s.scalars(select(Frame).order_by(Frame.id)))
        mesh_key = s.scalars(select(SceneObject.mesh_key)).first()
    assert mesh_key is not None
    lost = [frames[0].color_key, frames[7].depth_key, mesh_key]
    root = Path(app_env["DEXLABEL_STORAGE_URL"])
    for key in lost:
        assert key is not None
        (root / key).unlink()

    again = import_path(small_capture)[0]
    assert again.sequence_id == first.sequence_id and not again.created
    assert again.repaired == 3
    _assert_every_file_of_the_sequence_is_readable(storage, small_capture)
    assert import_path(small_capture)[0].repaired == 0


def test_a_reimport_names_stored_files_it_cannot_restore(
    app_env: dict, small_capture: Path
) -> None:
    from backend.errors import Conflict

    import_path(small_capture)
    with session_scope() as s:
        frame = s.scalars(select(Frame).order_by(Frame.id)).first()
        assert frame is not None
        odd_key = frame.color_key.rsplit("/", 1)[0] + "/renamed.jpg"
        frame.color_key = odd_key
        sequence_id = s.scalars(select(Sequence.id)).one()
    with pytest.raises(Conflict) as info:
        import_path(small_capture)
    assert odd_key in info.value.detail
    assert f"sequences delete {sequence_id}" in info.value.detail
