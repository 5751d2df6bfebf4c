"""benchmarks/data_draw.py: the table's jobs rerun on another collection's subsets, beside the table's records; the
table's own draw and jobs the table has not are refused. The jobs are stand-ins that record what they were given."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def draw():
    with benchmark_module("data_draw") as module:
        yield module


def _summary(success: float, episodes: int = 20) -> dict[str, Any]:
    return {"episodes": episodes, "success_rate": success, "mean_return": -150 - 100 * (1 - success)}


def test_jobs_rerun_on_the_second_draw_beside_the_table(draw: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    table = tmp_path / "table"
    (table / "records").mkdir(parents=True)
    (table / "records" / "piga-n2-s0.json").write_text(json.dumps(
        {"spec": {"data_seed": 100}, "control": _summary(1.0), "sweep": {"1.4": _summary(1.0, 5)}}))
    collected, ran = [], []

    def data_file(cfg, folder, n):
        collected.append((cfg.data_seed, n))
        return folder / f"data-n{n}.h5"

    def run_task(args):
        from common import machine  # benchmarks/ is on the path while the module is in use

        job, cfg, folder, data = args
        ran.append((job.name, job.seed, cfg.data_seed, data.name))
        return {"machine": machine(), "train_seconds": 1.0, "control": _summary(0.5),
                "sweep": {"1.4": _summary(0.0, 5)}}

    table_module = sys.modules[draw.run_all.__module__]  # the jobs run through the table's own runner
    monkeypatch.setattr(table_module, "data_file", data_file)
    monkeypatch.setattr(table_module, "_run_task", run_task)
    out = tmp_path / "draw"
    argv = ["--jobs", "piga-n2-s0", "planet-n250-s0", "--table", str(table), "--out", str(out)]
    assert draw.main(argv) == 0
    assert collected == [(200, 2), (200, 250)]
    assert sorted(ran) == [("piga-n2-s0", 0, 200, "data-n2.h5"), ("planet-n250-s0", 0, 200, "data-n250.h5")]
    page = out.with_suffix(".md").read_text()
    assert "| piga-n2-s0 | 100 (the table) | 100% (20) | -150.0 | 100% (5) |" in page
    assert "| piga-n2-s0 | 200 | 50% (20) | -200.0 | 0% (5) |" in page
    assert "| planet-n250-s0 | 100 (the table) | no record | | |" in page
    spec = json.loads((tmp_path / "draw_runs" / "records" / "piga-n2-s0.json").read_text())["spec"]
    assert spec["data_seed"] == 200 and spec["epochs"] > 0  # the table's spec, on the other draw
    collected.clear(), ran.clear()
    assert draw.main(argv) == 0 and collected == [] and ran == []  # the records are kept


@pytest.mark.parametrize("argv, message", [
    (["--data-seed", "100"], "is the table's own draw"),
    (["--jobs", "piga-n3-s0"], "not a piga or PlaNet-style job of the budget table: piga-n3-s0"),
    (["--jobs", "ddpg-state-s0"], "not a piga or PlaNet-style job"),
])
def test_the_tables_draw_and_unknown_jobs_are_refused(draw: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      argv: list[str], message: str) -> None:
    with pytest.raises(SystemExit):
        draw.main([*argv, "--out", str(tmp_path / "x")])
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x_runs").exists()
