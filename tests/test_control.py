"""Control: the oracle swings the pendulum up; goal images; piga-control's bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent
from piga.episodes import EpisodeConfig, run_episodes
from piga.goal import load_scene_image, render_goal_image
from piga.model import ModelConfig, PhysicsModel
from tests.test_cli import assert_one_line_error, run


@pytest.mark.parametrize("substeps", [1, 5])
def test_planning_dynamics_roll_like_the_physics_module(substeps: int) -> None:
    """The planner's plain-array engine follows piga.physics.rollout (model convention + φ = Gymnasium's)."""
    from agents.dynamics import PendulumDynamics
    from piga.physics import Euler, Pendulum, rollout

    system = Pendulum(g=9.3, a=1.2, dt=0.05, offset=0.4, length=1.1, mass=0.9, learnable=False)
    actions = torch.rand(50, 20, 1, generator=torch.Generator().manual_seed(0)) * 4 - 2
    theta0 = torch.linspace(-3, 3, 50)[:, None, None]  # (B, 1, 1) model angles
    speed0 = torch.linspace(-4, 4, 50)[:, None, None]
    p, v = rollout(system, Euler(substeps), theta0, speed0, actions)  # (B, H, 1, 1)
    dynamics = PendulumDynamics.of(system, Euler(substeps), gravity_mult=1.0)
    for i in (0, 17, 49):
        angles, speeds = dynamics.rollout(float(theta0[i]) + 0.4, float(speed0[i]), actions[i : i + 1])
        torch.testing.assert_close(angles[0], p[i, :, 0, 0] + 0.4, atol=1e-4, rtol=0)
        torch.testing.assert_close(speeds[0], v[i, :, 0, 0], atol=1e-4, rtol=0)
    stronger = PendulumDynamics.of(system, Euler(substeps), gravity_mult=1.4)
    assert stronger.g == pytest.approx(1.4 * 9.3) and stronger.substeps == substeps


def test_oracle_swings_up_from_hanging() -> None:
    torch.set_num_threads(1)
    config = EpisodeConfig(episodes=1, steps=150)
    result = run_episodes(OracleAgent.for_env(config.env_config(), MPCConfig()), config)
    episode = result["episodes"][0]
    assert episode["start"] == [math.pi, 0.0]
    assert episode["success"], episode
    assert result["summary"]["time_to_goal_steps_median"] < 130


def test_oracle_told_of_stronger_gravity_swings_up() -> None:
    """The counterfactual the piga agent relies on: planning with the changed gravity works."""
    torch.set_num_threads(1)
    config = EpisodeConfig(episodes=1, steps=150, gravity_mult=1.4)
    oracle = OracleAgent.for_env(config.env_config(), MPCConfig())
    assert oracle.planner.dynamics.g == pytest.approx(14.0) and oracle.planner.dynamics.a == 1.0  # the env's truth
    told = run_episodes(oracle, config)["summary"]
    assert told["success_rate"] == 1.0


def test_success_definition() -> None:
    class Still:
        def reset(self) -> None: ...

        def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
            return np.zeros(1, np.float32)

    hanging = run_episodes(Still(), EpisodeConfig(episodes=1, steps=30, hold_steps=10))
    assert not hanging["episodes"][0]["success"]  # hanging at rest is not upright
    at_goal = run_episodes(Still(), EpisodeConfig(episodes=1, steps=30, hold_steps=10, goal_angle=math.pi))
    assert at_goal["episodes"][0]["success"] and at_goal["episodes"][0]["time_to_goal_steps"] == 0


def test_piga_agent_reads_state_in_models_convention() -> None:
    model = PhysicsModel(ModelConfig())
    with torch.no_grad():
        model.encoder.background.fill_(1.0)
    agent = PigaMPCAgent(model, MPCConfig(), gravity_mult=1.4)
    assert agent.planner.dynamics.g == pytest.approx(1.4 * model.physical_parameters()["g"])
    assert model.physical_parameters()["g"] == pytest.approx(1.0)  # the model itself is not changed
    frames = np.stack([render_goal_image(30.0) for _ in range(4)])
    small = np.stack([load_scene_image_array(f) for f in frames])
    theta, theta_dot = agent.estimate_state(small)
    assert theta == pytest.approx(math.radians(30), abs=math.radians(3)) and abs(theta_dot) < 0.5
    with pytest.raises(ValueError, match="gravity_mult"):
        PigaMPCAgent(model, MPCConfig(), gravity_mult=0.0)


def load_scene_image_array(picture: np.ndarray) -> np.ndarray:
    """A picture through a PNG file and load_scene_image, as a user's goal image would go."""
    import tempfile

    import imageio.v3 as iio

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "x.png"
        iio.imwrite(path, picture)
        return load_scene_image(path, 64)


def test_goal_image_conversion_matches_the_env(tmp_path: Path) -> None:
    from envs import make_pixel_pendulum

    env = make_pixel_pendulum(draw_torque_arrow=False)
    obs, _ = env.reset(seed=0, options={"state": [0.5, 0.0]})
    picture = env.render()
    converted = load_scene_image_array(picture)
    assert np.abs(converted.astype(int) - obs[-1]).max() <= 1  # same pipeline, up to PNG round trip
    # a JPEG at another size and aspect still converts to 64x64 gray
    import imageio.v3 as iio

    wide = np.concatenate([np.full((500, 100, 3), 255, np.uint8), picture, np.full((500, 100, 3), 255, np.uint8)], axis=1)
    iio.imwrite(tmp_path / "wide.jpg", wide)
    assert load_scene_image(tmp_path / "wide.jpg", 64).shape == (64, 64)
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(ValueError, match="not a readable image"):
        load_scene_image(tmp_path / "bad.png", 64)


def test_control_cli_bad_input(tmp_path: Path) -> None:
    assert_one_line_error(run("piga-control"), "--model")
    assert_one_line_error(run("piga-control", "--model", str(tmp_path / "nope")), "checkpoint")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "checkpoint.pt").write_bytes(b"junk")
    assert_one_line_error(run("piga-control", "--model", str(broken)), "checkpoint")
    for bad in ("0", "-1", "nan", "abc"):
        assert_one_line_error(run("piga-control", "--oracle", "--gravity-mult", bad), "--gravity-mult")
    assert_one_line_error(run("piga-control", "--oracle", "--angle", "20"), "--write-goal-image")
    assert_one_line_error(run("piga-control", "--oracle", "--goal-image", str(tmp_path / "x.png")), "--model")
    assert_one_line_error(run("piga-control", "--write-goal-image", str(tmp_path / "g.png")), "--angle")
    assert_one_line_error(run("piga-control", "--write-goal-image", str(tmp_path / "g.txt"), "--angle", "5"), ".png")
    assert_one_line_error(run("piga-control", "--oracle", "--video", str(tmp_path / "v.avi")), ".mp4")


def test_write_goal_image(tmp_path: Path) -> None:
    out = tmp_path / "goal.png"
    result = run("piga-control", "--write-goal-image", str(out), "--angle", "-15")
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert_one_line_error(run("piga-control", "--write-goal-image", str(out), "--angle", "5"), "--overwrite")


def test_oracle_holds_a_tilted_goal_from_hanging() -> None:
    """A goal near the torque limit (hold torque 1.71 of 2), reached from hanging down, in state space."""
    torch.set_num_threads(1)
    goal = math.radians(20)
    agent = OracleAgent(10.0, 1.0, MPCConfig(goal_angle=goal))
    agent.reset()
    theta, speed = math.pi, 0.0
    for _ in range(150):
        u = float(np.clip(agent.act(None, np.array([theta, speed]))[0], -2, 2))
        speed = float(np.clip(speed + 0.05 * (15 * math.sin(theta) + 3 * u), -8, 8))
        theta += 0.05 * speed
    error = math.degrees(abs(math.remainder(theta - goal, 2 * math.pi)))
    assert error < 3 and abs(speed) < 0.3, (error, speed)


def test_parse_range() -> None:
    from piga.episodes import parse_range

    assert parse_range("0.5:1.8:0.1") == [round(0.5 + 0.1 * i, 10) for i in range(14)]
    assert parse_range("1:1:0.5") == [1.0]
    for bad in ("1:2", "a:b:c", "2:1:0.1", "1:2:0", "0:1e9:1"):
        with pytest.raises(ValueError):
            parse_range(bad)


def test_summary_markdown_has_a_row_per_summary() -> None:
    from piga.episodes import summary_markdown

    s = {"agent": "oracle", "gravity_mult": 1.0, "goal_angle": 0.0, "episodes": 2, "success_rate": 0.5, "mean_return": -200.0,
         "final_angle_error_mean": 0.01, "time_to_goal_steps_median": None, "plan_ms_median": 9.0, "plan_ms_p95": 12.0}
    table = summary_markdown([s, {**s, "agent": "piga"}]).splitlines()
    assert len(table) == 4 and "| oracle | 1.00 | 0.00 | 2 | 50% | -200.0 | 0.57 | – | 9.00 | 12.00 |" == table[2]


def test_sweep_cli_bad_input(tmp_path: Path) -> None:
    assert_one_line_error(run("piga-control", "--oracle", "--sweep", "0.5:1.8:0.1"), "--model")
    assert_one_line_error(run("piga-control", "--model", str(tmp_path / "none"), "--sweep", "1:2"), "START:STOP:STEP")


def test_agents_import_nothing_from_diagnostics() -> None:
    """The planner knows no diagnosis: importing every agents module in a fresh interpreter loads no piga.diagnostics."""
    import subprocess
    import sys

    code = ("import pkgutil, importlib, sys, agents\n"
            "for m in pkgutil.iter_modules(agents.__path__): importlib.import_module('agents.' + m.name)\n"
            "print(sorted(m for m in sys.modules if m.startswith(('piga.diagnostics', 'piga.train', 'piga.episodes'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
