"""Joint tables: the 21-joint DexYCB order and the 16-joint MANO skeleton order.

DexYCB (and our annotation tasks) list 21 hand joints: the wrist, then for each finger from the
thumb to the little finger its three joints and its tip. MANO's kinematic skeleton has 16 joints in
a different order (wrist; index, middle, little, ring, thumb with three joints each) and no tips;
tips are read off five mesh vertices. The tables here convert between the two.

For the thumb, DexYCB's names "thumb_mcp", "thumb_pip", "thumb_dip" are MANO's three thumb joints
(anatomically the CMC, MCP and IP joints); the names are kept as the dataset spells them.
"""

from __future__ import annotations

FINGER_NAMES: tuple[str, ...] = ("thumb", "index", "middle", "ring", "little")

_JOINT_SUFFIXES: tuple[str, ...] = ("mcp", "pip", "dip", "tip")

JOINT_NAMES: tuple[str, ...] = (
    "wrist",
    *(f"{finger}_{suffix}" for finger in FINGER_NAMES for suffix in _JOINT_SUFFIXES),
)

TIP_NAMES: tuple[str, ...] = tuple(f"{finger}_tip" for finger in FINGER_NAMES)

# Parent of each DexYCB joint: every finger chain hangs off the wrist (index 0).
JOINT_PARENTS: tuple[int, ...] = (
    -1,
    *(0 if k == 0 else 1 + 4 * f + k - 1 for f in range(len(FINGER_NAMES)) for k in range(4)),
)

NUM_JOINTS = len(JOINT_NAMES)  # 21
NUM_SKELETON_JOINTS = 16  # MANO's kinematic joints
NUM_POSE_JOINTS = NUM_SKELETON_JOINTS - 1  # joints 1..15 carry the 45-d hand pose

# MANO skeleton order: first joint index of each finger's 3-joint chain, per FINGER_NAMES.
MANO_FINGER_START: dict[str, int] = {"index": 1, "middle": 4, "little": 7, "ring": 10, "thumb": 13}

MANO_JOINT_NAMES: tuple[str, ...] = (
    "wrist",
    *(
        f"{finger}_{suffix}"
        for finger in ("index", "middle", "little", "ring", "thumb")
        for suffix in _JOINT_SUFFIXES[:3]
    ),
)

# MANO kinematic parents (kintree_table row 0, with -1 for the root).
MANO_PARENTS: tuple[int, ...] = (
    -1,
    *(0 if k == 0 else start + k - 1 for start in (1, 4, 7, 10, 13) for k in range(3)),
)

# Index into concat(skeleton (16 joints, MANO order), tips (5, FINGER_NAMES order)) for each of
# the 21 DexYCB joints.
SKELETON_TO_DEXYCB: tuple[int, ...] = (
    0,
    *(
        index
        for f, finger in enumerate(FINGER_NAMES)
        for index in (*range(MANO_FINGER_START[finger], MANO_FINGER_START[finger] + 3), 16 + f)
    ),
)

# Tip vertices of the 778-vertex official MANO mesh (thumb, index, middle, ring, little), the
# ones the DexYCB toolkit and most MANO layers use.
MANO_TIP_VERTEX_IDS: tuple[int, ...] = (745, 317, 444, 556, 673)
MANO_NUM_VERTICES = 778
