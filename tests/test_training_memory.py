"""A training run's memory is checked before the model is built (:mod:`piga.training.memory`): frames of 1024x1024
and a batch of 4 took 24 GB, and the kernel killed the process without a word; under a memory limit the line said
"choose smaller sizes", which named no option. With a batch of 2 the count of one pass let through a run that the
kernel killed at 23.9 GB: Adam's step and the process itself are counted too."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from piga.cli import train as cli
from piga.io import resources
from piga.io.resources import ResourceError
from piga.training.memory import check_training_fits, training_need
from piga.training.train import PRESETS
from piga.world.variants import activation_bytes, parameter_count
from tests.helpers import assert_one_line, run_in_process

GiB = 2**30


def test_the_activations_grow_with_the_frames_pixels() -> None:
    small, large = (replace(PRESETS["fast"].model, image_size=size) for size in (64, 1024))
    a_small, a_large = activation_bytes(small), activation_bytes(large)
    assert a_small is not None and a_large is not None
    assert 200 < a_large / a_small < 300  # 256x the pixels; the physics' own tensors do not grow
    assert 700 * 2**20 < a_large < 1000 * 2**20  # measured: 832 MiB per window


@pytest.mark.parametrize("available, needle", [
    (32 * GiB, "lower --batch-size to 2 or less, or collect or import the frames at a smaller --image-size"),
    (22.4 * GiB, "; collect or import the frames at a smaller --image-size (piga-collect, piga-import)"),
    (8 * GiB, "; collect or import the frames at a smaller --image-size (piga-collect, piga-import)"),
])
def test_a_1024_px_run_is_refused_with_what_to_lower(available: float, needle: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    config = replace(PRESETS["fast"].model, image_size=1024)
    parameters, activations = parameter_count(config), activation_bytes(config)
    monkeypatch.setattr(resources, "available_memory", lambda: int(available))
    with pytest.raises(ResourceError, match="training on frames of 1024x1024 needs about 35.3 GiB") as info:
        check_training_fits(parameters, activations, 4, True, "1024x1024")
    assert needle in str(info.value)
    if "--batch-size to 2" in needle:  # the batch it names fits, and one more does not
        fixed, batched = training_need(parameters, activations, 2, True)
        assert fixed + batched <= available < sum(training_need(parameters, activations, 3, True))
        check_training_fits(parameters, activations, 2, True, "1024x1024")


def test_a_raised_model_size_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(resources, "available_memory", lambda: 10**6)
    with pytest.raises(ResourceError, match=r"; lower --video-lstm-scale, or collect or import the frames"):
        check_training_fits(10**6, 10**6, 1, False, "64x64", ("--video-lstm-scale",))


def test_the_default_run_fits_without_a_word(monkeypatch: pytest.MonkeyPatch) -> None:
    config = PRESETS["fast"].model
    fixed, batched = training_need(parameter_count(config), activation_bytes(config) or 0, 32, True)
    assert fixed + batched < 1 * GiB  # 64x64, a batch of 32: well within any machine
    monkeypatch.setattr(resources, "available_memory", lambda: None)  # unknown: not refused
    check_training_fits(10**12, 10**12, 32, True, "64x64")


def test_the_cli_refuses_a_batch_too_large_for_the_memory_before_anything_is_written(
        tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    config = replace(PRESETS["fast"].model, image_size=64)
    fixed, batched = training_need(parameter_count(config), activation_bytes(config) or 0, 1, True)
    monkeypatch.setattr(resources, "available_memory", lambda: int(fixed + 1.5 * batched))  # a batch of 1 fits
    out = tmp_path / "run"
    code, _, err = run_in_process("piga-train-model", cli.main, str(tiny_data), "--out", str(out), "--preset", "fast",
                                  "--batch-size", "4", "--quiet", capsys=capsys)
    assert_one_line(code, err, "training on frames of 64x64 needs about", "lower --batch-size to 1 or less")
    assert not out.exists()


def test_the_benchmark_compares_the_count_with_a_measured_step(tmp_path: Path) -> None:
    """benchmarks/training_memory.py: one small case in a fresh process; the count covers what the whole run took."""
    import json
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import training_memory

    out = tmp_path / "memory"
    assert training_memory.main(["--out", str(out), "--sizes", "32"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    (row,), (run,) = record["cases"], record["runs"]
    assert row["size"] == 32 and row["batch"] == 2 and row["measured_gib"] >= 0 and row["counted_gib"] > 0
    assert run["size"] == 32 and run["refused"] is None and 0 < run["measured_gib"] <= run["counted_gib"]
    assert out.with_suffix(".md").read_text().count("| 32x32 | 2 |") == 2
