"""The API's contract, against the real app served by uvicorn on a seeded database (SQLite and
PostgreSQL, where NUL characters and 32-bit integers matter):

- schemathesis (its command line, deterministic, a bounded number of examples) over every
  operation, anonymous and with each kind of token: no server error, and every answer's
  status, content type, headers and body as the OpenAPI document declares them;
- every route the app has refuses callers without the right token: a route is an admin route
  unless it is on the public list or serves workers, pages or frames;
- every integer, number and path name the API takes is bounded in the OpenAPI document;
- request guards: NUL characters, out-of-range numbers, bodies past their limit (chunked too),
  marketplace refusals of the caller's values, dates with their time zone.
"""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

from backend.validation import MAX_ABS_FLOAT, MAX_INT32, MAX_KEY_LENGTH, MIN_INT32
from tests.conftest import _drop_all, reset_caches

ADMIN_EMAIL = "contract-admin@example.org"
ADMIN_PASSWORD = "contract admin password"
WORKER_EMAIL = "contract-worker@example.org"
WORKER_PASSWORD = "contract worker password"

# Examples per operation in schemathesis's fuzzing phase (its coverage phase adds the edge
# cases: boundaries, NUL characters, huge numbers).
ADMIN_EXAMPLES = 10
OTHER_EXAMPLES = 5
CHECKS = ",".join([
    "not_a_server_error", "status_code_conformance", "content_type_conformance",
    "response_headers_conformance", "response_schema_conformance", "unsupported_method",
    "allow_header_conformance",
])


@dataclass
class Served:
    """The app at ``base`` with one sequence, its tasks published, and a token of each kind."""

    base: str
    tokens: dict[str, str]
    sequence_id: int
    task_id: int
    serial: str
    backend: str
    root: Path
    log: list[str] = field(default_factory=list)

    def headers(self, kind: str | None) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[kind]}"} if kind else {}


def _free_socket() -> socket.socket:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    return sock


def _seed(client: httpx.Client, capture: Path) -> tuple[dict[str, str], int, dict]:
    """Through the API: the capture imported, its tasks created and published, a worker
    account, and a token of each kind."""
    def ok(resp: httpx.Response) -> Any:
        assert resp.status_code == 200, f"{resp.request.method} {resp.request.url}: {resp.text}"
        return resp.json()

    tokens = {"admin": ok(client.post("/api/auth/token", json={
        "email": ADMIN_EMAIL, "password": ADMIN_PASSWORD}))["access_token"]}
    admin = {"Authorization": f"Bearer {tokens['admin']}"}
    imported = ok(client.post("/api/captures/import", json={"path": str(capture)},
                              headers=admin))
    sequence_id = imported[0]["sequence_id"]
    task = ok(client.post(f"/api/sequences/{sequence_id}/tasks", headers=admin))[0]
    tokens["assignment"] = ok(client.post(f"/api/tasks/{task['id']}/assignments",
                                          json={"worker_id": "W1"}, headers=admin))["token"]
    tokens["task"] = ok(client.post(f"/api/tasks/{task['id']}/preview-token",
                                    headers=admin))["token"]
    tokens["view"] = ok(client.post(
        f"/api/sequences/{sequence_id}/views/{task['serial']}/token", headers=admin))["token"]
    ok(client.post("/api/portal/workers", headers=admin,
                   json={"email": WORKER_EMAIL, "password": WORKER_PASSWORD}))
    tokens["portal"] = ok(client.post("/api/portal/login", json={
        "email": WORKER_EMAIL, "password": WORKER_PASSWORD}))["access_token"]
    ok(client.post("/api/crowd/publish", json={"sequence_id": sequence_id}, headers=admin))
    return tokens, sequence_id, task


@pytest.fixture(scope="module", params=["sqlite", "postgres"])
def served(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory,
           small_capture: Path) -> Iterator[Served]:
    import uvicorn

    from backend.accounts.service import create_admin
    from backend.app import create_app
    from backend.db import session_scope
    from backend.migrate import upgrade

    root = tmp_path_factory.mktemp(f"contract-{request.param}")
    if request.param == "sqlite":
        url = f"sqlite:///{root / 'contract.db'}"
    else:
        url = request.getfixturevalue("postgres_server_url")
        _drop_all(url)
    sock = _free_socket()
    base = f"http://127.0.0.1:{sock.getsockname()[1]}"
    with pytest.MonkeyPatch.context() as mp:
        for key, value in {
            "DEXLABEL_VAR_DIR": str(root / "var"), "DEXLABEL_DATABASE_URL": url,
            "DEXLABEL_STORAGE_URL": str(root / "storage"), "DEXLABEL_ENV": "test",
            "DEXLABEL_PUBLIC_URL": base, "DEXLABEL_CAPTURE_ROOTS": str(small_capture),
        }.items():
            mp.setenv(key, value)
        for key in ("DEXLABEL_MTURK_ENDPOINT_URL", "DEXLABEL_MTURK_ACCESS_KEY_ID",
                    "DEXLABEL_MTURK_SECRET_ACCESS_KEY", "DEXLABEL_REDIS_URL"):
            mp.delenv(key, raising=False)
        reset_caches()
        upgrade(url)
        with session_scope() as session:
            create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        server = uvicorn.Server(uvicorn.Config(create_app(), log_level="warning",
                                               lifespan="off"))
        thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
        thread.start()
        deadline = time.monotonic() + 20
        while not server.started:
            assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
            time.sleep(0.01)
        try:
            with httpx.Client(base_url=base, timeout=60) as client:
                tokens, sequence_id, task = _seed(client, small_capture)
            yield Served(base, tokens, sequence_id, task["id"], task["serial"], request.param,
                         root)
        finally:
            server.should_exit = True
            thread.join(timeout=20)
            sock.close()
            reset_caches()
    if request.param == "postgres":
        _drop_all(url)


# ----- request guards --------------------------------------------------------------------

def test_nul_characters_are_refused_naming_the_field(served: Served) -> None:
    admin = served.headers("admin")
    with httpx.Client(base_url=served.base, timeout=30) as client:
        resp = client.post("/api/portal/login", json={"email": "a\x00b@example.org",
                                                      "password": "x"})
        assert resp.status_code == 422, resp.text
        assert resp.json()["fields"][0]["field"] == "email"
        resp = client.post("/api/auth/token", json={"email": ADMIN_EMAIL,
                                                    "password": "nul\x00here"})
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "password"
        resp = client.get("/api/jobs", params={"kind": "frame\x00stats"}, headers=admin)
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "query.kind"
        resp = client.get(f"/api/sequences/{served.sequence_id}/views/ab%00c/frames",
                          headers=admin)
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "path"
        resp = client.post("/api/crowd/workers/AWORKER/block", json={"reason": "spam\x00"},
                           headers=admin)
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "reason"


def test_numbers_out_of_range_are_refused_naming_the_field(served: Served) -> None:
    admin, page = served.headers("admin"), served.headers("assignment")
    with httpx.Client(base_url=served.base, timeout=30) as client:
        frame = f"/api/sequences/{served.sequence_id}/views/{served.serial}/frames/{2**40}.jpg"
        for path in (f"/api/jobs/{2**63}", f"/api/jobs/{2**31}", frame):
            resp = client.get(path, headers=admin)
            assert resp.status_code == 422, (path, resp.text)
            assert resp.json()["fields"][0]["field"].startswith("path.")
        resp = client.get("/api/tasks", params={"sequence_id": 2**63}, headers=admin)
        assert resp.status_code == 422
        assert resp.json()["fields"][0]["field"] == "query.sequence_id"
        save = {"version": 2**63, "tracks": []}
        resp = client.put("/api/annotate/tracks", json=save, headers=page)
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "version"
        # x = 10**400: no float holds it.
        huge_x = ('{"version": 0, "tracks": [{"point": 0, "keyframes": [[0, 1' + "0" * 400
                  + ', 5, 1]]}]}')
        resp = client.put("/api/annotate/tracks", content=huge_x, headers={
            **page, "Content-Type": "application/json"})
        assert resp.status_code == 422, resp.text
        assert resp.json()["error"] == "invalid_tracks"
        assert "keyframe 0 (frame 0): x is too large" in resp.json()["detail"], resp.text
        resp = client.put(f"/api/tasks/{served.task_id}/highlight",
                          content='{"box": [0, 0, 1e400, 5]}',
                          headers={**admin, "Content-Type": "application/json"})
        assert resp.status_code == 422, resp.text


def test_a_marketplace_refusal_of_the_callers_values_is_422_naming_the_field(
    served: Served
) -> None:
    admin = served.headers("admin")
    with httpx.Client(base_url=served.base, timeout=60) as client:
        # MTurk worker ids are "A" and capitals or digits: the marketplace refuses this one.
        resp = client.post("/api/crowd/workers/not-a-worker/block", json={"reason": "spam"},
                           headers=admin)
        assert resp.status_code == 422, resp.text
        body = resp.json()
        assert body["error"] == "marketplace_refused"
        assert [f["field"] for f in body["fields"]] == ["worker_id"]
        resp = client.post("/api/crowd/notify", headers=admin, json={
            "worker_ids": [""], "subject": "hello", "message": "hello"})
        assert resp.status_code == 422, resp.text
        assert [f["field"] for f in resp.json()["fields"]] == ["worker_ids"]


def test_dates_carry_their_time_zone(served: Served) -> None:
    admin = served.headers("admin")
    with httpx.Client(base_url=served.base, timeout=30) as client:
        sequence = client.get(f"/api/sequences/{served.sequence_id}", headers=admin).json()
        jobs = client.get("/api/jobs", headers=admin).json()
    stamps = [sequence["created_at"]] + [job["created_at"] for job in jobs]
    assert len(stamps) > 1
    for stamp in stamps:
        assert re.search(r"(Z|[+-]\d\d:\d\d)$", stamp), stamp


def test_body_limit_holds_for_chunked_bodies(served: Served) -> None:
    """A 60 MB chunked body is refused after the first megabyte, without reading the rest,
    on a route with its own limit (a save) and on one with the default."""
    sent = [0]

    def chunks() -> Iterator[bytes]:
        yield b'{"version": 0, "tracks": [], "pad": "'
        for _ in range(60 * 16):
            sent[0] += 65536
            yield b"x" * 65536
        yield b'"}'

    with httpx.Client(base_url=served.base, timeout=60) as client:
        for path, headers in (("/api/annotate/tracks", served.headers("assignment")),
                              ("/api/auth/token", {})):
            sent[0] = 0
            started = time.monotonic()
            method = "PUT" if path.endswith("tracks") else "POST"
            resp = client.request(method, path, content=chunks(),
                                  headers={**headers, "Content-Type": "application/json"})
            assert resp.status_code == 413, resp.text
            assert resp.json()["error"] == "payload_too_large"
            assert time.monotonic() - started < 20
        padded = '{"version": 0, "tracks": [], "pad": "' + "x" * 5_000_000 + '"}'
        resp = client.put("/api/annotate/tracks", content=padded, headers={
            **served.headers("assignment"), "Content-Type": "application/json"})
        assert resp.status_code == 413 and resp.json()["error"] == "payload_too_large"
        # A save under the limit goes through.
        resp = client.put("/api/annotate/tracks", json={"version": 0, "tracks": []},
                          headers=served.headers("assignment"))
        assert resp.status_code in (200, 409), resp.text


def test_unknown_api_addresses_and_wrong_methods_answer_in_the_error_shape(
    served: Served
) -> None:
    with httpx.Client(base_url=served.base, timeout=30) as client:
        resp = client.get("/api/no/such/thing")
        assert resp.status_code == 404 and resp.json()["error"] == "not_found"
        resp = client.request("OPTIONS", "/api/crowd/sync")
        assert resp.status_code == 405 and resp.headers["allow"] == "POST"
        assert resp.json()["error"] == "method_not_allowed"
        resp = client.get("/mturk/externalSubmit")
        assert resp.status_code == 405 and resp.headers["allow"] == "POST"


# ----- who may call what -----------------------------------------------------------------

# Routes anyone may call: logins, the HIT's exchange of its task token, the marketplace's own
# signed API and form post, the health check and the documentation.
PUBLIC = {
    ("POST", "/api/auth/token"), ("POST", "/api/portal/login"), ("POST", "/api/portal/register"),
    ("POST", "/api/annotate/start"), ("POST", "/mturk"), ("POST", "/mturk/"),
    ("POST", "/mturk/externalSubmit"), ("GET", "/healthz"), ("GET", "/docs"),
    ("GET", "/openapi.json"), ("HEAD", "/openapi.json"),
}
# Routes of a logged-in worker (portal token) and of the annotation page (assignment or task
# token). Every other route is an admin route (frame routes also take a view token, but in
# ?token=, never as a bearer).
WORKER = re.compile(r"^/api/portal/(?!workers$|invites$)")
PAGE = re.compile(
    r"^/api/annotate/(task|tracks|submit|proposals|suggestions|stretches|model-follow)$")


def _routes() -> list[tuple[str, str]]:
    """(method, path) of every route of the app, the fallbacks for unknown addresses left out."""
    from fastapi.routing import iter_route_contexts

    from backend.app import create_app

    found = []
    for route in iter_route_contexts(create_app().routes):
        if route.path and route.methods and "{rest:path}" not in route.path:
            found += [(method, route.path) for method in sorted(route.methods)]
    return found


def _concrete(path: str) -> str:
    """A path with its parameters filled in: numbers 1, names "x"."""
    def value(match: re.Match[str]) -> str:
        name = match[1]
        return "1" if name.endswith("id") or name in ("index", "frame") else "x"

    return re.sub(r"\{(\w+)(:\w+)?\}", value, path)


def _refused_kinds(path: str) -> tuple[str | None, ...]:
    if WORKER.match(path):
        return (None, "admin", "view", "task", "assignment")
    if PAGE.match(path):
        return (None, "admin", "view", "portal")
    return (None, "view", "task", "assignment", "portal")


def test_every_route_but_the_public_ones_refuses_anonymous_and_other_tokens(
    served: Served
) -> None:
    """Every route the app has, so a new one cannot slip through: an admin route unless it is
    public, a worker's or the page's."""
    routes = _routes()
    assert set(routes) >= PUBLIC, PUBLIC - set(routes)
    checked = 0
    with httpx.Client(base_url=served.base, timeout=30) as client:
        for method, path in routes:
            if (method, path) in PUBLIC:
                continue
            for kind in _refused_kinds(path):
                resp = client.request(method, _concrete(path), headers=served.headers(kind),
                                      json={})
                who = kind or "anonymous"
                assert resp.status_code in (401, 403), (
                    f"{method} {path} as {who}: {resp.status_code} {resp.text}")
                assert resp.json()["error"] in ("unauthorized", "forbidden"), resp.text
                checked += 1
    assert checked > 200


# ----- bounds in the OpenAPI document ----------------------------------------------------

def _resolve(schema: dict, doc: dict) -> dict:
    while "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        schema = doc["components"]["schemas"][name]
    return schema


def _unbounded(schema: dict, doc: dict, where: str, seen: set[str]) -> list[str]:
    """Integers, numbers and strings of a request schema that have no bounds."""
    if "$ref" in schema:
        name = schema["$ref"]
        if name in seen:
            return []
        seen = seen | {name}
    schema = _resolve(schema, doc)
    found: list[str] = []
    for key in ("anyOf", "oneOf", "allOf"):
        for part in schema.get(key, []):
            found += _unbounded(part, doc, where, seen)
    kind = schema.get("type")
    low = schema.get("minimum", schema.get("exclusiveMinimum", -float("inf")))
    high = schema.get("maximum", schema.get("exclusiveMaximum", float("inf")))
    if kind == "integer" and not MIN_INT32 <= low <= high <= MAX_INT32:
        found.append(f"{where}: integer without 32-bit bounds {schema}")
    if kind == "number" and not -MAX_ABS_FLOAT <= low <= high <= MAX_ABS_FLOAT:
        found.append(f"{where}: number without finite bounds {schema}")
    for name, prop in schema.get("properties", {}).items():
        found += _unbounded(prop, doc, f"{where}.{name}", seen)
    if isinstance(schema.get("items"), dict):
        found += _unbounded(schema["items"], doc, f"{where}[]", seen)
    if isinstance(schema.get("additionalProperties"), dict):
        found += _unbounded(schema["additionalProperties"], doc, f"{where}{{}}", seen)
    return found


def test_every_number_and_path_name_the_api_takes_is_bounded() -> None:
    """A new parameter or body field without bounds fails here, before it can reach a
    database column as an overflow (PostgreSQL's INTEGER is 32-bit)."""
    from backend.app import create_app

    doc = create_app().openapi()
    found: list[str] = []
    for path, operations in doc["paths"].items():
        for method, operation in operations.items():
            where = f"{method.upper()} {path}"
            for param in operation.get("parameters", []):
                schema = _resolve(param["schema"], doc)
                found += _unbounded(param["schema"], doc, f"{where} {param['name']}", set())
                if param["in"] == "path" and schema.get("type") == "string" and not (
                        0 < schema.get("maxLength", MAX_KEY_LENGTH + 1) <= MAX_KEY_LENGTH):
                    found.append(f"{where} {param['name']}: path name without a length limit")
            for content in operation.get("requestBody", {}).get("content", {}).values():
                found += _unbounded(content.get("schema", {}), doc, f"{where} body", set())
    assert not found, "\n".join(found)


def test_every_error_answer_is_declared_in_the_error_shape() -> None:
    from backend.app import create_app

    doc = create_app().openapi()
    assert "HTTPValidationError" not in doc["components"]["schemas"]
    assert set(doc["components"]["schemas"]["Error"]["required"]) == {"error", "detail"}
    for path, operations in doc["paths"].items():
        for method, operation in operations.items():
            for status in ("422", "4XX"):
                content = operation["responses"][status]["content"]["application/json"]
                assert content["schema"] == {"$ref": "#/components/schemas/Error"}, (
                    method, path, status)


# ----- schemathesis ----------------------------------------------------------------------

# Operations run last, once each kind of token is done with the seeded data: those that end
# the caller's session (every token of the account) and the deletion of the sequence.
LAST = r"/(logout|password)$|^/api/sequences/\{sequence_id\}$"


@dataclass
class Run:
    """One schemathesis run: its token, the operations (a path pattern; None: all but LAST),
    examples per operation, and parameters every request carries."""

    kind: str | None
    paths: str | None = None
    examples: int = OTHER_EXAMPLES
    fixed: dict[str, str] = field(default_factory=dict)


# In the order they run. Anonymous and admin over every operation; each other kind over the
# operations it opens (elsewhere it is refused like anyone: see the test above); the view
# token in ?token=, for its own sequence and camera.
RUNS = {
    "anonymous": Run(None),
    "admin": Run("admin", examples=ADMIN_EXAMPLES),
    "portal": Run("portal", r"^/api/portal/"),
    "assignment": Run("assignment", r"^/api/annotate/"),
    "task": Run("task", r"^/api/annotate/"),
    "view": Run(None, r"/views/\{serial\}/frames"),
    "portal-last": Run("portal", LAST),
    "admin-last": Run("admin", LAST, examples=ADMIN_EXAMPLES),
}


# On PostgreSQL (where NUL characters and 32-bit columns matter) the edge values only (the
# coverage phase: NUL, boundaries, huge numbers), anonymous and as an admin, to keep the
# whole test within a few minutes.
POSTGRES_RUNS = ("anonymous", "admin")


def _schemathesis(served: Served, name: str) -> tuple[dict, Path]:
    """One deterministic schemathesis run; its JSON report and its output's file."""
    run = RUNS[name]
    out = served.root / f"st-{name}"
    out.mkdir(exist_ok=True)
    report = out / "report.json"
    fixed = dict(run.fixed)
    if name == "view":
        fixed.update({"query.token": served.tokens["view"],
                      "path.sequence_id": str(served.sequence_id), "path.serial": served.serial})
    config = out / "schemathesis.toml"
    config.write_text("[parameters]\n" + "".join(
        f"{json.dumps(key)} = {json.dumps(value)}\n" for key, value in fixed.items()))
    command = [
        str(Path(sys.executable).with_name("st")), "--config-file", str(config), "run",
        f"{served.base}/openapi.json", "--checks", CHECKS, "--max-examples", str(run.examples),
        "--generation-deterministic", "--no-shrink", "--workers", "1",
        "--request-timeout", "60", "--no-color", "--report", "json",
        "--report-json-path", str(report), "--report-dir", str(out),
    ]
    if served.backend == "postgres":
        command += ["--phases", "coverage"]
    if run.paths:
        command += ["--include-path-regex", run.paths]
    if run.paths != LAST:
        command += ["--exclude-path-regex", LAST]
    for header, value in served.headers(run.kind).items():
        command += ["--header", f"{header}: {value}"]
    started = time.monotonic()
    done = subprocess.run(command, cwd=out, capture_output=True, text=True, timeout=600,
                          check=False)
    output = out / "output.txt"
    output.write_text(done.stdout + done.stderr)
    assert report.is_file(), f"schemathesis wrote no report:\n{done.stdout[-4000:]}{done.stderr}"
    result: dict = json.loads(report.read_text())
    served.log.append(f"{name}: {result['test_cases']['generated']} cases in "
                      f"{time.monotonic() - started:.0f} s")
    return result, output


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_schemathesis_finds_no_server_error_and_no_answer_off_the_schema(
    served: Served, name: str
) -> None:
    if served.backend == "postgres" and name not in POSTGRES_RUNS:
        pytest.skip("on PostgreSQL: the edge values of anonymous and admin calls only")
    result, output = _schemathesis(served, name)
    found = [f"{f['code']} {f['title']} x{f['count']}: {', '.join(f['operations'])}"
             for f in result["failures"]]
    errors = [json.dumps(e)[:300] for e in result.get("errors", [])]
    assert not found and not errors, (
        "\n".join(found + errors) + f"\n\nfull output: {output}\n" + output.read_text()[-6000:])
    assert result["operations"]["tested"] == result["operations"]["selected"] > 0
