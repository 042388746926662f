"""The body of the rig-health job: read in one short unit of work, estimate outside any
transaction, store the new calibration version in another. Idempotent enough to retry: a
retry computes again and stores one more (unused) version."""

from __future__ import annotations

import logging
import time
from typing import Any

from backend.db import session_scope
from backend.rig.service import estimate, read_inputs, store_version

log = logging.getLogger(__name__)


def run_rig_health(sequence_id: int) -> dict[str, Any]:
    """Estimate the rig of ``sequence_id`` and store the result as a new version."""
    started = time.perf_counter()
    with session_scope() as session:
        inputs = read_inputs(session, sequence_id)
    cameras, report = estimate(inputs)
    report["seconds"] = round(time.perf_counter() - started, 1)
    with session_scope() as session:
        version = store_version(session, sequence_id, cameras, report)
        number = version.number
    faulty = ", ".join(report["faulty"]) or "none"
    shape = "; hand shape off" if any(h["faults"] for h in report["hands"]) else ""
    log.info("rig health of sequence %d: version %d, faulty cameras: %s%s", sequence_id,
             number, faulty, shape)
    return {"sequence_id": sequence_id, "version": number, "faulty": report["faulty"],
            "message": f"calibration version {number}; cameras off: {faulty}{shape}"}
