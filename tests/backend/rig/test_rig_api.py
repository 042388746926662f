"""Rig health through the API and the CLI on the small synthetic capture (3 views x 6 frames):
the estimate runs as a job from the accepted labels, stores a new calibration version without
touching the imported one, and adopting a version changes the camera models the solve, QC and
export read; bad ids are refused with 4xx, the CLI refuses a sequence without labels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select
from typer.testing import CliRunner

from backend.captures.calibration import CalibrationVersion, calibrated_models
from backend.captures.flows import import_path
from backend.captures.models import Hand
from backend.captures.service import sequence_cameras
from backend.cli import app as cli_app
from backend.db import session_scope
from backend.jobs.runner import execute
from backend.rig.service import job_key
from backend.solve.inputs import gather_inputs
from tests.backend.solve.test_solve_api import _approve_from_truth

pytestmark = pytest.mark.slow


@pytest.fixture
def sequence(client: TestClient, admin_headers: dict, small_capture: Path) -> int:
    seq_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return seq_id


def _imported_extrinsics(seq_id: int) -> list:
    with session_scope() as s:
        return [c.extrinsics for c in sequence_cameras(s, seq_id)]


def test_rig_health_is_estimated_stored_and_adopted(client: TestClient, admin_headers: dict,
                                                    sequence: int,
                                                    small_capture: Path) -> None:
    url = f"/api/sequences/{sequence}/rig-health"
    first = client.get(url, headers=admin_headers).json()
    assert first["report"] is None and first["version_in_use"] == 0
    _approve_from_truth(small_capture, sequence)
    imported = _imported_extrinsics(sequence)
    queued = client.post(url, headers=admin_headers)
    assert queued.status_code == 202 and queued.json()["job_status"] == "queued"
    execute(job_key(sequence))
    status = client.get(url, headers=admin_headers).json()
    report = status["report"]
    assert status["job_status"] == "done" and report["version"] == 1
    assert not report["in_use"] and len(report["cameras"]) == 3
    # Labels from the truth on a calibrated rig: no camera is off.
    assert report["faulty"] == [] and all(c["time_offset_frames"] == 0
                                          for c in report["cameras"])
    assert all(c["residual_px_after"] < 1.0 for c in report["cameras"])
    # The imported hand shape is the subject's: its bones match the labelled ones.
    [hand] = report["hands"]
    assert hand["faults"] == [] and hand["bone_diff_median_mm"] < 0.5 and hand["frames"] >= 3
    assert _imported_extrinsics(sequence) == imported
    # A version in use changes the models every reader takes; the imported rows stay.
    with session_scope() as s:
        version = s.scalars(select(CalibrationVersion)).one()
        moved = dict(version.cameras)
        serial = next(iter(moved))
        entry = dict(moved[serial])
        entry["extrinsics"] = (np.asarray(entry["extrinsics"]) + [0, 0, 0, 0.01]).tolist()
        moved[serial] = entry
        version.cameras = moved
    adopted = client.post(f"/api/sequences/{sequence}/calibrations/1/adopt",
                          json={"solve": False}, headers=admin_headers)
    assert adopted.status_code == 200, adopted.text
    assert adopted.json() == {"sequence_id": sequence, "version_in_use": 1,
                              "solve": "not requested"}
    with session_scope() as s:
        models = calibrated_models(s, sequence_cameras(s, sequence))
    shifted = np.asarray(imported[0]) + [0, 0, 0, 0.01]
    assert np.allclose(models[0].T_cam_to_world, shifted)
    assert _imported_extrinsics(sequence) == imported
    back = client.post(f"/api/sequences/{sequence}/calibrations/0/adopt",
                       headers=admin_headers).json()
    assert back["version_in_use"] == 0 and back["solve"].startswith("solve run ")
    with session_scope() as s:
        models = calibrated_models(s, sequence_cameras(s, sequence))
    assert np.allclose(models[0].T_cam_to_world, imported[0])


def _rest_bones(betas: list[float]) -> np.ndarray:
    from worker.hand.calibrate import bone_lengths, rest_joint_map
    from worker.hand.model import load_hand_model

    base, basis = rest_joint_map(load_hand_model("right"))
    return bone_lengths(base + basis @ np.asarray(betas))


def test_a_wrong_hand_shape_is_named_and_refined_in_the_version(
        client: TestClient, admin_headers: dict, sequence: int, small_capture: Path) -> None:
    _approve_from_truth(small_capture, sequence)
    with session_scope() as s:
        hand = s.scalars(select(Hand).where(Hand.sequence_id == sequence)).one()
        true_betas = list(hand.betas)
        # Another subject's shape in the calibration: every bone a few mm off.
        hand.betas = [b + (1.5 if i == 0 else 0.0) for i, b in enumerate(true_betas)]
    off_mm = np.abs(_rest_bones(true_betas) - _rest_bones(
        [b + (1.5 if i == 0 else 0.0) for i, b in enumerate(true_betas)])) * 1000.0
    assert np.median(off_mm) > 1.5
    url = f"/api/sequences/{sequence}/rig-health"
    client.post(url, headers=admin_headers)
    execute(job_key(sequence))
    report = client.get(url, headers=admin_headers).json()["report"]
    [row] = report["hands"]
    assert row["faults"] and row["faults"][0].startswith("hand shape off")
    assert abs(row["bone_diff_median_mm"] - float(np.median(off_mm))) < 0.5
    assert report["faulty"] == []  # the cameras are fine
    # The version carries the fitted shape; in use, the solve reads it (the import is kept).
    adopted = client.post(f"/api/sequences/{sequence}/calibrations/1/adopt",
                          json={"solve": False}, headers=admin_headers)
    assert adopted.status_code == 200, adopted.text
    with session_scope() as s:
        betas = gather_inputs(s, sequence, with_depth=False).inputs.hand.betas
        imported = s.scalars(select(Hand).where(Hand.sequence_id == sequence)).one().betas
    assert imported[0] == pytest.approx(true_betas[0] + 1.5)
    fitted_off = np.abs(_rest_bones(list(betas)) - _rest_bones(true_betas)) * 1000.0
    assert np.median(fitted_off) < 0.5, fitted_off


def test_rig_health_refuses_bad_ids_and_non_admins(client: TestClient, admin_headers: dict,
                                                   sequence: int) -> None:
    assert client.get("/api/sequences/987654/rig-health",
                      headers=admin_headers).status_code == 404
    assert client.post("/api/sequences/987654/rig-health",
                       headers=admin_headers).status_code == 404
    missing = client.post(f"/api/sequences/{sequence}/calibrations/5/adopt",
                          headers=admin_headers)
    assert missing.status_code == 404 and "no calibration version 5" in missing.text
    assert client.post(f"/api/sequences/{sequence}/calibrations/-1/adopt",
                       headers=admin_headers).status_code == 422
    assert client.get(f"/api/sequences/{sequence}/rig-health").status_code == 401


def test_cli_rig_health_says_why_it_cannot_estimate(sequence: int) -> None:
    result = CliRunner().invoke(cli_app, ["rig", "health", str(sequence)])
    assert result.exit_code == 2
    assert "accepted hand labels in fewer than 3 views" in result.output
    result = CliRunner().invoke(cli_app, ["rig", "adopt", str(sequence), "3"])
    assert result.exit_code == 2 and "no calibration version 3" in result.output
