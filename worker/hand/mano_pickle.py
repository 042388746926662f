"""Reading and writing MANO's pickle files (MANO_RIGHT.pkl / MANO_LEFT.pkl) without chumpy.

The official files are Python 2 pickles of a dict whose arrays are partly chumpy objects and whose
J_regressor is a scipy.sparse csc_matrix. We unpickle with a restricted Unpickler: chumpy classes
become a stand-in that keeps the pickled state and is evaluated to a numpy array afterwards (a
plain `Ch` holds its value in `x`; the few reordering nodes that can appear, such as Select or
Reshape, are evaluated from their operands), and scipy.sparse matrices are rebuilt from their
state and made dense. Classes outside a short allow-list are refused, so a file cannot run code.

Known defect of the official left model: its shapedirs have the wrong sign in the x component
(the left file's x-column matches the right file's instead of being mirrored; smplx detects it by
comparing both models and flips the left one). Loading one file at a time, we flip it for any left
model when `fix_left_shapedirs` is True (the default), and `save_mano_pickle` writes left models
in the official files' convention, so our files and the official ones read back the same way.
"""

from __future__ import annotations

import io
import os
import pickle
import tempfile
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse

from worker.hand.joints import MANO_NUM_VERTICES, MANO_TIP_VERTEX_IDS
from worker.hand.params import HandModel, HandSide, check_side

_ROOT_PARENT_ON_DISK = 4294967295  # the official files store the root's parent as uint32 -1
_CHUMPY_KEYS = ("v_template", "shapedirs", "posedirs", "weights", "J")
_ALLOWED = {
    ("copyreg", "_reconstructor"), ("builtins", "object"), ("builtins", "set"),
    ("builtins", "frozenset"), ("builtins", "slice"), ("builtins", "complex"),
    ("collections", "OrderedDict"),
    ("_codecs", "encode"),  # how protocol 2 writes bytes from Python 3
}
_PY2_MODULES = {"__builtin__": "builtins", "copy_reg": "copyreg"}
# What numpy arrays, scalars and dtypes pickle through (in numpy, numpy.core or numpy._core).
_NUMPY_NAMES = {"_reconstruct", "scalar", "ndarray", "dtype", "_frombuffer"}
# What a pickled object's state arrives as: its dict, or (dict, slots) from protocol 2.
_PickledState = dict[str, Any] | tuple[dict[str, Any], Any]


class _ChumpyNode:
    """Stand-in for a pickled chumpy object: keeps its class name and state dict."""

    chumpy_class = "chumpy.ch.Ch"

    def __setstate__(self, state: _PickledState) -> None:
        self.state = state[0] if isinstance(state, tuple) else state


class _SparseNode:
    """Stand-in for a pickled scipy.sparse matrix: keeps its format and state dict."""

    sparse_format = "csc"

    def __setstate__(self, state: _PickledState) -> None:
        self.state = state[0] if isinstance(state, tuple) else state


@cache
def _stand_in(base: type, module: str, name: str) -> type:
    if base is _ChumpyNode:
        return type(name, (_ChumpyNode,), {"chumpy_class": f"{module}.{name}"})
    return type(name, (_SparseNode,), {"sparse_format": name[:3]})


class _ManoUnpickler(pickle.Unpickler):
    """Unpickler that needs neither chumpy nor a matching scipy version, and runs no code."""

    def find_class(self, module: str, name: str) -> Any:
        module = _PY2_MODULES.get(module, module)
        if module == "chumpy" or module.startswith("chumpy."):
            return _stand_in(_ChumpyNode, module, name)
        if module.startswith("scipy.sparse") and name in ("csc_matrix", "csr_matrix"):
            return _stand_in(_SparseNode, module, name)
        if (module == "numpy" or module.startswith("numpy.")) and name in _NUMPY_NAMES:
            # numpy 1.x pickles name numpy.core.*; numpy 2 moved it to numpy._core.
            if module.startswith("numpy.core") and hasattr(np, "_core"):
                module = "numpy._core" + module[len("numpy.core"):]
            return super().find_class(module, name)
        if (module, name) in _ALLOWED:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"MANO pickle refers to {module}.{name}, which is not allowed")


def _evaluate_chumpy(node: _ChumpyNode) -> np.ndarray:
    state = node.state
    kind = node.chumpy_class.rsplit(".", 1)[-1]
    if kind == "Select":
        values = as_array(state["a"]).ravel()[np.asarray(state["idxs"])]
        shape = state.get("preferred_shape")
        return values.reshape(shape) if shape is not None else values
    if kind == "Reshape":
        return as_array(state["a"]).reshape(state["newshape"])
    if kind == "transpose":
        return np.transpose(as_array(state["a"]), state.get("axes"))
    if "x" in state and "a" not in state:
        return as_array(state["x"])
    raise ValueError(f"cannot evaluate {node.chumpy_class} without chumpy")


def as_array(value: object) -> np.ndarray:
    """Any pickled MANO value (ndarray, chumpy stand-in, sparse stand-in) as a dense ndarray."""
    if isinstance(value, _ChumpyNode):
        return _evaluate_chumpy(value)
    if isinstance(value, _SparseNode):
        s = value.state
        shape = tuple(s["_shape"] if "_shape" in s else s["shape"])
        build = scipy.sparse.csc_matrix if value.sparse_format == "csc" else scipy.sparse.csr_matrix
        return build((s["data"], s["indices"], s["indptr"]), shape=shape).toarray()
    return np.asarray(value)


def _side_of(path: Path, data: dict[str, Any], side: str | None) -> HandSide:
    if side is not None:
        return check_side(side)
    if data.get("side") in ("right", "left"):
        return data["side"]
    upper = path.name.upper()
    if "LEFT" in upper and "RIGHT" not in upper:
        return "left"
    if "RIGHT" in upper and "LEFT" not in upper:
        return "right"
    raise ValueError(f"cannot tell the hand side of {path}; pass side='right' or side='left'")


def _tip_vertex_ids(data: dict[str, Any], arrays: dict[str, np.ndarray]) -> np.ndarray:
    """Fingertips: the file's own ids, MANO's usual ones for the 778-vertex mesh, or else for each
    finger the vertex its last bone owns that lies farthest along that bone."""
    if "tip_vertex_ids" in data:
        return as_array(data["tip_vertex_ids"]).astype(np.int64)
    vertices = arrays["v_template"]
    if vertices.shape[0] == MANO_NUM_VERTICES:
        return np.array(MANO_TIP_VERTEX_IDS, dtype=np.int64)
    joints = arrays["J_regressor"] @ vertices
    owner = arrays["weights"].argmax(axis=1)
    tips = []
    for last in (15, 3, 6, 12, 9):  # thumb, index, middle, ring, little in MANO order
        bone = joints[last] - joints[last - 1]
        ids = np.flatnonzero(owner == last)
        if ids.size == 0:
            raise ValueError(f"no vertex is skinned mainly to joint {last}; cannot find its tip")
        tips.append(ids[np.argmax((vertices[ids] - joints[last]) @ bone)])
    return np.array(tips, dtype=np.int64)


def load_mano_pickle(path: str | Path, side: str | None = None, *,
                     fix_left_shapedirs: bool = True) -> HandModel:
    """Load an official (or our) MANO pickle as a HandModel; chumpy need not be installed.

    side: "right" / "left"; when None, taken from the file's "side" entry or its name (MANO_LEFT
    / MANO_RIGHT). fix_left_shapedirs: negate shapedirs[:, 0, :] of a left model (see module doc).
    """
    path = Path(path)
    with path.open("rb") as f:
        data = _ManoUnpickler(f, encoding="latin1").load()
    if not isinstance(data, dict):
        raise ValueError(f"{path} does not hold a MANO parameter dict")
    hand_side = _side_of(path, data, side)
    arrays = {k: as_array(data[k]) for k in ("v_template", "shapedirs", "posedirs", "J_regressor",
                                             "weights", "kintree_table", "hands_components",
                                             "hands_mean", "f")}
    shapedirs = np.array(arrays["shapedirs"], dtype=np.float64)
    if hand_side == "left" and fix_left_shapedirs:
        shapedirs[:, 0, :] *= -1.0
    kintree = np.array(arrays["kintree_table"], dtype=np.int64)
    kintree[0, (kintree[0] < 0) | (kintree[0] >= kintree.shape[1])] = -1
    return HandModel(
        v_template=arrays["v_template"], shapedirs=shapedirs, posedirs=arrays["posedirs"],
        J_regressor=arrays["J_regressor"], weights=arrays["weights"], kintree_table=kintree,
        hands_components=arrays["hands_components"], hands_mean=arrays["hands_mean"],
        faces=arrays["f"], side=hand_side,
        tip_vertex_ids=_tip_vertex_ids(data, arrays),
    )


class _ChumpyArray:
    """Pickles as a chumpy.ch.Ch holding `x` (see _ChumpyStylePickler), for official-style files."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x

    def __getstate__(self) -> dict[str, Any]:
        # chumpy's own state layout, so that real chumpy can read the file too. Pickled with
        # protocol 2, the object is written as NEWOBJ of its class, then BUILD with this state.
        return {"x": self.x, "_dirty_vars": set(), "_itr": None, "_depends_on_deps": {},
                "_make_dense": False, "_make_sparse": False}


class _ChumpyStylePickler(pickle._Pickler):  # the pure-Python pickler lets us name the class
    """Writes references to _ChumpyArray as the global chumpy.ch.Ch (chumpy need not exist)."""

    # Members of the pure-Python pickler that the standard library's stubs leave out.
    write: Callable[[bytes], object]
    memoize: Callable[[object], None]

    def save_global(self, obj: object, name: str | None = None) -> None:
        if obj is _ChumpyArray:
            self.write(pickle.GLOBAL + b"chumpy.ch\nCh\n")
            self.memoize(obj)
            return
        super().save_global(obj, name)  # type: ignore[misc]  # undocumented, so not in the stubs


def _official_layout(model: HandModel, fix_left_shapedirs: bool) -> dict[str, Any]:
    shapedirs = np.array(model.shapedirs)
    if model.side == "left" and fix_left_shapedirs:
        shapedirs[:, 0, :] *= -1.0  # the official left file's convention
    kintree = np.array(model.kintree_table, dtype=np.int64)
    kintree[0, 0] = _ROOT_PARENT_ON_DISK
    return {
        "v_template": np.array(model.v_template), "shapedirs": shapedirs,
        "posedirs": np.array(model.posedirs),
        "J_regressor": scipy.sparse.csc_matrix(model.J_regressor),
        "weights": np.array(model.weights), "kintree_table": kintree,
        "hands_components": np.array(model.hands_components),
        "hands_mean": np.array(model.hands_mean), "hands_coeffs": np.zeros((1, 45)),
        "f": model.faces.astype(np.uint32), "J": model.rest_joints(),
        "bs_style": "lbs", "bs_type": "lrotmin",
        "side": model.side, "tip_vertex_ids": np.array(model.tip_vertex_ids),
    }


def save_mano_pickle(model: HandModel, path: str | Path, chumpy_style: bool = False, *,
                     fix_left_shapedirs: bool = True) -> None:
    """Write `model` in the official MANO pickle layout (protocol 2), atomically.

    Keys: v_template, shapedirs, posedirs, J_regressor (csc_matrix), weights, kintree_table,
    hands_components, hands_mean, hands_coeffs, f (uint32), J (16 x 3 rest joints), bs_style,
    bs_type, plus side and tip_vertex_ids. chumpy_style: store v_template, shapedirs, posedirs,
    weights and J as chumpy.ch.Ch objects, as the official files do.
    """
    data = _official_layout(model, fix_left_shapedirs)
    buffer = io.BytesIO()
    if chumpy_style:
        for key in _CHUMPY_KEYS:
            data[key] = _ChumpyArray(data[key])
        _ChumpyStylePickler(buffer, protocol=2).dump(data)
    else:
        pickle.dump(data, buffer, protocol=2)
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(buffer.getvalue())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
