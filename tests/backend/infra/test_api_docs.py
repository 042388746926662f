"""The interactive API documentation (/docs) is served whole by the app: every script, style
and icon its page names is on the app and answers with the right content type."""

from __future__ import annotations

import re
from html.parser import HTMLParser

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app

# What each kind of reference must answer with.
CONTENT_TYPES = {"script": "text/javascript", "stylesheet": "text/css", "icon": "image/"}


class _References(HTMLParser):
    """(kind, url) of every <script src> and <link href> of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.found: list[tuple[str, str]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "script" and a.get("src"):
            self.found.append(("script", a["src"] or ""))
        elif tag == "link" and a.get("href"):
            rel = a.get("rel") or ""
            self.found.append(("icon" if "icon" in rel else rel, a["href"] or ""))


def _references(html: str) -> list[tuple[str, str]]:
    parser = _References()
    parser.feed(html)
    # Swagger UI gets its spec's address in the page's own script.
    parser.found += [("spec", url) for url in re.findall(r"\burl:\s*'([^']+)'", html)]
    return parser.found


@pytest.fixture(scope="module")
def client() -> TestClient:
    return TestClient(create_app())


def test_docs_page_loads_every_asset_from_the_app(client: TestClient) -> None:
    resp = client.get("/docs")
    assert resp.status_code == 200 and resp.headers["content-type"].startswith("text/html")
    refs = _references(resp.text)
    assert {kind for kind, _ in refs} == {"script", "stylesheet", "icon", "spec"}, refs
    assert not re.search(r"(src|href)=\"(https?:)?//", resp.text), "a reference leaves the app"
    for kind, url in refs:
        assert url.startswith("/") and not url.startswith("//"), f"{kind} {url} is not on the app"
        asset = client.get(url)
        assert asset.status_code == 200, f"{url}: {asset.status_code}"
        content_type = asset.headers["content-type"]
        if kind == "spec":
            assert content_type == "application/json"
            assert asset.json()["info"]["title"] == "dexlabel"
        else:
            assert content_type.startswith(CONTENT_TYPES[kind]), f"{url}: {content_type}"
            assert len(asset.content) > 1000, f"{url} is nearly empty"


def test_swagger_ui_asks_no_outside_validator(client: TestClient) -> None:
    assert '"validatorUrl": null' in client.get("/docs").text


def test_docs_page_is_not_an_operation_of_the_api(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert not any(p.startswith("/docs") for p in paths)
