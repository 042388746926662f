"""The admin page's export: an admin signs in, exports a sequence and the project, sees the
job's progress and gets the archive, at the smallest and a common laptop window size."""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from playwright.sync_api import Page, expect
from sqlalchemy import create_engine, update

from backend.annotation.models import Assignment
from tests.browser.conftest import LiveServer
from tests.browser.test_admin import (  # noqa: F401  (fixtures)
    _submit,
    admin_page,
    queue_worker,
)

SIZES = ({"width": 1024, "height": 700}, {"width": 1440, "height": 900})
# The export job runs on the suite's one queue consumer, possibly behind QC and solve jobs of
# the other admin tests: its archive may take a while on a busy machine.
DOWNLOAD_MS = 180_000


@pytest.fixture(scope="module")
def accepted(live_server: LiveServer, queue_worker: None) -> list[int]:  # noqa: F811
    """Two careful workers' submitted hand labels, accepted as an approval leaves them (set in
    the database: direct-link work has no marketplace submission for the approve route to
    confirm, and the export does not depend on how work was accepted); their ids."""
    server = live_server
    rng = np.random.default_rng(23)
    ids = [_submit(server, server.task("hand", view), f"EXPORT-W{view}", "careful", rng)
           for view in (0, 1)]
    engine = create_engine(server.env["DEXLABEL_DATABASE_URL"])
    with engine.begin() as conn:
        conn.execute(update(Assignment).where(Assignment.id.in_(ids)).values(status="approved"))
    engine.dispose()
    return ids


def _fits(page: Page, selector: str) -> None:
    """The element is drawn whole inside the window, not clipped by its box."""
    box = page.locator(selector).bounding_box()
    assert box is not None, selector
    width = page.viewport_size["width"] if page.viewport_size else 0
    assert box["x"] >= 0 and box["x"] + box["width"] <= width, (selector, box)
    clipped = page.locator(selector).evaluate(
        "e => e.scrollWidth > e.clientWidth + 1 || e.scrollHeight > e.clientHeight + 1")
    assert not clipped, selector


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s['width']}x{s['height']}")
def test_admin_exports_a_sequence_and_the_project_and_gets_each_archive(
    admin_page: Page, live_server: LiveServer, accepted: list[int], output_dir: Path,  # noqa: F811
    size: dict[str, int],
) -> None:
    page, server = admin_page, live_server
    page.set_viewport_size(size)
    name = f"{size['width']}x{size['height']}"
    expect(page.locator("#export-format")).to_have_value("dexycb")
    # This test's sequence (other browser tests of the session may have added theirs).
    row = f"#sequence-rows button[data-export='{server.sequence_id}']"
    for selector in ("#export-format", "#export-project", row):
        _fits(page, selector)
    page.screenshot(path=str(output_dir / f"admin-export-{name}-before.png"))
    page.locator("#export-format").select_option("json")
    status = page.locator("#export-status")
    row_button = page.locator(row)
    with page.expect_download(timeout=DOWNLOAD_MS) as download_info:
        row_button.click()
        # The job's state is drawn while it runs (queued, running, then views done).
        expect(status).to_contain_text(f"json export of sequence #{server.sequence_id}")
    download = download_info.value
    assert download.suggested_filename == f"dexlabel-json-{server.sequence_id}.zip"
    expect(status).to_contain_text(
        re.compile(rf"done, saved dexlabel-json-{server.sequence_id}\.zip \(\d+ kB\)"))
    expect(page.locator("#sequences-view th").last).to_have_text("Export labels")
    _fits(page, "#export-status")
    page.screenshot(path=str(output_dir / f"admin-export-{name}-sequence-done.png"))
    with zipfile.ZipFile(download.path()) as archive:
        [member] = archive.namelist()
        document = json.loads(archive.read(member))
    assert document["sequence"]["id"] == server.sequence_id
    assert {w["assignment_id"] for w in document["work"]} >= set(accepted)

    page.locator("#export-format").select_option("cvat")
    with page.expect_download(timeout=DOWNLOAD_MS) as download_info:
        page.locator("#export-project").click()
        expect(status).to_contain_text("cvat export of project")
    download = download_info.value
    assert download.suggested_filename == "dexlabel-cvat-project.zip"
    expect(status).to_contain_text("cvat export of project: done, saved "
                                   "dexlabel-cvat-project.zip")
    # One document per view of each sequence: this test's 2 views under its own folder.
    folder = f"{document['sequence']['subject']}/{document['sequence']['name']}/"
    with zipfile.ZipFile(download.path()) as archive:
        assert len([n for n in archive.namelist()
                    if n.startswith(folder) and n.endswith(".xml")]) == 2
    expect(page.locator("#notice")).to_be_hidden()
    for selector in ("#export-project", "#export-format"):
        _fits(page, selector)
        assert page.locator(selector).bounding_box()["height"] < 40, selector  # one line
    page.screenshot(path=str(output_dir / f"admin-export-{name}-project-done.png"),
                    full_page=True)
