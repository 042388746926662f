"""The worker portal's HIT list and task page in Chromium: rows that tell the tasks apart
(target, view, frames and a thumbnail that is the view's first frame), the accepted HIT marked
with a way back to it, and a task frame that fits the window at 1366x768 and 1024x700 with the
annotation page's timeline in view inside it.

The capture is its own (seed 23), imported into the live server's instance folder; its HITs
are expired and its sequence deleted when the module ends, so the other browser tests see the
server as they left it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
from playwright.sync_api import Frame, Page, expect
from sqlalchemy import create_engine, select

from backend.crowd.titles import object_label
from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.helpers import READY

SEED = 23
NAME = f"synth_{SEED:06d}"
EMAIL, PASSWORD = "portal-list-worker@example.org", "portal list worker password"
SIZES = ({"width": 1366, "height": 768}, {"width": 1024, "height": 700})
# The thumbnail as the page drew it, read back from a canvas: width, height and RGBA bytes.
THUMB_PIXELS = """(img) => {
  const c = document.createElement("canvas");
  c.width = img.naturalWidth; c.height = img.naturalHeight;
  const g = c.getContext("2d");
  g.drawImage(img, 0, 0);
  return [c.width, c.height, Array.from(g.getImageData(0, 0, c.width, c.height).data)];
}"""


@pytest.fixture(scope="module")
def sequence(live_server: LiveServer) -> Iterator[dict]:
    """A second capture imported, its tasks created and published: the sequence, its capture
    folder and its HITs (per HIT id: the task's kind, target and view)."""
    from worker.synth import generate_capture

    server = live_server
    out = Path(server.env["DEXLABEL_VAR_DIR"]) / "captures" / "portal-list"
    generate_capture(out, seed=SEED, frames=CLIP_FRAMES, views=2, objects=1, workers=1)
    sid = server.admin("POST", "/api/captures/import", {"path": str(out)})[0]["sequence_id"]
    seq = server.admin("GET", f"/api/sequences/{sid}")
    tasks = server.admin("POST", f"/api/sequences/{sid}/tasks")
    published = server.admin("POST", "/api/crowd/publish", {
        "sequence_id": sid, "max_assignments": 1, "min_approval_rate": None, "reward": "0.45"})
    assert published["created"] == len(tasks) == 4
    side = {h["index"]: h["side"] for h in seq["hands"]}
    names = {o["index"]: object_label(o["name"]) for o in seq["objects"]}
    by_id = {t["id"]: t for t in tasks}
    hits = {}
    for hit_id, task_id in _published(server, sid):
        task = by_id[task_id]
        kind, index = task["target_key"].split(":")
        target = f"{side[int(index)]} hand" if kind == "hand" else names[int(index)]
        assert task["target"] == target
        hits[hit_id] = {"kind": kind, "target": target, "serial": task["serial"],
                        "view_name": f"camera {task['view_number']} of {task['num_views']}"}
    yield {"id": sid, "capture": out, "hits": hits}
    for hit_id in hits:
        httpx.post(f"{server.base}/api/crowd/hits/{hit_id}/expire", timeout=30,
                   headers={"Authorization": f"Bearer {server.admin_token}"})
    httpx.delete(f"{server.base}/api/sequences/{sid}?force=true", timeout=60,
                 headers={"Authorization": f"Bearer {server.admin_token}"})


def _published(server: LiveServer, sequence_id: int) -> list[tuple[str, int]]:
    """(HIT id, task id) of the sequence's published tasks, from the server's database."""
    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit

    engine = create_engine(server.env["DEXLABEL_DATABASE_URL"])
    with engine.connect() as conn:
        rows = conn.execute(select(CrowdHit.hit_id, CrowdHit.task_id)
                            .join(Task, Task.id == CrowdHit.task_id)
                            .where(Task.sequence_id == sequence_id))
        found = [(str(hit_id), int(task_id)) for hit_id, task_id in rows]
    engine.dispose()
    return found


@pytest.fixture
def portal_page(browser) -> Iterator[Page]:
    ctx = browser.new_context(viewport=SIZES[0])
    ctx.set_default_timeout(15000)
    page = ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    yield page
    ctx.close()
    assert not errors, f"uncaught errors in the page: {errors}"


def _first_frame(capture: Path, serial: str, size: tuple[int, int]) -> np.ndarray:
    """The capture's own first frame of the view, RGB, resized to ``size`` (w, h)."""
    path = next(capture.glob(f"*/*/{serial}/color_000000.jpg"))
    image = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA).astype(float)


def _check_rows(page: Page, sequence: dict, output_dir: Path) -> None:
    texts = []
    for hit_id, task in sequence["hits"].items():
        row = page.locator(f'tr[data-hit="{hit_id}"]')
        facts = f"{task['target']} · {task['view_name']} · {CLIP_FRAMES} frames"
        expect(row.locator(".facts")).to_have_text(facts)
        expect(row.locator(".facts")).to_have_attribute("title", f"camera serial {task['serial']}")
        expect(row.locator("a.hit-title")).to_have_text(f"Track the {facts}")
        expect(row).to_contain_text("$0.45")
        texts.append(row.inner_text())
        img = row.locator("img.thumb")
        expect(img).to_have_js_property("complete", True)
        width, height, rgba = img.evaluate(THUMB_PIXELS)
        assert (width, height) == (160, 120)
        drawn = np.array(rgba, dtype=float).reshape(height, width, 4)[..., :3]
        truth = _first_frame(sequence["capture"], task["serial"], (width, height))
        assert drawn.std() > 5, "the thumbnail is blank"
        assert np.abs(drawn - truth).mean() < 4.0  # the view's first frame, JPEG noise aside
    assert len(set(texts)) == len(texts) == 4
    page.screenshot(path=str(output_dir / "portal-list.png"), full_page=True)


def _check_fit(page: Page, output_dir: Path, name: str) -> None:
    """The frame's bottom inside the window; the annotation page's timeline inside the frame."""
    handle = page.wait_for_selector("#work-frame iframe")
    frame = handle.content_frame()
    assert isinstance(frame, Frame)
    frame.wait_for_function(READY)
    page.wait_for_function("""() => {
      const f = document.querySelector('#work-frame iframe').getBoundingClientRect();
      return f.bottom <= innerHeight && f.bottom >= innerHeight - 12 && f.height >= 400;
    }""")
    box = handle.bounding_box()
    assert box is not None
    viewport = page.viewport_size
    assert viewport is not None
    assert box["y"] + box["height"] <= viewport["height"]
    assert box["y"] < 80, "the chrome above the frame takes too much of the window"
    frame.wait_for_function("""() => {
      const t = document.getElementById('timeline').getBoundingClientRect();
      return t.height > 10 && t.top >= 0 && t.bottom <= innerHeight && t.width > 200;
    }""")
    page.screenshot(path=str(output_dir / f"portal-work-{name}.png"))


def test_rows_tell_tasks_apart_and_the_task_frame_fits_the_window(
    live_server: LiveServer, sequence: dict, portal_page: Page, output_dir: Path
) -> None:
    page, server = portal_page, live_server
    server.admin("POST", "/api/portal/workers", {"email": EMAIL, "password": PASSWORD})
    page.goto(f"{server.base}/market/")
    page.locator("#login input[name=email]").fill(EMAIL)
    page.locator("#login input[name=password]").fill(PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#hits-view")).to_be_visible()
    _check_rows(page, sequence, output_dir)

    hand = next(h for h, t in sequence["hits"].items() if t["kind"] == "hand")
    page.locator(f'tr[data-hit="{hand}"] a.hit-title').click()
    expect(page.locator("#preview-view")).to_be_visible()
    page.locator("#accept").click()
    expect(page.locator("#work-view")).to_be_visible()
    assignment = page.url.rsplit("/", 1)[1]
    for size in SIZES:
        page.set_viewport_size(size)
        _check_fit(page, output_dir, f"{size['width']}x{size['height']}")

    page.locator("#nav-hits").click()
    row = page.locator(f'tr[data-hit="{hand}"]')
    expect(row).to_have_attribute("data-mine", "Accepted")
    mark = row.locator(".mark-accepted")
    expect(mark).to_have_text("accepted · continue")
    expect(page.locator(".mark")).to_have_count(1)  # only this worker's one HIT
    page.screenshot(path=str(output_dir / "portal-list-accepted.png"), full_page=True)
    mark.click()
    expect(page.locator("#work-view")).to_be_visible()
    assert page.url.endswith(f"#/work/{assignment}")
    page.wait_for_selector("#work-frame iframe")
