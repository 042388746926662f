"""GET /api/annotate/suggestions: pre-fill suggestions from the accepted work of a target's
other views, through the real app on a small synthetic capture (4 views x 6 frames at 640x480,
with depth maps): view 0 is labelled, views 1, 2 and 3 carry careful accepted work.

Also: the tracking proposals carry the same check cells (worker.assist.checks).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from backend.db import session_scope

URL = "/api/annotate/suggestions"


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _truth(capture: Path, serial: str, frames: int) -> tuple[np.ndarray, np.ndarray]:
    from backend.captures.truth import CaptureTruth
    from worker.synth.annotators import hand_visibility

    joint_2d, seg = CaptureTruth(capture).view(serial, frames)
    return joint_2d, hand_visibility(joint_2d, seg)


def _accept(task_id: int, worker: str, tracks: list, status: str = "approved") -> int:
    """An assignment from a direct link, with QC's verdict ``status`` already given."""
    from backend.annotation.models import Assignment, Track
    from backend.db import utcnow

    with session_scope() as session:
        assignment = Assignment(task_id=task_id, worker_id=worker, external_id=f"direct-{worker}",
                                status=status, version=1, working_time_s=100.0,
                                submitted_at=utcnow())
        assignment.tracks = [Track(point_index=p, keyframes=rows) for p, rows in enumerate(tracks)]
        session.add(assignment)
        session.flush()
        return assignment.id


def _careful(capture: Path, task: dict, seed: int) -> list:
    """A careful simulated worker's tracks of a hand task (a keyframe on every frame)."""
    from worker.synth.annotators import annotate

    truth, visible = _truth(capture, task["serial"], task["num_frames"])
    return annotate(truth, visible, (task["width"], task["height"]), "careful",
                    np.random.default_rng(seed), key_step=1).tracks


@pytest.fixture(scope="module")
def capture4(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small synthetic capture with 4 views (suggestions need 3 other views); read-only."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("capture-4-views")
    generate_capture(root, seed=3, frames=6, views=4, objects=2)
    return root


@pytest.fixture
def hands(client: TestClient, admin_headers: dict, capture4: Path) -> dict:
    """The capture's hand tasks by view, object task 0 of view 0, and two direct links of the
    view 0 hand task (workers W1, W2)."""
    seq_id = import_path(capture4)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = [t for t in tasks if t["kind"] == "hand"]
    links = [client.post(f"/api/tasks/{hand[0]['id']}/assignments", json={"worker_id": w},
                         headers=admin_headers).json() for w in ("W1", "W2")]
    obj = next(t for t in tasks if t["kind"] == "object" and t["serial"] == hand[0]["serial"])
    return {"tasks": hand, "links": links, "object": obj}


def _get(client: TestClient, token: str, **params: int) -> dict:
    resp = client.get(URL, params=params, headers=_bearer(token))
    assert resp.status_code == 200, resp.text
    return resp.json()


def _fit_jobs() -> list[tuple[str, str]]:
    """The fit jobs' (key, status), in id order."""
    from sqlalchemy import select

    from backend.jobs.models import Job
    from backend.labels.suggestions import FITTED_KIND

    with session_scope() as session:
        return [(j.key, j.status) for j in session.scalars(
            select(Job).where(Job.kind == FITTED_KIND).order_by(Job.id))]


def _run_fit_jobs() -> int:
    """Run the queued fit jobs here (as a queue worker would); how many ran."""
    from backend.jobs.runner import execute

    queued = [key for key, status in _fit_jobs() if status == "queued"]
    for key in queued:
        execute(key)
    return len(queued)


def _fitted(client: TestClient, token: str, **params: int) -> dict:
    """The answer once the fit job it queued has run."""
    answer = _get(client, token, **params)
    if answer["preparing"]:
        assert _run_fit_jobs() >= 1
        answer = _get(client, token, **params)
    return answer


def _grid(points: list[dict]) -> np.ndarray:
    """(F, P, 2) of the answer's points, NaN where null."""
    rows = [[[np.nan, np.nan] if v is None else v for v in p["xy"]] for p in points]
    return np.swapaxes(np.array(rows, dtype=float), 0, 1)


@pytest.fixture
def accepted(hands: dict, capture4: Path) -> dict:
    """Careful accepted work of views 1, 2 and 3."""
    for view, seed in ((1, 11), (2, 12), (3, 13)):
        task = hands["tasks"][view]
        _accept(task["id"], f"A{view}", _careful(capture4, task, seed))
    return hands


def test_hand_suggestions_wait_for_accepted_work_in_one_other_view(
    client: TestClient, hands: dict, capture4: Path
) -> None:
    tasks, token = hands["tasks"], hands["links"][0]["token"]
    answer = _get(client, token)
    assert answer["available"] is False and answer["min_views"] == 1
    assert answer["method"] is None
    assert answer["reason"] == ("suggestions need accepted work in 1 other view of this hand; "
                                "there is none")
    assert answer["points"] == [] and answer["epipolar"] == [] and answer["views"] == []
    # Work of the same view, and work QC has not accepted, do not count.
    _accept(tasks[0]["id"], "same-view", _careful(capture4, tasks[0], 1))
    _accept(tasks[2]["id"], "waiting", _careful(capture4, tasks[2], 2), status="submitted")
    answer = _get(client, token)
    assert answer["available"] is False and answer["views"] == []
    # An object task says so.
    from backend.annotation.models import Assignment
    from backend.annotation.service import get_task_or_raise
    from backend.annotation.tokens import assignment_token

    aid = _accept(hands["object"]["id"], "O1", [[], []], status="working")
    with session_scope() as session:
        object_token = assignment_token(get_task_or_raise(session, hands["object"]["id"]),
                                        session.get_one(Assignment, aid))
    answer = _get(client, object_token)
    assert answer["min_views"] == 1 and answer["available"] is False
    assert "1 other view of this object; there is none" in answer["reason"]


@pytest.mark.parametrize(("views", "bound_px"), [((1,), 12.0), ((1, 3), 6.0)])
def test_one_or_two_accepted_views_give_fitted_suggestions_near_the_truth(
    client: TestClient, hands: dict, capture4: Path, views: tuple[int, ...], bound_px: float
) -> None:
    """The hand model fitted to one (two) careful views' labels and depth, projected into
    view 0; bounds: about twice the median error measured on this capture."""
    tasks, token = hands["tasks"], hands["links"][0]["token"]
    for view in views:
        _accept(tasks[view]["id"], f"A{view}", _careful(capture4, tasks[view], 30 + view))
    answer = _fitted(client, token)
    assert answer["available"] is True and answer["method"] == "fitted"
    assert answer["views"] == [tasks[v]["serial"] for v in views]
    truth, visible = _truth(capture4, tasks[0]["serial"], 6)
    xy = _grid(answer["points"])
    has = np.isfinite(xy).all(axis=-1)
    assert has[visible].mean() > 0.9
    errors = np.linalg.norm(xy - truth, axis=-1)[has & visible]
    assert np.median(errors) < bound_px, np.median(errors)


def _api_process_answers(token: str, asks: int) -> tuple[list[dict], bool]:
    """``asks`` requests for suggestions answered by a fresh API process (the app on this
    test's database and storage, no queue worker in it); its answers, and whether it loaded
    PyTorch."""
    import json
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    code = ("import json, sys\nfrom fastapi.testclient import TestClient\n"
            "from backend.app import create_app\nclient = TestClient(create_app())\n"
            f"answers = [client.get({URL!r}, headers={_bearer(token)!r}).json() "
            f"for _ in range({asks})]\n"
            "print(json.dumps([answers, 'torch' in sys.modules]))")
    env = {**os.environ, "DEXLABEL_INPROCESS_WORKER": "false",
           "PYTHONPATH": os.pathsep.join([str(root), *filter(None, [os.environ.get(
               "PYTHONPATH")])])}
    out = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True,
                         text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    answers, torch = json.loads(out.stdout.strip().splitlines()[-1])
    return answers, torch


def test_fitted_suggestions_are_prepared_by_one_queued_job(
    client: TestClient, hands: dict, capture4: Path
) -> None:
    """The fit runs on the worker queue, never in a request: the API answers at once that
    the suggestions are being prepared and queues one job however often it is asked; once the
    job has run, it serves them."""
    from backend.labels.suggestions import compute_fitted

    tasks, token = hands["tasks"], hands["links"][0]["token"]
    _accept(tasks[1]["id"], "A1", _careful(capture4, tasks[1], 31))
    answers, torch = _api_process_answers(token, asks=2)
    assert torch is False
    for answer in answers:
        assert answer["available"] is False and answer["preparing"] is True
        assert answer["reason"] == ("suggestions from the hand model are being prepared; "
                                    "they will appear shortly")
        assert answer["points"] == [] and answer["views"] == [tasks[1]["serial"]]
    assert _get(client, token)["preparing"] is True
    (job,) = _fit_jobs()
    assert job[1] == "queued" and job[0].startswith(f"fitted_suggestions:{tasks[0]['id']}:0:5:")
    assert _run_fit_jobs() == 1
    assert _fit_jobs() == [(job[0], "done")]
    answer = _get(client, token)
    assert answer["available"] is True and answer["preparing"] is False
    assert answer["method"] == "fitted"
    truth, visible = _truth(capture4, tasks[0]["serial"], 6)
    xy = _grid(answer["points"])
    has = np.isfinite(xy).all(axis=-1)
    errors = np.linalg.norm(xy - truth, axis=-1)[has & visible]
    assert has[visible].mean() > 0.9 and np.median(errors) < 12.0, np.median(errors)
    # A second run of the same work (two queue messages, a retry) leaves what is stored.
    assert "stored: True" in compute_fitted(tasks[0]["id"], 0, 5)["message"]
    # New accepted work is other work: a new job for it, the old result no longer served.
    _accept(tasks[3]["id"], "A3", _careful(capture4, tasks[3], 33))
    assert _get(client, token)["preparing"] is True
    assert [status for _, status in _fit_jobs()] == ["done", "queued"]


def test_suggestions_from_three_accepted_views_lie_near_the_truth(
    client: TestClient, accepted: dict, capture4: Path
) -> None:
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key
    from worker.assist.prefill import epipolar_lines

    tasks, link = accepted["tasks"], accepted["links"][0]
    answer = _get(client, link["token"])
    assert answer["available"] is True and answer["reason"] is None
    assert answer["method"] == "triangulated"
    assert answer["views"] == [tasks[1]["serial"], tasks[2]["serial"], tasks[3]["serial"]]
    assert (answer["first_frame"], answer["last_frame"]) == (0, 5)
    assert [p["point"] for p in answer["points"]] == list(range(21))
    truth, visible = _truth(capture4, tasks[0]["serial"], 6)
    xy = _grid(answer["points"])
    assert xy.shape == (6, 21, 2)
    cells = check_cells(check_key(get_settings().signing_key), link["assignment_id"], 21, 6)
    plain = np.ones((6, 21), bool)
    for point, frame in cells:
        plain[frame, point] = False
    # Suggested where at least two of the three views see the joint.
    seen_in = sum(_truth(capture4, tasks[v]["serial"], 6)[1].astype(int) for v in (1, 2, 3))
    both = seen_in >= 2
    has = np.isfinite(xy).all(axis=-1)
    assert both.sum() > 50 and not (has & ~both).any() and has[both].mean() > 0.95
    errors = np.linalg.norm(xy - truth, axis=-1)[has & plain]
    # Careful views (2 px per axis).
    assert np.median(errors) < 4.0 and errors.max() < 15.0
    suggested = np.array([[np.nan if v is None else float(v) for v in p["visible"]]
                          for p in answer["points"]]).T
    known = ~np.isnan(suggested)
    assert known[has].mean() > 0.9
    assert (suggested[known] == visible[known]).mean() > 0.9
    # The epipolar guide: each labelled view's line through the true joint of view 0.
    assert [e["serial"] for e in answer["epipolar"]] == answer["views"]
    for entry in answer["epipolar"]:
        labels = _grid([{"xy": p} for p in entry["xy"]])
        lines = epipolar_lines(np.array(entry["F"]), labels)
        distance = np.abs((lines[..., :2] * truth).sum(axis=-1) + lines[..., 2])
        assert np.nanmedian(distance) < 3.0


def test_check_cells_are_shown_15_px_off_and_only_there(
    client: TestClient, accepted: dict
) -> None:
    """Two assignments of one task read the same suggestions but for their own check cells;
    the epipolar data carries none."""
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key

    first, second = (_get(client, link["token"]) for link in accepted["links"])
    assert first["epipolar"] == second["epipolar"]
    key = check_key(get_settings().signing_key)
    mine, theirs = (set(check_cells(key, link["assignment_id"], 21, 6))
                    for link in accepted["links"])
    assert len(mine) == 4 and mine != theirs
    a, b = _grid(first["points"]), _grid(second["points"])
    moved = np.zeros((6, 21), bool)
    for point, frame in mine ^ theirs:
        shown = first["points"][point]["visible"][frame] is not False
        if shown:
            assert np.linalg.norm(a[frame, point] - b[frame, point]) == pytest.approx(15.0,
                                                                                    abs=2e-3)
            moved[frame, point] = True
    assert moved.any()
    np.testing.assert_array_equal(a[~moved], b[~moved])


@pytest.fixture(scope="module")
def tracked_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One view of a hand grasping over 24 frames at 640x480, where tracking holds between
    keyframes 4 frames apart (the 6 frames of the small capture move too far for it)."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("tracked-capture")
    generate_capture(root, seed=7, frames=24, views=1, workers=1)
    return root


def test_tracking_proposals_carry_the_same_check_cells(
    client: TestClient, admin_headers: dict, tracked_capture: Path
) -> None:
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key

    seq_id = import_path(tracked_capture)[0].sequence_id
    task = next(t for t in client.post(f"/api/sequences/{seq_id}/tasks",
                                       headers=admin_headers).json() if t["kind"] == "hand")
    links = [client.post(f"/api/tasks/{task['id']}/assignments", json={"worker_id": w},
                         headers=admin_headers).json() for w in ("T1", "T2")]
    body = {"tracks": [{"point": p, "keyframes": rows[::4] + rows[-1:]}
                       for p, rows in enumerate(_careful(tracked_capture, task, 5))]}
    answers = []
    for link in links:
        resp = client.post("/api/annotate/proposals", json=body, headers=_bearer(link["token"]))
        assert resp.status_code == 200, resp.text
        answers.append(resp.json())
    key = check_key(get_settings().signing_key)
    mine, theirs = (set(check_cells(key, link["assignment_id"], 21, 24)) for link in links)
    a, b = _grid(answers[0]["points"]), _grid(answers[1]["points"])
    moved = np.zeros((24, 21), bool)
    for point, frame in mine ^ theirs:
        if answers[0]["points"][point]["ok"][frame]:
            assert np.linalg.norm(a[frame, point] - b[frame, point]) == pytest.approx(15.0,
                                                                                    abs=2e-3)
            moved[frame, point] = True
    assert moved.any()
    np.testing.assert_array_equal(a[~moved], b[~moved])


def test_who_may_read_suggestions(
    client: TestClient, admin_headers: dict, accepted: dict
) -> None:
    link = accepted["links"][0]
    assert client.get(URL).status_code == 401
    assert client.get(URL, headers=_bearer("not.a.token")).status_code == 401
    # An admin's own token is not a worker's: it opens no assignment (as for proposals).
    assert client.get(URL, headers=admin_headers).status_code == 401
    preview = client.post(f"/api/tasks/{accepted['tasks'][0]['id']}/preview-token",
                          headers=admin_headers).json()["token"]
    resp = client.get(URL, headers=_bearer(preview))
    assert resp.status_code == 401 and "accept the HIT" in resp.json()["detail"]
    # A read-only review link reads what its assignment's own token reads.
    review = client.post(f"/api/assignments/{link['assignment_id']}/readonly-link",
                         headers=admin_headers).json()["url"].split("#token=")[1]
    assert _get(client, review) == _get(client, link["token"])


def test_another_views_assignment_reads_suggestions_for_its_own_view(
    client: TestClient, admin_headers: dict, accepted: dict, capture4: Path
) -> None:
    """Work of view 1 needs three OTHER views: views 2, 3 and, once accepted, view 0."""
    tasks = accepted["tasks"]
    token = client.post(f"/api/tasks/{tasks[1]['id']}/assignments", json={"worker_id": "W9"},
                        headers=admin_headers).json()["token"]
    answer = _fitted(client, token)
    assert answer["method"] == "fitted"
    assert answer["views"] == [tasks[2]["serial"], tasks[3]["serial"]]
    _accept(tasks[0]["id"], "A0", _careful(capture4, tasks[0], 10))
    answer = _get(client, token)
    assert answer["views"] == [tasks[0]["serial"], tasks[2]["serial"], tasks[3]["serial"]]
    assert answer["method"] == "triangulated"
    truth, _ = _truth(capture4, tasks[1]["serial"], 6)
    errors = np.linalg.norm(_grid(answer["points"]) - truth, axis=-1)
    assert np.nanmedian(errors) < 4.0


def test_suggestions_follow_changes_of_the_accepted_work(
    client: TestClient, accepted: dict, capture4: Path
) -> None:
    """The server keeps each view's result until the work it rests on changes."""
    from backend.annotation.models import Assignment

    token = accepted["links"][0]["token"]
    before = _get(client, token)
    assert _get(client, token) == before
    # A second accepted worker of view 1 who places every joint 8 px to the right.
    shifted = [[[r[0], r[1] + 8.0 if r[1] is not None and r[1] < 630 else r[1], *r[2:]]
                for r in rows] for rows in _careful(capture4, accepted["tasks"][1], 21)]
    aid = _accept(accepted["tasks"][1]["id"], "shifted", shifted)
    moved = np.linalg.norm(_grid(_get(client, token)["points"]) - _grid(before["points"]),
                           axis=-1)
    assert np.nanmedian(moved) > 1.0
    with session_scope() as session:
        session.get_one(Assignment, aid).status = "rejected"
    assert _get(client, token) == before


def test_a_frame_range_answers_its_frames_only(client: TestClient, accepted: dict) -> None:
    token = accepted["links"][0]["token"]
    whole, part = _get(client, token), _get(client, token, first_frame=2, last_frame=4)
    assert (part["first_frame"], part["last_frame"]) == (2, 4)
    assert [p["xy"][2:5] for p in whole["points"]] == [p["xy"] for p in part["points"]]
    assert [p["visible"][2:5] for p in whole["points"]] == [p["visible"] for p in part["points"]]
    assert [[xy[2:5] for xy in e["xy"]] for e in whole["epipolar"]] == \
        [e["xy"] for e in part["epipolar"]]


@pytest.mark.parametrize(("params", "problem"), [
    ({"first_frame": 6}, "first_frame 6 is out of range 0-5"),
    ({"last_frame": 9}, "last_frame 9 is out of range 0-5"),
    ({"first_frame": 4, "last_frame": 2}, "first_frame 4 is after last_frame 2"),
    ({"first_frame": -1}, "first_frame"),
    ({"last_frame": "end"}, "last_frame"),
])
def test_bad_frame_ranges_are_refused_naming_the_problem(
    client: TestClient, hands: dict, params: dict, problem: str
) -> None:
    resp = client.get(URL, params=params, headers=_bearer(hands["links"][0]["token"]))
    assert resp.status_code == 422, resp.text
    assert problem in resp.text


def test_openapi_documents_the_answer(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    operation = spec["paths"][URL]["get"]
    schema = operation["responses"]["200"]["content"]["application/json"]["schema"]
    assert schema["$ref"].endswith("/SuggestionsRead")
    fields = spec["components"]["schemas"]["SuggestionsRead"]["properties"]
    assert set(fields) == {"available", "reason", "views", "min_views", "method", "preparing",
                           "first_frame", "last_frame", "points", "epipolar"}
    assert "hypot(a, b)" in spec["components"]["schemas"]["EpipolarView"]["description"]



def test_accepted_work_has_the_other_views_fits_prepared_ahead(
    client: TestClient, hands: dict, capture4: Path
) -> None:
    """Once QC has accepted work (queue_fits), the fit of every other view nobody holds yet is
    queued, so its next worker finds the suggestions ready; a view a worker holds is fitted
    when that worker asks; asking again queues nothing more."""
    from backend.labels.suggestions import queue_fits
    from backend.storage import get_storage

    tasks, token = hands["tasks"], hands["links"][0]["token"]
    _accept(tasks[1]["id"], "A1", _careful(capture4, tasks[1], 31))
    with session_scope() as session:
        # View 0 is held by the link's worker: not prepared ahead.
        assert queue_fits(session, get_storage(), tasks[0]["sequence_id"], "hand:0") == 2
    assert sorted(int(key.split(":")[1]) for key, _ in _fit_jobs()) == sorted(
        tasks[v]["id"] for v in (2, 3))
    assert _get(client, token)["preparing"] is True
    jobs = _fit_jobs()
    assert sorted(int(key.split(":")[1]) for key, _ in jobs) == sorted(
        tasks[v]["id"] for v in (0, 2, 3))
    with session_scope() as session:
        assert queue_fits(session, get_storage(), tasks[0]["sequence_id"], "hand:0") == 2
    assert _fit_jobs() == jobs
    assert _run_fit_jobs() == 3
    answer = _get(client, token)
    assert answer["available"] is True and answer["method"] == "fitted"
    with session_scope() as session:
        assert queue_fits(session, get_storage(), tasks[0]["sequence_id"], "hand:0") == 0
