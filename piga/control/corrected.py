"""A diagnosis put to use in control: the corrected physics as a planner's dynamics, the fitted camera as a state reader.

Both plug into :class:`agents.mpc.PigaMPCAgent` through its protocols
(:class:`agents.dynamics.Dynamics`, :class:`agents.mpc.StateReader`), so the planner knows
nothing of the diagnosis. :class:`Correction` bundles them for a control job
(:class:`piga.control.jobs.ControlJob`), which rebuilds them in its worker process.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import Tensor

from agents.dynamics import start_of
from agents.mpc import EncoderReader
from envs.pendulum import MAX_ACTION
from piga.diagnostics import fit
from piga.diagnostics.vision import Camera, angle_table, match
from piga.io.runs import nominal_of
from piga.world.effects import scaled_gravity
from piga.world.model import PhysicsModel


class CorrectedDynamics:
    """The nominal engine plus the effects a diagnosis fitted, as a :class:`agents.dynamics.Dynamics`.

    The effects are the typed terms of :mod:`piga.world.effects` that the diagnosis fitted (delay,
    deadzone, saturation, damping, friction, bias, speed clip, within_frame) with the fitted g, a and
    coefficients, rolled by :func:`piga.diagnostics.fit.simulate`. For a delay of k steps the first k steps of every
    rollout use the actions already sent, which this object remembers (:meth:`executed`).
    Angles are Gymnasium's (θ = 0 upright), as for every planner's dynamics.

    Args:
        corrected: the diagnosis' chosen model (``effects``, ``delay``, ``values``).
        nominal: the identified model's dt and substeps (its g and a are replaced by the fitted
            ones; its offset φ is not needed in Gymnasium's convention).
        gravity_mult: multiplies the fitted g (the agent is told gravity changed).
    """

    def __init__(self, corrected: fit.Model, nominal: fit.Nominal, gravity_mult: float = 1.0):
        values = {**corrected.values, "g": scaled_gravity(corrected.values["g"], gravity_mult)}
        self.corrected = corrected.with_values(values)
        # the planner's θ̇ is the reader's velocity at the frame (a velocity_hold model's reader already
        # reads it through the integrator), not a difference to read again
        hold = {"velocity_hold": False} if hasattr(nominal, "velocity_hold") else {}
        self.nominal = replace(nominal, offset=0.0, **hold)
        self._params = {k: v.detach() for k, v in fit.parameters_of(self.corrected, self.nominal).items()}
        self.history: list[float] = []
        """The last actions sent (at most ``fit.MAX_DELAY``), oldest first."""

    def reset(self) -> None:
        self.history = []

    def executed(self, action: np.ndarray) -> None:
        u = float(np.clip(np.asarray(action).reshape(-1)[0], -MAX_ACTION, MAX_ACTION))
        self.history = [*self.history, u][-fit.MAX_DELAY :]

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """States (B, H, 2) = (θ, θ̇) of the H steps after ``state`` (1, 2) under actions (B, H, 1)."""
        theta, theta_dot = start_of(state)
        b, h = actions.shape[:2]
        past = torch.zeros(fit.MAX_DELAY, dtype=torch.float64)
        if self.history:
            past[-len(self.history) :] = torch.tensor(self.history, dtype=torch.float64)
        acts = torch.cat([past.expand(b, -1), actions[..., 0].double()], 1)  # (B, MAX_DELAY + H)
        f64 = {"dtype": torch.float64}
        w = fit.Windows(torch.full((b,), float(theta), **f64), torch.full((b,), float(theta_dot), **f64), acts,
                        torch.zeros(b, h, **f64), torch.ones(b, h, **f64), torch.zeros(b, dtype=torch.long))
        return fit.simulate(self.corrected, self._params, self.nominal, w, with_velocity=True).float()  # (B, H, 2)


class CameraReader(EncoderReader):
    """A :class:`agents.mpc.StateReader` that reads each frame's angle by matching it to the decoder's
    renders seen through ``camera`` (analysis by synthesis), instead of with the encoder; the
    angles of the L frames are unwrapped before the velocity estimator."""

    def __init__(self, model: PhysicsModel, camera: Camera):
        super().__init__(model)
        self.table = angle_table(model, camera)

    def read_frames(self, x: Tensor) -> Tensor:
        theta, _ = match(self.table, x.flatten(1))  # (K,) in [-π, π)
        return theta.view(-1, 1, 1)  # (K, N=1, D=1)

    def prepare(self, coords: Tensor) -> Tensor:
        return torch.from_numpy(np.unwrap(coords[:, 0, 0].double().numpy())).float().view(-1, 1, 1)


@dataclass(frozen=True)
class Correction:
    """What a diagnosis changes in a piga agent: its physics and, if it found a camera, how it reads frames.

    Implements :class:`piga.control.jobs.AgentCorrection`.
    """

    physics: fit.Model
    """The chosen physics (:meth:`piga.diagnostics.diagnose.Diagnosis.corrected_model`)."""
    camera: Camera | None = None
    """The fitted camera (:meth:`~piga.diagnostics.diagnose.Diagnosis.corrected_camera`); None: the encoder."""

    def dynamics(self, model: PhysicsModel, gravity_mult: float) -> CorrectedDynamics:
        """The corrected physics for ``model``'s agent, told gravity changed by ``gravity_mult``."""
        return CorrectedDynamics(self.physics, nominal_of(model), gravity_mult)

    def reader(self, model: PhysicsModel) -> CameraReader | None:
        """The camera-based state reader, or None to keep the encoder."""
        return None if self.camera is None else CameraReader(model, self.camera)
