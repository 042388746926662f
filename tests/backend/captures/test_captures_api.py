from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from backend.captures.frames import parse_bundle
from tests.backend.captures import capture_edits as edit


@pytest.fixture
def imported(client: TestClient, small_capture: Path) -> dict:
    result = import_path(small_capture)[0]
    serials = [str(s) for s in edit.meta(small_capture)["serials"]]
    return {"id": result.sequence_id, "serials": serials}


def test_login_with_a_wrong_password_is_refused(client: TestClient) -> None:
    resp = client.post("/api/auth/token", json={"email": "admin@example.org", "password": "nope"})
    assert resp.status_code == 401
    assert resp.json()["error"] == "unauthorized"


def test_sequences_need_an_admin(client: TestClient, imported: dict) -> None:
    assert client.get("/api/sequences").status_code == 401
    bad = client.get("/api/sequences", headers={"Authorization": "Bearer forged.token"})
    assert bad.status_code == 401 and "signature" in bad.json()["detail"]


def test_sequence_lists_cameras_objects_and_hands(
    client: TestClient, admin_headers: dict, imported: dict
) -> None:
    listing = client.get("/api/sequences", headers=admin_headers).json()
    assert [s["id"] for s in listing] == [imported["id"]]
    seq = client.get(f"/api/sequences/{imported['id']}", headers=admin_headers).json()
    assert [c["serial"] for c in seq["cameras"]] == imported["serials"]
    extrinsics = seq["cameras"][0]["extrinsics"]
    assert len(extrinsics) == 3 and len(extrinsics[0]) == 4
    assert seq["num_frames"] == 6 and len(seq["objects"]) == 2
    assert seq["hands"][0]["side"] == "right"


def test_unknown_sequence_is_404_with_the_id_named(client: TestClient, admin_headers: dict) -> None:
    resp = client.get("/api/sequences/999", headers=admin_headers)
    assert resp.status_code == 404 and "999" in resp.json()["detail"]


def test_frame_bundle_holds_every_frame_of_the_view_in_order(
    client: TestClient, admin_headers: dict, imported: dict, small_capture: Path
) -> None:
    serial = imported["serials"][1]
    resp = client.get(f"/api/sequences/{imported['id']}/views/{serial}/frames.bin",
                      headers=admin_headers)
    assert resp.status_code == 200
    assert resp.headers["content-type"] == "application/x-dexlabel-frames"
    header, blobs = parse_bundle(resp.content)
    assert [f["index"] for f in header["frames"]] == list(range(6))
    folder = edit.sequence_dir(small_capture) / serial
    assert blobs == [(folder / f"color_{i:06d}.jpg").read_bytes() for i in range(6)]
    again = client.get(f"/api/sequences/{imported['id']}/views/{serial}/frames.bin",
                       headers={**admin_headers, "If-None-Match": resp.headers["etag"]})
    assert again.status_code == 304


def test_manifest_urls_serve_colour_and_depth(
    client: TestClient, admin_headers: dict, imported: dict
) -> None:
    serial = imported["serials"][0]
    manifest = client.get(f"/api/sequences/{imported['id']}/views/{serial}/frames",
                          headers=admin_headers).json()
    assert manifest["num_frames"] == 6 and manifest["width"] > 0
    colour = client.get(manifest["frames"][3]["url"], headers=admin_headers)
    assert colour.headers["content-type"] == "image/jpeg"
    assert len(colour.content) == manifest["frames"][3]["bytes"]
    depth = client.get(manifest["frames"][3]["depth_url"], headers=admin_headers)
    assert depth.content[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_view_token_opens_its_own_view_only(
    client: TestClient, admin_headers: dict, imported: dict
) -> None:
    seq_id, (s0, s1, _) = imported["id"], imported["serials"]
    assert client.get(f"/api/sequences/{seq_id}/views/{s0}/frames.bin").status_code == 401
    token = client.post(f"/api/sequences/{seq_id}/views/{s0}/token", headers=admin_headers).json()
    own = client.get(f"/api/sequences/{seq_id}/views/{s0}/frames?token={token['token']}")
    assert own.status_code == 200
    # URLs in the manifest carry the token on, so the page can follow them as they are.
    assert client.get(own.json()["bundle_url"]).status_code == 200
    other = client.get(f"/api/sequences/{seq_id}/views/{s1}/frames.bin?token={token['token']}")
    assert other.status_code == 403


def test_frame_out_of_range_and_unknown_camera_are_404(
    client: TestClient, admin_headers: dict, imported: dict
) -> None:
    seq_id, serial = imported["id"], imported["serials"][0]
    resp = client.get(f"/api/sequences/{seq_id}/views/{serial}/frames/6.jpg", headers=admin_headers)
    assert resp.status_code == 404 and "0..5" in resp.json()["detail"]
    resp = client.get(f"/api/sequences/{seq_id}/views/nope/frames", headers=admin_headers)
    assert resp.status_code == 404 and "nope" in resp.json()["detail"]


def test_import_endpoint_reports_the_broken_file(
    client: TestClient, admin_headers: dict, small_capture: Path, app_env: dict
) -> None:
    cap = edit.copy_capture(small_capture, Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "c")
    (edit.sequence_dir(cap) / "meta.yml").write_text("serials: [")
    resp = client.post("/api/captures/import", json={"path": str(cap)}, headers=admin_headers)
    assert resp.status_code == 422
    body = resp.json()
    assert body["error"] == "invalid_capture" and body["path"].endswith("meta.yml")


def test_import_endpoint_needs_a_path(client: TestClient, admin_headers: dict) -> None:
    resp = client.post("/api/captures/import", json={}, headers=admin_headers)
    assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "path"


def test_a_view_longer_than_the_bundle_limit_points_to_the_manifest(
    client: TestClient, admin_headers: dict, imported: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.config import get_settings

    monkeypatch.setattr(get_settings(), "max_bundle_frames", 4)
    resp = client.get(f"/api/sequences/{imported['id']}/views/{imported['serials'][0]}/frames.bin",
                      headers=admin_headers)
    assert resp.status_code == 413 and "manifest" in resp.json()["detail"]


def test_import_endpoint_refuses_a_truncated_jpeg_naming_it(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path
) -> None:
    cap = edit.copy_capture(small_capture, Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "c")
    serial = str(edit.meta(cap)["serials"][0])
    frame = edit.sequence_dir(cap) / serial / "color_000005.jpg"
    frame.write_bytes(frame.read_bytes()[:-3000])
    resp = client.post("/api/captures/import", json={"path": str(cap)}, headers=admin_headers)
    assert resp.status_code == 422, resp.text
    body = resp.json()
    assert body["error"] == "invalid_capture"
    assert body["path"].endswith(f"{serial}/color_000005.jpg")
    assert "does not decode" in body["detail"]
    assert client.get("/api/sequences", headers=admin_headers).json() == []


def _import(client: TestClient, headers: dict, path: str) -> tuple[int, dict]:
    resp = client.post("/api/captures/import", json={"path": path}, headers=headers)
    return resp.status_code, resp.json()


def _nothing_imported(client: TestClient, headers: dict) -> bool:
    return client.get("/api/sequences", headers=headers).json() == []


def test_import_endpoint_takes_a_capture_in_the_instance_folder(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path
) -> None:
    var_dir = Path(app_env["DEXLABEL_VAR_DIR"])
    cap = edit.copy_capture(small_capture, var_dir / "captures" / "ok")
    status, body = _import(client, admin_headers, str(cap))
    assert status == 200 and body[0]["created"], body
    other = edit.copy_capture(small_capture, var_dir / "demo-like")
    status, body = _import(client, admin_headers, str(other))
    assert status == 200 and not body[0]["created"], body


def test_import_endpoint_refuses_a_path_with_a_nul_or_too_long(
    client: TestClient, admin_headers: dict, app_env: dict
) -> None:
    captures = Path(app_env["DEXLABEL_VAR_DIR"]) / "captures"
    status, body = _import(client, admin_headers, f"{captures}/a\x00b")
    assert status == 422, body
    assert "path" in body["detail"] and "NUL" in body["detail"]
    status, body = _import(client, admin_headers, f"{captures}/" + "x" * 5000)
    assert status == 422, body
    assert "path" in body["detail"] and "4096" in body["detail"]
    status, body = _import(client, admin_headers, f"{captures}/" + "y" * 3000)
    assert status == 422 and body["error"] == "invalid_capture", body
    assert "does not exist" in body["detail"] and len(body["detail"]) < 400
    assert _nothing_imported(client, admin_headers)


def test_import_endpoint_refuses_a_path_outside_the_capture_roots(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path,
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.config import get_settings

    outside = edit.copy_capture(small_capture, tmp_path / "elsewhere")
    for path in (str(outside), "/etc", f"{app_env['DEXLABEL_VAR_DIR']}/../elsewhere"):
        status, body = _import(client, admin_headers, path)
        assert status == 403, body
        assert "outside the folders captures are imported from" in body["detail"]
        assert "DEXLABEL_CAPTURE_ROOTS" in body["detail"]
    link = Path(app_env["DEXLABEL_VAR_DIR"]) / "captures" / "link"
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(outside)
    status, body = _import(client, admin_headers, str(link))
    assert status == 403 and "a symbolic link leads outside" in body["detail"], body
    assert str(outside) not in body["detail"]
    assert _nothing_imported(client, admin_headers)

    monkeypatch.setenv("DEXLABEL_CAPTURE_ROOTS", f"/nowhere:{tmp_path}")
    get_settings.cache_clear()
    status, body = _import(client, admin_headers, str(outside))
    assert status == 200 and body[0]["created"], body


def test_import_endpoint_refuses_a_capture_whose_root_is_outside(
    client: TestClient, admin_headers: dict, small_capture: Path, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch
) -> None:
    """A sequence folder right inside an allowed folder: its capture root (calibration and
    models) is the folder above, outside."""
    import shutil

    from backend.config import get_settings

    allowed = tmp_path / "allowed"
    allowed.mkdir()
    seq = shutil.copytree(edit.sequence_dir(small_capture), allowed / "seq")
    monkeypatch.setenv("DEXLABEL_CAPTURE_ROOTS", f'["{allowed}"]')
    get_settings.cache_clear()
    status, body = _import(client, admin_headers, str(seq))
    assert status == 403, body
    assert f"the capture root of {seq}" in body["detail"]
    assert "(folder 1 of DEXLABEL_CAPTURE_ROOTS)" in body["detail"]
