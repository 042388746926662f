"""The logins the demo prints work in a browser: after `dexlabel demo --no-serve`, `dexlabel
serve` on the same port (as the demo says) serves the worker portal and the admin page, and
each printed email and password signs in."""

from __future__ import annotations

import re
import subprocess
import time
from collections.abc import Iterator

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.cli.conftest import DEXLABEL, clean_env, free_port

LOGIN = re.compile(r"^(worker portal|admin page): +(http://\S+) +email (\S+) +password (\S+)$",
                   re.MULTILINE)


@pytest.fixture(scope="module")
def demo_logins(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, tuple]]:
    """A small demo (no simulated crowd), then its instance served; the printed logins."""
    root = tmp_path_factory.mktemp("demo-logins")
    port = free_port()
    env = clean_env(DEXLABEL_VAR_DIR=str(root / "var"))
    done = subprocess.run(
        [*DEXLABEL, "demo", "--no-serve", "--no-simulate", "--port", str(port), "--frames", "6",
         "--views", "2", "--objects", "1"],
        env=env, cwd=root, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    found = {m[1]: (m[2], m[3], m[4]) for m in LOGIN.finditer(done.stdout)}
    assert set(found) == {"worker portal", "admin page"}, done.stdout
    server = subprocess.Popen([*DEXLABEL, "serve", "--port", str(port)], env=env, cwd=root,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                assert server.poll() is None and time.monotonic() < deadline, "no server"
                time.sleep(0.2)
        yield found
    finally:
        server.terminate()
        server.wait(timeout=30)


def _sign_in(page: Page, url: str, email: str, password: str) -> None:
    page.goto(url)
    page.locator("#login input[name=email]").fill(email)
    page.locator("#login input[name=password]").fill(password)
    page.locator("#login button[type=submit]").click()


def test_the_printed_worker_login_opens_the_portal(page: Page, demo_logins: dict) -> None:
    url, email, password = demo_logins["worker portal"]
    _sign_in(page, url, email, password)
    expect(page.locator("#hits-view")).to_be_visible()


def test_the_printed_admin_login_opens_the_admin_page(page: Page, demo_logins: dict) -> None:
    url, email, password = demo_logins["admin page"]
    _sign_in(page, url, email, password)
    expect(page.locator("#sequences-view")).to_be_visible()
