"""benchmarks/planet_select.py: a finished run's selected weights scored beside its last weights' record; runs
without a valid loss are refused. Training is real and tiny; the episodes are stand-ins."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def select():
    with benchmark_module("planet_select") as module:
        yield module


def test_the_selected_weights_are_scored_beside_the_last(select: Any, tiny_data: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from agents.planet.config import PlanetTrainConfig, RSSMConfig
    from agents.planet.train import train_planet

    run = tmp_path / "table_runs" / "planet-n8-s0"
    train_planet(tiny_data, run, PlanetTrainConfig(steps=3, batch_size=2, chunk_length=4, checkpoint_every=1, threads=1),
                 RSSMConfig(depth=4, deter_size=8, stoch_size=4, hidden_size=8), progress=False)
    summary = {"episodes": 20, "success_rate": 0.5, "mean_return": -250.0}
    (run.parent / "records").mkdir()
    (run.parent / "records" / "planet-n8-s0.json").write_text(json.dumps(
        {"control": summary, "sweep": {"1.4": replace_rate(summary, 0.0)}}))
    calls = []

    def evaluate(kind, folder, cfg, gravity_mult=1.0, episodes=None, **job):
        calls.append((kind, folder.name, gravity_mult, episodes))
        return {"episodes": episodes or 20, "success_rate": 0.9 if gravity_mult == 1.0 else 0.2, "mean_return": -190.0}

    monkeypatch.setattr(sys.modules[select.planet_scores.__module__], "evaluate", evaluate)  # the table's scoring
    out = tmp_path / "select"
    assert select.main(["--runs", str(run), "--out", str(out)]) == 0
    assert calls == [("planet", "planet-n8-s0-valid", 1.0, None), ("planet", "planet-n8-s0-valid", 1.4, 5)]
    metrics = json.loads((run / "metrics.json").read_text())
    page = out.with_suffix(".md").read_text()
    assert f"| planet-n8-s0 | last | 3 | {metrics['learning_curve'][-1]['valid_loss']:.4f} | 50% (20) | -250.0 | 0% |" in page
    step = metrics["best_valid"]["step"]
    assert f"| planet-n8-s0 | selected on the valid split | {step} (3) | {metrics['best_valid']['loss']:.4f} | 90% (20) |" in page
    calls.clear()
    assert select.main(["--runs", str(run), "--out", str(out)]) == 0 and calls == []  # the record is kept


def replace_rate(summary: dict[str, Any], rate: float) -> dict[str, Any]:
    return {**summary, "success_rate": rate}


def test_a_run_without_a_valid_loss_is_refused(select: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "old"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"steps": 12000, "learning_curve": [], "best_valid": None}))
    with pytest.raises(SystemExit):
        select.main(["--runs", str(run), "--out", str(tmp_path / "x")])
    assert "no valid loss was measured during its training" in capsys.readouterr().err
