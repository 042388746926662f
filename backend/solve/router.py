"""Admin endpoints of the solve: request a run, list and read runs, a frame's outputs, pictures."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Response

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.solve import inspection, pictures, service
from backend.solve.models import SolveRun
from backend.solve.schemas import (
    InitialPoseUpdate,
    Optimiser,
    RunComparison,
    RunTimeline,
    SolveFrameRead,
    SolveRequest,
    SolveRunRead,
    SolveSettingsRead,
)
from backend.validation import Id, Index, Key
from worker.overlay import OverlayStyle

router = APIRouter(prefix="/api", tags=["solve"])

_PNG: dict[int | str, dict[str, Any]] = {200: {"content": {"image/png": {}}}}
StyleQuery = Annotated[OverlayStyle, Query(description=(
    "solid: shaded meshes; blend: half transparent; wireframe: the visible triangle edges "
    "only"))]
OptimiserQuery = Annotated[Optimiser, Query(description="paper or default")]


def _read(run: SolveRun, current: SolveRun | None) -> SolveRunRead:
    out = SolveRunRead.model_validate(run)
    out.current = current is not None and current.id == run.id
    return out


@router.post("/sequences/{sequence_id}/solve", response_model=SolveRunRead)
def request_solve(sequence_id: Id, session: SessionDep, _: CurrentAdmin,
                  body: SolveRequest | None = None) -> SolveRunRead:
    body = body or SolveRequest()
    run = service.request_solve(session, sequence_id, body.optimiser, body.params)
    return _read(run, service.current_run(session, sequence_id))


@router.get("/sequences/{sequence_id}/solve-runs", response_model=list[SolveRunRead])
def list_runs(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> list[SolveRunRead]:
    current = service.current_run(session, sequence_id)
    return [_read(run, current) for run in service.list_runs(session, sequence_id)]


@router.put("/sequences/{sequence_id}/objects/{index}/initial-pose")
def set_initial_pose(sequence_id: Id, index: Index, body: InitialPoseUpdate, session: SessionDep,
                     _: CurrentAdmin) -> dict:
    obj = service.set_initial_pose(session, sequence_id, index, body.pose)
    return {"sequence_id": sequence_id, "index": obj.index, "name": obj.name,
            "initial_pose": obj.initial_pose}


@router.get("/solve-runs/{run_id}", response_model=SolveRunRead)
def read_run(run_id: Id, session: SessionDep, _: CurrentAdmin) -> SolveRunRead:
    run = service.get_run_or_raise(session, run_id)
    return _read(run, service.current_run(session, run.sequence_id))


@router.get("/solve-runs/{run_id}/frames/{frame}", response_model=SolveFrameRead)
def read_frame(run_id: Id, frame: Index, session: SessionDep, _: CurrentAdmin,
               vertices: bool = Query(False, description="include the hand mesh")) -> dict:
    run = service.finished_run_or_raise(session, run_id)
    return pictures.frame_outputs(run, frame, vertices)


@router.get("/solve-runs/{run_id}/frames/{frame}/views/{view}.png", responses=_PNG,
            response_class=Response)
def view_overlay(run_id: Id, frame: Index, view: Key, session: SessionDep, _: CurrentAdmin,
                 style: StyleQuery = "solid",
                 alpha: float | None = Query(None, ge=0.0, le=1.0, description=(
                     "opacity of the meshes or lines, 0..1 (default by style: solid 0.85, "
                     "blend 0.5, wireframe 1)"))) -> Response:
    run = service.finished_run_or_raise(session, run_id)
    png = pictures.overlay_png(session, run, frame, view, style, alpha)
    return Response(png, media_type="image/png")


@router.get("/solve-runs/{run_id}/frames/{frame}/residuals.png", responses=_PNG,
            response_class=Response)
def residuals(run_id: Id, frame: Index, session: SessionDep, _: CurrentAdmin) -> Response:
    run = service.finished_run_or_raise(session, run_id)
    return Response(pictures.residuals_png(run, frame), media_type="image/png")


@router.get("/solve-runs/{run_id}/timeline", response_model=RunTimeline)
def timeline(run_id: Id, session: SessionDep, _: CurrentAdmin) -> dict:
    """Every frame at a glance, and the frames that need a look with their reasons."""
    return inspection.run_timeline(service.finished_run_or_raise(session, run_id))


@router.get("/solve-runs/{run_id}/compare/{other_id}", response_model=RunComparison)
def compare(run_id: Id, other_id: Id, session: SessionDep, _: CurrentAdmin) -> dict:
    """How run ``other_id`` differs from run ``run_id`` frame by frame (both finished, one
    sequence): hand joints (mm), each object's pose (mm, degrees), the largest differences."""
    return inspection.compare_runs(session, run_id, other_id)


@router.get("/solve-settings", response_model=SolveSettingsRead)
def solve_settings(_: CurrentAdmin, optimiser: OptimiserQuery = "default") -> dict:
    """The solver settings a new run gets (defaults, then the deployment's); a request's
    ``params`` may override any of them."""
    params = service.editable_params(optimiser)
    return {"optimiser": optimiser, "params": params,
            "kinds": {name: type(value).__name__ for name, value in params.items()}}
