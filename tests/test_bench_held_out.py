"""benchmarks/held_out.py: the runs on this machine scored on the held-out episodes' seed beside their records' seed-0
numbers, the runs not here listed, a rerun that reuses the records. The evaluation is a stand-in with known scores."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def held_out():
    with benchmark_module("held_out") as module:
        yield module


def _summary(agent: str, success: float, episodes: int = 20) -> dict[str, Any]:
    return {"agent": agent, "episodes": episodes, "success_rate": success, "mean_return": -150 - 100 * (1 - success)}


def _runs(tmp_path: Path) -> Path:
    runs = tmp_path / "runs"
    (runs / "records").mkdir(parents=True)
    for name, agent, here in (("piga-n2-s0", "piga", True), ("planet-n100-s0", "planet", False), ("oracle", "oracle", False)):
        record = {"spec": {"name": name, "agent": agent, "sequences": 2 if agent == "piga" else 100, "seed": 0},
                  "control": _summary(agent, 1.0), "sweep": {"1.4": _summary(agent, 0.8, 5)}}
        (runs / "records" / f"{name}.json").write_text(json.dumps(record))
        if here:
            (runs / name).mkdir()
            (runs / name / "checkpoint.pt").write_bytes(b"")
    return runs


def test_held_out_scores_the_runs_here_on_another_seed(held_out: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple] = []

    def evaluate(kind, run, cfg, gravity_mult=1.0, episodes=None, workers=1, seed=0, **job):
        calls.append((kind, run and run.name, gravity_mult, episodes, seed))
        return _summary(kind, 0.5 if gravity_mult == 1.0 else 0.4, episodes or cfg.episodes)

    monkeypatch.setattr(held_out, "evaluate", evaluate)
    runs, out = _runs(tmp_path), tmp_path / "held"
    assert held_out.main(["--runs", str(runs), "--out", str(out)]) == 0
    seed = held_out.HELD_OUT_SEED
    assert sorted(calls) == [("oracle", None, 1.0, None, seed), ("oracle", None, 1.4, 5, seed),
                             ("piga", "piga-n2-s0", 1.0, None, seed), ("piga", "piga-n2-s0", 1.4, 5, seed)]
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["not_here"] == ["planet-n100-s0"] and record["seed"] == seed != 0
    assert record["summary"]["piga"] == {"runs": 1, "seed0_x1": 100.0, "held_x1": 50.0, "seed0_x14": 80.0, "held_x14": 40.0}
    page = out.with_suffix(".md").read_text()
    assert "| piga-n2-s0 | piga | 2 | 0 | 100 → 50% (20) | -150.0 → -200.0 | 80 → 40% (5) |" in page
    assert "Not evaluated" in page and "planet-n100-s0" in page

    calls.clear()  # the same command again: every evaluation's record is kept
    assert held_out.main(["--runs", str(runs), "--out", str(out)]) == 0 and calls == []


def test_held_out_refuses_the_tables_own_seed_and_unknown_runs(held_out: Any, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    runs = _runs(tmp_path)
    with pytest.raises(SystemExit):
        held_out.main(["--runs", str(runs), "--seed", "0"])
    assert "--seed 0 gives the table's own episodes" in capsys.readouterr().err
    from piga.cli.common import PigaError

    with pytest.raises(PigaError, match="no record .* for piga-n9-s0"):  # one line under run_script, "error:" and all
        held_out.main(["--runs", str(runs), "--jobs", "piga-n9-s0"])


def test_no_other_benchmark_or_page_uses_the_held_out_seed(held_out: Any) -> None:
    root = Path(__file__).resolve().parents[1]
    seed = str(held_out.HELD_OUT_SEED)
    users = [path.relative_to(root).as_posix() for folder in ("benchmarks", "results", "docs", "agents", "piga")
             for path in (root / folder).rglob("*") if path.suffix in (".py", ".md")
             and not path.name.startswith("held_out") and seed in path.read_text(errors="replace")]
    assert users == []
