"""Two solves in one worker process at once: the solver's forward-mode Jacobians must not pull
each other's autodiff level away, and each thread gets the result it gets alone."""

from __future__ import annotations

import threading

import torch

from worker.solver.lm import levenberg_marquardt


def _problem(seed: int):
    gen = torch.Generator().manual_seed(seed)
    a = torch.randn(32, 24, 8, generator=gen, dtype=torch.float64)
    b = torch.randn(32, 24, generator=gen, dtype=torch.float64)
    return lambda x: torch.sin(torch.einsum("bmp,bp->bm", a, x)) - 0.5 * b


def test_concurrent_solves_each_get_their_own_result() -> None:
    alone = {seed: levenberg_marquardt(_problem(seed), torch.zeros(32, 8, dtype=torch.float64),
                                       15)[1] for seed in range(4)}
    results: dict[int, torch.Tensor] = {}
    errors: list[BaseException] = []

    def run(seed: int) -> None:
        try:
            for _ in range(3):
                results[seed] = levenberg_marquardt(
                    _problem(seed), torch.zeros(32, 8, dtype=torch.float64), 15)[1]
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(seed,)) for seed in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    for seed, cost in alone.items():
        assert torch.allclose(results[seed], cost)
