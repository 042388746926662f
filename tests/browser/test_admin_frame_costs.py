"""The cost per labelled 3D frame on the admin's Costs page: a table per sequence, a row per
target and the total, whose numbers equal the crowd ledger's rows and the solve's trusted
frames, read here straight from the live server's database and storage.

The module seeds the live server's own sequence (a hand and an object in 2 views): approved,
rejected and unfinished work with their actions and working time, the ledger's approvals,
rejection and bonuses (one pending), and a solve result with flagged frames. Its rows are
removed when the module ends, so the other browser tests see the server as they left it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from playwright.sync_api import Page, expect
from sqlalchemy import select

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.test_admin import admin_page  # noqa: F401  (fixture)
from tests.conftest import reset_caches

# worker, view, target, status, edit actions, working seconds, (reward, fee) cents if approved
WORK = [("FC-W1", 0, "hand:0", "approved", 180, 412.5, (40, 8)),
        ("FC-W2", 1, "hand:0", "approved", 95, 260.0, (40, 8)),
        ("FC-W3", 1, "hand:0", "rejected", 30, 45.0, None),
        ("FC-W4", 0, "object:0", "approved", 12, 38.5, (20, 4)),
        ("FC-W5", 1, "object:0", "working", 4, 9.0, None)]
BONUS = ("FC-W1", 25, 5)  # paid: worker, amount, fee (cents)
PENDING_BONUS = ("FC-W2", 50, 10)  # started, not paid: not spent


class _Env:
    """The live server's settings in this process, for the duration of a ``with``."""

    def __init__(self, server: LiveServer) -> None:
        self.server = server
        self.patch = pytest.MonkeyPatch()

    def __enter__(self) -> None:
        for key, value in self.server.env.items():
            self.patch.setenv(key, value)
        reset_caches()

    def __exit__(self, *_: object) -> None:
        self.patch.undo()
        reset_caches()


def _solve_result(frames: int) -> object:
    """A stored solve: hand joints everywhere but frame 0, frame 5 flagged; the object's pose
    flagged on the last 3 frames."""
    from worker.solver.types import SolveResult

    joints = np.zeros((frames, 21, 3))
    joints[0] = np.nan
    hand_flags: list[str | None] = [None] * frames
    hand_flags[5] = "the views disagree"
    flags: list[str | None] = [None] * (frames - 3) + ["one view only"] * 3
    return SolveResult(
        hand_pose_m=np.zeros((frames, 51)), hand_joints=joints,
        object_poses=np.tile(np.eye(4)[:3], (1, frames, 1, 1)),
        labelled=np.isfinite(joints).all(axis=(1, 2)), reasons=[None] * frames,
        kpt_error_px=np.full((frames, 2, 21), np.nan), depth_rms_mm=np.full(frames, np.nan),
        landmark_vertices=[[]], timings={}, object_confidence=np.ones((1, frames)),
        object_flags=[flags], hand_confidence=np.ones(frames), hand_flags=hand_flags)


@pytest.fixture(scope="module")
def seeded(live_server: LiveServer) -> Iterator[int]:
    """The seeded work, ledger and solve of the live server's sequence; the solve run's id."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd import totals
    from backend.crowd.models import CrowdPayment
    from backend.db import session_scope
    from backend.solve.models import SolveRun
    from backend.solve.service import store_result

    sequence_id = live_server.sequence_id
    with _Env(live_server), session_scope() as session:
        tasks = {(t.camera.view_index, t.target_key): t for t in session.scalars(
            select(Task).where(Task.sequence_id == sequence_id))}
        views = sorted({v for v, _ in tasks})
        made: dict[str, Assignment] = {}
        for worker, view, target, status, actions, seconds, paid in WORK:
            row = Assignment(task_id=tasks[(views[view], target)].id, worker_id=worker,
                             external_id=f"frame-costs-{worker}", status=status, version=1,
                             edit_count=actions, working_time_s=seconds)
            session.add(row)
            session.flush()
            made[worker] = row
            if status in ("approved", "rejected"):
                kind = "approval" if status == "approved" else "rejection"
                amount, fee = paid or (0, 0)
                _pay(session, totals, CrowdPayment(
                    kind=kind, assignment_id=row.id, worker_id=worker,
                    request_token=f"{kind}-fc-{row.id}", amount_cents=amount, fee_cents=fee))
        for (worker, amount, fee), state in ((BONUS, "done"), (PENDING_BONUS, "pending")):
            _pay(session, totals, CrowdPayment(
                kind="bonus", assignment_id=made[worker].id, worker_id=worker, state=state,
                request_token=f"bonus-fc-{worker}", amount_cents=amount, fee_cents=fee))
        run = store_result(session, sequence_id, _solve_result(CLIP_FRAMES), "right")
        run_id = run.id
    yield run_id
    with _Env(live_server), session_scope() as session:
        ids = [a.id for a in made.values()]
        for payment in session.scalars(select(CrowdPayment).where(
                CrowdPayment.assignment_id.in_(ids))):
            session.delete(payment)
        for assignment in session.scalars(select(Assignment).where(Assignment.id.in_(ids))):
            session.delete(assignment)
        session.delete(session.get_one(SolveRun, run_id))
        session.flush()
        totals.rebuild(session)


def _pay(session: object, totals: object, row: object) -> None:
    session.add(row)  # type: ignore[attr-defined]
    totals.record(session, row)  # type: ignore[attr-defined]


def _ledger(server: LiveServer) -> tuple[dict[str, int], dict[str, int], dict[str, float]]:
    """Per target of the sequence, summed here from the rows: spent cents (the ledger's
    approvals and paid bonuses with their fees), edit actions and working seconds (every
    assignment, this module's and any other's)."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd.models import CrowdPayment
    from backend.db import session_scope

    out: dict[str, int] = {}
    actions: dict[str, int] = {}
    seconds: dict[str, float] = {}
    with _Env(server), session_scope() as session:
        for target, edits, worked in session.execute(
                select(Task.target_key, Assignment.edit_count, Assignment.working_time_s)
                .join(Task, Task.id == Assignment.task_id)
                .where(Task.sequence_id == server.sequence_id)):
            actions[target] = actions.get(target, 0) + edits
            seconds[target] = seconds.get(target, 0.0) + worked
        for target, kind, state, amount, fee in session.execute(
                select(Task.target_key, CrowdPayment.kind, CrowdPayment.state,
                       CrowdPayment.amount_cents, CrowdPayment.fee_cents)
                .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
                .join(Task, Task.id == Assignment.task_id)
                .where(Task.sequence_id == server.sequence_id)):
            if kind == "approval" or (kind == "bonus" and state == "done"):
                out[target] = out.get(target, 0) + amount + fee
    return out, actions, seconds


def test_costs_page_draws_cost_per_labelled_frame_equal_to_the_ledger(
    admin_page: Page, live_server: LiveServer, seeded: int, output_dir: Path,  # noqa: F811
) -> None:
    page, server = admin_page, live_server
    ledger, actions, seconds = _ledger(server)
    # This module's work is in it (other modules may have added theirs).
    assert all(actions[t] >= sum(w[4] for w in WORK if w[2] == t) for t in actions)
    # Hand: every frame but 0 (unsolved) and 5 (flagged); object: all but the last 3.
    labelled = {"hand:0": CLIP_FRAMES - 2, "object:0": CLIP_FRAMES - 3}
    both = CLIP_FRAMES - 5  # frames 1-4 and 6-8

    page.locator("#nav-costs").click()
    table = page.locator(f'.frame-costs[data-sequence="{server.sequence_id}"]')
    expect(table.locator("caption")).to_contain_text(f"solve run {seeded}")
    for target in ("hand:0", "object:0"):
        cells = table.locator(f'tbody tr[data-target="{target}"] td')
        cents, frames = ledger[target], labelled[target]
        expect(cells.nth(0)).to_have_text(f"{frames} of {CLIP_FRAMES}")
        expect(cells.nth(1)).to_have_text(str(actions[target]))
        expect(cells.nth(2)).to_have_text(f"{seconds[target]:.1f} s")
        expect(cells.nth(3)).to_have_text(f"{cents / 100:.2f} USD")
        expect(cells.nth(4)).to_have_text(f"{actions[target] / frames:.2f}")
        expect(cells.nth(5)).to_have_text(f"{seconds[target] / frames:.2f}")
        expect(cells.nth(6)).to_have_text(f"{cents / frames / 100:.4f} USD")
    total = table.locator("tfoot tr td")
    spent = sum(ledger.values())
    expect(total.nth(0)).to_have_text(f"{both} of {CLIP_FRAMES}")
    expect(total.nth(1)).to_have_text(str(sum(actions.values())))
    expect(total.nth(3)).to_have_text(f"{spent / 100:.2f} USD")
    expect(total.nth(6)).to_have_text(f"{spent / both / 100:.4f} USD")
    # At least the seeded spend: 3 approvals' rewards and fees and the paid bonus, not the
    # pending one nor the rejection.
    assert spent >= 48 + 48 + 24 + 30
    # The sequence's line of the cost report (the ledger's running totals) says the same.
    costs = server.admin("GET", "/api/crowd/costs")
    assert isinstance(costs, dict)
    line = next(c for c in costs["by_sequence"] if c["key"] == str(server.sequence_id))
    assert line["spent"] == f"{spent / 100:.2f}"

    table.scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-frame-costs-1440.png"), full_page=True)
    page.set_viewport_size({"width": 1024, "height": 700})
    table.scroll_into_view_if_needed()
    box = table.locator("tfoot tr td").last.bounding_box()
    assert box is not None and box["x"] + box["width"] <= 1024, box
    page.screenshot(path=str(output_dir / "admin-frame-costs-1024.png"))
