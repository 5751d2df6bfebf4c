"""The pendulum's equation and its unmodelled effects, as typed terms, on numpy arrays or torch tensors.

One definition serves four users: the model's engine (:class:`piga.world.physics.Pendulum`, torch
float32 with gradients), the diagnosis' candidate physics (:func:`piga.diagnostics.fit.simulate`,
torch float64 under L-BFGS), the swing-up planner's engine (:mod:`agents.swingup`, numpy float64),
and the effect wrappers that make a "real" pendulum (:mod:`envs.effects`, Python floats). The
module imports neither torch nor Gymnasium, so ``envs`` may import it (and nothing else of piga):
a term is plain arithmetic plus the few elementwise functions below, which dispatch on their
argument (a torch tensor uses its own method, so gradients flow; a numpy array uses numpy; a Python
float uses :mod:`math`, as the wrappers always have).

The pendulum (a rod of mass m and length l, θ = 0 upright, Gymnasium's ``Pendulum-v1``)::

    θ̈ = (3 / 2l)·g·sin(θ + φ) + (3 / m l²)·τ,   τ = a·ũ + Σ passive torques(θ, θ̇)

Each effect is one typed record (:class:`Effect`): its name, its parameter's name and unit in the
engine's units (torques per m·l², so b is in 1/s and c, τ0 in rad/s² for m = l = 1), the grid a
fit starts from, the lower bound the physics stops at, and the stage it acts in, with what it does
there:

| stage | record | acts on | effects |
|---|---|---|---|
| ``command`` | :class:`CommandTerm` | the command u -> ũ | ``deadzone``, ``saturation``, ``gain`` |
| ``command`` | :class:`DiscreteTerm` | the command sequence | ``delay`` (ũ_t = u_{t-k}) |
| ``torque`` | :class:`TorqueTerm` | adds a passive torque τ(θ, θ̇) | ``damping``, ``friction``, ``bias``, ``cogging`` |
| ``velocity`` | :class:`VelocityTerm` | θ̇ after each step | ``speed_clip`` |
| ``integration`` | :class:`DiscreteTerm` | the integrator | ``within_frame`` (M substeps per frame) |

:data:`EFFECTS` lists them in the order they apply; :data:`CANDIDATES` are those the diagnosis
fits (a gain error is its refitted a; cogging is the effect kept outside the candidate set).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, NamedTuple

import numpy as np

__all__ = [
    "CANDIDATES",
    "COGGING_PERIODS",
    "EFFECTS",
    "FRICTION_SMOOTHING",
    "CommandTerm",
    "DiscreteTerm",
    "Effect",
    "Stage",
    "TorqueTerm",
    "VelocityTerm",
    "clip",
    "PendulumCoefficients",
    "acceleration_of",
    "pendulum_acceleration",
    "pendulum_coefficients",
    "pendulum_gains",
    "scaled_gravity",
    "sin",
]

Array = Any
"""A torch tensor, a numpy array or a Python float: whatever the caller computes in."""

Stage = Literal["command", "torque", "velocity", "integration"]

#: Speed scale (rad/s) of the smoothed Coulomb friction -c·tanh(θ̇ / FRICTION_SMOOTHING).
FRICTION_SMOOTHING = 0.1
#: Periods per turn of the cogging torque.
COGGING_PERIODS = 4


# ---------------------------------------------------------------------------------------------
# Elementwise functions on tensors, arrays and floats
# ---------------------------------------------------------------------------------------------


def _is_tensor(x: Array) -> bool:
    return type(x).__module__.startswith("torch")


def sin(x: Array) -> Array:
    """sin(x): ``Tensor.sin``, ``np.sin`` or ``math.sin``."""
    if _is_tensor(x):
        return x.sin()
    return np.sin(x) if isinstance(x, (np.ndarray, np.generic)) else math.sin(x)


def _tanh(x: Array) -> Array:
    if _is_tensor(x):
        return x.tanh()
    return np.tanh(x) if isinstance(x, (np.ndarray, np.generic)) else math.tanh(x)


def _sign(x: Array) -> Array:
    return x.sign() if _is_tensor(x) else np.sign(x)


def _relu(x: Array) -> Array:
    return x.relu() if _is_tensor(x) else np.maximum(x, 0.0)


def clip(x: Array, limit: Array) -> Array:
    """x clipped to [-limit, limit] (``limit`` may be a tensor that receives gradients)."""
    if _is_tensor(x):
        torch = sys.modules["torch"]
        if not _is_tensor(limit):
            limit = x.new_tensor(limit)
        return torch.minimum(torch.maximum(x, -limit), limit)
    return np.minimum(np.maximum(x, -limit), limit)


# ---------------------------------------------------------------------------------------------
# The pendulum's equation
# ---------------------------------------------------------------------------------------------


class PendulumCoefficients(NamedTuple):
    """The pendulum's equation with its gains multiplied in (:func:`pendulum_coefficients`)."""

    gravity: Array
    """k_g·g (rad/s²)."""
    drive: Array | None
    """k_τ·a, the acceleration per unit of command; None without actuation."""
    passive: tuple[tuple[TorqueTerm, Array], ...]
    """(term, k_τ·value) of each passive torque."""


def pendulum_gains(length: float = 1.0, mass: float = 1.0) -> tuple[float, float]:
    """(k_g, k_τ) = (3 / 2l, 3 / m l²): θ̈ = k_g·g·sin(θ + φ) + k_τ·τ for a rod of mass m and length l."""
    return 3.0 / (2.0 * length), 3.0 / (mass * length**2)


def pendulum_coefficients(g: Array, length: float = 1.0, mass: float = 1.0, *, gain: Array | None = None,
                          passive: Iterable[tuple[TorqueTerm, Array]] = ()) -> PendulumCoefficients:
    """The equation's coefficients, multiplied once: (k_g·g, k_τ·a or None, [(term, k_τ·value), ...]).

    A caller that steps the same equation many times (a fit's rollout) takes them once, and
    :func:`acceleration_of` then costs one product per term and step.
    """
    gravity_gain, torque_gain = pendulum_gains(length, mass)
    return PendulumCoefficients(gravity_gain * g, None if gain is None else torque_gain * gain,
                                tuple((term, torque_gain * value) for term, value in passive))


def acceleration_of(coefficients: PendulumCoefficients, theta: Array, v: Array, offset: Array = 0.0,
                    command: Array | None = None) -> Array:
    """θ̈ of the pendulum whose :func:`pendulum_coefficients` are given, under ``command`` ũ (None: no actuation)."""
    # an offset that is the float 0 adds nothing: skipped, it would be one more op per step of a rollout
    acc = coefficients.gravity * sin(theta if isinstance(offset, float) and offset == 0.0 else theta + offset)
    if command is not None:
        acc = acc + coefficients.drive * command
    for term, value in coefficients.passive:
        acc = acc + value * term.input(theta, v)
    return acc


def pendulum_acceleration(theta: Array, v: Array, g: Array, offset: Array = 0.0, length: float = 1.0, mass: float = 1.0,
                          *, actuation: tuple[Array, Array] | None = None,
                          passive: Iterable[tuple[TorqueTerm, Array]] = ()) -> Array:
    """θ̈ = (3 / 2l)·g·sin(θ + φ) + (3 / m l²)·(a·ũ + Σ τ_i(θ, θ̇)) of a rod pendulum (θ = 0 upright).

    ``actuation`` is the pair (a, ũ); ``passive`` the (term, value) pairs of the passive torques, each
    a value times its term's input (``-θ̇`` for damping). Every torque is added as
    ``(k_τ·coefficient)·input``, one at a time: the order in which piga's engine has always rounded
    (so a model trained before the terms were shared predicts to the last bit). Torques are in N·m
    for a rod of mass ``mass`` and length ``length``.
    """
    gain, command = actuation if actuation is not None else (None, None)
    return acceleration_of(pendulum_coefficients(g, length, mass, gain=gain, passive=passive), theta, v, offset, command)


def scaled_gravity(g: float, gravity_mult: float) -> float:
    """Gravity changed by a factor: g · ``gravity_mult`` (the environment's, or what an agent is told)."""
    if not (gravity_mult > 0 and math.isfinite(gravity_mult)):
        raise ValueError(f"gravity_mult must be finite and > 0, got {gravity_mult}")
    return g * gravity_mult


# ---------------------------------------------------------------------------------------------
# Effects as typed terms
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Effect:
    """An unmodelled effect of the pendulum: what a fit needs to know of it. Subclasses say what it does."""

    name: str
    """The effect's name (``NAME=VALUE`` on the command line, a candidate's name in a diagnosis)."""
    meaning: str
    """What the value means, in a few words."""
    parameter: str | None
    """Its continuous parameter's name in a fit ("b" for damping); None for a count (delay, substeps)."""
    unit: str
    """The unit of its value in piga's engine (torques per m·l²)."""
    grid: tuple[float, ...] = ()
    """Values a fit tries: starting points of L-BFGS, or every count searched."""
    lower_bound: float | None = None
    """Smallest value the physics uses (a fit may move the parameter below it; the physics stops there)."""
    vanishes_at: float | None = None
    """The parameter's value at which the effect is absent (0 for a torque or a deadzone), when there is one: a fit
    of the effect to data without it then lands near that value, instead of bending the other parameters."""
    candidate: bool = True
    """Among the diagnosis' candidates."""
    evidence: str = ""
    """What data would tell it from another effect that explains a recording as well (a format string over
    the fitted values, for a diagnosis' "ambiguous between")."""
    stage: ClassVar[Stage]


@dataclass(frozen=True, kw_only=True)
class CommandTerm(Effect):
    """An actuator effect, u -> ũ, applied to the command (clipped to the action range) before the gain a."""

    transform: Callable[[Array, Array], Array]
    """(u, value) -> ũ."""
    stage: ClassVar[Stage] = "command"


@dataclass(frozen=True, kw_only=True)
class TorqueTerm(Effect):
    """A passive torque τ(θ, θ̇) = value·input(θ, θ̇), computed from the state before each step and added to a·ũ."""

    input: Callable[[Array, Array], Array]
    """(θ, θ̇) -> the torque per unit of the parameter (``-θ̇`` for damping)."""
    vanishes_at: float | None = 0.0
    stage: ClassVar[Stage] = "torque"

    def torque(self, theta: Array, v: Array, value: Array) -> Array:
        """τ = value·input(θ, θ̇)."""
        return value * self.input(theta, v)


@dataclass(frozen=True, kw_only=True)
class VelocityTerm(Effect):
    """A limit on θ̇, applied to each new velocity of the integrator."""

    limit: Callable[[Array, Array], Array]
    """(θ̇, value) -> limited θ̇."""
    stage: ClassVar[Stage] = "velocity"


@dataclass(frozen=True, kw_only=True)
class DiscreteTerm(Effect):
    """An effect whose value is a count, searched over :attr:`grid`: a delay in steps, or substeps per frame."""

    acts_on: Literal["command", "integration"] = "command"
    """The command sequence (a delay) or the integrator (substeps per frame)."""
    parameter: str | None = None

    @property
    def stage(self) -> Stage:  # type: ignore[override]
        return self.acts_on


def _deadzone(u: Array, d: Array) -> Array:
    return _sign(u) * _relu(abs(u) - d)


DELAY = DiscreteTerm(name="delay", meaning="actuator dead time", unit="steps", grid=(1, 2, 3, 4),
                     evidence="actions that switch abruptly, with frames after each switch")
DEADZONE = CommandTerm(name="deadzone", meaning="actuator deadzone half-width", parameter="d", unit="action units",
                       grid=(0.05, 0.2, 0.4, 0.7, 1.0), vanishes_at=0.0, transform=_deadzone,
                       evidence="small actions, |u| below {d:.2f}")
SATURATION = CommandTerm(name="saturation", meaning="actuator limit", parameter="s", unit="action units",
                         grid=(0.5, 0.8, 1.1, 1.4, 1.8), lower_bound=1e-3, transform=clip,
                         evidence="large actions, |u| above {s:.2f}")
GAIN = CommandTerm(name="gain", meaning="actuator gain error factor", parameter="m", unit="factor", candidate=False,
                   transform=lambda u, m: m * u)
DAMPING = TorqueTerm(name="damping", meaning="viscous damping coefficient", parameter="b", unit="1/s",
                     grid=(0.0, 0.05, 0.1, 0.2, 0.4), input=lambda theta, v: -v,
                     evidence="free swings with no action at several speeds (a viscous torque grows with the speed)")
FRICTION = TorqueTerm(name="friction", meaning="smoothed Coulomb friction torque", parameter="c", unit="rad/s²",
                      grid=(0.0, 0.05, 0.1, 0.2, 0.4), input=lambda theta, v: -_tanh(v / FRICTION_SMOOTHING),
                      evidence="slow motion near rest, below 0.1 rad/s (Coulomb friction is as strong there as at "
                               "speed)")
BIAS = TorqueTerm(name="bias", meaning="constant torque bias", parameter="tau0", unit="rad/s²",
                  grid=(-0.3, -0.1, 0.0, 0.1, 0.3), input=lambda theta, v: 1.0,
                  evidence="the pendulum left at rest with no action (a bias moves its resting angle)")
COGGING = TorqueTerm(name="cogging", meaning="cogging (detent) torque amplitude", parameter="k", unit="rad/s²",
                     candidate=False, input=lambda theta, v: -sin(COGGING_PERIODS * theta))
SPEED_CLIP = VelocityTerm(name="speed_clip", meaning="speed limit", parameter="v", unit="rad/s",
                          grid=(2.0, 3.0, 4.0, 5.0, 6.0, 7.0), lower_bound=0.1, limit=clip,
                          evidence="speeds above {v:.2f} rad/s (a clip there holds them, any other effect lets them "
                                   "pass)")
WITHIN_FRAME = DiscreteTerm(name="within_frame", meaning="the system moves within the frame", unit="substeps per frame",
                            grid=(2, 3, 4, 8, 16), acts_on="integration",
                            evidence="a different action hold (another frame rate or action repeat: motion within "
                                     "the frame grows with the frame's length, an effect of the system does not)")

#: Every effect by name, in the order of the diagnosis' report; within a stage, the order they apply in.
EFFECTS: dict[str, Effect] = {e.name: e for e in (DAMPING, FRICTION, BIAS, DELAY, DEADZONE, SATURATION, SPEED_CLIP,
                                                  WITHIN_FRAME, GAIN, COGGING)}
#: The effects the diagnosis fits, in the order of its report.
CANDIDATES: tuple[str, ...] = tuple(name for name, e in EFFECTS.items() if e.candidate)
