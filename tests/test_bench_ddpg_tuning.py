"""benchmarks/ddpg_tuning.py: the model-free runs' table on results/ddpg_tuning.md is the committed records'."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import ddpg_tuning  # noqa: E402
from tests.helpers import assert_one_line  # noqa: E402


def test_the_committed_page_holds_the_records_table() -> None:
    assert ddpg_tuning.main(["--check"]) == 0


def test_a_record_that_changes_makes_the_page_stale(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    records = tmp_path / "records"
    shutil.copytree(ddpg_tuning.RECORDS, records)
    path = records / "ddpg-state-s1.json"
    record = json.loads(path.read_text())
    record["metrics"]["learning_curve"][-1]["eval_mean_return"] = -400.04
    path.write_text(json.dumps(record))
    page = tmp_path / "page.md"
    shutil.copy(ddpg_tuning.PAGE, page)
    code = ddpg_tuning.main(["--check", "--page", str(page), "--records", str(records)])
    assert_one_line(code, capsys.readouterr().err, "table is not the records'")
    assert ddpg_tuning.main(["--page", str(page), "--records", str(records)]) == 0
    assert "| `ddpg-state-s1` | DDPG | state | 1 | 30k | 13k | −158.0 (15k) | −400.0 |" in page.read_text()


def test_a_page_without_the_markers_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    page = tmp_path / "page.md"
    page.write_text("# no table\n")
    assert_one_line(ddpg_tuning.main(["--page", str(page)]), capsys.readouterr().err, "has no block between")
    assert page.read_text() == "# no table\n"


def test_the_drqv2_curve_on_the_page_is_its_records() -> None:
    record = json.loads((ddpg_tuning.ROOT / "results" / "drqv2_runs" / "records" / "pixels-s0.json").read_text())
    curve = record["learning_curve"]
    row = ("| evaluation return (5 episodes) | "
           + " | ".join(f"{r['eval_mean_return']:.1f}".replace("-", "\u2212") for r in curve) + " |")
    assert row in ddpg_tuning.PAGE.read_text()
    assert record["config"]["algo"] == "drqv2" and record["command"].endswith("--out RUN")
