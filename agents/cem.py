"""The cross-entropy method: maximise a batched objective over action sequences within bounds.

The optimiser knows nothing about models. The objective comes in as a closure that scores a
population of action sequences (B, H, A) with a value (B,). This is mbrl-lib's design, without
two of its mistakes:

- A score that is NaN or infinite ranks *last*, never first: a blown-up rollout cannot win.
- No state survives between calls. A warm start is passed in explicitly as ``init_mean``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import Tensor

from agents.config import CEMConfig

__all__ = ["CEMConfig", "CEMResult", "cem", "shift_warm_start"]


class CEMResult(NamedTuple):
    """What one optimisation returns."""

    actions: Tensor
    """(H, A) the best sequence found (the highest score among all samples, over all iterations)."""
    value: float
    """Its objective value (-inf if every score was non-finite)."""
    mean: Tensor
    """(H, A) the final sampling mean: shift it by one step to warm-start the next call."""


def cem(
    objective: Callable[[Tensor], Tensor],
    low: Tensor,
    high: Tensor,
    config: CEMConfig = CEMConfig(),
    init_mean: Tensor | None = None,
    generator: torch.Generator | None = None,
) -> CEMResult:
    """Maximises ``objective`` over action sequences in [low, high].

    Args:
        objective: maps actions (B, H, A) to values (B,). Higher is better. NaN and ±inf rank last.
        low, high: (A,) action bounds.
        config: see :class:`CEMConfig`.
        init_mean: (H, A) warm start of the sampling mean (default: the middle of the bounds).
        generator: torch RNG for the samples (explicit, for reproducibility), on the bounds' device.

    Returns:
        A :class:`CEMResult`.
    """
    low, high = low.float(), high.float()
    if low.dim() != 1 or low.shape != high.shape or not bool((high > low).all()):
        raise ValueError(f"bounds must be 1-D with high > low, got low={low.tolist()}, high={high.tolist()}")
    h, a = config.horizon, low.shape[0]
    mid, half = (high + low) / 2, (high - low) / 2
    mean = mid.expand(h, a).clone() if init_mean is None else init_mean.float().clamp(low, high).clone()
    if mean.shape != (h, a):
        raise ValueError(f"init_mean must be (H={h}, A={a}), got {tuple(mean.shape)}")
    std = (config.init_std * half).expand(h, a).clone()
    best_actions, best_value = mean.clone(), float("-inf")
    k = config.elites
    for _ in range(config.iterations):
        noise = torch.randn((config.candidates, h, a), generator=generator, device=low.device)
        samples = torch.addcmul(mean, std, noise).clamp_(low, high)  # (B, H, A): mean + std * noise, in bounds
        values = objective(samples)
        if values.shape != (config.candidates,):
            raise ValueError(f"objective must return ({config.candidates},) values, got {tuple(values.shape)}")
        ninf = float("-inf")
        values = torch.nan_to_num(values, nan=ninf, posinf=ninf, neginf=ninf)  # non-finite ranks last
        top, order = torch.topk(values, k)  # (E,) the best k, best first
        first, last = top[0::k - 1].tolist() if k > 1 else (float(top[0]),) * 2  # the best and the k-th
        if first > best_value:
            best_value, best_actions = first, samples[order[0]].clone()
        if last == ninf:  # some of the best k blew up: only the finite ones refit
            order = order[torch.isfinite(top)]
            if len(order) == 0:  # everything blew up: keep the distribution
                continue
        new_std, new_mean = torch.std_mean(samples[order], dim=0, unbiased=False)  # (H, A) each, over the elites
        if config.momentum:
            new_mean = config.momentum * mean + (1 - config.momentum) * new_mean
            new_std = config.momentum * std + (1 - config.momentum) * new_std
        mean = new_mean
        std = new_std.clamp_min(config.min_std) if config.min_std else new_std
    return CEMResult(best_actions, best_value, mean)


def shift_warm_start(mean: Tensor, low: Tensor, high: Tensor, fill: str = "middle") -> Tensor:
    """The next call's ``init_mean``: drop the executed first step and append a last one.

    ``fill`` is "middle" (the middle of the bounds, PlaNet's choice) or "repeat" (the last step
    again: a plan that holds a state with a constant torque keeps holding it).
    """
    if fill == "repeat":
        return torch.cat([mean[1:], mean[-1:]], dim=0)
    if fill != "middle":
        raise ValueError(f"fill must be 'middle' or 'repeat', got {fill!r}")
    fill_row = ((high + low) / 2).expand(1, mean.shape[1])
    return torch.cat([mean[1:], fill_row], dim=0)
