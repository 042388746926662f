"""The solve domain end to end on the small synthetic capture (3 views x 6 frames, 2 objects).

Approved assignments are made from the capture's ground truth: hand joints from joint_2d with
the visibility a careful person would mark, object landmarks from two mesh vertices projected
with the true object pose. The solve job runs inline (`execute`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
import typer
import yaml
from fastapi.testclient import TestClient
from sqlalchemy import select
from typer.testing import CliRunner

from backend.annotation.models import Task, Track
from backend.annotation.service import create_assignment
from backend.captures.assets import load_mesh
from backend.captures.flows import import_path
from backend.captures.models import Camera, Hand, SceneObject
from backend.captures.truth import CaptureTruth
from backend.cli.solve import calibrate_hand_command, solve_command
from backend.db import session_scope
from backend.jobs.runner import execute
from backend.labels import merge_labels
from backend.solve.service import job_key
from backend.storage import get_storage
from worker.formats.dexycb import HAND_SEG_VALUE
from worker.geometry.cameras import project_camera_points
from worker.hand import builtin_hand_model
from worker.hand.calibrate import bone_lengths, rest_joint_map
from worker.overlay import DARKEN
from worker.synth.annotators import hand_visibility

FRAMES = 6


def _sequence_dir(root: Path) -> Path:
    return next(root.glob("*/*/meta.yml")).parent


def _labels(root: Path, serial: str) -> list[dict]:
    folder = _sequence_dir(root) / serial
    out = []
    for f in range(FRAMES):
        with np.load(folder / f"labels_{f:06d}.npz") as npz:
            out.append({k: npz[k] for k in npz.files})
    return out


def _rows(xy: np.ndarray, visible: np.ndarray, width: int, height: int) -> list[list]:
    """Keyframes at every frame: [frame, x, y, visible01]; None outside the image."""
    rows = []
    for f, ((x, y), vis) in enumerate(zip(xy, visible, strict=True)):
        inside = np.isfinite(x) and 0 <= x < width and 0 <= y < height
        rows.append([f, float(x), float(y), int(vis)] if inside else [f, None, None, 0])
    return rows


def _object_points(root: Path, serial: str, obj: SceneObject, camera: Camera):
    """Two front-surface mesh vertices of the object, tracked with the true pose: (F, 2, 2) px
    and (F, 2) visibility (on the object's pixels and at the depth map's depth)."""
    meta = yaml.safe_load((_sequence_dir(root) / "meta.yml").read_text())
    obj_index = obj.index
    value = int(meta["ycb_ids"][obj_index])
    vertices = load_mesh(get_storage(), obj.mesh_key).vertices
    K = np.array([[camera.fx, 0, camera.ppx], [0, camera.fy, camera.ppy], [0, 0, 1.0]])
    labels = _labels(root, serial)
    xy = np.zeros((FRAMES, len(vertices), 2))
    seen = np.zeros((FRAMES, len(vertices)), dtype=bool)
    for f, lab in enumerate(labels):
        pose = lab["pose_y"][obj_index]
        cam = vertices @ pose[:, :3].T + pose[:, 3]
        xy[f] = project_camera_points(cam, K, np.asarray(camera.distortion))
        px = np.clip(np.round(xy[f]).astype(int), 0, [camera.width - 1, camera.height - 1])
        depth_png = _sequence_dir(root) / serial / f"aligned_depth_to_color_{f:06d}.png"
        depth = cv2.imread(str(depth_png), cv2.IMREAD_UNCHANGED)[px[:, 1], px[:, 0]] / 1000.0
        seen[f] = (lab["seg"][px[:, 1], px[:, 0]] == value) & (np.abs(depth - cam[:, 2]) < 0.01)
    candidates = np.flatnonzero(seen[0])
    if len(candidates) < 2:
        return np.full((FRAMES, 2, 2), np.nan), np.zeros((FRAMES, 2), bool)
    first = candidates[0]
    far = candidates[np.argmax(np.linalg.norm(vertices[candidates] - vertices[first], axis=1))]
    chosen = [first, far]
    return xy[:, chosen], seen[:, chosen]


def _approve(session, task: Task, points: list[list[list]], worker: str = "W1") -> None:
    assignment = create_assignment(session, task, worker)
    assignment.status, assignment.version = "approved", 1
    for p, rows in enumerate(points):
        session.add(Track(assignment_id=assignment.id, point_index=p, keyframes=rows))


def _approve_from_truth(root: Path, sequence_id: int, hands: bool = True) -> None:
    truth = CaptureTruth(root)
    with session_scope() as session:
        tasks = session.scalars(select(Task).where(Task.sequence_id == sequence_id)).all()
        for task in tasks:
            cam = session.get_one(Camera, task.camera_id)
            if task.kind == "hand" and hands:
                joint_2d, seg = truth.view(cam.serial, FRAMES)
                visible = hand_visibility(joint_2d, seg)
                _approve(session, task, [_rows(joint_2d[:, j], visible[:, j], cam.width,
                                               cam.height) for j in range(21)])
            elif task.kind == "object":
                obj = session.get_one(SceneObject, task.object_id)
                xy, visible = _object_points(root, cam.serial, obj, cam)
                _approve(session, task, [_rows(xy[:, p], visible[:, p], cam.width, cam.height)
                                         for p in range(2)])


@pytest.fixture
def sequence(client: TestClient, admin_headers: dict, small_capture: Path) -> int:
    seq_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return seq_id


@pytest.fixture
def approved(sequence: int, small_capture: Path) -> int:
    _approve_from_truth(small_capture, sequence)
    return sequence


def _solve(client: TestClient, headers: dict, seq_id: int, body: dict | None = None) -> dict:
    resp = client.post(f"/api/sequences/{seq_id}/solve", json=body, headers=headers)
    assert resp.status_code == 200, resp.text
    run = resp.json()
    assert run["status"] == "queued" and run["num_frames"] == FRAMES and run["num_views"] == 3
    execute(job_key(run["id"]))
    return client.get(f"/api/solve-runs/{run['id']}", headers=headers).json()


def _true_world_joints(root: Path, serial: str, extrinsics: list) -> np.ndarray:
    T = np.asarray(extrinsics)
    cam = np.stack([lab["joint_3d"][0] for lab in _labels(root, serial)])
    return cam @ T[:, :3].T + T[:, 3]


def _check_frame_json(client: TestClient, headers: dict, run_id: int, cameras: list[dict],
                      root: Path) -> None:
    frame = client.get(f"/api/solve-runs/{run_id}/frames/2", headers=headers).json()
    assert frame["labelled"] is True and frame["reason"] is None
    assert len(frame["hand_pose_m"]) == 51 and len(frame["hand_joints"]) == 21
    assert [o["index"] for o in frame["objects"]] == [0, 1]
    assert len(frame["objects"][0]["pose"]) == 3 and len(frame["objects"][0]["pose"][0]) == 4
    serial = cameras[0]["serial"]
    assert set(frame["kpt_error_px"]) == {c["serial"] for c in cameras}
    assert len(frame["kpt_error_px"][serial]) == 21 and frame["hand_vertices"] is None
    truth = _true_world_joints(root, serial, cameras[0]["extrinsics"])[2]
    error_mm = np.linalg.norm(np.asarray(frame["hand_joints"]) - truth, axis=1).mean() * 1000
    assert error_mm < 10.0
    with_mesh = client.get(f"/api/solve-runs/{run_id}/frames/2?vertices=true",
                           headers=headers).json()
    model = builtin_hand_model("right")  # no DEXLABEL_MANO_DIR here: the built-in hand
    assert np.asarray(with_mesh["hand_vertices"]).shape == model.v_template.shape
    assert np.asarray(with_mesh["hand_faces"]).shape == model.faces.shape


def _true_world_poses(root: Path, serial: str, extrinsics: list) -> np.ndarray:
    """(F, O, 3, 4) true object-to-world poses, from one view's labels and its extrinsics."""
    T = np.asarray(extrinsics)
    cam = np.stack([lab["pose_y"] for lab in _labels(root, serial)])
    return np.concatenate([T[:, :3] @ cam[..., :3], (T[:, :3] @ cam[..., 3:]) + T[:, 3:]], -1)


def _add_mm(vertices: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance (mm) between the model's vertices posed by a and by b (3, 4)."""
    pa, pb = vertices @ a[:, :3].T + a[:, 3], vertices @ b[:, :3].T + b[:, 3]
    return float(np.linalg.norm(pa - pb, axis=1).mean() * 1000.0)


def _check_object_poses(client: TestClient, headers: dict, run: dict, cameras: list[dict],
                        root: Path) -> None:
    """Every object pose in every frame is within 3 mm (ADD) of the truth or flagged with a
    reason; an object that does not move keeps its pose exactly; the grasped object is held in
    the frames where it is lifted, its landmarks hidden in some of them."""
    truth = _true_world_poses(root, cameras[0]["serial"], cameras[0]["extrinsics"])
    with session_scope() as s:
        meshes = {o.index: load_mesh(get_storage(), o.mesh_key).vertices for o in s.scalars(
            select(SceneObject).where(SceneObject.sequence_id == run["sequence_id"]))}
    solved = []
    for f in range(FRAMES):
        frame = client.get(f"/api/solve-runs/{run['id']}/frames/{f}", headers=headers).json()
        for obj in frame["objects"]:
            o, pose = obj["index"], np.asarray(obj["pose"], dtype=np.float64)
            error = _add_mm(meshes[o], pose, truth[f, o])
            assert 0.0 <= obj["confidence"] <= 1.0
            if obj["flag"] is None:
                assert error < 3.0, (f, o, error)
            else:
                assert obj["confidence"] < 1.0 and len(obj["flag"]) > 10, obj["flag"]
        solved.append([np.asarray(obj["pose"]) for obj in frame["objects"]])
    poses = np.asarray(solved)  # (F, O, 3, 4)
    moving = [o for o in meshes if _add_mm(meshes[o], truth[-1, o], truth[0, o]) > 1.0]
    assert len(moving) == 1, "the fixture lifts one object"
    for o in meshes:
        if o not in moving:
            assert np.abs(poses[:, o] - poses[0, o]).max() < 1e-9, "a static object moved"
    lifted = poses[-1, moving[0]]
    assert _add_mm(meshes[moving[0]], lifted, truth[-1, moving[0]]) < 3.0
    assert run["summary"]["object_flags"] == [
        f"frame {f}: {r}" for f in range(FRAMES) for o in sorted(meshes)
        if (r := client.get(f"/api/solve-runs/{run['id']}/frames/{f}", headers=headers)
            .json()["objects"][o]["flag"]) is not None]


def _check_pictures(client: TestClient, headers: dict, run_id: int, camera: dict,
                    root: Path) -> None:
    serial = camera["serial"]
    png = client.get(f"/api/solve-runs/{run_id}/frames/2/views/{serial}.png", headers=headers)
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    picture = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_COLOR)
    assert picture.shape == (camera["height"], camera["width"], 3)
    colour = cv2.imread(str(_sequence_dir(root) / serial / "color_000002.jpg"))
    dark = (colour.astype(np.float32) * DARKEN).astype(np.uint8)
    seg = _labels(root, serial)[2]["seg"]
    hand = seg == HAND_SEG_VALUE
    changed = np.abs(picture.astype(int) - dark.astype(int)).max(axis=2) > 12
    # The solved hand covers the true hand's pixels and leaves the background dark.
    assert hand.sum() > 200 and changed[hand].mean() > 0.8
    assert changed[seg == 0].mean() < 0.1
    by_index = client.get(f"/api/solve-runs/{run_id}/frames/2/views/0.png", headers=headers)
    assert by_index.content == png.content
    bars = client.get(f"/api/solve-runs/{run_id}/frames/2/residuals.png", headers=headers)
    assert bars.status_code == 200
    plot = cv2.imdecode(np.frombuffer(bars.content, np.uint8), cv2.IMREAD_COLOR)
    assert plot is not None and plot.shape[2] == 3 and (plot != 255).any()


def _check_bad_addresses(client: TestClient, headers: dict, run_id: int) -> None:
    base = f"/api/solve-runs/{run_id}/frames"
    for url in (f"{base}/6", f"{base}/6/residuals.png", f"{base}/6/views/0.png"):
        resp = client.get(url, headers=headers)
        assert resp.status_code == 404 and "frames 0..5" in resp.json()["detail"], url
    # A negative index is not an index at all: refused at the edge, naming the parameter.
    resp = client.get(f"{base}/-1/residuals.png", headers=headers)
    assert resp.status_code == 422 and "frame" in resp.json()["detail"], resp.json()
    resp = client.get(f"{base}/0/views/3.png", headers=headers)
    assert resp.status_code == 404 and "views 0..2" in resp.json()["detail"]
    assert client.get("/api/solve-runs/999", headers=headers).status_code == 404
    assert client.get(f"{base}/0").status_code == 401


def test_a_solve_run_fits_the_accepted_labels_and_serves_frames_and_pictures(
    client: TestClient, admin_headers: dict, approved: int, small_capture: Path
) -> None:
    # The fixture plays a whole grasp in 6 frames (0.2 s at 30 fps), far faster than a hand can
    # close: the pose-smoothness prior, which assumes 30 fps continuity, is switched off for it.
    run = _solve(client, admin_headers, approved,
                 {"optimiser": "default", "params": {"w_smooth_pose": 0.0}})
    assert run["status"] == "done", run["error"]
    assert run["current"] is True and run["optimiser"] == "default"
    assert run["params"]["optimiser"] == "default" and "w_kpt" in run["params"]
    summary = run["summary"]
    assert summary["labelled_frames"] >= 4 and summary["frames"] == FRAMES
    assert set(summary["fingertip_px"]) == {"thumb", "index", "middle", "ring", "little"}
    assert summary["kpt_px_mean"] < 3.0  # labels are exact; the fit reprojects onto them
    assert run["timings"]["total_s"] > 0 and run["timings"]["gather_s"] > 0
    cameras = client.get(f"/api/sequences/{approved}", headers=admin_headers).json()["cameras"]
    _check_frame_json(client, admin_headers, run["id"], cameras, small_capture)
    _check_object_poses(client, admin_headers, run, cameras, small_capture)
    _check_pictures(client, admin_headers, run["id"], cameras[0], small_capture)
    _check_bad_addresses(client, admin_headers, run["id"])


def test_solve_is_refused_without_betas_or_accepted_tracks_but_not_without_initial_pose(
    client: TestClient, admin_headers: dict, sequence: int, small_capture: Path
) -> None:
    url = f"/api/sequences/{sequence}/solve"
    resp = client.post(url, headers=admin_headers)
    assert resp.status_code == 409
    assert "no accepted (approved) tracks" in resp.json()["detail"]
    _approve_from_truth(small_capture, sequence)
    with session_scope() as s:
        s.scalars(select(Hand).where(Hand.sequence_id == sequence)).one().betas = None
        obj = s.scalars(select(SceneObject).where(SceneObject.sequence_id == sequence,
                                                  SceneObject.index == 1)).one()
        pose, name = obj.initial_pose, obj.name
        obj.initial_pose = None
    # No initial pose is not refused: the solve fits one (or fails naming the object); the
    # missing betas are.
    resp = client.post(url, headers=admin_headers)
    assert resp.status_code == 409 and resp.json()["error"] == "not_ready"
    assert "run `dexlabel calibrate-hand" in resp.json()["detail"] and name not in resp.text
    bad = client.put(f"/api/sequences/{sequence}/objects/1/initial-pose",
                     json={"pose": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]},
                     headers=admin_headers)
    assert bad.status_code == 422 and "rotation" in bad.json()["detail"]
    put = client.put(f"/api/sequences/{sequence}/objects/1/initial-pose", json={"pose": pose},
                     headers=admin_headers)
    assert put.status_code == 200, put.text
    resp = client.post(url, headers=admin_headers)
    assert resp.status_code == 409 and "run `dexlabel calibrate-hand" in resp.json()["detail"]
    assert client.post(url, json={"optimiser": "fast"}, headers=admin_headers).status_code == 422
    for params, problem in (({"w_fast": 1.0}, "params.w_fast is not a solver setting"),
                            ({"device": 0}, "params.device is not a solver setting"),
                            ({"use_depth": 1}, "params.use_depth must be a bool"),
                            ({"lm_iterations": 2.5}, "params.lm_iterations must be a int")):
        resp = client.post(url, json={"params": params}, headers=admin_headers)
        assert resp.status_code == 422 and problem in resp.json()["detail"], resp.text
    runs = client.get(f"/api/sequences/{sequence}/solve-runs", headers=admin_headers).json()
    assert runs == []


def test_the_deployment_s_solver_settings_apply_under_a_request_s_own(
    client: TestClient, admin_headers: dict, approved: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_SOLVE_PARAMS", '{"w_depth": 5.0, "lm_iterations": 3}')
    get_settings.cache_clear()
    url = f"/api/sequences/{approved}/solve"
    run = client.post(url, headers=admin_headers).json()
    assert (run["params"]["w_depth"], run["params"]["lm_iterations"]) == (5.0, 3)
    own = client.post(url, json={"params": {"w_depth": 2.0}}, headers=admin_headers).json()
    assert (own["params"]["w_depth"], own["params"]["lm_iterations"]) == (2.0, 3)
    monkeypatch.setenv("DEXLABEL_SOLVE_PARAMS", '{"w_nothing": 1}')
    get_settings.cache_clear()
    bad = client.post(url, headers=admin_headers)
    assert bad.status_code == 422 and "w_nothing is not a solver setting" in bad.json()["detail"]


def test_a_failing_solve_leaves_the_previous_run_current(
    client: TestClient, admin_headers: dict, approved: int
) -> None:
    first = _solve(client, admin_headers, approved, {"params": {"use_depth": False}})
    assert first["status"] == "done" and first["params"]["use_depth"] is False
    resp = client.post(f"/api/sequences/{approved}/solve", headers=admin_headers)
    second = resp.json()
    again = client.post(f"/api/sequences/{approved}/solve", headers=admin_headers).json()
    assert again["id"] == second["id"], "a run still queued is not queued twice"
    # The pose goes missing after the request was accepted and cannot be fitted again (these
    # synthetic shapes fit their depth equally in several poses): the run fails, naming it.
    with session_scope() as s:
        s.scalars(select(SceneObject).where(SceneObject.sequence_id == approved)
                  ).first().initial_pose = None
    execute(job_key(second["id"]))
    runs = client.get(f"/api/sequences/{approved}/solve-runs", headers=admin_headers).json()
    assert [r["id"] for r in runs] == [second["id"], first["id"]]
    assert runs[0]["status"] == "failed" and "no initial pose" in runs[0]["error"]
    assert "none could be fitted to frame 0" in runs[0]["error"]
    assert runs[0]["current"] is False and runs[1]["current"] is True
    resp = client.get(f"/api/solve-runs/{second['id']}/frames/0", headers=admin_headers)
    assert resp.status_code == 409 and "failed" in resp.json()["detail"]
    ok = client.get(f"/api/solve-runs/{first['id']}/frames/0", headers=admin_headers)
    assert ok.status_code == 200


def _cli() -> typer.Typer:
    app = typer.Typer()
    app.command("solve")(solve_command)
    app.command("calibrate-hand")(calibrate_hand_command)
    return app


# The command-line functions do not depend on the database kind: SQLite only, to save time.
@pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
def test_calibrate_hand_recovers_the_subjects_bone_lengths_from_accepted_tracks(
    approved: int, small_capture: Path
) -> None:
    runner = CliRunner()
    with session_scope() as s:
        hand = s.scalars(select(Hand).where(Hand.sequence_id == approved)).one()
        true_betas = np.asarray(hand.betas)
    refused = runner.invoke(_cli(), ["calibrate-hand", str(approved)])
    assert refused.exit_code == 2 and "--force" in refused.output  # bad input: exit 2
    result = runner.invoke(_cli(), ["calibrate-hand", str(approved), "--force"])
    assert result.exit_code == 0, result.output
    with session_scope() as s:
        fitted = np.asarray(s.scalars(select(Hand).where(Hand.sequence_id == approved))
                            .one().betas)
    assert fitted.shape == (10,) and not np.allclose(fitted, true_betas)
    base, basis = rest_joint_map(builtin_hand_model("right"))
    error = bone_lengths(base + basis @ fitted) - bone_lengths(base + basis @ true_betas)
    assert np.abs(error).max() < 1e-3


@pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
def test_the_solve_command_waits_for_the_run_and_prints_its_summary(
    approved: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from backend.cli import solve as solve_cli

    # --json without --wait: stdout is the queued run as one JSON document, nothing else.
    queued = CliRunner().invoke(_cli(), ["solve", str(approved), "--json"])
    assert queued.exit_code == 0, queued.output
    assert json.loads(queued.stdout) == {"run_id": 1, "status": "queued",
                                         "optimiser": "default"}
    assert "solve run 1 queued" in queued.stderr
    # --wait takes that queued run over; off a terminal it says the solve is alive as it runs.
    monkeypatch.setattr(solve_cli, "TICK_S", 0.5)
    result = CliRunner().invoke(_cli(), ["solve", str(approved), "--optimiser", "default",
                                         "--wait"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    ticks = [line for line in lines if re.fullmatch(r"solve run 1: running, \d+ s", line)]
    assert ticks, result.output
    done = lines.index(next(line for line in lines if line.startswith("solve run 1 done in ")))
    assert lines.index(ticks[0]) < done
    # The result in a few readable lines, no JSON.
    result_lines = lines[done:]
    assert len(result_lines) <= 8 and "{" not in result.output
    assert re.fullmatch(r"solve run 1 done in \d+\.\d s \(default optimiser\)", result_lines[0])
    assert any(re.fullmatch(r"  frames labelled: \d+ of \d+", line) for line in result_lines)
    assert any(re.fullmatch(r"  keypoint error: median \d+\.\d\d px, mean \d+\.\d\d px", line)
               for line in result_lines), result_lines
    assert all(len(line) <= 100 for line in result_lines)
    refused = CliRunner().invoke(_cli(), ["solve", "no-such/sequence"])
    assert refused.exit_code == 2 and "no sequence" in refused.output


def test_several_approved_labels_of_one_view_merge_to_the_median_and_the_majority() -> None:
    xy = np.zeros((3, 2, 2, 2))  # workers, frames, points, xy
    xy[:, 0, 0] = [[10, 5], [12, 6], [30, 40]]  # one wild worker: the median ignores it
    xy[:, 0, 1] = [[1, 1], [np.nan, np.nan], [3, 3]]  # one did not place it
    xy[:, 1, 0] = np.nan  # nobody placed it
    xy[:, 1, 1] = [[7, 7], [8, 8], [9, 9]]
    visible = np.zeros((3, 2, 2), dtype=bool)
    visible[:, 0, 0] = [True, True, False]
    visible[:, 1, 1] = [True, False, False]
    merged, vis = merge_labels([(xy[a], visible[a]) for a in range(3)])
    assert merged[0, 0].tolist() == [12, 6] and merged[0, 1].tolist() == [2, 2]
    assert np.isnan(merged[1, 0]).all() and merged[1, 1].tolist() == [8, 8]
    assert vis.tolist() == [[True, False], [False, False]]


@pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
def test_calibrate_hand_without_accepted_hand_tracks_says_so(sequence: int) -> None:
    result = CliRunner().invoke(_cli(), ["calibrate-hand", str(sequence), "--force"])
    assert result.exit_code == 2
    assert f"cannot calibrate hand 0 of sequence {sequence}" in result.output
    assert "fewer than 3 frames" in result.output
    with session_scope() as s:
        assert s.scalars(select(Hand).where(Hand.sequence_id == sequence)).one().betas
