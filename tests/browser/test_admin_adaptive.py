"""Adaptive publishing on the admin page in a real browser: a sequence of 4 views published
with the Views select set to adaptive shows, per target, 3 published views with their reason
and the held one marked, in the progress grid and in the units list, at 1024x700 and
1440x900 without sideways overflow.

The capture is its own (seed 23), imported into the live server's instance folder; its HITs
are expired and the sequence deleted when the module ends, so the other browser tests see the
server as they left it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIP_FRAMES, LiveServer
from tests.browser.test_admin import admin_page  # noqa: F401  (fixture)
from tests.browser.test_admin_project import OVERFLOW, _hit_ids

SEED = 23
NAME = f"synth_{SEED:06d}"
SIZES = ((1024, 700), (1440, 900))
START = "initial: worked first, the hand whole in view (3 of 4 views)"


@pytest.fixture(scope="module")
def sequence_id(live_server: LiveServer) -> Iterator[int]:
    """A 4-view capture with one object, imported with its tasks made; its id. Its HITs are
    expired and the sequence deleted when the module ends."""
    from worker.synth import generate_capture

    out = Path(live_server.env["DEXLABEL_VAR_DIR"]) / "captures" / "adaptive"
    generate_capture(out, seed=SEED, frames=CLIP_FRAMES, views=4, objects=1, workers=1)
    imported = live_server.admin("POST", "/api/captures/import", {"path": str(out)})
    seq = next(r["sequence_id"] for r in imported if r["name"] == NAME)  # type: ignore[index]
    live_server.admin("POST", f"/api/sequences/{seq}/tasks")
    yield seq
    auth = {"Authorization": f"Bearer {live_server.admin_token}"}
    for hit_id in _hit_ids(live_server, seq):
        httpx.post(f"{live_server.base}/api/crowd/hits/{hit_id}/expire", timeout=30, headers=auth)
    httpx.delete(f"{live_server.base}/api/sequences/{seq}?force=true", timeout=60, headers=auth)


def test_adaptive_publish_shows_why_each_view_was_published_and_which_wait(
    admin_page: Page, live_server: LiveServer, sequence_id: int, output_dir: Path,  # noqa: F811
) -> None:
    page = admin_page
    page.goto(f"{live_server.base}/admin/#/sequences/{sequence_id}")
    expect(page.locator("#progress-grid td.cell")).to_have_count(8)
    page.select_option("#publish-policy", "adaptive")
    page.locator("#publish-approval").fill("")
    page.click("#publish-check")
    expect(page.locator("#publish-cost")).to_contain_text("6 HITs")
    page.click("#publish-confirm")
    expect(page.locator("#project-status")).to_contain_text("Published 6 HITs")

    held = page.locator("#progress-grid td.cell.held")
    expect(held).to_have_count(2)
    # The hand starts from the view its depth shows whole and farthest (published first);
    # the object from its widest pair.
    for target, widest, start in (("hand:0", 2, 1), ("object:0", 3, 0)):
        cells = page.locator(f"#progress-grid td.cell[data-target='{target}']")
        expect(cells.locator(".cell-reason", has_text="initial: widest baselines (3 of 4 views)")
               ).to_have_count(widest)
        expect(cells.locator(".cell-reason", has_text=START)).to_have_count(start)
        expect(cells.and_(held)).to_have_count(1)
    expect(held.first.locator(".cell-state")).to_have_text("held back")
    expect(page.locator("#progress-summary")).to_contain_text("2 held back")
    progress = live_server.admin("GET", f"/api/sequences/{sequence_id}/progress")
    assert progress["publish_policy"] == "adaptive" and progress["held"] == 2  # type: ignore[index]
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        page.locator("#progress-panel").scroll_into_view_if_needed()
        assert page.evaluate(OVERFLOW) <= 0, width
        page.screenshot(path=str(output_dir / f"admin-adaptive-grid-{width}x{height}.png"))

    page.goto(f"{live_server.base}/admin/#/crowd/{sequence_id}")
    reasons = page.locator(".unit-reason")
    expect(reasons).to_have_count(6)
    expect(reasons.filter(has_text="initial: widest baselines (3 of 4 views)")).to_have_count(5)
    expect(reasons.filter(has_text=START)).to_have_count(1)
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        page.screenshot(path=str(output_dir / f"admin-adaptive-units-{width}x{height}.png"))
