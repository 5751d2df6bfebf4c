"""The profile of each learned parameter on the training frames (piga.evaluation.profile)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from piga.data.schema import read_sequences
from piga.evaluation.profile import PROFILE_FACTOR, parameter_profile
from piga.io.runs import load_model


def test_the_profile_scales_each_learned_parameter_and_puts_it_back(tiny_data: Path, tiny_run: Path) -> None:
    """Moved down by the factor, a parameter's profile sees its learned value as the "upper" point: the two ratios
    are each other's inverse. The model's parameters are as they were after each call."""
    model, _ = load_model(tiny_run)  # read, not written
    frames, actions = read_sequences(tiny_data, "train")
    before = {k: v.detach().clone() for k, v in model.state_dict().items()}
    profile = parameter_profile(model, frames, actions)
    assert set(profile) == {"g", "a"} and all(p.factor == pytest.approx(PROFILE_FACTOR) for p in profile.values())
    assert all(math.isfinite(p.lower) and math.isfinite(p.upper) and p.lower > 0 for p in profile.values())
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())
    with torch.no_grad():
        model.system.log_a -= math.log(PROFILE_FACTOR)
    moved = parameter_profile(model, frames, actions)["a"]
    assert moved.upper == pytest.approx(1 / profile["a"].lower, rel=1e-4)
    assert moved.value == pytest.approx(profile["a"].value / PROFILE_FACTOR, rel=1e-5)
    assert (moved.better is None) == (moved.upper >= 1 and moved.lower >= 1)
