"""Batched Levenberg-Marquardt for problems that are independent per frame (PyTorch).

residual_fn maps parameters (B, P) to residuals (B, M), row b depending only on parameters row
b. Jacobians come from forward-mode autodiff: one Jacobian-vector product per parameter, with
the same tangent direction in every frame, all P of them vectorised with torch.func.vmap, so a
Jacobian of all B frames costs about P forward passes of one batched evaluation. Each frame
keeps its own damping and accepts a step only if its own cost went down.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import torch
from torch.func import jvp, vmap

from worker import torch_threads

torch_threads.apply(torch)

ResidualFn = Callable[[torch.Tensor], torch.Tensor]

# PyTorch's forward-mode autodiff keeps its levels in process-wide state: two threads inside
# jvp at once (two solves in one worker process) pull the level from under each other ("no
# level exists"). Every forward-mode product of the solver holds this lock.
FORWARD_AD_LOCK = threading.RLock()


def cauchy_weights(errors: np.ndarray, scale: float) -> np.ndarray:
    """IRLS weights 1 / (1 + (e / scale)^2) of the Cauchy loss for errors (...) px (NaN: 1)."""
    return 1.0 / (1.0 + (np.nan_to_num(errors) / scale) ** 2)


def jacobian(residual_fn: ResidualFn, params: torch.Tensor) -> torch.Tensor:
    """(B, M, P) Jacobian of residual_fn at params (B, P), per frame."""
    size = params.shape[1]
    eye = torch.eye(size, dtype=params.dtype, device=params.device)
    tangents = eye[:, None, :].expand(size, params.shape[0], size)

    def directional(tangent: torch.Tensor) -> torch.Tensor:
        return jvp(residual_fn, (params,), (tangent,))[1]

    with FORWARD_AD_LOCK:
        return vmap(directional)(tangents).permute(1, 2, 0)


def levenberg_marquardt(residual_fn: ResidualFn, params: torch.Tensor, iterations: int,
                        damping: float = 1e-3, jacobian_fn: ResidualFn | None = None
                        ) -> tuple[torch.Tensor, torch.Tensor]:
    """Minimise sum(residual_fn(x)^2) per frame from params (B, P).

    jacobian_fn: x -> (B, M, P), when the caller has a cheaper Jacobian than forward-mode
    autodiff through residual_fn. Returns the parameters (B, P) and final per-frame costs (B,).
    """
    x = params.detach().clone()
    lam = torch.full((x.shape[0],), damping, dtype=x.dtype, device=x.device)
    with torch.no_grad():
        residuals = residual_fn(x)
    cost = (residuals * residuals).sum(1)
    for _ in range(iterations):
        jac = jacobian(residual_fn, x) if jacobian_fn is None else jacobian_fn(x)
        with torch.no_grad():
            hessian = jac.transpose(1, 2) @ jac
            grad = (jac.transpose(1, 2) @ residuals[..., None])[..., 0]
            diag = torch.diagonal(hessian, dim1=1, dim2=2)
            # Marquardt's scaling by diag(J^T J), floored so unobserved parameters stay put.
            damped = hessian + torch.diag_embed(lam[:, None] * (diag + 1e-9) + 1e-12)
            step = torch.linalg.solve(damped, -grad[..., None])[..., 0]
            trial = x + step
            trial_res = residual_fn(trial)
            trial_cost = (trial_res * trial_res).sum(1)
            better = trial_cost < cost
            x = torch.where(better[:, None], trial, x)
            residuals = torch.where(better[:, None], trial_res, residuals)
            cost = torch.where(better, trial_cost, cost)
            lam = torch.where(better, lam * 0.3, lam * 4.0).clamp(1e-9, 1e9)
    return x, cost
