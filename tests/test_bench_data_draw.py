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


def _row(agent: str, sequences: int, table: float | None, second: float) -> dict[str, Any]:
    return {"agent": agent, "sequences": sequences, "table": None if table is None else {"x1": _summary(table)},
            "x1": _summary(second)}


def test_each_draw_and_both_are_read_as_the_table_reads_its_curve(draw: Any) -> None:
    rows = {"piga-n2-s0": _row("piga", 2, 1.0, 1.0), "piga-n2-s1": _row("piga", 2, 1.0, 1.0),
            "planet-n250-s0": _row("planet", 250, 0.75, 0.0), "planet-n500-s0": _row("planet", 500, 0.5, 0.1),
            "planet-n1000-s0": _row("planet", 1000, 1.0, 0.9), "planet-n2000-s0": _row("planet", 2000, None, 1.0)}
    needs = {(row["threshold"], row["draw"]): row for row in draw.draw_needs(rows)}
    assert sorted(needs) == [(t, d) for t in (0.8, 0.95) for d in sorted(("table", "second", "both"))]
    # 80% between 500 and 1000, in log(sequences): the table's 50% -> 100%, the second's 10% -> 90%; both: 30% -> 95%
    for name, rate0, rate1 in (("table", 0.5, 1.0), ("second", 0.1, 0.9), ("both", 0.3, 0.95)):
        need = needs[(0.8, name)]["numerator"]
        assert need["bound"] == "exact" and need["value"] == pytest.approx(500 * 2 ** ((0.8 - rate0) / (rate1 - rate0)))
        assert needs[(0.8, name)]["denominator"]["bound"] == "at_most" and needs[(0.8, name)]["ratio"]["bound"] != "exact"
    # 2000 sequences have a run on the second draw only: on its curve, not on the pooled one
    assert needs[(0.95, "second")]["numerator"]["value"] == pytest.approx(1000 * 2 ** ((0.95 - 0.9) / 0.1))
    assert needs[(0.95, "both")]["numerator"]["value"] == pytest.approx(1000)
    record = {"jobs": rows, "needs": draw.draw_needs(rows), "data_seed": 200, "table_data_seed": 100}
    page = "\n".join(draw.needs_lines(record))
    assert "the PlaNet-style model at 250, 500, 1000 and 2000 sequences, piga at 2)" in page
    assert "| 80% | 100 (the table) | at most 2 (its smallest size; in every draw) | 758 (" in page
    assert draw.needs_lines({**record, "needs": []}) == []


def test_a_need_bounded_in_a_few_draws_says_so(draw: Any) -> None:
    table = sys.modules[draw.run_all.__module__]
    need = {"value": 952.0, "bound": "exact", "low": 917.0, "high": 964.0}
    assert table.need_cell({**need, "bounded_draws": 0.001}) == "952 (95%: 917–964; under 1% of draws a bound)"
    assert table.need_cell({**need, "bounded_draws": 0.08}) == "952 (95%: 917–964; 8% of draws a bound)"
    assert table.need_cell({**need, "bounded_draws": 0.0}) == "952 (95%: 917–964)"


def test_jobs_of_several_machines_are_named_by_machine(draw: Any) -> None:
    one = {"cpu": "AMD EPYC", "cpu_family_model": "26/2", "cores": 2, "torch": "2.13.0+cpu", "torch_threads": 1,
           "python": "3.11.7"}
    other = {**one, "cpu_family_model": "25/17"}
    lines = draw._machine_lines({"machine": one, "machines": {"piga-n2-s0": one, "planet-n1000-s0": other}})
    assert lines[0] == "Machines:" and lines[2].endswith(": piga-n2-s0") and lines[3].endswith(": planet-n1000-s0")
    assert "25/17" in lines[3]
    assert draw._machine_lines({"machine": one})[0].startswith("Machine: AMD EPYC (family/model 26/2)")
