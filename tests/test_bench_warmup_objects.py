"""benchmarks/warmup_objects.py: a real (tiny) collection and a real, shortened spring recipe stopped after its warm-up;
the page, the record and the templates figure."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

from tests.helpers import benchmark_module


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_runs_stop_after_the_warm_up_and_the_page_has_each_seed_on_both_data_sets(tmp_path: Path,
                                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    import piga.training.train as training

    real = training.preset_for

    def short(name, info):  # noqa: ANN001, ANN202
        recipe = real(name, info)
        return replace(recipe, train=replace(recipe.train, budget_steps=24, batch_size=8))

    monkeypatch.setattr(training, "preset_for", short)
    with benchmark_module("warmup_objects") as bench:
        monkeypatch.setattr(bench, "SEQUENCES", 10)
        out = tmp_path / "warm"
        assert bench.main(["--out", str(out), "--seeds", "0", "--data-sets", "spring-half", "spring"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert list(record["runs"]) == ["spring-half", "spring"]
    for name in ("spring-half", "spring"):
        run = record["runs"][name]["0"]
        assert run["warmup_steps"] <= run["step"] < run["total_steps"]  # stopped after the warm-up, before the end
        assert math.isfinite(run["check"]["ratio"]) and run["check"]["ratio"] >= 0
    page = out.with_suffix(".md").read_text()
    assert "| seed | spring-half | spring |" in page and "| 0 | " in page and "--half" in page
    assert "warm-templates-s0.png" in page
    assert (tmp_path / "warm-templates-s0.png").read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "warm-templates-s1.png").exists()
