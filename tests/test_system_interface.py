"""The System interface holds an articulated system: a cart-pole, with its configuration-dependent mass matrix.

The cart-pole is defined here, in the test, with nothing but the interface (its generalised coordinates,
positive parameters in log space, units and acceleration); the integrators and ``rollout`` step it
unchanged. Without actuation its energy is conserved, and it follows a reference integration.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest
import torch
from torch import Tensor

from piga.world.physics import RK4, System, rollout


class CartPole(System):
    """A cart of mass M on a rail, with a pole of point mass m at length l; θ = 0 upright, x to the right.

    Generalised coordinates q = (x, θ), one object with D = 2; the action is the force on the cart.
    M(q)·q̈ = f(q, q̇, u) with

        M(q) = [[M + m, m·l·cos θ], [m·l·cos θ, m·l²]],   f = [u + m·l·sin θ·θ̇², m·g·l·sin θ].
    """

    units: ClassVar[dict[str, str]] = {"g": "m/s²", "cart": "kg", "pole": "kg", "length": "m"}

    def __init__(self, g: float = 9.81, cart: float = 1.0, pole: float = 0.3, length: float = 0.7, dt: float = 0.02):
        super().__init__(n_objects=1, coord_dim=2, action_dim=1, dt=dt)
        for name, value in {"g": g, "cart": cart, "pole": pole, "length": length}.items():
            self._add_positive_parameter(name, value, learnable=True)

    def _values(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        return self.log_g.exp(), self.log_cart.exp(), self.log_pole.exp(), self.log_length.exp()

    def mass_matrix(self, q: Tensor) -> Tensor:
        """M(q), (B, 2, 2)."""
        _, cart, pole, length = self._values()
        c = torch.cos(q[:, 0, 1])  # (B,)
        off = pole * length * c
        return torch.stack([torch.stack([(cart + pole).expand_as(c), off], -1),
                            torch.stack([off, (pole * length**2).expand_as(c)], -1)], -2)  # (B, 2, 2)

    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        g, _, pole, length = self._values()
        s = torch.sin(p[:, 0, 1])  # (B,)
        force = torch.zeros_like(s) if u is None else u[:, 0]
        rhs = torch.stack([force + pole * length * s * v[:, 0, 1] ** 2, pole * g * length * s], -1)  # (B, 2)
        return torch.linalg.solve(self.mass_matrix(p), rhs).unsqueeze(1)  # (B, 1, 2)

    def energy(self, p: Tensor, v: Tensor) -> Tensor:
        """Kinetic plus potential energy, (B,)."""
        g, _, pole, length = self._values()
        qd = v[:, 0]  # (B, 2)
        kinetic = 0.5 * torch.einsum("bi,bij,bj->b", qd, self.mass_matrix(p), qd)
        return kinetic + pole * g * length * torch.cos(p[:, 0, 1])


def _start(b: int = 5) -> tuple[Tensor, Tensor]:
    gen = torch.Generator().manual_seed(0)
    p = (torch.rand(b, 1, 2, generator=gen, dtype=torch.float64) - 0.5) * torch.tensor([1.0, 4.0], dtype=torch.float64)
    v = (torch.rand(b, 1, 2, generator=gen, dtype=torch.float64) - 0.5) * 4
    return p, v


def test_the_cart_pole_conserves_energy_without_actuation() -> None:
    system = CartPole(dt=0.01).double()
    p0, v0 = _start()
    p, v = rollout(system, RK4(substeps=2), p0, v0, steps=300)  # 3 s
    with torch.no_grad():
        e0 = system.energy(p0, v0)
        energies = torch.stack([system.energy(p[:, t], v[:, t]) for t in range(p.shape[1])], 1)  # (B, T)
    drift = (energies - e0[:, None]).abs().max() / e0.abs().max()
    assert drift < 1e-7, float(drift)
    assert (p[:, -1] - p0).abs().max() > 0.1  # it moved


def test_the_cart_pole_follows_a_reference_integration() -> None:
    scipy_integrate = pytest.importorskip("scipy.integrate")
    system = CartPole(dt=0.05).double()
    p0, v0 = _start(3)
    u = torch.tensor([[0.8], [-1.5], [0.0]], dtype=torch.float64)  # (B, 1), held
    steps = 20
    p, v = rollout(system, RK4(substeps=8), p0, v0, u[:, None, :].expand(-1, steps, -1))
    for i in range(3):
        def f(_t: float, y: np.ndarray, i: int = i) -> np.ndarray:
            q, qd = torch.from_numpy(y[:2]).view(1, 1, 2), torch.from_numpy(y[2:]).view(1, 1, 2)
            with torch.no_grad():
                acc = system.acceleration(q, qd, u[i : i + 1])
            return np.r_[y[2:], acc.view(2).numpy()]

        y0 = np.r_[p0[i, 0].numpy(), v0[i, 0].numpy()]
        times = system.dt * np.arange(1, steps + 1)
        ref = scipy_integrate.solve_ivp(f, (0.0, times[-1]), y0, t_eval=times, rtol=1e-11, atol=1e-12, method="DOP853")
        np.testing.assert_allclose(p[i, :, 0].detach().numpy(), ref.y[:2].T, atol=1e-6)
        np.testing.assert_allclose(v[i, :, 0].detach().numpy(), ref.y[2:].T, atol=1e-5)


def test_the_cart_pole_learns_through_the_interface() -> None:
    """Its parameters are learned in log space like every system's: gradients reach them through a rollout."""
    system = CartPole().double()
    p0, v0 = _start(2)
    p, _ = rollout(system, RK4(substeps=2), p0, v0, torch.ones(2, 10, 1, dtype=torch.float64))
    p.square().sum().backward()
    grads = {name: getattr(system, f"log_{name}").grad for name in system.units}
    assert all(g is not None and torch.isfinite(g) and g != 0 for g in grads.values()), grads
    assert set(system.parameters_dict()) == set(system.units)
