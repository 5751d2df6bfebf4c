"""The "IN+IG" baseline: piga's encoder, velocity estimator and decoder around an Interaction Network.

The paper compares its explicit physics with an Interaction Network (Battaglia et al., 2016) over the
same inverse-graphics states. Here the physics engine of :class:`piga.world.model.PhysicsModel` is
replaced by a learned one, and everything else is piga's:

```
frames ─► Encoder ─► p_1..p_L ─► VelocityEstimator ─► (p_L, v_L)
                                                         │ per step, for every object i:
            e_ij = f_rel(s_i, s_j, p_i − p_j)   (every ordered pair j ≠ i)
            E_i  = Σ_j e_ij
            (Δp_i, Δv_i) = f_obj(s_i, E_i, u)
            v_i' = v_i + Δv_i,  p_i' = p_i + dt·v_i' + Δp_i
                                                         ▼
                                                     Decoder ─► predicted frames
```

with s_i the object's state (position and velocity, scaled to O(1); an angle as its sine and cosine).
The update's last layer starts at zero, so an untrained network moves every object at constant
velocity: a neutral start, not a physical answer. It has no physical parameters: nothing in it is g,
k or a, and control and diagnosis refuse its runs.

The velocity estimator is the backward difference (plus the paper's correction MLP when
``velocity_correction`` is on). The options that read the velocity through a physics engine
(``velocity_hold``, ``velocity_shoot``, ``velocity_physics``) have no engine here and are not used.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from piga.world.model import ModelConfig, ObjectModel
from piga.world.physics import SYSTEMS


def _mlp(inputs: int, hidden: int, outputs: int, layers: int = 2) -> nn.Sequential:
    """``layers`` hidden ReLU layers of ``hidden`` units, then a linear output."""
    dims = [inputs] + [hidden] * layers
    modules: list[nn.Module] = []
    for a, b in zip(dims[:-1], dims[1:]):
        modules += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*modules, nn.Linear(dims[-1], outputs))


class InteractionNetwork(nn.Module):
    """One step of a relational dynamics over N objects of D coordinates: (p, v, u) -> (p', v')."""

    def __init__(self, n_objects: int, coord_dim: int, action_dim: int, dt: float, image_size: int,
                 hidden: int = 128, effect_dim: int = 64):
        super().__init__()
        self.n, self.d, self.a, self.dt = n_objects, coord_dim, action_dim, dt
        # Scales to O(1), the velocity estimator's: an angle's speed of ~10 rad/s, a ball's of ~ the image per second.
        self.v_scale = 10.0 if coord_dim == 1 else float(image_size)
        self.image_size = image_size
        state = self._features_dim()
        self.relation = _mlp(2 * state + coord_dim, hidden, effect_dim) if n_objects > 1 else None
        self.effect_dim = effect_dim if n_objects > 1 else 0
        self.update = _mlp(state + self.effect_dim + action_dim, hidden, 2 * coord_dim)
        nn.init.zeros_(self.update[-1].weight)
        nn.init.zeros_(self.update[-1].bias)

    def _features_dim(self) -> int:
        return (2 if self.d == 1 else self.d) + self.d

    def _features(self, p: Tensor, v: Tensor) -> Tensor:
        """(B, N, D) positions and velocities -> (B, N, F) scaled state features."""
        if self.d == 1:  # an angle: its sine and cosine, so that a turn is the same state
            position = torch.cat([torch.sin(p), torch.cos(p)], dim=-1)
        else:  # pixels: the image spans [-1, 1]
            position = p / (self.image_size / 2) - 1
        return torch.cat([position, v / self.v_scale], dim=-1)

    def forward(self, p: Tensor, v: Tensor, u: Tensor | None) -> tuple[Tensor, Tensor]:
        """One frame: p, v (B, N, D), u (B, A) or None -> p', v' (B, N, D)."""
        b, n, _ = p.shape
        s = self._features(p, v)  # (B, N, F)
        parts = [s]
        if self.relation is not None:
            receiver = s[:, :, None].expand(b, n, n, s.shape[-1])  # (B, N, N, F): [i, j] -> s_i
            sender = s[:, None].expand(b, n, n, s.shape[-1])  # (B, N, N, F): [i, j] -> s_j
            offset = (p[:, :, None] - p[:, None]) / (self.image_size / 2)  # (B, N, N, D): p_i - p_j
            effects = self.relation(torch.cat([receiver, sender, offset], dim=-1))  # (B, N, N, E)
            others = 1.0 - torch.eye(n, dtype=p.dtype, device=p.device)  # no effect of an object on itself
            parts.append((effects * others[None, :, :, None]).sum(2))  # (B, N, E)
        if self.a:
            parts.append(u[:, None].expand(b, n, self.a))  # (B, N, A)
        out = self.update(torch.cat(parts, dim=-1))  # (B, N, 2D)
        dp, dv = out[..., : self.d], out[..., self.d :]
        v_next = v + self.v_scale * dv
        # position residual in pixels (or radians) per frame, scaled as the velocity's change over one frame
        p_next = p + self.dt * v_next + self.dt * self.v_scale * dp
        return p_next, v_next


class InteractionModel(ObjectModel):
    """piga's encoder, velocity estimator and decoder with an :class:`InteractionNetwork` as the dynamics."""

    def __init__(self, config: ModelConfig):
        # the system is read for its N and D only (a pendulum is one angle whatever n_objects says)
        system = SYSTEMS[config.system].for_model(config.system_options, config.dt, config.n_objects, config.image_size,
                                                   config.physics_init)
        n, d = system.n_objects, system.coord_dim
        super().__init__(config, n, d)
        self.dynamics = InteractionNetwork(n, d, config.action_dim, config.dt, config.image_size)
        self._add_decoder(n, d)

    def predict(self, coords: Tensor, actions: Tensor | None, steps: int,
                last_action: Tensor | None = None) -> Tensor:
        """Rolls the Interaction Network on from L encoded frames (see :meth:`ObjectModel.predict`)."""
        p, v = coords[:, -1], self.velocity(coords)  # (B, N, D) each
        positions = []
        for t in range(steps):
            p, v = self.dynamics(p, v, actions[:, t] if actions is not None else None)
            positions.append(p)
        return torch.stack(positions, dim=1)  # (B, steps, N, D)
