"""Two units of work recording the same marketplace submission at once (a confirm job beside a
`crowd sync`): one records it, the other finds it recorded, neither fails."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest
from sqlalchemy import func, select

from backend.annotation.service import create_assignment, create_tasks
from backend.captures.flows import import_path
from backend.crowd.models import CrowdSubmission
from backend.crowd.provider import SubmissionRecord
from backend.crowd.sync import accept_record
from backend.db import get_sessionmaker, session_scope
from backend.storage import get_storage


def test_a_submission_recorded_by_two_at_once_is_recorded_once(
    app_env: dict, small_capture: Path, database_url: str
) -> None:
    if not database_url.startswith("postgresql"):
        pytest.skip("SQLite lets one writer in at a time: the two cannot overlap there")
    seq_id = import_path(small_capture)[0].sequence_id
    with session_scope() as s:
        task = create_tasks(s, get_storage(), seq_id)[0]
        ours = create_assignment(s, task, "W-RACE", external_id="A-RACE", hit_id="H-RACE")
        assignment_id = ours.id
    record = SubmissionRecord(assignment_id="A-RACE", unit_id="H-RACE", worker_id="W-RACE",
                              status="submitted")
    first = get_sessionmaker()()
    try:
        assert accept_record(first, record)[0] == "accepted"  # inserted, not committed yet
        outcome: list[object] = []

        def second() -> None:
            try:
                with session_scope() as s:
                    outcome.append(accept_record(s, replace(record, status="approved"))[0])
            except Exception as exc:  # the failure this test is about
                outcome.append(exc)

        thread = threading.Thread(target=second)
        thread.start()
        time.sleep(0.5)  # the second waits on the first's uncommitted row
        first.commit()
        thread.join(timeout=30)
    finally:
        first.close()
    assert outcome == ["already_accepted"]
    with session_scope() as s:
        rows = s.scalar(select(func.count()).select_from(CrowdSubmission).where(
            CrowdSubmission.assignment_id == assignment_id))
        status = s.scalar(select(CrowdSubmission.market_status).where(
            CrowdSubmission.assignment_id == assignment_id))
    assert (rows, status) == (1, "Approved")
