"""A scale-out run across hosts, as the README's scale-out deploys it: an API host and two
queue-worker hosts with empty instance folders that cannot see each other's (private mount
namespaces, tests/deploy/hosts.py), on PostgreSQL, Redis and S3 (moto's server).

The tests run in order on one deployment: import, tasks, publish, the simulated crowd, the
confirm and QC jobs and the solve (all on worker hosts); the frame routes, suggestions,
proposals, replays and overlays from the API host; an export in each format, run on a worker
host and downloaded from the API host; then kill -9 of the worker host running a solve, which
the other worker host takes over. Each job's host is printed in a table and checked.
"""

from __future__ import annotations

import io
import time
import zipfile
from datetime import timedelta
from typing import Any, NamedTuple

import pytest
from sqlalchemy import create_engine, inspect, text

from tests.deploy.conftest import ADMIN, WORKER_HOSTS, Deployment

pytestmark = [pytest.mark.postgres, pytest.mark.redis, pytest.mark.slow]

FORMATS = ("dexycb", "coco", "bop", "cvat", "json")
TAKEOVER_LIMIT_S = 120.0


def query(d: Deployment, sql: str, **params: Any) -> list[Any]:
    engine = create_engine(d.database_url)
    try:
        with engine.connect() as conn:
            return list(conn.execute(text(sql), params))
    finally:
        engine.dispose()


def wait_until(what: str, predicate: Any, d: Deployment, timeout_s: float = 240) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        for host in d.hosts:
            assert host.alive() or host.killed, f"{host.name} died\n{host.log_tail()}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}\n{d.logs()}"
        time.sleep(0.5)


def idle(d: Deployment) -> bool:
    active = query(d, "SELECT count(*) FROM jobs WHERE status IN "
                      "('queued', 'running', 'retrying')")[0][0]
    return active == 0


def unaccepted_tasks(d: Deployment) -> list[int]:
    return [r[0] for r in query(d, "SELECT t.id FROM tasks t WHERE NOT EXISTS (SELECT 1 FROM "
                                   "assignments a WHERE a.task_id = t.id AND "
                                   "a.status = 'approved') ORDER BY t.id")]


def crowd_round(d: Deployment, round_: int, workers: int) -> str:
    first = 1 + 10 * (round_ - 1)
    return d.api_host.run(
        "crowd", "simulate", "--capture", str(d.capture), "--workers", str(workers),
        "--profile", "careful", "--base", d.api.base, "--admin-email", ADMIN[0],
        "--admin-password", ADMIN[1], "--seed", str(round_), "--first", str(first)).stdout


def approve_reviewed(d: Deployment) -> int:
    """The admin approves, per task without accepted work, the work QC left for review."""
    rows = query(d, "SELECT a.task_id, min(a.id) FROM assignments a JOIN qc_reports r ON "
                    "r.assignment_id = a.id WHERE r.outcome = 'review' AND NOT r.provisional "
                    "AND a.status = 'submitted' GROUP BY a.task_id")
    missing = set(unaccepted_tasks(d))
    approved = 0
    for task_id, assignment_id in rows:
        if task_id in missing:
            d.api.json("POST", f"/api/crowd/assignments/{assignment_id}/approve", {})
            approved += 1
    return approved


def test_import_publish_crowd_confirm_qc_and_solve_run_across_hosts(
        deployment: Deployment) -> None:
    d = deployment
    out = d.api_host.run("import", str(d.capture)).stdout
    sequences = d.api.json("GET", "/api/sequences")
    assert len(sequences) == 1, out
    seq = sequences[0]
    d.notes["sequence"] = seq
    assert "6 tasks" in d.api_host.run("tasks", "create", str(seq["id"])).stdout
    published = d.api_host.run("publish", "--reward", "0.50", "--assignments", "1").stdout
    assert "published: 6 created" in published, published
    for round_ in range(1, 4):
        missing = unaccepted_tasks(d)
        if not missing:
            break
        crowd_round(d, round_, len(missing))
        wait_until("the confirm and QC jobs", lambda: idle(d), d)
        if approve_reviewed(d):
            wait_until("QC after the admin's approvals", lambda: idle(d), d)
    assert unaccepted_tasks(d) == [], "tasks without accepted work after 3 rounds: " + str(
        query(d, "SELECT a.task_id, a.id, a.status, r.outcome, r.provisional, r.feedback "
                 "FROM assignments a LEFT JOIN qc_reports r ON r.assignment_id = a.id "
                 "ORDER BY a.id") + query(d, "SELECT key, status, attempts, error, result "
                                             "FROM jobs ORDER BY id"))
    runs = wait_until("the solve", lambda: query(
        d, "SELECT id, status FROM solve_runs WHERE status IN ('done', 'failed')"), d)
    assert [r[1] for r in runs] == ["done"], runs
    d.notes["run_id"] = runs[0][0]
    jobs = query(d, "SELECT kind, status, count(*) FROM jobs GROUP BY kind, status")
    kinds = {kind for kind, _, _ in jobs}
    assert {"confirm", "qc", "solve"} <= kinds, jobs
    assert all(status == "done" for _, status, _ in jobs), jobs


def test_frames_suggestions_proposals_replays_and_overlays_from_the_api_host(
        deployment: Deployment) -> None:
    d = deployment
    seq, run_id = d.need("sequence"), d.need("run_id")
    serial = seq["cameras"][0]["serial"]
    manifest = d.api.json("GET", f"/api/sequences/{seq['id']}/views/{serial}/frames")
    url = manifest["frames"][0]["url"]
    # Presigned on S3: the browser reads the bucket, not a host's disk.
    assert url.startswith(d.s3_endpoint), url
    assert _get_absolute(url)[:2] == b"\xff\xd8"  # a JPEG
    assert d.api.call("GET", f"/api/sequences/{seq['id']}/views/{serial}/frames/0.jpg"
                      )[1][:2] == b"\xff\xd8"

    tasks = d.api.json("GET", f"/api/tasks?sequence_id={seq['id']}")
    hand = next(t for t in tasks if t["kind"] == "hand")
    frames = hand["num_frames"]
    link = d.api.json("POST", f"/api/tasks/{hand['id']}/assignments", {"worker_id": "probe"})
    # Three views: never enough to triangulate another's joints; before any accepted work in
    # another view the route says why there are none, after it the hand model fitted to it (a
    # job on a worker host) suggests them, the route saying they are being prepared till then.
    suggestions = d.api.json("GET", "/api/annotate/suggestions", token=link["token"])
    if suggestions["available"]:
        assert suggestions["method"] == "fitted", suggestions
    elif suggestions["preparing"]:
        assert "being prepared" in suggestions["reason"], suggestions
    else:
        assert "1 other view" in suggestions["reason"], suggestions
    body = {"tracks": [{"point": 0, "keyframes": [[0, 320.0, 240.0, 1],
                                                  [frames - 1, 330.0, 245.0, 1]]}]}
    proposals = d.api.json("POST", "/api/annotate/proposals", body, token=link["token"])
    (point,) = proposals["points"]
    # Tracked in the view's frames (read from S3) between the two keyframes.
    assert len(point["xy"]) == frames and any(point["ok"][1:-1]), point

    approved = query(d, "SELECT a.id FROM assignments a JOIN qc_reports r ON "
                        "r.assignment_id = a.id WHERE a.status = 'approved' ORDER BY a.id")
    replay = d.api.json("GET", f"/api/qc/reports/{approved[0][0]}/review")
    assert replay["assignment_id"] == approved[0][0], replay
    assert len(replay["track"]["xy"]) == replay["num_frames"] == frames
    review_frame = replay["frames"]["urls"][0]
    assert _get_absolute(review_frame if review_frame.startswith("http")
                         else d.api.base + review_frame)[:2] == b"\xff\xd8"
    _, png, headers = d.api.call(
        "GET", f"/api/solve-runs/{run_id}/frames/0/views/{serial}.png")
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and headers["content-type"] == "image/png"
    assert d.api.call("GET", f"/api/solve-runs/{run_id}/frames/0/residuals.png")[1][:4] == \
        b"\x89PNG"
    timeline = d.api.json("GET", f"/api/solve-runs/{run_id}/timeline")
    assert len(timeline["frames"]) == frames, timeline


def _get_absolute(url: str) -> bytes:
    import urllib.request

    with urllib.request.urlopen(url, timeout=30) as resp:
        return bytes(resp.read())


def test_exports_run_on_worker_hosts_and_download_from_the_api_host(
        deployment: Deployment) -> None:
    d = deployment
    seq_id = d.need("sequence")["id"]
    exports = {fmt: d.api.json("POST", "/api/exports", {"format": fmt, "sequences": [seq_id]})
               for fmt in FORMATS}
    d.notes["exports"] = {fmt: e["id"] for fmt, e in exports.items()}

    def finished() -> list[dict] | None:
        states = [d.api.json("GET", f"/api/exports/{e['id']}") for e in exports.values()]
        return states if all(s["status"] in ("done", "failed") for s in states) else None

    states = wait_until("the export jobs", finished, d)
    assert [s["status"] for s in states] == ["done"] * len(FORMATS), states
    answers = {}
    for fmt, export in exports.items():
        answers[fmt] = _download(d, export["id"])[:2]
    refused = {fmt: (status, payload[:200]) for fmt, (status, payload) in answers.items()
               if status != 200}
    assert not refused, f"downloads refused by the API host: {refused}"
    for fmt, (_, payload) in answers.items():
        with zipfile.ZipFile(io.BytesIO(payload)) as archive:
            assert archive.testzip() is None and archive.namelist(), fmt


def _download(d: Deployment, export_id: int) -> tuple[int, bytes, dict[str, str]]:
    import urllib.error
    import urllib.request

    request = urllib.request.Request(f"{d.api.base}/api/exports/{export_id}/download")
    request.add_header("Authorization", f"Bearer {d.api.token}")
    try:
        with urllib.request.urlopen(request, timeout=60) as resp:
            return resp.status, resp.read(), dict(resp.headers)
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read(), dict(exc.headers)


class JobRow(NamedTuple):
    id: int
    kind: str
    key: str
    status: str
    attempts: int
    host: str | None  # the host of the last claim ("name:pid")
    took: timedelta | None  # the last attempt's time
    attempt_hosts: list[str]  # every attempt's host, in order


def job_rows(d: Deployment) -> list[JobRow]:
    """Every job with the hosts that ran it (None and [] where the job table records none)."""
    engine = create_engine(d.database_url)
    try:
        columns = {c["name"] for c in inspect(engine).get_columns("jobs")}
    finally:
        engine.dispose()
    host = "host" if "host" in columns else "NULL"
    log = "attempt_log" if "attempt_log" in columns else "NULL"
    rows = query(d, f"SELECT id, kind, key, status, attempts, {host}, finished_at - started_at, "
                    f"{log} FROM jobs ORDER BY id")
    return [JobRow(*r[:7], [e.get("host") for e in r[7] or []]) for r in rows]


def host_of(d: Deployment, recorded: str | None) -> str | None:
    """Which of the deployment's hosts a job's recorded host names."""
    names = [h.name for h in d.hosts if recorded and h.name in recorded]
    return names[0] if len(names) == 1 else None


def test_a_killed_worker_hosts_solve_is_taken_over_by_the_other(
        deployment: Deployment, capsys: pytest.CaptureFixture[str]) -> None:
    d = deployment
    run = d.api.json("POST", f"/api/sequences/{d.need('sequence')['id']}/solve", {})
    key = f"solve-run:{run['id']}"
    d.notes["killed_solve"] = key

    def job() -> JobRow:
        return next(r for r in job_rows(d) if r.key == key)

    wait_until(f"{key} to run", lambda: job().status == "running", d, 120)
    running_on = host_of(d, job().host)
    assert running_on in WORKER_HOSTS, f"{key} runs on no known host: {job().host!r}"
    victim = d.workers[running_on]
    d.notes["victim"] = victim.name
    d.notes["victim_files"] = victim.files()  # its folder goes with it
    victim.kill()
    killed_at = time.monotonic()
    wait_until(f"another attempt at {key}", lambda: job().attempts >= 2, d,
               TAKEOVER_LIMIT_S + 60)
    claimed = time.monotonic() - killed_at
    wait_until(f"{key} to finish", lambda: job().status in ("done", "failed"), d, 180)
    finished = time.monotonic() - killed_at
    row = job()
    with capsys.disabled():
        print(f"\n{key} ran on {victim.name}, killed (kill -9): attempt {row.attempts} "  # noqa: T201
              f"claimed {claimed:.0f} s later, {row.status} {finished:.0f} s after the kill "
              f"(that attempt {row.took.total_seconds() if row.took else 0:.0f} s)")
    assert (row.status, row.attempts) == ("done", 2), row
    survivor = next(n for n in WORKER_HOSTS if n != victim.name)
    assert [host_of(d, h) for h in row.attempt_hosts] == [victim.name, survivor], row
    assert query(d, "SELECT status FROM solve_runs WHERE id = :id", id=run["id"])[0][0] == "done"
    assert claimed < TAKEOVER_LIMIT_S, f"taken over {claimed:.0f} s after the kill"
    assert finished < TAKEOVER_LIMIT_S, f"finished {finished:.0f} s after the kill"


def test_every_job_records_the_worker_host_that_ran_it(
        deployment: Deployment, capsys: pytest.CaptureFixture[str]) -> None:
    d = deployment
    wait_until("the queue to be idle", lambda: idle(d), d, 120)
    rows = job_rows(d)
    header = (f"{'id':>4}  {'kind':<12} {'key':<26} {'status':<8} {'tries':>5} {'took':>6}  "
              "host (of each attempt)")
    lines = [header]
    lines += [f"{r.id:>4}  {r.kind:<12} {r.key:<26} {r.status:<8} {r.attempts:>5} "
              f"{r.took.total_seconds() if r.took else 0:>5.1f}s  "
              f"{' -> '.join(r.attempt_hosts) if len(r.attempt_hosts) > 1 else r.host}"
              for r in rows]
    with capsys.disabled():
        print("\njobs and the host that ran each:\n" + "\n".join(lines))  # noqa: T201
    assert {r.status for r in rows} == {"done"}, rows
    unrecorded = [r.key for r in rows if host_of(d, r.host) not in WORKER_HOSTS]
    assert not unrecorded, f"{len(unrecorded)} jobs record no worker host: {unrecorded}"
    ran_on = {r.key: host_of(d, r.host) for r in rows}
    by_id = {r.id: host_of(d, r.host) for r in rows}
    assert {by_id[i] for i in d.need("exports").values()} <= set(WORKER_HOSTS)
    survivor = next(n for n in WORKER_HOSTS if n != d.need("victim"))
    assert ran_on[d.need("killed_solve")] == survivor
    # Both worker hosts took work.
    assert set(ran_on.values()) == set(WORKER_HOSTS), ran_on


def test_no_host_holds_what_another_host_needs(deployment: Deployment,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    d = deployment
    listing = {h.name: h.files() if h.alive() else d.need("victim_files") for h in d.hosts}
    with capsys.disabled():
        for name, files in listing.items():
            print(f"{name} instance folder: {files or '(empty)'}")  # noqa: T201
    if d.isolated:
        # From outside, no host's folder is visible: each is on its host's own tmpfs; the
        # capture lies on the API host's alone, so the worker hosts read frames from S3.
        assert not any(d.api_host.hosts_root.rglob("*")), list(d.api_host.hosts_root.rglob("*"))
        assert d.api_host.path(d.capture).is_dir()
        assert not any(w.path(d.capture).exists() for w in d.workers.values() if w.alive())
        assert not any(w.path(d.api_host.var_dir).exists() for w in d.workers.values()
                       if w.alive())
    # README, "What stays in a host's instance folder": on a scale-out only the address of the
    # host's own server; nothing another host reads (storage, exports, database, queue, key).
    assert listing == {"api-host": ["server.json"], "worker-a": [], "worker-b": []}, listing


def test_the_default_lease_lets_a_killed_job_be_taken_over_within_two_minutes() -> None:
    """The deployment above runs with a short lease to keep the test short; the default
    lease must allow the same: a takeover by the reaper (every minute) within 2 minutes."""
    from backend.config import Settings

    assert Settings.model_fields["job_lease_s"].default <= 60
