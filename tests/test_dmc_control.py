"""Control of dm_control's pendulum: the planner's engines against MuJoCo and piga's own, the oracle's
swing-up with a torque limit of 1, and piga-control's DMC options."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from agents.dynamics import pendulum_state
from agents.swingup import DampedPendulumDynamics, SwingUpPlanner
from envs.dmc import DMCPendulumConfig
from piga.world.physics import RK4, Pendulum, rollout
from tests.helpers import assert_one_line_error, completed_in_process, run
from tests.test_dmc import needs_dmc


@needs_dmc
def test_oracle_engine_is_mujocos():
    from envs.dmc import make_dmc_pendulum

    config = DMCPendulumConfig(damping=0.3, mass=1.2)
    p = config.piga_params()
    env = make_dmc_pendulum(config)
    _, info = env.reset(seed=0, options={"state": [2.0, -1.0]})
    actions = np.random.default_rng(0).uniform(-1, 1, 25).astype(np.float32)
    states = []
    for u in actions:
        _, _, _, _, info = env.step(np.array([u]))
        states.append(info["state"])
    engine = DampedPendulumDynamics(p["g"], p["actuation_gain"], p["damping"], config.dt, config.action_repeat)
    rolled = engine.rollout(pendulum_state(2.0, -1.0), torch.from_numpy(actions).view(1, -1, 1))  # (1, H, 2)
    np.testing.assert_allclose(rolled[0].numpy(), np.array(states)[:, :2], atol=1e-4)


def test_rk4_engine_is_the_models():
    system = Pendulum(g=13.0, a=1.3, dt=0.04, learnable=False, damping=0.13).double()
    actions = torch.rand(1, 20, 1, dtype=torch.float64) * 2 - 1
    p, v = rollout(system, RK4(substeps=2), torch.full((1, 1, 1), 2.5, dtype=torch.float64),
                   torch.full((1, 1, 1), 0.5, dtype=torch.float64), actions)
    rolled = DampedPendulumDynamics(13.0, 1.3, 0.13, 0.04, 2, "rk4").rollout(pendulum_state(2.5, 0.5), actions.float())
    np.testing.assert_allclose(rolled[0, :, 0].numpy(), p[0, :, 0, 0].numpy(), atol=1e-5)
    np.testing.assert_allclose(rolled[0, :, 1].numpy(), v[0, :, 0, 0].numpy(), atol=1e-4)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_energy_cost_pumps_from_hanging_down(sign):
    """From rest at the bottom, where pushing straight up cannot lift the pole, the planner swings it up
    on the true physics within 9 s (four swings) and holds it within 8 degrees; also with the actuation
    reversed (a < 0: a flipped camera or motor, as a signed-actuation model learns it)."""
    p = DMCPendulumConfig().piga_params()
    engine = DampedPendulumDynamics(p["g"], sign * p["actuation_gain"], p["damping"], 0.04, 2)
    planner = SwingUpPlanner(engine)
    theta, speed, upright = math.pi, 0.0, []
    for _ in range(220):
        u = planner.plan(theta, speed)
        assert abs(float(u[0])) <= 1.0
        theta, speed = engine.rollout(pendulum_state(theta, speed), torch.from_numpy(u).view(1, 1, 1))[0, 0].tolist()
        upright.append(math.cos(theta) >= math.cos(math.radians(8)))
    assert not any(upright[:10])  # it had to swing
    assert all(upright[-25:]), "not held upright at the end"


@needs_dmc
def test_piga_control_dmc_oracle_scores_and_refuses_gymnasium_options(tmp_path, capsys):
    out = tmp_path / "oracle"
    result = run("piga-control", "--env", "piga/DMCPendulum-v0", "--oracle", "--episodes", "1", "--seed", "2", "--quiet",
                 "--out", str(out))
    assert result.returncode == 0, result.stderr
    import json

    payload = json.loads((tmp_path / "oracle.json").read_text())
    (oracle,) = payload["results"]
    # the episode from reset seed 2 that tests/test_episodes.py records (842 of 1000, in DMC's units)
    assert oracle == {"agent": "oracle", "scores": [842.0], "mean": 842.0, "std": 0.0}, oracle
    assert payload["config"]["planner"]["seed"] == 2  # --seed seeds the planner too, as on the pixel env
    assert "| oracle |" in (tmp_path / "oracle.md").read_text()
    from piga.cli.control import main

    for argv, needle in ((("--env", "piga/DMCPendulum-v0", "--horizon", "5"), "--horizon"),
                         (("--oracle", "--env-option", "mass=2"), "--env-option")):
        assert_one_line_error(completed_in_process("piga-control", main, *argv, capsys=capsys), needle)


def test_a_piga_model_is_run_only_through_the_view_it_was_identified_on(tmp_path, capsys):
    """A piga model given RGB frames failed inside its velocity estimator, and one given dm_control's camera 0 after
    identification face-on scored through a camera it never saw: both refused before an episode."""
    import h5py

    from envs.dmc import DMCPendulumConfig
    from piga.cli.common import PigaError
    from piga.cli.control import _check_piga_view

    data = tmp_path / "fixed.h5"
    with h5py.File(data, "w") as f:
        f.attrs["env_config"] = json.dumps({"camera": "fixed"})
    fixed, face = {"data": {"path": str(data)}}, {"data": {"path": str(tmp_path / "gone.h5")}}
    _check_piga_view("run", fixed, DMCPendulumConfig(camera="fixed"))
    _check_piga_view("run", face, DMCPendulumConfig())
    with pytest.raises(PigaError, match="read gray frames; drop --env-option color=rgb"):
        _check_piga_view("run", face, DMCPendulumConfig(color="rgb"))
    with pytest.raises(PigaError, match="identified through the 'face' camera, not 'fixed'; drop --env-option camera"):
        _check_piga_view("run", face, DMCPendulumConfig(camera="fixed"))
    with pytest.raises(PigaError, match="through the 'fixed' camera, not 'face'; give --env-option camera=fixed"):
        _check_piga_view("run", fixed, DMCPendulumConfig())
    # the camera's distance too: the pendulum another size in the frames (it ran, and scored through a view it never saw)
    far = tmp_path / "far.h5"
    with h5py.File(far, "w") as f:
        f.attrs["env_config"] = json.dumps({"camera": "face", "camera_distance": 1.5})
    _check_piga_view("run", {"data": {"path": str(far)}}, DMCPendulumConfig(camera_distance=1.5))
    with pytest.raises(PigaError, match="camera_distance=1, not 2; drop --env-option camera_distance"):
        _check_piga_view("run", face, DMCPendulumConfig(camera_distance=2.0))
    with pytest.raises(PigaError, match="camera_distance=1.5, not 1; give --env-option camera_distance=1.5"):
        _check_piga_view("run", {"data": {"path": str(far)}}, DMCPendulumConfig())
    # shadows, which the training file did not have, run with one line (the model scored 0 with them, 922 without,
    # without a word)
    capsys.readouterr()
    _check_piga_view("run", face, DMCPendulumConfig(shadows=True))
    assert capsys.readouterr().err == ("piga-control: warning: the env renders with shadows, the model's training file "
                                       "had none: its encoder reads frames lit otherwise than those it was trained on, "
                                       "so the score below measures that too\n")
    _check_piga_view("run", face, DMCPendulumConfig())
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("env", [(), ("--env", "piga/DMCPendulum-v0"), ("--sweep", "0.9:1.1:0.1")])
def test_a_missing_model_folder_is_said_alike_on_both_envs(tmp_path, capsys, env):
    """With the DMC env, a missing --model read "nosuchdir/checkpoint.pt: no checkpoint (is nosuchdir a
    piga-train-model run folder?)", where the pixel env says that the folder does not exist."""
    from piga.cli.control import main

    missing = str(tmp_path / "nosuchdir")
    assert_one_line_error(completed_in_process("piga-control", main, *env, "--model", missing, "--episodes", "1",
                                               "--quiet", capsys=capsys),
                          f"--model {missing} does not exist (give the folder that piga-train-model or piga-baseline "
                          "wrote its checkpoint.pt in)")


def test_the_physics_an_env_changes_from_the_training_file_are_named():
    from piga.cli.control import physics_difference

    trained = DMCPendulumConfig().to_dict()
    assert physics_difference(trained, DMCPendulumConfig()) is None
    assert physics_difference(trained, DMCPendulumConfig(shadows=True, max_speed=1.0)) is None  # no physics
    assert physics_difference(trained, DMCPendulumConfig(flip="motor")) == ("flip=motor", "flip=none")
    assert (physics_difference({"mass": 2.0, "flip": "camera"}, DMCPendulumConfig(length=0.3)) ==
            ("mass=1, length=0.3, flip=none", "mass=2, length=0.5, flip=camera"))  # absent: the default


@pytest.mark.parametrize("data, said", [
    ({"env_config": DMCPendulumConfig(damping=0.2).to_dict()},
     "the env differs from the model's training file in damping=0.1, flip=motor (trained on damping=0.2, flip=none): the "
     "planner's physics will not match"),
    # the training file gone, and an older checkpoint that does not keep its config: against DMC's defaults, saying so
    ({"path": "gone.h5", "env_id": "piga/DMCPendulum-v0"},
     "the env differs from DMC's default pendulum in flip=motor (default flip=none), and the model's training file, "
     "which would say what it was trained on, is not found: the planner's physics may not match"),
    ({"path": "gone.h5", "env_id": None}, None),  # an imported recording's model: nothing is known
])
def test_the_warning_of_other_physics_says_what_it_compares_with(data, said, tmp_path, monkeypatch, capsys):
    from piga.cli.control import _warn_if_other_physics

    monkeypatch.chdir(tmp_path)
    _warn_if_other_physics({"data": data}, DMCPendulumConfig(flip="motor", damping=0.1))
    err = capsys.readouterr().err
    assert err == ("" if said is None else f"piga-control: warning: {said}\n")


@needs_dmc
@pytest.mark.parametrize("options, said", [(("flip=motor",), "flip=motor (trained on flip=none)"),
                                           (("length=0.3", "mass=2"), "mass=2, length=0.3 (trained on mass=1, "
                                                                      "length=0.5)"),
                                           ((), None)])
def test_an_env_of_other_physics_runs_with_a_warning(options, said, tmp_path, monkeypatch, capsys):
    """flip=motor ran silently (a score of 0 where the model's own env scores 922), while the camera's options are
    refused: it is a fair sim-to-real test, so it runs, and one line says what the model assumes."""
    from types import SimpleNamespace

    import piga.control.dmc as dmc
    import piga.io.checkpoint
    import piga.io.runs
    from piga.cli import control
    from piga.io.checkpoint import RunKind
    from tests.helpers import run_in_process

    model = SimpleNamespace(config=SimpleNamespace(system="pendulum", image_size=16, dt=0.04, input_frames=2))
    monkeypatch.setattr(piga.io.checkpoint, "checked_run_kind", lambda run: RunKind.PIGA)
    monkeypatch.setattr(piga.io.runs, "load_model", lambda run: (model, {}))
    monkeypatch.setattr(piga.io.runs, "training_env_config", lambda checkpoint: DMCPendulumConfig().to_dict())
    monkeypatch.setattr(control, "_check_dmc_rate", lambda *args: None)
    monkeypatch.setattr(control, "warn_if_unconverged", lambda *args: None)
    monkeypatch.setattr(dmc, "PigaSwingUp", lambda model, planner: None)
    monkeypatch.setattr(dmc, "run_dmc_episodes", lambda *args, **kwargs: (_ for _ in ()).throw(KeyboardInterrupt))
    argv = [arg for option in options for arg in ("--env-option", option)]
    code, _, err = run_in_process("piga-control", control.main, "--env", "piga/DMCPendulum-v0", "--model",
                                  str(tmp_path), "--episodes", "1", "--quiet", *argv, capsys=capsys)
    assert code == 130  # (stopped at the episodes: the warning before them is what is checked)
    warnings = [line for line in err.splitlines() if "warning" in line]
    if said is None:
        assert warnings == [], err
    else:
        assert warnings == [f"piga-control: warning: the env differs from the model's training file in {said}: the "
                            "planner's physics will not match"], err


@needs_dmc
def test_a_piga_model_is_run_on_frames_of_its_own_size(tmp_path, monkeypatch, capsys):
    """A DMC model identified on 32 px frames was given 64 px ones ("encode takes frames of (C, H, W) = (1, 32, 32), the
    model's, got (1, 64, 64)"), with no option to change them: the env renders at the model's size."""
    from types import SimpleNamespace

    import piga.control.dmc as dmc
    import piga.io.checkpoint
    import piga.io.runs
    from piga.cli import control
    from piga.io.checkpoint import RunKind
    from tests.helpers import run_in_process

    sizes = []
    model = SimpleNamespace(config=SimpleNamespace(system="pendulum", image_size=32, dt=0.04, input_frames=2))
    monkeypatch.setattr(piga.io.checkpoint, "checked_run_kind", lambda run: RunKind.PIGA)
    monkeypatch.setattr(piga.io.runs, "load_model", lambda run: (model, {}))
    monkeypatch.setattr(control, "_check_piga_view", lambda *args: None)
    monkeypatch.setattr(control, "_check_dmc_rate", lambda *args: None)
    monkeypatch.setattr(control, "warn_if_unconverged", lambda *args: None)
    monkeypatch.setattr(dmc, "PigaSwingUp", lambda model, planner: None)
    monkeypatch.setattr(dmc, "run_dmc_episodes", lambda agent, name, config, *args, **kwargs:
                        sizes.append(config.env.image_size) or (_ for _ in ()).throw(KeyboardInterrupt))
    code, _, _ = run_in_process("piga-control", control.main, "--env", "piga/DMCPendulum-v0", "--model",
                                str(tmp_path), "--episodes", "1", "--quiet", capsys=capsys)
    assert sizes == [32] and code == 130  # (stopped there: the size is what is checked)
