"""Model-predictive control of the pendulum: the shared :class:`~agents.planner.Planner` with Gymnasium's cost.

:class:`PendulumPlanner` plans over whatever :class:`~agents.dynamics.Dynamics` it is given, in
Gymnasium's convention (θ = 0 upright), with Gymnasium's reward -(wrap(θ - θ_goal)² + 0.1·θ̇² +
0.001·u²) summed over the horizon (:class:`~agents.cost.PendulumCost`), or a cost it is given instead
(a learned reward head: :class:`agents.reward_head.LearnedCost`).

- :class:`OracleAgent` plans from the true state (``info["state"]``) with the true physics.
- :class:`PigaMPCAgent` sees only frames. A :class:`StateReader` turns its last L frames into
  (θ, θ̇) in the model's convention (by default :class:`EncoderReader`: the trained encoder and
  velocity estimator); the agent adds the model's angle offset φ (Gymnasium's θ = model θ + φ) and
  plans over the model's *learned* physics (its g times a gravity multiplier, if told gravity
  changed, and its a), or over any other dynamics it is given, such as the physics corrected by
  a diagnosis (:mod:`piga.control.corrected`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Protocol

import numpy as np
import torch
from torch import Tensor

from agents.config import MPCConfig
from agents.cost import Cost, PendulumCost
from agents.dynamics import Dynamics, PendulumDynamics, pendulum_state
from agents.planner import Planner
from envs.pendulum import MAX_ACTION, PENDULUM_DT, PixelPendulumConfig
from piga.world.model import PhysicsModel, frames_to_float

__all__ = ["EncoderReader", "MPCConfig", "OracleAgent", "PendulumPlanner", "PigaMPCAgent", "StateReader"]


class PendulumPlanner:
    """The pendulum's goals over a :class:`~agents.planner.Planner`: each plan scores against the goal,
    or against upright while swinging up toward a goal in the upper half, and a warm-started plan near
    the goal searches with a narrower initial spread. Angles are Gymnasium's (θ = 0 upright).

    Args:
        dynamics: what predicts the rollouts (learned, true or corrected physics, ...).
        config: planner settings.
        cost: what every plan scores instead of Gymnasium's cost (a learned objective,
            :class:`agents.reward_head.LearnedCost`); goal-free, so then the goal must be upright.
    """

    def __init__(self, dynamics: Dynamics, config: MPCConfig = MPCConfig(), cost: Cost | None = None):
        if cost is not None and config.goal_angle != 0.0:
            raise ValueError(f"a learned cost scores one task, upright; got goal_angle {config.goal_angle}")
        self.config = config
        self._cost = cost
        self.optimizer = Planner(dynamics, self.cost(config.goal_angle), [-MAX_ACTION], [MAX_ACTION], config.cem,
                                 warm_start=config.warm_fill if config.warm_start else "off",  # type: ignore[arg-type]
                                 execute=config.execute, seed=config.seed)  # type: ignore[arg-type]
        self._holding_cem = config.cem if config.warm_init_std is None else replace(config.cem, init_std=config.warm_init_std)
        """CEM settings of a warm-started plan near the goal."""

    @property
    def dynamics(self) -> Dynamics:
        """What the plans roll out."""
        return self.optimizer.dynamics

    def cost(self, goal: float) -> Cost:
        """Gymnasium's cost with the configured weights, scored against ``goal`` (or the given cost)."""
        if self._cost is not None:
            return self._cost
        cfg = self.config
        return PendulumCost(goal, cfg.angle_weight, cfg.velocity_weight, cfg.action_weight)

    def reset(self) -> None:
        """Forgets the warm start and the dynamics' history, and reseeds (a new episode)."""
        self.optimizer.reset()

    def near_goal(self, theta: float) -> bool:
        """Whether θ is within ``swing_up_angle`` of the goal (holding, not swinging up)."""
        limit = self.config.swing_up_angle or math.pi / 3
        return abs(math.remainder(theta - self.config.goal_angle, 2 * math.pi)) <= limit

    def current_goal(self, theta: float) -> float:
        """The angle scored against from θ: the goal, or upright while swinging up."""
        goal = self.config.goal_angle
        if not self.config.swing_up_angle or abs(math.remainder(goal, 2 * math.pi)) >= math.pi / 2 or self.near_goal(theta):
            return goal
        return 0.0

    def executed(self, action: np.ndarray) -> None:
        """Told the action that was sent (passed on to the dynamics, which may keep a history)."""
        self.optimizer.executed(action)

    def plan(self, theta: float, theta_dot: float) -> np.ndarray:
        """The first action (1,) of the plan from the state (θ, θ̇), told to the dynamics as executed."""
        action = self.plan_sequence(theta, theta_dot)[0]
        self.executed(action)
        return action

    def plan_sequence(self, theta: float, theta_dot: float) -> np.ndarray:
        """The whole plan (H, 1) from the state (θ, θ̇); advances the warm start."""
        holding = self.optimizer.warm and self.near_goal(theta)
        return self.optimizer.plan(pendulum_state(theta, theta_dot), self.cost(self.current_goal(theta)),
                                   self._holding_cem if holding else None)


class OracleAgent:
    """The planner with the true state (``info["state"]``) and the true physics (g, a).

    Use :meth:`for_env` to take them from the environment's configuration.
    """

    def __init__(self, g: float, a: float, config: MPCConfig = MPCConfig(), dt: float = PENDULUM_DT):
        self.planner = PendulumPlanner(PendulumDynamics(g, a, dt), config)

    @classmethod
    def for_env(cls, env: PixelPendulumConfig, config: MPCConfig = MPCConfig()) -> OracleAgent:
        """The oracle of an environment: its gravity (times its multiplier) and its actuation gain."""
        return cls(g=env.effective_gravity, a=env.actuation_gain, config=config)

    def reset(self) -> None:
        """Starts an episode."""
        self.planner.reset()

    def act(self, frames: np.ndarray | None, state: np.ndarray) -> np.ndarray:
        """Action (1,) from the true state [θ, θ̇]; the frames are ignored."""
        return self.planner.plan(float(state[0]), float(state[1]))


class StateReader(Protocol):
    """Reads the pendulum's state from the last L frames."""

    def __call__(self, frames: np.ndarray) -> tuple[float, float]:
        """(θ, θ̇) in the model's convention (Gymnasium's θ = θ + φ) from uint8 frames (L, H, W)."""
        ...

    def executed(self, action: np.ndarray) -> None:
        """Told the action (A,) applied over the frame the next call ends with (zeros at the start of an
        episode: nothing acted before the first frame)."""
        ...


class EncoderReader:
    """A :class:`StateReader`: each frame's coordinate from the model's encoder, then its velocity estimator.

    The encoder reads each frame alone (:meth:`PhysicsModel.encode` puts the (B, T) frames in one
    batch of independent frames), so the frames already read in the previous call are not read
    again: a frame stack moves on by one frame per step, and only the new frame is read. This is
    a quarter of the encoder's work per step at L = 4, with the same result (tests/test_control.py
    checks it against a fresh read). Subclasses
    change how a frame is read (:meth:`read_frames`) and how the L coordinates are prepared for
    the velocity estimator (:meth:`prepare`).
    """

    def __init__(self, model: PhysicsModel):
        self.model = model.eval()
        self._frames: np.ndarray | None = None  # uint8 (L, H, W) of the last call
        self._coords: Tensor | None = None  # (L, N, D) their coordinates
        self.last_action: np.ndarray | None = None
        """(A,) the action over the last frame; a model that reads velocities through its integrator
        (``velocity_hold``) needs it; :meth:`executed` sets it."""

    def executed(self, action: np.ndarray) -> None:
        """Keeps the action (A,) as :attr:`last_action`."""
        self.last_action = action

    def read_frames(self, x: Tensor) -> Tensor:
        """Float frames (K, C, H, W) in [0, 1] -> coordinates (K, N, D)."""
        return self.model.encode(x[None])[0]

    def prepare(self, coords: Tensor) -> Tensor:
        """The L frames' coordinates (L, N, D) as the velocity estimator takes them (here unchanged)."""
        return coords

    @torch.inference_mode()
    def __call__(self, frames: np.ndarray) -> tuple[float, float]:
        frames = np.ascontiguousarray(frames)
        old = self._frames
        if old is not None and old.shape == frames.shape and np.array_equal(old[1:], frames[:-1]):
            new, kept = frames[-1:], self._coords[1:]  # the stack moved on by one frame
        else:
            new, kept = frames, None
        x = frames_to_float(torch.from_numpy(new)[None], self.model.config.channels)[0]  # (K, C, H, W)
        coords = self.read_frames(x)  # (K, N, D)
        if kept is not None:
            coords = torch.cat([kept, coords])  # (L, N, D)
        self._frames, self._coords = frames.copy(), coords
        last = None
        if self.model.config.velocity_hold and self.last_action is not None:
            last = torch.as_tensor(self.last_action, dtype=torch.float32).view(1, -1)  # (1, A)
        p, v = self.model.initial_state(self.prepare(coords)[None], last)  # (1, N, D) each
        return float(p[0, 0, 0]), float(v[0, 0, 0])


class PigaMPCAgent:
    """Control from pixels: frames -> (θ, θ̇) -> CEM over the model's physics.

    Args:
        model: a trained :class:`PhysicsModel` of the pendulum.
        config: planner settings.
        gravity_mult: the agent is told gravity changed by this factor; it multiplies its
            learned g the same way (zero-shot, no retraining). Used for the default dynamics only.
        keep_trace: keep, per step, the believed state and the plan (for videos).
        dynamics: what to plan with instead of the model's learned physics (for example the physics
            corrected by ``piga-diagnose``); already told of any gravity change.
        reader: how to read the state from frames instead of the model's encoder (for example
            through the camera found by ``piga-diagnose``).
        cost: what to plan against instead of Gymnasium's cost (a learned objective:
            :class:`agents.reward_head.LearnedCost`).
    """

    def __init__(self, model: PhysicsModel, config: MPCConfig = MPCConfig(), gravity_mult: float = 1.0,
                 keep_trace: bool = False, dynamics: Dynamics | None = None, reader: StateReader | None = None,
                 cost: Cost | None = None):
        if model.config.system != "pendulum":
            raise ValueError(f"PigaMPCAgent controls a pendulum model, got system {model.config.system!r}")
        if not (gravity_mult > 0 and math.isfinite(gravity_mult)):
            raise ValueError(f"gravity_mult must be finite and > 0, got {gravity_mult}")
        self.model = model.eval()
        self.offset = model.physical_parameters().get("offset", 0.0)
        """φ: Gymnasium's θ = model θ + φ."""
        if dynamics is None:
            dynamics = PendulumDynamics.of(model.system, model.integrator, gravity_mult)  # type: ignore[arg-type]
        self.planner = PendulumPlanner(dynamics, config, cost)
        self.read_state: StateReader = reader if reader is not None else EncoderReader(model)
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
        self.read_state.executed(np.zeros(1, np.float32))  # nothing acted before the first frame

    def estimate_state(self, frames: np.ndarray) -> tuple[float, float]:
        """(θ, θ̇) in the model's convention (Gymnasium's θ = θ + ``offset``) from the last L frames, uint8 (L, H, W)."""
        return self.read_state(frames)

    def act(self, frames: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        """Action (1,) from the last L frames (uint8 (L, H, W)); ``state`` is never used."""
        theta, theta_dot = self.read_state(frames)
        plan = self.planner.plan_sequence(theta + self.offset, theta_dot)
        self.planner.executed(plan[0])
        self.read_state.executed(plan[0])
        if self.keep_trace:
            self.trace.append((theta, theta_dot, plan))
        return plan[0]
