"""Export rules: what may be exported, export jobs, and the export itself. Services flush, never
commit; the job (kind ``export``) is a row of the job table whose ``progress`` counts the views
written and whose ``result`` names the finished archive's storage key (backend.exports.stored).
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

from sqlalchemy import exists, select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.captures.models import Camera, Sequence, Subject
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError, NotFound
from backend.exports.archive import ExportArchive
from backend.exports.content import fetch_solve, load_sequence
from backend.exports.formats import EXPORTERS
from backend.jobs.models import Job
from backend.jobs.service import enqueue_job, get_job_or_raise
from backend.labels import INCLUDE_STATUSES
from backend.solve.models import SolveRun
from worker.formats import FORMATS, SOLVE_FORMATS
from worker.formats.dexycb import SPLIT_SETUPS

JOB_KIND = "export"
INCLUDES = tuple(INCLUDE_STATUSES)
ARCHIVES = ("zip", "tar")
FRAME_MODES = ("copy", "link")
# Options each format takes, and their allowed values.
OPTIONS: dict[str, dict[str, tuple[str, ...]]] = {
    "dexycb": {"frames": FRAME_MODES, "split": SPLIT_SETUPS},
    "bop": {"frames": FRAME_MODES},
    "coco": {"labels": ("2d", "3d")},
    "json": {},
    "cvat": {},
}


class InvalidExport(DexlabelError, status_code=422, code="invalid_export"):
    pass


class NotExportable(Conflict, code="not_exportable"):
    pass


class Covered(NamedTuple):
    """What an export covers: its sequence ids, and for a whole-project export the sequences
    left out with the reason ("sequence 3 (s/n) has no finished solve; ...")."""

    ids: list[int]
    skipped: list[str]


def check_request(session: Session, fmt: str, sequence_ids: list[int] | None, include: str,
                  options: dict[str, Any], archive: str = "zip") -> Covered:
    """The sequences an export of ``fmt`` covers once every rule holds; InvalidExport (422) or
    NotExportable (409) naming the problem. Listed sequences must all be exportable; the whole
    project (``sequence_ids`` None) covers those that are, skipping the others by name, and is
    refused only when none is."""
    if fmt not in FORMATS:
        raise InvalidExport(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}",
                            field="format")
    if include not in INCLUDES:
        raise InvalidExport(f"include must be one of {', '.join(INCLUDES)}, got {include!r}",
                            field="include")
    if fmt == "coco" and include != "accepted":
        raise InvalidExport("the coco format holds one hand per image: it exports accepted "
                            "labels only (include=accepted); json and cvat export submitted "
                            "work", field="include")
    _check_options(fmt, options, archive)
    if sequence_ids is None:
        ids = list(session.scalars(select(Sequence.id).order_by(Sequence.id)))
        if not ids:
            raise NotExportable("the project has no sequences to export")
    else:
        ids = list(dict.fromkeys(sequence_ids))
        if not ids:
            raise InvalidExport("sequences must list at least one sequence id, or ask for all",
                                field="sequences")
    # A constant number of statements whatever the project's size (a whole-project export of
    # 1,000 sequences used to send four per sequence).
    names = _names(session, ids)
    ready = _exportable(session, None if sequence_ids is None else ids, fmt, include)
    if sequence_ids is not None:
        for sequence_id in ids:
            _check_sequence(sequence_id, names, ready, fmt, include)
        return Covered(ids, [])
    covered, skipped = [], []
    for sequence_id in ids:
        try:
            _check_sequence(sequence_id, names, ready, fmt, include)
        except NotExportable as exc:
            skipped.append(exc.detail)
        else:
            covered.append(sequence_id)
    if not covered:
        raise NotExportable(f"no sequence of the project can be exported as {fmt}: "
                            + "; ".join(skipped[:5])
                            + (f"; and {len(skipped) - 5} more" if len(skipped) > 5 else ""),
                            field="sequences")
    return Covered(covered, skipped)


def _check_options(fmt: str, options: dict[str, Any], archive: str) -> None:
    allowed = OPTIONS[fmt]
    for name, value in options.items():
        if name not in allowed:
            known = ", ".join(allowed) or "none"
            raise InvalidExport(f"options.{name} is not an option of the {fmt} format "
                                f"(options: {known})", field=f"options.{name}")
        if value is not None and value not in allowed[name]:
            raise InvalidExport(f"options.{name} must be one of {', '.join(allowed[name])}, "
                                f"got {value!r}", field=f"options.{name}")
    if options.get("frames") == "link" and archive == "zip":
        raise InvalidExport("options.frames=link needs a tar archive or a folder; a zip "
                            "archive cannot hold links", field="options.frames")


def _names(session: Session, ids: list[int]) -> dict[int, str]:
    """Each existing sequence of ``ids`` as an export names it: "sequence 3 (subject/name)"."""
    rows = session.execute(select(Sequence.id, Subject.name, Sequence.name)
                           .join(Subject, Subject.id == Sequence.subject_id)
                           .where(Sequence.id.in_(ids)))
    return {i: f"sequence {i} ({subject}/{name})" for i, subject, name in rows}


def _exportable(session: Session, ids: list[int] | None, fmt: str, include: str
                ) -> dict[str, set[int]]:
    """Of ``ids`` (None: every sequence), those with a finished solve and, for a labels
    format, those with work in ``include``'s statuses: one statement each."""
    if fmt in SOLVE_FORMATS:
        solved = select(SolveRun.sequence_id).where(SolveRun.status == "done").distinct()
        if ids is not None:
            solved = solved.where(SolveRun.sequence_id.in_(ids))
        return {"solved": set(session.scalars(solved))}
    labelled = (select(Task.sequence_id).distinct()
                .where(exists().where(Assignment.task_id == Task.id,
                                      Assignment.status.in_(INCLUDE_STATUSES[include]))))
    if ids is not None:
        labelled = labelled.where(Task.sequence_id.in_(ids))
    return {include: set(session.scalars(labelled))}


def _check_sequence(sequence_id: int, names: dict[int, str], ready: dict[str, set[int]],
                    fmt: str, include: str) -> None:
    name = names.get(sequence_id)
    if name is None:
        raise NotFound(f"sequence {sequence_id} does not exist", field="sequences")
    if fmt in SOLVE_FORMATS:
        if sequence_id not in ready["solved"]:
            raise NotExportable(f"{name} has no finished solve; the {fmt} format exports its "
                                f"3D labels (run `dexlabel solve {sequence_id}`)",
                                field="sequences")
        return
    if sequence_id not in ready[include]:
        what = "accepted" if include == "accepted" else "submitted"
        raise NotExportable(f"{name} has no {what} labels to export", field="sequences")


def request_export(session: Session, fmt: str, sequence_ids: list[int] | None,
                   include: str = "accepted", options: dict[str, Any] | None = None,
                   archive: str = "zip") -> Job:
    """Check the request and queue its export job (runs after commit)."""
    options = {k: v for k, v in (options or {}).items() if v is not None}
    if archive not in ARCHIVES:
        raise InvalidExport(f"archive must be one of {', '.join(ARCHIVES)}, got {archive!r}",
                            field="archive")
    ids, skipped = check_request(session, fmt, sequence_ids, include, options, archive)
    key = f"{JOB_KIND}:{secrets.token_hex(8)}"
    args = {"format": fmt, "sequence_ids": ids, "include": include, "options": options,
            "archive": archive, "skipped": skipped}
    job = enqueue_job(session, JOB_KIND, key, args)
    job.max_attempts = 2
    job.progress = {"done": 0, "total": 0, "stage": "queued"}
    session.flush()
    return job


def get_export_or_raise(session: Session, export_id: int) -> Job:
    job = get_job_or_raise(session, export_id)
    if job.kind != JOB_KIND:
        raise NotFound(f"no export {export_id}")
    return job


def run_export(fmt: str, sequence_ids: list[int], include: str, options: dict[str, Any],
               out: Path, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Write the export to ``out`` (zip, tar or folder by its suffix); each sequence is read in
    its own short unit of work. Returns counts for the job's result."""
    with session_scope() as session:
        views = {sid: len(list(session.scalars(select(Camera.id).where(
            Camera.sequence_id == sid)))) for sid in sequence_ids}
    total, done = sum(views.values()), 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    with ExportArchive(out) as archive:
        exporter = EXPORTERS[fmt](archive, options, include)
        for sequence_id in sequence_ids:
            with session_scope() as session:
                # CVAT needs no solve, but where there is one it says which joints left the
                # image (exported outside).
                content = load_sequence(session, sequence_id, include)
            fetch_solve(content)
            exporter.add(content, step)
        exporter.finish()
        archive.commit()
        return {"path": str(out), "bytes": out.stat().st_size if out.is_file() else
                archive.bytes_written, "files": archive.files, "sequences": len(sequence_ids),
                "frames": exporter.frames_written}
