"""The PlaNet-style baseline: the RSSM's shapes, its training step and run folder, and the latent planner."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from agents.config import CEMConfig
from agents.planet.config import IterativeConfig, LatentPlannerConfig, PlanetTrainConfig, RSSMConfig
from agents.planet.planner import PlanetAgent
from agents.planet.rssm import Belief, WorldModel, model_steps, sample

#: A model small enough for a test to train in a second.
TINY = RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=1)
# on the CPU, where a resumed run continues bit for bit (on a GPU, CUDA's atomic accumulations differ run to run)
TINY_TRAIN = PlanetTrainConfig(steps=4, batch_size=4, chunk_length=8, checkpoint_every=2, threads=1, device="cpu")
TINY_CEM = LatentPlannerConfig(cem=CEMConfig(horizon=4, iterations=2, candidates=20, elites=4))


def test_rssm_shapes() -> None:
    model = WorldModel(TINY)
    frames = torch.randint(0, 256, (3, 5, 64, 64), dtype=torch.uint8)
    actions = torch.rand(3, 5, 1) * 4 - 2
    h, s, prior, post = model.observe(frames, actions, torch.Generator().manual_seed(0))
    assert h.shape == (3, 5, 16) and s.shape == (3, 5, 4)
    assert prior.mean.shape == post.std.shape == (3, 5, 4) and bool((post.std >= TINY.min_std).all())
    assert model.embed(frames).shape == (3, 5, TINY.embed_size)
    assert model.decode(h, s).shape == (3, 5, 1, 64, 64)
    assert model.reward(h, s).shape == (3, 5)
    parts = model.loss(frames, actions, torch.zeros(3, 5), TINY_TRAIN)
    assert all(p.dim() == 0 and torch.isfinite(p) for p in parts)
    assert parts.kl.item() >= 0
    returns = model.imagine_return(Belief(h[:1, -1], s[:1, -1]), torch.zeros(7, 6, 1))
    assert returns.shape == (7,)
    decoded, rewards = model.open_loop(frames, actions, 2, torch.Generator().manual_seed(0))
    assert decoded.shape == (3, 5, 1, 64, 64) and rewards.shape == (3, 5)
    changed = frames.clone()
    changed[:, 2:] = 0  # frames after the context are never read
    torch.testing.assert_close(model.open_loop(changed, actions, 2, torch.Generator().manual_seed(0))[0], decoded)


def test_one_training_step_lowers_the_loss(tiny_data: Path) -> None:
    from agents.planet.train import _Sequences

    torch.manual_seed(0)
    model = WorldModel(TINY)
    batch = _Sequences(tiny_data, "train").batch(np.random.default_rng(0), 4, 8)

    def loss() -> torch.Tensor:
        return model.loss(*batch, TINY_TRAIN, torch.Generator().manual_seed(1)).loss

    before = loss()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3, eps=1e-4)
    before.backward()
    optimizer.step()
    with torch.no_grad():
        after = loss()
    assert after.item() < before.item() - 1e-3 * abs(before.item()), (before.item(), after.item())


def test_training_writes_a_run_and_resumes_exactly(tiny_data: Path, tmp_path: Path) -> None:
    from agents.planet.train import load_planet, train_planet

    straight, _ = train_planet(tiny_data, tmp_path / "a", TINY_TRAIN, TINY, progress=False)
    train_planet(tiny_data, tmp_path / "b", replace(TINY_TRAIN, steps=2), TINY, progress=False)
    resumed, state = train_planet(tiny_data, tmp_path / "b", TINY_TRAIN, resume=True, progress=False)
    assert state.step == 4 and [r["step"] for r in state.history] == [2, 4]
    for (name, p), q in zip(straight.state_dict().items(), resumed.state_dict().values()):
        assert torch.equal(p, q), name
    loaded, ckpt = load_planet(tmp_path / "b")
    assert ckpt["kind"] == "planet" and loaded.config == TINY
    import json

    metrics = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert len(metrics["learning_curve"]) == 2 and metrics["valid"]["loss"] > 0
    assert (tmp_path / "b" / "tensorboard").is_dir()
    open_loop = metrics["open_loop"]
    assert open_loop["split"] == "valid" and open_loop["context"] == 5 and len(open_loop["frame_mse"]) == 16
    assert (tmp_path / "b" / "openloop.png").stat().st_size > 0


def test_nan_stops_and_names_the_last_good_checkpoint(tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from agents.planet.train import train_planet
    from piga.training.train import TrainingDiverged

    original = WorldModel.loss
    calls = []

    def loss_that_blows_up(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        parts = original(self, *args, **kwargs)
        if not torch.is_grad_enabled():  # the valid split's loss at a checkpoint
            return parts
        calls.append(1)
        return parts._replace(loss=parts.loss * float("nan")) if len(calls) == 3 else parts

    monkeypatch.setattr(WorldModel, "loss", loss_that_blows_up)
    with pytest.raises(TrainingDiverged, match=f"at step 3; last good checkpoint: {tmp_path / 'run' / 'checkpoint.pt'}"):
        train_planet(tiny_data, tmp_path / "run", TINY_TRAIN, TINY, progress=False)


def test_a_file_without_rewards_is_refused(tiny_data: Path, tmp_path: Path) -> None:
    from agents.planet.train import check_planet_data
    from piga.data.schema import DataFormatError, inspect_dataset
    from tests.helpers import copy_without

    path = copy_without(tiny_data, tmp_path / "no_rewards.h5", "rewards")
    with pytest.raises(DataFormatError, match="no /rewards"):
        check_planet_data(inspect_dataset(path), TINY_TRAIN)


def test_model_steps_group_env_steps() -> None:
    frames = torch.arange(7)[None, :, None, None].expand(2, 7, 3, 3)  # (B, T, H, W), frame t filled with t
    actions = torch.arange(14, dtype=torch.float32).reshape(2, 7, 1)
    rewards = torch.ones(2, 7)
    f, a, r = model_steps(frames, actions, rewards, 3)
    assert f.shape == (2, 2, 3, 3) and a.shape == (2, 2, 3) and r.shape == (2, 2)
    assert f[0, :, 0, 0].tolist() == [0, 3]  # every R-th frame; the 7th is dropped
    assert a[1, 1].tolist() == [10.0, 11.0, 12.0]  # the R actions after frame 3, in order
    assert r.tolist() == [[3.0, 3.0], [3.0, 3.0]]
    assert all(x is y for x, y in zip(model_steps(frames, actions, rewards, 1), (frames, actions, rewards)))


def test_action_repeat_holds_each_planned_action_for_r_steps(tiny_data: Path) -> None:
    from agents.planet.train import _Sequences

    torch.manual_seed(0)
    model = WorldModel(replace(TINY, action_repeat=3))
    assert model.rssm.pre_gru.in_features == TINY.stoch_size + 3
    frames, actions, rewards = _Sequences(tiny_data, "train").batch(np.random.default_rng(0), 2, 4, repeat=3)
    assert frames.shape == (2, 4, 64, 64) and actions.shape == (2, 4, 3) and rewards.shape == (2, 4)
    assert torch.isfinite(model.loss(frames, actions, rewards, TINY_TRAIN).loss)
    agent = PlanetAgent(model, TINY_CEM)
    stream = np.random.default_rng(1).integers(0, 256, (7, 1, 64, 64), dtype=np.uint8)
    acted = np.concatenate([agent.act(f) for f in stream])
    assert acted[0] == acted[1] == acted[2] and acted[3] == acted[4] == acted[5] and acted[2] != acted[3]
    assert agent.previous.tolist() == [[acted[6]] * 3]  # the next frame read follows the action held since the last
    agent.reset()
    assert np.array_equal(np.concatenate([agent.act(f) for f in stream]), acted)
    from piga.control.episodes import EpisodeConfig, run_episodes

    result = run_episodes(agent, EpisodeConfig(episodes=1, steps=7, hold_steps=1, frame_stack=1), keep_plan_ms=True)
    assert len(result.episodes[0].plan_ms) == 3  # timed where it planned: steps 0, 3 and 6


@pytest.mark.parametrize("horizon,repeat", [(1, 1), (5, 1), (5, 2)])
def test_fast_imagination_equals_the_reference(horizon: int, repeat: int) -> None:
    from agents.planet.imagine import Imagination

    torch.manual_seed(0)
    model = WorldModel(replace(TINY, action_repeat=repeat)).eval()
    imagination = Imagination(model)
    belief = Belief(torch.randn(1, TINY.deter_size), torch.randn(1, TINY.stoch_size))
    for batch in (9, 3):  # a new shape reallocates the buffers
        actions = torch.rand(batch, horizon, 1) * 4 - 2
        with torch.inference_mode():
            reference = model.imagine_return(belief, actions, torch.Generator().manual_seed(5))
        fast = imagination(belief, actions, torch.Generator().manual_seed(5))
        assert fast.shape == (batch,)
        torch.testing.assert_close(fast, reference, rtol=1e-4, atol=1e-5)


def test_latent_planner_actions_in_bounds_and_deterministic_for_a_seed() -> None:
    torch.manual_seed(0)
    model = WorldModel(TINY)
    frames = np.random.default_rng(0).integers(0, 256, (6, 1, 64, 64), dtype=np.uint8)

    def episode(seed: int) -> np.ndarray:
        agent = PlanetAgent(model, replace(TINY_CEM, seed=seed))
        agent.reset()
        return np.concatenate([agent.act(f) for f in frames])

    first, again, other = episode(0), episode(0), episode(1)
    assert first.shape == (6,) and first.dtype == np.float32
    assert np.all(np.abs(first) <= 2.0) and np.all(np.abs(other) <= 2.0)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)
    reference = PlanetAgent(model, TINY_CEM, fast=False)
    reference.reset()
    np.testing.assert_allclose(np.concatenate([reference.act(f) for f in frames]), first, atol=1e-4)


TINY_ITERATIVE = IterativeConfig(rounds=2, episodes=1, steps_per_round=2, episode_steps=36)


def _iterative(data: Path, run: Path, rounds: int, resume: bool = False) -> tuple[WorldModel, object]:
    from agents.planet.iterative import train_planet_iterative

    return train_planet_iterative(data, run, TINY_TRAIN, replace(TINY_ITERATIVE, rounds=rounds), TINY, resume=resume,
                                  progress=False, planner=TINY_CEM)


@pytest.mark.slow
def test_iterative_rounds_append_collected_episodes_and_leave_the_data_file_alone(tiny_data: Path, tmp_path: Path) -> None:
    import hashlib
    import json

    from piga.data.schema import inspect_dataset, load_rewards, read_sequences

    digest = hashlib.sha256(tiny_data.read_bytes()).hexdigest()
    _, state = _iterative(tiny_data, tmp_path / "run", rounds=1)
    after_one = inspect_dataset(tmp_path / "run" / "collected.h5")
    _, state = _iterative(tiny_data, tmp_path / "run", rounds=2, resume=True)
    assert hashlib.sha256(tiny_data.read_bytes()).hexdigest() == digest
    collected = inspect_dataset(tmp_path / "run" / "collected.h5")
    # 36 steps per episode cut into sequences of the file's 16 frames: 2 per episode, 4 left over
    assert (after_one.n_sequences, collected.n_sequences, collected.steps) == (2, 4, 16)
    assert collected.attrs["rounds"] == 2 and len(collected.attrs["episode_returns"]) == 2 and not collected.has_states
    # its env_config is the env that collected it: episodes of the round's length, not the source file's
    assert collected.attrs["env_config"]["episode_length"] == TINY_ITERATIVE.episode_steps
    assert collected.attrs["seed"] == TINY_TRAIN.seed  # the seed its rounds' episodes draw theirs from
    assert collected.attrs["effects"] == {}  # (missing, a file of gain=1.5 was scored against a true a of 1)
    frames, actions = read_sequences(tmp_path / "run" / "collected.h5", "train")
    assert frames.shape == (4, 16, 64, 64) and frames.dtype == np.uint8 and np.abs(actions).max() <= 2.0
    assert np.all(load_rewards(tmp_path / "run" / "collected.h5", "train") <= 0)
    assert state.step == TINY_TRAIN.steps + 2 * TINY_ITERATIVE.steps_per_round
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["collected_sequences"] == 4 and metrics["iterative"]["rounds"] == 2
    assert metrics["train_sequences"] == 8 + 4


@pytest.mark.slow  # two iterative runs with a planner round each; by default
# test_training_writes_a_run_and_resumes_exactly checks that a PlaNet-style run resumes exactly
def test_iterative_resume_is_exact(tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from agents.planet import iterative as planet_iterative
    from piga.data.schema import read_sequences

    straight, _ = _iterative(tiny_data, tmp_path / "a", rounds=2)
    _iterative(tiny_data, tmp_path / "b", rounds=1)  # stopped after round 1, then asked for one more
    with monkeypatch.context() as patch:  # and stopped again while collecting round 2: it is collected again, the same
        patch.setattr(planet_iterative, "collect_round", lambda *args, **kwargs: (_ for _ in ()).throw(KeyboardInterrupt))
        with pytest.raises(KeyboardInterrupt):
            _iterative(tiny_data, tmp_path / "b", rounds=2, resume=True)
    resumed, _ = _iterative(tiny_data, tmp_path / "b", rounds=2, resume=True)
    for (name, p), q in zip(straight.state_dict().items(), resumed.state_dict().values()):
        assert torch.equal(p, q), name
    for x, y in zip(read_sequences(tmp_path / "a" / "collected.h5", "train"), read_sequences(tmp_path / "b" / "collected.h5", "train")):
        assert np.array_equal(x, y)


def test_collected_rounds_must_account_for_its_sequences(tiny_data: Path, tmp_path: Path) -> None:
    """An edited ``rounds`` was trusted on --resume (round 2 was never collected); an unreadable file's reason was cut
    at 120 characters, mid-parenthesis."""
    import h5py

    from agents.planet.iterative import COLLECTED, _append, check_iterative_data, rounds_collected
    from piga.data.schema import DataFormatError, inspect_dataset, load_rewards, read_sequences

    info, path = inspect_dataset(tiny_data), tmp_path / COLLECTED
    env = check_iterative_data(info, TINY_ITERATIVE)
    frames, actions = read_sequences(tiny_data, "train")
    new = {"frames": frames[:2], "actions": actions[:2], "rewards": load_rewards(tiny_data, "train")[:2], "returns": [0.0]}
    _append(path, info, env, new, 1, "test", seed=3)
    assert inspect_dataset(path).attrs["seed"] == 3
    assert rounds_collected(tmp_path, per_round=2) == 1
    with h5py.File(path, "a") as f:
        f.attrs["rounds"] = 5
    with pytest.raises(DataFormatError, match="says it holds 5 rounds of 2 sequences, but it holds 2 sequences; the run "
                                              "cannot continue exactly: restore it, or train the run again with --overwrite"):
        rounds_collected(tmp_path, per_round=2)
    path.write_text("garbage\n")
    with pytest.raises(DataFormatError) as caught:
        rounds_collected(tmp_path, per_round=2)
    said = str(caught.value)
    assert "is needed)): restore it" in said and said.count("(") == said.count(")"), said


def test_transition_alignment_pairs_each_reward_with_the_state_its_actions_lead_to() -> None:
    config = RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, reward_alignment="transition")
    model = WorldModel(config)
    predicted, rewards = torch.arange(6.0).reshape(2, 3), -torch.arange(6.0).reshape(2, 3)  # (B, T)
    head, target = model.aligned_rewards(predicted, rewards)
    assert torch.equal(head, predicted[:, 1:]) and torch.equal(target, rewards[:, :-1])
    assert WorldModel(replace(config, reward_alignment="frame")).aligned_rewards(predicted, rewards) == (predicted, rewards)
    with pytest.raises(ValueError, match="RSSMConfig.reward_alignment must be one of 'frame', 'transition'"):
        RSSMConfig(reward_alignment="later")  # type: ignore[arg-type]
    frames = torch.randint(0, 256, (2, 5, 64, 64), dtype=torch.uint8)
    parts = model.loss(frames, torch.zeros(2, 5, 2), torch.zeros(2, 5), TINY_TRAIN, torch.Generator().manual_seed(0))
    assert torch.isfinite(parts.loss) and parts.reward >= 0


def test_observe_draws_the_noise_that_sampling_step_by_step_would() -> None:
    """observe() draws its T noise tensors before the loop (one copy to the model's device): the same numbers as
    sample() at each step, so that runs continue exactly across the change and across devices."""
    config = RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16)
    model = WorldModel(config)
    frames, actions = torch.randint(0, 256, (2, 4, 64, 64), dtype=torch.uint8), torch.randn(2, 4, 2)
    h, s, _, _ = model.observe(frames, actions, torch.Generator().manual_seed(7))
    generator, embeds = torch.Generator().manual_seed(7), model.embed(frames)
    belief, previous, expected = model.rssm.initial(2), torch.zeros(2, 2), []
    for step in range(4):
        hidden, _ = model.rssm.transition(belief, previous)
        belief, previous = Belief(hidden, sample(model.rssm.posterior(hidden, embeds[:, step]), generator)), actions[:, step]
        expected.append(belief.s)
    assert torch.equal(s, torch.stack(expected, 1))


def test_the_reward_head_has_the_layers_and_width_asked_for() -> None:
    def widths(config: RSSMConfig) -> list[tuple[int, int]]:
        return [(m.in_features, m.out_features) for m in WorldModel(config).reward_head if isinstance(m, torch.nn.Linear)]

    small = RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=8)
    assert widths(small) == [(20, 8), (8, 8), (8, 1)]  # the default: 2 hidden layers of hidden_size
    assert widths(replace(small, reward_layers=3, reward_units=12)) == [(20, 12), (12, 12), (12, 12), (12, 1)]
    with pytest.raises(ValueError, match="reward_units must be >= 0"):
        replace(small, reward_units=-1)
    with pytest.raises(ValueError, match="reward_layers must be >= 1"):
        replace(small, reward_layers=0)


@pytest.mark.slow
def test_the_checkpoint_keeps_the_weights_of_the_lowest_valid_loss(tiny_data: Path, tmp_path: Path) -> None:
    """Each checkpoint measures the valid split's loss; the lowest one's weights are kept (resumed exactly) and
    write_selected makes them a run of their own: the weights a run stopped at that step has."""
    import json

    from agents.planet.run import load_planet, write_selected
    from agents.planet.train import train_planet

    config = replace(TINY_TRAIN, steps=6, checkpoint_every=1, lr=3e-2)  # a high rate: the valid loss moves about
    _, state = train_planet(tiny_data, tmp_path / "run", config, TINY, progress=False)
    losses = [r["valid_loss"] for r in state.history]
    assert len(losses) == 6 and state.best_valid_loss == min(losses)
    assert state.best_step == 1 + losses.index(min(losses))
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["best_valid"] == {"step": state.best_step, "loss": state.best_valid_loss}
    train_planet(tiny_data, tmp_path / "half", replace(config, steps=3), TINY, progress=False)
    _, resumed = train_planet(tiny_data, tmp_path / "half", config, resume=True, progress=False)
    assert (resumed.best_step, resumed.best_valid_loss) == (state.best_step, state.best_valid_loss)
    assert write_selected(tmp_path / "half", tmp_path / "selected") == {"step": state.best_step, "loss": state.best_valid_loss}
    train_planet(tiny_data, tmp_path / "stopped", replace(config, steps=state.best_step), TINY, progress=False)
    for (name, p), q in zip(load_planet(tmp_path / "stopped")[0].state_dict().items(),
                            load_planet(tmp_path / "selected")[0].state_dict().values()):
        assert torch.equal(p, q), name
    assert load_planet(tmp_path / "selected")[1]["state"]["step"] == state.best_step


def test_no_model_is_selected_without_a_valid_loss(tiny_data: Path, tmp_path: Path) -> None:
    from agents.planet.run import write_selected
    from agents.planet.train import train_planet
    from piga.io.checkpoint import CHECKPOINT

    train_planet(tiny_data, tmp_path / "run", replace(TINY_TRAIN, steps=2), TINY, progress=False)
    ckpt = torch.load(tmp_path / "run" / CHECKPOINT, weights_only=False)
    ckpt["best_model"], ckpt["state"]["best_step"] = None, 0  # as a run trained before the valid loss was measured
    torch.save(ckpt, tmp_path / "run" / CHECKPOINT)
    with pytest.raises(ValueError, match="no valid loss was measured during training"):
        write_selected(tmp_path / "run", tmp_path / "selected")


def test_a_world_model_that_beats_neither_blind_guess_did_not_learn() -> None:
    """The end-of-run check of ``piga-baseline planet``: the filtered frames' reconstructions against the mean frame,
    the rewards against 0 (skipped when every reward is 0); the open-loop steps after the context do not count."""
    from agents.planet.train import did_not_learn

    trained = {"context": 2, "frame_mse": [0.001, 0.001, 0.05], "mean_frame_mse": [0.01, 0.01, 0.01],
               "reward_abs_error": [0.2, 0.3], "zero_reward_abs_error": [5.0, 5.0]}
    assert did_not_learn(trained) is None
    blind = {**trained, "frame_mse": [0.0095, 0.0092, 0.001]}  # 0.935 of the mean frame's over the context
    assert "no better than the average frame (MSE 0.01)" in did_not_learn(blind)
    rewards = {**trained, "reward_abs_error": [4.6, 4.6]}
    assert "no better than predicting 0 (mean error 5)" in did_not_learn(rewards)
    assert did_not_learn({**rewards, "zero_reward_abs_error": [0.0, 0.0]}) is None  # no reward to learn
