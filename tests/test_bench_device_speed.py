"""benchmarks/device_speed.py: it times both trainings on the CPU, refuses cuda without a GPU in one line,
and computes the speed-up of a GPU row over each CPU row."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import device_speed  # noqa: E402
from tests.helpers import assert_one_line  # noqa: E402


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 sequences x 40 frames (4 train: 108 windows, more than one batch of 32; chunks of 20 x 2 frames)."""
    from piga.data.collect import CollectConfig, collect

    path = tmp_path_factory.mktemp("speed") / "pendulum.h5"
    collect(CollectConfig(sequences=6, steps=40, seed=1, workers=1, split=(4, 1, 1)), path, progress=False, command="t")
    return path


@pytest.mark.slow
def test_it_times_both_trainings_on_the_cpu(pendulum: Path, tmp_path: Path) -> None:
    out = tmp_path / "speed"
    assert device_speed.main(["--data", str(pendulum), "--out", str(out), "--steps", "1", "--warmup", "1",
                              "--repeats", "1", "--threads", "1"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert [(r["workload"], r["device"]) for r in record["rows"]] == [("piga fast", "cpu"), ("PlaNet-style", "cpu")]
    assert all(r["median"] > 0 for r in record["rows"]) and record["speedups"] == []
    assert "| piga fast | CPU | this machine | 1 |" in out.with_suffix(".md").read_text()


def test_cuda_without_a_gpu_gets_one_line(pendulum: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(device_speed, "cuda_available", lambda: False)
    code = device_speed.main(["--data", str(pendulum), "--out", str(tmp_path / "speed"), "--device", "cuda"])
    assert_one_line(code, capsys.readouterr().err, "--device cuda: no CUDA device is available")
    assert not list(tmp_path.iterdir())


def test_the_speed_up_is_the_ratio_of_the_medians() -> None:
    rows = [{"workload": "piga fast", "device": "cpu", "device_name": "CPU", "threads": 2, "median": 0.3,
             "machine": "this machine"},
            {"workload": "piga fast", "device": "cuda:0", "device_name": "H100", "threads": 2, "median": 0.02,
             "machine": "this machine"},
            {"workload": "piga fast", "device": "cpu", "device_name": "CPU", "threads": 2, "median": 0.4,
             "machine": "EPYC (cpu.json)"}]
    assert [(s["cpu_machine"], s["speedup"]) for s in device_speed.speedups(rows)] == \
        [("this machine", pytest.approx(15.0)), ("EPYC (cpu.json)", pytest.approx(20.0))]


def test_full_gpu_needs_the_gpu_timed(pendulum: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        device_speed.main(["--data", str(pendulum), "--out", str(tmp_path / "speed"), "--full", "gpu"])
    assert stop.value.code == 1 and "--full gpu needs --device cuda" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_the_page_lists_the_whole_trainings_and_a_reference_joins_them(tmp_path: Path) -> None:
    full = {"device": "cpu", "device_name": "CPU", "threads": 2, "seconds": 190.0, "steps": 2022,
            "learned": {"g": 10.001, "a": 0.999}, "errors": {"g": 1e-4, "a": 7e-4}, "converged": True,
            "machine": "this machine"}
    record = {"command": "c", "machine": {"cpu": "EPYC"}, "settings": {"data": "d", "steps": 1, "warmup": 0, "repeats": 1},
              "references": [], "rows": [], "speedups": [], "full": [full]}
    page = device_speed.markdown(record)
    assert "| CPU | this machine | 2 | 2022 | 190.0 | 0.010% | 0.070% | yes |" in page
