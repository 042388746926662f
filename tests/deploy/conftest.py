"""The scale-out deployment the multi-host test runs: one PostgreSQL database, one Redis
database and one S3 bucket (moto's server) shared by an API host and two queue-worker hosts,
each with an empty instance folder of its own (tests/deploy/hosts.py). Admin calls go over
HTTP to the API host; the database is read directly only to see what the hosts did."""

from __future__ import annotations

import json
import logging
import secrets
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from tests.backend.cli.conftest import clean_env, free_port
from tests.conftest import REDIS_URL, _unavailable, throwaway_database
from tests.deploy.hosts import Host, namespaces_available

WORKER_HOSTS = ("worker-a", "worker-b")
ADMIN = ("admin@multihost.test", secrets.token_urlsafe(16))
# Short enough that a killed worker's job is taken over within the test's minutes (the
# reaper looks every minute); the heartbeat renews it every third.
LEASE_S = "20"


class Api:
    """The admin's HTTP client of the API host (JSON in and out, a bearer token)."""

    def __init__(self, base: str) -> None:
        self.base, self.token = base, ""

    def call(self, method: str, path: str, body: Any = None, token: str | None = None,
             expect: int = 200) -> tuple[int, bytes, dict[str, str]]:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.base + path, data=data, method=method)
        request.add_header("Content-Type", "application/json")
        bearer = token if token is not None else self.token
        if bearer:
            request.add_header("Authorization", f"Bearer {bearer}")
        try:
            with urllib.request.urlopen(request, timeout=60) as resp:
                status, payload, headers = resp.status, resp.read(), dict(resp.headers)
        except urllib.error.HTTPError as exc:
            status, payload, headers = exc.code, exc.read(), dict(exc.headers)
        assert status == expect, f"{method} {path}: {status} {payload[:500]!r}"
        return status, payload, headers

    def json(self, method: str, path: str, body: Any = None, **kw: Any) -> Any:
        return json.loads(self.call(method, path, body, **kw)[1])


@dataclass
class Deployment:
    api_host: Host
    workers: dict[str, Host]
    api: Api
    database_url: str
    capture: Path
    isolated: bool
    s3_endpoint: str
    notes: dict[str, Any] = field(default_factory=dict)

    @property
    def hosts(self) -> list[Host]:
        return [self.api_host, *self.workers.values()]

    def need(self, name: str) -> Any:
        """What an earlier test of the walk recorded (they run in order on one deployment)."""
        if name not in self.notes:
            pytest.fail(f"an earlier step of the walk failed before it recorded {name!r}")
        return self.notes[name]

    def logs(self) -> str:
        return "\n".join(h.log_tail() for h in self.hosts)


@contextmanager
def _redis_database() -> Iterator[str]:
    """A Redis database number no one uses now (the suite's own is left alone), claimed with
    a key and flushed afterwards."""
    import redis

    base = REDIS_URL.rsplit("/", 1)[0]
    claim = f"dexlabel-multihost-{uuid.uuid4().hex}"
    try:
        for number in range(14, 0, -1):
            client = redis.Redis.from_url(f"{base}/{number}")
            if client.dbsize() == 0 and client.set("multihost-claim", claim, nx=True, ex=3600):
                break
        else:
            pytest.fail("no empty Redis database among 1-14 for the multi-host test")
    except redis.RedisError as exc:
        _unavailable("Redis", exc)
    try:
        yield f"{base}/{number}"
    finally:
        client.flushdb()


def _bucket(endpoint: str) -> str:
    import boto3

    name = f"multihost-{uuid.uuid4().hex[:8]}"
    boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1",
                 aws_access_key_id="testing", aws_secret_access_key="testing"
                 ).create_bucket(Bucket=name)
    return name


def wait_http(url: str, host: Host, timeout_s: float = 120) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        assert host.alive(), f"{host.name} exited\n{host.log_tail()}"
        try:
            with urllib.request.urlopen(url, timeout=5):
                return
        except urllib.error.HTTPError:
            return
        except OSError:
            pass
        assert time.monotonic() < deadline, f"{url} did not answer\n{host.log_tail()}"
        time.sleep(0.3)


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory, s3_endpoint: str
               ) -> Iterator[Deployment]:
    """An API host and two worker hosts, started; a migrated database with an admin signed
    in; a small synthetic capture on the API host's own disk (3 views, 1 object)."""
    logging.getLogger("werkzeug").setLevel(logging.WARNING)  # moto's line per request
    root = tmp_path_factory.mktemp("multihost")
    isolated = namespaces_available()
    with ExitStack() as services:
        database_url = services.enter_context(throwaway_database("dexlabel_multihost"))
        redis_url = services.enter_context(_redis_database())
        yield from _deployment(root, isolated, database_url, redis_url, s3_endpoint)


def _deployment(root: Path, isolated: bool, database_url: str, redis_url: str,
                s3_endpoint: str) -> Iterator[Deployment]:
    """The hosts on those services, each with every setting of the README's scale-out; each
    host is stopped afterwards and its log's end printed."""
    hosts_root, logs = root / "hosts", root / "logs"
    hosts_root.mkdir()
    logs.mkdir()
    port = free_port()
    access_key = "AKMULTIHOST" + secrets.token_hex(6).upper()
    requester_secret = secrets.token_hex(20)
    capture = hosts_root / "api-host" / "captures"
    common = clean_env(
        DEXLABEL_ENV="prod", DEXLABEL_SECRET_KEY=secrets.token_hex(32),
        DEXLABEL_DATABASE_URL=database_url, DEXLABEL_REDIS_URL=redis_url,
        DEXLABEL_STORAGE_URL=f"s3://{_bucket(s3_endpoint)}/captures",
        DEXLABEL_S3_ENDPOINT_URL=s3_endpoint, AWS_ACCESS_KEY_ID="testing",
        AWS_SECRET_ACCESS_KEY="testing", DEXLABEL_PUBLIC_URL=f"http://127.0.0.1:{port}",
        DEXLABEL_MARKET_REQUESTERS=f"{access_key}:{requester_secret}",
        DEXLABEL_MTURK_ACCESS_KEY_ID=access_key,
        DEXLABEL_MTURK_SECRET_ACCESS_KEY=requester_secret,
        DEXLABEL_INPROCESS_WORKER="false", DEXLABEL_JOB_LEASE_S=LEASE_S,
        DEXLABEL_JOB_RETRY_BASE_S="1", DEXLABEL_CAPTURE_ROOTS=str(capture))
    api_host = Host("api-host", hosts_root, common, isolated, logs)
    workers = {name: Host(name, hosts_root, common, isolated, logs) for name in WORKER_HOSTS}
    deployment = Deployment(api_host, workers, Api(f"http://127.0.0.1:{port}"), database_url,
                            capture, isolated, s3_endpoint)
    try:
        migrate = Host("migrate", hosts_root, common, isolated, logs)
        migrate.start("migrate")
        assert migrate.proc is not None and migrate.proc.wait(timeout=300) == 0, \
            migrate.log_tail()
        api_host.start("serve", "--host", "127.0.0.1", "--port", str(port))
        for worker in workers.values():
            worker.start("worker", "--workers", "2")
        wait_http(f"{deployment.api.base}/healthz", api_host)
        api_host.run("create-admin", ADMIN[0], "--password", ADMIN[1])
        api_host.run("synth", str(capture), "--seed", "5", "--frames", "12", "--views", "3",
                     "--objects", "1")
        deployment.api.token = deployment.api.json(
            "POST", "/api/auth/token", {"email": ADMIN[0], "password": ADMIN[1]},
            token="")["access_token"]
        yield deployment
    finally:
        for host in deployment.hosts:
            host.stop()
        print(deployment.logs())  # noqa: T201 (the hosts' last words, shown on failure)
