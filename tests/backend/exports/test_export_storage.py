"""Export archives live in the instance's storage, not on the disk of the host that ran the job:
an export run on a "worker host" (its own instance folder, gone once the job ends) downloads
from the API, from the local storage folder and from S3 (moto's server); archives past
DEXLABEL_EXPORT_RETENTION_DAYS and archives no export names are cleaned up; an export can be
deleted."""

from __future__ import annotations

import io
import json
import shutil
import tarfile
import zipfile
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, update

from backend.config import get_settings
from backend.db import session_scope
from backend.exports.flows import queue_cleanup
from backend.exports.stored import CLEANUP_KIND, clean_up_archives
from backend.jobs.models import Job
from backend.jobs.runner import execute
from backend.storage import get_storage
from tests.backend.conftest import ADMIN_EMAIL, ADMIN_PASSWORD
from tests.backend.solve.test_solve_api import approved, sequence  # noqa: F401
from tests.conftest import reset_caches

pytestmark = pytest.mark.slow


@pytest.fixture(params=["local", "s3"])
def storage_url(request: pytest.FixtureRequest, app_env: dict,
                monkeypatch: pytest.MonkeyPatch) -> str:
    """The instance's storage: its local folder, or a bucket on moto's S3 server."""
    if request.param == "local":
        return str(app_env["DEXLABEL_STORAGE_URL"])
    endpoint = request.getfixturevalue("s3_endpoint")
    bucket = request.getfixturevalue("s3_bucket")
    url = f"s3://{bucket}/instance"
    monkeypatch.setenv("DEXLABEL_STORAGE_URL", url)
    monkeypatch.setenv("DEXLABEL_S3_ENDPOINT_URL", endpoint)
    reset_caches()
    return url


@pytest.fixture
def client(storage_url: str) -> Iterator[TestClient]:
    from backend.accounts.service import create_admin
    from backend.app import create_app

    with session_scope() as s:
        create_admin(s, ADMIN_EMAIL, ADMIN_PASSWORD)
    with TestClient(create_app()) as c:
        yield c


def _on_worker_host(key: str, var_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the job as a host with its own instance folder would, then lose that folder (the
    API host cannot see another host's disk)."""
    api_var = get_settings().var_dir
    monkeypatch.setenv("DEXLABEL_VAR_DIR", str(var_dir))
    get_settings.cache_clear()
    try:
        execute(key)
    finally:
        monkeypatch.setenv("DEXLABEL_VAR_DIR", str(api_var))
        get_settings.cache_clear()
    assert not (var_dir / "exports").exists(), "the archive was written to the host's disk"
    shutil.rmtree(var_dir, ignore_errors=True)


def _export(client: TestClient, headers: dict, body: dict, worker_var: Path,
            monkeypatch: pytest.MonkeyPatch) -> dict:
    resp = client.post("/api/exports", json=body, headers=headers)
    assert resp.status_code == 200, resp.text
    with session_scope() as s:
        key = s.get_one(Job, resp.json()["id"]).key
    _on_worker_host(key, worker_var, monkeypatch)
    state = client.get(f"/api/exports/{resp.json()['id']}", headers=headers).json()
    assert state["status"] == "done", state
    assert "key" not in state["result"] and "path" not in state["result"]
    return state


def _stored_key(export_id: int) -> str:
    with session_scope() as s:
        return str(s.get_one(Job, export_id).result["key"])


@pytest.mark.parametrize(("fmt", "archive"),
                         [("json", "zip"), ("cvat", "tar"), ("coco", "zip")])
def test_an_archive_written_on_a_worker_host_downloads_from_storage(
    client: TestClient, admin_headers: dict, approved: int, storage_url: str,  # noqa: F811
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fmt: str, archive: str,
) -> None:
    state = _export(client, admin_headers, {"format": fmt, "sequences": [approved],
                                            "archive": archive},
                    tmp_path / "worker-var", monkeypatch)
    key = _stored_key(state["id"])
    assert key == f"exports/export-{state['id']:06d}.{archive}"
    stored = get_storage().get_bytes(key)
    resp = client.get(state["download_url"], headers=admin_headers)
    assert resp.status_code == 200, resp.text
    assert resp.headers["content-type"] == ("application/zip" if archive == "zip"
                                            else "application/x-tar")
    assert f"dexlabel-export-{state['id']:06d}.{archive}" in resp.headers["content-disposition"]
    assert resp.content == stored and int(resp.headers["content-length"]) == len(stored)
    if archive == "zip":
        names = zipfile.ZipFile(io.BytesIO(resp.content)).namelist()
    else:
        with tarfile.open(fileobj=io.BytesIO(resp.content)) as tar:
            names = tar.getnames()
    assert len(names) == state["result"]["files"] > 0
    if fmt == "json":
        document = json.loads(zipfile.ZipFile(io.BytesIO(resp.content)).read(names[0]))
        assert document
    assert not (get_settings().var_dir / "exports").exists()


def _age(export_id: int, days: float) -> None:
    with session_scope() as s:
        s.execute(update(Job).where(Job.id == export_id).values(
            finished_at=datetime.now(UTC) - timedelta(days=days)))


def test_archives_past_their_retention_are_deleted_by_the_clean_up_job(
    client: TestClient, admin_headers: dict, approved: int, storage_url: str,  # noqa: F811
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("DEXLABEL_EXPORT_RETENTION_DAYS", "7")
    get_settings.cache_clear()
    body = {"format": "json", "sequences": [approved]}
    old = _export(client, admin_headers, body, tmp_path / "w1", monkeypatch)
    new = _export(client, admin_headers, body, tmp_path / "w2", monkeypatch)
    old_key, new_key = _stored_key(old["id"]), _stored_key(new["id"])
    _age(old["id"], 8)
    orphan = "exports/export-999999.zip"  # an archive whose export row is gone
    get_storage().put_bytes(orphan, b"PK")

    queue_cleanup()
    queue_cleanup()  # one queued clean-up at a time
    with session_scope() as s:
        jobs = list(s.scalars(select(Job).where(Job.kind == CLEANUP_KIND)))
    assert len(jobs) == 1 and jobs[0].status == "queued"
    execute(CLEANUP_KIND)
    with session_scope() as s:
        job = s.scalars(select(Job).where(Job.kind == CLEANUP_KIND)).one()
        assert job.status == "done" and job.result["expired_exports"] == [old["id"]], job.result
    storage = get_storage()
    assert not storage.exists(old_key)
    assert storage.exists(new_key) and storage.exists(orphan), "a young archive was deleted"
    resp = client.get(f"/api/exports/{old['id']}/download", headers=admin_headers)
    assert resp.status_code == 410, resp.text
    assert resp.json()["error"] == "archive_gone"
    assert "DEXLABEL_EXPORT_RETENTION_DAYS" in resp.json()["detail"]
    read = client.get(f"/api/exports/{old['id']}", headers=admin_headers).json()
    assert read["status"] == "done" and read["download_url"] is None
    assert client.get(f"/api/exports/{new['id']}/download", headers=admin_headers).status_code \
        == 200

    # A week and a day later everything stored then is past its retention, orphan included.
    done = clean_up_archives(now=datetime.now(UTC) + timedelta(days=8))
    assert done["deleted"] == 2 and done["orphans"] == 1, done
    assert not storage.exists(new_key) and not storage.exists(orphan)
    assert storage.list_prefix("exports") == []


def test_an_admin_deletes_an_export_and_its_archive(
    client: TestClient, admin_headers: dict, approved: int, storage_url: str,  # noqa: F811
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    state = _export(client, admin_headers, {"format": "json", "sequences": [approved]},
                    tmp_path / "w", monkeypatch)
    key = _stored_key(state["id"])
    url = f"/api/exports/{state['id']}"
    assert client.delete(url).status_code == 401
    resp = client.delete(url, headers=admin_headers)
    assert resp.status_code == 200 and resp.json() == {"id": state["id"], "state": "deleted"}
    assert not get_storage().exists(key)
    for method in (client.get, client.delete):
        gone = method(url, headers=admin_headers)
        assert gone.status_code == 404 and gone.json()["error"] == "not_found", gone.text
    missing = client.delete("/api/exports/77", headers=admin_headers)
    assert missing.status_code == 404 and "77" in missing.json()["detail"]

    running = client.post("/api/exports", json={"format": "json", "sequences": [approved]},
                          headers=admin_headers).json()
    with session_scope() as s:
        s.execute(update(Job).where(Job.id == running["id"]).values(status="running"))
    refused = client.delete(f"/api/exports/{running['id']}", headers=admin_headers)
    assert refused.status_code == 409 and refused.json()["error"] == "conflict", refused.text
    assert "running" in refused.json()["detail"]
