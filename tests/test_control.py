"""Control: the oracle swings the pendulum up; goal images; piga-control's bad input."""

from __future__ import annotations

import importlib.util
import math
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent
from piga.cli.control import main as control_main
from piga.control.episodes import EpisodeConfig, run_episodes
from piga.control.goal import load_scene_image, render_goal_image
from piga.world.model import ModelConfig, PhysicsModel
from tests.helpers import ENV, assert_one_line_error, completed_in_process, run


def ctl(capsys: pytest.CaptureFixture[str], *argv: str) -> subprocess.CompletedProcess[str]:
    """``piga-control`` run in this process."""
    return completed_in_process("piga-control", control_main, *argv, capsys=capsys)


@pytest.mark.parametrize("substeps", [1, 5])
def test_planning_dynamics_roll_like_the_physics_module(substeps: int) -> None:
    """The planner's plain-array engine follows piga.world.physics.rollout (model convention + φ = Gymnasium's)."""
    from agents.dynamics import PendulumDynamics, pendulum_state
    from piga.world.physics import Euler, Pendulum, rollout

    system = Pendulum(g=9.3, a=1.2, dt=0.05, offset=0.4, length=1.1, mass=0.9, learnable=False)
    actions = torch.rand(50, 20, 1, generator=torch.Generator().manual_seed(0)) * 4 - 2
    theta0 = torch.linspace(-3, 3, 50)[:, None, None]  # (B, 1, 1) model angles
    speed0 = torch.linspace(-4, 4, 50)[:, None, None]
    p, v = rollout(system, Euler(substeps), theta0, speed0, actions)  # (B, H, 1, 1)
    dynamics = PendulumDynamics.of(system, Euler(substeps), gravity_mult=1.0)
    for i in (0, 17, 49):
        states = dynamics.rollout(pendulum_state(float(theta0[i]) + 0.4, float(speed0[i])), actions[i : i + 1])
        assert states.shape == (1, 20, 2)
        torch.testing.assert_close(states[0, :, 0], p[i, :, 0, 0] + 0.4, atol=1e-4, rtol=0)
        torch.testing.assert_close(states[0, :, 1], v[i, :, 0, 0], atol=1e-4, rtol=0)
    stronger = PendulumDynamics.of(system, Euler(substeps), gravity_mult=1.4)
    assert stronger.g == pytest.approx(1.4 * 9.3) and stronger.substeps == substeps


def test_oracle_swings_up_from_hanging() -> None:
    torch.set_num_threads(1)
    config = EpisodeConfig(episodes=1, steps=150)
    result = run_episodes(OracleAgent.for_env(config.env_config(), MPCConfig()), config)
    episode = result.episodes[0]
    assert episode.start == (math.pi, 0.0)
    assert episode.success, episode
    assert result.summary.time_to_goal_steps_median < 130


def test_oracle_told_of_stronger_gravity_swings_up() -> None:
    """The counterfactual the piga agent relies on: planning with the changed gravity works."""
    torch.set_num_threads(1)
    config = EpisodeConfig(episodes=1, steps=150, gravity_mult=1.4)
    oracle = OracleAgent.for_env(config.env_config(), MPCConfig())
    assert oracle.planner.dynamics.g == pytest.approx(14.0) and oracle.planner.dynamics.a == 1.0  # the env's truth
    told = run_episodes(oracle, config).summary
    assert told.success_rate == 1.0


def test_success_definition() -> None:
    class Still:
        def reset(self) -> None: ...

        def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
            return np.zeros(1, np.float32)

    hanging = run_episodes(Still(), EpisodeConfig(episodes=1, steps=30, hold_steps=10))
    assert not hanging.episodes[0].success  # hanging at rest is not upright
    at_goal = run_episodes(Still(), EpisodeConfig(episodes=1, steps=30, hold_steps=10, goal_angle=math.pi))
    assert at_goal.episodes[0].success and at_goal.episodes[0].time_to_goal_steps == 0


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


def test_control_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(run("piga-control"), "--model")  # once as a script
    assert_one_line_error(ctl(capsys, "--model", str(tmp_path / "nope")), "checkpoint")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "checkpoint.pt").write_bytes(b"junk")
    assert_one_line_error(ctl(capsys, "--model", str(broken)), "checkpoint")
    for bad in ("0", "-1", "nan", "abc"):
        assert_one_line_error(ctl(capsys, "--oracle", "--gravity-mult", bad), "--gravity-mult")
    assert_one_line_error(ctl(capsys, "--oracle", "--angle", "20"), "--write-goal-image")
    assert_one_line_error(ctl(capsys, "--oracle", "--goal-image", str(tmp_path / "x.png")), "--model")
    assert_one_line_error(ctl(capsys, "--write-goal-image", str(tmp_path / "g.png")), "--angle")
    assert_one_line_error(ctl(capsys, "--write-goal-image", str(tmp_path / "g.txt"), "--angle", "5"), ".png")
    assert_one_line_error(ctl(capsys, "--oracle", "--video", str(tmp_path / "v.avi")), ".mp4")


def test_write_goal_image(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "goal.png"
    result = ctl(capsys, "--write-goal-image", str(out), "--angle", "-15")
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert_one_line_error(ctl(capsys, "--write-goal-image", str(out), "--angle", "5"), "--overwrite")


def test_a_one_frame_gif_is_a_goal_image_and_an_animation_is_refused(tmp_path: Path) -> None:
    """imageio reads a GIF whole, as (frames, H, W, 3): one frame was refused as "not a 2-D image"."""
    import imageio.v3 as iio

    picture = render_goal_image(10.0)
    still, animation = tmp_path / "one.gif", tmp_path / "two.gif"
    iio.imwrite(still, picture[None], extension=".gif")
    iio.imwrite(animation, np.stack([picture, render_goal_image(20.0)]), extension=".gif", duration=50)
    png = tmp_path / "one.png"
    iio.imwrite(png, picture)
    assert np.abs(load_scene_image(still, 64).astype(int) - load_scene_image(png, 64).astype(int)).max() <= 8  # a palette
    with pytest.raises(ValueError, match="two.gif: an animation of 2 frames; give one image"):
        load_scene_image(animation, 64)


def test_write_goal_image_of_minus_zero_says_zero(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = ctl(capsys, "--write-goal-image", str(tmp_path / "goal.png"), "--angle", "-0")
    assert result.returncode == 0, result.stderr
    assert "the pendulum at 0 deg" in result.stdout, result.stdout


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
    from piga.control.episodes import parse_range

    assert parse_range("0.5:1.8:0.1") == [round(0.5 + 0.1 * i, 10) for i in range(14)]
    assert parse_range("1:1:0.5") == [1.0]
    for bad in ("1:2", "a:b:c", "2:1:0.1", "1:2:0", "0:1e9:1"):
        with pytest.raises(ValueError):
            parse_range(bad)


def test_summary_markdown_has_a_row_per_summary() -> None:
    from piga.evaluation.episodes import EpisodeSummary, summary_markdown

    s = {"agent": "oracle", "gravity_mult": 1.0, "goal_angle": 0.0, "episodes": 2, "success_rate": 0.5, "mean_return": -200.0,
         "final_angle_error_mean": 0.01, "time_to_goal_steps_median": None, "plan_ms_median": 9.0, "plan_ms_p95": 12.0}
    table = summary_markdown([EpisodeSummary.from_dict(s), EpisodeSummary.from_dict({**s, "agent": "piga"})]).splitlines()
    assert len(table) == 4 and "| oracle | 1 | 0.00 | 2 | 50% | -200.0 | 0.57 | – | 9.00 | 12.00 |" == table[2]


def test_sweep_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(ctl(capsys, "--oracle", "--sweep", "0.5:1.8:0.1"), "--model")
    assert_one_line_error(ctl(capsys, "--model", str(tmp_path / "none"), "--sweep", "1:2"), "START:STOP:STEP")


def test_the_ray_option_is_checked_before_any_work(capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("host:port", "ray://head:10001", "head:70000"):
        assert ctl(capsys, "--oracle", "--ray", bad).returncode == 1
        assert_one_line_error(ctl(capsys, "--oracle", "--ray", bad), "--ray", "HOST:PORT")
    assert_one_line_error(ctl(capsys, "--oracle", "--ray", "auto"), "--ray runs the jobs of --sweep")
    assert_one_line_error(ctl(capsys, "--env", "piga/DMCPendulum-v0", "--ray", "auto"), "--ray is not an option")


def test_a_sweep_on_ray_without_ray_or_its_cluster_is_refused_in_one_line(control_model: Path, monkeypatch: pytest.MonkeyPatch,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    sweep = ("--model", str(control_model), "--sweep", "1:1:1", "--episodes", "1", "--steps", "20", "--quiet")
    if importlib.util.find_spec("ray") is not None:
        line = assert_one_line_error(ctl(capsys, *sweep, "--ray", f"127.0.0.1:{port}"), "Connection refused")
        assert line == f"piga-control: error: --ray 127.0.0.1:{port}: no Ray cluster at 127.0.0.1:{port}: Connection refused"
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    line = assert_one_line_error(ctl(capsys, *sweep, "--ray", "auto"))
    assert line == "piga-control: error: --ray auto: Ray is not installed: pip install -e '.[ray]'"


@pytest.mark.slow
def test_agents_import_nothing_from_diagnostics() -> None:
    """The planner knows no diagnosis: importing every agents module in a fresh interpreter loads no piga.diagnostics."""
    import subprocess
    import sys

    code = ("import pkgutil, importlib, sys, agents\n"
            "for m in pkgutil.iter_modules(agents.__path__): importlib.import_module('agents.' + m.name)\n"
            "print(sorted(m for m in sys.modules if m.startswith(('piga.diagnostics', 'piga.training.train', 'piga.control.episodes', 'piga.control.jobs'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# --- piga-control end to end on a tiny model (its control quality means nothing) -----------------


@pytest.fixture(scope="module")
def control_model(tiny_run: Path) -> Path:
    """A pendulum model trained for one epoch on the tiny data: the session's run folder (tests/conftest.py)."""
    return tiny_run


@pytest.mark.slow
def test_sweep_writes_a_table_per_multiplier(control_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    out = tmp_path / "sweep-x1.0"  # a stem with a dot: OUT.json is appended, never replaces ".0"
    result = run("piga-control", "--model", str(control_model), "--sweep", "1:1.5:0.5", "--episodes", "1", "--steps", "20",
                 "--workers", "2", "--out", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    record = json.loads(Path(f"{out}.json").read_text())
    assert record["multipliers"] == [1.0, 1.5]
    # the planner's settings are in the record, not only in the page's command line
    assert record["planner"]["warm_start"] is True and record["planner"]["cem"]["horizon"] == 20, record["planner"]
    assert record["command"].startswith("piga-control --model ")
    rows = [(r["summary"]["agent"], r["summary"]["gravity_mult"]) for r in record["results"]]
    assert rows == [("piga", 1.0), ("oracle", 1.0), ("piga", 1.5), ("oracle", 1.5)]
    assert all(len(r["episodes"]) == 1 for r in record["results"])
    assert Path(f"{out}.md").read_text().count("| piga |") == 2
    assert Path(f"{out}.png").read_bytes()[:4] == b"\x89PNG"

    # --not-told: the piga agent plans with its learned g at each multiplier, and its rows say so
    result = ctl(capsys, "--model", str(control_model), "--sweep", "1.5:1.5:0.5", "--not-told", "--episodes", "1",
                 "--steps", "20", "--workers", "1", "--out", str(tmp_path / "not-told"), "--quiet")
    assert result.returncode == 0, result.stderr
    rows = [r["summary"]["agent"] for r in json.loads((tmp_path / "not-told.json").read_text())["results"]]
    assert rows == ["piga (not told)", "oracle"] and "| piga (not told) |" in result.stdout


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_is_written_and_decodes(control_model: Path, tmp_path: Path, suffix: str,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    import imageio.v3 as iio

    video = tmp_path / f"episode{suffix}"
    result = ctl(capsys, "--model", str(control_model), "--episodes", "1", "--steps", "20", "--video", str(video),
                 "--quiet")
    assert result.returncode == 0, result.stderr
    frames = iio.imread(video)  # (T, H, W, 3): real | belief | plan, one per step
    assert frames.shape[0] == 20 and frames.shape[2] >= 3 * 64 and frames.std() > 1
    assert_one_line_error(ctl(capsys, "--model", str(control_model), "--episodes", "1", "--steps", "20", "--video",
                              str(video)), "--overwrite")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.slow
def test_interrupted_sweep_ends_with_its_workers(control_model: Path, sig: signal.Signals) -> None:
    """Ctrl-C or SIGTERM to piga-control during a sweep: one line, a non-zero exit, and no worker left."""
    if not Path("/proc/self/stat").exists():
        pytest.skip("needs /proc")
    proc = subprocess.Popen(["piga-control", "--model", str(control_model), "--sweep", "0.5:1.5:0.5", "--workers", "2",
                             "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        deadline = time.monotonic() + 60
        while len(_children(proc.pid)) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        workers = _children(proc.pid)
        assert len(workers) == 2, "the sweep did not start its two workers"
        time.sleep(1.0)  # well into the episodes
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode != 0
    *warnings, last = err.strip().splitlines()  # the tiny model's own warning (it did not converge) may come first
    assert last == "piga-control: interrupted; nothing was written" and len(warnings) <= 1, err
    assert all(line.startswith("piga-control: warning: the run ") for line in warnings), err
    deadline = time.monotonic() + 10
    while any(map(_alive, workers)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(map(_alive, workers))


def _children(pid: int) -> list[int]:
    """Live child processes of ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_cem_settings_from_the_command_line() -> None:
    """PlaNet's CEM can be given; elites follow the candidates unless given; the defaults are the dataclasses'."""
    from agents.cem import CEMConfig
    from piga.cli import control as cli

    parser = cli.build_parser()
    default = cli._mpc_config(parser.parse_args(["--oracle"]), 0.0)
    assert default == MPCConfig()
    planet = cli._mpc_config(parser.parse_args(["--oracle", "--horizon", "12", "--iterations", "10", "--candidates", "1000",
                                                "--elites", "100", "--no-warm-start"]), 0.0)
    assert planet.cem == replace(CEMConfig(), init_std=MPCConfig().cem.init_std) and not planet.warm_start
    few = cli._mpc_config(parser.parse_args(["--oracle", "--candidates", "10"]), 0.0)
    assert few.cem.candidates == 10 and few.cem.elites == 1
    assert "(default 200)" in " ".join(parser.format_help().split())


def test_control_cli_bad_cem_and_episode_settings(capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(ctl(capsys, "--oracle", "--candidates", "10", "--elites", "20"),
                          "--elites (20) must be at most --candidates (10)")
    assert_one_line_error(ctl(capsys, "--oracle", "--candidates", "1"), "--candidates must be at least 2")
    result = ctl(capsys, "--oracle", "--steps", "3")
    assert_one_line_error(result, "--steps: expected an integer in [20, 100000] (success is the goal held for the last 20 "
                          "steps")
    assert "EpisodeConfig" not in result.stderr
    ok = ctl(capsys, "--oracle", "--candidates", "10", "--episodes", "1", "--steps", "20", "--quiet")
    assert ok.returncode == 0 and "success" in ok.stdout, ok.stderr


def test_goal_image_that_is_not_the_scene_is_refused(control_model: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """White, black or noise is refused whatever the model's training; a render of the scene is read."""
    import imageio.v3 as iio

    from piga.control.goal import NotTheSceneError, goal_from_image, scene_mismatch
    from piga.io.runs import load_model

    model, ckpt = load_model(control_model)  # one epoch: its own re-rendering check means nothing
    rng = np.random.default_rng(0)
    for name, picture in (("white", np.full((300, 300, 3), 255, np.uint8)), ("black", np.zeros((80, 80), np.uint8)),
                          ("noise", rng.integers(0, 256, (200, 200, 3)).astype(np.uint8))):
        iio.imwrite(tmp_path / f"{name}.png", picture)
        with pytest.raises(NotTheSceneError, match="not a picture of the pendulum scene"):
            goal_from_image(model, ckpt, tmp_path / f"{name}.png")
    for angle in (0.0, 13.7, -100.0, 180.0):
        assert scene_mismatch(load_scene_image_array(render_goal_image(angle))) < 0.1
    iio.imwrite(tmp_path / "goal.png", render_goal_image(13.7))
    goal_from_image(model, ckpt, tmp_path / "goal.png")  # accepted
    assert_one_line_error(ctl(capsys, "--model", str(control_model), "--goal-image", str(tmp_path / "white.png")),
                          "not a picture of the pendulum scene")


def test_goal_image_messages(control_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "dot.png", np.zeros((1, 1), np.uint8))
    assert_one_line_error(ctl(capsys, "--model", str(control_model), "--goal-image", str(tmp_path / "dot.png")),
                          "1x1 pixels, too small")
    assert_one_line_error(ctl(capsys, "--model", str(control_model), "--goal-image", str(tmp_path)),
                          "is a folder, not an image file")


def test_a_job_with_a_correction_plans_and_reads_with_it(control_model: Path) -> None:
    """A diagnosis' correction travels to a worker (pickled) and replaces the agent's physics and reader."""
    import pickle

    from piga.diagnostics import fit
    from piga.control.corrected import CameraReader, CorrectedDynamics, Correction
    from piga.diagnostics.vision import Camera
    from piga.control.jobs import ControlJob, build_agent, run_job

    correction = Correction(fit.Model(("damping",), 0, {"g": 9.0, "a": 1.1, "b": 0.2}), Camera(blur=1.0))
    job = ControlJob("piga", EpisodeConfig(episodes=1, steps=20, gravity_mult=1.4), MPCConfig(), str(control_model),
                     correction=correction)
    job = pickle.loads(pickle.dumps(job))
    agent = build_agent(job)
    assert isinstance(agent, PigaMPCAgent) and isinstance(agent.read_state, CameraReader)
    dynamics = agent.planner.dynamics
    assert isinstance(dynamics, CorrectedDynamics) and dynamics.corrected.values["g"] == pytest.approx(9.0 * 1.4)
    assert len(run_job(job).episodes) == 1
    with pytest.raises(ValueError, match="no correction"):
        ControlJob("oracle", EpisodeConfig(), correction=correction)


def test_encoder_reader_reads_only_the_new_frame_and_agrees_with_a_fresh_read() -> None:
    """The reader keeps the coordinates of frames it has seen; this holds only while the encoder reads
    each frame alone, which this test checks against reading all L frames anew."""
    from agents.mpc import EncoderReader

    model = PhysicsModel(ModelConfig())
    with torch.no_grad():
        model.encoder.background.fill_(1.0)
    frames = np.stack([load_scene_image_array(render_goal_image(a)) for a in (20.0, 24.0, 29.0, 35.0, 42.0)])
    reader = EncoderReader(model)
    reader(frames[:4])
    calls = []
    model.encoder.register_forward_hook(lambda module, args, out: calls.append(args[0].shape[0]))
    moved_on = reader(frames[1:])
    assert calls == [1]  # only the new frame went through the encoder
    assert moved_on == pytest.approx(EncoderReader(model)(frames[1:]), abs=1e-5)
    assert calls == [1, 4]


def test_piga_control_parses_its_arguments_without_torch() -> None:
    """A mistyped command is answered at once: the parser and its defaults do not import torch."""
    import subprocess
    import sys

    code = "import sys, piga.cli.control as c; c.build_parser().parse_args(['--oracle']); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_not_told_plans_with_the_learned_g_unscaled_in_an_env_at_the_multiplier(
        control_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """--not-told: the environment's gravity is x1.4, the agent's planning gravity its learned g (what it is told: 1)."""
    import json

    import agents.mpc
    from agents.dynamics import PendulumDynamics
    from piga.control.jobs import ControlJob, build_agent
    from piga.io.runs import load_model

    model, _ = load_model(control_model)
    learned = PendulumDynamics.of(model.system, model.integrator).gravity_gain
    built: list[PigaMPCAgent] = []

    class Recorded(PigaMPCAgent):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            built.append(self)

    monkeypatch.setattr(agents.mpc, "PigaMPCAgent", Recorded)
    gains = {}
    for flags in ((), ("--not-told",)):
        out = tmp_path / f"run{len(flags)}"
        result = ctl(capsys, "--model", str(control_model), "--gravity-mult", "1.4", *flags, "--episodes", "1", "--steps",
                     "20", "--out", str(out), "--quiet")
        assert result.returncode == 0, result.stderr
        assert json.loads(Path(f"{out}.json").read_text())["summary"]["gravity_mult"] == 1.4  # the env's, either way
        gains[flags] = built[-1].planner.dynamics.gravity_gain
        assert ("(not told)" in result.stdout) == bool(flags)
    assert gains[("--not-told",)] == pytest.approx(learned) and gains[()] == pytest.approx(1.4 * learned)
    episodes = EpisodeConfig(episodes=1, steps=20, gravity_mult=1.4)
    assert build_agent(ControlJob("piga", episodes, model_dir=str(control_model), told=False)
                       ).planner.dynamics.gravity_gain == pytest.approx(learned)
    with pytest.raises(ValueError, match="piga agent"):
        ControlJob("oracle", episodes, told=False)


def test_not_told_is_refused_for_the_oracle(capsys: pytest.CaptureFixture[str]) -> None:
    assert_one_line_error(ctl(capsys, "--oracle", "--not-told", "--gravity-mult", "1.4"), "--not-told", "oracle")


def test_an_out_set_records_what_the_model_run_says_against_it(control_model: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A run that did not converge scored "success 100%" in OUT.json and OUT.md without a word: the warning reached
    stderr only."""
    import json
    import shutil

    run = tmp_path / "run"
    shutil.copytree(control_model, run)
    metrics = json.loads((run / "metrics.json").read_text())
    for converged in (False, True):
        metrics.update(converged=converged, convergence={"outcome": "unsettled", "reason": "still drifting at the end"})
        (run / "metrics.json").write_text(json.dumps(metrics))
        out = tmp_path / f"scored-{converged}"
        result = ctl(capsys, "--model", str(run), "--episodes", "1", "--steps", "20", "--out", str(out), "--quiet")
        assert result.returncode == 0, result.stderr
        warning = json.loads(Path(f"{out}.json").read_text())["model_warning"]
        page = Path(f"{out}.md").read_text()
        if converged:
            assert warning is None and "Warning" not in page
        else:
            assert warning == f"the run {run} did not converge: still drifting at the end"
            assert f"**Warning:** {warning}" in page and page.startswith("# piga-control\n\n**Warning:**")


def test_the_effects_of_the_training_file_are_compared_as_the_env_holds_them() -> None:
    """A training file's effects as JSON pairs ([["delay", 1]]) were always unlike the env's tuples, and, written as an
    object by hand ({"delay": 1}, which the schema takes), were named raw: "the effects {'delay': 1}"."""
    from envs.pendulum import PixelPendulumConfig
    from piga.cli.control import pixel_physics_difference

    plain = PixelPendulumConfig()
    assert pixel_physics_difference({"effects": [["delay", 1]]}, plain) == ("no effect", "the effects delay=1")
    assert pixel_physics_difference({"effects": {"delay": 1}}, plain) == ("no effect", "the effects delay=1")
    delayed = PixelPendulumConfig(effects=(("delay", 1),))
    assert pixel_physics_difference({"effects": [["delay", 1]]}, delayed) is None
    assert pixel_physics_difference({"effects": [["delay", 2]]}, delayed) == ("other effects", "the effects delay=2")
