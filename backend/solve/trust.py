"""What a finished solve says of each target of its sequence, for the adaptive publishing
policy (backend.crowd.adaptive): per target key, the per-frame confidence and flags the solve
stored (backend.solve.results) and where the target was solved (world metres)."""

from __future__ import annotations

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.captures.models import SceneObject
from backend.crowd.adaptive import TargetTrust
from backend.solve.results import hand_trust, object_trust


def target_trust(session: Session, sequence_id: int, arrays: dict[str, np.ndarray]
                 ) -> dict[str, TargetTrust]:
    """Per target key of the sequence ("hand:0", "object:1", ...): confidence (F,), flags
    (F,) and points (F, N, 3): the solved hand joints, or the solved object's origin."""
    out: dict[str, TargetTrust] = {}
    names = [str(n) for n in arrays.get("object_names", np.zeros(0, str))]
    object_confidence, object_flags = object_trust(arrays)
    origins = np.asarray(arrays["object_poses"], np.float64)[:, :, :3, 3]
    rows = session.execute(
        select(Task.target_key, Task.kind, SceneObject.name)
        .outerjoin(SceneObject, SceneObject.id == Task.object_id)
        .where(Task.sequence_id == sequence_id).distinct()).all()
    for target, kind, name in rows:
        if kind == "hand":
            confidence, flags = hand_trust(arrays)
            out[target] = TargetTrust(confidence, flags, np.asarray(arrays["hand_joints"]))
        elif name in names:
            o = names.index(name)
            out[target] = TargetTrust(object_confidence[o], object_flags[o],
                                      origins[o][:, None, :])
    return out
