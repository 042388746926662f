"""Hand model: MANO's parameter format, our built-in open hand, and a differentiable layer.

Joints come in the DexYCB order (`JOINT_NAMES`); models are `HandModel`s, loaded from the
official MANO pickles or built in; `HandLayer` poses them in PyTorch, and worker.hand.posing
is where every caller turns pose_m into vertices and joints. Lengths are metres.
"""

from worker.hand.builtin import builtin_hand_model
from worker.hand.joints import FINGER_NAMES, JOINT_NAMES, JOINT_PARENTS, TIP_NAMES
from worker.hand.layer import HandLayer, HandOutput
from worker.hand.model import HandModel, load_hand_model, load_mano_pickle, save_mano_pickle

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
