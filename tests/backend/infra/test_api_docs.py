"""The interactive API documentation (/docs) is served whole by the app: every script, style
and icon its page names is on the app and answers with the right content type."""

from __future__ import annotations

import re
from collections.abc import Callable
from html.parser import HTMLParser
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.routing import APIRoute, iter_route_contexts
from fastapi.testclient import TestClient

from backend.accounts.deps import current_admin, current_worker
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


def _calls(dependant: Any) -> set[Any]:
    """Every function a route's dependencies call, however deep."""
    found = {dependant.call}
    for sub in dependant.dependencies:
        found |= _calls(sub)
    return found


def _operations_needing(app: FastAPI, dependency: Callable[..., Any]) -> set[tuple[str, str]]:
    """(method, path) of every operation whose dependencies include ``dependency``."""
    found = set()
    for route in iter_route_contexts(app.routes):
        original = route.original_route
        if (isinstance(original, APIRoute) and original.include_in_schema
                and dependency in _calls(original.dependant)):
            found |= {(m.lower(), route.path) for m in route.methods or ()}
    return found


def test_the_api_document_declares_the_bearer_scheme_that_admin_routes_use() -> None:
    """/docs shows an Authorize button: the document declares HTTP bearer, and every admin
    and worker operation asks for it, so a token given there is sent with them."""
    app = create_app()
    doc = app.openapi()
    scheme = doc["components"]["securitySchemes"]["bearer"]
    assert (scheme["type"], scheme["scheme"]) == ("http", "bearer")
    assert "POST /api/auth/token" in scheme["description"]
    admin = _operations_needing(app, current_admin)
    worker = _operations_needing(app, current_worker)
    assert len(admin) > 20 and ("get", "/api/jobs") in admin and worker
    for method, path in admin | worker:
        assert doc["paths"][path][method].get("security") == [{"bearer": []}], (method, path)
    # What one calls to get a token, and the health check, ask for none.
    for method, path in (("post", "/api/auth/token"), ("post", "/api/portal/login"),
                         ("get", "/healthz")):
        assert "security" not in doc["paths"][path][method], (method, path)


def test_an_admin_route_answers_the_token_the_docs_page_sends(client: TestClient) -> None:
    """Swagger UI sends the authorised token as `Authorization: Bearer`; without one the
    answer is our own 401 in the error shape, not FastAPI's 403."""
    refused = client.get("/api/jobs")
    assert refused.status_code == 401 and refused.json()["error"] == "unauthorized"
    wrong = client.get("/api/jobs", headers={"Authorization": "Basic abc"})
    assert wrong.status_code == 401 and wrong.json()["error"] == "unauthorized"


def test_the_root_page_links_the_worker_portal_admin_page_and_docs(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    links = re.findall(r'<a href="([^"]+)">([^<]+)</a>', page.text)
    assert ("/market/", "Worker portal") in links
    assert {"/admin/", "/docs"} <= {href for href, _ in links}
    for href, _ in links:
        assert client.get(href).status_code == 200, href
