"""benchmarks/arrow.py: runs scored on the table's episodes with the torque arrow shown, beside their records'
arrow-free numbers; what is not a piga or PlaNet-style run is refused. The runs are empty stand-ins, and the
episodes stand-ins that record the settings they were given."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from tests.helpers import benchmark_module


@pytest.fixture
def arrow():
    with benchmark_module("arrow") as module:
        yield module


def test_runs_are_scored_with_the_arrow_beside_their_records(arrow: Any, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    import piga.control.jobs

    run = tmp_path / "table_runs" / "planet-n8-s0"
    run.mkdir(parents=True)
    (run / "checkpoint.pt").write_bytes(b"")  # the episodes are stand-ins: nothing loads it
    (run / "config.json").write_text(json.dumps({"kind": "planet"}))  # as the benchmarks write it
    (run.parent / "records").mkdir()
    (run.parent / "records" / "planet-n8-s0.json").write_text(json.dumps(
        {"control": {"episodes": 20, "success_rate": 0.5, "mean_return": -250.0},
         "sweep": {"1.4": {"episodes": 5, "success_rate": 0.0, "mean_return": -900.0}}}))
    seen = []

    def run_split(job, workers, progress=True):
        seen.append((job.agent, job.episodes.torque_arrow, job.episodes.gravity_mult,
                     job.episodes.episodes, job.episodes.seed))
        rate = 0.25 if job.episodes.gravity_mult == 1.0 else 0.0
        return SimpleNamespace(summary=SimpleNamespace(to_dict=lambda: {
            "episodes": job.episodes.episodes, "success_rate": rate, "mean_return": -300.0}))

    monkeypatch.setattr(piga.control.jobs, "run_split", run_split)
    out = tmp_path / "arrow"
    assert arrow.main(["--runs", str(run), "--out", str(out)]) == 0
    assert seen == [("planet", True, 1.0, 20, 0), ("planet", True, 1.4, 5, 0)]  # the table's episodes, arrow shown
    page = out.with_suffix(".md").read_text()
    assert "| planet-n8-s0 | planet | 50 → 25% (20) | -250.0 → -300.0 | 0 → 0% (5) |" in page
    seen.clear()
    assert arrow.main(["--runs", str(run), "--out", str(out)]) == 0 and seen == []  # the record is kept


def test_a_folder_without_a_checkpoint_is_refused(arrow: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit):
        arrow.main(["--runs", str(tmp_path / "empty"), "--out", str(tmp_path / "x")])
    assert "holds no checkpoint.pt" in capsys.readouterr().err
    assert not (tmp_path / "x_runs").exists()
