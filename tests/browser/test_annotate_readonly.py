"""An admin's read-only link (POST /api/assignments/{id}/readonly-link) opens the annotation page
on a worker's saved tracks: every point drawn where it was saved, a "read-only review" banner,
no Submit button, and nothing the reviewer does changes or sends anything."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import httpx
from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import drag_image, goto_frame, open_task, point_states, value_at

LAST = CLIP_FRAMES - 1
HIDDEN_POINT, HIDDEN_FROM, HIDDEN_TO = 8, 4, 7


def _saved_position(point: int, frame: int) -> tuple[float, float]:
    """Where the worker put each joint (image px): a 7 x 3 grid, wide enough apart that no
    marker or label covers another's centre; moved by 40 px right, 20 down by the last frame."""
    shift = frame / LAST
    return 60.0 + 80.0 * (point % 7) + 40.0 * shift, 80.0 + 80.0 * (point // 7) + 20.0 * shift


def _tracks() -> list[dict]:
    tracks = []
    for p in range(21):
        first, last = _saved_position(p, 0), _saved_position(p, LAST)
        rows = [[0, *first, 1], [LAST, *last, 1]]
        if p == HIDDEN_POINT:
            rows[1:1] = [[HIDDEN_FROM, None, None, 0], [HIDDEN_TO + 1, *_saved_position(
                p, HIDDEN_TO + 1), 1]]
        tracks.append({"point": p, "keyframes": rows})
    return tracks


def _saved_assignment(server: LiveServer) -> dict:
    link = server.assign(server.task("hand", view=1), worker="reviewed-worker")
    resp = httpx.put(f"{server.base}/api/annotate/tracks", timeout=30,
                     json={"version": 0, "tracks": _tracks(), "working_time_s": 95.0},
                     headers={"Authorization": f"Bearer {link['token']}"})
    assert resp.status_code == 200, resp.text
    return link


def _drawn_colour(page: Page, x: float, y: float) -> str:
    """The canvas colour at image position (x, y), as #rrggbb."""
    return page.evaluate("""([x, y]) => {
      const { editor } = window.__dexlabel;
      const s = editor.transform.toScreen(x, y);
      const dpr = window.devicePixelRatio || 1;
      const d = editor.ctx.getImageData(Math.round(s.x * dpr), Math.round(s.y * dpr), 1, 1).data;
      return "#" + [d[0], d[1], d[2]].map((v) => v.toString(16).padStart(2, "0")).join("");
    }""", [x, y])


def _points_drawn_where_saved(page: Page, frame: int, colours: list[str]) -> None:
    goto_frame(page, frame)
    for p in range(21):
        if p == HIDDEN_POINT and HIDDEN_FROM <= frame <= HIDDEN_TO:
            continue
        x, y = _saved_position(p, frame)
        v = value_at(page, p, frame)
        assert abs(v["x"] - x) < 1e-6 and abs(v["y"] - y) < 1e-6, (p, v)
        assert _drawn_colour(page, x, y) == colours[p].lower(), (p, frame)


def test_readonly_link_shows_the_saved_tracks_and_allows_no_change(
    page: Page, live_server: LiveServer, output_dir: Path
) -> None:
    link = _saved_assignment(live_server)
    readonly = live_server.admin(
        "POST", f"/api/assignments/{link['assignment_id']}/readonly-link")
    assert readonly["url"].startswith("/annotate/?")
    writes: list[str] = []
    page.on("request", lambda r: writes.append(f"{r.method} {r.url}")
            if r.method in ("PUT", "POST") else None)
    open_task(page, live_server.base + readonly["url"])
    assert page.evaluate("window.__dexlabel.error") is None
    banner = page.locator("#banner")
    expect(banner).to_be_visible()
    expect(banner).to_contain_text("Read-only review")
    expect(banner).to_contain_text("reviewed-worker")
    expect(page.locator("#save-status")).to_have_text("Read-only review")
    expect(page.locator("#submit")).to_be_hidden()
    for button in ("#undo", "#redo", "#toggle-occluded", "#delete-keyframe"):
        expect(page.locator(button)).to_be_disabled()
    assert page.evaluate("window.__dexlabel.saver") is None
    assert page.evaluate("window.__dexlabel.editor.readOnly") is True

    colours = page.evaluate("window.__dexlabel.editor.task.point_colors")
    _points_drawn_where_saved(page, 0, colours)
    _points_drawn_where_saved(page, LAST, colours)
    goto_frame(page, 5)
    states = point_states(page)
    assert states[HIDDEN_POINT] == "occluded" and states.count("interpolated") == 20
    page.set_viewport_size({"width": 1440, "height": 900})
    page.screenshot(path=str(output_dir / "annotate-readonly-1440.png"))

    # A reviewer's drag, keys and submit shortcut change nothing and send nothing.
    goto_frame(page, 0)
    before = page.evaluate("window.__dexlabel.store.tracks()")
    drag_image(page, _saved_position(3, 0), (300.0, 300.0))
    for key in ("o", "Delete", "Control+z", "Control+Enter"):
        page.keyboard.press(key)
    page.mouse.click(*page.evaluate("window.__dexlabel.imageToClient(600, 400)").values())
    assert page.evaluate("window.__dexlabel.store.tracks()") == before
    assert not [w for w in writes if "/api/annotate/" in w], writes
    # The token in the page's address cannot write either, whatever sends it.
    token = parse_qs(urlsplit(page.url).fragment)["token"][0]
    status = page.evaluate("""async (token) => (await fetch("/api/annotate/tracks", {
      method: "PUT", headers: {"Authorization": `Bearer ${token}`,
                               "Content-Type": "application/json"},
      body: JSON.stringify({version: 1, tracks: []})})).status""", token)
    assert status == 403
    stored = live_server.worker_get_task(link["token"])["assignment"]
    assert stored["version"] == 1 and stored["tracks"]["tracks"] == _tracks()

    page.set_viewport_size({"width": 1024, "height": 700})
    page.wait_for_timeout(200)
    expect(banner).to_be_visible()
    box = banner.bounding_box()
    assert box is not None and box["x"] >= 0 and box["x"] + box["width"] <= 1024
    page.screenshot(path=str(output_dir / "annotate-readonly-1024.png"))
