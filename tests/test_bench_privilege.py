"""benchmarks/privilege.py: the page and JSON from its jobs' records, the rows each job scores (and with what it is
told and planned against), a rerun that reuses the records, and a failed job's one line. The data, training, reward
head and episodes are stand-ins with known scores: the benchmark's bookkeeping is tested, not the models."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def privilege():
    with benchmark_module("privilege") as module:
        yield module


class _Model:
    def physical_parameters(self) -> dict[str, float]:
        return {"g": 9.9, "a": 1.0}


def _success(run: str, gravity: float, told: bool, head: bool) -> float:
    """The stand-in's success: the paper readout 0.5, a learned reward 0.8, not told at x1.4 0.1, else 1; +0.05 per seed."""
    seed = int(run.rsplit("-s", 1)[1])
    base = 0.5 if run.startswith("paper") else 0.8 if head else 0.1 if (gravity != 1.0 and not told) else 1.0
    return base - 0.05 * seed


def _stand_ins(privilege: Any, monkeypatch: pytest.MonkeyPatch, fail: str | None = None) -> list[tuple]:
    calls: list[tuple] = []

    def data_file(cfg, folder, n):
        calls.append(("data", n))
        return folder / f"data-n{n}.h5"

    def train_piga(data, run, seed, cfg, n, model=None):
        calls.append(("train", run.name, None if model is None else model.readout))
        if run.name == fail:
            raise RuntimeError("training diverged")
        run.mkdir(parents=True, exist_ok=True)
        return 600.0

    def evaluate(kind, run, cfg, gravity_mult=1.0, episodes=None, workers=1, **job):
        calls.append(("eval", run.name, gravity_mult, job.get("told", True), job.get("reward_head"), cfg.episodes))
        s = _success(run.name, gravity_mult, job.get("told", True), job.get("reward_head") is not None)
        return {"agent": kind, "episodes": cfg.episodes, "success_rate": s, "mean_return": -200 * (2 - s),
                "gravity_mult": gravity_mult}

    def head(model, data, run, config):
        calls.append(("head", run.name, config.steps))
        return {"path": str(run / "reward_head.pt"), "metrics": {"valid_abs_error": 0.1, "valid_abs_error_mean_guess": 2.0}}

    monkeypatch.setattr(privilege, "data_file", data_file)
    monkeypatch.setattr(privilege, "train_piga", train_piga)
    monkeypatch.setattr(privilege, "evaluate", evaluate)
    monkeypatch.setattr(privilege, "learned_reward_head", head)
    monkeypatch.setattr("piga.io.runs.load_model", lambda run: (_Model(), {"model_config": {"readout": "x"}}))
    return calls


def test_the_page_and_json_are_written_and_a_rerun_reuses_the_records(privilege, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _stand_ins(privilege, monkeypatch)
    out = tmp_path / "results" / "privilege"
    argv = ["--out", str(out), "--seeds", "0", "1", "--episodes", "7"]
    assert privilege.main(argv) == 0
    trained = [c for c in calls if c[0] == "train"]
    assert trained == [("train", "piga-n25-s0", None), ("train", "paper-readout-n25-s0", "regress"),
                       ("train", "piga-n25-s1", None), ("train", "paper-readout-n25-s1", "regress")]
    evals = {(c[1], c[2], c[3], c[4] is not None) for c in calls if c[0] == "eval"}
    assert evals == {(run, m, told, head) for s in (0, 1)
                     for run, m, told, head in ((f"piga-n25-s{s}", 1.0, True, False), (f"piga-n25-s{s}", 1.4, True, False),
                                                (f"piga-n25-s{s}", 1.0, True, True), (f"piga-n25-s{s}", 1.4, True, True),
                                                (f"piga-n25-s{s}", 1.4, False, False),
                                                (f"paper-readout-n25-s{s}", 1.0, True, False),
                                                (f"paper-readout-n25-s{s}", 1.4, True, False))}
    assert all(c[5] == 7 for c in calls if c[0] == "eval")
    record = json.loads(out.with_suffix(".json").read_text())
    rows = {e["row"]: e for e in record["summary"]}
    assert list(rows) == ["default", "learned-reward", "paper-readout", "not-told"]
    assert rows["not-told"]["1.4"]["success_per_seed"] == pytest.approx([0.1, 0.05])
    assert rows["not-told"]["1"] == {**rows["default"]["1"], "same_as": "default"}  # x1.0: nothing to tell
    assert rows["learned-reward"]["1"]["mean_return"] == pytest.approx(-200 * (2 - 0.775))
    page = out.with_suffix(".md").read_text()
    assert "| paper-readout | " in page and "| 50%, 45% | −305.0 | 50%, 45% | −305.0 | 10, 10 |" in page
    assert "| 100%, 95% (= default) |" in page and f"`python benchmarks/privilege.py {' '.join(argv)}`" in page
    assert "piga-n25-s0: 0.100 (constant 2.000)" in page
    assert sorted(p.name for p in (out.parent / "privilege_runs" / "records").iterdir()) == [
        "paper-readout-n25-s0.json", "paper-readout-n25-s1.json", "piga-n25-s0.json", "piga-n25-s1.json"]

    calls.clear()
    assert privilege.main(argv) == 0  # every record kept: nothing trained or scored
    assert calls == [] and json.loads(out.with_suffix(".json").read_text())["summary"] == record["summary"]
    assert privilege.main([*argv[:-2], "--episodes", "9"]) == 0  # other episodes: every job again
    assert len([c for c in calls if c[0] == "train"]) == 4


def test_a_failed_job_ends_with_one_line_and_keeps_the_records_before(privilege, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    _stand_ins(privilege, monkeypatch, fail="paper-readout-n25-s0")
    out = tmp_path / "privilege"
    with pytest.raises(SystemExit) as info:
        privilege.main(["--out", str(out)])
    assert info.value.code == 1
    assert capsys.readouterr().err == ("privilege.py: error: job paper-readout-n25-s0 failed: RuntimeError: training "
                                       "diverged\n")
    assert [p.stem for p in (out.parent / "privilege_runs" / "records").iterdir()] == ["piga-n25-s0"]
    assert not out.with_suffix(".md").exists()


def test_an_abbreviated_option_is_refused(privilege) -> None:
    with pytest.raises(SystemExit):
        privilege.parser().parse_args(["--seed", "0"])
