"""benchmarks/planet_faithful.py: each variant trained with its settings over the table's, on the table's data file,
scored and set beside the table's runs at that size; a rerun reuses the records. Training and episodes are stand-ins."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def faithful():
    with benchmark_module("planet_faithful") as module:
        yield module


def test_a_variant_trains_with_its_settings_on_the_tables_data(faithful: Any, tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple] = []
    runs = tmp_path / "runs"
    (runs / "records").mkdir(parents=True)
    summary = {"episodes": 20, "success_rate": 0.5, "mean_return": -250.0}
    (runs / "records" / "planet-n500-s0.json").write_text(json.dumps(
        {"spec": {"seed": 0}, "control": summary, "sweep": {"1.4": {**summary, "success_rate": 0.0}}, "train_seconds": 5400}))

    def data_file(cfg, folder, n):
        calls.append(("data", folder.name, n))
        return folder / f"data-n{n}.h5"

    def train_planet_run(data, run, seed, cfg, n, device):
        calls.append(("train", data.name, run.name, seed, cfg.overrides["rssm"], cfg.overrides["planet"], device))
        run.mkdir(parents=True)
        (run / "metrics.json").write_text(json.dumps({"valid": {"loss": 1.0}, "open_loop": {}}))
        return 6000.0

    def evaluate(kind, run, cfg, gravity_mult=1.0, episodes=None, **job):
        calls.append(("eval", kind, run.name, gravity_mult, episodes))
        return {"episodes": episodes or 20, "success_rate": 0.9 if gravity_mult == 1.0 else 0.2, "mean_return": -190.0}

    for name, stand_in in (("data_file", data_file), ("train_planet_run", train_planet_run)):
        monkeypatch.setattr(faithful, name, stand_in)
    monkeypatch.setattr(sys.modules[faithful.planet_scores.__module__], "evaluate", evaluate)  # the table's scoring
    out = tmp_path / "faithful"
    args = ["--runs", str(runs), "--out", str(out), "--variants", "planet-reward"]
    assert faithful.main(args) == 0
    assert calls == [("data", "runs", 500),
                     ("train", "data-n500.h5", "planet-reward-n500-s0", 0, {"reward_alignment": "transition"},
                      {"reward_scale": 10.0}, "cpu"),
                     ("eval", "planet", "planet-reward-n500-s0", 1.0, None),
                     ("eval", "planet", "planet-reward-n500-s0", 1.4, 5)]
    page = out.with_suffix(".md").read_text()
    assert "| the table's (planet-n500-s0) |" in page and "| 0 | 50% (20) | -250.0 | 0% | 90 |" in page
    assert "| planet-reward (planet-reward-n500-s0) |" in page and "| 0 | 90% (20) | -190.0 | 20% | 100 |" in page
    calls.clear()
    assert faithful.main(args) == 0 and calls == []  # the record is kept
    # --train-only trains PlaNet's sizes on the device asked for, and neither scores nor records nor writes a page
    assert faithful.main([*args[:2], "--variants", "planet-sizes", "--device", "cuda", "--train-only",
                          "--out", str(tmp_path / "trained")]) == 0
    assert calls == [("data", "runs", 500),
                     ("train", "data-n500.h5", "planet-sizes-n500-s0", 0,
                      {"deter_size": 200, "stoch_size": 30, "hidden_size": 200, "depth": 32, "reward_layers": 3,
                       "reward_units": 300}, {"batch_size": 50}, "cuda")]
    assert not (tmp_path / "trained.md").exists() and not (tmp_path / "trained_runs" / "records").exists()


def test_a_size_the_table_does_not_have_is_refused(faithful: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        faithful.main(["--sequences", "300", "--out", str(tmp_path / "x")])
    assert "--sequences 300: the budget preset's PlaNet-style sizes are 100, 250, 500, 1000, 2000" in capsys.readouterr().err
