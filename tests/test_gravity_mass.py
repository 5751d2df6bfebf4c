"""Gravity's m run: g held at the user's value, the shared mass m learned (the paper's Table 1, last column)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from envs.scenes import draw_start, scene_config
from piga.cli.train import main as train_main
from piga.data.collect_scenes import SceneCollectConfig, collect_scene
from piga.data.schema import inspect_dataset
from piga.evaluation.evaluate import parameter_errors
from piga.world.model import ModelConfig, PhysicsModel
from piga.world.physics import Euler, Gravity, GravityOptions, rollout
from piga.training.train import model_config_for, preset_for
from tests.helpers import assert_one_line, run_in_process


def test_mass_scales_the_force_like_g() -> None:
    p = torch.tensor([[[10.0, 10.0], [20.0, 12.0], [14.0, 22.0]]])
    reference = Gravity(g=60.0, learnable=False).acceleration(p, torch.zeros_like(p))
    heavy = Gravity(g=30.0, mass=2.0, learnable=False).acceleration(p, torch.zeros_like(p))
    torch.testing.assert_close(heavy, reference)  # a_i = sum_j g·m_j·d/|d|^3: only g·m matters
    with pytest.raises(ValueError, match="only as g·m"):
        Gravity(mass=1.0, learnable=True)
    assert Gravity().parameters_dict() == {"g": 1.0}  # the g run: unit masses, a constant


def test_m_learned_from_true_trajectories_with_g_fixed() -> None:
    """Through the engine alone: m starts at 1/60 (g·m = 1, the g run's start) and reaches the truth m = 1."""
    scene = scene_config("gravity")
    rng = np.random.default_rng(0)
    paths = [draw_start(scene, rng, 7) for _ in range(8)]
    ps = torch.tensor(np.stack([p for p, _ in paths]), dtype=torch.float64)  # (B, T, N, 2)
    vs = torch.tensor(np.stack([v for _, v in paths]), dtype=torch.float64)
    system = Gravity(g=60.0, mass=1 / 60, learnable=("m",), dt=scene.dt).double()
    assert not system.log_g.requires_grad and system.log_m.requires_grad
    optimizer = torch.optim.LBFGS(system.parameters(), max_iter=40, line_search_fn="strong_wolfe")

    def loss() -> torch.Tensor:
        optimizer.zero_grad()
        pred, _ = rollout(system, Euler(10), ps[:, 0], vs[:, 0], steps=6)
        value = (pred - ps[:, 1:]).square().mean()
        value.backward()
        return value

    optimizer.step(loss)
    assert system.parameters_dict()["g"] == pytest.approx(60.0)
    assert system.parameters_dict()["m"] == pytest.approx(1.0, rel=0.01)


def test_fixed_g_model_starts_far_and_only_m_gets_gradients() -> None:
    config = ModelConfig(system="gravity", dt=0.5, image_size=36, channels=3, n_objects=3, input_frames=4,
                         pred_frames=2, template_size=18, system_options=GravityOptions(fixed_g=60.0))
    model = PhysicsModel(config)
    assert model.physical_parameters() == pytest.approx({"g": 60.0, "m": 1 / 60})
    assert model.learned_parameter_names() == ["m"]
    frames = torch.randint(0, 255, (2, 6, 36, 36, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    model(frames, torch.zeros(2, 6, 0)).loss.backward()
    assert model.system.log_m.grad is not None and model.system.log_m.grad.abs() > 0
    assert model.system.log_g.grad is None
    errors = parameter_errors(model, {"g": 60.0, "m": 1.0})
    assert list(errors) == ["m"] and errors["m"]["relative_error"] == pytest.approx(59 / 60)  # g was given, not learned
    with pytest.raises(ValueError, match="for gravity"):
        ModelConfig.from_dict({"system": "spring", "fixed_g": 60.0})


@pytest.fixture(scope="module")
def gravity_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("gravity") / "gravity.h5"
    config = SceneCollectConfig(scene=scene_config("gravity"), sequences=4, steps=18, seed=0, workers=1, split=(2, 1, 1))
    return collect_scene(config, path, progress=False, command="test")


def test_fixed_g_reaches_the_model_and_is_refused_elsewhere(gravity_data: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    info = inspect_dataset(gravity_data)
    config = model_config_for(info, preset_for("fast", info).model).with_options(fixed_g=60.0)
    assert config.extrapolate_frames == 24 and config.pred_frames == 12  # the paper's (4, 12, 24) for gravity
    spring = tmp_path / "spring.h5"
    collect_scene(SceneCollectConfig(scene=scene_config("spring"), sequences=2, steps=12, seed=0, workers=1,
                                     split=(1, 1, 0)), spring, progress=False, command="test")
    code, _, err = run_in_process("piga-train-model", train_main, str(spring), "--out", str(tmp_path / "run"),
                                  "--fixed-g", "60", capsys=capsys)
    assert_one_line(code, err, "--fixed-g", "gravity")
    assert not (tmp_path / "run").exists()
    code, _, err = run_in_process("piga-train-model", train_main, str(spring), "--out", str(tmp_path / "run"),
                                  "--signed-actuation", capsys=capsys)  # the pendulum's option, likewise
    assert_one_line(code, err, "--signed-actuation", "pendulum")
    assert not (tmp_path / "run").exists()
