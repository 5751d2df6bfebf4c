"""The scenes' velocity at frame L read through the engine (shooting), against the spring's ground truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from envs.scenes import draw_start, scene_config
from piga.world.model import ModelConfig, PhysicsModel

L, T = 4, 6


def _errors(substeps: int) -> dict[str, tuple[float, float]]:
    """Per velocity reading: error of v_L against the generator's, and of the next T positions predicted with
    the true k, l, both in pixels (per second) and averaged over objects and sequences."""
    scene = scene_config("spring")
    rng = np.random.default_rng(0)
    paths = [draw_start(scene, rng, L + T) for _ in range(8)]
    p = torch.tensor(np.stack([ps for ps, _ in paths]), dtype=torch.float64)  # (B, L+T, N, 2)
    v_true = torch.tensor(np.stack([vs[L - 1] for _, vs in paths]), dtype=torch.float64)  # (B, N, 2)
    base = ModelConfig(system="spring", dt=0.3, image_size=32, channels=3, n_objects=2, substeps=substeps,
                       velocity_correction=False, physics_init={"k": 4.0, "l": 6.0})
    errors = {}
    for name, flags in {"difference": {}, "cubic": {"velocity_physics": True}, "shoot": {"velocity_shoot": True}}.items():
        model = PhysicsModel(replace(base, **flags)).double()
        with torch.no_grad():
            _, v = model.initial_state(p[:, :L])
            pred = model.predict(p[:, :L], None, T)  # (B, T, N, 2)
        errors[name] = (float((v - v_true).norm(dim=-1).mean()), float((pred - p[:, L:]).norm(dim=-1).mean()))
    return errors


def test_shooting_recovers_the_generators_velocity_and_path() -> None:
    same = _errors(substeps=10)  # the generator's own integrator: shooting gives its velocity
    assert same["shoot"][0] < 0.01 < same["cubic"][0] / 5, same
    assert same["shoot"][1] < 0.01, same
    engine = _errors(substeps=5)  # the scenes' engine: its rollouts stay far closer than with the cubic term
    assert engine["shoot"][1] < engine["cubic"][1] / 5 and engine["cubic"][1] < engine["difference"][1] / 2, engine


def test_shooting_lets_no_gradient_into_the_physics() -> None:
    config = ModelConfig(system="spring", dt=0.3, image_size=32, channels=3, n_objects=2, velocity_shoot=True)
    model = PhysicsModel(config)
    coords = (torch.rand(3, 4, 2, 2) * 20 + 6).requires_grad_()
    _, v = model.initial_state(coords)
    v.sum().backward()
    assert coords.grad is not None and model.system.log_k.grad is None and model.system.log_l.grad is None
