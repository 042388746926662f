"""The Prolific test double's endpoints (see prolific_double.py), each as Prolific's public
documentation describes it."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Annotated, Any

from fastapi import Body, FastAPI, Request

if TYPE_CHECKING:
    from tests.backend.crowd.prolific_double import ProlificDouble

EDITABLE_AFTER_PUBLISH = {"internal_name", "total_available_places"}
JsonBody = Annotated[dict[str, Any], Body()]


def add_routes(app: FastAPI, double: ProlificDouble) -> None:
    _study_routes(app, double)
    _submission_routes(app, double)
    _bonus_routes(app, double)
    _group_routes(app, double)


def _refuse(status: int, detail: str) -> Exception:
    from tests.backend.crowd.prolific_double import Refusal

    return Refusal(status, detail)


def _study(double: ProlificDouble, study_id: str) -> dict[str, Any]:
    if study_id not in double.studies:
        raise _refuse(404, "Not found.")
    return double.studies[study_id]


def _shown(study: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in study.items() if key != "taken"}


def _page(request: Request, items: list[dict[str, Any]]) -> dict[str, Any]:
    page = int(request.query_params.get("page", "1"))
    chunk = items[(page - 1) * 200:page * 200]
    more = len(items) > page * 200
    href = str(request.url.include_query_params(page=page + 1)) if more else None
    return {"results": chunk, "_links": {"next": {"href": href}}}


def _study_routes(app: FastAPI, double: ProlificDouble) -> None:
    @app.post("/api/v1/studies/", status_code=201)
    def create_study(request: Request, body: JsonBody) -> dict[str, Any]:
        access = body.get("access_details") or []
        if body.get("total_available_places") != sum(a["total_allocation"] for a in access):
            raise _refuse(400, "total_available_places must equal the sum of the "
                               "access details' total_allocation")
        with double.lock:
            study_id = double.new_id("st")
            double.studies[study_id] = {
                **body, "id": study_id, "status": "UNPUBLISHED", "taken": 0,
                "completion_codes": [{"code": "C" + study_id[-6:].upper(),
                                      "code_type": "COMPLETED"}]}
            double.counts["studies_created"] += 1
            made = _shown(double.studies[study_id])
        if double.fault("drop_after_create"):
            request.scope["drop_reply"] = True
        return made

    @app.get("/api/v1/studies/")
    def list_studies(request: Request, state: str | None = None) -> dict[str, Any]:
        with double.lock:
            found = [_shown(s) for s in double.studies.values()
                     if state is None or s["status"] == state]
        return _page(request, found)

    @app.get("/api/v1/studies/{study_id}/")
    def get_study(study_id: str) -> dict[str, Any]:
        return _shown(_study(double, study_id))

    @app.patch("/api/v1/studies/{study_id}/")
    def update_study(study_id: str, body: JsonBody) -> dict[str, Any]:
        with double.lock:
            study = _study(double, study_id)
            if study["status"] != "UNPUBLISHED":
                if set(body) - EDITABLE_AFTER_PUBLISH:
                    raise _refuse(400, "only internal_name and total_available_places can "
                                       "be changed after publishing")
                if body.get("total_available_places", 1 << 30) < \
                        study["total_available_places"]:
                    raise _refuse(400, "total_available_places can only be increased")
            study.update(body)
            return _shown(study)

    @app.post("/api/v1/studies/{study_id}/transition/")
    def transition_study(study_id: str, body: JsonBody) -> dict[str, Any]:
        moves = {("PUBLISH", "UNPUBLISHED"): "ACTIVE", ("PAUSE", "ACTIVE"): "PAUSED",
                 ("START", "PAUSED"): "ACTIVE", ("STOP", "ACTIVE"): "COMPLETED",
                 ("STOP", "PAUSED"): "COMPLETED"}
        with double.lock:
            study = _study(double, study_id)
            after = moves.get((body.get("action"), study["status"]))
            if after is None:
                raise _refuse(400, f"cannot {body.get('action')} a study in status "
                                   f"{study['status']}")
            study["status"] = after
            return _shown(study)

    @app.get("/api/v1/studies/{study_id}/access-details-progress/")
    def progress(study_id: str) -> dict[str, Any]:
        study = _study(double, study_id)
        taken: dict[str, int] = {}
        for item in double.submissions.values():
            if item["study_id"] == study_id:
                taken[item["external_url"]] = taken.get(item["external_url"], 0) + 1
        return {"id": f"ad-{study_id}", "progress": [
            {"external_url": a["external_url"], "total_allocation": a["total_allocation"],
             "allocated": taken.get(a["external_url"], 0)}
            for a in study.get("access_details", [])]}

    @app.get("/api/v1/studies/{study_id}/submissions/")
    def study_submissions(request: Request, study_id: str) -> dict[str, Any]:
        _study(double, study_id)
        with double.lock:
            found = [dict(s) for s in double.submissions.values() if s["study_id"] == study_id]
        return _page(request, found)


def _submission_routes(app: FastAPI, double: ProlificDouble) -> None:
    from tests.backend.crowd.prolific_double import REJECTION_CATEGORIES

    @app.get("/api/v1/submissions/{submission_id}/")
    def get_submission(submission_id: str) -> dict[str, Any]:
        if double.fault("submission_503"):
            raise _refuse(503, "Service unavailable.")
        if submission_id not in double.submissions:
            raise _refuse(404, "Not found.")
        return dict(double.submissions[submission_id])

    @app.post("/api/v1/submissions/{submission_id}/transition/")
    def transition(submission_id: str, body: JsonBody) -> dict[str, Any]:
        action = body.get("action")
        if action == "REJECT":
            if len(str(body.get("message", ""))) < 100:
                raise _refuse(400, "message must be at least 100 characters")
            if body.get("rejection_category") not in REJECTION_CATEGORIES:
                raise _refuse(400, "rejection_category is not valid")
        with double.lock:
            submission = double.submissions.get(submission_id)
            if submission is None:
                raise _refuse(404, "Not found.")
            if submission["status"] != "AWAITING REVIEW" or action not in ("APPROVE",
                                                                           "REJECT"):
                raise _refuse(400, f"cannot {action} a submission in status "
                                   f"{submission['status']}")
            submission["status"] = "APPROVED" if action == "APPROVE" else "REJECTED"
            return dict(submission)


def _bonus_routes(app: FastAPI, double: ProlificDouble) -> None:
    @app.post("/api/v1/submissions/bonus-payments/", status_code=201)
    def set_up_bonuses(body: JsonBody) -> dict[str, Any]:
        _study(double, str(body.get("study_id")))
        rows = [line.split(",") for line in str(body.get("csv_bonuses", "")).splitlines()]
        with double.lock:
            bulk_id = double.new_id("bb")
            double.bulks[bulk_id] = {"id": bulk_id, "study": body["study_id"],
                                     "rows": rows, "status": "PENDING"}
            return {"id": bulk_id, "study": body["study_id"], "status": "PENDING",
                    "total_amount": sum(float(amount) for _, amount in rows)}

    @app.get("/api/v1/bulk-bonus-payments/{bulk_id}/")
    def get_bulk(bulk_id: str) -> dict[str, Any]:
        if bulk_id not in double.bulks:
            raise _refuse(404, "Not found.")
        bulk = double.bulks[bulk_id]
        return {"id": bulk_id, "study": bulk["study"], "status": bulk["status"]}

    @app.post("/api/v1/bulk-bonus-payments/{bulk_id}/pay/")
    def pay(request: Request, bulk_id: str) -> dict[str, Any]:
        with double.lock:
            if bulk_id not in double.bulks:
                raise _refuse(404, "Not found.")
            double.paying += 1
            double.max_paying = max(double.max_paying, double.paying)
            overlapping = double.paying > 1
        try:
            if overlapping or double.fault("throttle_pays"):
                double.counts["throttled_pays"] += 1
                raise _refuse(429, "Request was throttled.")
            time.sleep(0.01)
            with double.lock:
                bulk = double.bulks[bulk_id]
                # Not idempotent, as documented: every call pays.
                double.payments.extend((bulk_id, who, amount) for who, amount in bulk["rows"])
                bulk["status"] = "PAID"
        finally:
            with double.lock:
                double.paying -= 1
        if double.fault("drop_after_pay"):
            request.scope["drop_reply"] = True
        return {"id": bulk_id, "status": "PAID"}


def _group_routes(app: FastAPI, double: ProlificDouble) -> None:
    @app.get("/api/v1/participant-groups/")
    def list_groups(request: Request) -> dict[str, Any]:
        return _page(request, [{"id": g["id"], "name": g["name"]}
                               for g in double.groups.values()])

    @app.post("/api/v1/participant-groups/", status_code=201)
    def create_group(body: JsonBody) -> dict[str, Any]:
        with double.lock:
            group_id = double.new_id("pg")
            double.groups[group_id] = {"id": group_id, "name": body["name"], "members": set()}
            return {"id": group_id, "name": body["name"]}

    @app.post("/api/v1/participant-groups/{group_id}/participants/")
    def add(group_id: str, body: JsonBody) -> dict[str, Any]:
        if group_id not in double.groups:
            raise _refuse(404, "Not found.")
        double.groups[group_id]["members"].update(body["participant_ids"])
        return {"results": sorted(double.groups[group_id]["members"])}

    @app.delete("/api/v1/participant-groups/{group_id}/participants/")
    def remove(group_id: str, body: JsonBody) -> dict[str, Any]:
        if group_id not in double.groups:
            raise _refuse(404, "Not found.")
        double.groups[group_id]["members"].difference_update(body["participant_ids"])
        return {"results": sorted(double.groups[group_id]["members"])}

    @app.post("/api/v1/messages/", status_code=201)
    def message(body: JsonBody) -> dict[str, Any]:
        double.messages.append(body)
        return {"id": double.new_id("msg")}

    @app.post("/api/v1/hooks/secrets/", status_code=201)
    def make_secret(body: JsonBody) -> dict[str, Any]:
        double.secret = f"whsec-{double.new_id('')}"
        return {"id": double.new_id("sec"), "value": double.secret,
                "workspace_id": body["workspace_id"]}

    @app.get("/api/v1/hooks/subscriptions/")
    def list_subscriptions(request: Request) -> dict[str, Any]:
        return _page(request, list(double.subscriptions))

    @app.post("/api/v1/hooks/subscriptions/", status_code=201)
    def subscribe(body: JsonBody) -> dict[str, Any]:
        made = {"id": double.new_id("hook"), "event_type": body["event_type"],
                "target_url": body["target_url"], "workspace_id": body["workspace_id"]}
        double.subscriptions.append(made)
        return made
