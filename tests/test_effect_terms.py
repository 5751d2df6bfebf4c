"""The effect terms of piga.world.effects: one definition on Python floats, numpy arrays and torch tensors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from piga.world.effects import (
    CANDIDATES,
    EFFECTS,
    CommandTerm,
    DiscreteTerm,
    TorqueTerm,
    VelocityTerm,
    pendulum_acceleration,
    scaled_gravity,
)

VALUES = {"deadzone": 0.4, "saturation": 1.1, "gain": 0.8, "damping": 0.2, "friction": 0.15, "bias": -0.3,
          "cogging": 0.25, "speed_clip": 3.0}


def _apply(name: str, theta: object, x: object, value: object) -> object:
    term = EFFECTS[name]
    if isinstance(term, CommandTerm):
        return term.transform(x, value)
    if isinstance(term, TorqueTerm):
        return term.torque(theta, x, value)
    assert isinstance(term, VelocityTerm)
    return term.limit(x, value)


@pytest.mark.parametrize("name", sorted(VALUES))
def test_a_term_is_the_same_on_floats_arrays_and_tensors(name: str) -> None:
    rng = np.random.default_rng(0)
    theta, x = rng.uniform(-3, 3, 50), rng.uniform(-5, 5, 50)
    value = VALUES[name]
    on_floats = np.array([_apply(name, float(t), float(u), value) for t, u in zip(theta, x)], np.float64)
    on_arrays = np.broadcast_to(_apply(name, theta, x, value), (50,))
    param = torch.tensor(value, dtype=torch.float64, requires_grad=True)
    on_tensors = _apply(name, torch.from_numpy(theta), torch.from_numpy(x), param)
    # the same arithmetic; sin and tanh come from each library's own implementation (a last-bit difference)
    np.testing.assert_allclose(on_arrays, on_floats, rtol=1e-15, atol=0)
    np.testing.assert_allclose(torch.broadcast_to(on_tensors, (50,)).detach().numpy(), on_floats, rtol=1e-15, atol=0)
    on_tensors.sum().backward()  # the fit's gradient reaches the effect's parameter
    assert param.grad is not None and torch.isfinite(param.grad)


def test_the_records_describe_every_candidate() -> None:
    for name in CANDIDATES:
        term = EFFECTS[name]
        assert term.unit and term.grid and term.evidence, name
        if isinstance(term, DiscreteTerm):
            assert term.parameter is None and all(float(k).is_integer() and k >= 1 for k in term.grid)
        else:
            assert term.parameter is not None
    assert {EFFECTS[n].stage for n in CANDIDATES} == {"command", "torque", "velocity", "integration"}
    assert EFFECTS["delay"].stage == "command" and EFFECTS["within_frame"].stage == "integration"


def test_the_pendulum_equation_and_a_gravity_change() -> None:
    """θ̈ = (3 / 2l)·g·sin(θ + φ) + (3 / m l²)·(a·ũ − b·θ̇), on floats and tensors alike."""
    from piga.world.effects import DAMPING

    expected = 3 / (2 * 1.3) * 9.0 * math.sin(0.7 + 0.1) + 3 / (0.8 * 1.3**2) * (2.0 * 0.5 - 0.2 * 0.4)
    kwargs = {"actuation": (2.0, 0.5), "passive": [(DAMPING, 0.2)]}
    assert pendulum_acceleration(0.7, 0.4, 9.0, 0.1, 1.3, 0.8, **kwargs) == pytest.approx(expected, rel=1e-15)
    on_tensor = pendulum_acceleration(torch.tensor(0.7, dtype=torch.float64), 0.4, 9.0, 0.1, 1.3, 0.8, **kwargs)
    assert float(on_tensor) == pytest.approx(expected, rel=1e-15)
    assert scaled_gravity(10.0, 1.4) == 10.0 * 1.4
    with pytest.raises(ValueError, match="gravity_mult"):
        scaled_gravity(10.0, 0.0)
