"""benchmarks/planet_crosscheck.py: piga's RSSM and mbrl-lib's PlaNet trained on the same batches, and the one
line it stops with when mbrl is not installed."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from .helpers import assert_one_line, benchmark_module

TINY = ("--steps", "3", "--batch-size", "4", "--chunk-length", "8", "--deter-size", "16", "--stoch-size", "4",
        "--hidden-size", "16", "--depth", "4", "--log-every", "2", "--valid-sequences", "2")


@pytest.fixture
def crosscheck():
    with benchmark_module("planet_crosscheck") as module:
        yield module


def test_both_models_train_on_the_same_batches(crosscheck, tiny_data: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mbrl.models.planet")
    import torch

    threads = torch.get_num_threads()
    out = tmp_path / "crosscheck"
    try:
        assert crosscheck.main(["--data", str(tiny_data), *TINY, "--out", str(out)]) == 0
    finally:
        torch.set_num_threads(threads)
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["same_batches"]
    models = record["models"]
    assert models["piga"]["batches_sha256"] == models["mbrl"]["batches_sha256"]
    # the same sizes and layers: the same parameter count (deter_size == hidden_size, so the GRU's input layers agree)
    assert models["piga"]["parameters"] == models["mbrl"]["parameters"] > 0
    for name in ("piga", "mbrl"):
        assert [p["step"] for p in models[name]["curve"]] == [2, 3]
        assert all(math.isfinite(v) for p in models[name]["curve"] for v in p.values())
        assert models[name]["seconds_per_step_median"] > 0
        row = record["valid"]["models"][name]
        assert len(row["open_loop_reward_abs_error_by_step"]) == record["valid"]["open_loop_steps"] > 0
        assert all(math.isfinite(v) for k, v in row.items() if not k.endswith("by_step"))
        assert all(row[k] >= 0 for k in ("pixel_mse", "reward_mse", "kl", "open_loop_reward_mse", "open_loop_pixel_mse"))
    # mbrl's matched objective: twice piga's KL weight, clip and Adam epsilon
    assert record["settings"]["mbrl_scale"] == 2.0
    page = out.with_suffix(".md").read_text()
    assert "fingerprints equal" in page and "| KL weight | 1 | 2 |" in page
    assert "mbrl.models.planet.PlaNetModel" in page and "## What differs" in page
    assert "step 3:" in capsys.readouterr().out


def test_without_mbrl_it_says_how_to_install_it(crosscheck, tiny_data: Path, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    for name in [n for n in sys.modules if n == "mbrl" or n.startswith("mbrl.")] + ["mbrl"]:
        monkeypatch.setitem(sys.modules, name, None)  # the import fails, whether or not mbrl is installed
    with pytest.raises(SystemExit) as info:
        crosscheck.main(["--data", str(tiny_data), *TINY, "--out", str(tmp_path / "crosscheck")])
    assert_one_line(info.value.code, capsys.readouterr().err, "mbrl.models.planet is not importable",
                    "pip install --no-deps mbrl==0.2.0")
    assert not list(tmp_path.iterdir())
