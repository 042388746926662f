"""bench/qc.py's hand scenarios carried on from the first QC pass the way the product goes on.

A first QC pass of one worker per view decides little at 4 views: where the images or the
track itself discredit two of the others, a careful worker has fewer than three views to be
compared with, and the product waits (a provisional report never acts). What happens next is
simulated as plainly as possible, through the product's own jobs (backend.jobs.runner):

- work QC left for review is decided by an admin who judges right (careful work approved,
  the rest rejected): that work counts as flagged, whatever the admin decided;
- a rejected label's task (by QC or by the admin) gets another worker drawn from the same
  mixed crowd (the marketplace re-opens it with one more assignment), and the target's QC
  runs again: every label not acted on yet is scored again with the new view beside it;
- a provisional report that passes waits for those views; one still waiting when nothing is
  left to re-open is reported apart ("waiting"), and counted as flagged for careful work and
  as not flagged for bad work (the worse reading for both).

The verdict of each first worker: "flagged" (an admin had to decide it, or QC rejected it),
"approve" (QC approved it), or "waiting".
"""

from __future__ import annotations

from collections.abc import Callable

from sqlalchemy import select

# Rounds of admin decisions and re-opened tasks before the crowd is left as it stands.
MAX_ROUNDS = 8


def _report(assignment_id: int) -> tuple[str | None, list[str]]:
    """(outcome, reasons) of the assignment's QC report; (None, []) before one."""
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with session_scope() as session:
        row = session.scalar(select(QCReport).where(QCReport.assignment_id == assignment_id))
        return (None, []) if row is None else (row.outcome, list(row.reasons or []))


def _status(assignment_id: int) -> str:
    from backend.annotation.models import Assignment
    from backend.db import session_scope

    with session_scope() as session:
        return session.get_one(Assignment, assignment_id).status


def settle(sequence_id: int, profile_of: dict[int, str],
           resubmit: Callable[[int], tuple[int, str]],
           careful_flags: list[str] | None = None) -> tuple[dict[int, str], dict[str, int]]:
    """Carry one crowd's hand labels on from its first QC pass (module docstring).

    profile_of: {assignment id: profile} of the first workers (extended here with the
    re-opened tasks' workers); resubmit(task id) submits another worker drawn from the crowd,
    returning (assignment id, profile); ``careful_flags`` (if given) collects why careful work
    went to an admin (a few). Returns each first worker's verdict and the counts (rounds,
    reopened, admin_decided)."""
    import _qc_pipeline as pipe

    first = set(profile_of)
    verdict: dict[int, str] = {}
    counts = {"rounds": 0, "reopened": 0, "admin_decided": 0}
    why = careful_flags if careful_flags is not None else []
    for _ in range(MAX_ROUNDS):
        asked: list[int] = []
        decided = 0
        for task_id, (assignment_id, status) in sorted(pipe._unaccepted(sequence_id).items()):
            outcome, reasons = _report(assignment_id)
            if status == "submitted" and outcome in ("review", "reject"):
                right = profile_of.get(assignment_id) == "careful"
                if assignment_id in first:
                    verdict[assignment_id] = "flagged"
                if right and len(why) < 6:
                    why.append(f"{'first' if assignment_id in first else 'later'} careful: "
                               + "; ".join(reasons[:3]))
                pipe._admin_decides(assignment_id, right)
                decided += 1
                status = "approved" if right else "rejected"
            if status == "rejected":
                new_id, profile = resubmit(task_id)
                profile_of[new_id] = profile
                counts["reopened"] += 1
                asked.append(task_id)
        if not asked and not decided:
            break
        counts["rounds"] += 1
        counts["admin_decided"] += decided
        pipe.request_qc_of(asked)
        pipe.drain()
    for assignment_id in first - set(verdict):
        status = _status(assignment_id)
        verdict[assignment_id] = {"approved": "approve", "rejected": "flagged"}.get(
            status, "waiting")
    return verdict, counts


def rates(verdicts: list[tuple[str, str]]) -> dict[str, float | int]:
    """careful_flagged / bad_flagged over (profile, verdict) pairs, "waiting" counted against
    each side (module docstring), and how many waited."""
    careful = [v for p, v in verdicts if p == "careful"]
    bad = [v for p, v in verdicts if p != "careful"]
    return {
        "careful_flagged": round(sum(v != "approve" for v in careful) / max(len(careful), 1), 4),
        "bad_flagged": round(sum(v == "flagged" for v in bad) / max(len(bad), 1), 4),
        "careful": len(careful), "bad": len(bad),
        "careful_waiting": sum(v == "waiting" for v in careful),
        "bad_waiting": sum(v == "waiting" for v in bad),
    }
