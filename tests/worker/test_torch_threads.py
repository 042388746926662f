"""worker.torch_threads: one PyTorch intra-op thread per process unless set otherwise, applied
where dexlabel's PyTorch modules load (checked in fresh interpreters)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from worker import torch_threads

PROBE = ("import torch; torch.set_num_threads(3); import worker.solver.lm; "
         "print(torch.get_num_threads())")


def _threads_after_import(**env: str) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items()
             if k not in ("DEXLABEL_TORCH_THREADS", "OMP_NUM_THREADS")}
    return subprocess.run([sys.executable, "-c", PROBE], env={**clean, **env},
                          capture_output=True, text=True, timeout=120)


def test_loading_the_solver_sets_one_thread_or_the_setting() -> None:
    assert _threads_after_import().stdout.strip() == "1"
    assert _threads_after_import(DEXLABEL_TORCH_THREADS="2").stdout.strip() == "2"
    # OMP_NUM_THREADS alone: PyTorch's own choice (here the probe's 3) is left as it is.
    assert _threads_after_import(OMP_NUM_THREADS="2").stdout.strip() == "3"


def test_a_bad_setting_is_refused_naming_it() -> None:
    done = _threads_after_import(DEXLABEL_TORCH_THREADS="many")
    assert done.returncode != 0
    assert "DEXLABEL_TORCH_THREADS must be a whole number of threads, 1 or more; got 'many'" \
        in done.stderr


@pytest.mark.parametrize("raw", ["0", "-2", "1.5", ""])
def test_thread_count_refuses_what_is_not_a_positive_whole_number(
        raw: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_TORCH_THREADS", raw)
    with pytest.raises(ValueError, match="DEXLABEL_TORCH_THREADS"):
        torch_threads.thread_count()
