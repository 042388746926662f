"""Query plans of the admin listings and the heavy reads on a DexYCB-shaped database.

bench/scale_db.py fills PostgreSQL with sequences of 8 views, a hand and 4 objects and all the
work on them (tasks, HITs, assignments with tracks, QC reports, payments, jobs, solve runs);
here with 100 sequences (4,000 tasks, ~58,000 frames), enough rows, once ANALYZEd, that the
planner scans a big table whole only where nothing better exists. Each listing and read runs
as the product runs it; every SQL statement it sends is recorded and EXPLAINed with its own
parameters, and no plan may read a big table (tasks, assignments, tracks, qc_reports,
crowd_hits, crowd_submissions, jobs, frames) with a sequential scan. The statement counts keep
the reads free of one-query-per-row loops.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from sqlalchemy import Engine, event, select

from backend.progress.schemas import SequenceProgress
from tests.conftest import _drop_all, reset_caches

pytestmark = pytest.mark.postgres

SEQUENCES = 100
BIG_TABLES = {"tasks", "assignments", "tracks", "qc_reports", "crowd_hits", "jobs", "frames",
              "crowd_submissions"}
BENCH = Path(__file__).resolve().parents[3] / "bench" / "scale_db.py"


def _bench() -> ModuleType:
    if "scale_db" in sys.modules:
        return sys.modules["scale_db"]
    spec = importlib.util.spec_from_file_location("scale_db", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["scale_db"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def filled(postgres_server_url: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The session's PostgreSQL database, migrated and filled by bench/scale_db.py's fill."""
    from backend.migrate import upgrade

    url = postgres_server_url
    _drop_all(url)
    upgrade(url)
    _bench().fill(url, SEQUENCES)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DEXLABEL_DATABASE_URL", url)
        mp.setenv("DEXLABEL_VAR_DIR", str(tmp_path_factory.mktemp("plans-var")))
        mp.setenv("DEXLABEL_ENV", "test")
        reset_caches()
        yield url
        reset_caches()
    _drop_all(url)


@pytest.fixture(scope="module")
def sequence_id(filled: str) -> int:
    """A finished sequence in the middle (its latest solve run is done)."""
    from backend.db import session_scope
    from backend.solve.models import SolveRun

    with session_scope() as session:
        found = session.scalar(select(SolveRun.sequence_id).where(
            SolveRun.status == "done", SolveRun.sequence_id >= SEQUENCES // 2)
            .order_by(SolveRun.sequence_id).limit(1))
    assert found is not None
    return int(found)


@contextmanager
def _recorded(engine: Engine) -> Iterator[list[tuple[str, Any]]]:
    statements: list[tuple[str, Any]] = []

    def before(_conn: Any, _cursor: Any, statement: str, parameters: Any, _context: Any,
               _executemany: bool) -> None:
        statements.append((statement, parameters))

    event.listen(engine, "before_cursor_execute", before)
    try:
        yield statements
    finally:
        event.remove(engine, "before_cursor_execute", before)


def _scans(plan: dict[str, Any]) -> Iterator[tuple[str, str]]:
    """(node type, relation) of every node of a JSON plan that reads a table."""
    if "Relation Name" in plan:
        yield plan["Node Type"], plan["Relation Name"]
    for child in plan.get("Plans", []):
        yield from _scans(child)


def _plans(fn: Callable[[Any], object]) -> list[tuple[str, list[tuple[str, str]]]]:
    """Run ``fn(session)``; each SELECT it sent, with the tables its plan reads and how."""
    from backend.db import get_engine, session_scope

    engine = get_engine()
    with _recorded(engine) as statements, session_scope() as session:
        fn(session)
    out = []
    raw = engine.raw_connection()
    try:
        cursor = raw.cursor()
        for statement, parameters in statements:
            if not statement.lstrip().upper().startswith("SELECT"):
                continue
            cursor.execute(f"EXPLAIN (FORMAT JSON) {statement}", parameters)
            plan = cursor.fetchone()[0]
            plan = json.loads(plan) if isinstance(plan, str) else plan
            out.append((statement, list(_scans(plan[0]["Plan"]))))
    finally:
        raw.close()
    return out


def _no_seq_scans(fn: Callable[[Any], object]) -> int:
    """Assert no plan of ``fn`` scans a big table sequentially; returns the number of SELECT
    statements it sent."""
    plans = _plans(fn)
    bad = [(table, statement.split("FROM", 1)[-1][:160])
           for statement, scans in plans for node, table in scans
           if node == "Seq Scan" and table in BIG_TABLES]
    assert not bad, f"sequential scans: {bad}"
    return len(plans)


Get = Callable[[str], Callable[[Any], Any]]


@pytest.fixture(scope="module")
def api(filled: str) -> Get:
    """``api(path)``: a GET of the admin API through the app, as a function of a (unused)
    session that returns the JSON answer."""
    from fastapi.testclient import TestClient

    from backend.accounts.service import create_admin
    from backend.app import create_app
    from backend.db import session_scope

    email, password = "plans@dexlabel.local", "plans-password-1"
    with session_scope() as session:
        create_admin(session, email, password)
    client = TestClient(create_app())
    token = client.post("/api/auth/token", json={"email": email, "password": password})
    assert token.status_code == 200, token.text
    headers = {"Authorization": f"Bearer {token.json()['access_token']}"}

    def get(path: str) -> Callable[[Any], Any]:
        def call(_session: Any) -> Any:
            resp = client.get(path, headers=headers)
            assert resp.status_code == 200, resp.text
            return resp.json()
        return call
    return get


def test_the_fill_is_dexycb_shaped(filled: str, sequence_id: int) -> None:
    """8 views x (1 hand + 4 objects) tasks per sequence, ~72 frames per view, every task of
    a finished sequence accepted and its solve run made from the accepted labels as they
    are now (the progress page calls it solved)."""
    from sqlalchemy import func

    from backend.annotation.models import Task
    from backend.captures.models import Frame
    from backend.db import session_scope
    from backend.progress.service import sequence_progress

    with session_scope() as session:
        assert session.scalar(select(func.count()).select_from(Task)) == SEQUENCES * 40
        frames = session.scalar(select(func.count()).select_from(Frame)) or 0
        assert 64 * 8 * SEQUENCES <= frames <= 81 * 8 * SEQUENCES
        progress = sequence_progress(session, sequence_id)
    assert progress.state == "solved"
    assert len(progress.tasks) == 40 and progress.counts["accepted"] == 40
    assert progress.solve is not None and progress.solve.labels == "current"


def _serial(sequence_id: int) -> str:
    from backend.captures.models import Camera
    from backend.db import session_scope

    with session_scope() as session:
        return str(session.scalar(select(Camera.serial).where(
            Camera.sequence_id == sequence_id).order_by(Camera.view_index).limit(1)))


def test_listings_use_indexes(api: Get, sequence_id: int) -> None:
    """The admin listings of one sequence or one page: indexes only, a bounded number of
    statements (the progress grid: the sequence with its cameras, objects, hands and subject,
    its tasks, their assignments, reviews, HITs and views, the solve run and the digest; the
    task listing: the tasks, their sequences with the cameras, objects and hands that name a
    task's view and target, and their states)."""
    seq = sequence_id
    for path, most in ((f"/api/sequences/{seq}/progress", 16),
                       (f"/api/qc/reports?sequence_id={seq}", 3),
                       ("/api/jobs", 3), ("/api/jobs?status=failed", 3),
                       ("/api/jobs?kind=solve", 3), (f"/api/tasks?sequence_id={seq}", 11),
                       ("/api/sequences", 8),
                       (f"/api/sequences/{seq}/views/{_serial(seq)}/frames", 4)):
        statements = _no_seq_scans(api(path))
        assert statements <= most, (path, statements)


def test_progress_of_every_sequence_takes_the_same_few_statements(filled: str) -> None:
    """`dexlabel status` without a sequence: every sequence's progress in a few grouped
    statements, whatever their number, equal to each sequence's own progress. (A page of
    many sequences reads a large share of these small tables: the planner may scan them.)"""
    from backend.db import session_scope
    from backend.progress.service import sequence_progress, sequences_progress

    ids = list(range(1, SEQUENCES + 1))
    found: list[Any] = []
    plans = _plans(lambda session: found.extend(sequences_progress(session, ids)))
    assert len(plans) <= 12, len(plans)
    assert [p.sequence_id for p in found] == ids
    assert {p.state for p in found} >= {"solved"}
    with session_scope() as session:
        for p in (found[0], found[SEQUENCES // 2], found[-1]):
            assert sequence_progress(session, p.sequence_id) == p


def test_status_lists_every_sequence_page_by_page(filled: str,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    from backend.cli import app
    from backend.cli import status as progress_cli

    monkeypatch.setattr(progress_cli, "STATUS_PAGE", 30)  # 100 sequences: 4 pages
    runner = CliRunner()
    lines = runner.invoke(app, ["status"]).output.splitlines()
    assert [int(line.split()[0]) for line in lines] == list(range(1, SEQUENCES + 1))
    listed = json.loads(runner.invoke(app, ["status", "--json"]).output)
    assert [p["sequence_id"] for p in listed] == list(range(1, SEQUENCES + 1))
    assert all(progress_cli.summary_line(SequenceProgress.model_validate(p)) == line
               for p, line in zip(listed, lines, strict=True))


def test_task_and_sequence_listings_are_paged(api: Get) -> None:
    """Every task of the project in pages of a few statements each, whatever the page size."""
    page = api("/api/tasks?limit=20&offset=200")
    assert [t["id"] for t in page(None)] == list(range(201, 221))
    assert _no_seq_scans(page) <= 11
    assert len(api("/api/tasks")(None)) == 500
    assert len(api("/api/sequences")(None)) == min(SEQUENCES, 50)
    assert [s["id"] for s in api("/api/sequences?limit=5&offset=10")(None)] == [
        11, 12, 13, 14, 15]


def test_accepted_labels_reads_use_indexes(filled: str, sequence_id: int) -> None:
    """The accepted-labels reads of the pipeline, the QC job and the solve."""
    from backend.annotation.models import Assignment, Task
    from backend.captures.models import Sequence
    from backend.labels import accepted_digest, approved_labels, count_accepted
    from backend.quality.inputs import target_inputs

    seq = sequence_id

    def frames(session: Any) -> int:
        return int(session.get_one(Sequence, seq).num_frames)

    assert _no_seq_scans(lambda s: accepted_digest(s, seq)) == 2
    # The sequence, its cameras, the calibration version in use, the target's tasks, their
    # assignments and all their tracks.
    assert _no_seq_scans(lambda s: target_inputs(s, seq, "hand:0")) <= 6
    assert _no_seq_scans(lambda s: target_inputs(s, seq, "object:2")) <= 6
    assert _no_seq_scans(lambda s: approved_labels(s, seq, frames(s))) <= 4
    assert _no_seq_scans(lambda s: count_accepted(s, seq)) == 2

    # A view's depth maps as the QC job's visibility check finds them.
    from backend.captures.service import sequence_cameras
    from backend.quality.inputs import depth_maps

    assert _no_seq_scans(lambda s: depth_maps(s, sequence_cameras(s, seq), {0, 3})) == 3

    # Lookups by id: a task's work, an assignment's tracks.
    def by_id(session: Any) -> None:
        task_id = session.scalar(select(Task.id).where(Task.sequence_id == seq).limit(1))
        work = session.scalars(select(Assignment).where(Assignment.task_id == task_id)).all()
        assert work and all(a.tracks for a in work)
    _no_seq_scans(by_id)


def test_qc_population_reads_the_newest_reports_by_index(
    filled: str, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The thresholds' population is the newest reports of the kind, read backwards by id
    (bounded here below the table's size, as it is in a big project)."""
    from backend.quality import service

    monkeypatch.setattr(service, "POPULATION_LIMIT", 100)
    rows: list[list[dict]] = []
    _no_seq_scans(lambda s: rows.append(service._population(s, "hand", {})))
    assert len(rows[0]) == 100
    _no_seq_scans(lambda s: service._population(s, "object", {}))


def test_worker_quality_reads_an_index_alone(filled: str) -> None:
    from backend.quality.service import worker_quality

    plans = _plans(worker_quality)
    tally = [scans for statement, scans in plans if "qc_reports" in statement]
    assert tally == [[("Index Only Scan", "qc_reports")]]


def _costs_row_by_row(session: Any) -> tuple[dict[str, list[int]], dict[str, list[int]]]:
    """Spent and committed cents per sequence and per worker, from every ledger row, HIT and
    submission one by one: (by sequence, by worker), each [spent, committed]."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd import pricing
    from backend.crowd.models import CrowdHit, CrowdPayment, CrowdSubmission

    by_sequence: dict[str, list[int]] = {}
    by_worker: dict[str, list[int]] = {}

    def add(totals: dict[str, list[int]], key: object, spent: int = 0, held: int = 0) -> None:
        entry = totals.setdefault(str(key), [0, 0])
        entry[0] += spent
        entry[1] += held

    decided_ids: set[int] = set()
    decided_per_hit: dict[str, int] = {}
    for pay, seq, hit_id in session.execute(
            select(CrowdPayment, Task.sequence_id, Assignment.hit_id)
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id)):
        money = pay.amount_cents + pay.fee_cents
        spent = money if pay.kind == "approval" or (
            pay.kind == "bonus" and pay.state == "done") else 0
        held = money if pay.kind == "bonus" and pay.state == "pending" else 0
        add(by_sequence, seq, spent, held)
        add(by_worker, pay.worker_id, spent, held)
        if pay.kind in ("approval", "rejection"):
            decided_ids.add(pay.assignment_id)
            decided_per_hit[hit_id] = decided_per_hit.get(hit_id, 0) + 1
    waiting: dict[str, list[str]] = {}
    for sub in session.scalars(select(CrowdSubmission)):
        if sub.assignment_id not in decided_ids:
            waiting.setdefault(sub.hit_id, []).append(sub.worker_id)
    for hit, seq in session.execute(select(CrowdHit, Task.sequence_id)
                                    .join(Task, Task.id == CrowdHit.task_id)
                                    .where(CrowdHit.hit_id.is_not(None))):
        each = hit.reward_cents + pricing.fee_cents(hit.reward_cents, hit.max_assignments)
        workers = waiting.get(hit.hit_id, [])
        for worker in workers:
            add(by_worker, worker, held=each)
        slots = len(workers) if hit.expired_at is not None else max(
            hit.max_assignments - decided_per_hit.get(hit.hit_id, 0), 0)
        add(by_sequence, seq, held=slots * each)
    return by_sequence, by_worker


def test_costs_summed_by_the_database_match_a_row_by_row_count(filled: str) -> None:
    """The grouped sums give every sequence's and worker's spent and committed money as
    adding up the ledger, the HITs and the submissions one row at a time does."""
    from backend.crowd import costs, pricing
    from backend.db import session_scope

    def cents(money: str) -> int:
        return pricing.dollars_to_cents(money)

    with session_scope() as session:
        report = costs.costs(session)
        by_sequence, by_worker = _costs_row_by_row(session)
    assert {line.key: [cents(line.spent), cents(line.committed)]
            for line in report.by_sequence} == by_sequence
    assert {line.key: [cents(line.spent), cents(line.committed)]
            for line in report.by_worker} == by_worker
    assert len(report.by_sequence) == SEQUENCES
    assert cents(report.total.committed) > 0 and cents(report.total.spent) > 0


def test_a_whole_project_export_is_checked_in_a_few_statements(filled: str) -> None:
    """Which sequences an export covers: a few statements whatever the project's size (it
    was four per sequence), and the same answer as asking for each sequence on its own."""
    from backend.db import session_scope
    from backend.exports.service import NotExportable, check_request

    for fmt in ("json", "dexycb"):
        found: list[Any] = []
        plans = _plans(lambda s, fmt=fmt, found=found: found.append(
            check_request(s, fmt, None, "accepted", {})))
        assert len(plans) <= 4, (fmt, len(plans))
        covered, skipped = found[0]
        assert covered and len(covered) + len(skipped) == SEQUENCES
        with session_scope() as session:
            for seq in (covered[0], covered[-1]):
                assert check_request(session, fmt, [seq], "accepted", {}).ids == [seq]
            for reason in skipped[:3]:
                seq = int(reason.split()[1])
                with pytest.raises(NotExportable, match=re.escape(reason)):
                    check_request(session, fmt, [seq], "accepted", {})


def test_crowd_worker_medians_taken_by_the_database_match_the_rows(filled: str) -> None:
    """The worker listing's medians, which PostgreSQL takes, equal the median of each worker's
    rows, and its workers are every id the reports, submissions, payments and blocks name."""
    import statistics
    from collections import defaultdict

    from backend.annotation.models import Assignment
    from backend.crowd.models import CrowdPayment, CrowdSubmission, CrowdWorkerAction
    from backend.db import session_scope
    from backend.quality import worker_records as workers
    from backend.quality.models import QCReport

    with session_scope() as session:
        listed = workers.list_workers(session, 1000, 0)
        ids = {w.worker_id for w in listed}
        named = (set(session.scalars(select(QCReport.worker_id)
                                     .where(QCReport.provisional.is_(False))))
                 | set(session.scalars(select(CrowdSubmission.worker_id)))
                 | set(session.scalars(select(CrowdPayment.worker_id)))
                 | set(session.scalars(select(CrowdWorkerAction.worker_id)
                                       .where(CrowdWorkerAction.kind == "block"))))
        assert ids == named and [w.worker_id for w in listed] == sorted(ids)
        errors: dict[str, list[float]] = defaultdict(list)
        for wid, metrics in session.execute(select(QCReport.worker_id, QCReport.metrics)):
            if metrics.get("median_error_px") is not None:
                errors[wid].append(float(metrics["median_error_px"]))
        times: dict[str, list[float]] = defaultdict(list)
        for wid, seconds in session.execute(
                select(Assignment.worker_id, Assignment.working_time_s)
                .where(Assignment.submitted_at.is_not(None))):
            times[wid].append(float(seconds))
    checked = 0
    for w in listed:
        want_error = round(statistics.median(errors[w.worker_id]), 3) \
            if errors[w.worker_id] else None
        want_time = round(statistics.median(times[w.worker_id]), 3) \
            if times[w.worker_id] else None
        assert w.median_error_px == pytest.approx(want_error, abs=1.01e-3), w.worker_id
        assert w.median_working_time_s == pytest.approx(want_time, abs=1.01e-3), w.worker_id
        checked += want_error is not None
    assert checked > 10
