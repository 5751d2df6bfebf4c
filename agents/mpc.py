"""Model-predictive control of the pendulum with CEM over a physics model.

One planner serves two agents:

- :class:`PigaMPCAgent` sees only frames. Its last L frames go through the trained encoder and
  velocity estimator to give (θ, θ̇). CEM then plans over the model's *learned* physics: its
  learned g (times a gravity multiplier, if the agent is told gravity changed), its learned a,
  and its offset φ.
- :class:`OracleAgent` is the same planner with the true state from ``info["state"]`` and the
  true parameters.

Both plan in Gymnasium's convention (θ = 0 upright). The piga agent converts its model angle
with θ = model θ + φ. The planning reward is Gymnasium's:
-(wrap(θ - θ_goal)² + 0.1·θ̇² + 0.001·u²), summed over the horizon.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import torch
from torch import Tensor

from agents.cem import CEMConfig, cem, shift_warm_start
from envs.pendulum import MAX_ACTION, PENDULUM_DT
from piga.diagnostics import fit as diag_fit
from piga.diagnostics.diagnose import nominal_of
from piga.diagnostics.vision import Camera, angle_table, match
from piga.model import PhysicsModel, frames_to_float
from piga.physics import Euler, Pendulum, System, rollout
from piga.velocity import wrap_angle


@dataclass(frozen=True)
class MPCConfig:
    """Planner settings. The CEM defaults are tuned for the pendulum (README, ``piga-control``)."""

    cem: CEMConfig = field(default_factory=lambda: CEMConfig(horizon=20, iterations=5, candidates=200, elites=20))
    """CEM settings."""
    goal_angle: float = 0.0
    """θ_goal in Gymnasium's convention (0 = upright)."""
    angle_weight: float = 1.0
    """Weight of wrap(θ - θ_goal)²."""
    velocity_weight: float = 0.1
    """Weight of θ̇²."""
    action_weight: float = 0.001
    """Weight of u²."""
    swing_up_angle: float = math.radians(60)
    """For a goal in the upper half (|θ_goal| < 90°): while the pendulum is farther than this from
    the goal, the planner scores against upright instead. Swinging up toward upright is
    symmetric and reliable; aiming straight at a tilted goal gets CEM stuck pushing one way at
    the torque limit (0 disables)."""
    warm_start: bool = True
    """Start each plan from the previous one, shifted by a step."""
    warm_fill: str = "repeat"
    """How the shifted warm start's new last step is filled: "middle" (0) or "repeat"."""
    warm_init_std: float | None = 0.3
    """CEM's initial std for warm-started plans near the goal, within ``swing_up_angle`` of it (None:
    always the cold start's ``cem.init_std``). Holding needs precise torques; swinging up needs
    exploration, or CEM gets stuck pushing at the torque limit."""
    execute: str = "mean"
    """Which plan acts: "best" (the highest-scoring sample) or "mean" (CEM's final mean, smoother)."""
    seed: int = 0
    """Seed of the planner's RNG."""

    def __post_init__(self) -> None:
        if self.execute not in ("mean", "best") or self.warm_fill not in ("middle", "repeat"):
            raise ValueError(f"execute must be 'mean' or 'best' and warm_fill 'middle' or 'repeat', got "
                             f"{self.execute!r}, {self.warm_fill!r}")


class PendulumPlanner:
    """CEM over a pendulum physics model; stateless except the warm start.

    Args:
        system: a :class:`piga.physics.Pendulum` (learned, or with the true values for the oracle).
        integrator: its integrator (Euler with the model's substeps).
        offset: φ, the system's angle offset: Gymnasium's θ = system θ + φ. The planner works in
            the system's own angle and scores in Gymnasium's.
        config: planner settings.
    """

    def __init__(self, system: System, integrator: Euler, config: MPCConfig = MPCConfig(), offset: float = 0.0):
        self.system, self.integrator, self.offset = system, integrator, float(offset)
        self.config = config
        self.low = torch.tensor([-MAX_ACTION])
        self.high = torch.tensor([MAX_ACTION])
        self.generator = torch.Generator().manual_seed(config.seed)
        self._mean: Tensor | None = None

    def reset(self) -> None:
        """Forgets the warm start and reseeds (a new episode)."""
        self._mean = None
        self.generator.manual_seed(self.config.seed)

    def near_goal(self, theta: float) -> bool:
        """Whether the system angle θ is within ``swing_up_angle`` of the goal (holding, not swinging up)."""
        limit = self.config.swing_up_angle or math.pi / 3
        return abs(math.remainder(theta + self.offset - self.config.goal_angle, 2 * math.pi)) <= limit

    def current_goal(self, theta: float) -> float:
        """The angle scored against from the system angle θ: the goal, or upright while swinging up."""
        goal = self.config.goal_angle
        if not self.config.swing_up_angle or abs(math.remainder(goal, 2 * math.pi)) >= math.pi / 2 or self.near_goal(theta):
            return goal
        return 0.0

    def objective(self, theta: float, theta_dot: float) -> Callable[[Tensor], Tensor]:
        """The closure CEM maximises: actions (B, H, 1) -> return (B,) from the system state (θ, θ̇)."""
        cfg = self.config
        goal = self.current_goal(theta)

        @torch.no_grad()
        def value(actions: Tensor) -> Tensor:
            p, v = self.rollout(theta, theta_dot, actions)  # (B, H) each
            err = wrap_angle(p + self.offset - goal)  # (B, H), Gymnasium's convention
            cost = cfg.angle_weight * err**2 + cfg.velocity_weight * v**2 + cfg.action_weight * actions[..., 0] ** 2
            return -cost.sum(1)

        return value

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        """Angles and velocities (B, H) of the system from (θ, θ̇) under actions (B, H, 1)."""
        b = actions.shape[0]
        p0 = torch.full((b, 1, 1), float(theta))
        v0 = torch.full((b, 1, 1), float(theta_dot))
        p, v = rollout(self.system, self.integrator, p0, v0, actions)  # (B, H, 1, 1) each
        return p[..., 0, 0], v[..., 0, 0]

    def executed(self, action: np.ndarray) -> None:
        """Told the action that was sent (a planner with an actuator delay keeps a history)."""

    def plan(self, theta: float, theta_dot: float) -> np.ndarray:
        """The first action (1,) of the best plan from the system state (θ, θ̇)."""
        return self.plan_sequence(theta, theta_dot)[0]

    def plan_sequence(self, theta: float, theta_dot: float) -> np.ndarray:
        """The whole best plan (H, 1) from the system state (θ, θ̇); advances the warm start."""
        cem_config = self.config.cem
        if self._mean is not None and self.config.warm_init_std is not None and self.near_goal(theta):
            cem_config = replace(cem_config, init_std=self.config.warm_init_std)
        result = cem(self.objective(theta, theta_dot), self.low, self.high, cem_config,
                     init_mean=self._mean, generator=self.generator)
        plan = result.mean if self.config.execute == "mean" else result.actions
        if self.config.warm_start:
            self._mean = shift_warm_start(result.mean, self.low, self.high, self.config.warm_fill)
        return plan.numpy().astype(np.float32)


class CorrectedPlanner(PendulumPlanner):
    """The planner over physics corrected by ``piga-diagnose``: the nominal engine plus fitted effects.

    The effects are those of :mod:`piga.diagnostics.fit` (delay, deadzone, saturation, damping,
    friction, bias, speed clip) with the fitted g, a and coefficients. For a delay of k steps the
    first k steps of every rollout use the actions already sent, which the planner remembers.

    Args:
        corrected: the diagnosis' chosen model (``effects``, ``delay``, ``values``).
        nominal: the identified model's φ, dt and substeps (its g and a are replaced by the fitted ones).
        config: planner settings.
        gravity_mult: multiplies the fitted g (as for the piga agent).
    """

    def __init__(self, corrected: diag_fit.Model, nominal: diag_fit.Nominal, config: MPCConfig = MPCConfig(),
                 gravity_mult: float = 1.0):
        values = {**corrected.values, "g": corrected.values["g"] * gravity_mult}
        self.corrected = diag_fit.Model(corrected.effects, corrected.delay, values)
        self.nominal = nominal
        self._params = {k: v.detach() for k, v in diag_fit.parameters_of(self.corrected, nominal).items()}
        self.history: list[float] = []
        super().__init__(Pendulum(g=values["g"], a=values["a"], dt=nominal.dt, learnable=False), Euler(nominal.substeps),
                         config, offset=nominal.offset)

    def reset(self) -> None:
        super().reset()
        self.history = []

    def executed(self, action: np.ndarray) -> None:
        self.history = (self.history + [float(np.clip(np.asarray(action).reshape(-1)[0], -MAX_ACTION, MAX_ACTION))])[
            -diag_fit.MAX_DELAY :]

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        F = diag_fit
        b, h = actions.shape[:2]
        past = torch.zeros(F.MAX_DELAY, dtype=torch.float64)
        if self.history:
            past[-len(self.history) :] = torch.tensor(self.history, dtype=torch.float64)
        acts = torch.cat([past.expand(b, -1), actions[..., 0].double()], 1)  # (B, MAX_DELAY + H)
        w = F.Windows(torch.full((b,), float(theta), dtype=torch.float64), torch.full((b,), float(theta_dot), dtype=torch.float64),
                      acts, torch.zeros(b, h, dtype=torch.float64), torch.ones(b, h, dtype=torch.float64),
                      torch.zeros(b, dtype=torch.long))
        out = F.simulate(self.corrected, self._params, self.nominal, w, with_velocity=True).float()  # (B, H, 2)
        return out[..., 0], out[..., 1]


class OracleAgent:
    """The planner with the true state (``info["state"]``) and the true parameters (g, a)."""

    def __init__(self, g: float, a: float, config: MPCConfig = MPCConfig(), dt: float = PENDULUM_DT):
        system = Pendulum(g=g, a=a, dt=dt, learnable=False)
        self.planner = PendulumPlanner(system, Euler(1), config)

    def reset(self) -> None:
        """Starts an episode."""
        self.planner.reset()

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
        """Action (1,) from the true state [θ, θ̇]; the frames are ignored."""
        return self.planner.plan(float(state[0]), float(state[1]))


class PigaMPCAgent:
    """Control from pixels: frames -> encoder + velocity -> (θ, θ̇) -> CEM over learned physics.

    Args:
        model: a trained :class:`PhysicsModel` of the pendulum.
        config: planner settings.
        gravity_mult: the agent is told gravity changed by this factor; it multiplies its
            learned g the same way (zero-shot, no retraining).
        corrected: a model chosen by ``piga-diagnose`` (:class:`piga.diagnostics.fit.Model`); the
            agent then plans with it (:class:`CorrectedPlanner`) instead of the learned physics.
        camera: a camera found by ``piga-diagnose`` (:class:`piga.diagnostics.vision.Camera`); the
            agent then reads each frame's angle by matching it to the decoder's renders through
            that camera, instead of with the encoder.
    """

    def __init__(self, model: PhysicsModel, config: MPCConfig = MPCConfig(), gravity_mult: float = 1.0,
                 keep_trace: bool = False, corrected: diag_fit.Model | None = None, camera: Camera | None = None):
        if model.config.system != "pendulum":
            raise ValueError(f"PigaMPCAgent controls a pendulum model, got system {model.config.system!r}")
        if not (gravity_mult > 0 and math.isfinite(gravity_mult)):
            raise ValueError(f"gravity_mult must be finite and > 0, got {gravity_mult}")
        self.model = model.eval()
        system = copy.deepcopy(model.system)  # the learned physics, told about the new gravity
        system.set_parameters(g=system.parameters_dict()["g"] * gravity_mult)
        self.offset = float(getattr(system, "offset", torch.tensor(0.0)).detach())
        if corrected is None:
            self.planner = PendulumPlanner(system, model.integrator, config, offset=self.offset)
        else:  # plan with the physics corrected by piga-diagnose
            self.planner = CorrectedPlanner(corrected, nominal_of(model), config, gravity_mult)
        self.table = angle_table(model, camera) if camera is not None else None
        self.keep_trace = keep_trace
        self.trace: list[tuple[float, float, np.ndarray]] = []
        """With ``keep_trace``: per step, the believed (θ, θ̇) in the model's convention and the plan (H, 1)."""

    @property
    def input_frames(self) -> int:
        """L, frames the agent needs per decision."""
        return self.model.config.input_frames

    def reset(self) -> None:
        """Starts an episode."""
        self.planner.reset()
        self.trace = []

    @torch.no_grad()
    def estimate_state(self, frames: np.ndarray) -> tuple[float, float]:
        """(θ, θ̇) in the model's convention (Gymnasium's θ = θ + ``offset``) from the last L frames, uint8 (L, H, W)."""
        x = frames_to_float(torch.from_numpy(np.ascontiguousarray(frames))[None], self.model.config.channels)
        if self.table is None:
            coords = self.model.encode(x)  # (1, L, 1, 1)
        else:
            theta, _ = match(self.table, x[0].flatten(1))  # (L,)
            coords = torch.from_numpy(np.unwrap(theta.double().numpy())).float().view(1, -1, 1, 1)
        p, v = self.model.initial_state(coords)
        return float(p[0, 0, 0]), float(v[0, 0, 0])

    def act(self, frames: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        """Action (1,) from the last L frames (uint8 (L, H, W)); ``state`` is never used."""
        theta, theta_dot = self.estimate_state(frames)
        plan = self.planner.plan_sequence(theta, theta_dot)
        self.planner.executed(plan[0])
        if self.keep_trace:
            self.trace.append((theta, theta_dot, plan))
        return plan[0]
