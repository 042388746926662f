"""Running the crowd from the admin page, in a real browser: the publish form offers each
provider (the team with an assignee) and shows the cost in that provider's fees before
anything is published; the Team view makes an account and an invite link (its token in the
fragment) that a new member registers with; the Crowd view shows each unit's places, holders
and state as the API gives them, adds a place to one unit, expires another once confirmed
(and extends it open again), and closes work left "working"; in the review queue R asks
before it rejects, and R alone sends nothing. Screenshots of each view at 1440x900 and 1024x700.

The capture is its own (seed 23), imported into the live server; its units are expired and
its sequence deleted when the module ends, so the other browser tests see the server as
they left it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.sync_api import Page, Request, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import server_settings
from tests.browser.test_admin import admin_page  # noqa: F401  (fixture)

SEED = 23
NAME = f"synth_{SEED:06d}"
UNITS = 4  # a hand and an object in each of 2 views
SIZES = ((1440, 900), (1024, 700))
MEMBER = "crowd-member@example.org"
INVITED = "crowd-invited@example.org"
PASSWORD = "a team member's password"
FEEDBACK = "Several fingertips sit on the knuckles from frame 4 on: please check each joint."


def _shots(page: Page, output_dir: Path, name: str) -> None:
    """Screenshots ``admin-crowd-{name}-{w}x{h}.png`` at each size, then back to 1440x900."""
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(100)
        page.screenshot(path=str(output_dir / f"admin-crowd-{name}-{width}x{height}.png"),
                        full_page=True)
        over = page.evaluate("() => document.scrollingElement.scrollWidth - window.innerWidth")
        assert over <= 0, f"{name} at {width}x{height}: the page scrolls sideways by {over} px"
    page.set_viewport_size({"width": SIZES[0][0], "height": SIZES[0][1]})


@pytest.fixture(scope="module")
def crowd(live_server: LiveServer, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """The capture imported and its tasks made; filled in by the tests in order (the member's
    worker id). Its units are expired and the sequence deleted at the end."""
    from backend.captures.flows import import_path
    from worker.synth import generate_capture

    capture = tmp_path_factory.mktemp("crowd") / "capture"
    generate_capture(capture, seed=SEED, frames=CLIP_FRAMES, views=2, objects=1)
    with server_settings(live_server):
        sequence_id = import_path(capture)[0].sequence_id
    tasks = live_server.admin("POST", f"/api/sequences/{sequence_id}/tasks")
    assert isinstance(tasks, list) and len(tasks) == UNITS
    yield {"sequence_id": sequence_id, "tasks": tasks}
    headers = {"Authorization": f"Bearer {live_server.admin_token}"}
    for unit in _units(live_server, sequence_id):
        if unit["state"] == "open":
            httpx.post(f"{live_server.base}/api/crowd/hits/{unit['hit_id']}/expire",
                       headers=headers, timeout=30)
    httpx.delete(f"{live_server.base}/api/sequences/{sequence_id}?force=true", headers=headers,
                 timeout=60)


def _units(server: LiveServer, sequence_id: int) -> list[dict]:
    units = server.admin("GET", f"/api/crowd/units?sequence_id={sequence_id}")
    assert isinstance(units, list)
    return units


def _posts(page: Page, path: str) -> list[dict]:
    """The JSON bodies the page sends to ``path`` from now on."""
    sent: list[dict] = []

    def seen(request: Request) -> None:
        if request.method == "POST" and urlsplit(request.url).path == path:
            sent.append(request.post_data_json or {})
    page.on("request", seen)
    return sent


def test_team_view_makes_an_account_and_an_invite_a_member_registers_with(
    admin_page: Page, live_server: LiveServer, browser, crowd: dict,  # noqa: F811
    output_dir: Path,
) -> None:
    page = admin_page
    page.locator("#nav-team").click()
    expect(page.locator("#team-view")).to_be_visible()
    page.locator("#account-email").fill(MEMBER)
    page.locator("#account-password").fill(PASSWORD)
    page.locator("#account-create").click()
    expect(page.locator("#team-result")).to_contain_text(f"{MEMBER} can sign in")
    member = next(m for m in live_server.admin("GET", "/api/crowd/team?limit=1000")
                  if m["email"] == MEMBER)
    row = page.locator(f'#team-rows tr[data-worker="{member["worker_id"]}"]')
    expect(row.locator('[data-col="email"]')).to_have_text(MEMBER)
    expect(row.locator('[data-col="approved"]')).to_have_text("0")
    crowd["member"] = member["worker_id"]

    page.locator("#invite-create").click()
    link = page.locator("#invite-url")
    expect(link).to_have_value(re.compile(f"^{re.escape(live_server.base)}/market/#invite="))
    url = urlsplit(link.input_value())
    assert url.fragment.startswith("invite=") and not url.query, url
    _shots(page, output_dir, "team")

    newcomer = browser.new_context().new_page()
    newcomer.goto(link.input_value())
    form = newcomer.locator("#register")
    form.locator("input[name=email]").fill(INVITED)
    form.locator("input[name=password]").fill(PASSWORD)
    form.locator("button[type=submit]").click()
    expect(newcomer.locator("#notice")).to_contain_text("Account created")
    newcomer.context.close()

    page.locator("#nav-crowd").click()
    page.locator("#nav-team").click()
    expect(page.locator("#team-rows [data-col=email]", has_text=INVITED)).to_have_count(1)


def test_publish_offers_each_provider_and_shows_the_cost_in_its_fees_first(
    admin_page: Page, live_server: LiveServer, crowd: dict, output_dir: Path,  # noqa: F811
) -> None:
    page, sid = admin_page, crowd["sequence_id"]
    page.goto(f"{live_server.base}/admin/#/sequences/{sid}")
    provider = page.locator("#publish-provider")
    expect(provider).to_have_value("mturk")
    assert provider.locator("option").evaluate_all("o => o.map(x => x.value)") == [
        "mturk", "prolific", "team"]
    assignee = page.locator("#publish-assignee-field")
    expect(assignee).to_be_hidden()
    # The team: an assignee field, its choices the team's accounts.
    provider.select_option("team")
    expect(assignee).to_be_visible()
    expect(page.locator(f'#publish-team option[value="{crowd["member"]}"]')).to_have_count(1)
    page.locator("#publish-assignee").fill(crowd["member"])
    _shots(page, output_dir, "publish-team")
    provider.select_option("mturk")
    expect(assignee).to_be_hidden()

    sent = _posts(page, "/api/crowd/publish")
    page.locator("#publish-reward").fill("0.40")
    page.locator("#publish-approval").fill("")
    page.locator("#publish-check").click()
    cost = page.locator("#publish-cost")
    expect(cost).to_contain_text(f"MTurk-compatible marketplace: {UNITS} HITs \u00d7 1 assignment "
                                 "at $0.40 + $0.08 fee")
    assert sent == [{"sequence_id": sid, "provider": "mturk", "reward": "0.40",
                     "max_assignments": 1, "min_approval_rate": None, "dry_run": True}]
    assert _units(live_server, sid) == []  # a dry run publishes nothing
    _shots(page, output_dir, "publish")

    page.locator("#publish-confirm").click()
    expect(page.locator("#project-status")).to_contain_text(f"Published {UNITS} HITs")
    assert sent[-1]["provider"] == "mturk" and "dry_run" not in sent[-1]
    assert len(_units(live_server, sid)) == UNITS


def _hold(server: LiveServer, hit_id: str, worker_id: str) -> int:
    """The worker takes the unit on the marketplace and our page opens it (nothing submitted):
    work left "working". Our assignment id."""
    from sqlalchemy import select

    from backend.annotation.models import Task
    from backend.annotation.service import start_assignment
    from backend.crowd.models import CrowdHit
    from backend.db import session_scope
    from backend.market import clock, workers

    with server_settings(server), session_scope() as session:
        market = workers.accept(session, worker_id, hit_id, clock.now())
        task = session.get_one(Task, session.scalar(
            select(CrowdHit.task_id).where(CrowdHit.hit_id == hit_id)))
        return start_assignment(session, task, market.assignment_id, worker_id, hit_id).id


def _row_matches_the_api(page: Page, unit: dict) -> None:
    row = page.locator(f'#unit-rows tr[data-unit="{unit["hit_id"]}"]')
    expect(row).to_have_attribute("data-state", unit["state"])
    for column in ("provider", "decided", "holders", "submitted", "state"):
        expect(row.locator(f'[data-col="{column}"]')).to_have_text(str(unit[column]))
    expect(row.locator('[data-col="places"]')).to_contain_text(str(unit["places"]))


def test_crowd_view_adds_a_place_expires_a_unit_and_closes_work_left_working(
    admin_page: Page, live_server: LiveServer, crowd: dict, output_dir: Path,  # noqa: F811
) -> None:
    page, server, sid = admin_page, live_server, crowd["sequence_id"]
    held, grown, expired = [u["hit_id"] for u in _units(server, sid)][:3]
    ours = _hold(server, held, crowd["member"])
    # From the sequence's page to its units, and only its units.
    page.goto(f"{server.base}/admin/#/sequences/{sid}")
    page.locator("#sequence-units").click()
    expect(page.locator("#crowd-title")).to_have_text(f"Crowd \u00b7 sequence #{sid}")
    expect(page.locator("#unit-rows tr")).to_have_count(UNITS)
    for unit in _units(server, sid):
        _row_matches_the_api(page, unit)
    by_id = {u["hit_id"]: u for u in _units(server, sid)}
    assert (by_id[held]["holders"], by_id[held]["provider"]) == (1, "mturk")

    # A place more.
    page.locator(f'#unit-rows tr[data-unit="{grown}"] button[data-action="add"]').click()
    expect(page.locator("#crowd-result")).to_have_text(f"Added 1 place to {grown}.")
    assert {u["hit_id"]: u for u in _units(server, sid)}[grown]["places"] == 2
    expect(page.locator(f'#unit-rows tr[data-unit="{grown}"] [data-col="places"]')) \
        .to_contain_text("2")

    # Expire: asked first; Cancel sends nothing, Confirm expires it.
    expire = page.locator(f'#unit-rows tr[data-unit="{expired}"] button[data-action="expire"]')
    expire.click()
    expect(page.locator("#crowd-confirm-text")).to_contain_text(f"Expire {expired}?")
    _shots(page, output_dir, "expire-asked")
    page.locator("#crowd-confirm-no").click()
    expect(page.locator("#crowd-confirm")).to_be_hidden()
    assert {u["hit_id"]: u for u in _units(server, sid)}[expired]["state"] == "open"
    expire.click()
    page.locator("#crowd-confirm-yes").click()
    expect(page.locator(f'#unit-rows tr[data-unit="{expired}"]')).to_have_attribute(
        "data-state", "expired")
    for unit in _units(server, sid):
        _row_matches_the_api(page, unit)
    # Extended, an expired unit is open again, for 24 h from now.
    page.locator(f'#unit-rows tr[data-unit="{expired}"] button[data-action="extend"]').click()
    expect(page.locator("#crowd-result")).to_have_text(f"{expired} stays open 24 h from now.")
    expect(page.locator(f'#unit-rows tr[data-unit="{expired}"]')).to_have_attribute(
        "data-state", "open")

    # The unit's assignments: the member's work, still "working", with their email; closed.
    page.locator(f'#unit-rows tr[data-unit="{held}"] button[data-action="assignments"]').click()
    work = page.locator(f'#unit-assignment-rows tr[data-assignment="{ours}"]')
    expect(work.locator('[data-col="worker"]')).to_have_text(f"{crowd['member']} · {MEMBER}")
    expect(work).to_have_attribute("data-status", "working")
    _shots(page, output_dir, "units")
    work.locator("button[data-close]").click()
    expect(page.locator("#crowd-confirm-text")).to_contain_text(f"Close assignment {ours}?")
    page.keyboard.press("Enter")
    expect(work).to_have_attribute("data-status", "closed")
    expect(page.locator(f'#unit-rows tr[data-unit="{held}"] [data-col="holders"]')) \
        .to_have_text("0")
    listed = server.admin("GET", f"/api/crowd/units/{held}/assignments")
    assert [a["status"] for a in listed] == ["closed"]  # type: ignore[index]
    _shots(page, output_dir, "units-closed")


def _waiting_report(server: LiveServer, task_id: int) -> int:
    """Submitted work of the task with a QC report waiting for an admin; its assignment id."""
    from backend.annotation.models import Task
    from backend.annotation.service import create_assignment
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with server_settings(server), session_scope() as session:
        task = session.get_one(Task, task_id)
        work = create_assignment(session, task, "AQUEUEWORKER01", "queue-r-confirm", None)
        work.status = "submitted"
        session.add(QCReport(assignment_id=work.id, task_id=task.id,
                             sequence_id=task.sequence_id, target_key=task.target_key,
                             worker_id=work.worker_id, metrics={}, outcome="review",
                             feedback=FEEDBACK, views=1))
        session.flush()
        return work.id


def test_r_in_the_review_queue_asks_first_and_alone_sends_nothing(
    admin_page: Page, live_server: LiveServer, crowd: dict, output_dir: Path,  # noqa: F811
) -> None:
    page = admin_page
    hand = next(t for t in crowd["tasks"] if t["kind"] == "hand")
    assignment = _waiting_report(live_server, hand["id"])
    page.goto(f"{live_server.base}/admin/#/queue/{assignment}")
    expect(page.locator("#queue-list li.selected")).to_have_attribute(
        "data-assignment", str(assignment))
    feedback = page.locator("#queue-feedback")
    expect(feedback).not_to_have_value("")
    sent = _posts(page, f"/api/crowd/assignments/{assignment}/reject")
    page.locator("#queue-tally").click()  # out of the feedback field: keys decide

    page.keyboard.press("r")
    confirm = page.locator("#queue-confirm")
    expect(confirm).to_be_visible()
    expect(page.locator("#queue-confirm-text")).to_contain_text(
        f"Reject assignment {assignment}?")
    expect(page.locator("#queue-confirm-detail")).to_have_text(feedback.input_value())
    expect(page.locator("#queue-confirm-yes")).to_be_focused()
    # A while later, still nothing sent; A does not approve while the question is open.
    page.keyboard.press("a")
    page.wait_for_timeout(600)
    assert sent == []
    _shots(page, output_dir, "queue-reject-asked")
    page.keyboard.press("Escape")
    expect(confirm).to_be_hidden()
    page.wait_for_timeout(300)
    assert sent == []
    assert live_server.admin("GET", f"/api/qc/reports/{assignment}")["action"] is None  # type: ignore[index]

    page.keyboard.press("r")
    expect(confirm).to_be_visible()
    with page.expect_request(lambda r: r.method == "POST" and r.url.endswith(
            f"/api/crowd/assignments/{assignment}/reject")):
        page.keyboard.press("Enter")
    assert sent == [{"feedback": feedback.input_value().strip()}]
    expect(confirm).to_be_hidden()
