"""The logins the demo prints work in a browser: after `dexlabel demo --no-serve`, `dexlabel
serve` on the same port (as the demo says) serves the worker portal and the admin page, and
each printed email and password signs in. Screenshots of each sign-in form and the page behind
it at 1440 x 900 and 1024 x 700 go to the browser tests' output folder."""

from __future__ import annotations

import re
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port
from tests.browser.conftest import VIEWPORT

NARROW = {"width": 1024, "height": 700}
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


def _sign_in(page: Page, url: str, email: str, password: str, shots: Path) -> None:
    """Sign in with the form, screenshot (shots-login[-1024].png) at both sizes first."""
    page.goto(url)
    for suffix, size in (("-1024", NARROW), ("", VIEWPORT)):
        page.set_viewport_size(size)
        expect(page.locator("#login")).to_be_visible()
        page.screenshot(path=f"{shots}-login{suffix}.png")
    page.locator("#login input[name=email]").fill(email)
    page.locator("#login input[name=password]").fill(password)
    page.locator("#login button[type=submit]").click()


def _screenshots(page: Page, shots: Path) -> None:
    """The signed-in page at both sizes (shots[-1024].png); the narrow one scrolls no wider."""
    page.screenshot(path=f"{shots}.png")
    page.set_viewport_size(NARROW)
    assert page.evaluate("document.documentElement.scrollWidth") <= NARROW["width"]
    page.screenshot(path=f"{shots}-1024.png")
    page.set_viewport_size(VIEWPORT)


def _sign_out_revokes(page: Page, storage_key: str, me_url: str) -> None:
    """Sign out: the form is back, and the token the page held is refused by the server."""
    token = page.evaluate(f"sessionStorage.getItem('{storage_key}')")
    headers = {"Authorization": f"Bearer {token}"}
    assert token and httpx.get(me_url, headers=headers, timeout=10).status_code == 200
    page.locator("#sign-out").click()
    expect(page.locator("#login")).to_be_visible()
    assert page.evaluate(f"sessionStorage.getItem('{storage_key}')") is None
    assert httpx.get(me_url, headers=headers, timeout=10).status_code == 401


def test_the_printed_worker_login_opens_the_portal(page: Page, demo_logins: dict,
                                                   output_dir: Path) -> None:
    url, email, password = demo_logins["worker portal"]
    _sign_in(page, url, email, password, output_dir / "demo-portal")
    expect(page.locator("#hits-view")).to_be_visible()
    _screenshots(page, output_dir / "demo-portal")
    _sign_out_revokes(page, "dexlabel.portal.token", url.replace("/market/", "/api/portal/me"))


def test_the_printed_admin_login_opens_the_admin_page(page: Page, demo_logins: dict,
                                                      output_dir: Path) -> None:
    url, email, password = demo_logins["admin page"]
    _sign_in(page, url, email, password, output_dir / "demo-admin")
    expect(page.locator("#sequences-view")).to_be_visible()
    _screenshots(page, output_dir / "demo-admin")
    _sign_out_revokes(page, "dexlabel.admin.token", url.replace("/admin/", "/api/auth/me"))
