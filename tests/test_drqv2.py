"""DrQ-v2 in SB3's loop: the augmentation shifts by whole pixels, the exploration std follows its
schedule, the update trains the encoder by the critic alone, and a run resumes exactly and acts in
piga's episodes."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from agents.sb3.config import SB3Config
from agents.sb3.drqv2 import DrQV2Policy, ScheduledNoise, random_shift
from tests.test_dmc import needs_dmc

#: Tiny settings: a few seconds of training (the encoder is DrQ-v2's, the MLPs small).
TINY = SB3Config(algo="drqv2", obs="pixels", steps=400, learning_starts=150, eval_every=200, eval_episodes=1, batch_size=8,
                 net_arch=(16, 16), feature_dim=8, buffer_size=500, threads=1, device="cpu")


def test_random_shift_moves_each_image_by_whole_pixels_with_the_border_replicated() -> None:
    x = torch.arange(2 * 3 * 12 * 12, dtype=torch.float32).reshape(2, 3, 12, 12)
    generator = torch.Generator().manual_seed(5)
    shifted = random_shift(x, pad=2, generator=generator)
    shifts = torch.randint(0, 5, (2, 2), generator=torch.Generator().manual_seed(5))  # the same draw: (dx, dy) + pad
    padded = F.pad(x, (2, 2, 2, 2), mode="replicate")
    for i, (dx, dy) in enumerate(shifts.tolist()):
        torch.testing.assert_close(shifted[i], padded[i, :, dy:dy + 12, dx:dx + 12])
    torch.testing.assert_close(random_shift(x, pad=0), x)


def test_the_exploration_std_falls_linearly_then_stays() -> None:
    noise = ScheduledNoise(1, start=1.0, end=0.1, steps=100)
    assert [noise.std(s) for s in (0, 50, 100, 1000)] == pytest.approx([1.0, 0.55, 0.1, 0.1])
    np.random.seed(0)
    noise.step = 100
    draws = np.array([noise()[0] for _ in range(4000)])
    assert draws.std() == pytest.approx(0.1, rel=0.05)


def test_the_critic_trains_the_encoder_and_the_actor_does_not() -> None:
    from stable_baselines3.common.buffers import NStepReplayBuffer

    from agents.sb3.drqv2 import DrQV2
    from agents.sb3.train import _vec_env

    torch.manual_seed(0)
    venv = _vec_env(TINY, None, 0, episode_seed=0)
    model = DrQV2("CnnPolicy", venv, learning_rate=1e-3, buffer_size=100, learning_starts=40, batch_size=4, train_freq=2,
                  action_noise=ScheduledNoise(1, 1.0, 0.1, 100), policy_kwargs={"net_arch": [16, 16], "feature_dim": 8},
                  replay_buffer_class=NStepReplayBuffer, replay_buffer_kwargs={"n_steps": 3, "gamma": 0.99}, seed=0,
                  device="cpu")
    model.learn(50)
    policy: DrQV2Policy = model.policy
    # the actor's loss reaches the actor only: its features are detached from the encoder
    features = policy.encoder(torch.randint(0, 256, (4, 3, 64, 64)).float())
    policy.zero_grad()
    (-torch.min(*policy.critic(features.detach(), policy.actor(features.detach())))).mean().backward()
    assert all(p.grad is None for p in policy.encoder.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in policy.actor.parameters())
    encoder = [p.detach().clone() for p in policy.encoder.parameters()]
    target = [p.detach().clone() for p in policy.critic_target.parameters()]
    model.train(gradient_steps=1, batch_size=4)
    assert any(not torch.equal(a, b) for a, b in zip(encoder, policy.encoder.parameters())), "the critic left the encoder"
    assert any(not torch.equal(a, b) for a, b in zip(target, policy.critic_target.parameters())), "no soft update"
    venv.close()


@pytest.mark.slow  # three pixel runs (about 20 s alone); by default tests/test_ddpg.py::test_training_resumes_exactly
# checks the SB3 runs' checkpoint and resume, and the tests above DrQ-v2's own update
def test_a_run_resumes_exactly_and_acts_in_piga_episodes(tmp_path: Path) -> None:
    from agents.sb3.run import SB3Agent, load_sb3
    from agents.sb3.train import train_sb3
    from piga.control.episodes import EpisodeConfig, run_episodes

    tiny = replace(TINY, learning_starts=190)  # 10 updates before the cut at step 200, 200 after it
    straight = train_sb3(tiny, tmp_path / "a", progress=False)
    train_sb3(replace(tiny, steps=200), tmp_path / "b", progress=False)
    resumed = train_sb3(tiny, tmp_path / "b", resume=True, progress=False)
    assert [r["eval_mean_return"] for r in resumed["learning_curve"]] == [r["eval_mean_return"] for r in straight["learning_curve"]]
    a, b = load_sb3(tmp_path / "a")[0], load_sb3(tmp_path / "b")[0]
    for (name, p), q in zip(a.policy.state_dict().items(), b.policy.state_dict().values()):
        assert torch.equal(p, q), name
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import learning_curve

    assert learning_curve.main([str(tmp_path / "b"), "--out", str(tmp_path / "curve.json")]) == 0
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert curve["learning_curve"] == resumed["learning_curve"] and curve["config"]["algo"] == "drqv2"
    assert "commit" not in curve  # trained in Python: no record of the command or its code
    (tmp_path / "b" / "config.json").write_text(json.dumps({"command": f"piga-baseline ddpg --out {tmp_path / 'b'}",
                                                           "commit": "abc", "resumed_commits": ["def"]}))
    assert learning_curve.main([str(tmp_path / "b"), "--out", str(tmp_path / "curve.json"), "--overwrite"]) == 0
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert (curve["command"], curve["commit"], curve["resumed_commits"]) == ("piga-baseline ddpg --out RUN", "abc", ["def"])
    for record, needle in (([1], "config.json is not a run record"), ({"command": 5}, "'command' must be the command line")):
        (tmp_path / "b" / "config.json").write_text(json.dumps(record))  # each was an internal error
        assert learning_curve.main([str(tmp_path / "b"), "--out", str(tmp_path / "bad.json")]) == 1
        assert not (tmp_path / "bad.json").exists()
    agent = SB3Agent.from_run(tmp_path / "a")
    assert agent.input_frames == 1 and agent.model.observation_space.shape == (3, 64, 64)
    assert np.isfinite(run_episodes(agent, EpisodeConfig(episodes=1, steps=10, hold_steps=5)).summary.mean_return)


@pytest.mark.slow  # two pixel runs; the batches themselves are compared in tests/test_replay.py
def test_a_run_with_its_observations_on_the_device_learns_as_one_in_host_memory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The device-resident buffer (a GPU's; here forced on the CPU) gives the host buffer's run, and checkpoints as
    itself (tests/test_replay.py: its pickle samples the same batches)."""
    import pickle

    from agents.sb3 import replay
    from agents.sb3.run import REPLAY_BUFFERS, load_sb3
    from agents.sb3.train import train_sb3

    host = train_sb3(TINY, tmp_path / "host", progress=False)
    monkeypatch.setattr(replay, "fits_on_device", lambda *args: True)
    device = train_sb3(TINY, tmp_path / "device", progress=False)
    assert [r["eval_mean_return"] for r in host["learning_curve"]] == [r["eval_mean_return"] for r in device["learning_curve"]]
    weights = [load_sb3(tmp_path / name)[0].policy.state_dict() for name in ("host", "device")]
    for name, p in weights[0].items():
        assert torch.equal(p, weights[1][name]), name
    with open(next((tmp_path / "device" / REPLAY_BUFFERS).glob("*.pkl")), "rb") as file:
        assert type(pickle.load(file)).__name__ == "DeviceNStepReplayBuffer"


def test_drqv2_has_its_papers_values_and_learns_from_pixels_only() -> None:
    config = SB3Config(algo="drqv2", obs="pixels")
    assert (config.learning_rate, config.batch_size, config.tau, config.train_freq, config.n_step, config.frame_stack,
            config.net_arch, config.noise_std, config.noise_final_std, config.learning_starts) == \
        (1e-4, 256, 0.01, 2, 3, 3, (1024, 1024), 1.0, 0.1, 4000)
    assert config.buffer_size == 100_000  # its own, not the DDPG pixels preset's 50000
    # its warm-up is 4000 frames, physics steps: 2000 env steps at the DMC pendulum's action repeat 2 (it was 4000)
    assert SB3Config(algo="drqv2", obs="pixels", env="piga/DMCPendulum-v0").learning_starts == 2000
    assert SB3Config(algo="drqv2", obs="pixels", env="piga/DMCPendulum-v0", learning_starts=10).learning_starts == 10
    with pytest.raises(ValueError, match="DrQ-v2 learns from pixels; --obs state"):
        SB3Config(algo="drqv2", obs="state")


def test_the_dmc_pendulum_is_learnt_from_its_frames_in_whole_episodes_of_its_length() -> None:
    from envs import DMC_PENDULUM

    config = replace(TINY, env=DMC_PENDULUM, steps=1000, eval_every=500)
    assert (config.episode_steps, config.learned_return) == (500, 200.0)  # 1000 physics steps at action repeat 2
    for bad, needle in (({"obs": "state", "algo": "ddpg"}, "--obs state is for piga/PixelPendulum-v0"),
                        ({"torque_arrow": True}, "no torque arrow"), ({"eval_every": 400}, "multiple of the episode length 500")):
        with pytest.raises(ValueError, match=needle):
            replace(config, **bad)


@pytest.mark.slow  # a DrQ-v2 run on MuJoCo's renders, then its DMC episodes: about 16 s
@needs_dmc
def test_a_drqv2_run_on_the_dmc_pendulum_is_scored_in_dmcs_episodes_and_nowhere_else(tmp_path: Path, capsys) -> None:
    """``piga-baseline ddpg --env piga/DMCPendulum-v0`` trains on DMC's frames and reward; ``piga-control --env
    piga/DMCPendulum-v0 --model`` scores it in DMC's units beside piga and the oracle, and the pixel pendulum refuses it."""
    from piga.cli.baseline import main as baseline
    from piga.cli.control import main as control
    from tests.helpers import assert_one_line_error, assert_sb3_run_finished, completed_in_process, run_in_process

    run = tmp_path / "drq"
    code, out, err = run_in_process("piga-baseline", baseline, "ddpg", "--env", "piga/DMCPendulum-v0", "--algo", "drqv2",
                                    "--obs", "pixels", "--steps", "500", "--eval-every", "500", "--eval-episodes", "1",
                                    "--learning-starts", "450", "--batch-size", "8", "--buffer-size", "600", "--out",
                                    str(run), "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)  # 500 steps cannot learn: exit 1, the summary and the outputs kept
    trained_code = code
    assert ("never reached 200" in out and "never reached 200 in 500 env steps" in err) if code else "first reached 200" in out
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["env"] == "piga/DMCPendulum-v0" and "first_step_reaching_200" in metrics
    assert 0 <= metrics["final_eval_mean_return"] <= 1000  # DMC's score of one 500-frame episode
    code, out, err = run_in_process("piga-control", control, "--env", "piga/DMCPendulum-v0", "--model", str(run),
                                    "--episodes", "1", "--quiet", capsys=capsys)
    assert code == 0 and "| drqv2 |" in out and "Planner" not in out
    # as on the pixel env: a run that did not learn is scored, and said so in one warning line
    assert (err.count("\n") == 1 and "did not learn" in err) if trained_code else not err, err
    assert_one_line_error(completed_in_process("piga-control", control, "--model", str(run), "--episodes", "1", "--quiet",
                                               capsys=capsys), "trained on piga/DMCPendulum-v0", "--env piga/DMCPendulum-v0")
    assert_one_line_error(completed_in_process("piga-control", control, "--env", "piga/DMCPendulum-v0", "--model", str(run),
                                               "--env-option", "action_repeat=4", "--quiet", capsys=capsys),
                          "action_repeat 2")


def test_the_bfloat16_encoder_gives_float32_features_close_to_float32s() -> None:
    from agents.sb3.drqv2 import Encoder

    torch.manual_seed(0)
    exact, rounded = Encoder(3, 64), Encoder(3, 64, bfloat16=True)
    rounded.load_state_dict(exact.state_dict())
    x = torch.randint(0, 256, (4, 3, 64, 64)).float()
    a, b = exact(x), rounded(x)
    assert b.dtype == torch.float32 and not torch.equal(a, b)  # computed in bfloat16: rounded
    assert ((a - b).norm() / a.norm()).item() < 0.03
    b.sum().backward()
    assert all(p.grad is not None and p.grad.dtype == torch.float32 for p in rounded.parameters())  # weights stay float32


def test_auto_precision_is_bfloat16_only_for_drqv2_on_a_cpu_that_has_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.sb3.config as sb3_config

    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    drq = SB3Config(algo="drqv2", obs="pixels")
    for hardware, expected in ((True, "bfloat16"), (False, "float32")):
        monkeypatch.setattr(sb3_config, "bfloat16_in_hardware", lambda hardware=hardware: hardware)
        assert sb3_config.resolve_precision(drq, cpu) == expected
        assert sb3_config.resolve_precision(drq, cuda) == "float32"  # torch's TF32 convolutions there
        assert sb3_config.resolve_precision(SB3Config(algo="ddpg", obs="pixels"), cpu) == "float32"
        for given in ("float32", "bfloat16"):
            assert sb3_config.resolve_precision(replace(drq, encoder_precision=given), cuda) == given
    with pytest.raises(ValueError, match="encoder_precision bfloat16 is for DrQ-v2; SB3's sac"):
        SB3Config(algo="sac", obs="pixels", encoder_precision="bfloat16")


@pytest.mark.slow  # three pixel runs and a resume: about 22 s
def test_a_run_keeps_its_precision_in_its_record_its_model_and_its_resume(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The record holds the precision resolved (not "auto", which another machine would read otherwise); a run
    recorded before the option computed in float32 and resumes so."""
    import agents.sb3.config as sb3_config
    from agents.sb3.run import load_sb3
    from piga.cli import baseline
    from tests.helpers import assert_sb3_run_finished, run_in_process

    monkeypatch.setattr(sb3_config, "bfloat16_in_hardware", lambda: True)
    tiny = ("--algo", "drqv2", "--obs", "pixels", "--eval-every", "200", "--eval-episodes", "1", "--learning-starts",
            "190", "--batch-size", "8", "--buffer-size", "500", "--device", "cpu", "--quiet")
    for given, recorded in (("auto", "bfloat16"), ("float32", "float32")):
        out = tmp_path / given
        code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--out", str(out), "--steps", "200",
                                      "--encoder-precision", given, *tiny, capsys=capsys)
        assert_sb3_run_finished(code, err)
        assert json.loads((out / "config.json").read_text())["ddpg"]["encoder_precision"] == recorded
        assert load_sb3(out)[0].policy.encoder_precision == recorded
    record = json.loads((out / "config.json").read_text())
    del record["ddpg"]["encoder_precision"]  # as written before the option
    (out / "config.json").write_text(json.dumps(record))
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--out", str(out), "--resume", "--obs", "pixels",
                                  "--algo", "drqv2", "--steps", "400", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert json.loads((out / "config.json").read_text())["ddpg"]["encoder_precision"] == "float32"
    assert json.loads((out / "metrics.json").read_text())["encoder_precision"] == "float32"


def test_the_bfloat16_encoders_layout_changes_no_feature_order() -> None:
    """Channels-last memory is a layout: the features must come out in the channel-first order of float32's."""
    from agents.sb3.drqv2 import Encoder

    torch.manual_seed(0)
    exact, rounded = Encoder(3, 64), Encoder(3, 64, bfloat16=True)
    rounded.load_state_dict(exact.state_dict())
    assert rounded.convnet[0].weight.is_contiguous(memory_format=torch.channels_last)
    x = torch.randint(0, 256, (2, 3, 64, 64)).float()
    a, b = exact(x), rounded(x)
    assert torch.corrcoef(torch.stack([a.flatten(), b.flatten()]))[0, 1] > 0.999


@needs_dmc
def test_a_dmc_run_of_drqv2s_view_sees_84x84_rgb_and_is_scored_through_it() -> None:
    """``view="drqv2"``: the agent sees stacks of 3 RGB frames of 84x84 from dm_control's camera 0, piga's episodes
    score it through the same view, and an env option that would show it other frames is refused."""
    from agents.sb3.config import DMC_VIEWS
    from agents.sb3.run import SB3Agent
    from agents.sb3.train import _vec_env, new_model
    from envs import DMC_PENDULUM
    from envs.dmc import DMCPendulumConfig
    from piga.cli.common import PigaError
    from piga.cli.control import _sb3_view
    from piga.control.dmc import DMCControlConfig, run_dmc_episodes

    with pytest.raises(ValueError, match="a view of piga/DMCPendulum-v0"):
        replace(TINY, view="drqv2")
    with pytest.raises(ValueError, match=r"SB3Config.learning_rate must be in \(0, 10\]"):
        replace(TINY, learning_rate=float("inf"))
    with pytest.raises(ValueError, match="SB3Config.noise_final_std must be at most 10"):
        replace(TINY, noise_final_std=float("inf"))
    config = replace(TINY, env=DMC_PENDULUM, steps=1000, eval_every=500, view="drqv2")
    assert config.frame_pixels == 3 * 84 * 84 and replace(config, view="fixed").frame_pixels == 64 * 64
    venv = _vec_env(config, None, 0, episode_seed=0)
    assert venv.observation_space.shape == (9, 84, 84)  # DrQ-v2's 3 stacked RGB frames
    agent = SB3Agent(new_model(config, venv, torch.device("cpu")), config)
    env = _sb3_view(agent, DMCPendulumConfig(mass=1.1), {"mass"})
    assert (env.camera, env.color, env.image_size, env.mass) == ("fixed", "rgb", 84, 1.1)
    assert _sb3_view(agent, DMCPendulumConfig(image_size=84), {"image_size"}) == DMCPendulumConfig(**DMC_VIEWS["drqv2"])
    with pytest.raises(PigaError, match="trained on its view 'drqv2'; drop --env-option color"):
        _sb3_view(agent, DMCPendulumConfig(color="gray"), {"color"})
    with pytest.raises(PigaError, match="trained on its view 'drqv2'; drop --env-option camera_distance"):
        _sb3_view(agent, DMCPendulumConfig(camera_distance=1.5), {"camera_distance"})  # it scored through it, silently
    batch = run_dmc_episodes(agent, "drqv2", DMCControlConfig(episodes=1, env=replace(env, episode_length=20)))
    assert len(batch.returns) == 1 and agent._stack.shape == (9, 84, 84)
    frames = agent._stack
    assert not np.array_equal(frames[-3], frames[-1])  # the newest frame's three channels, not one channel thrice
