"""Synthetic captures in the DexYCB raw layout, with exact ground truth (see capture.py).

The public names load lazily, so processes that only render views (worker.synth.views) do not
import torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from worker.synth.capture import SynthSummary, generate_capture

__all__ = ["SynthSummary", "generate_capture"]


def __getattr__(name: str) -> object:
    if name in __all__:
        from worker.synth import capture

        return getattr(capture, name)
    raise AttributeError(f"module 'worker.synth' has no attribute {name!r}")
