"""Label formats, each with one home: the DexYCB raw layout (``dexycb``: read by the importer,
written by the synthetic capture and the export), COCO keypoints (``coco``), BOP (``bop``),
CVAT for video XML (``cvat``; read back by ``cvat_read``) and dexlabel's own JSON
(``jsonfmt``).

The modules are pure: arrays and plain values in, file contents (bytes, documents) out; the
export (backend.exports) feeds them from the database and storage and writes the archive.
"""

from __future__ import annotations

FORMATS = ("dexycb", "coco", "bop", "cvat", "json")
# Formats whose labels come from a sequence's solve (3D poses): no solve, no export.
SOLVE_FORMATS = ("dexycb", "bop")
