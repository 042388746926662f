"""The stage pipeline under concurrency: work submitted while its target's QC job runs is
scored by the next run, so once the queue is idle every submitted assignment has a report
(SQLite and PostgreSQL)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import crowd_submits, publish_hand_tasks
from tests.conftest import _drop_all


@pytest.fixture(params=["sqlite", "postgres"])
def market_database_url(request: pytest.FixtureRequest, tmp_path: Path,
                        migrated_sqlite: Path) -> Iterator[str]:
    """The app's database of each kind (the marketplace tests' default is SQLite only)."""
    if request.param == "sqlite":
        yield request.getfixturevalue("market_database_url_sqlite")
        return
    url = request.getfixturevalue("postgres_server_url")
    _drop_all(url)
    yield url
    _drop_all(url)


@pytest.fixture
def market_database_url_sqlite(tmp_path: Path, migrated_sqlite: Path) -> str:
    import shutil

    target = tmp_path / "market.db"
    shutil.copyfile(migrated_sqlite, target)
    return f"sqlite:///{target}"


def _job(key: str):
    from backend.jobs.models import Job

    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        session.expunge(job)
        return job


def _confirm(outcomes: list) -> None:
    """Run the confirm job the page's submit queued for each outcome's assignment."""
    from backend.annotation.models import Assignment
    from backend.jobs.runner import execute
    from backend.pipeline import confirm_key

    with session_scope() as session:
        ids = [session.scalar(select(Assignment.id).where(
            Assignment.external_id == o.assignment_id)) for o in outcomes]
    for assignment_id in ids:
        execute(confirm_key(assignment_id))


def _drain() -> list[str]:
    """Run queued jobs here until none is left (what an idle queue means); the keys run."""
    from backend.jobs.consumer import run_queued

    return run_queued(max_rounds=50)


def test_work_submitted_during_its_qc_run_is_scored_by_the_next_run(
        crowd_url: str, qc_capture: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.annotation.models import Assignment
    from backend.jobs.runner import execute
    from backend.quality import flows
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    sequence_id, _ = publish_hand_tasks(qc_capture, max_assignments=1)
    first = crowd_submits(crowd_url, qc_capture, ["careful"] * 3)
    _confirm(first)
    key = qc_key(sequence_id, "hand:0")
    assert _job(key).status == "queued"

    # The QC job stops at its first checkpoint (after its first action) until released.
    reached, release = threading.Event(), threading.Event()

    def hold() -> None:
        reached.set()
        assert release.wait(120)

    monkeypatch.setattr(flows, "checkpoint", hold)
    runner = threading.Thread(target=execute, args=(key,), daemon=True)
    runner.start()
    try:
        assert reached.wait(120), "the QC job never reached its first action"
        with session_scope() as session:  # this run scored the first three only
            assert len(list(session.scalars(select(QCReport.id)))) == 3
        late = crowd_submits(crowd_url, qc_capture, ["careful"] * 3, seed=1, first_worker=4)
        assert [o.status for o in late] == ["submitted"] * 3
        _confirm(late)  # each asks for the target's QC while its job runs
        assert _job(key).status == "running"
    finally:
        release.set()
        runner.join(120)
    monkeypatch.setattr(flows, "checkpoint", lambda: None)
    job = _job(key)
    assert (job.status, job.attempts) == ("queued", 0), "the run asked for again was dropped"
    assert job.requests > job.requests_claimed

    assert key in _drain()
    with session_scope() as session:
        submitted = set(session.scalars(select(Assignment.id).where(
            Assignment.status != "working")))
        reported = set(session.scalars(select(QCReport.assignment_id)))
    assert len(submitted) == 6
    assert submitted == reported
    assert _job(key).status == "done"
