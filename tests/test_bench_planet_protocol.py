"""benchmarks/planet_protocol.py: PlaNet's data protocol at the table's env steps and optimiser steps, scored like the
table's runs and set beside them; a rerun reuses the records. Training and episodes are stand-ins."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def protocol():
    with benchmark_module("planet_protocol") as module:
        yield module


def test_the_plan_matches_the_tables_env_steps_and_optimiser_steps(protocol: Any) -> None:
    cfg = protocol.PRESETS["budget"]
    for n, rounds, per_round in ((100, 15, 733), (250, 45, 244), (500, 95, 115)):
        plan = protocol.plan_for(n, cfg, 25, 1000)
        assert (plan.rounds, plan.round_steps) == (rounds, per_round)
        assert 25 * cfg.steps + plan.rounds * cfg.episode_steps == n * cfg.steps  # the table's env steps
        assert plan.total_steps == cfg.planet_steps and plan.first_steps >= 1000  # and its optimiser steps
    with pytest.raises(ValueError, match="not a positive whole number of 200-step episodes"):
        protocol.plan_for(100, cfg, 24, 1000)  # 76 x 40 env steps: 15.2 episodes
    with pytest.raises(ValueError, match="leave none for 15 rounds"):
        protocol.plan_for(100, cfg, 25, 11990)


def test_each_budget_runs_once_and_sits_beside_the_tables_runs(protocol: Any, tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "runs"
    (runs / "records").mkdir(parents=True)
    summary = {"episodes": 20, "success_rate": 0.75, "mean_return": -356.5}
    (runs / "records" / "planet-n250-s0.json").write_text(json.dumps(
        {"spec": {"seed": 0}, "control": summary, "sweep": {"1.4": {**summary, "success_rate": 0.0}}, "train_seconds": 6000}))
    calls: list[tuple] = []

    def train(job):
        calls.append(("train", job.name, job.plan.rounds, job.plan.round_steps, job.seed))
        run = job.folder / job.name
        run.mkdir(parents=True)
        (run / "metrics.json").write_text(json.dumps({"steps": 12000, "iterative": {"rounds": job.plan.rounds}}))
        return 7200.0

    def evaluate(kind, run, cfg, gravity_mult=1.0, episodes=None, **job):
        calls.append(("eval", kind, run.name, gravity_mult, episodes))
        return {"episodes": episodes or 20, "success_rate": 0.9 if gravity_mult == 1.0 else 0.2, "mean_return": -190.0}

    monkeypatch.setattr(protocol, "train", train)
    monkeypatch.setattr(sys.modules[protocol.planet_scores.__module__], "evaluate", evaluate)  # the table's scoring
    out = tmp_path / "protocol"
    args = ["--runs", str(runs), "--out", str(out), "--sequences", "250"]
    assert protocol.main(args) == 0
    assert calls == [("train", "protocol-n250-s0", 45, 244, 0), ("eval", "planet", "protocol-n250-s0", 1.0, None),
                     ("eval", "planet", "protocol-n250-s0", 1.4, 5)]
    assert "1 of 1 job(s) to run, about" in capsys.readouterr().out
    page = out.with_suffix(".md").read_text()
    assert "| 10,000 (250) | random actions (the table's planet-n250-s0) | 0 | - | 75% (20) | -356.5 | 0% | 100 |" in page
    assert "| 10,000 (250) | PlaNet's protocol (protocol-n250-s0) | 0 | 45 x 244 (+1020 first) | 90% (20) | -190.0 | 20% | 120 |" in page
    calls.clear()
    assert protocol.main(args) == 0 and calls == []  # the record is kept
    assert "0 of 1 job(s) to run" in capsys.readouterr().out
    assert protocol.main([*args, "--workers", "2"]) == 0 and calls == []  # workers play the same episodes: kept too


def test_workers_play_the_scored_episodes(protocol: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[int] = []

    def train(job):
        run = job.folder / job.name
        run.mkdir(parents=True)
        (run / "metrics.json").write_text(json.dumps({"steps": 12000, "iterative": {"rounds": job.plan.rounds}}))
        return 1.0

    def evaluate(kind, run, cfg, gravity_mult=1.0, episodes=None, workers=1, **job):
        seen.append(workers)
        return {"episodes": episodes or 20, "success_rate": 1.0, "mean_return": -150.0}

    monkeypatch.setattr(protocol, "train", train)
    monkeypatch.setattr(sys.modules[protocol.planet_scores.__module__], "evaluate", evaluate)
    (tmp_path / "runs" / "records").mkdir(parents=True)
    args = ["--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "protocol"), "--sequences", "100", "--workers", "2"]
    assert protocol.main(args) == 0 and seen == [2, 2]


def test_a_budget_the_table_does_not_have_is_refused(protocol: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        protocol.main(["--sequences", "300", "--out", str(tmp_path / "x")])
    assert "--sequences 300: the budget preset's PlaNet-style sizes are 100, 250, 500, 1000, 2000" in capsys.readouterr().err


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_a_tiny_protocol_run_collects_its_rounds_and_continues(protocol: Any, tmp_path: Path) -> None:
    """The real loop on the tiny preset: the table's first sequences seed it, each round adds a planner episode, and
    a rerun of a finished run trains nothing more."""
    cfg = protocol.PRESETS["tiny"]
    (tmp_path / "runs").mkdir()
    plan = protocol.Plan(sequences=16, seed_sequences=11, rounds=2, first_steps=1, round_steps=1)
    job = protocol.Job("protocol-n16-s0", plan, 0, cfg, tmp_path / "out", tmp_path / "runs")
    protocol.train(job)
    metrics = json.loads((tmp_path / "out" / job.name / "metrics.json").read_text())
    assert metrics["steps"] == 3 and metrics["iterative"]["rounds"] == 2
    assert metrics["iterative"]["collected_sequences"] == 2  # one 16-frame sequence from each 20-step episode
    assert (tmp_path / "runs" / "data-n11.h5").exists()
    stamp = (tmp_path / "out" / job.name / "checkpoint.pt").stat().st_mtime_ns
    protocol.train(job)
    assert (tmp_path / "out" / job.name / "checkpoint.pt").stat().st_mtime_ns == stamp
