"""What QC finds for a hand target: the consensus, the views behind each point, every
assignment's quality, the replay's references and each camera's lag and offset."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.quality.metrics import AssignmentQC
from worker.quality.view_offset import ViewOffset


@dataclass
class HandReport:
    """consensus: (F, P, 3) world metres, NaN where unsupported. support: (F, P) number of
    distinct views behind each point. assignments: AssignmentQC per assignment key.
    provisional: fewer than 3 distinct views support the target."""

    consensus: np.ndarray
    support: np.ndarray
    assignments: dict[str, AssignmentQC]
    provisional: bool
    # What a reviewer's replay draws, per assignment key: "reference" (F, P, 2) px where the
    # other views place each point (NaN where they do not fix it), "errors" (F, P) raw px
    # from the label to it (NaN where not scored).
    replay: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    # Per view, its camera's systematic offset (worker.quality.view_offset) and its lag in
    # whole frames: where found, the view's labels were taken back through them before scoring.
    camera_offsets: dict[int, ViewOffset] = field(default_factory=dict)
    camera_lags: dict[int, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        pts = np.round(self.consensus, 6).astype(object)
        pts[~np.isfinite(self.consensus)] = None
        return {"consensus": pts.tolist(), "support": self.support.astype(int).tolist(),
                "provisional": self.provisional,
                "assignments": {k: a.to_dict() for k, a in self.assignments.items()}}
