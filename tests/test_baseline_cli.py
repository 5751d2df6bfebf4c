"""``piga-baseline`` as a user runs it (bad input: one line), and ``piga-control`` on baseline runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from piga.cli import baseline, control
from tests.helpers import assert_one_line, assert_planet_run_finished, assert_sb3_run_finished, copy_without, run_in_process

TINY_PLANET = ("--steps", "2", "--batch-size", "2", "--chunk-length", "8", "--deter-size", "8", "--stoch-size", "4",
               "--hidden-size", "8", "--depth", "4", "--reward-layers", "1", "--reward-units", "6", "--threads", "1", "--quiet")
TINY_DDPG = ("--steps", "200", "--eval-every", "200", "--eval-episodes", "1", "--learning-starts", "100", "--quiet",
             "--learning-rate", "0.0005", "--batch-size", "32", "--noise-std", "0.3")


@pytest.fixture(scope="module")
def planet_run(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("planet") / "run"
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(out), *TINY_PLANET,
                                  capsys=_NoCapture())
    assert code in (0, 1) and (out / "metrics.json").exists()  # 1: a 2-step run did not learn; its outputs stay
    return out


class _NoCapture:
    """run_in_process for a module fixture, where capsys is not available."""

    def readouterr(self) -> tuple[str, str]:
        return "", ""


@pytest.fixture(scope="module")
def ddpg_result(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, str, str]:
    """A tiny DDPG run from the state: (run folder, exit code, stdout, stderr). 200 steps cannot learn the swing-up."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("ddpg") / "run"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code, _, _ = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(out), *TINY_DDPG,
                                    capsys=_NoCapture())
    assert_sb3_run_finished(code, stderr.getvalue())
    return out, code, stdout.getvalue(), stderr.getvalue()


@pytest.fixture(scope="module")
def ddpg_run(ddpg_result: tuple[Path, int, str, str]) -> Path:
    return ddpg_result[0]


def test_a_ddpg_run_that_never_learned_says_so_and_keeps_its_outputs(ddpg_result: tuple[Path, int, str, str]) -> None:
    """Exit 1 and one line, not an exit 0 that a script would take for success; the summary, checkpoint and
    records stay (--resume continues such a run: tests/test_device.py)."""
    from agents.sb3.run import load_sb3

    run, code, stdout, err = ddpg_result
    assert stdout.splitlines()[-1].endswith(f"never reached -200; wrote {run}/metrics.json")
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["first_step_reaching_minus_200"] is None and metrics["steps"] == 200
    assert_one_line(code, err, "piga-baseline: error: the run did not learn: its evaluation return never reached -200 in "
                    f"200 env steps (final {metrics['final_eval_mean_return']:.1f}); its outputs are in {run}")
    assert code == 1
    record = json.loads((run / "config.json").read_text())
    from piga.io.pool import git_commit

    assert record["kind"] == "ddpg" and record["commit"] == git_commit()  # the code that trained it
    assert load_sb3(run)[1].steps == 200


def test_a_ddpg_run_that_learned_exits_0(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.sb3.train as sb3_train

    def learned(config: Any, run_dir: Path, *args: Any, **kwargs: Any) -> dict[str, Any]:
        return {"steps": 400, "train_seconds": 6.0, "final_eval_mean_return": -150.0,
                "learning_curve": [{"step": 200, "eval_mean_return": -900.0}, {"step": 400, "eval_mean_return": -150.0}]}

    monkeypatch.setattr(sb3_train, "train_sb3", learned)
    code, stdout, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out",
                                       str(tmp_path / "run"), *TINY_DDPG, capsys=capsys)
    assert code == 0 and err == ""
    assert "final evaluation mean return -150.0; first reached -200 at step 400" in stdout


def test_ddpg_tuning_options_reach_the_run(ddpg_run: Path) -> None:
    from agents.sb3.run import load_sb3

    saved = json.loads((ddpg_run / "config.json").read_text())["ddpg"]
    assert (saved["learning_rate"], saved["batch_size"], saved["noise_std"]) == (0.0005, 32, 0.3)
    model, config, _ = load_sb3(ddpg_run)
    assert (model.batch_size, model.learning_rate, config.noise_std) == (32, 0.0005, 0.3)
    assert np.allclose(model.action_noise._sigma, 0.3)


def test_sac_takes_its_own_presets_and_resumes_only_as_sac(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from stable_baselines3 import SAC

    from agents.sb3.config import ALGORITHM_PRESETS
    from agents.sb3.run import load_sb3

    out = tmp_path / "sac"
    code, stdout, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--algo", "sac", "--obs", "state", "--out", str(out),
                                       "--steps", "200", "--eval-every", "200", "--eval-episodes", "1", "--batch-size", "16",
                                       "--learning-starts", "150", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert "training SAC from state" in stdout
    model, config, _ = load_sb3(out)
    assert isinstance(model, SAC) and model.action_noise is None  # SAC explores with its own policy
    sac = ALGORITHM_PRESETS["sac"]
    assert (config.algo, config.gamma, config.buffer_size, config.net_arch) == ("sac", sac["gamma"], sac["buffer_size"], sac["net_arch"])
    assert (config.learning_starts, model.learning_starts) == (150, 150)  # a given option overrides the preset
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(out), "--resume",
                                  "--steps", "400", "--algo", "ddpg", capsys=capsys)
    assert_one_line(code, err, "was trained with --algo sac, not ddpg")
    # without --algo, the run's own (its default, ddpg, was refused as "trained with --algo sac, not ddpg")
    code, stdout, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(out),
                                       "--resume", "--steps", "400", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert load_sb3(out)[1].algo == "sac"


def test_planet_resume_reads_the_model_config_from_the_checkpoint(planet_run: Path, tiny_data: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A run whose config.json has no "rssm" (older benchmark runs) resumes from its checkpoint's."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(planet_run, run)
    record = json.loads((run / "config.json").read_text())
    del record["rssm"]
    (run / "config.json").write_text(json.dumps(record))
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((run / "config.json").read_text())["rssm"]["deter_size"] == 8
    assert json.loads((run / "metrics.json").read_text())["steps"] == 3


def test_planet_resume_without_its_record_rebuilds_it_from_the_checkpoint_exactly(
        planet_run: Path, tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With config.json deleted, --resume was refused ("start it again with --overwrite"), throwing the checkpoint
    away; piga-train-model rebuilds its record from the checkpoint. The run continues as the one with its record."""
    import shutil

    import torch

    from agents.planet.run import load_planet

    runs = {name: tmp_path / name for name in ("kept", "lost")}
    for name, run in runs.items():
        shutil.copytree(planet_run, run)
        if name == "lost":
            (run / "config.json").unlink()
        code, out, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run),
                                        "--resume", "--steps", "3", "--quiet", capsys=capsys)
        assert_planet_run_finished(code, err)
        assert ("config.json is missing; the resumed run rewrites it from the checkpoint" in out) == (name == "lost"), out
    kept, lost = (load_planet(runs[name])[0].state_dict() for name in ("kept", "lost"))
    assert all(torch.equal(kept[key], lost[key]) for key in kept)
    record = json.loads((runs["lost"] / "config.json").read_text())
    assert record["command"] is None and record["kind"] == "planet" and record["train"]["steps"] == 3
    assert record["rssm"]["deter_size"] == 8 and len(record["resumed"]) == 1


@pytest.mark.slow
def test_ddpg_resume_without_its_record_rebuilds_it_from_the_checkpoint(ddpg_run: Path, tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    run = tmp_path / "run"
    shutil.copytree(ddpg_run, run)
    recorded = json.loads((run / "config.json").read_text())["ddpg"]
    (run / "config.json").unlink()
    code, out, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(run),
                                    "--resume", "--steps", "400", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert "config.json is missing; the resumed run rewrites it from the checkpoint" in out, out
    record = json.loads((run / "config.json").read_text())
    assert record["command"] is None and record["kind"] == "ddpg"
    assert record["ddpg"] == {**recorded, "steps": 400, "device": record["ddpg"]["device"]}


def test_an_iterative_planet_run_without_its_record_says_what_the_checkpoint_lacks(
        planet_run: Path, tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    run = tmp_path / "run"
    shutil.copytree(planet_run, run)
    (run / "config.json").unlink()
    (run / "collected.h5").write_bytes(b"")  # the rounds' episodes: an --iterative run
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--rounds", "2", "--quiet", capsys=capsys)
    assert_one_line(code, err, "config.json is missing, and the checkpoint does not hold the --iterative settings",
                    "restore config.json, or start the run again with --overwrite")
    assert not (run / "config.json").exists()


def test_planet_reward_options_reach_the_run_and_resume_keeps_them(tiny_data: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), *TINY_PLANET,
                                  "--reward-alignment", "transition", "--reward-scale", "10", capsys=capsys)
    assert_planet_run_finished(code, err)
    record = json.loads((run / "config.json").read_text())
    assert record["rssm"]["reward_alignment"] == "transition" and record["train"]["reward_scale"] == 10
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--reward-scale", "5", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume keeps the run's recipe; drop --reward-scale")
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--reward-alignment=frame", "--quiet", capsys=capsys)  # the default's value, given: refused too
    assert_one_line(code, err, "--resume keeps the run's recipe; drop --reward-alignment")
    # the starting command's own values may be repeated: that command plus --resume (and more steps) continues the run
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--steps", "3",
                                  *TINY_PLANET[2:], "--reward-alignment", "transition", "--reward-scale", "10", "--resume",
                                  capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((run / "metrics.json").read_text())["steps"] == 3


@pytest.mark.parametrize("args, needle", [
    (("planet", "missing.h5", "--out", "r"), "no such file"),
    (("ddpg", "--obs", "state", "--algo", "td3", "--out", "r"), "--algo: invalid choice: 'td3'"),
    (("ddpg", "--obs", "state", "--steps", "0", "--out", "r"), "--steps: expected a positive integer, got 0"),
    (("ddpg", "--obs", "eyes", "--out", "r"), "--obs: invalid choice: 'eyes'"),
    (("ddpg", "--obs", "latent", "--out", "r"), "give --data"),
    (("ddpg", "--obs", "state", "--eval-every", "300", "--out", "r"), "multiple of the episode length 200"),
    (("ddpg", "--obs", "state", "--out", "r", "--resume"), "does not exist"),
])
def test_bad_input_gets_one_line(args: tuple[str, ...], needle: str, capsys: pytest.CaptureFixture[str],
                                 tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = run_in_process("piga-baseline", baseline.main, *args, capsys=capsys)
    assert_one_line(code, err, needle)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("imported", [False, True])
def test_a_file_without_rewards_gets_one_line(imported: bool, tiny_data: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """An imported recording was told that "files from piga-collect have them": no advice for a recording."""
    import h5py

    path = copy_without(tiny_data, tmp_path / "old.h5", "rewards")
    if imported:
        with h5py.File(path, "r+") as f:
            f.attrs["source_frames"] = 100
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(path), "--out", str(tmp_path / "r"),
                                  *TINY_PLANET, capsys=capsys)
    assert_one_line(code, err, "has no /rewards, as no imported recording has; the PlaNet-style model learns a reward "
                    "head from the env's rewards" if imported else "has no /rewards; the PlaNet-style model learns a "
                    "reward head (collect the data with piga-collect, which writes them)")
    assert not (tmp_path / "r").exists()
    from piga.data.schema import DataFormatError, load_rewards

    with pytest.raises(DataFormatError, match="as no imported recording has" if imported else "files from piga-collect"):
        load_rewards(path, "train")  # (piga's learned-reward ablation reads them here)


def test_planet_on_a_file_without_a_valid_split_says_what_it_checks_on(tiny_data: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Its open-loop check read the train split without a word (piga-train-model warns of a missing test split)."""
    import shutil

    import h5py

    path = Path(shutil.copy(tiny_data, tmp_path / "train_only.h5"))
    with h5py.File(path, "a") as f:
        f["split"][...] = 0
        if "split_counts" in f.attrs:
            del f.attrs["split_counts"]
    code, out, err = run_in_process("piga-baseline", baseline.main, "planet", str(path), "--out", str(tmp_path / "r"),
                                    *TINY_PLANET, capsys=capsys)
    assert code in (0, 1) and len(err.splitlines()) <= 1, err  # 1: a 2-step run did not learn, said in one line
    assert ("no valid sequences, so no valid loss is measured, and the open-loop check (metrics.json, "
            "openloop.png) reads the train split, which is not held out") in out
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["open_loop"]["split"] == "train"


def test_an_action_repeat_longer_than_the_sequences_gets_one_line(tiny_data: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(tmp_path / "r"),
                                  *TINY_PLANET, "--action-repeat", "3", capsys=capsys)  # 8 model steps x 3 > 16 frames
    assert_one_line(code, err, "x action repeat 3")
    assert not (tmp_path / "r").exists()


def test_planet_run_records_its_kind_and_refuses_to_be_overwritten(planet_run: Path, tiny_data: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    record = json.loads((planet_run / "config.json").read_text())
    assert record["kind"] == "planet" and record["rssm"]["deter_size"] == 8
    assert [record["rssm"][k] for k in ("hidden_size", "depth", "reward_layers", "reward_units")] == [8, 4, 1, 6]
    metrics = json.loads((planet_run / "metrics.json").read_text())
    assert metrics["steps"] == 2 and len(metrics["learning_curve"]) == 1
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(planet_run),
                                  *TINY_PLANET, capsys=capsys)
    assert_one_line(code, err, "already holds a run", "--resume", "--overwrite")
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(planet_run),
                                  "--resume", capsys=capsys)
    assert_one_line(code, err, "is a planet run, not a ddpg run")


def test_piga_control_runs_a_ddpg_run_as_trained(ddpg_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "eval"
    code, stdout, err = run_in_process("piga-control", control.main, "--model", str(ddpg_run), "--episodes", "2",
                                       "--steps", "20", "--gravity-mult", "1.4", "--quiet", "--out", str(out), capsys=capsys)
    assert code == 0, err
    lines = stdout.splitlines()
    assert lines[0] == "note: the ddpg agent runs as trained: it cannot be told that gravity changed"
    assert lines[1].startswith(f"ddpg ({ddpg_run}), gravity x1.4")
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["kind"] == "ddpg" and result["summary"]["episodes"] == 2 and result["summary"]["gravity_mult"] == 1.4


@pytest.mark.parametrize("option, needle", [
    (("--goal-image", "goal.png"), "cannot be given a goal image"),
    (("--goal-angle", "30"), "has no goal input"),
    (("--video", "v.avi"), ".mp4 or .gif"),
])
def test_piga_control_refuses_goals_for_baselines(planet_run: Path, option: tuple[str, ...], needle: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process("piga-control", control.main, "--model", str(planet_run), *option, capsys=capsys)
    assert_one_line(code, err, needle)


@pytest.mark.parametrize("kind, workers, panels", [("planet", "2", 2), ("ddpg", "1", 1)])
@pytest.mark.slow
def test_piga_control_writes_a_baseline_video(planet_run: Path, ddpg_run: Path, tmp_path: Path, kind: str, workers: str,
                                              panels: int, capsys: pytest.CaptureFixture[str]) -> None:
    """Episode 0 as real frames (| the PlaNet-style model's reconstruction), also when workers ran the episodes."""
    import imageio.v3 as iio

    video = tmp_path / "episode.mp4"  # (a GIF writer may merge identical frames)
    run = planet_run if kind == "planet" else ddpg_run
    args = ("--model", str(run), "--episodes", "2", "--steps", "20", "--workers", workers, "--quiet", "--video", str(video))
    code, stdout, err = run_in_process("piga-control", control.main, *args, capsys=capsys)
    assert code == 0, err
    assert f"wrote {video}" in stdout
    frames = iio.imread(video)  # (T, H, W, 3): the panels side by side, 4x upscaled
    assert frames.shape[0] == 20 and frames.shape[1:3] == (256, 256 * panels)
    code, _, err = run_in_process("piga-control", control.main, *args, capsys=capsys)
    assert_one_line(code, err, "--overwrite")


def test_control_jobs_dispatch_on_the_run_kind(planet_run: Path, ddpg_run: Path) -> None:
    from agents.planet.planner import PlanetAgent
    from agents.sb3.run import SB3Agent
    from piga.control.episodes import EpisodeConfig
    from piga.control.jobs import ControlJob, build_agent, run_job
    from piga.io.checkpoint import RunKind, run_kind

    assert (run_kind(planet_run), run_kind(ddpg_run)) == (RunKind.PLANET, RunKind.DDPG)
    episodes = EpisodeConfig(episodes=1, steps=2, hold_steps=1)
    assert isinstance(build_agent(ControlJob("planet", episodes, model_dir=str(planet_run))), PlanetAgent)
    assert isinstance(build_agent(ControlJob("ddpg", episodes, model_dir=str(ddpg_run))), SB3Agent)
    result = run_job(ControlJob("planet", episodes, model_dir=str(planet_run)))
    assert result.summary.labels["agent"] == "planet" and np.isfinite(result.summary.mean_return)
    with pytest.raises(ValueError, match="needs model_dir"):
        ControlJob("ddpg", episodes)


def test_episodes_split_over_workers_are_the_episodes_of_one_process(planet_run: Path) -> None:
    from piga.control.episodes import EpisodeConfig
    from piga.control.jobs import ControlJob, run_job, run_split, split_job

    job = ControlJob("planet", EpisodeConfig(episodes=3, steps=4, hold_steps=1, seed=2, frame_stack=1), model_dir=str(planet_run))
    assert [(j.episodes.first_episode, j.episodes.episodes) for j in split_job(job, 2)] == [(0, 2), (2, 1)]
    one, split = run_job(job), run_split(job, workers=2, progress=False)
    timing = ("plan_ms_median", "plan_ms_p95")
    assert [{k: v for k, v in e.to_dict().items() if k not in timing} for e in split.episodes] == \
           [{k: v for k, v in e.to_dict().items() if k not in timing} for e in one.episodes]
    assert {k: v for k, v in split.summary.to_dict().items() if k not in timing} == \
           {k: v for k, v in one.summary.to_dict().items() if k not in timing}
    assert len({e.return_ for e in one.episodes}) == 3  # three different episodes, not one thrice


@pytest.mark.slow
def test_planet_iterative_from_the_command_line(tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(out), *TINY_PLANET,
                                       "--iterative", "1", "--rounds", "1", "--round-steps", "2", "--episode-steps", "16",
                                       capsys=capsys)
    assert_planet_run_finished(code, err)
    assert "then 1 round of 1 planner episode + 2 steps" in stdout
    record = json.loads((out / "config.json").read_text())
    assert record["iterative"]["episodes"] == 1 and record["iterative"]["noise"] == 0.3
    assert json.loads((out / "metrics.json").read_text())["iterative"]["collected_sequences"] == 1
    code, stdout, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(out), "--resume",
                                       "--rounds", "2", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((out / "metrics.json").read_text())["iterative"]["rounds"] == 2


@pytest.mark.parametrize("option, needle", [
    (("--rounds", "2"), "--rounds goes with --iterative"),
    (("--round-steps", "100"), "--round-steps goes with --iterative"),  # the default's value, written: still ignored
    (("--exploration-noise=0.3",), "--exploration-noise goes with --iterative"),
    (("--iterative", "0", "--episode-steps", "200"), "--episode-steps goes with --iterative"),
    (("--iterative", "1", "--exploration-noise", "-1"), "--exploration-noise: expected a number in [0, 10], got -1"),
    (("--iterative", "1", "--exploration-noise", "1e300"), "--exploration-noise: expected a number in [0, 10]"),
    (("--iterative", "1", "--exploration-noise", "nan"), "--exploration-noise: expected a number in [0, 10]"),
    (("--iterative", "1", "--episode-steps", "8"), "--episode-steps must be at least the sequence length"),
    (("--iterative", "1", "--max-minutes", "5"), "bound the run with --rounds"),
])
def test_planet_iterative_bad_input_gets_one_line(tiny_data: Path, tmp_path: Path, option: tuple[str, ...], needle: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(tmp_path / "r"),
                                  *TINY_PLANET, *option, capsys=capsys)
    assert_one_line(code, err, needle)
    assert not (tmp_path / "r").exists()
