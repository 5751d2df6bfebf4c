"""Is each learned physical parameter at the value that predicts the training frames best?

A run whose learning rate decays before a parameter reaches its value stands still there, and the convergence
check's drift test takes it for settled: on 50 pendulum sequences of 10 frames, 400 steps left a at 0.48
(52% off), moving by 0.9% over the last tenth of the steps. The frames themselves say so: the training split's
prediction error falls when a grows. This module measures that profile, with labels nowhere: each learned
positive parameter (the system's ``log_*``) scaled by 1/``factor`` and by ``factor`` in turn, the others as
learned, and the predicted frames of the first windows of the training split compared with the frames.

It is a coarse test on purpose. Near its value the prediction error of a well-identified parameter is not a
clean parabola (a dm_control run with g 5% off predicted its training frames 16% better with g 10% lower, and
4.5x worse with g 40% lower); a factor of e^0.5 = 1.65 steps over such bumps and finds only a parameter that is
far from where the frames want it (``results/convergence_calibration.md``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from piga.evaluation.evaluate import rollout_frames
from piga.world.model import PhysicsModel, frames_to_float

#: The factor each parameter is scaled by, down and up: e^0.5.
PROFILE_FACTOR = math.exp(0.5)
#: Sequences of the training split the profile predicts (their first windows).
PROFILE_SEQUENCES = 64


@dataclass(frozen=True)
class ParameterProfile:
    """The training frames' prediction MSE with one parameter scaled down and up, relative to that at its value."""

    value: float
    lower: float
    """MSE with the parameter divided by the factor, over the MSE at the learned value."""
    upper: float
    """... multiplied by the factor."""
    factor: float

    @property
    def better(self) -> float | None:
        """The scaled value that predicts better, if one does (the one that predicts best)."""
        if min(self.lower, self.upper) >= 1:
            return None
        return self.value / self.factor if self.lower < self.upper else self.value * self.factor


@torch.no_grad()
def parameter_profile(model: PhysicsModel, frames: np.ndarray, actions: np.ndarray,
                      factor: float = PROFILE_FACTOR) -> dict[str, ParameterProfile]:
    """The profile of each learned positive parameter of ``model``'s system (see the module docstring) on
    ``frames`` uint8 (B, T, H, W(, C)) and ``actions`` (B, T, A), predicting ``pred_frames`` after the first L."""
    cfg = model.config
    steps = min(cfg.pred_frames, frames.shape[1] - cfg.input_frames)
    truth = frames_to_float(torch.from_numpy(frames[:, cfg.input_frames : cfg.input_frames + steps]), cfg.channels).numpy()

    def mse() -> float:
        pred, _ = rollout_frames(model, frames, actions, steps)  # (B, S, C, H, W)
        return float(((pred - truth) ** 2).mean(dtype=np.float64))

    was_training = model.training
    model.eval()
    try:
        return _profile(model, mse, factor)
    finally:
        model.train(was_training)


def _profile(model: PhysicsModel, mse: Callable[[], float], factor: float) -> dict[str, ParameterProfile]:
    """The profiles, with ``mse()`` the prediction error of the model as it stands (in eval mode)."""
    at_value = mse()
    if not (math.isfinite(at_value) and at_value > 0):  # nothing to compare with (a perfect or a broken prediction)
        return {}
    out: dict[str, ParameterProfile] = {}
    for name, p in model.system.named_parameters():
        if not (name.startswith("log_") and p.requires_grad and p.numel() == 1):
            continue
        base = p.detach().clone()
        ratios = []
        try:
            for shift in (-math.log(factor), math.log(factor)):
                p.copy_(base + shift)
                ratio = mse() / at_value
                ratios.append(ratio if math.isfinite(ratio) else math.inf)  # a prediction that blew up: worse
        finally:  # the model leaves as it came, whatever stopped the loop
            p.copy_(base)
        out[name.removeprefix("log_")] = ParameterProfile(float(base.exp()), ratios[0], ratios[1], factor)
    return out


def profile_dict(profile: dict[str, ParameterProfile]) -> dict[str, dict[str, Any]]:
    """What metrics.json keeps under ``profile``."""
    return {name: asdict(p) for name, p in profile.items()}
