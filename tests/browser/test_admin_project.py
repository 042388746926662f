"""Project control on the admin page in a real browser: an admin imports a capture, creates its
tasks and publishes them (the count and cost shown before, the HITs after), the progress grid
follows the API's task states, a worker is blocked and unblocked (the marketplace's own state
checked through its API), a bonus paid shows in costs under the sequence's name, the job table
shows whole results, and no page overflows sideways at 1024 px or clips a column at 1280x720.

The capture is its own (seed 17), imported through the page into the live server's instance
folder; its HITs are expired and the sequence deleted when the module ends, so the other
browser tests see the server as they left it.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Page, expect
from sqlalchemy import create_engine, select

from backend.crowd.simulate import WORKER_EMAIL, WORKER_PASSWORD, simulate
from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, CLIP_FRAMES, LiveServer
from tests.browser.test_admin import (  # noqa: F401  (fixtures)
    admin_page,
    queue_worker,
)

SEED = 17
NAME = f"synth_{SEED:06d}"
REWARD, FEE, HITS = "0.40", "0.08", 4  # one hand and one object, in each of 2 views
BONUS = "0.25"
# The first simulated worker of this module (sim-worker-041): others of the suite start at 1.
FIRST_WORKER = 41
SIZES = ({"width": 1024, "height": 700}, {"width": 1280, "height": 720},
         {"width": 1440, "height": 900})
SETTLE_S = 120.0
OVERFLOW = "() => document.scrollingElement.scrollWidth - window.innerWidth"


@pytest.fixture(scope="module")
def capture(live_server: LiveServer) -> Iterator[Path]:
    """A second capture inside the instance folder (where an HTTP import may read); when the
    module ends, its sequence's HITs are expired and the sequence deleted."""
    from worker.synth import generate_capture

    out = Path(live_server.env["DEXLABEL_VAR_DIR"]) / "captures" / "project"
    generate_capture(out, seed=SEED, frames=CLIP_FRAMES, views=2, objects=1, workers=1)
    yield out
    sequence = _sequence(live_server)
    if sequence is None:
        return
    for hit_id in _hit_ids(live_server, sequence["id"]):
        httpx.post(f"{live_server.base}/api/crowd/hits/{hit_id}/expire", timeout=30,
                   headers={"Authorization": f"Bearer {live_server.admin_token}"})
    httpx.delete(f"{live_server.base}/api/sequences/{sequence['id']}?force=true", timeout=60,
                 headers={"Authorization": f"Bearer {live_server.admin_token}"})


def _sequence(server: LiveServer) -> dict | None:
    listed = server.admin("GET", "/api/sequences?limit=1000")
    return next((s for s in listed if s["name"] == NAME), None)  # type: ignore[union-attr]


def _hit_ids(server: LiveServer, sequence_id: int) -> list[str]:
    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit

    engine = create_engine(server.env["DEXLABEL_DATABASE_URL"])
    with engine.connect() as conn:
        ids = list(conn.scalars(select(CrowdHit.hit_id).join(Task, Task.id == CrowdHit.task_id)
                                .where(Task.sequence_id == sequence_id,
                                       CrowdHit.hit_id.is_not(None),
                                       CrowdHit.expired_at.is_(None))))
    engine.dispose()
    return ids


def _grid_matches_the_api(page: Page, server: LiveServer, sequence_id: int) -> dict:
    """Every cell of the page's grid holds its task's state as the API gives it."""
    progress = server.admin("GET", f"/api/sequences/{sequence_id}/progress")
    assert isinstance(progress, dict)
    cells = page.locator("#progress-grid td[data-task]")
    expect(cells).to_have_count(len(progress["tasks"]))
    for task in progress["tasks"]:
        cell = page.locator(f'#progress-grid td[data-task="{task["task_id"]}"]')
        expect(cell).to_have_attribute("data-state", task["state"])
        expect(cell.locator(".cell-state")).to_have_text(task["state"])
        row = page.locator(f'#progress-grid tr[data-serial="{task["serial"]}"]')
        expect(row.locator(f'td[data-target="{task["target_key"]}"]')).to_have_attribute(
            "data-task", str(task["task_id"]))
    return progress


def _portal_hits(server: LiveServer, index: int) -> list[dict]:
    """The HITs the marketplace offers the simulated worker ``index`` (its portal's API)."""
    login = httpx.post(f"{server.base}/api/portal/login", timeout=30, json={
        "email": WORKER_EMAIL.format(index=index),
        "password": WORKER_PASSWORD.format(index=index)})
    assert login.status_code == 200, login.text
    hits = httpx.get(f"{server.base}/api/portal/hits", timeout=30,
                     headers={"Authorization": f"Bearer {login.json()['access_token']}"})
    assert hits.status_code == 200, hits.text
    return hits.json()


def _settle(server: LiveServer) -> None:
    """Until no job is queued, running or retrying."""
    deadline = time.monotonic() + SETTLE_S
    while time.monotonic() < deadline:
        if not [j for j in server.admin("GET", "/api/jobs?limit=1000")
                if j["status"] in ("queued", "running", "retrying")]:
            return
        time.sleep(0.5)
    raise AssertionError(f"jobs still pending after {SETTLE_S} s")


def _no_overflow(page: Page, what: str) -> None:
    over = page.evaluate(OVERFLOW)
    assert over <= 0, f"{what}: the page scrolls sideways by {over} px"


@pytest.fixture(scope="module")
def project(live_server: LiveServer, capture: Path, queue_worker: None) -> dict:  # noqa: F811
    """Filled in by the tests in order: the sequence, the worker, the work."""
    return {}


def test_import_create_tasks_and_publish_with_the_cost_shown_first(
    admin_page: Page, live_server: LiveServer,  # noqa: F811
    capture: Path, project: dict, output_dir: Path,
) -> None:
    page, server = admin_page, live_server
    # A folder outside the capture roots: refused, and the page says why.
    page.locator("#import-path").fill("/etc")
    page.locator("#import-start").click()
    status = page.locator("#import-status")
    expect(status).to_contain_text(re.compile(r"Import of /etc failed \(403\): .+"))
    expect(status).to_have_class("notice error")

    page.locator("#import-path").fill(str(capture))
    page.locator("#import-start").click()
    expect(status).to_contain_text(f"/{NAME} (#")
    expect(status).to_contain_text("2 views, 12 frames): imported")
    sequence = _sequence(server)
    assert sequence is not None
    sid = sequence["id"]
    project["sequence"] = sequence
    row = page.locator(f'#sequence-rows tr[data-sequence="{sid}"]')
    expect(row.locator(".progress-summary")).to_have_attribute("data-state", "no tasks")
    expect(row.locator(".progress-cell")).to_contain_text("no tasks yet; not solved yet")

    row.locator("a").click()
    expect(page.locator("#no-tasks")).to_be_visible()
    page.locator("#create-tasks").click()
    expect(page.locator("#project-status")).to_have_text(f"Created {HITS} tasks ({HITS} in all).")
    progress = _grid_matches_the_api(page, server, sid)
    assert {t["state"] for t in progress["tasks"]} == {"open"}
    assert len(progress["views"]) == 2 and progress["targets"] == ["hand:0", "object:0"]

    # Bad input: the API's refusal, as a notice; nothing can be published from it.
    page.locator("#publish-reward").fill("1000.01")
    page.locator("#publish-approval").fill("")
    page.locator("#publish-check").click()
    expect(page.locator("#project-status")).to_contain_text(
        re.compile(r"Checking the cost failed \(422\): .*reward"))
    expect(page.locator("#publish-confirm")).to_be_disabled()

    page.locator("#publish-reward").fill(REWARD)
    page.locator("#publish-check").click()
    plan = server.admin("POST", "/api/crowd/publish", {
        "sequence_id": sid, "reward": REWARD, "max_assignments": 1, "min_approval_rate": None,
        "dry_run": True})
    assert isinstance(plan, dict) and plan["cost"]["hits"] == HITS
    total = plan["cost"]["total"]
    assert float(total) == pytest.approx(HITS * (float(REWARD) + float(FEE)))
    cost = page.locator("#publish-cost")
    expect(cost).to_have_text(f"MTurk-compatible marketplace: {HITS} HITs \u00d7 1 assignment "
                              f"at ${REWARD} + ${FEE} fee: rewards ${plan['cost']['rewards']} "
                              f"+ fees ${plan['cost']['fees']} = ${total}")
    confirm = page.locator("#publish-confirm")
    expect(confirm).to_have_text(f"Publish {HITS} HITs for ${total}")
    # Shown before anything is sent: the tasks are still open.
    _grid_matches_the_api(page, server, sid)
    page.screenshot(path=str(output_dir / "admin-project-publish-cost.png"))

    confirm.click()
    expect(page.locator("#project-status")).to_have_text(f"Published {HITS} HITs for ${total}.")
    expect(confirm).to_be_disabled()
    progress = _grid_matches_the_api(page, server, sid)
    assert {t["state"] for t in progress["tasks"]} == {"published"}
    assert progress["hits_live"] == HITS
    page.screenshot(path=str(output_dir / "admin-project-published.png"))


def test_worked_tasks_show_in_the_grid_and_a_worker_is_blocked_then_unblocked(
    admin_page: Page, live_server: LiveServer,  # noqa: F811
    capture: Path, project: dict, output_dir: Path,
) -> None:
    page, server = admin_page, live_server
    sid = project["sequence"]["id"]
    tasks = {t["task_id"] for t in server.admin(
        "GET", f"/api/sequences/{sid}/progress")["tasks"]}  # type: ignore[call-overload]
    [done] = simulate(server.base, capture, 1, "careful", ADMIN_EMAIL, ADMIN_PASSWORD, seed=4,
                      first_index=FIRST_WORKER)
    assert done.status == "submitted" and done.task_id in tasks, done
    server.admin("POST", "/api/crowd/sync")
    _settle(server)
    project["worker"] = worker = done.worker_id
    [ours] = server.admin("GET", f"/api/crowd/workers/{worker}")["assignments"]  # type: ignore[call-overload]
    project["assignment"] = ours["assignment_id"]

    page.goto(f"{server.base}/admin/#/sequences/{sid}")
    progress = _grid_matches_the_api(page, server, sid)
    worked = next(t for t in progress["tasks"] if t["task_id"] == done.task_id)
    assert worked["state"] in ("submitted", "in review", "accepted"), worked
    assert sum(t["state"] == "published" for t in progress["tasks"]) == HITS - 1

    # The worker's record: their numbers as the API gives them.
    stats = server.admin("GET", f"/api/crowd/workers/{worker}")
    assert isinstance(stats, dict)
    page.locator("#nav-workers").click()
    row = page.locator(f'#worker-rows tr[data-worker="{worker}"]')
    expect(row.locator("td").nth(2)).to_have_text(str(stats["submitted"]))
    expect(row.locator("svg.spark")).to_have_attribute("data-points", str(len(stats["history"])))
    minutes, seconds = divmod(round(stats["median_working_time_s"]), 60)
    expect(row.locator("td").nth(6)).to_have_text(f"{minutes} min {seconds:02d} s" if minutes
                                                  else f"{seconds} s")
    row.locator("button[data-open-worker]").click()
    # The provider's worker id, and beside it the portal account's email.
    expect(page.locator("#worker-title")).to_have_text(
        f"{worker} \u00b7 {WORKER_EMAIL.format(index=FIRST_WORKER)}")
    expect(page.locator(f'#worker-assignments tr[data-assignment="{ours["assignment_id"]}"]')) \
        .to_contain_text(project["sequence"]["subject"] + "/" + NAME)
    offered = _portal_hits(server, FIRST_WORKER)
    assert len(offered) >= HITS - 1, offered

    page.locator("#block").click()
    expect(page.locator("#worker-result")).to_have_text(
        "Blocking needs a reason: the worker reads it.")
    page.locator("#block-reason").fill("Labels placed at random in the last batch.")
    page.locator("#block").click()
    expect(page.locator("#worker-confirm-text")).to_contain_text(f"Block {worker}?")
    assert not server.admin("GET", f"/api/crowd/workers/{worker}")["blocked"]  # type: ignore[call-overload]
    page.screenshot(path=str(output_dir / "admin-project-block-confirm.png"))
    page.locator("#worker-confirm-yes").click()
    expect(page.locator("#worker-result")).to_have_text(f"{worker} is blocked.")
    expect(row.locator("td").last).to_have_text("blocked")
    # The marketplace keeps every HIT of ours from the worker now.
    assert _portal_hits(server, FIRST_WORKER) == []
    expect(page.locator("#unblock")).to_be_visible()
    page.locator("#block-reason").fill("")
    page.locator("#unblock").click()
    expect(page.locator("#worker-confirm-text")).to_contain_text(f"Unblock {worker}?")
    page.locator("#worker-confirm-yes").click()
    expect(page.locator("#worker-result")).to_have_text(f"{worker} is unblocked.")
    expect(row.locator("td").last).to_have_text("no")
    assert [h["hit_id"] for h in _portal_hits(server, FIRST_WORKER)] == \
        [h["hit_id"] for h in offered]


def test_a_bonus_paid_shows_in_costs_under_the_sequence_name(
    admin_page: Page, live_server: LiveServer,  # noqa: F811
    project: dict, output_dir: Path,
) -> None:
    page, server = admin_page, live_server
    sequence, worker, aid = project["sequence"], project["worker"], project["assignment"]
    name = f"{sequence['subject']}/{NAME}"
    page.locator("#nav-workers").click()
    page.locator(f'#worker-rows tr[data-worker="{worker}"] button[data-open-worker]').click()
    page.locator("#bonus-assignment").select_option(str(aid))
    page.locator("#bonus-amount").fill(BONUS)
    page.locator("#bonus-reason").fill("Careful work on the occluded frames.")
    page.locator("#bonus").click()
    expect(page.locator("#worker-confirm-text")).to_have_text(
        f"Pay {worker} a bonus of ${BONUS} (plus the marketplace's fee) on assignment {aid}?")
    page.locator("#worker-confirm-yes").click()
    expect(page.locator("#worker-result")).to_contain_text(
        f"Paid {worker} a ${BONUS} bonus (fee $")
    expect(page.locator('[data-fact="Earned"]')).to_contain_text(f"bonuses ${BONUS}")
    page.screenshot(path=str(output_dir / "admin-project-worker.png"))

    costs = server.admin("GET", "/api/crowd/costs")
    assert isinstance(costs, dict)
    line = next(c for c in costs["by_sequence"] if c["key"] == str(sequence["id"]))
    assert line["name"] == name and line["spent_bonuses"] == BONUS
    page.locator("#nav-costs").click()
    row = page.locator(f'#cost-sequence-rows tr[data-sequence="{sequence["id"]}"]')
    expect(row.locator("td").first).to_have_text(name)
    expect(row.locator("td").nth(3)).to_have_text(f"${BONUS}")
    expect(page.locator(f'#cost-worker-rows tr[data-worker="{worker}"] td').nth(3)) \
        .to_have_text(f"${BONUS}")


def test_jobs_filter_by_status_and_kind_and_show_whole_results(
    admin_page: Page, live_server: LiveServer,  # noqa: F811
    project: dict, output_dir: Path,
) -> None:
    page, server = admin_page, live_server
    done = server.admin("GET", "/api/jobs?status=done&kind=qc&limit=1000")
    assert isinstance(done, list) and done
    page.locator("#nav-jobs").click()
    page.locator("#job-kind").select_option("qc")
    page.locator("#job-status").select_option("done")
    rows = page.locator("#job-rows tr[data-job]")
    expect(rows).to_have_count(min(len(done), 200))
    assert set(rows.evaluate_all("rs => rs.map(r => r.dataset.kind + ' ' + r.dataset.status)")) \
        == {"qc done"}
    job = done[0]
    page.locator(f'#job-rows button[data-expand="{job["id"]}"]').click()
    text = page.locator(f'#job-rows tr[data-detail-of="{job["id"]}"] pre')
    expect(text).to_be_visible()
    assert json.loads(text.inner_text()) == job["result"]
    page.screenshot(path=str(output_dir / "admin-project-jobs.png"))
    page.locator(f'#job-rows button[data-expand="{job["id"]}"]').click()
    expect(page.locator("#job-rows tr.job-detail")).to_have_count(0)
    page.locator("#job-status").select_option("failed")
    failed = server.admin("GET", "/api/jobs?status=failed&kind=qc")
    expect(rows).to_have_count(len(failed))  # type: ignore[arg-type]


def test_no_page_overflows_at_1024_and_no_column_is_clipped_at_1280x720(
    admin_page: Page, live_server: LiveServer,  # noqa: F811
    project: dict, output_dir: Path,
) -> None:
    page, server = admin_page, live_server
    sid, worker = project["sequence"]["id"], project["worker"]
    reports = server.admin("GET", f"/api/qc/reports?sequence_id={sid}")
    assert isinstance(reports, list) and reports, "no QC report on the worked task"
    pages = {
        "sequences": "#/sequences", "sequence": f"#/sequences/{sid}",
        "report": f"#/sequences/{sid}/reports/{reports[0]['assignment_id']}",
        "workers": "#/workers", "jobs": "#/jobs", "costs": "#/costs", "queue": "#/queue",
    }
    for size in SIZES:
        page.set_viewport_size(size)
        tag = f"{size['width']}x{size['height']}"
        for name, hash_ in pages.items():
            page.goto(f"{server.base}/admin/{hash_}")
            expect(page.locator(f"#{'sequence' if name in ('sequence', 'report') else name}"
                                "-view")).to_be_visible()
            if name == "sequences":
                expect(page.locator("#sequence-rows .progress-summary")).to_have_count(
                    page.locator("#sequence-rows tr").count())
            if name == "report":
                expect(page.locator("#report-detail")).to_be_visible()
                _action_column_in_view(page)
            if name == "workers":
                page.locator(f'#worker-rows tr[data-worker="{worker}"] '
                             "button[data-open-worker]").click()
                expect(page.locator("#worker-detail")).to_be_visible()
            if name == "jobs":  # one job shown whole (the page keeps it open between visits)
                expect(page.locator("#job-rows tr[data-job]").first).to_be_visible()
                if not page.locator("#job-rows tr.job-detail").count():
                    page.locator("#job-rows button[data-expand]").first.click()
                expect(page.locator("#job-rows tr.job-detail")).to_have_count(1)
            page.wait_for_load_state("networkidle")
            _no_overflow(page, f"{name} at {tag}")
            page.screenshot(path=str(output_dir / f"admin-project-{name}-{tag}.png"),
                            full_page=True)


def _action_column_in_view(page: Page) -> None:
    """The reports table's last column is drawn whole inside its box and the window."""
    action = page.locator("#reports th").last
    expect(action).to_have_text("Action")
    box = action.bounding_box()
    holder = page.locator("#reports").evaluate(
        "t => { const b = t.parentElement.getBoundingClientRect(); "
        "return {right: b.right, "
        "scroll: t.parentElement.scrollWidth - t.parentElement.clientWidth}; }")
    width = page.viewport_size["width"] if page.viewport_size else 0
    assert box is not None and box["x"] + box["width"] <= min(holder["right"], width) + 1, \
        (box, holder)
    assert holder["scroll"] <= 0, f"the reports table scrolls by {holder['scroll']} px"
