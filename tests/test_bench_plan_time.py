"""benchmarks/plan_time.py with ``--planet``: piga and the PlaNet-style agent timed in one run, and their ratio per env step."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from agents.planet.config import PlanetTrainConfig, RSSMConfig
from agents.planet.train import train_planet

from .helpers import run, train_tiny

ROOT = Path(__file__).resolve().parents[1]


def test_plan_time_times_the_planet_agent_in_the_same_run(tiny_data: Path, tmp_path: Path) -> None:
    piga_run = train_tiny(tiny_data, tmp_path / "piga")
    planet_run = tmp_path / "planet"
    train_planet(tiny_data, planet_run, PlanetTrainConfig(steps=2, batch_size=4, chunk_length=8, checkpoint_every=2, threads=1),
                 RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=2), progress=False)
    out = tmp_path / "plan_time"
    result = run("python", str(ROOT / "benchmarks" / "plan_time.py"), "--model", str(piga_run), "--planet", str(planet_run),
                 "--no-reference", "--episodes", "1", "--steps", "20", "--out", str(out))
    assert result.returncode == 0, result.stderr
    record = json.loads(out.with_suffix(".json").read_text())
    rows = {row["agent"]: row for row in record["rows"]}
    planet = rows["PlaNet-style (latent CEM, PlaNet's settings)"]
    assert planet["env_steps_per_plan"] == 2 and rows["piga"]["env_steps_per_plan"] == 1
    ratio = record["planet_ratio"]
    assert ratio["planet_ms_per_step"] == planet["plan_ms_median"] / 2
    assert ratio["ratio_per_step"] == ratio["planet_ms_per_step"] / rows["piga"]["plan_ms_median"] > 0
    page = out.with_suffix(".md").read_text()
    assert "PlaNet-style" in page and f"{ratio['ratio_per_step']:.0f}x faster" in page and "reference rows" not in page
    assert len(record["load_average"]["before"]) == 3


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
