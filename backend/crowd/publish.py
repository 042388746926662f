"""Publishing tasks as HITs: one HIT per task and round, never two.

Every CreateHIT carries a UniqueRequestToken derived from (task, its creation time, round) and
the deployment's secret, and the HIT is remembered in ``crowd_hits``. A publish interrupted
anywhere and run again either finds the row or gets HitAlreadyExists from the marketplace and
recovers the HIT id from it; the row outlives the marketplace's 24-hour token memory.
"""

from __future__ import annotations

import hashlib
import re
from datetime import UTC
from xml.sax.saxutils import escape

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task, TrainingClip
from backend.annotation.tokens import task_token
from backend.config import get_settings
from backend.crowd import pricing
from backend.crowd.client import MarketplaceError, MTurkClient, call
from backend.crowd.models import CrowdHit, CrowdQualification
from backend.crowd.schemas import PublishOptions
from backend.crowd.titles import hit_title, task_facts
from backend.errors import Conflict, DexlabelError

EXTERNAL_QUESTION_NS = ("http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/"
                        "2006-07-14/ExternalQuestion.xsd")
HIT_ALREADY_EXISTS = "AWS.MechanicalTurk.HitAlreadyExists"
QUALIFICATION_EXISTS = "AWS.MechanicalTurk.QualificationTypeAlreadyExists"
TRAINING_QUALIFICATION = "dexlabel: passed training"
# MTurk's system qualification types.
PERCENT_APPROVED = "000000000000000000L0"
LOCALE = "00000000000000000071"
_HIT_ID_IN_MESSAGE = re.compile(r"HIT\s?Id\W*([A-Za-z0-9]+)", re.IGNORECASE)
# The description of each kind of task; the title names the task itself (titles.hit_title).
_DESCRIPTIONS = {
    "hand": ("Click each hand joint on a few frames of a short grasp video; the tool "
             "interpolates between them. Mark joints you cannot see as occluded."),
    "object": ("Pick two points on the highlighted object and follow them through a short "
               "grasp video; mark them occluded when hidden."),
}


class TooManyAssignments(DexlabelError, status_code=422, code="too_many_assignments"):
    pass


def check_assignments(count: int, allow_large_hits: bool) -> None:
    """10+ assignments per HIT raise MTurk's fee from 20% to 40%: only on explicit request."""
    if count >= pricing.LARGE_HIT_ASSIGNMENTS and not allow_large_hits:
        raise TooManyAssignments(
            f"{count} assignments per HIT: 10 or more cost 20% more in MTurk fees; "
            "pass allow_large_hits (--allow-large-hits) to publish them anyway",
            field="max_assignments")


def request_token(task: Task, round_: int) -> str:
    """Deterministic per (task, round) and per deployment (keyed by the secret). The task's
    creation time is part of it: a database may give a deleted task's id to a new one (SQLite
    does), and the new task must not be handed the old task's HIT."""
    created = task.created_at.astimezone(UTC).isoformat()
    seed = f"{get_settings().signing_key}|hit|{task.id}|{created}|{round_}".encode()
    return f"dxhit-{task.id}-{round_}-{hashlib.sha256(seed).hexdigest()[:24]}"


def external_question(task: Task, frame_height: int) -> str:
    """The ExternalQuestion XML: the annotation page for this task, in MTurk's iframe."""
    base = get_settings().public_url.rstrip("/")
    url = f"{base}/annotate/?task={task_token(task)}"
    return (f'<ExternalQuestion xmlns="{EXTERNAL_QUESTION_NS}">'
            f"<ExternalURL>{escape(url)}</ExternalURL>"
            f"<FrameHeight>{frame_height}</FrameHeight></ExternalQuestion>")


def training_qualification(session: Session, client: MTurkClient) -> str:
    """Our "passed training" qualification type id, created on the marketplace once."""
    row = session.scalar(select(CrowdQualification).where(
        CrowdQualification.name == TRAINING_QUALIFICATION))
    if row is not None:
        return row.qualification_type_id
    try:
        reply = call(client, "create_qualification_type", Name=TRAINING_QUALIFICATION,
                     Keywords="dexlabel, training",
                     Description="Granted to workers who passed the dexlabel training task.",
                     QualificationTypeStatus="Active")
    except MarketplaceError as exc:
        if exc.turk_code == QUALIFICATION_EXISTS:
            raise Conflict(f"the marketplace already has a qualification type named "
                           f"{TRAINING_QUALIFICATION!r} that this database does not know") from exc
        raise
    type_id = reply["QualificationType"]["QualificationTypeId"]
    # Not flushed: the caller writes once its marketplace calls are done (see publish_task).
    session.add(CrowdQualification(name=TRAINING_QUALIFICATION, qualification_type_id=type_id))
    return type_id


def requirements(session: Session, client: MTurkClient, options: PublishOptions) -> list[dict]:
    reqs: list[dict] = []
    if options.min_approval_rate is not None:
        reqs.append({"QualificationTypeId": PERCENT_APPROVED, "Comparator": "GreaterThanOrEqualTo",
                     "IntegerValues": [options.min_approval_rate], "ActionsGuarded": "Accept"})
    if options.locales:
        reqs.append({"QualificationTypeId": LOCALE, "Comparator": "In",
                     "LocaleValues": [{"Country": c} for c in options.locales],
                     "ActionsGuarded": "Accept"})
    if options.require_training:
        reqs.append({"QualificationTypeId": training_qualification(session, client),
                     "Comparator": "Exists", "ActionsGuarded": "DiscoverPreviewAndAccept"})
    return reqs


def published_hit(session: Session, task_id: int, round_: int) -> CrowdHit | None:
    return session.scalar(select(CrowdHit).where(
        CrowdHit.task_id == task_id, CrowdHit.round == round_))


def _hit_params(session: Session, task: Task, options: PublishOptions, reqs: list[dict],
                token: str) -> dict:
    description = _DESCRIPTIONS.get(task.kind, _DESCRIPTIONS["hand"])
    return {
        "Title": hit_title(task_facts(session, task)), "Description": description,
        "Keywords": options.keywords,
        "Reward": pricing.cents_to_dollars(pricing.dollars_to_cents(options.reward)),
        "MaxAssignments": options.max_assignments, "LifetimeInSeconds": options.lifetime_s,
        "AssignmentDurationInSeconds": options.assignment_duration_s,
        "AutoApprovalDelayInSeconds": options.auto_approval_delay_s,
        "Question": external_question(task, options.frame_height),
        "RequesterAnnotation": f"dexlabel task {task.id} round {options.round}",
        "QualificationRequirements": reqs, "UniqueRequestToken": token,
    }


def _recovered_hit_id(exc: MarketplaceError) -> str:
    match = _HIT_ID_IN_MESSAGE.search(exc.detail)
    if match is None:
        raise MarketplaceError(f"HIT already exists but its id is not in the reply: {exc.detail}",
                               exc.operation, exc.turk_code) from exc
    return match.group(1)


def _is_training_clip(session: Session, task_id: int) -> bool:
    return session.scalar(select(TrainingClip.id).where(TrainingClip.task_id == task_id)) \
        is not None


def publish_task(
    session: Session, client: MTurkClient, task: Task, options: PublishOptions,
    reqs: list[dict],
) -> tuple[str, str]:
    """Publish one task in ``options.round``; (HIT id, "created" | "recovered" | "existing").

    The marketplace is called before anything is written here: a transaction held open across
    the call would lock the embedded SQLite database the built-in marketplace writes to.
    """
    check_assignments(options.max_assignments, options.allow_large_hits)
    if _is_training_clip(session, task.id):
        # New workers take the training clip to earn the qualification: it cannot require it.
        reqs = [r for r in reqs if r["QualificationTypeId"] in (PERCENT_APPROVED, LOCALE)]
    row = published_hit(session, task.id, options.round)
    if row is not None and row.hit_id is not None:
        return row.hit_id, "existing"
    token = request_token(task, options.round)
    try:
        reply = call(client, "create_hit", **_hit_params(session, task, options, reqs, token))
        hit_id, outcome = reply["HIT"]["HITId"], "created"
    except MarketplaceError as exc:
        if exc.turk_code != HIT_ALREADY_EXISTS:
            raise
        hit_id, outcome = _recovered_hit_id(exc), "recovered"
    if row is None:
        row = CrowdHit(task_id=task.id, round=options.round, request_token=token,
                       max_assignments=options.max_assignments,
                       reward_cents=pricing.dollars_to_cents(options.reward))
        session.add(row)
    row.hit_id = hit_id
    return hit_id, outcome
