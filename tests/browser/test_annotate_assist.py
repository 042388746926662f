"""Assisted annotation in the real page: tracking proposals shown as ghosts and accepted as
"tracked" keyframes, a correction that re-tracks its neighbours, sources that survive a reload;
suggestions pre-filled from three other views' accepted work, and epipolar lines through the true
joint; before three other views are accepted, the reason why not."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, VIEWPORT, LiveServer
from tests.browser.helpers import (
    best_tracked_joint,
    check_cells,
    goto_frame,
    grab_and_drop,
    open_task,
    pan_to_centre,
    queue_worker,
    screens,
    select_point,
    server_keyframes,
    server_settings,
    step_through,
    to_client,
    value_at,
    wait_saved,
    zoom_on_points,
)

LAST = CLIP_FRAMES - 1
# View 1 of the suite's capture shows the whole hand in the first and the last frame.
VIEW = 1
# Tracking proposals hold within about 1-2 px of the truth where they hold at all (BENCHMARKS);
# clicks land on whole screen px.
TRACK_TOL_PX = 3.0
SIZES = [(1024, 700), (1366, 768), (1440, 900)]
TRACK_GHOST_RGB = (0x35, 0xD0, 0xFF)


def _check_cells(server: LiveServer, assignment_id: int) -> set[tuple[int, int]]:
    return check_cells(server, assignment_id, 21, CLIP_FRAMES)


def _screens(page: Page, output_dir: Path, name: str) -> None:
    screens(page, output_dir, name, SIZES, VIEWPORT)


def _canvas_has_colour(page: Page, x: float, y: float, rgb: tuple[int, int, int],
                       canvas: str = "#view", radius: int = 2) -> bool:
    """Whether a pixel of ``canvas`` within ``radius`` CSS px of (x, y) (CSS px in the canvas)
    is within 40 levels of ``rgb`` in every channel."""
    return page.evaluate("""([sel, x, y, rgb, radius]) => {
      const canvas = document.querySelector(sel);
      const dpr = canvas.width / canvas.getBoundingClientRect().width;
      const ctx = canvas.getContext("2d");
      for (let dy = -radius; dy <= radius; dy++) {
        for (let dx = -radius; dx <= radius; dx++) {
          const px = Math.round((x + dx) * dpr);
          const d = ctx.getImageData(px, Math.round((y + dy) * dpr), 1, 1).data;
          if ([0, 1, 2].every((i) => Math.abs(d[i] - rgb[i]) <= 40)) return true;
        }
      }
      return false;
    }""", [canvas, x, y, list(rgb), radius])


def _proposal_bodies(page: Page) -> list[dict[str, Any]]:
    bodies: list[dict[str, Any]] = []
    page.on("request", lambda r: bodies.append(json.loads(r.post_data or "{}"))
            if r.url.endswith("/api/annotate/proposals") else None)
    return bodies


def _wait_assist_idle(page: Page) -> None:
    page.wait_for_function("!window.__dexlabel.assist.pending")


def _track_and_look(page: Page, joint: int, truth: list[np.ndarray], checks: set,
                    output_dir: Path) -> int:
    """T at frame 5, then at a proposed frame: one ghost near the joint's true position, cyan
    on the frame and on the joint's timeline row; nothing written yet. Returns that frame."""
    goto_frame(page, 5)
    page.keyboard.press("t")
    page.wait_for_function("window.__dexlabel.assist.proposals !== null")
    expect(page.locator("#assist-status")).to_contain_text("of 10 frames tracked")
    marks = page.evaluate("window.__dexlabel.assist.timelineMarks()")
    assert marks[0]["point"] == joint and len(marks[0]["frames"]) >= 3, marks
    look = min(marks[0]["frames"], key=lambda f: abs(f - 8))
    goto_frame(page, look)
    drawn = page.evaluate("window.__dexlabel.assist.drawn")
    assert len(drawn["ghosts"]) == 1 and drawn["ghosts"][0]["point"] == joint, (
        drawn, page.evaluate("window.__dexlabel.assist.proposals"),
        page.locator("#assist-status").text_content())
    ghost = np.array(drawn["ghosts"][0]["xy"])
    if (joint, look) not in checks:
        assert np.linalg.norm(ghost - truth[look][joint]) < TRACK_TOL_PX, (ghost, look)
    s = page.evaluate("([x, y]) => window.__dexlabel.editor.transform.toScreen(x, y)",
                      ghost.tolist())
    assert _canvas_has_colour(page, s["x"] + 13, s["y"], TRACK_GHOST_RGB)
    cell = page.evaluate("""([p, f]) => { const t = window.__dexlabel.page.timeline;
      const c = t.cellCentre(p, f); return {x: c.x, y: c.y - t.rowHeight / 2 + 2}; }""",
                         [joint, look])
    assert _canvas_has_colour(page, cell["x"], cell["y"], TRACK_GHOST_RGB,
                              canvas=".timeline-canvas", radius=1)
    assert len(page.evaluate(f"window.__dexlabel.store.keyframes({joint})")) == 2
    # The ghost and the interpolated point it would replace, both in the middle of the view.
    held = value_at(page, joint, look)
    pan_to_centre(page, (ghost[0] + held["x"]) / 2, (ghost[1] + held["y"]) / 2)
    _screens(page, output_dir, "assist-track-ghosts")
    return look


def test_track_accept_correct_and_reload_keep_sources(
    live_server: LiveServer, page: Page, output_dir: Path
) -> None:
    task = live_server.task("hand", VIEW)
    link = live_server.assign(task, "W-assist")
    checks = _check_cells(live_server, link["assignment_id"])
    bodies = _proposal_bodies(page)
    open_task(page, live_server.page_url(link["token"]))
    truth = [live_server.truth(task["serial"], f) for f in range(CLIP_FRAMES)]
    joint = best_tracked_joint(live_server, link["token"], truth, TRACK_TOL_PX)
    zoom_on_points(page, [truth[0][joint], truth[LAST][joint]])
    select_point(page, joint)
    page.mouse.click(*to_client(page, *truth[0][joint]))
    select_point(page, joint)
    goto_frame(page, LAST)
    grab_and_drop(page, tuple(truth[0][joint]), tuple(truth[LAST][joint]))

    look = _track_and_look(page, joint, truth, checks, output_dir)
    step_through(page, 0, LAST)
    page.keyboard.press("Enter")
    expect(page.locator("#assist-status")).to_contain_text("Accepted:")
    wait_saved(page)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])[joint]
    tracked = {r[0]: r for r in stored if len(r) == 5 and r[4] == "tracked"}
    assert len(tracked) >= 3 and look in tracked, stored
    assert [len(r) for r in stored if r[0] in (0, LAST)] == [4, 4]
    for frame, row in tracked.items():
        if (joint, frame) not in checks:
            error = np.hypot(row[1] - truth[frame][joint][0], row[2] - truth[frame][joint][1])
            assert error < TRACK_TOL_PX, (frame, row, truth[frame][joint])

    # The worker drags the keyframe at a middle frame onto the joint: it becomes "edited" and
    # both sides are tracked again from it.
    fix = look
    goto_frame(page, fix)
    before = value_at(page, joint, fix)
    asked = len(bodies)
    grab_and_drop(page, (before["x"], before["y"]), tuple(truth[fix][joint]))
    _wait_assist_idle(page)
    assert page.evaluate(f"window.__dexlabel.store.keyframeAt({joint}, {fix}).source") == "edited"
    assert len(bodies) == asked + 1
    retrack = bodies[-1]
    # The sides of the correction that held tracked keyframes.
    first = 0 if min(tracked) < fix else fix
    last = LAST if max(tracked) > fix else fix
    assert (retrack["first_frame"], retrack["last_frame"]) == (first, last)
    anchors = retrack["tracks"][0]["keyframes"]
    assert [r[0] for r in anchors] == [0, fix, LAST]
    assert np.hypot(*(np.array(anchors[1][1:3]) - truth[fix][joint])) < 1.5
    expect(page.locator("#assist-status")).to_contain_text(f"Re-tracked frames {first}-{last}")
    wait_saved(page)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])[joint]
    sources = {r[0]: (r[4] if len(r) == 5 else "placed") for r in stored}
    assert sources[fix] == "edited" and sources[0] == sources[LAST] == "placed"
    neighbours = [f for f in (fix - 1, fix + 1) if f in sources]
    assert neighbours and all(sources[f] == "tracked" for f in neighbours), sources

    page.reload()
    page.wait_for_function("window.__dexlabel.ready")
    reloaded = page.evaluate(f"window.__dexlabel.store.keyframes({joint})")
    assert {k["frame"]: k["source"] for k in reloaded} == sources

    # A reviewer's read-only link: no assistance shown, its keys ask for and write nothing.
    readonly = live_server.admin("POST",
                                 f"/api/assignments/{link['assignment_id']}/readonly-link")
    open_task(page, live_server.base + readonly["url"])
    expect(page.locator("#assist")).to_be_hidden()
    saved = page.evaluate("JSON.stringify(window.__dexlabel.store.toJSON())")
    asked = len(bodies)
    goto_frame(page, 5)
    for key in ("t", "Shift+T", "Enter", "u", "Shift+U"):
        page.keyboard.press(key)
    page.wait_for_timeout(300)
    assert len(bodies) == asked
    assert page.evaluate("JSON.stringify(window.__dexlabel.store.toJSON())") == saved


# ---- pre-fill from other views and epipolar lines ------------------------------------------

# Suggestions need accepted work in 3 other views (worker.assist.prefill.MIN_ACCEPTED_VIEWS):
# views 1-3 are accepted, view 0 is suggested.
PREFILL_VIEWS = 4
SUGGEST_GHOST_RGB = (0xFF, 0x5F, 0xD2)
# Three exact views' labels triangulated and reprojected: well under a px, except at the
# assignment's check cells (15 px off on purpose).
SUGGEST_TOL_PX = 2.0
# A fitted suggestion from two views' labels and depth (careful labels: median 1.5 px, 90th
# percentile 3.6 px, tests/worker/solver/test_solver_suggest.py).
FITTED_TOL_PX = 8.0
# The page's epipolar lines pass this close to the joint's true position (undistorted pinhole
# pixels against this view's slight lens distortion, near the image's centre).
LINE_TOL_PX = 2.0


@pytest.fixture(scope="module")
def prefill_capture(live_server: LiveServer, tmp_path_factory: pytest.TempPathFactory
                    ) -> dict[str, Any]:
    """A four-view capture imported into the live server, its hand work in views 1 to 3
    accepted (exact labels on every frame); the hand tasks of every view (sorted by serial)
    and view 0's truth."""
    from backend.annotation.models import Assignment, Track
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.db import session_scope, utcnow
    from worker.synth import generate_capture
    from worker.synth.annotators import hand_visibility

    capture = tmp_path_factory.mktemp("prefill") / "capture"
    generate_capture(capture, seed=9, frames=CLIP_FRAMES, views=PREFILL_VIEWS, objects=1)
    truth = CaptureTruth(capture)
    with server_settings(live_server):
        sequence_id = import_path(capture)[0].sequence_id
        tasks = live_server.admin("POST", f"/api/sequences/{sequence_id}/tasks")
        hands = sorted((t for t in tasks if t["kind"] == "hand"), key=lambda t: t["serial"])
        for view, task in enumerate(hands[1:], start=1):
            joints, seg = truth.view(task["serial"], CLIP_FRAMES)
            visible = hand_visibility(joints, seg)
            rows = [[[f, *joints[f, p].round(2).tolist(), int(visible[f, p])]
                     for f in range(CLIP_FRAMES)] for p in range(21)]
            with session_scope() as session:
                assignment = Assignment(
                    task_id=task["id"], worker_id=f"prefill-{view}", status="approved",
                    external_id=f"direct-prefill-{view}", version=1,
                    working_time_s=100.0, submitted_at=utcnow())
                assignment.tracks = [Track(point_index=p, keyframes=r)
                                     for p, r in enumerate(rows)]
                session.add(assignment)
    joints, _ = truth.view(hands[0]["serial"], CLIP_FRAMES)
    return {"task": hands[0], "truth": joints, "hands": hands, "capture": capture}


def _central_joint(joints: np.ndarray, width: int, height: int) -> int:
    """The joint nearest the image's centre (where lens distortion bends lines least)."""
    return int(np.argmin(np.hypot(joints[:, 0] - width / 2, joints[:, 1] - height / 2)))


def test_suggestions_from_three_accepted_views_are_shown_used_and_lines_cross_the_joint(
    live_server: LiveServer, prefill_capture: dict[str, Any], page: Page, output_dir: Path
) -> None:
    task, truth = prefill_capture["task"], prefill_capture["truth"]
    link = live_server.assign(task, "W-prefill")
    checks = _check_cells(live_server, link["assignment_id"])
    open_task(page, live_server.page_url(link["token"]))
    expect(page.locator("#suggest-note")).to_contain_text("Suggestions from 3 other views")
    frame = 6
    joint = _central_joint(truth[frame], task["width"], task["height"])
    select_point(page, joint)
    goto_frame(page, frame)
    zoom_on_points(page, truth[frame])

    drawn = page.evaluate("window.__dexlabel.assist.drawn")
    suggestion = drawn["suggestion"]
    assert suggestion is not None and suggestion["point"] == joint
    error = np.hypot(*(np.array(suggestion["xy"]) - truth[frame][joint]))
    assert (14 < error < 16) if (joint, frame) in checks else error < SUGGEST_TOL_PX, error
    s = page.evaluate("([x, y]) => window.__dexlabel.editor.transform.toScreen(x, y)",
                      suggestion["xy"])
    assert _canvas_has_colour(page, s["x"] + 13, s["y"], SUGGEST_GHOST_RGB)

    lines = drawn["lines"]
    assert len(lines) >= 1, drawn
    for line in lines:
        x, y = truth[frame][joint]
        assert abs(line["a"] * x + line["b"] * y + line["c"]) < LINE_TOL_PX, (line, x, y)
        # Drawn: the canvas shows the line's colour where it crosses the image, away from the
        # points (at a quarter of its length).
        (x0, y0), (x1, y1) = line["ends"]
        q = page.evaluate("([x, y]) => window.__dexlabel.editor.transform.toScreen(x, y)",
                          [x0 + (x1 - x0) / 4, y0 + (y1 - y0) / 4])
        box = page.locator("#view").bounding_box()
        assert box is not None
        if 0 < q["x"] < box["width"] and 0 < q["y"] < box["height"]:
            assert not _canvas_has_colour(page, q["x"], q["y"], (0x1B, 0x1F, 0x24), radius=0)
    assert {line["serial"][-4:] for line in lines} <= {
        s[-4:] for s in page.evaluate("window.__dexlabel.assist.epipolar.map((e) => e.serial)")}
    # The lines are explained where they are drawn: a legend on the image names each line's
    # camera by its number (as the header does) and says what the lines mean.
    legend = page.locator("#epipolar-legend")
    expect(legend).to_be_visible()
    for line in lines:
        assert line["camera"] == task["view_serials"].index(line["serial"]) + 1
        expect(legend).to_contain_text(f"camera {line['camera']}")
    expect(legend).to_contain_text("E hides them")
    _screens(page, output_dir, "assist-prefill-lines")

    page.keyboard.press("e")
    assert page.evaluate("window.__dexlabel.assist.drawn.lines") == []
    expect(legend).to_be_hidden()
    page.keyboard.press("e")
    assert len(page.evaluate("window.__dexlabel.assist.drawn.lines")) == len(lines)

    # U uses the active joint's suggestions; Shift+U every joint's; one undo takes either back.
    page.keyboard.press("u")
    keyframes = page.evaluate(f"window.__dexlabel.store.keyframes({joint})")
    assert len(keyframes) >= CLIP_FRAMES - 2 and {k["source"] for k in keyframes} == {"prefilled"}
    assert page.evaluate("window.__dexlabel.assist.drawn.suggestion") is None
    page.keyboard.press("Control+z")
    assert page.evaluate(f"window.__dexlabel.store.keyframes({joint})") == []
    page.keyboard.press("Shift+U")
    expect(page.locator("#assist-status")).to_contain_text("suggested keyframes for 21 points")
    used = page.evaluate("JSON.stringify(window.__dexlabel.store.toJSON().tracks)")
    page.keyboard.press("Control+z")
    assert page.evaluate("window.__dexlabel.store.tracks().flat().length") == 0, (
        "one undo takes every joint's suggestions back")
    page.keyboard.press("Control+Shift+z")
    assert page.evaluate("JSON.stringify(window.__dexlabel.store.toJSON().tracks)") == used
    wait_saved(page)
    stored = server_keyframes(live_server.worker_get_task(link["token"])["assignment"])
    assert sum(len(rows) for rows in stored.values()) >= 21 * (CLIP_FRAMES - 2)
    assert {r[4] for rows in stored.values() for r in rows} == {"prefilled"}
    for p, rows in stored.items():
        for r in rows:
            if r[3] == 1 and (p, r[0]) not in checks:
                assert np.hypot(r[1] - truth[r[0]][p][0], r[2] - truth[r[0]][p][1]) < 3.0, (p, r)


@pytest.fixture
def fit_worker(live_server: LiveServer, output_dir: Path) -> Iterator[None]:
    """A queue consumer on the live server's database and queue: it runs the fit jobs."""
    with queue_worker(live_server, output_dir / "assist-fit-worker.log"):
        yield


def test_suggestions_from_two_accepted_views_are_fitted_and_the_page_says_so(
    live_server: LiveServer, prefill_capture: dict[str, Any], fit_worker: None, page: Page,
    output_dir: Path
) -> None:
    """View 3's other views are 0 (not labelled), 1 and 2 (accepted): two, too few to
    triangulate; the hand model fitted to them (a job on the worker queue: the page says
    they are being prepared, then asks again) suggests view 3's joints."""
    from backend.captures.truth import CaptureTruth

    task = prefill_capture["hands"][3]
    link = live_server.assign(task, "W-prefill-fitted")
    checks = _check_cells(live_server, link["assignment_id"])
    open_task(page, live_server.page_url(link["token"]))
    expect(page.locator("#suggest-note")).to_contain_text(
        "suggestions from the hand model are being prepared; they will appear shortly")
    _screens(page, output_dir, "assist-fitted-preparing")
    expect(page.locator("#suggest-note")).to_contain_text(
        "Suggestions from 2 other views, fitted: check each",
        timeout=150_000)
    assert page.evaluate("window.__dexlabel.assist.suggestions.size") == 21
    truth, _ = CaptureTruth(prefill_capture["capture"]).view(task["serial"], CLIP_FRAMES)
    frame = 6
    joint = _central_joint(truth[frame], task["width"], task["height"])
    select_point(page, joint)
    goto_frame(page, frame)
    suggestion = page.evaluate("window.__dexlabel.assist.drawn.suggestion")
    assert suggestion is not None and suggestion["point"] == joint
    error = np.hypot(*(np.array(suggestion["xy"]) - truth[frame][joint]))
    # Two views with exact labels: a few px (the fit, not the labels, is the error).
    assert (joint, frame) in checks or error < FITTED_TOL_PX, error
    _screens(page, output_dir, "assist-fitted-suggestions")
