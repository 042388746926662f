"""The largest frame an import takes (DEXLABEL_MAX_FRAME_WIDTH x DEXLABEL_MAX_FRAME_HEIGHT,
4096 x 4096 by default): a camera over it is refused from its intrinsics, before any frame is
decoded, with a clear 422 over HTTP and an error line from `dexlabel import`."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from tests.backend.captures import capture_edits as edit

HUGE = 16000


def _enlarge_first_camera(capture: Path) -> str:
    """The first camera's intrinsics say HUGE x HUGE and its first frame's header agrees (a
    file of a few bytes: decoding it would be the first thing to fail). Its serial."""
    serial = str(edit.meta(capture)["serials"][0])
    path = next((capture / "calibration" / "intrinsics").glob(f"{serial}_*.yml"))
    doc = yaml.safe_load(path.read_text())
    doc["color"].update(width=HUGE, height=HUGE)
    path.write_text(yaml.safe_dump(doc))
    sof = b"\xff\xc0\x00\x11\x08" + HUGE.to_bytes(2, "big") * 2 + b"\x03" + b"\x00" * 9
    (edit.sequence_dir(capture) / serial / "color_000000.jpg").write_bytes(b"\xff\xd8" + sof)
    return serial


def test_a_frame_over_the_limit_is_refused_from_the_intrinsics_over_http(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path,
) -> None:
    cap = edit.copy_capture(small_capture, Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "c")
    serial = _enlarge_first_camera(cap)
    resp = client.post("/api/captures/import", json={"path": str(cap)}, headers=admin_headers)
    assert resp.status_code == 422, resp.text
    body = resp.json()
    assert body["error"] == "invalid_capture"
    assert body["path"].startswith(f"calibration/intrinsics/{serial}_")
    assert (f"frames of {HUGE}x{HUGE} are larger than an import takes (4096x4096: "
            "DEXLABEL_MAX_FRAME_WIDTH, DEXLABEL_MAX_FRAME_HEIGHT)") in body["detail"]
    assert client.get("/api/sequences", headers=admin_headers).json() == []


def test_the_limit_is_a_setting_and_the_cli_names_it(
    app_env: dict, small_capture: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from backend.cli import app
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_MAX_FRAME_WIDTH", "320")
    get_settings.cache_clear()
    done = CliRunner().invoke(app, ["import", str(small_capture)])
    assert done.exit_code == 2, done.output
    assert "frames of 640x480 are larger than an import takes (320x4096" in done.output
    monkeypatch.setenv("DEXLABEL_MAX_FRAME_WIDTH", "640")
    get_settings.cache_clear()
    done = CliRunner().invoke(app, ["import", str(small_capture)])
    assert done.exit_code == 0, done.output
