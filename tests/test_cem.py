"""CEM on known objectives: it finds the optimum, respects bounds, and a NaN never wins."""

from __future__ import annotations

import pytest
import torch

from agents.cem import CEMConfig, cem, shift_warm_start

LOW, HIGH = torch.tensor([-2.0]), torch.tensor([2.0])
SMALL = CEMConfig(horizon=5, iterations=8, candidates=300, elites=30)


def test_finds_the_maximum_of_a_quadratic() -> None:
    target = torch.tensor([0.5, -1.0, 1.5, 0.0, -0.3]).view(5, 1)
    result = cem(lambda x: -((x - target) ** 2).sum((1, 2)), LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(0))
    assert torch.allclose(result.actions, target, atol=0.1)
    assert result.value > -0.05


def test_optimum_outside_bounds_lands_on_the_bound() -> None:
    result = cem(lambda x: -((x - 5.0) ** 2).sum((1, 2)), LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(0))
    assert result.actions.max() <= 2.0 and torch.allclose(result.actions, torch.full((5, 1), 2.0), atol=0.05)


def test_nan_and_inf_never_win() -> None:
    def objective(x: torch.Tensor) -> torch.Tensor:
        value = -((x - 1.0) ** 2).sum((1, 2))
        blown = x[:, 0, 0] < 0  # half the population "blows up", with a huge or NaN score
        return torch.where(blown, torch.where(x[:, 1, 0] < 0, torch.tensor(float("nan")), torch.tensor(float("inf"))), value)

    result = cem(objective, LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(1))
    assert result.actions[0, 0] >= 0 and torch.isfinite(torch.tensor(result.value))


def test_all_non_finite_returns_minus_inf() -> None:
    result = cem(lambda x: torch.full((x.shape[0],), float("nan")), LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(0))
    assert result.value == float("-inf")


def test_no_state_between_calls_and_seeded() -> None:
    f = lambda x: -((x - 0.7) ** 2).sum((1, 2))  # noqa: E731
    a = cem(f, LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(3))
    cem(f, LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(9))  # an unrelated call in between
    b = cem(f, LOW, HIGH, SMALL, generator=torch.Generator().manual_seed(3))
    assert torch.equal(a.actions, b.actions)


def test_warm_start_is_explicit() -> None:
    mean = torch.arange(5.0).view(5, 1) / 5
    shifted = shift_warm_start(mean, LOW, HIGH)
    assert torch.equal(shifted[:4], mean[1:]) and shifted[4, 0] == 0.0
    with pytest.raises(ValueError, match="init_mean"):
        cem(lambda x: x.sum((1, 2)), LOW, HIGH, SMALL, init_mean=torch.zeros(3, 1))


def test_bad_config() -> None:
    with pytest.raises(ValueError, match="elites"):
        CEMConfig(candidates=10, elites=20)
    with pytest.raises(ValueError, match="bounds"):
        cem(lambda x: x.sum((1, 2)), HIGH, LOW, SMALL)
