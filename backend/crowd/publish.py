"""Publishing tasks as units of work of a crowd provider: one per task and round, never two.

Every unit carries a key derived from (task, its creation time, round) and the deployment's
secret (MTurk's UniqueRequestToken), and is remembered in ``crowd_hits`` with its provider. A
publish interrupted anywhere and run again either finds the row or has the provider recover the
unit published under the key (MTurk: HitAlreadyExists names the HIT); the row outlives the
provider's memory of the key (MTurk's: 24 hours).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from datetime import UTC

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task, TrainingClip
from backend.annotation.tokens import task_token
from backend.config import get_settings
from backend.crowd import pricing
from backend.crowd.models import CrowdHit, CrowdQualification
from backend.crowd.provider import CrowdProvider, FeeSchedule, PublishedUnit, Requirements, UnitSpec
from backend.crowd.providers import provider_of
from backend.crowd.providers.mturk import EXTERNAL_QUESTION_NS  # noqa: F401 (its old home)
from backend.crowd.schemas import PublishOptions
from backend.crowd.titles import hit_title, task_facts
from backend.errors import DexlabelError

TRAINING_QUALIFICATION = "dexlabel: passed training"
# The description of each kind of task; the title names the task itself (titles.hit_title).
_DESCRIPTIONS = {
    "hand": ("Click each hand joint on a few frames of a short grasp video; the tool "
             "interpolates between them. Mark joints you cannot see as occluded."),
    "object": ("Pick two points on the highlighted object and follow them through a short "
               "grasp video; mark them occluded when hidden."),
}
# The expected working time of a task, for a provider's pay floor.
EXPECTED_S = {"hand": 600, "object": 300}


class TooManyAssignments(DexlabelError, status_code=422, code="too_many_assignments"):
    pass


def check_assignments(count: int, allow_large_hits: bool, fees: FeeSchedule) -> None:
    """Units with the provider's large-unit place count (MTurk: 10+ assignments per HIT raise
    its fee from 20% to 40%) cost more in fees: only on explicit request."""
    if not fees.large_unit_places or count < fees.large_unit_places or allow_large_hits:
        return
    more = round((fees.large_unit_rate - fees.reward_rate) * 100)
    raise TooManyAssignments(
        f"{count} assignments per HIT: {fees.large_unit_places} or more cost {more}% more in "
        f"{fees.provider} fees; pass allow_large_hits (--allow-large-hits) to publish them "
        "anyway", field="max_assignments")


def request_token(task: Task, round_: int) -> str:
    """Deterministic per (task, round) and per deployment (keyed by the secret). The task's
    creation time is part of it: a database may give a deleted task's id to a new one (SQLite
    does), and the new task must not be handed the old task's HIT."""
    created = task.created_at.astimezone(UTC).isoformat()
    seed = f"{get_settings().signing_key}|hit|{task.id}|{created}|{round_}".encode()
    return f"dxhit-{task.id}-{round_}-{hashlib.sha256(seed).hexdigest()[:24]}"


def page_url(task: Task) -> str:
    """The annotation page of this task (its task token in the address)."""
    base = get_settings().public_url.rstrip("/")
    return f"{base}/annotate/?task={task_token(task)}"


def _group_name(provider: CrowdProvider) -> str:
    """Our name of the provider's "passed training" allow-list (MTurk's keeps the name it was
    created under when MTurk was the only crowd)."""
    if provider.name == "mturk":
        return TRAINING_QUALIFICATION
    return f"{TRAINING_QUALIFICATION} ({provider.name})"


def training_qualification(session: Session, crowd: CrowdProvider) -> str:
    """Our "passed training" allow-list on the provider (an MTurk qualification type), made
    there once: ``provider.training_group()`` the first time, then found in our table."""
    provider = provider_of(crowd)
    name = _group_name(provider)
    row = session.scalar(select(CrowdQualification).where(CrowdQualification.name == name))
    if row is not None:
        return row.qualification_type_id
    type_id = provider.training_group()
    # Not flushed: the caller writes once its provider calls are done (see publish_task).
    session.add(CrowdQualification(name=name, qualification_type_id=type_id))
    return type_id


def requirements(session: Session, crowd: CrowdProvider, options: PublishOptions
                 ) -> Requirements:
    """Who may take the units ``options`` publishes."""
    group = training_qualification(session, crowd) if options.require_training else None
    return Requirements(min_approval_rate=options.min_approval_rate,
                        locales=tuple(options.locales), group=group, assignee=options.assignee)


def published_hit(session: Session, task_id: int, round_: int) -> CrowdHit | None:
    return session.scalar(select(CrowdHit).where(
        CrowdHit.task_id == task_id, CrowdHit.round == round_))


def unit_spec(session: Session, task: Task, options: PublishOptions,
              reqs: Requirements | None) -> UnitSpec:
    """The unit of work publishing ``task`` in ``options.round`` (None: no requirements)."""
    reqs = reqs or Requirements()
    if _is_training_clip(session, task.id):
        # New workers take the training clip to earn the allow-list: it cannot require it.
        reqs = Requirements(reqs.min_approval_rate, reqs.locales, None, reqs.assignee)
    return UnitSpec(
        key=request_token(task, options.round), task_id=task.id,
        title=hit_title(task_facts(session, task)),
        description=_DESCRIPTIONS.get(task.kind, _DESCRIPTIONS["hand"]),
        keywords=options.keywords, page_url=page_url(task),
        reward_cents=pricing.dollars_to_cents(options.reward), places=options.max_assignments,
        lifetime_s=options.lifetime_s, allotted_s=options.assignment_duration_s,
        auto_approve_s=options.auto_approval_delay_s,
        expected_s=EXPECTED_S.get(task.kind, EXPECTED_S["hand"]),
        frame_height=options.frame_height,
        note=f"dexlabel task {task.id} round {options.round}", requirements=reqs)


def _is_training_clip(session: Session, task_id: int) -> bool:
    return session.scalar(select(TrainingClip.id).where(TrainingClip.task_id == task_id)) \
        is not None


def publish_tasks(session: Session, crowd: CrowdProvider, tasks: Sequence[Task],
                  options: PublishOptions, reqs: Requirements | None,
                  reasons: Mapping[int, str | None] | None = None) -> list[tuple[str, str]]:
    """Publish the tasks in ``options.round`` in one provider batch; per task (unit id,
    "created" | "recovered" | "existing"). ``reasons``: per task id, why it is published
    (backend.crowd.adaptive), kept on its new unit's row.

    The provider is called before anything is written here: a transaction held open across
    the call would lock the embedded SQLite database the built-in marketplace writes to.
    """
    provider = provider_of(crowd)
    fees = provider.fees()
    check_assignments(options.max_assignments, options.allow_large_hits, fees)
    rows = {task.id: published_hit(session, task.id, options.round) for task in tasks}
    due = [task for task in tasks if _unpublished(rows[task.id])]
    specs = [unit_spec(session, task, options, reqs) for task in due]
    if specs:
        provider.check_publish(specs)
    published: dict[str, PublishedUnit] = {
        unit.key: unit for unit in (provider.publish(specs) if specs else [])}
    spec_of = {spec.task_id: spec for spec in specs}
    out: list[tuple[str, str]] = []
    for task in tasks:
        row = rows[task.id]
        if row is not None and row.hit_id is not None:
            out.append((row.hit_id, "existing"))
            continue
        spec = spec_of[task.id]
        unit = published[spec.key]
        if row is None:
            row = CrowdHit(task_id=task.id, round=options.round, request_token=spec.key,
                           max_assignments=options.max_assignments,
                           reward_cents=spec.reward_cents, provider=provider.name,
                           reason=(reasons or {}).get(task.id))
            session.add(row)
        row.hit_id = unit.unit_id
        out.append((unit.unit_id, unit.outcome))
    return out


def _unpublished(row: CrowdHit | None) -> bool:
    return row is None or row.hit_id is None


def publish_task(session: Session, crowd: CrowdProvider, task: Task, options: PublishOptions,
                 reqs: Requirements | None) -> tuple[str, str]:
    """Publish one task in ``options.round``; (unit id, "created" | "recovered" |
    "existing")."""
    return publish_tasks(session, crowd, [task], options, reqs)[0]
