"""The cost of a labelled 3D frame: per target, the human actions, working seconds and the
ledger's spend, over the frames the current solve labelled and did not flag; the money adds up
to the ledger's rows and to the cost report, in the API and in `dexlabel status`."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from backend.crowd import costs, decisions, flows
from backend.crowd.schemas import PublishOptions
from backend.db import session_scope
from tests.backend.crowd.helpers import make_tasks, synced_submission
from tests.backend.market.helpers import WORKER, WORKER_2

FRAMES = 6  # make_tasks' sequences have 6 frames
# (edit actions, working seconds) the annotation page recorded on each assignment.
WORK = {WORKER: (40, 120.5), WORKER_2: (25, 70.0)}


def _add_object_task(sequence_id: int) -> None:
    """Object 0 in the sequence and its task in the first view (no work on it)."""
    from backend.annotation.models import Task
    from backend.captures.models import Camera, SceneObject

    with session_scope() as session:
        session.add(SceneObject(sequence_id=sequence_id, index=0, ycb_id=3, name="003_cracker_box",
                                mesh_key="meshes/none.obj", num_vertices=8, num_faces=12))
        camera = session.scalars(select(Camera).where(Camera.sequence_id == sequence_id)).first()
        assert camera is not None
        session.add(Task(sequence_id=sequence_id, camera_id=camera.id, kind="object",
                         target_key="object:0", num_points=2))


def _store_solve(sequence_id: int) -> None:
    """A solve result: hand joints on frames 0-4 (frame 5 unsolved), frame 3 flagged; the
    object's pose trusted on frames 0-3, flagged on 4 and 5."""
    from backend.solve.service import store_result
    from worker.solver.types import SolveResult

    joints = np.zeros((FRAMES, 21, 3))
    joints[5] = np.nan
    hand_flags: list[str | None] = [None] * FRAMES
    hand_flags[3] = "fingertips disagree with the depth"
    with session_scope() as session:
        store_result(session, sequence_id, SolveResult(
            hand_pose_m=np.zeros((FRAMES, 51)), hand_joints=joints,
            object_poses=np.tile(np.eye(4)[:3], (1, FRAMES, 1, 1)),
            labelled=np.isfinite(joints).all(axis=(1, 2)), reasons=[None] * FRAMES,
            kpt_error_px=np.full((FRAMES, 3, 21), np.nan), depth_rms_mm=np.full(FRAMES, np.nan),
            landmark_vertices=[[]], timings={}, object_confidence=np.ones((1, FRAMES)),
            object_flags=[[None, None, None, None, "one view only", "one view only"]],
            hand_confidence=np.ones(FRAMES), hand_flags=hand_flags), "right")


@pytest.fixture
def paid(crowd_url: str, mturk: Any) -> int:
    """A sequence of 3 hand views and an object: WORKER approved with a $1.00 bonus paid and a
    $0.50 bonus pending, WORKER_2 rejected, the third view open; a solve result stored.
    Reward $0.50 + $0.10 fee. Returns the sequence id."""
    from backend.annotation.models import Assignment, Task

    tasks = make_tasks(3, "grasp")
    hits = flows.publish_each(mturk, PublishOptions(min_approval_rate=None), None).hit_ids
    approved = synced_submission(crowd_url, hits[0], WORKER)
    rejected = synced_submission(crowd_url, hits[1], WORKER_2)
    with session_scope() as session:
        for assignment_id, worker in ((approved, WORKER), (rejected, WORKER_2)):
            row = session.get_one(Assignment, assignment_id)
            row.edit_count, row.working_time_s = WORK[worker]
        sequence_id = int(session.scalar(select(Task.sequence_id).where(Task.id == tasks[0])))
    with session_scope() as session:
        decisions.approve(session, mturk, approved)
    with session_scope() as session:
        decisions.reject(session, mturk, rejected, "The joints were placed on the other hand.")
    flows.pay_bonus(mturk, approved, 100, "Careful work on occluded frames")
    with session_scope() as session:  # started, not paid yet: not spent
        decisions.begin_bonus(session, approved, 50, "Extra frames", key="extra")
    _add_object_task(sequence_id)
    _store_solve(sequence_id)
    return sequence_id


def _ledger_spent_cents(sequence_id: int) -> int:
    """The sequence's spend summed here straight from the ledger's rows."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd.models import CrowdPayment

    with session_scope() as session:
        rows = session.execute(
            select(CrowdPayment.kind, CrowdPayment.state, CrowdPayment.amount_cents,
                   CrowdPayment.fee_cents)
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id).where(Task.sequence_id == sequence_id))
        return sum(amount + fee for kind, state, amount, fee in rows
                   if kind == "approval" or (kind == "bonus" and state == "done"))


def test_cost_per_labelled_frame_divides_work_and_ledger_spend_by_trusted_frames(
        paid: int) -> None:
    from backend.annotation.models import Assignment
    from backend.progress.frame_costs import frame_costs

    with session_scope() as session:
        found = frame_costs(session, [paid])[0]
        work_rows = session.scalar(select(func.count()).select_from(Assignment))
        report = costs.costs(session)
    hand, obj = found.targets
    assert (hand.target_key, obj.target_key) == ("hand:0", "object:0")
    # Hand: frames 0, 1, 2, 4 (5 unsolved, 3 flagged); every assignment's work counts.
    assert (hand.views, hand.assignments, hand.frames, hand.frames_labelled) == (3, work_rows, 6, 4)
    assert (hand.actions, hand.seconds) == (65, 190.5)
    # $0.50 reward + $0.10 fee + $1.00 bonus + $0.20 fee; the rejection and the pending bonus
    # cost nothing yet.
    assert hand.money_cents == _ledger_spent_cents(paid) == 180
    assert (hand.money, hand.currency) == ("1.80", "USD")
    assert (hand.actions_per_frame, hand.seconds_per_frame, hand.money_per_frame) == (
        16.25, 47.62, "0.4500")
    # Object 0: frames 0-3 trusted; nothing done or paid on it yet.
    assert (obj.frames_labelled, obj.actions, obj.money_cents, obj.money_per_frame) == (
        4, 0, 0, "0.0000")
    # Total: frames where hand and object are both trusted (0, 1, 2); the ledger's spent line.
    assert found.total.frames_labelled == 3
    assert found.total.money_cents == 180
    line = next(c for c in report.by_sequence if c.key == str(paid))
    assert found.total.money == line.spent
    assert found.total.money_per_frame == "0.6000"


def test_frame_costs_api_and_status_command_show_the_same_figures(paid: int, api: Any) -> None:
    from backend.cli import app

    resp = api.get(f"/api/sequences/{paid}/frame-costs")
    assert resp.status_code == 200, resp.text
    body = resp.json()
    assert [(t["target_key"], t["frames_labelled"], t["money_per_frame"])
            for t in body["targets"]] == [("hand:0", 4, "0.4500"), ("object:0", 4, "0.0000")]
    listed = api.get("/api/frame-costs").json()
    assert [s["sequence_id"] for s in listed] == [paid] and listed[0] == body
    assert api.get("/api/sequences/999999/frame-costs").status_code == 404
    out = CliRunner().invoke(app, ["status", str(paid)])
    assert out.exit_code == 0, out.output
    rows = {line.split()[0]: line.split() for line in out.output.splitlines()
            if line.startswith(("hand:0 ", "object:0 ", "total "))}
    # target, 3D frames, actions, seconds, money, then per frame: actions, seconds, money
    assert rows["hand:0"][1:] == ["4", "65", "190.5", "1.80", "16.25", "47.62", "0.4500", "USD"]
    assert rows["total"][1:5] == ["3", "65", "190.5", "1.80"]
    # --json: the progress API's figures and the same cost lines, each target named.
    out = CliRunner().invoke(app, ["status", str(paid), "--json"])
    assert out.exit_code == 0, out.output
    printed = json.loads(out.output)
    assert printed["frame_costs"] == body
    assert [t["label"] for t in body["targets"]] == ["hand 0", "object 0 (003_cracker_box)"]
