"""Browser tests: the real annotation page in Debian's Chromium (headless), driven by Playwright,
against the real app served by uvicorn in a subprocess on a free port.

One server per session (SQLite database, local storage, a small synthetic capture imported);
every test takes fresh assignments through the admin API, so tests do not share work.
Screenshots go to tests/browser/output/ (or $DEXLABEL_TEST_OUTPUT).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlencode

import httpx
import numpy as np
import pytest

from tests.conftest import reset_caches

CHROMIUM = os.environ.get("DEXLABEL_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
ADMIN_EMAIL = "browser-tests@example.org"
ADMIN_PASSWORD = "browser-tests-password"
# A short clip keeps the tests quick; 2 views so tests can use different tasks.
CLIP_FRAMES = 12
CLIP_VIEWS = 2
VIEWPORT = {"width": 1440, "height": 900}
# What a page shows after a server round trip (an overlay rendered, a job's result) can take
# several seconds on a loaded machine: assertions on it wait this long, as actions do.
EXPECT_TIMEOUT_MS = 15_000


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class LiveServer:
    """The running app, with admin helpers to set up tasks and assignments."""

    base: str
    capture: Path
    sequence_id: int
    admin_token: str
    tasks: list[dict] = field(default_factory=list)
    # The settings the server runs with (for a queue worker started beside it).
    env: dict[str, str] = field(default_factory=dict)

    def admin(self, method: str, path: str, json: dict | None = None) -> dict | list:
        headers = {"Authorization": f"Bearer {self.admin_token}"}
        resp = httpx.request(method, self.base + path, json=json, headers=headers, timeout=30)
        assert resp.status_code == 200, resp.text
        return resp.json()

    def task(self, kind: str, view: int = 0) -> dict:
        serials = sorted({t["serial"] for t in self.tasks})
        return next(t for t in self.tasks if t["kind"] == kind and t["serial"] == serials[view])

    def assign(self, task: dict, worker: str = "W1") -> dict:
        """A new assignment of ``task``: {"assignment_id", "external_id", "token", "page_url"}."""
        return self.admin("POST", f"/api/tasks/{task['id']}/assignments", {"worker_id": worker})

    def worker_get_task(self, token: str) -> dict:
        resp = httpx.get(f"{self.base}/api/annotate/task", timeout=30,
                         headers={"Authorization": f"Bearer {token}"})
        assert resp.status_code == 200, resp.text
        return resp.json()

    def page_url(self, token: str, **extra: str) -> str:
        query = f"?{urlencode(extra)}" if extra else ""
        return f"{self.base}/annotate/{query}#{urlencode({'token': token})}"

    def truth(self, serial: str, frame: int) -> np.ndarray:
        """Ground-truth 2D joints (21 x 2, image px) of the synthetic hand in one frame."""
        folder = next(self.capture.glob(f"*/*/{serial}"))
        return np.load(folder / f"labels_{frame:06d}.npz")["joint_2d"][0].astype(float)


def _wait_up(base: str, proc: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the server exited during start-up; see {log}")
        try:
            if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"the server did not start in 60 s; see {log}")


def _prepare_database(env: dict[str, str], capture: Path) -> int:
    """Migrate, create the admin and import the capture, in this process under ``env``."""
    from backend.accounts.service import create_admin
    from backend.captures.flows import import_path
    from backend.db import session_scope
    from backend.migrate import upgrade

    with pytest.MonkeyPatch.context() as mp:
        for key, value in env.items():
            mp.setenv(key, value)
        reset_caches()
        try:
            upgrade(env["DEXLABEL_DATABASE_URL"])
            with session_scope() as session:
                create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
            return import_path(capture)[0].sequence_id
        finally:
            reset_caches()


@pytest.fixture(scope="session")
def output_dir() -> Path:
    out = Path(os.environ.get("DEXLABEL_TEST_OUTPUT", Path(__file__).parent / "output"))
    out.mkdir(parents=True, exist_ok=True)
    return out


@pytest.fixture(scope="session")
def live_server(tmp_path_factory: pytest.TempPathFactory, output_dir: Path) -> Iterator[LiveServer]:
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("browser")
    capture = root / "capture"
    generate_capture(capture, seed=5, frames=CLIP_FRAMES, views=CLIP_VIEWS, objects=1)
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    env = {
        "DEXLABEL_VAR_DIR": str(root / "var"),
        "DEXLABEL_DATABASE_URL": f"sqlite:///{root / 'browser.db'}",
        "DEXLABEL_STORAGE_URL": str(root / "storage"),
        "DEXLABEL_ENV": "test",
        "DEXLABEL_INPROCESS_WORKER": "false",
        "DEXLABEL_PUBLIC_URL": base,
    }
    sequence_id = _prepare_database(env, capture)
    log = output_dir / "server.log"
    with log.open("w") as log_file:
        proc = subprocess.Popen(
            [sys.executable, "-m", "backend.cli", "serve", "--port", str(port)],
            env={**os.environ, **env}, stdout=log_file, stderr=subprocess.STDOUT)
        try:
            _wait_up(base, proc, log)
            token = httpx.post(f"{base}/api/auth/token", timeout=30, json={
                "email": ADMIN_EMAIL, "password": ADMIN_PASSWORD}).json()["access_token"]
            server = LiveServer(base=base, capture=capture, sequence_id=sequence_id,
                                admin_token=token, env=env)
            server.tasks = server.admin("POST", f"/api/sequences/{sequence_id}/tasks")
            yield server
        finally:
            proc.terminate()
            proc.wait(timeout=20)


@pytest.fixture(scope="session")
def browser() -> Iterator:
    from playwright.sync_api import expect, sync_playwright

    from tests.conftest import REQUIRE_SERVICES

    if not Path(CHROMIUM).exists():
        message = f"Chromium is not installed at {CHROMIUM} (apt-get install chromium)"
        if REQUIRE_SERVICES:
            pytest.fail(message)
        pytest.skip(message)
    expect.set_options(timeout=EXPECT_TIMEOUT_MS)
    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield chromium
        chromium.close()


@pytest.fixture
def context(browser) -> Iterator:
    ctx = browser.new_context(viewport=VIEWPORT)
    ctx.set_default_timeout(15000)
    yield ctx
    ctx.close()


@pytest.fixture
def page(context) -> Iterator:
    """A page whose uncaught script errors fail the test."""
    p = context.new_page()
    errors: list[str] = []
    p.on("pageerror", lambda exc: errors.append(str(exc)))
    yield p
    assert not errors, f"uncaught errors in the page: {errors}"
