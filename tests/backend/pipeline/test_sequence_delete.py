"""Deleting a sequence (DELETE /api/sequences/{id}): admins only; refused with 409 while it has
submitted or approved work unless forced; its rows, the work on it and its stored files go, and
the same capture imports again afterwards."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient
from sqlalchemy import func, select

from backend.annotation.models import Assignment, Task
from backend.annotation.service import create_tasks
from backend.captures.flows import import_path
from backend.captures.models import Camera, Frame, Sequence
from backend.db import session_scope
from backend.storage import get_storage


def _count(model: type) -> int:
    with session_scope() as s:
        return int(s.scalar(select(func.count()).select_from(model)) or 0)


def _stored(app_env: dict) -> list[Path]:
    root = Path(app_env["DEXLABEL_STORAGE_URL"])
    return sorted(p for p in root.rglob("*") if p.is_file())


def _with_work(sequence_id: int, status: str) -> None:
    with session_scope() as s:
        task = create_tasks(s, get_storage(), sequence_id)[0]
        s.add(Assignment(task_id=task.id, worker_id="W1", external_id=f"A-{status}",
                         status=status))


def test_deleting_a_sequence_removes_its_rows_and_files_and_it_imports_again(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path
) -> None:
    sequence_id = import_path(small_capture)[0].sequence_id
    _with_work(sequence_id, "working")
    storage = get_storage()
    storage.put_bytes(f"solves/{_uid(sequence_id)}/run_000001/result.npz", b"npz")
    files = len(_stored(app_env))

    resp = client.delete(f"/api/sequences/{sequence_id}", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    body = resp.json()
    assert body["sequence_id"] == sequence_id and body["files"] == files
    assert body["tasks"] == 9 and (body["assignments"], body["finished_assignments"]) == (1, 0)
    assert [_count(m) for m in (Sequence, Camera, Frame, Task, Assignment)] == [0] * 5
    assert _stored(app_env) == []
    assert client.get(f"/api/sequences/{sequence_id}", headers=admin_headers).status_code == 404
    assert client.delete(f"/api/sequences/{sequence_id}",
                         headers=admin_headers).status_code == 404

    again = import_path(small_capture)[0]
    assert again.created
    with session_scope() as s:
        frame = s.scalars(select(Frame)).first()
        assert frame is not None and storage.get_bytes(frame.color_key)


def _uid(sequence_id: int) -> str:
    with session_scope() as s:
        seq = s.get(Sequence, sequence_id)
        assert seq is not None
        return seq.storage_uid


def test_a_sequence_with_submitted_or_approved_work_is_deleted_only_when_forced(
    client: TestClient, admin_headers: dict, app_env: dict, small_capture: Path
) -> None:
    sequence_id = import_path(small_capture)[0].sequence_id
    _with_work(sequence_id, "approved")
    files = _stored(app_env)

    resp = client.delete(f"/api/sequences/{sequence_id}", headers=admin_headers)
    assert resp.status_code == 409, resp.text
    assert "1 submitted or approved" in resp.json()["detail"]
    assert "force" in resp.json()["detail"]
    assert _count(Sequence) == 1 and _count(Assignment) == 1 and _stored(app_env) == files

    resp = client.delete(f"/api/sequences/{sequence_id}?force=true", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    assert resp.json()["finished_assignments"] == 1
    assert _count(Sequence) == 0 and _count(Assignment) == 0 and _stored(app_env) == []


def test_deleting_a_sequence_needs_an_admin(client: TestClient, small_capture: Path) -> None:
    sequence_id = import_path(small_capture)[0].sequence_id
    assert client.delete(f"/api/sequences/{sequence_id}").status_code == 401
    assert _count(Sequence) == 1
