"""Integration within the frame (piga/world/physics): RK4 and the velocity read through the
integrator, against a fine-step reference of the continuous pendulum with a held action."""

from __future__ import annotations

import math

import pytest
import torch

from piga.world.physics import RK4, Euler, Pendulum, PendulumOptions, hold_velocity, make_integrator, rollout

DT = 0.04


def _pendulum(damping: float | None = 0.13) -> Pendulum:
    system = Pendulum(g=13.03, a=1.328, dt=DT, learnable=False, damping=damping)
    return system.double()


def _start(batch: int = 6) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(0)
    p0 = (torch.rand(batch, 1, 1, generator=gen, dtype=torch.float64) * 2 - 1) * math.pi
    v0 = (torch.rand(batch, 1, 1, generator=gen, dtype=torch.float64) * 2 - 1) * 6
    actions = torch.rand(batch, 25, 1, generator=gen, dtype=torch.float64) * 2 - 1
    return p0, v0, actions


@pytest.mark.slow
def test_rk4_follows_a_fine_step_reference():
    system = _pendulum()
    p0, v0, actions = _start()
    reference, reference_v = rollout(system, Euler(substeps=2000), p0, v0, actions)  # the continuous system
    rk4, rk4_v = rollout(system, RK4(substeps=2), p0, v0, actions)
    euler, _ = rollout(system, Euler(substeps=1), p0, v0, actions)
    rk4_error = (rk4 - reference).abs().max().item()
    euler_error = (euler - reference).abs().max().item()
    assert rk4_error < 1e-3, rk4_error  # the reference itself is off by O(h) = ~4e-4
    assert (rk4_v - reference_v).abs().max().item() < 3e-3
    assert euler_error > 30 * rk4_error, (euler_error, rk4_error)


def test_rk4_converges_at_fourth_order():
    system = _pendulum()
    p0, v0, actions = _start()
    fine, _ = rollout(system, RK4(substeps=64), p0, v0, actions)
    errors = [(rollout(system, RK4(substeps=m), p0, v0, actions)[0] - fine).abs().max().item() for m in (1, 2)]
    assert 10 < errors[0] / errors[1] < 25, errors  # 2^4 = 16


@pytest.mark.parametrize("integrator", [Euler(substeps=2), Euler(substeps=10), RK4(substeps=2)])
def test_hold_velocity_recovers_the_velocity_at_the_frame(integrator):
    """From two frames and the action between them: the true velocity, where the chord is off by ~dt·F/2."""
    system = _pendulum()
    p0, v0, actions = _start()
    p, v = rollout(system, integrator, p0, v0, actions)  # (B, T, 1, 1)
    chord = (p[:, 1:] - p[:, :-1]) / DT  # (B, T-1, 1, 1)
    b, t = chord.shape[:2]
    read = hold_velocity(system, integrator, p[:, :-1].reshape(b * t, 1, 1), chord.reshape(b * t, 1, 1),
                         actions[:, 1:].reshape(b * t, 1))
    truth = v[:, 1:].reshape(b * t, 1, 1)
    assert (read - truth).abs().max().item() < 1e-5
    assert (chord.reshape(b * t, 1, 1) - truth).abs().max().item() > 0.05  # the chord alone lags


def test_hold_velocity_is_the_difference_for_one_euler_substep():
    system = _pendulum(damping=None)
    p0, v0, actions = _start()
    p, v = rollout(system, Euler(substeps=1), p0, v0, actions[:, :1])
    read = hold_velocity(system, Euler(substeps=1), p0, (p[:, 0] - p0) / DT, actions[:, 0])
    assert torch.allclose(read, v[:, 0], atol=1e-9)


def test_gradcheck_rk4_and_damping():
    system = _pendulum()
    p0, v0, actions = _start(batch=2)
    actions = actions[:, :3].clone().requires_grad_(True)
    p0 = p0.clone().requires_grad_(True)

    def f(p0_: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return rollout(system, RK4(substeps=2), p0_, v0, u)[0]

    assert torch.autograd.gradcheck(f, (p0, actions))
    system.log_b.requires_grad_(True)
    p, _ = rollout(system, RK4(substeps=2), p0.detach(), v0, actions.detach())
    (grad,) = torch.autograd.grad(p.sum(), system.log_b)
    assert grad.item() != 0


def test_make_integrator_names():
    assert isinstance(make_integrator("rk4", 3), RK4) and make_integrator("euler", 1).substeps == 1
    with pytest.raises(ValueError, match="unknown integrator"):
        make_integrator("verlet", 1)
    with pytest.raises(ValueError, match="substeps"):
        RK4(substeps=0)


def test_continuous_preset_model_reads_velocity_through_its_integrator():
    from dataclasses import replace

    from piga.world.model import PhysicsModel
    from piga.training.train import PRESETS

    config = replace(PRESETS["continuous"].model, dt=DT)
    model = PhysicsModel(config)
    assert isinstance(model.integrator, RK4) and set(model.physical_parameters()) >= {"g", "a", "b"}
    assert model.physical_parameters()["b"] == pytest.approx(config.system_options.damping_init)
    coords = torch.tensor([0.1, 0.12, 0.15, 0.19]).view(1, 4, 1, 1)
    with pytest.raises(ValueError, match="action over the last input frame"):
        model.initial_state(coords)
    _, v_push = model.initial_state(coords, torch.ones(1, 1))
    _, v_none = model.initial_state(coords, torch.zeros(1, 1))
    assert v_push.item() > v_none.item() > 0.04 / DT  # a held push adds speed within the frame
    frames = torch.randint(0, 255, (2, 14, 64, 64), dtype=torch.uint8)
    out = model(frames, torch.rand(2, 14, 1) * 2 - 1)
    out.loss.backward()
    assert model.system.log_b.grad is not None


def _fit_a(signed: bool, steps: int = 150) -> float:
    """Fits g, a, b by gradient descent on 5-frame rollouts of a pendulum whose actuation is flipped (a < 0)."""
    truth = Pendulum(g=13.0, a=-1.3, dt=DT, learnable=False, damping=0.13, signed_actuation=True)
    gen = torch.Generator().manual_seed(1)
    p0 = (torch.rand(64, 1, 1, generator=gen) * 2 - 1) * math.pi
    v0 = (torch.rand(64, 1, 1, generator=gen) * 2 - 1) * 4
    actions = torch.rand(64, 5, 1, generator=gen) * 2 - 1
    with torch.no_grad():
        target, _ = rollout(truth, RK4(substeps=2), p0, v0, actions)
    model = Pendulum(g=1.0, a=0.3, dt=DT, damping=0.01, signed_actuation=signed)
    opt = torch.optim.Adam(model.parameters(), lr=0.1)
    for _ in range(steps):
        opt.zero_grad()
        pred, _ = rollout(model, RK4(substeps=2), p0, v0, actions)
        loss = (pred - target).square().mean()
        loss.backward()
        opt.step()
    return model.parameters_dict()["a"]


@pytest.mark.slow
def test_signed_actuation_learns_a_flipped_motor():
    assert _fit_a(signed=True) == pytest.approx(-1.3, rel=0.05)
    assert _fit_a(signed=False, steps=50) > 0  # in log space it cannot cross 0


def test_signed_actuation_parameters():
    system = Pendulum(a=0.3, signed_actuation=True, learnable=("g", "a"))
    assert "a" in system.parameters_dict() and not hasattr(system, "log_a")
    system.set_parameters(a=-2.0, g=5.0)
    assert system.parameters_dict() == pytest.approx({"g": 5.0, "a": -2.0})
    with pytest.raises(ValueError, match="nonzero"):
        system.set_parameters(a=0.0)


@pytest.mark.parametrize("fields", [{"integrator": "rk4", "substeps": 2}, {"system_options": PendulumOptions(learn_damping=True)}])
def test_continuous_models_are_refused_by_the_planner_and_carried_by_the_diagnosis(fields):
    """The pendulum planner's engine is Euler without damping: a --preset continuous model gets a clear
    refusal there, not a silently wrong plan. The diagnosis carries the model's integrator and damping
    (its candidates are effects on top of them)."""
    from agents.dynamics import PendulumDynamics
    from piga.diagnostics import nominal_of
    from piga.world.model import ModelConfig, PhysicsModel

    model = PhysicsModel(ModelConfig(**fields))
    with pytest.raises(ValueError, match="preset continuous"):
        PendulumDynamics.of(model.system, model.integrator)
    nominal = nominal_of(model)
    assert nominal.integrator == fields.get("integrator", "euler") and nominal.substeps == fields.get("substeps", 1)
    assert (nominal.b > 0) == ("system_options" in fields)
    plain = PhysicsModel(ModelConfig())
    assert PendulumDynamics.of(plain.system, plain.integrator).substeps == 1


def test_parameter_errors_compare_a_with_the_signed_truth_of_a_flipped_file() -> None:
    from piga.evaluation.evaluate import parameter_errors
    from piga.world.model import ModelConfig, PhysicsModel

    model = PhysicsModel(ModelConfig(image_size=32, system_options=PendulumOptions(signed_actuation=True)))
    model.system.set_parameters(a=-1.3)
    flipped = {"g": 13.0, "actuation_gain": 1.328, "actuation_sign": -1.0}
    assert parameter_errors(model, flipped)["a"]["true"] == pytest.approx(-1.328)
    assert parameter_errors(model, flipped)["a"]["relative_error"] == pytest.approx(0.028 / 1.328, rel=1e-5)
    assert parameter_errors(model, {**flipped, "actuation_sign": 1.0})["a"]["relative_error"] > 1.9


def test_a_gain_effect_is_part_of_the_true_a() -> None:
    """A model that learned a = 0.21 from frames collected with --effect gain=0.2 was scored 79% off a true a of 1."""
    from piga.evaluation.evaluate import applied_params, parameter_errors
    from piga.world.model import ModelConfig, PhysicsModel

    params = {"g": 10.0, "actuation_gain": 1.0}
    assert applied_params(params, {"gain": 0.2, "damping": 0.1})["actuation_gain"] == pytest.approx(0.2)
    assert applied_params(params, {"blur": 2.0}) == params and applied_params(params, "not json") == params
    model = PhysicsModel(ModelConfig(image_size=32))
    model.system.set_parameters(a=0.21)
    error = parameter_errors(model, applied_params(params, {"gain": 0.2}))["a"]
    assert error["true"] == pytest.approx(0.2) and error["relative_error"] == pytest.approx(0.05, rel=1e-4)
