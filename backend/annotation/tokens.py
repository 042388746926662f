"""The page's tokens: a task token opens a read-only preview of one task, an assignment token
opens one assignment for editing. Both are signed with the deployment's secret and name the
sequence and view whose frames they open."""

from __future__ import annotations

from backend.annotation.models import Assignment, Task
from backend.config import get_settings
from backend.security import sign_token

TASK_SCOPE = "task"
ASSIGNMENT_SCOPE = "assignment"
TOKEN_TTL_S = 14 * 24 * 3600
PREVIEW_ASSIGNMENT_ID = "ASSIGNMENT_ID_NOT_AVAILABLE"


def task_token(task: Task) -> str:
    payload = {"scope": TASK_SCOPE, "task_id": task.id, "sequence_id": task.sequence_id,
               "serial": task.camera.serial}
    return sign_token(payload, get_settings().secret_key, TOKEN_TTL_S)


def assignment_token(task: Task, assignment: Assignment) -> str:
    payload = {"scope": ASSIGNMENT_SCOPE, "assignment_id": assignment.id, "task_id": task.id,
               "sequence_id": task.sequence_id, "serial": task.camera.serial}
    return sign_token(payload, get_settings().secret_key, TOKEN_TTL_S)
