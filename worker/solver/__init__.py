"""3D solve: MANO hand and 6D object poses per frame from crowd keypoints and depth.

`solve(inputs, settings)` minimises E = E_kpt + E_depth + E_reg (DexYCB's energy) with either
the paper's per-frame Adam (`optimiser="paper"`) or the default batched Levenberg-Marquardt.
Pure NumPy/PyTorch: no I/O. World = the capture's master frame, metres; pixels x right, y down.
"""

from worker.solver.solve import hand_vertices, solve
from worker.solver.types import (
    HandTarget,
    Landmark,
    ObjectTarget,
    SolveInputs,
    SolveResult,
    SolveSettings,
)

__all__ = [
    "HandTarget",
    "Landmark",
    "ObjectTarget",
    "SolveInputs",
    "SolveResult",
    "SolveSettings",
    "hand_vertices",
    "solve",
]
