"""3D solve: MANO hand and 6D object poses per frame from crowd keypoints and depth.

`solve(inputs, settings)` minimises E = E_kpt + E_depth + E_reg (DexYCB's energy) with either
the paper's per-frame Adam (`optimiser="paper"`) or the default batched Levenberg-Marquardt.
Pure NumPy/PyTorch: no I/O. World = the capture's master frame, metres; pixels x right, y down.

The input and settings types load with the package; `solve` and `hand_vertices` (PyTorch) load
on first use, so that a process that only builds inputs or reads settings (the API) never
imports PyTorch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from worker.lazy import lazy_names
from worker.solver.types import (
    HandTarget,
    Landmark,
    ObjectTarget,
    SolveInputs,
    SolveResult,
    SolveSettings,
)

if TYPE_CHECKING:
    from worker.solver.entry import hand_vertices, solve

# Name -> the module that defines it, imported when the name is first read. (The module is not
# named solve: importing a submodule sets the package's attribute of its name, which would hide
# the function.)
_LAZY = {"hand_vertices": "worker.solver.entry", "solve": "worker.solver.entry"}

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


__getattr__ = lazy_names(globals(), _LAZY)
