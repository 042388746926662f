"""The admins' review page in a real browser: QC reports of real submitted work, a report's
charts, an admin's approval that pays, the API's refusals shown, worker quality, the job table,
costs and a solve run's overlays.

Work comes in two ways. Direct assignment links (no marketplace) for three workers, two careful
ones on the two views of the hand and a spammer, with tracks saved and submitted as the
annotation page does. Then the sequence's tasks published on the built-in marketplace and
worked through the portal by simulated careful workers (backend.crowd.simulate). Submissions
queue confirm and QC jobs, which a queue consumer (``dexlabel worker`` on the live server's
database and queue) runs.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from backend.captures.truth import CaptureTruth
from backend.crowd.simulate import WORKER_PASSWORD, simulate
from tests.browser.conftest import ADMIN_EMAIL, ADMIN_PASSWORD, LiveServer
from tests.browser.helpers import queue_worker as consumer
from tests.browser.helpers import wait_overlay_shows
from worker.synth.annotators import annotate

QC_TIMEOUT_S = 120.0
# (worker, view of the hand task, simulated profile): two careful views agree with each other;
# the spammer's random points cannot.
CROWD = (("ADMIN-W1", 0, "careful"), ("ADMIN-W2", 1, "careful"), ("ADMIN-W3", 0, "spammer"))
# One simulated marketplace worker per task of the capture (a hand and an object in 2 views).
MARKET_WORKERS = 4
REWARD, FEE = 0.40, 0.08  # the HITs' reward and MTurk's 20% fee on it (dollars)


@pytest.fixture(scope="module")
def queue_worker(live_server: LiveServer, output_dir: Path) -> Iterator[None]:
    """A queue consumer on the live server's database and queue (confirm, QC, solve jobs)."""
    with consumer(live_server, output_dir / "admin-worker.log"):
        yield


def _submit(server: LiveServer, task: dict, worker: str, profile: str,
            rng: np.random.Generator) -> int:
    """One worker's whole assignment through the annotation API; the assignment id."""
    link = server.assign(task, worker)
    auth = {"Authorization": f"Bearer {link['token']}"}
    reply = server.worker_get_task(link["token"])
    xy, visible = CaptureTruth(server.capture).points(reply["task"], rng)
    work = annotate(xy, visible, (task["width"], task["height"]), profile, rng)
    body = {"version": reply["assignment"]["version"], "edit_count": 30, "working_time_s": 120.0,
            "tracks": [{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]}
    saved = httpx.put(f"{server.base}/api/annotate/tracks", json=body, headers=auth, timeout=30)
    assert saved.status_code == 200, saved.text
    body["version"] = saved.json()["version"]
    done = httpx.post(f"{server.base}/api/annotate/submit", json=body, headers=auth, timeout=30)
    assert done.status_code == 200, done.text
    assert done.json()["status"] == "submitted"
    return int(link["assignment_id"])


def _wait_qc_done(server: LiveServer, key: str) -> dict:
    deadline = time.monotonic() + QC_TIMEOUT_S
    job: dict = {}
    while time.monotonic() < deadline:
        job = next((j for j in server.admin("GET", "/api/jobs?kind=qc") if j["key"] == key), {})
        if job.get("status") in ("done", "failed"):
            break
        time.sleep(0.5)
    assert job.get("status") == "done", f"the QC job did not finish: {job}"
    return job


@pytest.fixture(scope="module")
def qc_work(live_server: LiveServer, queue_worker: None) -> dict[str, int]:
    """Submitted, QC-scored work of the hand; worker id -> assignment id."""
    server = live_server
    rng = np.random.default_rng(11)
    ids = {worker: _submit(server, server.task("hand", view), worker, profile, rng)
           for worker, view, profile in CROWD}
    server.admin("POST", "/api/qc/runs", {"sequence_id": server.sequence_id,
                                          "target_key": "hand:0"})
    _wait_qc_done(server, f"qc:{server.sequence_id}:hand:0")
    return ids


@pytest.fixture
def admin_page(page: Page, live_server: LiveServer) -> Page:
    """The review page, signed in."""
    page.goto(f"{live_server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill(ADMIN_PASSWORD)
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#sequences-view")).to_be_visible()
    return page


def test_sign_in_refuses_a_wrong_password(page: Page, live_server: LiveServer) -> None:
    page.goto(f"{live_server.base}/admin/")
    page.locator("#login input[name=email]").fill(ADMIN_EMAIL)
    page.locator("#login input[name=password]").fill("not the password")
    page.locator("#login button[type=submit]").click()
    expect(page.locator("#notice")).to_have_class("notice error")
    expect(page.locator("#notice")).not_to_be_empty()
    expect(page.locator("#login-view")).to_be_visible()
    assert page.evaluate("sessionStorage.getItem('dexlabel.admin.token')") is None


def test_reports_table_shows_each_outcome_waiting_work_first(
    admin_page: Page, live_server: LiveServer, qc_work: dict[str, int], output_dir: Path
) -> None:
    page, server = admin_page, live_server
    reports = server.admin("GET", f"/api/qc/reports?sequence_id={server.sequence_id}")
    ours = {r["assignment_id"]: r for r in reports if r["assignment_id"] in qc_work.values()}
    assert len(ours) == len(CROWD)
    spammer, careful = ours[qc_work["ADMIN-W3"]], ours[qc_work["ADMIN-W1"]]
    # Two views: no point has the three views a consensus needs, so every verdict is
    # provisional and says so; the spammer's random points are still caught by their own
    # track (they jump about), and careful work passes.
    for report in ours.values():
        assert report["provisional"], report
        assert "provisional: fewer than 3 camera views to compare with" in report["reasons"]
        assert report["metrics"]["median_error_px"] is None
    # This 12-frame clip is a grasp 6 times faster than at 30 fps: a careful track that follows
    # every bend shakes by ~35 px/frame^2 there, beyond track_jitter_px's review bound, and with
    # two views no other view gives the motion's own shake to compare with. Careful work may
    # be sent to review for it, never rejected.
    assert spammer["outcome"] in ("review", "reject") and careful["outcome"] != "reject"
    assert any(r.startswith("track_jitter_px") for r in spammer["reasons"]), spammer

    page.locator(f'#sequence-rows tr[data-sequence="{server.sequence_id}"] a').click()
    expect(page.locator("#sequence-view")).to_be_visible()
    rows = page.locator("#report-rows tr")
    expect(rows).to_have_count(len(reports))
    for aid, report in ours.items():
        row = page.locator(f'#report-rows tr[data-assignment="{aid}"]')
        expect(row).to_have_attribute("data-outcome", report["outcome"])
        expect(row).to_contain_text(report["worker_id"])
        median = report["metrics"]["median_error_px"]
        unknown = "\u2013"  # the page's en dash for a value it does not have
        expect(row.locator("td").nth(6)).to_have_text(
            unknown if median is None else f"{median:.1f} px")
    waiting = [r["assignment_id"] for r in reports if r["outcome"] == "review" and not r["action"]]
    shown = [int(a) for a in rows.evaluate_all("rs => rs.map(r => r.dataset.assignment)")]
    assert sorted(shown[:len(waiting)]) == sorted(waiting)
    assert sorted(shown) == sorted(r["assignment_id"] for r in reports)

    runs = server.admin("GET", f"/api/sequences/{server.sequence_id}/solve-runs")
    expect(page.locator("#run-rows tr")).to_have_count(len(runs))
    if not runs:
        expect(page.locator("#no-runs")).to_be_visible()

    page.locator("#outcome-filter").select_option(spammer["outcome"])
    same = [r for r in reports if r["outcome"] == spammer["outcome"]]
    expect(rows).to_have_count(len(same))
    expect(page.locator(f'#report-rows tr[data-assignment="{spammer["assignment_id"]}"]')) \
        .to_be_visible()
    page.screenshot(path=str(output_dir / "admin-reports.png"))


def test_report_detail_draws_per_joint_errors_and_shows_a_refused_decision(
    admin_page: Page, live_server: LiveServer, qc_work: dict[str, int], output_dir: Path
) -> None:
    page, server = admin_page, live_server
    aid = qc_work["ADMIN-W3"]
    detail = server.admin("GET", f"/api/qc/reports/{aid}")
    page.goto(f"{server.base}/admin/#/sequences/{server.sequence_id}/reports/{aid}")
    panel = page.locator("#report-detail")
    expect(panel).to_be_visible()
    selected = page.locator(f'#report-rows tr[data-assignment="{aid}"]')
    expect(selected).to_have_class(re.compile(r"\bselected\b"))
    waits = detail["outcome"] == "review" and not detail["action"]
    expect(selected).to_have_class(re.compile(r"\bwaiting\b" if waits else r"^(?!.*waiting)"))

    bars = page.locator('#joint-chart svg[data-chart="per-joint"] rect')
    expect(bars).to_have_count(21)
    labels = bars.evaluate_all("rs => rs.map(r => r.dataset.label)")
    assert labels[0] == "wrist" and labels[1] == "thumb_mcp" and labels[20] == "little_tip"
    heights = bars.evaluate_all("rs => rs.map(r => Number(r.getAttribute('height')))")
    known = [(h, v) for h, v in zip(heights, detail["per_joint"], strict=True) if v is not None]
    if known:  # the tallest bar is the largest error, the others in proportion
        tallest = max(known, key=lambda hv: hv[1])
        assert tallest[0] == pytest.approx(140.0) and all(h <= 140.0 for h, _ in known)
    else:  # two views: no joint has a consensus to be measured against, every bar a stub
        assert len(set(heights)) == 1 and heights[0] < 5, heights
    expect(page.locator('#frame-chart svg[data-chart="per-frame"] rect')) \
        .to_have_count(len(detail["per_frame"]))
    median = detail["metrics"]["median_error_px"]
    expect(page.locator('[data-fact="median_error_px"] .value')) \
        .to_have_text(re.compile(("\u2013" if median is None else rf"{median:.1f} px") + "$"))
    # Under its readable name, with what it measures as the tooltip.
    expect(page.locator('#detail-facts dt[title]').filter(has_text="Median error")).to_have_count(1)
    expect(page.locator("#decision-feedback")).to_have_value(detail["feedback"])
    page.screenshot(path=str(output_dir / "admin-report.png"))

    # Work from a direct link has no marketplace submission: the API refuses to pay for it,
    # and the page says why.
    page.locator("#approve").click()
    result = page.locator("#decision-result")
    expect(result).to_contain_text(f"assignment {aid} has no submission confirmed by the "
                                   "marketplace")
    expect(result).to_have_class("notice error")
    assert server.admin("GET", f"/api/qc/reports/{aid}")["action"] == detail["action"]

    page.locator("#decision-feedback").fill("")
    page.locator("#reject").click()
    expect(result).to_contain_text("A rejection needs feedback")


def test_jobs_workers_and_costs_panels_show_the_api_state(
    admin_page: Page, live_server: LiveServer, qc_work: dict[str, int], output_dir: Path
) -> None:
    page, server = admin_page, live_server
    job = next(j for j in server.admin("GET", "/api/jobs?kind=qc")
               if j["key"] == f"qc:{server.sequence_id}:hand:0")
    page.locator("#nav-jobs").click()
    row = page.locator(f'#job-rows tr[data-job="{job["id"]}"]')
    expect(row).to_have_attribute("data-status", "done")
    expect(row).to_contain_text(job["key"])
    expect(row.locator("button[data-retry]")).to_have_count(0)
    # The job's result in the API's one line ("qc: hand:0 scored 3: 2 approve, ..."), drawn.
    assert job["message"].startswith("qc: hand:0 scored "), job
    line = row.locator(".outcome-line")
    expect(line).to_have_text(job["message"])
    assert line.evaluate("e => e.getBoundingClientRect().height") > 0
    page.screenshot(path=str(output_dir / "admin-jobs.png"))
    # On a narrow screen the Action column stays in view; each outcome stays one sentence.
    page.set_viewport_size({"width": 1024, "height": 700})
    action = page.locator("#jobs th").last
    expect(action).to_have_text("Action")
    box = action.bounding_box()
    assert box is not None and box["x"] + box["width"] <= 1024, box
    lines = page.locator("#job-rows .outcome-line").all_inner_texts()
    assert lines and all(text.strip() and "\n" not in text for text in lines), lines
    page.screenshot(path=str(output_dir / "admin-jobs-1024.png"))
    page.set_viewport_size({"width": 1440, "height": 900})

    quality = {w["worker_id"]: w for w in server.admin("GET", "/api/qc/workers")}
    page.locator("#nav-workers").click()
    for worker in qc_work:
        if worker in quality:
            expect(page.locator(f'#worker-rows tr[data-worker="{worker}"]')).to_contain_text(
                f"{quality[worker]['score'] * 100:.1f}%")
    expect(page.locator("#worker-rows tr")).to_have_count(len(quality))

    costs = server.admin("GET", "/api/crowd/costs")
    page.locator("#nav-costs").click()
    expect(page.locator("#cost-spent")).to_contain_text(f"${float(costs['total']['spent']):.2f}")
    expect(page.locator("#cost-committed")).to_contain_text(
        f"${float(costs['total']['committed']):.2f}")
    expect(page.locator("#cost-head-sequence th")).to_have_count(9)
    expect(page.locator("#cost-sequence-rows tr")).to_have_count(len(costs["by_sequence"]))
    expect(page.locator("#cost-worker-rows tr")).to_have_count(len(costs["by_worker"]))
    page.screenshot(path=str(output_dir / "admin-costs.png"))


def test_an_expired_session_shows_the_sign_in_form_again(
    admin_page: Page, live_server: LiveServer
) -> None:
    page = admin_page
    page.evaluate("sessionStorage.setItem('dexlabel.admin.token', 'not-a-valid-token')")
    page.reload()
    expect(page.locator("#login-view")).to_be_visible()
    expect(page.locator("#notice")).to_contain_text("sign in again")
    assert page.evaluate("sessionStorage.getItem('dexlabel.admin.token')") is None



@pytest.fixture(scope="module")
def market_work(live_server: LiveServer, qc_work: dict[str, int]) -> dict[str, str]:
    """The sequence's tasks published on the built-in marketplace and worked by simulated
    careful workers through the portal; their submissions confirmed and QC-scored.
    Marketplace worker id -> the worker's portal email."""
    server = live_server
    server.admin("POST", "/api/crowd/publish", {
        "sequence_id": server.sequence_id, "max_assignments": 1, "min_approval_rate": None,
        "reward": f"{REWARD:.2f}"})
    outcomes = simulate(server.base, server.capture, MARKET_WORKERS, "careful", ADMIN_EMAIL,
                        ADMIN_PASSWORD, seed=3)
    workers = {o.worker_id: o.email for o in outcomes if o.status == "submitted"}
    assert len(workers) == MARKET_WORKERS, outcomes
    _wait_reports(server, set(workers))
    return workers


def _wait_reports(server: LiveServer, workers: set[str]) -> None:
    """Until every worker's submission is confirmed and QC-scored and no job is pending."""
    deadline = time.monotonic() + QC_TIMEOUT_S
    while time.monotonic() < deadline:
        scored = {r["worker_id"] for r in server.admin(
            "GET", f"/api/qc/reports?sequence_id={server.sequence_id}")}
        busy = [j for j in server.admin("GET", "/api/jobs")
                if j["status"] in ("queued", "running", "retrying")]
        if workers <= scored and not busy:
            return
        time.sleep(0.5)
    raise AssertionError(f"no QC reports for {workers - scored} in {QC_TIMEOUT_S} s")



def _api_approve(server: LiveServer, assignment_id: int) -> httpx.Response:
    return httpx.post(f"{server.base}/api/crowd/assignments/{assignment_id}/approve", json={},
                      headers={"Authorization": f"Bearer {server.admin_token}"}, timeout=30)


def test_admin_approves_marketplace_work_left_for_review_and_it_is_paid(
    admin_page: Page, live_server: LiveServer, market_work: dict[str, str], output_dir: Path
) -> None:
    page, server = admin_page, live_server
    reports = server.admin("GET", f"/api/qc/reports?sequence_id={server.sequence_id}")
    waiting = [r for r in reports if r["worker_id"] in market_work
               and r["outcome"] == "review" and not r["action"] and not r["provisional"]]
    assert waiting, f"no marketplace work left for review: {reports}"
    report = waiting[0]
    aid, before = report["assignment_id"], server.admin("GET", "/api/crowd/costs")["total"]

    page.locator(f'#sequence-rows tr[data-sequence="{server.sequence_id}"] a').click()
    page.locator("#outcome-filter").select_option("review")
    row = page.locator(f'#report-rows tr[data-assignment="{aid}"]')
    expect(row).to_have_class(re.compile(r"\bwaiting\b"))
    expect(row).to_contain_text("waiting for you")
    row.locator("a").click()
    expect(page.locator("#detail-title")).to_have_text(f"Assignment {aid}")
    expect(page.locator("#joint-chart rect")).to_have_count(2)
    expect(page.locator("#joint-chart rect").first).to_have_attribute("data-label", "landmark_1")
    feedback = page.locator("#decision-feedback")
    expect(feedback).to_have_value(report["feedback"])
    note = "Checked by hand: both landmarks sit on the object."
    feedback.fill(note)
    page.locator("#approve").click()
    result = page.locator("#decision-result")
    expect(result).to_have_text(f"Approved assignment {aid}.")
    page.screenshot(path=str(output_dir / "admin-approved.png"))

    # The API holds the decision: a second approval is refused, and the reward and its fee
    # moved from committed to spent.
    again = _api_approve(server, aid)
    assert again.status_code == 409 and again.json()["detail"] == \
        f"assignment {aid} is already approved"
    after = server.admin("GET", "/api/crowd/costs")
    total = after["total"]
    assert float(total["spent"]) == pytest.approx(float(before["spent"]) + REWARD + FEE)
    assert float(total["committed"]) == pytest.approx(float(before["committed"]) - REWARD - FEE)
    line = next(w for w in after["by_worker"] if w["key"] == report["worker_id"])
    assert float(line["spent_rewards"]) == pytest.approx(REWARD)
    assert _portal_feedback(server, market_work[report["worker_id"]]) == [note]

    # The page shows the API's refusal of a second decision, and the new spend.
    page.locator("#approve").click()
    expect(result).to_have_text(f"assignment {aid} is already approved")
    expect(result).to_have_class("notice error")
    page.locator("#nav-costs").click()
    expect(page.locator("#cost-spent")).to_contain_text(f"${float(total['spent']):.2f}")
    expect(page.locator(f'#cost-worker-rows tr[data-worker="{report["worker_id"]}"] td')
           .nth(2)).to_have_text(f"${REWARD:.2f}")
    page.screenshot(path=str(output_dir / "admin-costs-after.png"))




def test_admin_rejects_marketplace_work_with_edited_feedback_and_nothing_is_spent(
    admin_page: Page, live_server: LiveServer, market_work: dict[str, str]
) -> None:
    page, server = admin_page, live_server
    decided = {p["key"] for p in server.admin("GET", "/api/crowd/costs")["by_worker"]
               if float(p["spent"]) > 0}
    reports = server.admin("GET", f"/api/qc/reports?sequence_id={server.sequence_id}")
    report = next(r for r in reports if r["worker_id"] in set(market_work) - decided
                  and not r["action"])
    aid, before = report["assignment_id"], server.admin("GET", "/api/crowd/costs")["total"]
    page.goto(f"{server.base}/admin/#/sequences/{server.sequence_id}/reports/{aid}")
    expect(page.locator("#detail-title")).to_have_text(f"Assignment {aid}")
    why = "The index tip drifts off the finger in the last frames; please recheck them."
    page.locator("#decision-feedback").fill(why)
    page.locator("#reject").click()
    # Asked first, with the feedback the worker will read; nothing sent before Reject.
    expect(page.locator("#decision-confirm-detail")).to_have_text(why)
    assert server.admin("GET", f"/api/qc/reports/{aid}")["action"] is None
    page.locator("#decision-confirm-yes").click()
    expect(page.locator("#decision-result")).to_have_text(f"Rejected assignment {aid}.")

    again = httpx.post(f"{server.base}/api/crowd/assignments/{aid}/reject", json={"feedback": "x"},
                       headers={"Authorization": f"Bearer {server.admin_token}"}, timeout=30)
    assert again.status_code == 409 and again.json()["detail"] == \
        f"assignment {aid} is already rejected"
    total = server.admin("GET", "/api/crowd/costs")["total"]
    assert total["spent"] == before["spent"]
    assert float(total["committed"]) == pytest.approx(float(before["committed"]) - REWARD - FEE)
    # The worker reads the admin's words in the portal.
    assert _portal_feedback(server, market_work[report["worker_id"]]) == [why]

def _portal_feedback(server: LiveServer, email: str) -> list[str | None]:
    """The feedback on each of the worker's assignments, as the portal shows it."""
    index = int(email.split("@")[0].rsplit("-", 1)[1])
    login = httpx.post(f"{server.base}/api/portal/login", timeout=30, json={
        "email": email, "password": WORKER_PASSWORD.format(index=index)})
    assert login.status_code == 200, login.text
    mine = httpx.get(f"{server.base}/api/portal/assignments", timeout=30,
                     headers={"Authorization": f"Bearer {login.json()['access_token']}"})
    assert mine.status_code == 200, mine.text
    return [a["feedback"] for a in mine.json()["assignments"]]


def _solved_run(server: LiveServer, market_work: dict[str, str]) -> dict:
    """Every marketplace submission approved (admin decisions), then a finished solve run."""
    for report in server.admin("GET", f"/api/qc/reports?sequence_id={server.sequence_id}"):
        if report["worker_id"] in market_work:
            assert _api_approve(server, report["assignment_id"]).status_code in (200, 409)
    run = server.admin("POST", f"/api/sequences/{server.sequence_id}/solve", {})
    deadline = time.monotonic() + QC_TIMEOUT_S
    while run["status"] not in ("done", "failed") and time.monotonic() < deadline:
        time.sleep(0.5)
        run = server.admin("GET", f"/api/solve-runs/{run['id']}")
    assert run["status"] == "done", run
    return run


def test_a_finished_solve_run_shows_its_overlay_per_frame_and_view(
    admin_page: Page, live_server: LiveServer, market_work: dict[str, str], output_dir: Path
) -> None:
    page, server = admin_page, live_server
    run = _solved_run(server, market_work)
    page.goto(f"{server.base}/admin/#/sequences/{server.sequence_id}")
    row = page.locator(f'#run-rows tr[data-run="{run["id"]}"]')
    expect(row).to_contain_text("done")
    row.locator("button[data-show-run]").click()
    image = page.locator("#overlay-image")
    expect(image).to_have_attribute("src", re.compile(r"^blob:"))
    expect(page.locator("#overlay-view option")).to_have_count(run["num_views"])

    # A frame with a solved hand when there is one (how many depends on the work the other
    # admin tests accepted or rejected), and the last frame in the last view.
    frames = [server.admin("GET", f"/api/solve-runs/{run['id']}/frames/{f}")
              for f in range(run["num_frames"])]
    with_hand = [f["frame"] for f in frames if isinstance(f, dict) and f["hand_joints"]]
    hands = 0
    for frame, view in ((with_hand[0] if with_hand else 0, "0"),
                        (run["num_frames"] - 1, str(run["num_views"] - 1))):
        page.locator("#overlay-frame").fill(str(frame))  # the frame slider
        expect(page.locator("#solve-frame-label")).to_have_text(
            f"Frame {frame} of {run['num_frames'] - 1}")
        page.locator("#overlay-view").select_option(view)
        png = httpx.get(f"{server.base}/api/solve-runs/{run['id']}/frames/{frame}/views/{view}.png",
                        headers={"Authorization": f"Bearer {server.admin_token}"}, timeout=30)
        assert png.status_code == 200
        # The picture shown is the API's PNG of this frame and view, byte for byte.
        wait_overlay_shows(page, png.content)
        hands += _meshes_drawn_where_the_solve_puts_them(server, run, frame, int(view),
                                                         png.content)
    assert hands >= 1 or not with_hand, "the frame with a solved hand was not checked"
    page.screenshot(path=str(output_dir / "admin-overlay.png"), full_page=True)


def _meshes_drawn_where_the_solve_puts_them(server: LiveServer, run: dict, frame: int,
                                            view: int, overlay: bytes) -> int:
    """The overlay's drawn pixels (where it differs from the darkened colour frame) cover the
    solved hand's joints and each object's origin, projected through the view's own camera
    (lens distortion included), and not the whole picture; 1 when the frame has a solved hand
    (a frame the solve left unlabelled has none to draw), else 0."""
    import cv2

    from worker.overlay import DARKEN

    auth = {"Authorization": f"Bearer {server.admin_token}"}
    sequence = server.admin("GET", f"/api/sequences/{server.sequence_id}")
    assert isinstance(sequence, dict)
    cam = next(c for c in sequence["cameras"] if c["view_index"] == view)
    raw = httpx.get(f"{server.base}/api/sequences/{server.sequence_id}/views/{cam['serial']}"
                    f"/frames/{frame}.jpg", headers=auth, timeout=30)
    assert raw.status_code == 200
    image = cv2.imdecode(np.frombuffer(raw.content, np.uint8), cv2.IMREAD_COLOR)
    shown = cv2.imdecode(np.frombuffer(overlay, np.uint8), cv2.IMREAD_COLOR)
    assert shown.shape == image.shape
    drawn = np.abs(shown.astype(np.float32) - image.astype(np.float32) * DARKEN).max(axis=2) > 25
    assert 0.002 < drawn.mean() < 0.6, drawn.mean()
    near = cv2.dilate(drawn.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0  # within 4 px
    solved = server.admin("GET", f"/api/solve-runs/{run['id']}/frames/{frame}")
    assert isinstance(solved, dict)
    c2w = np.asarray(cam["extrinsics"], dtype=np.float64)
    K = np.array([[cam["fx"], 0, cam["ppx"]], [0, cam["fy"], cam["ppy"]], [0, 0, 1]])

    def project(world: np.ndarray) -> np.ndarray:
        in_cam = (world - c2w[:, 3]) @ c2w[:, :3]  # world -> camera (inverse of c2w)
        uv, _ = cv2.projectPoints(in_cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                                  np.asarray(cam["distortion"], dtype=np.float64))
        return uv.reshape(-1, 2)

    def on_drawn(uv: np.ndarray) -> np.ndarray:
        h, w = drawn.shape
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        px = np.round(uv[inside]).astype(int).clip(0, [w - 1, h - 1])
        return near[px[:, 1], px[:, 0]]

    for obj in solved["objects"]:
        assert obj["pose"] is not None, obj
        origin = on_drawn(project(np.asarray(obj["pose"], dtype=np.float64)[:, 3][None]))
        assert origin.all(), obj
    if solved["hand_joints"] is None:
        assert solved["reason"], solved
        return 0
    joints = on_drawn(project(np.asarray(solved["hand_joints"], dtype=np.float64)))
    assert len(joints) >= 10 and joints.mean() >= 0.8, joints
    return 1


def test_sequence_and_worker_listings_page_through_the_api(
    admin_page: Page, live_server: LiveServer, output_dir: Path
) -> None:
    """One page: no pager. An address past the last page: a way back, nothing else. The
    rows drawn are the API's page at the address's offset."""
    page, server = admin_page, live_server
    listed = server.admin("GET", "/api/sequences?limit=50")
    assert isinstance(listed, list) and 0 < len(listed) <= 50
    rows = page.locator("#sequence-rows tr")
    expect(rows).to_have_count(len(listed))
    expect(page.locator("#sequence-pager")).to_be_hidden()
    page.goto(f"{server.base}/admin/#/sequences/from/50")
    expect(page.locator("#sequence-pager")).to_be_visible()
    expect(rows).to_have_count(0)
    expect(page.locator("#sequence-pager span")).to_have_text("no more sequences")
    expect(page.locator("#no-sequences")).to_be_hidden()
    back = page.locator("#sequence-pager a", has_text="Previous")
    expect(back).to_have_attribute("href", "#/sequences")
    expect(page.locator("#sequence-pager a", has_text="Next")).to_have_attribute(
        "aria-disabled", "true")
    page.screenshot(path=str(output_dir / "admin-sequences-past-the-end.png"))
    back.click()
    expect(rows).to_have_count(len(listed))
    expect(page.locator("#sequence-pager")).to_be_hidden()
    page.goto(f"{server.base}/admin/#/workers/from/200")
    expect(page.locator("#worker-pager span")).to_have_text("no more workers")
    expect(page.locator("#worker-pager a", has_text="Previous")).to_have_attribute(
        "href", "#/workers")
