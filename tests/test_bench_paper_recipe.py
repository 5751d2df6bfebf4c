"""benchmarks/paper_recipe.py: the commands it runs, the page from its records, a rerun that reuses them, a continued
paper run that keeps its earlier stretch, and a failed command's one line. ``piga-collect`` and ``piga-train-model``
are stand-ins (a training writes the metrics.json of a known run): the bookkeeping is tested, not the recipes."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def paper_recipe():
    with benchmark_module("paper_recipe") as module:
        yield module


def _stand_ins(module: Any, monkeypatch: pytest.MonkeyPatch, fail: bool = False) -> tuple[list[list[str]], dict[str, int]]:
    calls: list[list[str]] = []
    stood = {"steps": 0}  # where the stand-in's paper run stands

    def logged(args: list[str], log: Path) -> int:
        calls.append(args)
        out = Path(args[args.index("--out") + 1])
        if args[0] == "piga-collect":
            out.write_bytes(b"h5")
            return 0
        if fail:
            return 2
        paper = "spring-paper" in out.name
        if paper:  # each command trains 100 more steps of the paper's plan
            stood["steps"] += 100
        steps = stood["steps"] if paper else 1718
        out.mkdir(parents=True, exist_ok=True)
        metrics = {"split": "test", "frame_ssim_mean": {"prediction": 0.9, "extrapolation": 0.8},
                   "parameter_errors": {"k": {"learned": 3.0, "true": 4.0, "relative_error": 0.25}},
                   "convergence": {"outcome": "unsettled" if paper else "converged", "planned_steps": 25000 if paper else 1718},
                   "training": {"epochs": steps // 50, "steps": steps, "seconds": 6.0 * steps, "device": "cpu"}}
        (out / "metrics.json").write_text(json.dumps(metrics))
        (out / "checkpoint.pt").write_bytes(b"pt")
        return 3 if paper else 0

    monkeypatch.setattr(module, "logged_command", logged)
    monkeypatch.setattr(sys.modules["prediction"], "logged_command", logged)
    monkeypatch.setenv("PIGA_COMMIT", "abc1234")
    return calls, stood


def test_both_recipes_train_on_the_paper_file_and_a_resume_keeps_the_earlier_stretch(
        paper_recipe: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls, stood = _stand_ins(paper_recipe, monkeypatch)
    out = tmp_path / "results" / "paper_recipe"
    assert paper_recipe.main(["--out", str(out), "--max-minutes", "6.5", "--device", "cpu"]) == 0
    collect, fast, paper = calls
    assert collect[:6] == ["piga-collect", "--system", "spring", "--preset", "paper", "--seed"]
    assert fast[fast.index("--preset") + 1] == "fast" and "--max-minutes" not in fast and "--overwrite" in fast
    assert paper[paper.index("--preset") + 1] == "paper" and paper[paper.index("--max-minutes") + 1] == "6.5"
    page = out.with_suffix(".md").read_text()
    assert "| paper | 100 (25,000) | 2 | 10.0 | k = 3 (25.0% off 4) | 0.900 | 0.800 | 3 (unsettled) |" in page
    assert "| fast | 1,718 (1,718) |" in page and "commit abc1234" in page

    calls.clear()  # a rerun reuses both records: nothing runs
    assert paper_recipe.main(["--out", str(out)]) == 0 and calls == []

    assert paper_recipe.main(["--out", str(out), "--resume", "--max-minutes", "60"]) == 0
    (resumed,) = calls
    assert "--resume" in resumed and "--preset" not in resumed and "--overwrite" not in resumed
    record = json.loads((out.parent / "paper_recipe_runs" / "records" / "spring-paper.json").read_text())
    assert [s["steps"] for s in record["segments"]] == [100, 200]
    assert "to step 100 (10.0 min)" in out.with_suffix(".md").read_text()

    stood["steps"] -= 100  # a continuation whose budget is spent trains no step: the record stays as it was
    assert paper_recipe.main(["--out", str(out), "--resume", "--max-minutes", "60"]) == 0
    again = json.loads((out.parent / "paper_recipe_runs" / "records" / "spring-paper.json").read_text())
    assert again == record


def test_a_failed_command_is_one_line(paper_recipe: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    _stand_ins(paper_recipe, monkeypatch, fail=True)
    assert paper_recipe.main(["--out", str(tmp_path / "paper_recipe")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "failed (exit 2)" in err[0] and "see " in err[0]
