"""Acceptance: a worker signs in to the portal, accepts a HIT that a requester published with
boto3's real mturk client, labels 21 joints on two keyframes in the framed annotation page,
submits through /mturk/externalSubmit; the requester sees the Answer and approves; the worker
sees the payment."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Frame, Page, expect

from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS
from backend.market.questions import parse_answers
from tests.backend.market.helpers import external_question, make_client
from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import (
    READY,
    confirm_submit,
    drag_image,
    goto_frame,
    place_joints,
    point_states,
    wait_saved,
    zoom_on_points,
)

LAST = CLIP_FRAMES - 1
VIEW = 1  # this view of the synthetic capture shows the whole hand in the first and last frame
EMAIL, PASSWORD = "portal-worker@example.org", "portal worker password"
DEV_SECRET = DEV_MARKET_REQUESTERS.split(":")[1]


@pytest.fixture
def portal_page(browser) -> Iterator[Page]:
    """A page tall enough for the HIT's frame; uncaught script errors fail the test."""
    ctx = browser.new_context(viewport={"width": 1440, "height": 1000})
    ctx.set_default_timeout(15000)
    page = ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    yield page
    ctx.close()
    assert not errors, f"uncaught errors in the page: {errors}"


def _publish(server: LiveServer, task: dict) -> tuple[object, str]:
    """The requester publishes the task as a HIT on the built-in marketplace; (client, HITId)."""
    token = server.admin("POST", f"/api/tasks/{task['id']}/preview-token")["token"]
    mturk = make_client(server.base, (DEV_MARKET_ACCESS_KEY, DEV_SECRET))
    hit = mturk.create_hit(
        Title="Track 21 hand joints (portal acceptance)", Description="Click each joint",
        Reward="0.50", MaxAssignments=1, LifetimeInSeconds=3600,
        AssignmentDurationInSeconds=1800, AutoApprovalDelayInSeconds=86400,
        Question=external_question(f"{server.base}/annotate/?task={token}", 700))["HIT"]
    return mturk, hit["HITId"]


def _sign_in(page: Page, server: LiveServer, email: str = EMAIL,
             password: str = PASSWORD) -> None:
    page.goto(f"{server.base}/market/")
    page.locator("#login input[name=email]").fill(email)
    page.locator("#login input[name=password]").fill(password)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#hits-view")).to_be_visible()


def _framed_page(page: Page, box: str) -> Frame:
    handle = page.wait_for_selector(f"{box} iframe")
    sandbox = handle.get_attribute("sandbox")
    assert sandbox == ("allow-scripts allow-forms allow-same-origin "
                       "allow-top-navigation-by-user-activation")
    frame = handle.content_frame()
    assert frame is not None
    frame.wait_for_function(READY)
    assert frame.evaluate("window.__dexlabel.error") in (None, False, ""), "page failed to load"
    return frame


def _annotate_two_keyframes(frame: Frame, first, last) -> None:
    zoom_on_points(frame, [*first, *last])
    place_joints(frame, first, range(21))
    goto_frame(frame, LAST)
    for p in range(21):
        drag_image(frame, tuple(first[p]), tuple(last[p]))
    assert point_states(frame) == ["keyframe"] * 21
    wait_saved(frame)


def _submit(page: Page, frame: Frame) -> None:
    frame.locator("#submit").click()
    dialog = frame.locator("#submit-dialog")
    expect(dialog).to_contain_text("Every point is placed or marked occluded")
    confirm_submit(dialog).click()
    expect(page.locator("#notice")).to_contain_text("Submitted")
    expect(page.locator("#hits-view")).to_be_visible()


def test_worker_accepts_annotates_submits_and_sees_the_payment(
    live_server: LiveServer, portal_page: Page, output_dir: Path
) -> None:
    page, server = portal_page, live_server
    server.admin("POST", "/api/portal/workers", {"email": EMAIL, "password": PASSWORD})
    task = server.task("hand", VIEW)
    mturk, hit_id = _publish(server, task)
    _sign_in(page, server)
    row = page.locator(f'tr[data-hit="{hit_id}"]')
    expect(row).to_contain_text("$0.50")
    expect(row).to_contain_text("30 min")
    row.locator("a.hit-title").click()
    preview = _framed_page(page, "#preview-frame")
    assert preview.evaluate("window.__dexlabel.ready")
    page.locator("#accept").click()
    frame = _framed_page(page, "#work-frame")
    assert "turkSubmitTo=" in frame.url and "workerId=A" in frame.url

    first, last = server.truth(task["serial"], 0), server.truth(task["serial"], LAST)
    _annotate_two_keyframes(frame, first, last)
    page.screenshot(path=str(output_dir / "portal-work.png"))
    _submit(page, frame)
    submitted = page.locator(f'tr[data-hit="{hit_id}"]')
    expect(submitted).to_have_attribute("data-mine", "Submitted")
    expect(submitted.locator(".mark")).to_have_text("submitted")

    found = mturk.list_assignments_for_hit(HITId=hit_id)["Assignments"]
    assert [a["AssignmentStatus"] for a in found] == ["Submitted"]
    assert parse_answers(found[0]["Answer"])["result"].startswith("submitted:")
    mturk.approve_assignment(AssignmentId=found[0]["AssignmentId"],
                             RequesterFeedback="Accurate joints, thank you")

    page.locator("#nav-earnings").click()
    expect(page.locator("#earned-paid")).to_contain_text("$0.50")
    done = page.locator(f'tr[data-assignment="{found[0]["AssignmentId"]}"]')
    expect(done).to_have_attribute("data-status", "Approved")
    expect(done).to_contain_text("Accurate joints, thank you")
    page.screenshot(path=str(output_dir / "portal-earnings.png"))
