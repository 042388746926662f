"""Hand models in MANO's parameter format: the type, and where a model comes from.

`load_hand_model` is the one entry point the product uses: the official MANO pickles when a MANO
directory is configured (settings' DEXLABEL_MANO_DIR), the built-in open hand otherwise.
"""

from __future__ import annotations

from pathlib import Path

from worker.hand.builtin import builtin_hand_model
from worker.hand.mano_pickle import load_mano_pickle, save_mano_pickle
from worker.hand.params import HandModel, HandSide, check_side

__all__ = [
    "HandModel",
    "HandSide",
    "load_hand_model",
    "load_mano_pickle",
    "mano_file_name",
    "save_mano_pickle",
]


def mano_file_name(side: HandSide) -> str:
    """The official file name for `side`: MANO_RIGHT.pkl or MANO_LEFT.pkl."""
    return f"MANO_{check_side(side).upper()}.pkl"


def load_hand_model(side: HandSide, mano_dir: str | Path | None = None) -> HandModel:
    """The hand model for `side`: MANO_<SIDE>.pkl from `mano_dir` if given, else the built-in.

    Raises FileNotFoundError naming the missing file when mano_dir lacks it.
    """
    side = check_side(side)
    if mano_dir is None:
        return builtin_hand_model(side)
    path = Path(mano_dir) / mano_file_name(side)
    if not path.is_file():
        raise FileNotFoundError(f"MANO model file not found: {path} (expected {path.name} in "
                                f"the MANO directory {Path(mano_dir)})")
    return load_mano_pickle(path, side)
