"""PyTorch's intra-op threads for dexlabel's work: one per process unless set otherwise.

The hand model and the solver's Levenberg-Marquardt work on small tensors (a frame's 51
parameters, a few hundred depth matches), where a second thread saves nothing. Where processes
share cores (the in-process worker beside the web server, several queue workers on one host, a
test run beside benchmarks), OpenMP threads waiting for each other oversubscribe them: an
8-frame hand follow took 63 s with PyTorch's default of one thread per core beside a busy test
run, and 8.7 s with one thread. Work runs in parallel across worker processes instead.

DEXLABEL_TORCH_THREADS sets the count (a whole number, 1 or more). Where it is unset and
OMP_NUM_THREADS is set, PyTorch's own choice from that is kept.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from types import ModuleType

ENV = "DEXLABEL_TORCH_THREADS"
DEFAULT = 1


def thread_count() -> int | None:
    """The intra-op threads to use: DEXLABEL_TORCH_THREADS, else DEFAULT, else None where
    only OMP_NUM_THREADS is set (PyTorch reads that itself). A bad value is refused naming it."""
    raw = os.environ.get(ENV)
    if raw is None:
        return None if os.environ.get("OMP_NUM_THREADS") else DEFAULT
    try:
        count = int(raw.strip())
    except ValueError:
        count = 0
    if count < 1:
        raise ValueError(f"{ENV} must be a whole number of threads, 1 or more; got {raw!r}")
    return count


def apply(torch: ModuleType) -> None:
    """Set PyTorch's intra-op threads per thread_count(); called where dexlabel's PyTorch
    modules load (a later torch.set_num_threads, as bench/solve.py's --threads, still wins)."""
    count = thread_count()
    if count is not None and torch.get_num_threads() != count:
        torch.set_num_threads(count)
