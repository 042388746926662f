"""The page's tokens: a task token opens a read-only preview of one task, an assignment token
opens one assignment for editing, a read-only token shows an admin one assignment's saved
tracks for an hour (it can never save or submit). All are signed with the deployment's
secret and are sent as a bearer header. The frames are read with a view token made for each
page load (``frame_token``): read-only, one view, valid for an hour, the only token that goes
into a frame URL."""

from __future__ import annotations

from urllib.parse import urlencode

from backend.accounts.deps import view_token
from backend.annotation.models import Assignment, Task
from backend.config import get_settings
from backend.security import sign_token

TASK_SCOPE = "task"
ASSIGNMENT_SCOPE = "assignment"
# (The read-only token's scope keeps its first name: links already handed out stay valid.)
READONLY_SCOPE = "review"
TOKEN_TTL_S = 14 * 24 * 3600
# A read-only link is made for a look at the work now, and shows the worker's labels to whoever
# holds it; it lasts about as long as that look.
READONLY_TOKEN_TTL_S = 3600
PREVIEW_ASSIGNMENT_ID = "ASSIGNMENT_ID_NOT_AVAILABLE"
# The page loads every frame of its view at once, right after it reads its task; a reload
# reads the task again and gets a new frame token.
FRAME_TOKEN_TTL_S = 3600


def task_token(task: Task) -> str:
    payload = {"scope": TASK_SCOPE, "task_id": task.id, "sequence_id": task.sequence_id,
               "serial": task.camera.serial}
    return sign_token(payload, get_settings().signing_key, TOKEN_TTL_S)


def assignment_token(task: Task, assignment: Assignment) -> str:
    payload = {"scope": ASSIGNMENT_SCOPE, "assignment_id": assignment.id, "task_id": task.id,
               "sequence_id": task.sequence_id, "serial": task.camera.serial}
    return sign_token(payload, get_settings().signing_key, TOKEN_TTL_S)


def readonly_token(task: Task, assignment: Assignment) -> str:
    """A read-only token for one assignment's saved tracks (READONLY_TOKEN_TTL_S)."""
    payload = {"scope": READONLY_SCOPE, "assignment_id": assignment.id, "task_id": task.id,
               "sequence_id": task.sequence_id, "serial": task.camera.serial}
    return sign_token(payload, get_settings().signing_key, READONLY_TOKEN_TTL_S)


def frame_token(task: Task) -> str:
    """A read-only view token for the task's frames (sequence and camera), for frame URLs."""
    return view_token(task.sequence_id, task.camera.serial, FRAME_TOKEN_TTL_S)


def page_url(base: str, token: str, **params: str) -> str:
    """The annotation page's address for ``token``: the token rides in the fragment
    (``#token=``), which browsers never send, so no server, proxy or access log sees it."""
    query = f"?{urlencode(params)}" if params else ""
    return f"{base.rstrip('/')}/annotate/{query}#{urlencode({'token': token})}"
