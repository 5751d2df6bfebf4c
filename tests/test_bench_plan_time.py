"""benchmarks/plan_time.py with ``--planet``: piga and the PlaNet-style agent timed in one run, and their ratio per env step."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from agents.planet.config import PlanetTrainConfig, RSSMConfig
from agents.planet.train import train_planet

from .helpers import benchmark_module, run, train_tiny

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_plan_time_times_the_planet_agent_in_the_same_run(tiny_data: Path, tiny_run: Path, tmp_path: Path) -> None:
    piga_run = tiny_run  # read, not written
    planet_run = tmp_path / "planet"
    train_planet(tiny_data, planet_run, PlanetTrainConfig(steps=2, batch_size=4, chunk_length=8, checkpoint_every=2, threads=1),
                 RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=2), progress=False)
    out = tmp_path / "plan_time"
    result = run("python", str(ROOT / "benchmarks" / "plan_time.py"), "--model", str(piga_run), "--planet", str(planet_run),
                 "--equal-budget", "--no-reference", "--episodes", "1", "--steps", "20", "--out", str(out))
    assert result.returncode == 0, result.stderr
    record = json.loads(out.with_suffix(".json").read_text())
    rows = {row["agent"]: row for row in record["rows"]}
    planet = rows["PlaNet-style (latent CEM, PlaNet's settings)"]
    assert planet["env_steps_per_plan"] == 2 and rows["piga"]["env_steps_per_plan"] == 1
    equal = rows["PlaNet-style (latent CEM, piga's budget)"]
    assert (equal["cem"]["candidates"], equal["cem"]["horizon"], equal["cem"]["iterations"]) == (800, 10, 5)
    assert equal["model_steps"] / 2 == rows["piga"]["model_steps"] == 20_000 and planet["model_steps"] == 120_000
    ratio = record["planet_ratio"]
    for key, row in (("own", planet), ("equal", equal)):
        assert ratio[key]["planet_ms_per_step"] == row["plan_ms_median"] / 2
        assert ratio[key]["ratio_per_step"] == ratio[key]["planet_ms_per_step"] / rows["piga"]["plan_ms_median"] > 0
    assert ratio["ratio_per_step"] == ratio["own"]["ratio_per_step"]
    page = out.with_suffix(".md").read_text()
    assert "reference rows" not in page and "| 800 x 10 x 5, top 80 | 2 | 20,000 |" in page
    assert all(f"{ratio[key]['ratio_per_step']:.0f}x faster" in page for key in ("own", "equal"))
    assert len(record["load_average"]["before"]) == 3


@pytest.fixture
def plan_time():
    with benchmark_module("plan_time") as module:
        yield module


def test_equal_budget_cem_matches_model_steps_per_env_step(plan_time) -> None:
    from agents.config import CEMConfig

    equal_budget_cem, model_steps = plan_time.equal_budget_cem, plan_time.model_steps
    piga = CEMConfig(horizon=20, iterations=5, candidates=200, elites=20)
    for repeat in (1, 2, 4):
        cem = equal_budget_cem(piga, repeat)
        assert model_steps(cem) == repeat * model_steps(piga) and cem.horizon * repeat == 20
        assert cem.elites / cem.candidates == 0.1 and cem.init_std == CEMConfig().init_std
    assert equal_budget_cem(CEMConfig(horizon=5, iterations=2, candidates=10, elites=3), 2).horizon == 3  # lookahead rounded up


@pytest.mark.slow  # a git worktree and four benchmark processes: about 25 s
def test_plan_time_at_two_revisions_alternates_and_gives_ratios(tiny_data: Path, tmp_path: Path) -> None:
    """benchmarks/plan_time_revisions.py: the baseline in a temporary worktree (removed after), both revisions
    timed in turn, each agent's ratio of medians."""
    piga_run = train_tiny(tiny_data, tmp_path / "piga")
    out = tmp_path / "revisions"
    result = run("python", str(ROOT / "benchmarks" / "plan_time_revisions.py"), "--baseline", "HEAD", "--model",
                 str(piga_run), "--pairs", "1", "--episodes", "1", "--steps", "20", "--out", str(out))
    assert result.returncode == 0, result.stderr
    record = json.loads(out.with_suffix(".json").read_text())
    for agent in ("oracle", "piga"):
        s = record["summary"][agent]
        assert len(s["baseline_ms"]) == len(s["current_ms"]) == 1
        assert s["ratio"] == s["current_median_ms"] / s["baseline_median_ms"] > 0
    assert "piga-revisions-" not in subprocess.run(["git", "-C", str(ROOT), "worktree", "list"], capture_output=True,
                                                    text=True).stdout
    bad = run("python", str(ROOT / "benchmarks" / "plan_time_revisions.py"), "--baseline", "no-such-rev", "--model",
              str(piga_run), "--out", str(out))
    assert bad.returncode != 0 and "not a revision" in bad.stderr


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_the_planet_plan_time_benchmark_times_both_engines_and_checks_their_actions(tmp_path: Path) -> None:
    out = tmp_path / "planet_plan_time"
    result = run("python", str(ROOT / "benchmarks" / "planet_plan_time.py"), "--steps", "2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    (row,) = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert row["device"] == "cpu" and row["plans"] == 1 and row["same_actions"] and row["fast_ms"] > 0
