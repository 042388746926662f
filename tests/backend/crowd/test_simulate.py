"""The simulated crowd against the served app: accounts, accept, autosave, submit, externalSubmit;
the requester then sees the assignments through boto3's real mturk client."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import select
from typer.testing import CliRunner

from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS, get_settings
from backend.crowd.client import make_client
from backend.crowd.publish import publish_task
from backend.crowd.schemas import PublishOptions
from backend.crowd.simulate import simulate
from backend.db import session_scope
from tests.backend.crowd.helpers import ADMIN_EMAIL, ADMIN_PASSWORD
from tests.backend.market.helpers import make_client as boto3_client


def _publish_tasks(capture: Path, kinds: tuple[str, ...] = ("hand",)) -> list[str]:
    """Import the capture, create its tasks, publish one HIT per task of ``kinds``; HIT ids."""
    from backend.accounts.service import create_admin
    from backend.annotation.models import Task
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.storage import get_storage

    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        task_ids = [t.id for t in create_tasks(session, get_storage(), sequence_id)
                    if t.kind in kinds]
    client, hit_ids = make_client(get_settings()), []
    for task_id in task_ids:
        with session_scope() as session, session.no_autoflush:
            task = session.get_one(Task, task_id)
            hit_ids.append(publish_task(session, client, task,
                                        PublishOptions(min_approval_rate=None), [])[0])
    return hit_ids


def test_simulated_workers_submit_through_the_portal(crowd_url: str, small_capture: Path) -> None:
    from backend.annotation.models import Assignment

    hit_ids = _publish_tasks(small_capture)
    assert len(hit_ids) == 3
    outcomes = simulate(crowd_url, small_capture, 3, "careful", ADMIN_EMAIL, ADMIN_PASSWORD)
    assert [o.status for o in outcomes] == ["submitted"] * 3
    assert sorted(o.hit_id for o in outcomes) == sorted(hit_ids)

    requester = boto3_client(crowd_url, (DEV_MARKET_ACCESS_KEY,
                                         DEV_MARKET_REQUESTERS.split(":")[1]))
    for outcome in outcomes:
        found = requester.list_assignments_for_hit(HITId=outcome.hit_id)["Assignments"]
        assert [(a["AssignmentId"], a["WorkerId"], a["AssignmentStatus"]) for a in found] == [
            (outcome.assignment_id, outcome.worker_id, "Submitted")]

    with session_scope() as session:
        for outcome in outcomes:
            ours = session.scalar(select(Assignment).where(
                Assignment.external_id == outcome.assignment_id))
            assert ours is not None and ours.status == "submitted"
            assert ours.worker_id == outcome.worker_id
            assert sorted(t.point_index for t in ours.tracks) == list(range(21))
            first = min(ours.tracks, key=lambda t: t.point_index).keyframes
            assert (first[0][0], first[-1][0]) == (0, 5)  # the clip's 6 frames

    again = simulate(crowd_url, small_capture, 1, "careful", ADMIN_EMAIL, ADMIN_PASSWORD)
    assert again[0].status == "no HIT available"
    assert again[0].worker_id == outcomes[0].worker_id  # the account is reused


def test_cli_simulate_labels_hand_and_object_tasks(crowd_url: str, small_capture: Path) -> None:
    """9 tasks (3 views x (hand + 2 objects), one object hidden in a view): all submitted."""
    from backend.cli import app

    assert len(_publish_tasks(small_capture, ("hand", "object"))) == 9
    result = CliRunner().invoke(app, [
        "crowd", "simulate", "--workers", "9", "--profile", "mixed", "--capture",
        str(small_capture), "--admin-email", ADMIN_EMAIL, "--admin-password", ADMIN_PASSWORD])
    assert result.exit_code == 0, result.output
    assert "9 of 9 simulated workers submitted" in result.output
    bad = CliRunner().invoke(app, ["crowd", "simulate", "--capture", str(small_capture),
                                   "--profile", "perfect", "--admin-email", ADMIN_EMAIL,
                                   "--admin-password", ADMIN_PASSWORD])
    assert bad.exit_code == 2 and "unknown profile" in bad.output


def test_simulated_workers_leave_hits_that_do_not_open_the_annotation_page(
    crowd_url: str, small_capture: Path
) -> None:
    """A HIT someone published by hand (no task token in its URL) is neither accepted nor broken."""
    requester = boto3_client(crowd_url, (DEV_MARKET_ACCESS_KEY,
                                         DEV_MARKET_REQUESTERS.split(":")[1]))
    question = (
        '<ExternalQuestion xmlns="http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/'
        f'2006-07-14/ExternalQuestion.xsd"><ExternalURL>{crowd_url}/annotate/</ExternalURL>'
        "<FrameHeight>800</FrameHeight></ExternalQuestion>")
    foreign = requester.create_hit(
        Title="A survey", Description="not ours", Reward="0.10", LifetimeInSeconds=3600,
        AssignmentDurationInSeconds=600, Question=question, MaxAssignments=1)["HIT"]["HITId"]
    hit_ids = _publish_tasks(small_capture)
    outcomes = simulate(crowd_url, small_capture, 3, "careful", ADMIN_EMAIL, ADMIN_PASSWORD)
    assert [o.status for o in outcomes] == ["submitted"] * 3
    assert sorted(o.hit_id for o in outcomes) == sorted(hit_ids)
    assert requester.list_assignments_for_hit(HITId=foreign)["Assignments"] == []
