"""Unit and worker actions: extend or close a unit (a HIT), add places, allow-lists
(qualifications), blocks, messages, each through the crowd provider. Each is recorded in our
database so repeating one is a clear Conflict, not a surprise.

A unit's action goes to the provider that published it; a worker's to the provider given, else
the setting's (DEXLABEL_CROWD_PROVIDER); lifting a block or a grant, to the one that made it.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.crowd.models import CrowdHit, CrowdWorkerAction
from backend.crowd.provider import CrowdProvider
from backend.crowd.providers import get_provider, provider_of
from backend.crowd.publish import check_assignments, training_qualification
from backend.db import utcnow
from backend.errors import Conflict, NotFound


def get_hit_or_raise(session: Session, hit_id: str) -> CrowdHit:
    row = session.scalar(select(CrowdHit).where(CrowdHit.hit_id == hit_id))
    if row is None:
        raise NotFound(f"no HIT {hit_id} was published from this database")
    return row


def _crowd(crowd: CrowdProvider | None, name: str | None = None) -> CrowdProvider:
    """The provider given, else the one named (a row's), else the setting's."""
    return provider_of(crowd) if crowd is not None else get_provider(name)


def extend_hit(session: Session, crowd: CrowdProvider | None, hit_id: str,
               seconds: int) -> CrowdHit:
    """Keep the unit open ``seconds`` from now (it reopens a closed one)."""
    row = get_hit_or_raise(session, hit_id)
    _crowd(crowd, row.provider).extend(hit_id, seconds)
    row.expired_at = None
    session.flush()
    return row


def expire_hit(session: Session, crowd: CrowdProvider | None, hit_id: str) -> CrowdHit:
    row = get_hit_or_raise(session, hit_id)
    if row.expired_at is not None:
        raise Conflict(f"HIT {hit_id} is already expired", state="expired")
    _crowd(crowd, row.provider).close(hit_id)
    row.expired_at = utcnow()
    session.flush()
    return row


def add_assignments(session: Session, crowd: CrowdProvider | None, hit_id: str, count: int,
                    allow_large_hits: bool = False) -> CrowdHit:
    """Add ``count`` places to the unit; the key makes a retry add nothing."""
    row = get_hit_or_raise(session, hit_id)
    provider = _crowd(crowd, row.provider)
    check_assignments(row.max_assignments + count, allow_large_hits, provider.fees())
    provider.add_places(hit_id, count, f"dxadd-{hit_id[:40]}-{row.max_assignments}")
    row.max_assignments += count
    session.flush()
    return row


def _worker_action(session: Session, worker_id: str, kind: str, target: str
                   ) -> CrowdWorkerAction | None:
    return session.scalar(select(CrowdWorkerAction).where(
        CrowdWorkerAction.worker_id == worker_id, CrowdWorkerAction.kind == kind,
        CrowdWorkerAction.target == target))


def grant_qualification(session: Session, crowd: CrowdProvider | None, worker_id: str,
                        type_id: str | None, value: int = 1, notify: bool = False) -> str:
    """Put the worker on an allow-list (unset: our "passed training" one); its id."""
    provider = _crowd(crowd)
    with session.no_autoflush:  # our rows are written after the provider calls
        type_id = type_id or training_qualification(session, provider)
        if _worker_action(session, worker_id, "qualification", type_id) is not None:
            raise Conflict(f"worker {worker_id} already holds qualification {type_id}",
                           state="granted")
        provider.grant(worker_id, type_id, value, notify)
    session.add(CrowdWorkerAction(worker_id=worker_id, kind="qualification", target=type_id,
                                  value=value, provider=provider.name))
    session.flush()
    return type_id


def revoke_qualification(session: Session, crowd: CrowdProvider | None, worker_id: str,
                         type_id: str | None, reason: str | None = None) -> str:
    with session.no_autoflush:
        type_id = type_id or training_qualification(session, _crowd(crowd))
        row = _worker_action(session, worker_id, "qualification", type_id)
        if row is None:
            raise Conflict(f"worker {worker_id} does not hold qualification {type_id}",
                           state="not_granted")
        _crowd(crowd, row.provider).revoke(worker_id, type_id, reason)
    session.delete(row)
    session.flush()
    return type_id


def block_worker(session: Session, crowd: CrowdProvider | None, worker_id: str,
                 reason: str) -> None:
    if _worker_action(session, worker_id, "block", "") is not None:
        raise Conflict(f"worker {worker_id} is already blocked", state="blocked")
    provider = _crowd(crowd)
    provider.block(worker_id, reason)
    session.add(CrowdWorkerAction(worker_id=worker_id, kind="block", target="", reason=reason,
                                  provider=provider.name))
    session.flush()


def unblock_worker(session: Session, crowd: CrowdProvider | None, worker_id: str,
                   reason: str | None = None) -> None:
    """Lift our block of ``worker_id``; not blocked is a Conflict."""
    row = _worker_action(session, worker_id, "block", "")
    if row is None:
        raise Conflict(f"worker {worker_id} is not blocked", state="not_blocked")
    _crowd(crowd, row.provider).unblock(worker_id, reason)
    session.delete(row)
    session.flush()


def notify_workers(crowd: CrowdProvider | None, worker_ids: list[str], subject: str,
                   message: str) -> list[dict[str, str]]:
    """Send a message; the provider's per-worker failures (empty when all went out)."""
    return _crowd(crowd).notify(worker_ids, subject, message)
