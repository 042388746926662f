"""Acceptance, as a new admin and a new team member would do it, in a real browser: the admin
makes an invite on the Team view; the member opens the link, registers and signs in to the
portal; the admin publishes the sequence to the team with the member as assignee through the
publish form (the cost in the team's fees: 0); the member finds the hand task "assigned to
you", accepts it, places the hand's joints on two keyframes in the framed page and submits, and
the portal shows it submitted; the admin adds a place to one unit and expires another (asked
first) on the Crowd view, and in the review queue R asks before it rejects the member's work:
its status stays "submitted" until the rejection is confirmed.

The publish form publishes every task of a sequence, so the capture is its own (seed 31: two
views, a hand and an object in each; the hand of the second view stays in the picture in the
first and last frame): four units, all for the member. QC is not run here (the loop tests run
it): the member's work gets a report waiting for an admin as QC leaves one. Its units are
expired and its sequence deleted at the end. Screenshots of each step at 1440x900 and 1024x700
go to /tmp/shots-accept/.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright.sync_api import Browser, Frame, Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import READY, confirm_submit, server_settings
from tests.browser.test_admin import admin_page  # noqa: F401  (fixture)
from tests.browser.test_portal import _annotate_two_keyframes

SEED = 31
LAST = CLIP_FRAMES - 1
SHOTS = Path("/tmp/shots-accept")
SIZES = ((1440, 900), (1024, 700))
MEMBER = "team-flow-member@example.org"
PASSWORD = "the member's own password"
FEEDBACK = "The fingertips drift off the hand between the keyframes: please check each joint."


def _shots(page: Page, name: str) -> None:
    """Screenshots ``{name}-{w}x{h}.png`` at each size (whole page), then back to the first."""
    SHOTS.mkdir(parents=True, exist_ok=True)
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(200)
        page.screenshot(path=str(SHOTS / f"{name}-{width}x{height}.png"), full_page=True)
    page.set_viewport_size({"width": SIZES[0][0], "height": SIZES[0][1]})


def _units(server: LiveServer, sequence_id: int) -> dict[str, dict]:
    units = server.admin("GET", f"/api/crowd/units?sequence_id={sequence_id}")
    assert isinstance(units, list)
    return {u["hit_id"]: u for u in units}


@pytest.fixture
def sequence(live_server: LiveServer, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """The capture imported, its tasks made: {"id", "tasks"}; its open units expired and the
    sequence deleted at the end."""
    from backend.captures.flows import import_path
    from worker.synth import generate_capture

    capture = tmp_path_factory.mktemp("team-flow") / "capture"
    generate_capture(capture, seed=SEED, frames=CLIP_FRAMES, views=2, objects=1)
    with server_settings(live_server):
        sequence_id = import_path(capture)[0].sequence_id
    tasks = live_server.admin("POST", f"/api/sequences/{sequence_id}/tasks")
    assert isinstance(tasks, list) and len(tasks) == 4
    yield {"id": sequence_id, "tasks": tasks, "capture": capture}
    headers = {"Authorization": f"Bearer {live_server.admin_token}"}
    for unit in _units(live_server, sequence_id).values():
        if unit["state"] == "open":
            httpx.post(f"{live_server.base}/api/crowd/hits/{unit['hit_id']}/expire",
                       headers=headers, timeout=30)
    httpx.delete(f"{live_server.base}/api/sequences/{sequence_id}?force=true", headers=headers,
                 timeout=60)


def _invite_and_register(admin: Page, server: LiveServer, browser: Browser) -> Page:
    """Step 1: the admin's invite link; the member registers with it and signs in. The
    member's portal page."""
    admin.locator("#nav-team").click()
    expect(admin.locator("#team-view")).to_be_visible()
    admin.locator("#invite-create").click()
    link = admin.locator("#invite-url")
    expect(link).to_have_value(re.compile(f"^{re.escape(server.base)}/market/#invite="))
    _shots(admin, "1-admin-team-invite")

    member = browser.new_context(viewport={"width": 1440, "height": 900}).new_page()
    member.context.set_default_timeout(15000)
    member.goto(link.input_value())
    form = member.locator("#register")
    # A newcomer's page starts with making the account, above the sign-in form.
    assert member.locator("#login-view > form").first.get_attribute("id") == "register"
    form.locator("input[name=email]").fill(MEMBER)
    form.locator("input[name=password]").fill(PASSWORD)
    _shots(member, "1-member-register")
    form.locator("button[type=submit]").click()
    # Signed in at once, on the list of HITs (none for them yet).
    expect(member.locator("#notice")).to_contain_text(
        f"Account created: you are signed in as {MEMBER}.")
    expect(member.locator("#hits-view")).to_be_visible()
    expect(member.locator("#who")).to_contain_text(MEMBER)
    _shots(member, "1-member-signed-in")
    return member


def _publish_to_member(admin: Page, server: LiveServer, sequence_id: int,
                       worker_id: str) -> None:
    """Step 2: the sequence published to the team, assigned to the member, the cost checked
    first (the team's fees are 0)."""
    admin.goto(f"{server.base}/admin/#/sequences/{sequence_id}")
    admin.locator("#publish-provider").select_option("team")
    expect(admin.locator("#publish-assignee-field")).to_be_visible()
    expect(admin.locator(f'#publish-team option[value="{worker_id}"]')).to_have_text(MEMBER)
    admin.locator("#publish-assignee").fill(worker_id)
    # The team's members are the lab's own: no approval rate to meet.
    expect(admin.locator("#publish-approval-field")).to_be_hidden()
    admin.locator("#publish-check").click()
    cost = admin.locator("#publish-cost")
    expect(cost).to_contain_text("Our team (portal): 4 HITs \u00d7 1 assignment")
    expect(cost).to_contain_text("+ $0.00 fee")
    expect(cost).to_contain_text("fees $0.00")
    expect(cost).to_contain_text("recorded only: the team is paid nothing through dexlabel")
    _shots(admin, "2-admin-publish-team")
    admin.locator("#publish-confirm").click()
    expect(admin.locator("#project-status")).to_contain_text("Published 4 HITs")
    units = _units(server, sequence_id).values()
    assert [(u["provider"], u["state"]) for u in units] == [("team", "open")] * 4


def _truth(task: dict, frame: int) -> np.ndarray:
    """The true 2D joints (21 x 2, image px) of the hand in one frame of the task's view."""
    folder = next(task["capture"].glob(f"*/*/{task['serial']}"))
    return np.load(folder / f"labels_{frame:06d}.npz")["joint_2d"][0].astype(float)


def _work_frame(member: Page) -> Frame:
    frame = member.wait_for_selector("#work-frame iframe").content_frame()
    assert frame is not None
    frame.wait_for_function(READY)
    return frame


def _annotate_and_submit(member: Page, server: LiveServer, task: dict, hit_id: str) -> None:
    """Step 3: the member finds the hand task assigned to them, accepts it, places the 21
    joints on the first and last frame and submits; back on the list, it shows submitted."""
    member.reload()
    expect(member.locator("#hits-view")).to_be_visible()
    row = member.locator(f'tr[data-hit="{hit_id}"]')
    expect(row.locator(".mark-assigned")).to_have_text("assigned to you")
    _shots(member, "3-member-assigned")
    row.locator("a.hit-title").click()
    member.locator("#accept").click()
    frame = _work_frame(member)
    first, last = _truth(task, 0), _truth(task, LAST)
    _annotate_two_keyframes(frame, first, last)
    _shots(member, "3-member-annotated")
    frame.locator("#submit").click()
    confirm_submit(frame.locator("#submit-dialog")).click()
    expect(member.locator("#notice")).to_contain_text("Submitted")
    expect(member.locator("#hits-view")).to_be_visible()
    submitted = member.locator(f'tr[data-hit="{hit_id}"]')
    expect(submitted).to_have_attribute("data-mine", "Submitted")
    expect(submitted.locator(".mark-submitted")).to_have_text("submitted")
    _shots(member, "3-member-submitted")


def _unit_row(page: Page, hit_id: str):
    return page.locator(f'#unit-rows tr[data-unit="{hit_id}"]')


def _add_a_place_and_expire(admin: Page, server: LiveServer, sequence_id: int, grown: str,
                            expired: str) -> None:
    """Step 4a: on the Crowd view, a place more on one unit; another expired once confirmed."""
    admin.goto(f"{server.base}/admin/#/crowd/{sequence_id}")
    expect(admin.locator("#unit-rows tr")).to_have_count(4)
    _unit_row(admin, grown).locator('button[data-action="add"]').click()
    expect(admin.locator("#crowd-result")).to_have_text(f"Added 1 place to {grown}.")
    expect(_unit_row(admin, grown).locator('[data-col="places"]')).to_contain_text("2")
    assert _units(server, sequence_id)[grown]["places"] == 2

    _unit_row(admin, expired).locator('button[data-action="expire"]').click()
    unit = _units(server, sequence_id)[expired]
    expect(admin.locator("#crowd-confirm-text")).to_contain_text(
        f"Expire {expired}? It is task {unit['task_id']} (view {unit['serial']}, "
        f"{unit['target_key']}).")
    _shots(admin, "4-admin-crowd-expire-asked")
    assert _units(server, sequence_id)[expired]["state"] == "open"
    admin.locator("#crowd-confirm-yes").click()
    row = _unit_row(admin, expired)
    expect(row).to_have_attribute("data-state", "expired")
    expect(row.locator('[data-col="state"]')).to_have_text("expired")
    assert _units(server, sequence_id)[expired]["state"] == "expired"
    _shots(admin, "4-admin-crowd-done")


def _wait_for_review(server: LiveServer, assignment_id: int) -> None:
    """The member's submitted work confirmed with the team's marketplace (the confirm job's
    work, run here: no queue worker runs beside this server), with a QC report waiting for an
    admin, as QC leaves one whose figures it cannot decide on."""
    from backend import pipeline
    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with server_settings(server):
        assert pipeline.confirm(assignment_id)["state"] == "accepted"
        with session_scope() as session:
            work = session.get_one(Assignment, assignment_id)
            assert work.status == "submitted", work.status
            task = work.task
            session.add(QCReport(assignment_id=work.id, task_id=task.id,
                                 sequence_id=task.sequence_id, target_key=task.target_key,
                                 worker_id=work.worker_id, metrics={}, outcome="review",
                                 feedback=FEEDBACK, views=1))


def _status(server: LiveServer, hit_id: str) -> str:
    [work] = server.admin("GET", f"/api/crowd/units/{hit_id}/assignments")  # type: ignore[misc]
    return str(work["status"])


def _reject_asked_first(admin: Page, server: LiveServer, hit_id: str) -> None:
    """Step 4b: in the review queue R asks; nothing is sent until the rejection is confirmed."""
    [work] = server.admin("GET", f"/api/crowd/units/{hit_id}/assignments")  # type: ignore[misc]
    assignment = work["assignment_id"]
    _wait_for_review(server, assignment)
    admin.goto(f"{server.base}/admin/#/queue/{assignment}")
    expect(admin.locator("#queue-list li.selected")).to_have_attribute(
        "data-assignment", str(assignment))
    expect(admin.locator("#queue-feedback")).to_have_value(FEEDBACK)
    admin.locator("#queue-tally").click()  # out of the feedback field: keys decide
    admin.keyboard.press("r")
    expect(admin.locator("#queue-confirm")).to_be_visible()
    expect(admin.locator("#queue-confirm-text")).to_contain_text(
        f"Reject assignment {assignment}?")
    admin.wait_for_timeout(500)
    assert _status(server, hit_id) == "submitted"
    _shots(admin, "4-admin-queue-reject-asked")
    admin.locator("#queue-confirm-yes").click()
    expect(admin.locator("#queue-confirm")).to_be_hidden()
    for _ in range(50):
        if _status(server, hit_id) != "submitted":
            break
        admin.wait_for_timeout(200)
    assert _status(server, hit_id) == "rejected"
    _shots(admin, "4-admin-queue-rejected")


def test_an_admin_invites_a_member_assigns_a_hand_task_and_decides_on_the_work(
    admin_page: Page, live_server: LiveServer, browser: Browser,  # noqa: F811
    sequence: dict,
) -> None:
    admin, server, sid = admin_page, live_server, sequence["id"]
    member = _invite_and_register(admin, server, browser)
    [account] = [m for m in server.admin("GET", "/api/crowd/team?limit=1000")  # type: ignore[union-attr]
                 if m["email"] == MEMBER]
    _publish_to_member(admin, server, sid, account["worker_id"])

    units = _units(server, sid)
    by_task = {u["task_id"]: u["hit_id"] for u in units.values()}
    hands = sorted((t for t in sequence["tasks"] if t["kind"] == "hand"),
                   key=lambda t: t["serial"])
    task = {**hands[1], "capture": sequence["capture"]}
    objects = [t for t in sequence["tasks"] if t["kind"] != "hand"]
    try:
        _annotate_and_submit(member, server, task, by_task[task["id"]])
    finally:
        member.context.close()
    _add_a_place_and_expire(admin, server, sid, by_task[hands[0]["id"]],
                            by_task[objects[0]["id"]])
    _reject_asked_first(admin, server, by_task[task["id"]])
