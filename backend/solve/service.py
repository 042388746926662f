"""Solve rules: who may be solved, runs, reading a run's outputs. Services flush, never commit.

A sequence can be solved once its hand has betas (the subject's shape) and at least one
assignment has been approved. An object without an initial pose gets one fitted to frame 0 by
the solve, which fails, naming the object and why, where that fit fails (then an admin gives
it). A request creates a run and queues the ``solve`` job; the run's outputs become the
sequence's current result only when the job finishes, so a re-run (or a failed one) never
hides the previous result.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.captures.models import SceneObject, Sequence
from backend.captures.service import get_sequence_or_raise
from backend.config import get_settings
from backend.db import utcnow
from backend.errors import Conflict, DexlabelError, NotFound
from backend.jobs.service import enqueue_job
from backend.labels import count_accepted
from backend.solve.models import SolveRun
from backend.solve.results import encode_result, result_key
from backend.storage import get_storage
from worker.solver import SolveSettings
from worker.solver.types import SolveResult

JOB_KIND = "solve"
Optimiser = Literal["paper", "default"]
OPTIMISERS: tuple[Optimiser, ...] = ("paper", "default")
# A given rotation block must be orthonormal to this tolerance (unitless).
ROTATION_TOLERANCE = 1e-4


class SolveNotReady(Conflict, code="not_ready"):
    """The sequence lacks something the solve needs; the detail says what and how to give it."""


class InvalidSolveRequest(DexlabelError, status_code=422, code="invalid_request"):
    pass


class InvalidPose(DexlabelError, status_code=422, code="invalid_pose"):
    pass


def job_key(run_id: int) -> str:
    return f"solve-run:{run_id}"


def check_ready(session: Session, seq: Sequence) -> None:
    """Raise SolveNotReady naming the first thing the sequence lacks."""
    for hand in seq.hands:
        if not hand.betas:
            raise SolveNotReady(
                f"hand {hand.index} ({hand.side}) has no betas; run `dexlabel calibrate-hand "
                f"{seq.id}` or give them in the capture's mano.yml", hand_index=hand.index)
    if count_accepted(session, seq.id) == 0:
        raise SolveNotReady(f"sequence {seq.id} has no accepted (approved) tracks to solve from")


# Settings a request may not override: chosen by their own field or by the deployment.
_FIXED_PARAMS = ("optimiser", "device")


def solver_params(optimiser: Optimiser, overrides: dict | None = None) -> dict:
    """The solver settings a run records and uses (JSON): defaults, then the deployment's
    DEXLABEL_SOLVE_PARAMS, then ``overrides``."""
    settings = dataclasses.asdict(SolveSettings(optimiser=optimiser,
                                                device=get_settings().solve_device))
    for name, value in {**get_settings().solve_params, **(overrides or {})}.items():
        if name not in settings or name in _FIXED_PARAMS:
            allowed = sorted(set(settings) - set(_FIXED_PARAMS))
            raise InvalidSolveRequest(f"params.{name} is not a solver setting; one of "
                                f"{', '.join(allowed)}", field=f"params.{name}")
        default = settings[name]
        wrong_kind = isinstance(default, bool) != isinstance(value, bool)
        if wrong_kind or (isinstance(default, int) and value != int(value)):
            raise InvalidSolveRequest(f"params.{name} must be a {type(default).__name__}, got "
                                f"{value!r}", field=f"params.{name}")
        settings[name] = type(default)(value)
    return settings


def editable_params(optimiser: Optimiser) -> dict:
    """The settings a run of ``optimiser`` gets that a request may override."""
    return {name: value for name, value in solver_params(optimiser).items()
            if name not in _FIXED_PARAMS}


def _optimiser(name: str) -> Optimiser:
    """``name`` as one of OPTIMISERS; InvalidSolveRequest (422) when it is none of them."""
    for known in OPTIMISERS:
        if name == known:
            return known
    raise InvalidSolveRequest(f"optimiser must be one of {', '.join(OPTIMISERS)}, got "
                              f"{name!r}", field="optimiser")


def request_solve(session: Session, sequence_id: int, optimiser: str | None = None,
                  params: dict | None = None, labels_digest: str | None = None) -> SolveRun:
    """Create a run of the sequence's solve and queue its job (runs after commit); a run
    with the same settings that is still queued is returned instead of a second one.

    optimiser: "paper" or "default"; None takes DEXLABEL_SOLVE_OPTIMISER. params: overrides
    of the solver's settings (see solver_params).
    Raises NotFound (no sequence), SolveNotReady (409) or InvalidSolveRequest (422: an
    unknown optimiser or parameter).
    """
    chosen = _optimiser(optimiser or get_settings().solve_optimiser)
    settings = solver_params(chosen, params)
    seq = get_sequence_or_raise(session, sequence_id)
    check_ready(session, seq)
    waiting = session.scalars(select(SolveRun).where(
        SolveRun.sequence_id == seq.id, SolveRun.status == "queued",
        SolveRun.optimiser == chosen).order_by(SolveRun.id)).all()
    for run in waiting:
        # Not started yet, so it will read the newest labels: asking again changes nothing.
        if run.params == settings:
            run.labels_digest = labels_digest or run.labels_digest
            return run
    run = SolveRun(sequence_id=seq.id, optimiser=chosen, params=settings,
                   status="queued", timings={}, num_frames=seq.num_frames,
                   num_views=len(seq.cameras), labels_digest=labels_digest)
    session.add(run)
    session.flush()
    enqueue_job(session, JOB_KIND, job_key(run.id), {"run_id": run.id})
    return run


def get_run_or_raise(session: Session, run_id: int) -> SolveRun:
    run = session.get(SolveRun, run_id)
    if run is None:
        raise NotFound(f"solve run {run_id} does not exist")
    return run


def list_runs(session: Session, sequence_id: int) -> list[SolveRun]:
    get_sequence_or_raise(session, sequence_id)
    return list(session.scalars(select(SolveRun).where(SolveRun.sequence_id == sequence_id)
                                .order_by(SolveRun.id.desc())))


def current_run(session: Session, sequence_id: int) -> SolveRun | None:
    """The sequence's result: its newest run that finished."""
    stmt = (select(SolveRun).where(SolveRun.sequence_id == sequence_id,
                                   SolveRun.status == "done")
            .order_by(SolveRun.finished_at.desc(), SolveRun.id.desc()).limit(1))
    return session.scalars(stmt).first()


def finished_run_or_raise(session: Session, run_id: int) -> SolveRun:
    """A run whose outputs can be read; 409 while it is queued, running or failed."""
    run = get_run_or_raise(session, run_id)
    if run.status != "done" or run.result_key is None:
        raise Conflict(f"solve run {run_id} is {run.status}; outputs exist once it is done",
                       state=run.status)
    return run


def check_frame(run: SolveRun, frame: int) -> None:
    if not 0 <= frame < run.num_frames:
        raise NotFound(f"frame {frame} is out of range: run {run.id} has frames 0.."
                       f"{run.num_frames - 1}")


def resolve_view(run: SolveRun, view: str, serials: list[str]) -> int:
    """A view given as a camera serial or an index into the run's views."""
    if view in serials:
        return serials.index(view)
    if view.isdigit() and int(view) < len(serials):
        return int(view)
    raise NotFound(f"view {view!r} is out of range: run {run.id} has views 0..{len(serials) - 1}"
                   f" (serials {', '.join(serials)})")


def set_initial_pose(session: Session, sequence_id: int, index: int,
                     pose: list[list[float]]) -> SceneObject:
    """Give object ``index`` its object-to-world (3, 4) pose at the first frame, metres."""
    seq = get_sequence_or_raise(session, sequence_id)
    obj = next((o for o in seq.objects if o.index == index), None)
    if obj is None:
        raise NotFound(f"object {index} is out of range: sequence {sequence_id} has objects "
                       f"0..{len(seq.objects) - 1}")
    matrix = np.asarray(pose, dtype=np.float64)
    if not np.isfinite(matrix).all():
        raise InvalidPose("pose must hold finite numbers", field="pose")
    rot = matrix[:, :3]
    if (np.abs(rot.T @ rot - np.eye(3)).max() > ROTATION_TOLERANCE
            or np.linalg.det(rot) < 0):
        raise InvalidPose("pose's first three columns must be a rotation (orthonormal, "
                          "determinant +1)", field="pose")
    obj.initial_pose = matrix.tolist()
    session.flush()
    return obj


def store_object_poses(session: Session, sequence_id: int, object_poses: np.ndarray) -> SolveRun:
    """A finished run of the sequence whose stored result holds these object poses (O, F, 3, 4)
    object-to-world, every pose trusted, and no hand: stands a known answer in for the solver
    (benchmarks and tests of what follows a solve, such as the landmark check)."""
    objects, frames = object_poses.shape[:2]
    sequence = get_sequence_or_raise(session, sequence_id)
    result = SolveResult(
        hand_pose_m=np.full((frames, 51), np.nan), hand_joints=np.full((frames, 21, 3), np.nan),
        object_poses=object_poses, labelled=np.zeros(frames, bool), reasons=[None] * frames,
        kpt_error_px=np.full((frames, len(sequence.cameras), 21), np.nan),
        depth_rms_mm=np.full(frames, np.nan),
        landmark_vertices=[[] for _ in range(objects)], timings={},
        object_confidence=np.ones((objects, frames)),
        object_flags=[[None] * frames for _ in range(objects)])
    return store_result(session, sequence_id, result, None)


def store_result(session: Session, sequence_id: int, result: SolveResult,
                 hand_side: str | None, optimiser: Optimiser = "default",
                 params: dict | None = None) -> SolveRun:
    """A finished run of the sequence holding ``result`` as its outputs (a known answer standing
    in for the solver: benchmarks, tests, a result solved elsewhere). hand_side: "left" or
    "right" when the result has a hand (its betas in result.betas), else None."""
    sequence = get_sequence_or_raise(session, sequence_id)
    frames = len(result.labelled)
    run = SolveRun(sequence_id=sequence_id, optimiser=optimiser, params=params or {},
                   status="done", timings=dict(result.timings), num_frames=frames,
                   num_views=len(sequence.cameras), finished_at=utcnow())
    session.add(run)
    session.flush()
    run.result_key = result_key(sequence.storage_uid, run.id)
    get_storage().put_bytes(run.result_key, encode_result(
        result, [c.serial for c in sequence.cameras], [o.name for o in sequence.objects],
        hand_side), "application/octet-stream")
    return run
