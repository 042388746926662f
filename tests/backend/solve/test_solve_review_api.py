"""Reviewing solve runs through the API: overlay styles, the frames that need a look, and the
comparison of two runs, on runs whose outputs are the small capture's ground truth (stored
without the solver, see tests/solve_truth.py) so every expected value is known."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from backend.captures.assets import load_mesh
from backend.captures.flows import import_path
from backend.captures.models import SceneObject
from backend.db import session_scope
from backend.solve.pictures import run_arrays
from backend.solve.service import get_run_or_raise
from backend.storage import get_storage
from tests.solve_truth import FLAG_REASON, store_truth_run
from worker.overlay import DARKEN

# The API's bookkeeping does not depend on the database kind: SQLite only, to save time.
pytestmark = pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)

SHIFT_M = (0.003, 0.0, 0.004)  # 5 mm
TURN_DEG = 3.0
FLAGGED = (1, 4)


@pytest.fixture
def runs(client: TestClient, small_capture: Path) -> dict[str, int]:
    """Two done runs of the small capture: the truth (frames 1 and 4 flagged) and the truth
    with the hand 5 mm off and object 0 turned 3 degrees about its z axis."""
    seq = import_path(small_capture)[0].sequence_id
    truth = store_truth_run(small_capture, seq, flagged=FLAGGED)
    moved = store_truth_run(small_capture, seq, hand_shift_m=SHIFT_M, object_turn_deg=TURN_DEG)
    return {"sequence": seq, "truth": truth, "moved": moved}


def _picture(client: TestClient, headers: dict, url: str) -> np.ndarray:
    resp = client.get(url, headers=headers)
    assert resp.status_code == 200, resp.text
    assert resp.headers["content-type"] == "image/png"
    return cv2.imdecode(np.frombuffer(resp.content, np.uint8), cv2.IMREAD_COLOR)


def _joints_px(client: TestClient, headers: dict, run_id: int, frame: int, seq: int
               ) -> np.ndarray:
    """The solved hand joints of ``frame`` projected into view 0 (px, lens included)."""
    joints = np.asarray(client.get(f"/api/solve-runs/{run_id}/frames/{frame}",
                                   headers=headers).json()["hand_joints"])
    cam = client.get(f"/api/sequences/{seq}", headers=headers).json()["cameras"][0]
    c2w = np.asarray(cam["extrinsics"], dtype=np.float64)
    K = np.array([[cam["fx"], 0, cam["ppx"]], [0, cam["fy"], cam["ppy"]], [0, 0, 1]])
    in_cam = (joints - c2w[:, 3]) @ c2w[:, :3]
    uv, _ = cv2.projectPoints(in_cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                              np.asarray(cam["distortion"], dtype=np.float64))
    return uv.reshape(-1, 2)


def test_overlay_styles_draw_solid_blended_or_wire_meshes_over_the_hand(
    client: TestClient, admin_headers: dict, runs: dict[str, int]
) -> None:
    base = f"/api/solve-runs/{runs['truth']}/frames/2/views/0.png"
    plain = client.get(base, headers=admin_headers).content
    assert client.get(f"{base}?style=solid", headers=admin_headers).content == plain
    solid = _picture(client, admin_headers, f"{base}?style=solid")
    wire = _picture(client, admin_headers, f"{base}?style=wireframe")
    blend = _picture(client, admin_headers, f"{base}?style=blend")
    clear = _picture(client, admin_headers, f"{base}?style=blend&alpha=0")
    # alpha 0 draws nothing: the darkened frame is what every style draws over.
    dark = clear.astype(int)

    def changed(picture: np.ndarray) -> np.ndarray:
        return np.abs(picture.astype(int) - dark).max(axis=2) > 12

    uv = np.round(_joints_px(client, admin_headers, runs["truth"], 2, runs["sequence"]))
    h, w = dark.shape[:2]
    box = np.zeros((h, w), bool)
    x0, y0 = np.clip(uv.min(axis=0).astype(int) - 4, 0, [w, h])
    x1, y1 = np.clip(uv.max(axis=0).astype(int) + 5, 0, [w, h])
    box[y0:y1, x0:x1] = True
    solid_px, wire_px = changed(solid)[box].sum(), changed(wire)[box].sum()
    # The wireframe's thin lines cover the hand, but far fewer pixels than its surfaces.
    assert solid_px > 0.5 * box.sum(), (solid_px, box.sum())
    assert 0.05 * solid_px < wire_px < 0.8 * solid_px, (wire_px, solid_px)
    near = cv2.dilate(changed(wire).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    px = uv[inside].astype(int)
    assert inside.sum() >= 15 and near[px[:, 1], px[:, 0]].mean() >= 0.9
    # Blending lets more of the frame through than solid: it stays closer to the dark frame.
    mask = changed(solid)
    assert (np.abs(blend.astype(int) - dark)[mask].mean()
            < np.abs(solid.astype(int) - dark)[mask].mean())
    # Under alpha 0 the picture is the view's colour frame at DARKEN, untouched.
    serial = client.get(f"/api/sequences/{runs['sequence']}",
                        headers=admin_headers).json()["cameras"][0]["serial"]
    jpg = client.get(f"/api/sequences/{runs['sequence']}/views/{serial}/frames/2.jpg",
                     headers=admin_headers)
    colour = cv2.imdecode(np.frombuffer(jpg.content, np.uint8), cv2.IMREAD_COLOR)
    assert np.abs((colour.astype(np.float32) * DARKEN).astype(int) - dark).max() <= 1


def test_overlay_style_and_alpha_out_of_range_are_refused_naming_them(
    client: TestClient, admin_headers: dict, runs: dict[str, int]
) -> None:
    base = f"/api/solve-runs/{runs['truth']}/frames/2/views/0.png"
    for query, field in (("style=outline", "style"), ("alpha=1.5", "alpha"),
                         ("alpha=-0.1", "alpha"), ("alpha=half", "alpha")):
        resp = client.get(f"{base}?{query}", headers=admin_headers)
        assert resp.status_code == 422, (query, resp.text)
        assert field in resp.json()["detail"], resp.json()
    resp = client.get(f"{base}?style=outline", headers=admin_headers)
    assert "wireframe" in resp.json()["detail"]


def test_timeline_lists_the_flagged_frames_with_their_reasons(
    client: TestClient, admin_headers: dict, runs: dict[str, int]
) -> None:
    resp = client.get(f"/api/solve-runs/{runs['truth']}/timeline", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    timeline = resp.json()
    assert timeline["num_frames"] == 6 and len(timeline["frames"]) == 6
    assert [f["frame"] for f in timeline["flagged"]] == list(FLAGGED)
    name = client.get(f"/api/solve-runs/{runs['truth']}/frames/1",
                      headers=admin_headers).json()["objects"][0]["name"]
    assert timeline["flagged"][0]["reasons"] == [f"{name}: {FLAG_REASON}"]
    assert timeline["flagged"][0]["min_confidence"] == 0.2
    # Frame f's errors are 0.5 + f + 0.25 j + v px: mean over 3 views and 21 joints.
    for row in timeline["frames"]:
        assert row["kpt_px_mean"] == pytest.approx(0.5 + row["frame"] + 0.25 * 10 + 1, abs=1e-3)
    other = client.get(f"/api/solve-runs/{runs['moved']}/timeline", headers=admin_headers)
    assert other.json()["flagged"] == []


def test_comparing_a_run_with_itself_finds_no_difference(
    client: TestClient, admin_headers: dict, runs: dict[str, int]
) -> None:
    run = runs["truth"]
    resp = client.get(f"/api/solve-runs/{run}/compare/{run}", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    same = resp.json()
    assert same["run_a"] == same["run_b"] == run and same["num_frames"] == 6
    assert same["hand_mm"] == [0.0] * 6 and same["hand_max_mm"] == [0.0] * 6
    assert same["hand_mean_mm"] == 0.0
    for obj in same["objects"]:
        for key in ("add_mm", "translation_mm", "rotation_deg"):
            assert obj[key] == [0.0] * 6, (obj["name"], key)
    assert all(row["mm"] == 0.0 for row in same["largest"])


def test_comparing_two_runs_measures_what_their_stored_poses_differ_by(
    client: TestClient, admin_headers: dict, runs: dict[str, int]
) -> None:
    resp = client.get(f"/api/solve-runs/{runs['truth']}/compare/{runs['moved']}",
                      headers=admin_headers)
    assert resp.status_code == 200, resp.text
    diff = resp.json()
    with session_scope() as s:
        a = run_arrays(get_run_or_raise(s, runs["truth"]))
        b = run_arrays(get_run_or_raise(s, runs["moved"]))
        meshes = [load_mesh(get_storage(), o.mesh_key).vertices for o in s.scalars(
            select(SceneObject).where(SceneObject.sequence_id == runs["sequence"])
            .order_by(SceneObject.index))]
    # The hand moved rigidly by 5 mm: every joint, every frame.
    joints = np.linalg.norm(a["hand_joints"] - b["hand_joints"], axis=-1) * 1000
    assert np.allclose(joints, 5.0, atol=1e-6)
    assert diff["hand_mm"] == pytest.approx(joints.mean(axis=1).tolist(), abs=1e-3)
    assert diff["hand_max_mm"] == pytest.approx(joints.max(axis=1).tolist(), abs=1e-3)
    turned, still = diff["objects"]
    assert turned["rotation_deg"] == pytest.approx([TURN_DEG] * 6, abs=1e-3)
    assert turned["translation_mm"] == [0.0] * 6
    for o, obj in enumerate(diff["objects"]):
        pa, pb = a["object_poses"][o], b["object_poses"][o]
        add = [np.linalg.norm((meshes[o] @ pa[f, :, :3].T + pa[f, :, 3])
                              - (meshes[o] @ pb[f, :, :3].T + pb[f, :, 3]), axis=1).mean() * 1000
               for f in range(6)]
        assert obj["add_mm"] == pytest.approx(add, abs=1e-3), obj["name"]
    assert still["add_mm"] == [0.0] * 6 and max(turned["add_mm"]) > 0.5
    largest = diff["largest"]
    assert len(largest) == 10 and [r["mm"] for r in largest] == sorted(
        (r["mm"] for r in largest), reverse=True)
    everything = sorted([5.0] * 6 + turned["add_mm"] + still["add_mm"], reverse=True)
    assert [r["mm"] for r in largest] == pytest.approx(everything[:10], abs=1e-3)


@pytest.fixture(scope="module")
def other_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A second, tiny capture: a sequence whose runs cannot be compared with the first's."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("other-capture")
    generate_capture(root, seed=8, frames=6, views=1, objects=1, width=64, height=48)
    return root


def test_comparing_runs_of_different_sequences_or_unfinished_runs_is_refused(
    client: TestClient, admin_headers: dict, runs: dict[str, int], other_capture: Path
) -> None:
    other_seq = import_path(other_capture)[0].sequence_id
    other = store_truth_run(other_capture, other_seq)
    resp = client.get(f"/api/solve-runs/{runs['truth']}/compare/{other}", headers=admin_headers)
    assert resp.status_code == 422 and resp.json()["error"] == "not_comparable"
    assert "different sequences" in resp.json()["detail"]
    with session_scope() as s:
        get_run_or_raise(s, runs["moved"]).status = "running"
    resp = client.get(f"/api/solve-runs/{runs['truth']}/compare/{runs['moved']}",
                      headers=admin_headers)
    assert resp.status_code == 409 and "running" in resp.json()["detail"]
    resp = client.get(f"/api/solve-runs/{runs['moved']}/timeline", headers=admin_headers)
    assert resp.status_code == 409 and "running" in resp.json()["detail"]
    resp = client.get(f"/api/solve-runs/{runs['truth']}/compare/999", headers=admin_headers)
    assert resp.status_code == 404 and "999" in resp.json()["detail"]
    resp = client.get(f"/api/solve-runs/{runs['truth']}/compare/x", headers=admin_headers)
    assert resp.status_code == 422
    assert client.get(f"/api/solve-runs/{runs['truth']}/compare/{other}").status_code == 401


def test_solve_settings_are_the_defaults_a_request_may_override(
    client: TestClient, admin_headers: dict
) -> None:
    resp = client.get("/api/solve-settings?optimiser=paper", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    settings = resp.json()
    assert settings["optimiser"] == "paper"
    assert settings["params"]["w_kpt"] == 1.0 and settings["params"]["use_depth"] is True
    assert "device" not in settings["params"] and "optimiser" not in settings["params"]
    assert settings["kinds"]["w_kpt"] == "float" and settings["kinds"]["lm_iterations"] == "int"
    assert settings["kinds"]["use_depth"] == "bool" and set(settings["kinds"]) == set(
        settings["params"])
    bad = client.get("/api/solve-settings?optimiser=fast", headers=admin_headers)
    assert bad.status_code == 422 and "optimiser" in bad.json()["detail"]
