"""Every ORM model, imported in one place so Alembic and the app see the whole schema."""

from backend.accounts.models import Admin, PortalAccount, PortalInvite
from backend.annotation.models import Assignment, Task, Track, TrainingClip
from backend.captures.calibration import CalibrationVersion
from backend.captures.models import Camera, Frame, Hand, SceneObject, Sequence, Subject
from backend.crowd import models as crowd
from backend.crowd.providers.prolific import models as prolific
from backend.db import Base
from backend.jobs.models import Job
from backend.market import models as market
from backend.quality.models import QCReport
from backend.solve.models import SolveRun

__all__ = [
    "Admin", "Assignment", "Base", "CalibrationVersion", "Camera", "Frame", "Hand", "Job",
    "PortalAccount", "PortalInvite", "QCReport", "SceneObject", "Sequence", "SolveRun",
    "Subject", "Task", "Track", "TrainingClip", "crowd", "market", "prolific",
]
