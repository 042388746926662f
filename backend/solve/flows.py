"""The body of the ``solve`` job: read inputs, run worker.solver, store outputs, finish the run.

Idempotent: a run already done returns its summary; a retry after a crash solves again and
overwrites the same storage key. Each database step is its own short unit of work, and the
solve itself runs outside any transaction. Bad input (the solver's ValueError) fails the run
for good, with the message; any other error is recorded and re-raised so the job retries.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from backend.captures.models import Sequence
from backend.db import session_scope, utcnow
from backend.solve.inputs import gather_inputs
from backend.solve.models import SolveRun
from backend.solve.results import encode_result, residual_summary, result_key
from backend.storage import get_storage
from worker.solver import SolveSettings, solve

log = logging.getLogger(__name__)


def _settings(params: dict[str, Any]) -> SolveSettings:
    known = set(SolveSettings.__dataclass_fields__)
    return SolveSettings(**{k: v for k, v in params.items() if k in known})


def _start(run_id: int) -> SolveRun | None:
    """Mark the run running; None when it is already done (nothing to do)."""
    with session_scope() as session:
        run = session.get(SolveRun, run_id)
        if run is None:
            raise LookupError(f"solve run {run_id} does not exist")
        if run.status == "done":
            return None
        run.status, run.error, run.started_at = "running", None, utcnow()
        session.flush()
        session.expunge(run)
        return run


def _fail(run_id: int, message: str) -> None:
    with session_scope() as session:
        run = session.get(SolveRun, run_id)
        if run is not None:
            run.status, run.error, run.finished_at = "failed", message, utcnow()


def _solve_and_store(run: SolveRun) -> tuple[dict[str, Any], dict[str, float], str]:
    timings: dict[str, float] = {}
    started = time.perf_counter()
    with session_scope() as session:
        gathered = gather_inputs(session, run.sequence_id)
        uid = session.get_one(Sequence, run.sequence_id).storage_uid
    timings["gather_s"] = time.perf_counter() - started
    result = solve(gathered.inputs, _settings(run.params))
    timings.update({f"solver_{k}": float(v) for k, v in result.timings.items()})
    stored = time.perf_counter()
    key = result_key(uid, run.id)
    get_storage().put_bytes(key, encode_result(result, gathered.serials, gathered.object_names,
                                               gathered.hand_side), "application/octet-stream")
    timings["store_s"] = time.perf_counter() - stored
    timings["total_s"] = time.perf_counter() - started
    summary = residual_summary(result.kpt_error_px, result.depth_rms_mm, result.labelled)
    summary["solver"] = result.to_summary()
    # Every object pose the evidence cannot pin down, with the reason ("frame F: ..."): these
    # are exported as unlabelled.
    summary["object_flags"] = [f"frame {f}: {flags[f]}" for f in range(len(result.labelled))
                               for flags in result.object_flags if flags[f] is not None]
    return summary, timings, key


def run_solve(run_id: int) -> dict[str, Any]:
    """Solve run ``run_id`` and record its outputs; returns the run's summary."""
    run = _start(run_id)
    if run is None:
        with session_scope() as session:
            return {"run_id": run_id, "summary": session.get_one(SolveRun, run_id).summary}
    try:
        summary, timings, key = _solve_and_store(run)
    except ValueError as exc:  # bad input: solving again cannot help
        _fail(run_id, f"{type(exc).__name__}: {exc}")
        return {"run_id": run_id, "error": str(exc)}
    except Exception as exc:
        _fail(run_id, f"{type(exc).__name__}: {exc}")
        raise
    with session_scope() as session:
        row = session.get_one(SolveRun, run_id)
        row.status, row.summary, row.timings = "done", summary, timings
        row.result_key, row.finished_at = key, utcnow()
    log.info("solve run %d done in %.1f s", run_id, timings["total_s"])
    return {"run_id": run_id, "summary": summary}
