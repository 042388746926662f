"""Hand model: MANO's parameter format, our built-in open hand, and a differentiable layer.

Joints come in the DexYCB order (`JOINT_NAMES`); models are `HandModel`s, loaded from the
official MANO pickles or built in; `HandLayer` poses them in PyTorch, and worker.hand.posing
is where every caller turns pose_m into vertices and joints. Lengths are metres.

Only the joint tables load with the package: the rest (PyTorch for the layer, SciPy for the
pickles) loads on first use, so that a process that only names joints (the API, the CLI) never
imports PyTorch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from worker.hand.joints import FINGER_NAMES, JOINT_NAMES, JOINT_PARENTS, TIP_NAMES
from worker.lazy import lazy_names

if TYPE_CHECKING:
    from worker.hand.builtin import builtin_hand_model
    from worker.hand.layer import HandLayer, HandOutput
    from worker.hand.model import HandModel, load_hand_model, load_mano_pickle, save_mano_pickle

# Name -> the module that defines it, imported when the name is first read.
_LAZY = {
    "HandLayer": "worker.hand.layer",
    "HandOutput": "worker.hand.layer",
    "HandModel": "worker.hand.model",
    "builtin_hand_model": "worker.hand.builtin",
    "load_hand_model": "worker.hand.model",
    "load_mano_pickle": "worker.hand.model",
    "save_mano_pickle": "worker.hand.model",
}

__all__ = [
    "FINGER_NAMES",
    "JOINT_NAMES",
    "JOINT_PARENTS",
    "TIP_NAMES",
    "HandLayer",
    "HandModel",
    "HandOutput",
    "builtin_hand_model",
    "load_hand_model",
    "load_mano_pickle",
    "save_mano_pickle",
]


__getattr__ = lazy_names(globals(), _LAZY)
