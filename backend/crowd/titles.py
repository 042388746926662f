"""What a HIT is called: the target, the view and the clip's length, so that a worker's list of
HITs tells one task from another ("Track the right hand · camera 3 of 8 · 72 frames"). A view
is named by its place among the sequence's cameras; its serial means nothing to a worker."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.captures.models import Hand, SceneObject
from backend.captures.service import object_label

# MTurk rejects a CreateHIT whose Title is longer than this.
MAX_TITLE_CHARS = 128


@dataclass(frozen=True)
class TaskFacts:
    """What a worker needs to tell a task apart: its target, view and length."""

    kind: str  # "hand" | "object"
    target: str  # "right hand", "mustard bottle"
    serial: str  # the camera serial of the view
    num_frames: int
    sequence_id: int
    view_number: int = 1  # the view's place among the sequence's cameras, from 1
    num_views: int = 1

    @property
    def view_name(self) -> str:
        """The view as a worker calls it: "camera 3 of 8"."""
        return f"camera {self.view_number} of {self.num_views}"


def task_facts(session: Session, task: Task) -> TaskFacts:
    if task.kind == "hand":
        hand = session.get(Hand, task.hand_id) if task.hand_id is not None else None
        target = f"{hand.side} hand" if hand is not None and hand.side else "hand"
    else:
        obj = session.get(SceneObject, task.object_id) if task.object_id is not None else None
        target = object_label(obj.name) if obj is not None else "object"
    serials = [camera.serial for camera in task.sequence.cameras]
    return TaskFacts(kind=task.kind, target=target, serial=task.camera.serial,
                     num_frames=task.sequence.num_frames, sequence_id=task.sequence_id,
                     view_number=serials.index(task.camera.serial) + 1, num_views=len(serials))


def hit_title(facts: TaskFacts) -> str:
    """The HIT's Title, at most MAX_TITLE_CHARS: a long object name is shortened, never the
    view or the frame count."""
    tail = f" · {facts.view_name} · {facts.num_frames} frames"
    head = "Track the "
    room = MAX_TITLE_CHARS - len(head) - len(tail)
    target = facts.target if len(facts.target) <= room else facts.target[:max(room - 1, 1)] + "…"
    return f"{head}{target}{tail}"[:MAX_TITLE_CHARS]
