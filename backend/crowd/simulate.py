"""A simulated crowd: workers who do exactly what a browser does, over HTTP, against a running app.

Each worker gets a portal account (created through the admin API, or reused), signs in, lists
the HITs, accepts one, opens the annotation page's assignment (``/api/annotate/start`` with the
task token of the work URL), autosaves its tracks twice, submits them, and posts the
marketplace's completion form to ``{turkSubmitTo}/mturk/externalSubmit``. The labels come from
the ground truth of a synthetic capture (matched by the task's camera serial), spoiled by the
worker's profile (worker.synth.annotators).
"""

from __future__ import annotations

import time
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import numpy as np

from backend.captures.layout import SequencePlan, read_sequence
from backend.errors import DexlabelError
from worker.formats import dexycb
from worker.geometry.cameras import CameraModel, intrinsics_matrix
from worker.geometry.mesh_io import read_mesh
from worker.synth.annotators import annotate, draw_profiles, hand_visibility, mesh_landmarks

WORKER_EMAIL = "sim-worker-{index:03d}@simulated.dexlabel.org"
WORKER_PASSWORD = "simulated worker {index:03d}"
HTTP_TIMEOUT_S = 30.0
# Attempts of a request that a server error left without effect, and the pause between them.
RETRIES = 3
RETRY_PAUSE_S = 0.2
# Centroid splits of an object's mesh before landmarks are picked (see surface_points).
SURFACE_LEVELS = 2


class SimulationError(DexlabelError):
    """A step of the worker flow answered with an error."""

    status_code = 502
    code = "simulation_failed"


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


def surface_points(vertices: np.ndarray, faces: np.ndarray,
                   levels: int = SURFACE_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """The same surface with a point added at each triangle's centroid (split in three),
    ``levels`` times: (N', 3) vertices and (M', 3) faces.

    A person picks landmarks anywhere on the object, not only at mesh vertices; on a coarse
    mesh (the synthetic box has 8 corners, each on the silhouette in most views) the corners
    alone rarely give two clearly visible landmarks. Centroids inherit their face's normal.
    """
    for _ in range(levels):
        centroids = vertices[faces].mean(axis=1)
        ids = np.arange(len(vertices), len(vertices) + len(faces))
        a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
        faces = np.concatenate([np.stack([a, b, ids], 1), np.stack([b, c, ids], 1),
                                np.stack([c, a, ids], 1)])
        vertices = np.concatenate([vertices, centroids])
    return vertices, faces


class CaptureTruth:
    """Ground truth of a synthetic capture's views, read once per view (serial)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self._views: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._plans: dict[Path, SequencePlan] = {}

    def _folder(self, serial: str) -> Path:
        found = sorted(p for p in self.root.glob(f"*/*/{serial}") if p.is_dir())
        if not found:
            raise SimulationError(f"the capture at {self.root} has no view {serial!r}")
        return found[0]

    def _labels(self, serial: str, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, 21, 2) joint_2d px, (F, H, W) seg and (F, O, 3, 4) object-to-camera pose_y of
        one view, each label file read once."""
        if serial not in self._views:
            folder = self._folder(serial)
            joints, segs, poses = [], [], []
            for f in range(frames):
                with np.load(folder / dexycb.labels_file(f)) as labels:
                    joints.append(labels[dexycb.JOINT_2D][0].astype(np.float64))
                    segs.append(labels[dexycb.SEG])
                    poses.append(labels[dexycb.POSE_Y].astype(np.float64))
            self._views[serial] = (np.stack(joints), np.stack(segs), np.stack(poses))
        return self._views[serial]

    def _shown(self, serial: str, frames: int) -> np.ndarray:
        """(F,) the truth frame each of the view's image frames shows: a camera of a capture
        with rig faults may be late (worker.synth.faults); workers label what they see."""
        from worker.synth.faults import shown_frames

        return shown_frames(self.root, serial, frames)

    def view(self, serial: str, frames: int) -> tuple[np.ndarray, np.ndarray]:
        """(F, 21, 2) joint_2d px and (F, H, W) seg of one view, as its images show them."""
        joint_2d, seg, _ = self._labels(serial, frames)
        shown = self._shown(serial, frames)
        return joint_2d[shown], seg[shown]

    def _plan(self, folder: Path) -> SequencePlan:
        if folder not in self._plans:
            self._plans[folder] = read_sequence(folder)
        return self._plans[folder]

    def object_points(self, serial: str, index: int, frames: int,
                      rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Two landmarks on object ``index`` in one view: surface points visible where it first
        shows, followed through its true poses as the view's images show them; (F, 2, 2) px
        and (F, 2) visibility."""
        plan = self._plan(self._folder(serial).parent)
        cam = next(c for c in plan.cameras if c.serial == serial)
        # The view's own camera frame as the world: the labels' pose_y are object-to-camera.
        camera = CameraModel(intrinsics_matrix(cam.fx, cam.fy, cam.ppx, cam.ppy),
                             np.asarray(cam.distortion), np.eye(3, 4), cam.width, cam.height)
        mesh = read_mesh(plan.objects[index].mesh_path)
        _, seg, poses = self._labels(serial, frames)
        shown = self._shown(serial, frames)
        seg, poses = seg[shown], poses[shown]
        vertices, faces = surface_points(np.asarray(mesh.vertices, float),
                                         np.asarray(mesh.faces, int))
        xy, visible, _ = mesh_landmarks(camera, seg, int(plan.objects[index].ycb_id), vertices,
                                        faces, poses[:, index], rng)
        return xy, visible

    def object_poses(self) -> np.ndarray:
        """(O, F, 3, 4) true object-to-world poses of the capture's (first) sequence, metres,
        from its first view's labels (object-to-camera) and that camera's extrinsics."""
        seq_dir = min(p.parent for p in self.root.glob(f"*/*/{dexycb.META_FILE}"))
        plan = self._plan(seq_dir)
        camera = plan.cameras[0]
        _, _, in_cam = self._labels(camera.serial, plan.num_frames)
        to_world = np.asarray(camera.extrinsics, dtype=np.float64)
        rot = np.einsum("ij,fojk->ofik", to_world[:, :3], in_cam[..., :3])
        trans = np.einsum("ij,foj->ofi", to_world[:, :3], in_cam[..., 3]) + to_world[:, 3]
        return np.concatenate([rot, trans[..., None]], axis=-1)

    def points(self, task: dict, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The task's true points (F, P, 2) px and visibility (F, P)."""
        if task["kind"] == "hand":
            joint_2d, seg = self.view(task["serial"], task["num_frames"])
            return joint_2d, hand_visibility(joint_2d, seg)
        return self.object_points(task["serial"], int(task["target_key"].split(":")[1]),
                                  task["num_frames"], rng)


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

    def label(self, token: str, version: int, tracks: list[list[list[float | None]]]) -> int:
        """Autosave half the points, then all of them, then submit; the final version."""
        auth = {"Authorization": f"Bearer {token}"}
        body = [{"point": p, "keyframes": rows} for p, rows in enumerate(tracks)]
        for step, part in enumerate((body[: len(body) // 2 or 1], body)):
            saved = _checked(self.http.put(f"{self.base}/api/annotate/tracks", headers=auth, json={
                "version": version, "tracks": part, "edit_count": 10 * (step + 1),
                "working_time_s": 60.0 * (step + 1)}), "autosave tracks")
            version = saved["version"]
        done = _checked(self.http.post(f"{self.base}/api/annotate/submit", headers=auth, json={
            "version": version, "tracks": body, "edit_count": 25, "working_time_s": 150.0}),
            "submit tracks")
        return int(done["version"])

    def external_submit(self, params: dict[str, str], version: int) -> None:
        """The completion form the page posts to the marketplace."""
        url = f"{params['turkSubmitTo'].rstrip('/')}/mturk/externalSubmit"
        form = {"assignmentId": params["assignmentId"], "result": f"submitted:{version}"}
        _checked(self.http.post(url, data=form), "post externalSubmit")


def admin_token(http: httpx.Client, base: str, email: str, password: str) -> str:
    reply = _checked(http.post(f"{base.rstrip('/')}/api/auth/token",
                               json={"email": email, "password": password}), "admin log in")
    return reply["access_token"]


def _work_one(client: WorkerClient, admin: str, index: int, profile: str, truth: CaptureTruth,
              rng: np.random.Generator, only: Collection[str] | None = None) -> WorkerOutcome:
    email = WORKER_EMAIL.format(index=index)
    token, worker_id = client.sign_in(admin, email, WORKER_PASSWORD.format(index=index))
    outcome = WorkerOutcome(email=email, worker_id=worker_id, profile=profile,
                            status="no HIT available")
    accepted = client.accept_first(token, only)
    if accepted is None or not accepted.get("work_url"):
        return outcome
    params, page_token, reply = client.open_page(accepted["work_url"])
    task = reply["task"]
    xy, visible = truth.points(task, rng)
    work = annotate(xy, visible, (task["width"], task["height"]), profile, rng)
    version = client.label(page_token, reply["assignment"]["version"], work.tracks)
    client.external_submit(params, version)
    outcome.status, outcome.task_id = "submitted", task["id"]
    outcome.hit_id, outcome.assignment_id = params.get("hitId"), params["assignmentId"]
    return outcome


def simulate(base: str, capture: Path, workers: int, profile: str, admin_email: str,
             admin_password: str, seed: int = 0, first_index: int = 1) -> list[WorkerOutcome]:
    """Run ``workers`` simulated workers one after another against the app at ``base``.

    Worker i (from ``first_index``) is ``sim-worker-<i>`` with a deterministic password, so a
    re-run reuses the same accounts; a worker already done with every HIT on offer reports "no
    HIT available". Hand and object tasks alike are worked (object landmarks are mesh
    vertices followed through the object's true poses). A later round of a crowd starts
    where the last one ended (``first_index``), so HITs re-opened after a rejection go to
    workers who have not done them yet.
    """
    rng = np.random.default_rng(seed)
    profiles = draw_profiles(workers, profile, rng)
    truth = CaptureTruth(capture)
    try:
        with httpx.Client(timeout=HTTP_TIMEOUT_S) as http:
            admin = admin_token(http, base, admin_email, admin_password)
            client = WorkerClient(http, base)
            return [_work_one(client, admin, first_index + i, name, truth, rng)
                    for i, name in enumerate(profiles)]
    except httpx.HTTPError as exc:
        raise SimulationError(f"could not reach the app at {base}: {exc}") from exc
