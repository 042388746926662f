"""The review queue and the assignment replay in a real browser.

A capture of its own with four views (a swap needs three other views to be seen), imported into
the session's live server; its hand tasks published on the built-in marketplace and worked by
simulated workers: a swapper (ring and little fingers exchanged mid-clip) and three careful
ones. A queue consumer beside the server runs the confirm and QC jobs with automatic actions
off, so every report waits for an admin. The page then replays the swapper's work (its swap
span on the timeline, the heat map coloured by error, its points where its track puts them),
rejects it with the feedback prefilled from the evidence, and pays a careful worker a bonus and
approves the work, all from the keyboard.
"""

from __future__ import annotations

import colorsys
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, LiveServer
from tests.conftest import reset_caches

PROFILES = ("swapper", "careful", "careful", "careful")
FRAMES = 12
# Simulated marketplace workers of this module (accounts of their own).
FIRST_WORKER = 71
QC_TIMEOUT_S = 150.0
ERROR_MAX_PX = 20.0  # admin/core/replay.js: an error this large is drawn full red


def _rgb(error: float) -> np.ndarray:
    """admin/core/replay.js errorColour(error) as 0-255 RGB."""
    t = min(max(error / ERROR_MAX_PX, 0.0), 1.0)
    r, g, b = colorsys.hls_to_rgb(round(120 * (1 - t)) / 360, 0.42, 0.85)
    return np.array([r, g, b]) * 255


def _hex(colour: str) -> np.ndarray:
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)], float)


@pytest.fixture(scope="module")
def review_capture(live_server: LiveServer, tmp_path_factory: pytest.TempPathFactory
                   ) -> tuple[Path, int, list[str]]:
    """The four-view capture imported into the live server, its hand tasks published; its path,
    sequence id and HIT ids."""
    from backend.annotation.models import Task
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.crowd.client import make_client
    from backend.crowd.publish import publish_task
    from backend.crowd.schemas import PublishOptions
    from backend.db import session_scope
    from worker.synth import generate_capture

    capture = tmp_path_factory.mktemp("review") / "capture"
    generate_capture(capture, seed=8, frames=FRAMES, views=len(PROFILES), objects=1,
                     width=320, height=240)
    with pytest.MonkeyPatch.context() as mp:
        for key, value in live_server.env.items():
            mp.setenv(key, value)
        reset_caches()
        try:
            sequence_id = import_path(capture)[0].sequence_id
            live_server.admin("POST", f"/api/sequences/{sequence_id}/tasks")
            with session_scope() as session:
                task_ids = list(session.scalars(Task.__table__.select().with_only_columns(
                    Task.id).where(Task.sequence_id == sequence_id, Task.kind == "hand")))
            client, hits = make_client(get_settings()), list[str]()
            options = PublishOptions(min_approval_rate=None, max_assignments=1)
            for task_id in task_ids:
                with session_scope() as session, session.no_autoflush:
                    hits.append(publish_task(session, client, session.get_one(Task, task_id),
                                             options, [])[0])
        finally:
            reset_caches()
    assert len(hits) == len(PROFILES), hits
    return capture, sequence_id, hits


@pytest.fixture(scope="module")
def review_worker(live_server: LiveServer, output_dir: Path) -> Iterator[None]:
    """A queue consumer on the live server's database that scores but never acts: every report
    waits for an admin."""
    log = output_dir / "admin-review-worker.log"
    env = {**os.environ, **live_server.env, "DEXLABEL_QC_AUTO_ACTIONS": "false"}
    with log.open("w") as log_file:
        proc = subprocess.Popen([sys.executable, "-m", "backend.cli", "worker", "--workers", "1"],
                                env=env, stdout=log_file, stderr=subprocess.STDOUT)
        try:
            yield
        finally:
            proc.terminate()
            proc.wait(timeout=20)


@pytest.fixture(scope="module")
def reviewed(live_server: LiveServer, review_capture: tuple[Path, int, list[str]],
             review_worker: None) -> dict[str, Any]:
    """The simulated crowd's work on the capture, scored; profile -> an assignment id."""
    from backend.captures.truth import CaptureTruth
    from backend.crowd.simulate import WorkerClient, _work_one, admin_token

    # Only this capture's HITs: others left open by earlier tests in the session are not ours.
    capture, sequence_id, hit_ids = review_capture
    rng = np.random.default_rng(4)
    truth = CaptureTruth(capture)
    with httpx.Client(timeout=30.0) as http:
        admin = admin_token(http, live_server.base, ADMIN_EMAIL, ADMIN_PASSWORD)
        worker = WorkerClient(http, live_server.base)
        outcomes = [_work_one(worker, admin, FIRST_WORKER + i, profile, truth, rng,
                              set(hit_ids)) for i, profile in enumerate(PROFILES)]
    assert [o.status for o in outcomes] == ["submitted"] * len(PROFILES), outcomes
    deadline = time.monotonic() + QC_TIMEOUT_S
    reports: list[dict] = []
    while time.monotonic() < deadline:
        reports = live_server.admin("GET", f"/api/qc/reports?sequence_id={sequence_id}")
        busy = [j for j in live_server.admin("GET", "/api/jobs")
                if j["status"] in ("queued", "running", "retrying")]
        if len(reports) == len(PROFILES) and not busy and all(r["views"] == 4 for r in reports):
            break
        time.sleep(0.5)
    assert len(reports) == len(PROFILES), reports
    by_worker = {r["worker_id"]: r["assignment_id"] for r in reports}
    ids = {"swapper": by_worker[outcomes[0].worker_id]}
    ids.update({f"careful{i}": by_worker[o.worker_id] for i, o in enumerate(outcomes[1:])})
    # The marketplace's own assignment ids, to read what it recorded.
    ids.update({f"market:{by_worker[o.worker_id]}": o.assignment_id for o in outcomes})
    return ids


def _market_record(server: LiveServer, market_id: str) -> tuple[dict, list[dict]]:
    """The marketplace's record of an assignment and its bonus payments, through boto3."""
    from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS
    from tests.backend.market.helpers import make_client

    mturk = make_client(server.base, (DEV_MARKET_ACCESS_KEY,
                                      DEV_MARKET_REQUESTERS.split(":")[1]))
    return (mturk.get_assignment(AssignmentId=market_id)["Assignment"],
            mturk.list_bonus_payments(AssignmentId=market_id)["BonusPayments"])


def _sign_in(page: Page, server: LiveServer, size: tuple[int, int]) -> None:
    page.set_viewport_size({"width": size[0], "height": size[1]})
    page.goto(f"{server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill(ADMIN_PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#sequences-view")).to_be_visible()


def _open(page: Page, server: LiveServer, assignment_id: int) -> dict:
    """Open one waiting report in the queue; its review as the API gives it."""
    page.goto(f"{server.base}/admin/#/queue/{assignment_id}")
    panel = page.locator("#queue-review [data-review]")
    expect(panel).to_have_attribute("data-assignment", str(assignment_id))
    expect(panel).to_have_attribute("data-image-frame", "0")
    return server.admin("GET", f"/api/qc/reports/{assignment_id}/review")


def _pixel(page: Page, selector: str, x: float, y: float) -> np.ndarray:
    """RGB of a canvas at CSS px (x, y)."""
    rgba = page.evaluate("""([sel, x, y]) => {
      const c = document.querySelector(sel);
      const r = c.width / c.getBoundingClientRect().width;
      return Array.from(c.getContext("2d").getImageData(Math.floor(x * r), Math.floor(y * r),
                                                        1, 1).data);
    }""", [selector, x, y])
    return np.array(rgba[:3], float)


def test_queue_replays_a_swapper_and_decides_from_the_keyboard(
        page: Page, live_server: LiveServer, reviewed: dict[str, Any], output_dir: Path) -> None:
    server = live_server
    _sign_in(page, server, (1280, 720))
    page.locator("#nav-queue").click()
    expect(page.locator("#queue-view")).to_be_visible()
    expect(page.locator("#queue-keys")).to_be_in_viewport()
    queue = server.admin("GET", "/api/qc/queue?limit=500")["items"]
    rows = page.locator("#queue-list li")
    expect(rows).to_have_count(len(queue))
    listed = [int(a) for a in rows.evaluate_all("rs => rs.map(r => r.dataset.assignment)")]
    assert listed == [r["assignment_id"] for r in queue]
    ranks = [(r["provisional"], ["reject", "review", "approve"].index(r["outcome"]))
             for r in queue]
    assert ranks == sorted(ranks)
    swapper = reviewed["swapper"]
    assert queue[0]["assignment_id"] == swapper, queue[:3]

    review = _open(page, server, swapper)
    assert review["swaps"], review["reasons"]
    median = review["metrics"]["median_error_px"]
    expect(page.locator('#queue-review [data-review-metric="median_error_px"]')) \
        .to_contain_text(f"{median:.1f} px")
    for reason in review["reasons"]:
        expect(page.locator("#queue-review .reasons")).to_contain_text(reason)
    swap = review["swaps"][0]
    assert sorted(swap["fingers"]) == ["little", "ring"]
    page.screenshot(path=str(output_dir / "admin-review-queue-1280.png"))

    # The swap span on the timeline, under the heat map's columns of its frames.
    heat = page.locator("#queue-review canvas.heatmap")
    left, top, cell, row = (float(heat.get_attribute(f"data-{k}") or "nan")
                            for k in ("left", "top", "cell", "row"))
    span = page.locator('#queue-review svg.timeline g[data-kind="swap"]').first
    expect(span).to_have_attribute("data-first", str(swap["frames"][0]))
    expect(span).to_have_attribute("data-last", str(swap["frames"][1]))
    expect(span).to_contain_text("ring ↔ little")
    rect = span.locator("rect")
    assert float(rect.get_attribute("x") or "nan") == pytest.approx(left + swap["frames"][0] * cell)
    assert float(rect.get_attribute("width") or "nan") == pytest.approx(
        (swap["frames"][1] - swap["frames"][0] + 1) * cell)

    # Heat map cells: the swapped fingers' red inside the span, a careful joint's green.
    errors = np.array([[np.nan if v is None else v for v in f] for f in review["errors"]])
    first, last = swap["frames"]
    frame = first + int(np.nanargmax(np.nanmax(errors[first:last + 1, 13:21], axis=1)))
    swapped = 13 + int(np.nanargmax(errors[frame, 13:21]))
    careful = next(p for p in (1, 2, 5, 6, 9, 0) if np.isfinite(errors[frame, p]))
    assert errors[frame, swapped] > 10.0 and errors[frame, careful] < 5.0
    for point in (swapped, careful):
        colour = _pixel(page, "#queue-review canvas.heatmap", left + (frame + 0.5) * cell,
                        top + (point + 0.5) * row)
        assert np.abs(colour - _rgb(errors[frame, point])).max() < 12, (point, colour)
    hot = _pixel(page, "#queue-review canvas.heatmap", left + (frame + 0.5) * cell,
                 top + (swapped + 0.5) * row)
    assert hot[0] > hot[1] + 60  # red over green

    # A click on a heat map cell shows its frame; the worker's points lie where its track is.
    heat.click(position={"x": left + (frame + 0.5) * cell, "y": top + (careful + 0.5) * row})
    panel = page.locator("#queue-review [data-review]")
    expect(panel).to_have_attribute("data-frame", str(frame))
    expect(panel).to_have_attribute("data-image-frame", str(frame))
    # The clip opens on the box the points cover over it; the whole frame is one button away.
    page.locator('#queue-review button[data-act="fit"]').click()
    expect(panel).to_have_attribute("data-zoom", "1.00")
    canvas = page.locator("#queue-review canvas.replay")
    box = canvas.evaluate("c => [parseFloat(c.style.width), parseFloat(c.style.height)]")
    scale = min(box[0] / review["width"], box[1] / review["height"])
    ox, oy = box[0] / 2 - review["width"] / 2 * scale, box[1] / 2 - review["height"] / 2 * scale
    track = review["track"]
    drawn = [(p, np.array(xy, float) * scale + [ox, oy])
             for p, (xy, shown) in enumerate(zip(track["xy"][frame], track["visible"][frame],
                                                 strict=True)) if shown and xy[0] is not None]
    hits = 0
    for p, at in drawn:
        # Dots are drawn in point order: a later dot over this one shows its own colour.
        top_dot = max(q for q, other in drawn if q >= p and np.hypot(*(other - at)) <= 4.5)
        pixel = _pixel(page, "#queue-review canvas.replay", *at)
        hits += int(np.abs(pixel - _hex(review["point_colours"][top_dot])).max() < 16)
    assert len(drawn) >= 8 and hits >= 0.85 * len(drawn), (hits, len(drawn))

    # Keys: frames step, Space plays and pauses, zoom keeps the points under the wheel.
    page.locator("body").press("ArrowRight")
    expect(panel).to_have_attribute("data-frame", str(min(frame + 1, FRAMES - 1)))
    page.locator("body").press("ArrowLeft")
    expect(panel).to_have_attribute("data-frame", str(frame))
    page.locator("body").press(" ")
    expect(panel).to_have_attribute("data-playing", "true")
    page.locator("body").press(" ")
    expect(panel).not_to_have_attribute("data-playing", "true")
    page.locator('#queue-review button[data-act="zoom-in"]').click()
    expect(panel).to_have_attribute("data-zoom", "1.50")
    canvas.scroll_into_view_if_needed()
    middle = canvas.bounding_box()
    assert middle is not None
    page.mouse.move(middle["x"] + middle["width"] / 2, middle["y"] + middle["height"] / 2)
    page.mouse.wheel(0, -100)
    expect(panel).to_have_attribute("data-zoom", "1.88")
    # The heat map names the cell under the mouse.
    heat.scroll_into_view_if_needed()
    heat.hover(position={"x": left + (frame + 0.5) * cell, "y": top + (swapped + 0.5) * row})
    expect(heat).to_have_attribute("title", re.compile(
        rf"^{review['point_names'][swapped]}, frame {frame}: {errors[frame, swapped]:.1f} px"))
    page.locator('#queue-review button[data-act="points"]').click()

    # The rejection's feedback is prefilled from the evidence; typing a key into it decides
    # nothing; R asks (the feedback shown), Enter rejects, and the next waiting report opens.
    feedback = page.locator("#queue-feedback")
    expect(feedback).to_have_value(re.compile(r"[Rr]ing and little swapped in frames \d+-\d+"))
    feedback.press("End")
    feedback.type(" a")
    assert server.admin("GET", f"/api/qc/reports/{swapper}")["action"] is None
    sent = feedback.input_value()
    page.locator("#queue-keys").click()
    page.keyboard.press("r")
    expect(page.locator("#queue-confirm-detail")).to_have_text(sent.strip())
    assert server.admin("GET", f"/api/qc/reports/{swapper}")["action"] is None
    page.keyboard.press("Enter")
    expect(page.locator("#queue-result")).to_contain_text(f"Rejected assignment {swapper}")
    expect(panel).not_to_have_attribute("data-assignment", str(swapper))
    report = server.admin("GET", f"/api/qc/reports/{swapper}")
    assert report["action"] == "rejected", report
    assert swapper not in [r["assignment_id"] for r in
                           server.admin("GET", "/api/qc/queue?limit=500")["items"]]
    record, _ = _market_record(server, str(reviewed[f"market:{swapper}"]))
    assert record["AssignmentStatus"] == "Rejected"
    assert record["RequesterFeedback"] == sent.strip()

    # A careful worker: a bonus (B, $0.10), then approval (A).
    careful_id = reviewed["careful0"]
    _open(page, server, careful_id)
    page.locator("#queue-keys").click()
    page.keyboard.press("b")
    expect(page.locator("#queue-result")).to_contain_text("Bonus of $0.10 paid to")
    page.keyboard.press("a")
    expect(page.locator("#queue-result")).to_contain_text(f"Approved assignment {careful_id}")
    assert server.admin("GET", f"/api/qc/reports/{careful_id}")["action"] == "approved"
    record, bonuses = _market_record(server, str(reviewed[f"market:{careful_id}"]))
    assert record["AssignmentStatus"] == "Approved"
    assert [b["BonusAmount"] for b in bonuses] == ["0.10"], bonuses
    page.screenshot(path=str(output_dir / "admin-review-decided-1280.png"))


def test_review_panel_fits_narrow_windows_and_the_sequence_view(
        page: Page, live_server: LiveServer, reviewed: dict[str, Any], output_dir: Path) -> None:
    server = live_server
    _sign_in(page, server, (1024, 700))
    careful_id = reviewed["careful1"]
    _open(page, server, careful_id)
    for selector in ("#queue-review canvas.replay", "#queue-review canvas.heatmap",
                     "#queue-decision", "#queue-list"):
        box = page.locator(selector).bounding_box()
        assert box is not None and box["x"] >= 0 and box["x"] + box["width"] <= 1024, selector
    assert page.evaluate("document.documentElement.scrollWidth") <= 1024
    # The heat map's 21 joint names in 13 px type, on rows tall enough to hold them.
    heat = page.locator("#queue-review canvas.heatmap")
    assert float(heat.get_attribute("data-row") or 0) >= 15
    assert heat.get_attribute("data-font") == "13"
    page.screenshot(path=str(output_dir / "admin-review-queue-1024.png"))

    # The same panel under a sequence's reports.
    sequence_id = server.admin("GET", f"/api/qc/reports/{careful_id}")["sequence_id"]
    page.set_viewport_size({"width": 1280, "height": 720})
    page.goto(f"{server.base}/admin/#/sequences/{sequence_id}/reports/{careful_id}")
    panel = page.locator("#report-review [data-review]")
    expect(panel).to_have_attribute("data-assignment", str(careful_id))
    expect(panel).to_have_attribute("data-image-frame", "0")
    panel.scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-review-sequence-1280.png"))
    page.set_viewport_size({"width": 1024, "height": 700})
    page.screenshot(path=str(output_dir / "admin-review-sequence-1024.png"))
    page.set_viewport_size({"width": 1440, "height": 900})
    page.screenshot(path=str(output_dir / "admin-review-sequence-1440.png"), full_page=True)

    # The read-only annotation page: a new tab with its link, or, where the server has no such
    # link yet, the button disabled with a reason.
    button = page.locator('#report-review button[data-act="readonly"]')
    before = len(page.context.pages)
    button.click()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        if len(page.context.pages) > before and "/annotate" in page.context.pages[-1].url:
            break
        if button.is_disabled():
            break
        time.sleep(0.2)
    if button.is_disabled():
        expect(button).to_have_attribute("title", re.compile("read-only annotation links"))
    else:
        assert "/annotate" in page.context.pages[-1].url
