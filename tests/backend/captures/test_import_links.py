"""An HTTP import reads nothing outside the folders captures are imported from: a symbolic link
inside a capture (one frame, or a whole sequence folder) that leads outside is refused with 403
naming it relative to the capture, and the folders are named relative to the instance folder
(no absolute path of the server in the answer). `dexlabel import` still reads any path."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from tests.backend.captures import capture_edits as edit


def _import(client: TestClient, headers: dict, path: Path) -> tuple[int, dict]:
    resp = client.post("/api/captures/import", json={"path": str(path)}, headers=headers)
    assert resp.headers["content-type"].startswith("application/json")
    return resp.status_code, resp.json()


def _nothing_imported(client: TestClient, headers: dict) -> bool:
    return client.get("/api/sequences", headers=headers).json() == []


def _no_server_paths(detail: str, *paths: Path) -> None:
    for path in paths:
        assert str(path) not in detail, detail


@pytest.fixture
def inside(app_env: dict, small_capture: Path) -> Path:
    """A copy of the capture in the instance folder's captures/."""
    return edit.copy_capture(small_capture, Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "c")


def test_a_frame_linked_to_a_file_outside_the_roots_is_refused_by_name(
    client: TestClient, admin_headers: dict, app_env: dict, inside: Path, tmp_path: Path,
) -> None:
    seq = edit.sequence_dir(inside)
    serial = str(edit.meta(inside)["serials"][1])
    frame = seq / serial / "color_000003.jpg"
    secret = tmp_path / "outside" / "private.jpg"
    secret.parent.mkdir()
    shutil.copyfile(frame, secret)  # a readable JPEG of the right size, but not the capture's
    frame.unlink()
    frame.symlink_to(secret)
    status, body = _import(client, admin_headers, inside)
    assert status == 403, body
    assert body["error"] == "forbidden"
    rel = f"{seq.relative_to(inside).as_posix()}/{serial}/color_000003.jpg"
    assert body["detail"].startswith(f"{rel} (a symbolic link in the capture?) is outside the "
                                     "folders captures are imported from (captures/ in the "
                                     "instance folder, the instance folder)"), body
    _no_server_paths(body["detail"], secret, Path(app_env["DEXLABEL_VAR_DIR"]))
    assert _nothing_imported(client, admin_headers)
    # The command line reads any path: the operator chose it.
    assert import_path(inside)[0].created


def test_a_sequence_folder_linked_outside_the_roots_is_refused_by_name(
    client: TestClient, admin_headers: dict, app_env: dict, inside: Path, tmp_path: Path,
) -> None:
    seq = edit.sequence_dir(inside)
    moved = shutil.move(seq, tmp_path / "elsewhere")
    seq.symlink_to(moved, target_is_directory=True)
    status, body = _import(client, admin_headers, inside)
    assert status == 403, body
    assert body["detail"].startswith(f"{seq.relative_to(inside).as_posix()} (a symbolic link "
                                     "in the capture?) is outside"), body
    _no_server_paths(body["detail"], Path(moved), Path(app_env["DEXLABEL_VAR_DIR"]))
    assert _nothing_imported(client, admin_headers)


def test_a_linked_model_file_that_stays_inside_the_roots_is_read(
    client: TestClient, admin_headers: dict, app_env: dict, inside: Path, tmp_path: Path,
) -> None:
    model = next(p for p in (inside / "models").rglob("*") if p.is_file())
    kept = Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "shared" / model.name
    kept.parent.mkdir()
    shutil.copyfile(model, kept)
    model.unlink()
    model.symlink_to(kept)  # a link that stays inside the roots is read
    status, body = _import(client, admin_headers, inside)
    assert status == 200 and body[0]["created"], body


def test_roots_outside_the_instance_are_named_by_their_place_in_the_setting(
    client: TestClient, admin_headers: dict, small_capture: Path, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from backend.config import get_settings

    allowed = tmp_path / "allowed"
    allowed.mkdir()
    monkeypatch.setenv("DEXLABEL_CAPTURE_ROOTS", f"{allowed}:{tmp_path / 'other'}")
    get_settings.cache_clear()
    status, body = _import(client, admin_headers, small_capture)
    assert status == 403, body
    assert ("(folder 1 of DEXLABEL_CAPTURE_ROOTS, folder 2 of DEXLABEL_CAPTURE_ROOTS)"
            in body["detail"]), body
    _no_server_paths(body["detail"], allowed)
