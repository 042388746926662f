"""A simulated crowd: workers who do exactly what a browser does, over HTTP, against a running app.

Each worker gets a portal account (created through the admin API, or reused), signs in, lists
the HITs, accepts one, opens the annotation page's assignment (``/api/annotate/start`` with the
task token of the work URL), autosaves its tracks twice, submits them, and posts the
marketplace's completion form to ``{turkSubmitTo}/mturk/externalSubmit``. The labels come from
the ground truth of a synthetic capture (matched by the task's camera serial), spoiled by the
worker's profile (worker.synth.annotators), keyed as the labelling ``protocol`` asks:
``keyframes`` (the product's: a keyframe every few frames and where the path bends),
``every-frame`` (DexYCB's: every joint clicked on every frame) or ``assisted`` (the product's
with the page's assistance: worker.synth.assisted's worker, careful or blind, asking the same
routes the page asks, see ``PageAssistance``). The page's effort counters are reported as such
a worker earns them: an edit action per keyframe (a click, or a key for an occluded one:
worker.synth.annotators.keyframe_actions), or with assistance what the page's edit counter
records (worker.synth.assisted.Actions.edits: clicks, drags, occlusion keys, accepts; not
the re-tracks the page writes by itself), and a modelled working time: READING_S to read the
task and play the clip, then SECONDS_PER_ACTION per action (no person is timed here).
"""

from __future__ import annotations

import time
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from urllib.parse import parse_qs, urlsplit

import httpx
import numpy as np

from backend.captures.truth import CaptureTruth
from backend.errors import DexlabelError
from worker.synth.annotators import KEY_STEP, annotate, draw_profiles, keyframe_actions
from worker.synth.assisted import Prefill, assisted_annotate

WORKER_EMAIL = "sim-worker-{index:03d}@simulated.dexlabel.org"
WORKER_PASSWORD = "simulated worker {index:03d}"
HTTP_TIMEOUT_S = 30.0
# Attempts of a request that a server error left without effect, and the pause between them.
RETRIES = 3
RETRY_PAUSE_S = 0.2
# The modelled working time, s: reading the task and playing the clip once, then each edit
# action (a click or key, with the look before it).
READING_S = 60.0
SECONDS_PER_ACTION = 3.0
Protocol = Literal["keyframes", "every-frame", "assisted"]
# protocol -> (key step, follow the motion: None as the profile does), for the protocols
# keyed without assistance
PROTOCOLS: dict[str, tuple[int, bool | None]] = {"keyframes": (KEY_STEP, None),
                                                 "every-frame": (1, False)}
ASSISTED = "assisted"
# The profiles of an assisted crowd (worker.synth.assisted): "mixed" draws a blind acceptor
# with this probability, a careful worker otherwise.
ASSISTED_PROFILES = ("careful", "blind")
ASSISTED_BLIND_SHARE = 0.2
# While the suggestions route answers ``preparing`` (a fit on the worker queue), the page asks
# again this often for at most this long, s (frontend/annotate/core/assist.js).
SUGGEST_POLL_S = 4.0
SUGGEST_POLL_LIMIT_S = 180.0


def working_seconds(actions: int) -> float:
    """The modelled active working time of ``actions`` edit actions, s."""
    return READING_S + SECONDS_PER_ACTION * actions


class SimulationError(DexlabelError, status_code=502, code="simulation_failed"):
    """A step of the worker flow answered with an error."""


@dataclass
class WorkerOutcome:
    """What one simulated worker did: status is "submitted" or "no HIT available"."""

    email: str
    worker_id: str
    profile: str
    status: str
    hit_id: str | None = None
    assignment_id: str | None = None
    task_id: int | None = None


def _checked(resp: httpx.Response, step: str) -> Any:
    if resp.status_code != 200:
        raise SimulationError(f"{step}: HTTP {resp.status_code}: {resp.text[:300]}")
    return resp.json() if "json" in resp.headers.get("content-type", "") else resp.text


class WorkerClient:
    """One simulated worker's HTTP session with the app at ``base``."""

    def __init__(self, http: httpx.Client, base: str) -> None:
        self.http = http
        self.base = base.rstrip("/")

    def _again(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        """A request that changes nothing when it fails, tried again after a server error as
        a browser's user would (the portal's HIT list can lose a race with a requester call
        on the same HIT and answer 500; nothing was written)."""
        for attempt in range(RETRIES):
            resp = self.http.request(method, url, **kwargs)
            if resp.status_code < 500:
                break
            time.sleep(RETRY_PAUSE_S * (attempt + 1))
        return resp

    def sign_in(self, admin_token: str, email: str, password: str) -> tuple[str, str]:
        """Create the account (or reuse it) and log in; (portal token, worker id)."""
        resp = self.http.post(f"{self.base}/api/portal/workers",
                              headers={"Authorization": f"Bearer {admin_token}"},
                              json={"email": email, "password": password})
        if resp.status_code != 409:
            _checked(resp, f"create worker {email}")
        reply = _checked(self.http.post(f"{self.base}/api/portal/login",
                                        json={"email": email, "password": password}),
                         f"log in {email}")
        return reply["access_token"], reply["worker_id"]

    def accept_first(self, token: str, only: Collection[str] | None = None) -> dict | None:
        """Accept the first HIT on offer (of ``only``'s HIT ids, if given); the portal's
        assignment reply, or None."""
        auth = {"Authorization": f"Bearer {token}"}
        hits = _checked(self._again("GET", f"{self.base}/api/portal/hits", headers=auth),
                        "list HITs")
        for hit in hits:
            if only is not None and hit["hit_id"] not in only:
                continue
            # Only HITs that open our annotation page with a task token can be worked here.
            preview = self._again("GET", f"{self.base}/api/portal/hits/{hit['hit_id']}",
                                  headers=auth)
            url = preview.json().get("preview_url") if preview.status_code == 200 else None
            if "task=" not in (url or ""):
                continue
            resp = self._again("POST", f"{self.base}/api/portal/hits/{hit['hit_id']}/accept",
                               headers=auth)
            if resp.status_code == 200:
                return resp.json()
        return None

    def open_page(self, work_url: str) -> tuple[dict[str, str], str, dict]:
        """What the page does on load: (query parameters, assignment token, task reply)."""
        params = {k: v[0] for k, v in parse_qs(urlsplit(work_url).query).items()}
        started = _checked(self.http.post(f"{self.base}/api/annotate/start", json={
            "task_token": params["task"], "assignment_id": params["assignmentId"],
            "worker_id": params["workerId"], "hit_id": params.get("hitId")}), "start assignment")
        token = started["token"]
        task = _checked(self.http.get(f"{self.base}/api/annotate/task",
                                      headers={"Authorization": f"Bearer {token}"}), "read task")
        return params, token, task

    def label(self, token: str, version: int, tracks: list[list[list[float | None]]],
              actions: int | None = None) -> int:
        """Autosave half the points, then all of them, then submit; the final version. The
        page's counters grow as the points are placed: ``actions`` edit actions in all
        (default: one per keyframe) in READING_S plus SECONDS_PER_ACTION each."""
        auth = {"Authorization": f"Bearer {token}"}
        body = [{"point": p, "keyframes": rows} for p, rows in enumerate(tracks)]
        total = sum(len(rows) for rows in tracks) if actions is None else actions
        half = body[: len(body) // 2 or 1]
        done_half = sum(len(rows) for rows in tracks[:len(half)]) if actions is None \
            else actions * len(half) // max(len(body), 1)
        for part, count in ((half, done_half), (body, total)):
            saved = _checked(self.http.put(f"{self.base}/api/annotate/tracks", headers=auth, json={
                "version": version, "tracks": part, "edit_count": count,
                "working_time_s": working_seconds(count)}), "autosave tracks")
            version = saved["version"]
        done = _checked(self.http.post(f"{self.base}/api/annotate/submit", headers=auth, json={
            "version": version, "tracks": body, "edit_count": total,
            "working_time_s": working_seconds(total)}), "submit tracks")
        return int(done["version"])

    def external_submit(self, params: dict[str, str], version: int) -> None:
        """The completion form the page posts to the marketplace."""
        url = f"{params['turkSubmitTo'].rstrip('/')}/mturk/externalSubmit"
        form = {"assignmentId": params["assignmentId"], "result": f"submitted:{version}"}
        _checked(self.http.post(url, data=form), "post externalSubmit")


def _fill_held(xy: np.ndarray, ok: np.ndarray, reply: dict[str, Any]) -> None:
    """Writes a proposals answer (per point ``xy`` and ``ok`` over frames ``first_frame``..)
    into the clip's (F, P, 2) positions and (F, P) flags where it holds."""
    first = int(reply["first_frame"])
    for point in reply["points"]:
        for i, (at, held) in enumerate(zip(point["xy"], point["ok"], strict=True)):
            if held and at is not None:
                xy[first + i, point["point"]], ok[first + i, point["point"]] = at, True


class PageAssistance:
    """What the annotation page shows one assignment, asked of its routes (a
    worker.synth.assisted.Assistance): POST /api/annotate/proposals (between anchors, and
    ``follow`` forward from a point's last keyframe, as the page's Track all asks), GET
    /api/annotate/suggestions and, on hand tasks, POST /api/annotate/model-follow (both
    polled while ``preparing``, as the page does). The check cells
    are planted by the routes. The page re-tracks around a correction by itself."""

    follows = True
    retracks = True

    def __init__(self, client: WorkerClient, token: str, task: dict,
                 poll_s: float = SUGGEST_POLL_S, poll_limit_s: float = SUGGEST_POLL_LIMIT_S,
                 model: bool = True) -> None:
        self.client, self.auth = client, {"Authorization": f"Bearer {token}"}
        self.frames = int(task["num_frames"])
        self.size = (int(task["width"]), int(task["height"]))
        # Whether the worker presses Follow hand (hand tasks only): the follow is a job, so
        # an app served without a queue worker would keep it preparing.
        self.hand = model and task.get("kind") == "hand"
        self.poll_s, self.poll_limit_s = poll_s, poll_limit_s
        self._suggested: tuple[Prefill | None] | None = None

    def proposals(self, anchors: list[list[list[Any]]], forward: list[int]
                  ) -> tuple[np.ndarray, np.ndarray]:
        asked = [p for p, rows in enumerate(anchors) if rows]
        xy = np.full((self.frames, len(anchors), 2), np.nan)
        ok = np.zeros((self.frames, len(anchors)), dtype=bool)
        if not asked:
            return xy, ok
        frames = [int(r[0]) for p in asked for r in anchors[p]]
        body: dict[str, Any] = {
            "tracks": [{"point": p, "keyframes": anchors[p]} for p in asked],
            "first_frame": min(frames),
            "last_frame": self.frames - 1 if forward else max(frames)}
        if forward:
            body["follow"] = [{"point": p, "direction": "forward"} for p in forward]
        reply = _checked(self.client.http.post(f"{self.client.base}/api/annotate/proposals",
                                               headers=self.auth, json=body), "proposals")
        _fill_held(xy, ok, reply)
        return xy, ok

    def model_follow(self, anchors: list[list[list[Any]]], begin: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray] | None:
        """POST /api/annotate/model-follow with every point's anchors (and ``begin``: the
        frame the page is on when asked again after a start), asked again while it answers
        ``preparing`` (as the page's Follow hand does, for as long); nothing proposed where it
        says why not. None on an object task (the page offers it on hands only)."""
        if not self.hand:
            return None
        xy = np.full((self.frames, len(anchors), 2), np.nan)
        ok = np.zeros((self.frames, len(anchors)), dtype=bool)
        body: dict[str, Any] = {"tracks": [{"point": p, "keyframes": rows}
                                           for p, rows in enumerate(anchors) if rows]}
        if begin is not None:
            body["begin"] = begin
        reply = self._polled("POST", "/api/annotate/model-follow", "model follow", json=body)
        if reply.get("available"):
            _fill_held(xy, ok, reply)
        return xy, ok

    def _polled(self, method: str, path: str, step: str, **kwargs: Any) -> dict[str, Any]:
        """A route's answer, asked again every poll_s while it says ``preparing`` (a job on
        the worker queue), for poll_limit_s at most."""
        started = time.monotonic()
        while True:
            reply: dict[str, Any] = _checked(self.client.http.request(
                method, f"{self.client.base}{path}", headers=self.auth, **kwargs), step)
            if not reply.get("preparing") or time.monotonic() - started >= self.poll_limit_s:
                return reply
            time.sleep(self.poll_s)

    def suggestions(self) -> Prefill | None:
        """The view's suggestions as the page shows them (asked once: the page keeps them)."""
        if self._suggested is None:
            self._suggested = (self._ask_suggestions(),)
        return self._suggested[0]

    def _ask_suggestions(self) -> Prefill | None:
        reply = self._polled("GET", "/api/annotate/suggestions", "suggestions")
        if not reply.get("available") or not reply.get("points"):
            return None
        points = max(int(p["point"]) for p in reply["points"]) + 1
        xy = np.full((self.frames, points, 2), np.nan)
        visible = np.ones((self.frames, points), dtype=bool)
        known = np.zeros((self.frames, points), dtype=bool)
        first = int(reply["first_frame"])
        for point in reply["points"]:
            for i, (at, vis) in enumerate(zip(point["xy"], point["visible"], strict=True)):
                if at is not None:
                    xy[first + i, point["point"]] = at
                # The page takes a suggestion of unknown visibility as visible.
                visible[first + i, point["point"]] = vis is not False
                known[first + i, point["point"]] = vis is not None
        return Prefill(xy=xy, visible=visible, known=known)


def admin_token(http: httpx.Client, base: str, email: str, password: str) -> str:
    reply = _checked(http.post(f"{base.rstrip('/')}/api/auth/token",
                               json={"email": email, "password": password}), "admin log in")
    return reply["access_token"]


def _work_one(client: WorkerClient, admin: str, index: int, profile: str, truth: CaptureTruth,
              rng: np.random.Generator, only: Collection[str] | None = None,
              protocol: Protocol = "keyframes", model_follow: bool = True) -> WorkerOutcome:
    email = WORKER_EMAIL.format(index=index)
    token, worker_id = client.sign_in(admin, email, WORKER_PASSWORD.format(index=index))
    outcome = WorkerOutcome(email=email, worker_id=worker_id, profile=profile,
                            status="no HIT available")
    accepted = client.accept_first(token, only)
    if accepted is None or not accepted.get("work_url"):
        return outcome
    params, page_token, reply = client.open_page(accepted["work_url"])
    task = reply["task"]
    page = (PageAssistance(client, page_token, task, model=model_follow)
            if protocol == ASSISTED else None)
    # An object's landmarks are the worker's to pick, unless the page already suggests some:
    # a person then follows the spots they mark.
    suggested = page.suggestions() if page is not None and task["kind"] != "hand" else None
    xy, visible = truth.points(task, rng, None if suggested is None
                               else (suggested.xy, suggested.shown()))
    if page is not None:
        done = assisted_annotate(xy, visible, page, profile, rng)
        tracks, edits = done.tracks, done.actions["edits"]
    else:
        key_step, follow = PROTOCOLS[protocol]
        work = annotate(xy, visible, (task["width"], task["height"]), profile, rng, key_step,
                        follow)
        effort = keyframe_actions(work.tracks)
        tracks, edits = work.tracks, effort["clicks"] + effort["drags"] + effort["keys"]
    version = client.label(page_token, reply["assignment"]["version"], tracks, edits)
    client.external_submit(params, version)
    outcome.status, outcome.task_id = "submitted", task["id"]
    outcome.hit_id, outcome.assignment_id = params.get("hitId"), params["assignmentId"]
    return outcome


def draw_assisted(count: int, profile: str, rng: np.random.Generator) -> list[str]:
    """``count`` assisted profiles: all ``profile`` (careful or blind), or for ``mixed`` a
    blind acceptor with ASSISTED_BLIND_SHARE, careful otherwise."""
    if profile == "mixed":
        return ["blind" if b else "careful" for b in rng.random(count) < ASSISTED_BLIND_SHARE]
    if profile not in ASSISTED_PROFILES:
        raise ValueError(f"unknown profile {profile!r} for assisted work; one of "
                         f"{', '.join(ASSISTED_PROFILES)} or mixed")
    return [profile] * count


def simulate(base: str, capture: Path, workers: int, profile: str, admin_email: str,
             admin_password: str, seed: int = 0, first_index: int = 1,
             protocol: Protocol = "keyframes", model_follow: bool = True
             ) -> list[WorkerOutcome]:
    """Run ``workers`` simulated workers one after another against the app at ``base``.

    Worker i (from ``first_index``) is ``sim-worker-<i>`` with a deterministic password, so a
    re-run reuses the same accounts; a worker already done with every HIT on offer reports "no
    HIT available". Hand and object tasks alike are worked (object landmarks are mesh
    vertices followed through the object's true poses). A later round of a crowd starts
    where the last one ended (``first_index``), so HITs re-opened after a rejection go to
    workers who have not done them yet. ``model_follow``: assisted workers ask for the hand
    model's follow on hand views without suggestions (a job: the app needs a queue worker).
    """
    rng = np.random.default_rng(seed)
    profiles = (draw_assisted(workers, profile, rng) if protocol == ASSISTED
                else draw_profiles(workers, profile, rng))
    truth = CaptureTruth(capture)
    try:
        with httpx.Client(timeout=HTTP_TIMEOUT_S) as http:
            admin = admin_token(http, base, admin_email, admin_password)
            client = WorkerClient(http, base)
            return [_work_one(client, admin, first_index + i, name, truth, rng,
                              protocol=protocol, model_follow=model_follow)
                    for i, name in enumerate(profiles)]
    except httpx.HTTPError as exc:
        raise SimulationError(f"could not reach the app at {base}: {exc}") from exc
