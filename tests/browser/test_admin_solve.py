"""Solve review on the admin page in a real browser: a done run's overlays stepped and played
frame by frame per view, the residual chart beside them, wireframe meshes, the flagged frames on
the slider, a re-run with other settings, and two runs compared.

The runs hold the live capture's ground truth (tests/solve_truth.py): stored without the solver,
so they are ready at once and every expected value is known. Run B is run A with the hand 5 mm
off and the object turned 3 degrees; run A flags FLAGGED frames.
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect
from sqlalchemy import select

from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, CLIP_FRAMES, LiveServer
from tests.browser.helpers import server_settings, wait_overlay_shows
from tests.solve_truth import FLAG_REASON, store_truth_run

FLAGGED = (3, 8)
SHIFT_M = (0.003, 0.0, 0.004)  # 5 mm
TURN_DEG = 3.0


@pytest.fixture(scope="module")
def truth_runs(live_server: LiveServer) -> dict[str, int]:
    with server_settings(live_server):
        a = store_truth_run(live_server.capture, live_server.sequence_id, flagged=FLAGGED)
        b = store_truth_run(live_server.capture, live_server.sequence_id, hand_shift_m=SHIFT_M,
                            object_turn_deg=TURN_DEG)
    return {"a": a, "b": b}


@pytest.fixture
def solve_page(page: Page, live_server: LiveServer, truth_runs: dict[str, int]) -> Page:
    """The sequence page, signed in, with run A's overlays open."""
    page.goto(f"{live_server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill(ADMIN_PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#sequences-view")).to_be_visible()
    page.goto(f"{live_server.base}/admin/#/sequences/{live_server.sequence_id}")
    page.locator(f'#run-rows tr[data-run="{truth_runs["a"]}"] button[data-show-run]').click()
    expect(page.locator("#overlay-image")).to_have_attribute("src", re.compile(r"^blob:"))
    return page


def _api_png(server: LiveServer, run: int, frame: int, view: int, query: str = "") -> bytes:
    resp = httpx.get(f"{server.base}/api/solve-runs/{run}/frames/{frame}/views/{view}.png"
                     f"{query}", headers={"Authorization": f"Bearer {server.admin_token}"},
                     timeout=30)
    assert resp.status_code == 200, resp.text
    return resp.content


def _wait_shown(page: Page, png: bytes) -> None:
    """Until the overlay shows exactly ``png`` (the API's picture)."""
    wait_overlay_shows(page, png, 20.0)


def _chart(page: Page, frame: int) -> str:
    chart = page.locator("#solve-residuals svg[data-chart=residuals]")
    expect(chart).to_have_attribute("data-frame", str(frame))
    expect(chart).to_be_visible()
    return chart.inner_html()


def _expect_frame(page: Page, frame: int) -> None:
    expect(page.locator("#solve-frame-label")).to_have_text(f"Frame {frame} of {CLIP_FRAMES - 1}")
    expect(page.locator("#overlay-frame")).to_have_value(str(frame))


def test_stepping_through_frames_shows_each_frame_s_overlay_and_residuals(
    solve_page: Page, live_server: LiveServer, truth_runs: dict[str, int], output_dir: Path
) -> None:
    page, server, run = solve_page, live_server, truth_runs["a"]
    expect(page.locator("#overlay-view option")).to_have_count(2)
    _expect_frame(page, 0)
    _wait_shown(page, _api_png(server, run, 0, 0))
    first = _chart(page, 0)
    # Frame f's errors are 0.5 + f + 0.25 j + v px: 21 joints x 2 views of bars, all drawn.
    expect(page.locator("#solve-residuals svg")).to_have_attribute("data-bars", "42")
    page.locator("#solve-next").click()
    _expect_frame(page, 1)
    assert _chart(page, 1) != first
    _wait_shown(page, _api_png(server, run, 1, 0))
    page.locator("#overlay-frame").focus()
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    _expect_frame(page, 3)
    page.locator("#overlay-frame").fill("6")
    _expect_frame(page, 6)
    page.locator("#overlay-view").select_option("1")
    _wait_shown(page, _api_png(server, run, 6, 1))
    page.locator("#solve-prev").click()
    _expect_frame(page, 5)
    _wait_shown(page, _api_png(server, run, 5, 1))
    # Frame 5's largest error, little tip in view 1: 0.5 + 5 + 0.25 * 20 + 1 = 11.5 px; axis 20.
    expect(page.locator("#solve-residuals svg")).to_have_attribute("data-max", "20")
    # Eight quick steps: the frames stepped over while one is on its way are never asked for.
    asked: list[int] = []
    page.on("request", lambda r: asked.extend(
        int(m) for m in re.findall(r"/frames/(\d+)/views/", r.url)))
    page.locator("#overlay-frame").focus()
    for _ in range(8):
        page.keyboard.press("ArrowLeft")
    _expect_frame(page, 0)
    _wait_shown(page, _api_png(server, run, 0, 1))
    assert asked[-1] == 0 and len(asked) < 8, asked
    page.locator("#overlay-frame").fill("5")
    page.locator("#solve-play").click()
    expect(page.locator("#solve-play")).to_have_text("Pause")
    expect(page.locator("#solve-frame-label")).to_have_text(re.compile(r"Frame (7|8|9|10)\b"))
    page.locator("#solve-play").click()
    expect(page.locator("#solve-play")).to_have_text("Play")
    for width, height in ((1280, 720), (1024, 700), (1440, 900)):
        page.set_viewport_size({"width": width, "height": height})
        page.locator("#overlay").scroll_into_view_if_needed()
        page.screenshot(path=str(output_dir / f"admin-solve-{width}x{height}.png"))
    page.set_viewport_size({"width": 1280, "height": 720})
    _assert_fits(page)


def _assert_fits(page: Page) -> None:
    """Nothing in the overlay panel sticks out sideways at this width."""
    panel = page.locator("#overlay").bounding_box()
    assert panel is not None
    for selector in ("#overlay-image", "#solve-residuals svg", "#solve-next", "#solve-frame-label"):
        box = page.locator(selector).bounding_box()
        assert box is not None and box["x"] + box["width"] <= panel["x"] + panel["width"] + 1, (
            selector)


def _changed(picture: np.ndarray, dark: np.ndarray) -> np.ndarray:
    return np.abs(picture.astype(int) - dark.astype(int)).max(axis=2) > 12


def _hand_box(server: LiveServer, run: int, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """The solved hand joints projected into view 0 (px, lens included), and the (H, W) box
    around them grown by 4 px."""
    auth = {"Authorization": f"Bearer {server.admin_token}"}
    joints = np.asarray(httpx.get(f"{server.base}/api/solve-runs/{run}/frames/{frame}",
                                  headers=auth, timeout=30).json()["hand_joints"])
    sequence = server.admin("GET", f"/api/sequences/{server.sequence_id}")
    assert isinstance(sequence, dict)
    cam = next(c for c in sequence["cameras"] if c["view_index"] == 0)
    c2w = np.asarray(cam["extrinsics"], dtype=np.float64)
    K = np.array([[cam["fx"], 0, cam["ppx"]], [0, cam["fy"], cam["ppy"]], [0, 0, 1]])
    uv, _ = cv2.projectPoints(((joints - c2w[:, 3]) @ c2w[:, :3]).reshape(-1, 1, 3),
                              np.zeros(3), np.zeros(3), K, np.asarray(cam["distortion"], float))
    uv = uv.reshape(-1, 2)
    box = np.zeros((cam["height"], cam["width"]), bool)
    lo = np.clip(np.floor(uv.min(axis=0)).astype(int) - 4, 0, None)
    hi = np.ceil(uv.max(axis=0)).astype(int) + 5
    box[lo[1]:hi[1], lo[0]:hi[0]] = True
    return uv, box


def test_wireframe_draws_thin_lines_over_the_hand_where_solid_fills_it(
    solve_page: Page, live_server: LiveServer, truth_runs: dict[str, int], output_dir: Path
) -> None:
    page, server, run, frame = solve_page, live_server, truth_runs["a"], 4
    page.locator("#overlay-frame").fill(str(frame))
    page.locator("#overlay-style").select_option("wireframe")
    expect(page.locator("#overlay-alpha")).to_have_value("1")
    wire_png = _api_png(server, run, frame, 0, "?style=wireframe")
    _wait_shown(page, wire_png)
    decode = lambda data: cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)  # noqa: E731
    wire = decode(wire_png)
    solid = decode(_api_png(server, run, frame, 0, "?style=solid"))
    dark = decode(_api_png(server, run, frame, 0, "?style=blend&alpha=0"))
    uv, box = _hand_box(server, run, frame)
    solid_px, wire_px = _changed(solid, dark)[box].sum(), _changed(wire, dark)[box].sum()
    assert solid_px > 0.4 * box.sum() and 0.05 * solid_px < wire_px < 0.8 * solid_px, (
        solid_px, wire_px, box.sum())
    near = cv2.dilate(_changed(wire, dark).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    px = np.round(uv).astype(int)
    assert near[px[:, 1], px[:, 0]].mean() >= 0.9
    page.locator("#overlay-style").select_option("blend")
    _wait_shown(page, _api_png(server, run, frame, 0, "?style=blend"))
    page.locator("#overlay-alpha").fill("0.3")
    _wait_shown(page, _api_png(server, run, frame, 0, "?style=blend&alpha=0.3"))
    page.locator("#overlay-style").select_option("wireframe")
    _wait_shown(page, wire_png)
    page.locator("#overlay").scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-solve-wireframe.png"))


def test_flagged_frames_are_marked_on_the_slider_and_listed_with_their_reasons(
    solve_page: Page, truth_runs: dict[str, int], output_dir: Path
) -> None:
    page = solve_page
    ticks = page.locator("#solve-ticks button.tick")
    expect(ticks).to_have_count(len(FLAGGED))
    assert [t.get_attribute("data-frame") for t in ticks.all()] == [str(f) for f in FLAGGED]
    items = page.locator("#solve-flagged li")
    expect(items).to_have_count(len(FLAGGED))
    expect(items.first).to_contain_text(FLAG_REASON)
    # Each tick sits under where the slider's thumb is at that frame.
    slider = page.locator("#overlay-frame").bounding_box()
    assert slider is not None
    for frame, tick in zip(FLAGGED, ticks.all(), strict=True):
        page.locator("#overlay-frame").fill(str(frame))
        thumb = page.locator("#overlay-frame").evaluate(
            "el => { const r = el.getBoundingClientRect(), t = 16;"
            " return r.left + t / 2 + (r.width - t) * el.value / el.max; }")
        box = tick.bounding_box()
        assert box is not None and abs(box["x"] + box["width"] / 2 - thumb) <= 3, (frame, box)
    page.locator("#overlay-frame").fill("0")
    ticks.nth(1).click()
    _expect_frame(page, FLAGGED[1])
    expect(ticks.nth(1)).to_have_class(re.compile(r"\bcurrent\b"))
    expect(page.locator("#solve-frame-status")).to_have_class(re.compile(r"\bflagged\b"))
    items.first.locator("button").click()
    _expect_frame(page, FLAGGED[0])
    page.locator("#overlay-frame").fill("0")
    expect(page.locator("#solve-frame-status")).not_to_have_class(re.compile(r"\bflagged\b"))
    page.locator("#overlay").scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-solve-flagged.png"))


def test_two_runs_compare_frame_by_frame_and_a_run_with_itself_not_at_all(
    solve_page: Page, live_server: LiveServer, truth_runs: dict[str, int], output_dir: Path
) -> None:
    page, server = solve_page, live_server
    a, b = truth_runs["a"], truth_runs["b"]
    page.locator("#compare-a").select_option(str(a))
    page.locator("#compare-b").select_option(str(b))
    page.locator("#compare-runs").click()
    expect(page.locator("#compare-result")).to_be_visible()
    want = server.admin("GET", f"/api/solve-runs/{a}/compare/{b}")
    assert isinstance(want, dict) and want["hand_mean_mm"] == pytest.approx(5.0, abs=1e-3)
    expect(page.locator("#compare-summary")).to_contain_text("hand joints 5.0 mm apart")
    expect(page.locator("#compare-summary")).to_contain_text(f"{TURN_DEG:.1f}°")
    rows = page.locator("#compare-rows tr")
    expect(rows).to_have_count(len(want["largest"]))
    for row, expected in zip(rows.all(), want["largest"], strict=True):
        cells = row.locator("td").all_inner_texts()
        assert cells[0] == str(expected["frame"]) and cells[1] == expected["target"]
        assert float(cells[2]) == pytest.approx(expected["mm"], abs=0.006)
    lines = page.locator("#compare-chart polyline")
    expect(lines).to_have_count(2)
    # Every frame has a value: a point per frame on each line.
    assert len((lines.first.get_attribute("points") or "").split()) == CLIP_FRAMES
    page.locator("#compare-result").scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-solve-compare.png"))
    rows.first.locator("button").click()
    _expect_frame(page, want["largest"][0]["frame"])
    page.locator("#compare-b").select_option(str(a))
    page.locator("#compare-runs").click()
    expect(page.locator("#compare-summary")).to_contain_text("hand joints 0.0 mm apart")
    expect(page.locator("#compare-rows tr td:nth-child(3)").first).to_have_text("0.00")


# How long the page may take to show what the server answered to a request it sent (the
# server may be busy with a whole test suite beside it).
SLOW_MS = 30_000


def test_a_re_run_with_other_settings_is_queued_with_them(
    solve_page: Page, live_server: LiveServer, truth_runs: dict[str, int], output_dir: Path
) -> None:
    page, server = solve_page, live_server
    page.locator(f'#run-rows tr[data-run="{truth_runs["a"]}"] button[data-rerun]').click()
    expect(page.locator("#solve-rerun")).to_have_attribute("open", "")
    page.locator("#rerun-optimiser").select_option("paper")
    # The form is drawn again for the chosen optimiser: type into that one.
    expect(page.locator("#rerun-settings")).to_have_attribute("data-optimiser", "paper")
    field = page.locator('#rerun-settings input[name="paper_iterations"]')
    expect(field).to_be_visible()
    field.fill("2.5")
    page.locator("#rerun-start").click()
    status = page.locator("#rerun-status")
    expect(status).to_contain_text('paper_iterations must be a whole number, got "2.5"',
                                   timeout=SLOW_MS)
    field.fill("7")
    page.locator('#rerun-settings input[name="use_depth"]').uncheck()
    page.locator("#solve-rerun").scroll_into_view_if_needed()
    page.screenshot(path=str(output_dir / "admin-solve-rerun.png"))
    added = None
    if _accepted(server) == 0:
        # The API's refusal is shown as it words it; then one accepted assignment is enough.
        page.locator("#rerun-start").click()
        expect(status).to_contain_text("no accepted (approved) tracks", timeout=SLOW_MS)
        added = _approve_one(server)
    page.locator("#rerun-start").click()
    expect(status).to_contain_text(re.compile(r"Run #\d+ is queued \(paper; "), timeout=SLOW_MS)
    expect(status).to_contain_text("paper_iterations 7")
    run_id = int(re.findall(r"#(\d+)", status.inner_text())[0])
    try:
        expect(page.locator(f'#run-rows tr[data-run="{run_id}"]')).to_contain_text(
            "queued", timeout=SLOW_MS)
        run = server.admin("GET", f"/api/solve-runs/{run_id}")
        assert isinstance(run, dict) and run["optimiser"] == "paper"
        assert run["params"]["paper_iterations"] == 7 and run["params"]["use_depth"] is False
    finally:
        _clean_up(server, run_id, added)


def _accepted(server: LiveServer) -> int:
    from backend.db import session_scope
    from backend.labels import count_accepted

    with server_settings(server), session_scope() as session:
        return count_accepted(session, server.sequence_id)


def _approve_one(server: LiveServer) -> int:
    """An approved (empty) assignment of the object task: the sequence may be solved."""
    from backend.annotation.models import Assignment
    from backend.db import session_scope

    link = server.assign(server.task("object", 1), "SOLVE-RERUN")
    with server_settings(server), session_scope() as session:
        assignment = session.get_one(Assignment, int(link["assignment_id"]))
        assignment.status = "approved"
    return int(link["assignment_id"])


def _clean_up(server: LiveServer, run_id: int, assignment_id: int | None) -> None:
    """The queued run failed and its job out of the queue (no worker of a later test solves
    it), and the assignment approved for it gone."""
    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.jobs.models import Job
    from backend.solve.models import SolveRun
    from backend.solve.service import job_key

    with server_settings(server), session_scope() as session:
        run = session.get_one(SolveRun, run_id)
        run.status, run.error = "failed", "cancelled by the browser test"
        for job in session.scalars(select(Job).where(Job.key == job_key(run_id))):
            job.status, job.error = "failed", "cancelled by the browser test"
        if assignment_id is not None:
            session.delete(session.get_one(Assignment, assignment_id))
