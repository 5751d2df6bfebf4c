"""benchmarks/prediction.py: the page, figure and JSON from its jobs' records, a rerun that reuses them, and a failed
job's one line. ``piga-collect`` and ``piga-train-model`` are stand-ins (a training writes a metrics.json whose scores
are known): the benchmark's bookkeeping is tested, not the models."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import benchmark_module

PRED, EXT = 3, 5  # the stand-in's T_pred and T_ext


@pytest.fixture
def prediction():
    with benchmark_module("prediction") as module:
        yield module


def _ssim(model: str, seed: int, step: int) -> float:
    """The stand-in's SSIM: piga best, falling with the step, and 0.01 higher per seed."""
    return {"piga": 0.95, "in-ig": 0.9, "video-lstm": 0.7}[model] - 0.01 * step + 0.01 * seed


def _stand_ins(prediction: Any, monkeypatch: pytest.MonkeyPatch, fail: str | None = None) -> list[list[str]]:
    """Commands are recorded, not run: piga-collect writes its file, piga-train-model its metrics.json (or exits 2
    for a run named ``fail``)."""
    calls: list[list[str]] = []

    def logged(args: list[str], log: Path) -> int:
        calls.append(args)
        out = Path(args[args.index("--out") + 1])
        if args[0] == "piga-collect":
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(b"h5")
            return 0
        if out.name == fail:
            return 2
        model, seed = args[args.index("--model") + 1], int(args[args.index("--seed") + 1])
        ssim = [_ssim(model, seed, t) for t in range(PRED + EXT)]
        out.mkdir(parents=True, exist_ok=True)
        metrics = {"model": model, "split": "test", "input_frames": 4, "pred_frames": PRED, "extrapolate_frames": EXT,
                   "frame_ssim_per_step": ssim, "frame_mse_per_step": [1 - v for v in ssim],
                   "frame_ssim_mean": {"prediction": sum(ssim[:PRED]) / PRED, "extrapolation": sum(ssim[PRED:]) / EXT},
                   "frame_mse_mean": {}, "converged": True, "convergence": {"outcome": "converged"},
                   "training": {"seconds": 60.0, "steps": int(args[args.index("--budget-steps") + 1])}}
        (out / "metrics.json").write_text(json.dumps(metrics))
        os.utime(out / "metrics.json", (0, 0))  # file times come from a coarse clock: freshness is not read from them
        return 0

    monkeypatch.setattr(prediction, "logged_command", logged)
    # the stand-in's files are not HDF5: the counts are the models' sizes as if built for them
    monkeypatch.setattr(prediction, "parameter_counts", lambda cfg, folder: {
        system: {model: {"piga": 1_263_203, "in-ig": 1_315_237, "video-lstm": 891_395}[model] for model in cfg.models}
        for system in cfg.systems})
    return calls


def test_the_page_figure_and_json_are_written_and_a_rerun_reuses_the_records(prediction, tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _stand_ins(prediction, monkeypatch)
    out = tmp_path / "results" / "prediction"
    argv = ["--out", str(out), "--systems", "spring", "gravity", "--seeds", "0", "1", "--budget-steps", "7",
            "--jobs", "1"]
    assert prediction.main(argv) == 0
    trained = [c for c in calls if c[0] == "piga-train-model"]
    assert len(trained) == 2 * 3 * 2 and all(c[c.index("--budget-steps") + 1] == "7" for c in trained)
    assert [c[2] for c in calls if c[0] == "piga-collect"] == ["spring", "gravity"]
    record = json.loads(out.with_suffix(".json").read_text())
    entry = record["summary"]["gravity"]["in-ig"]
    seed_means = [sum(_ssim("in-ig", s, t) for t in range(PRED)) / PRED for s in (0, 1)]
    assert entry["ssim_prediction"]["mean"] == pytest.approx(sum(seed_means) / 2)
    assert entry["ssim_prediction"]["spread"] == pytest.approx(0.01 / 2 ** 0.5)  # the seeds' sample std
    assert entry["ssim_per_step"][PRED] == pytest.approx((_ssim("in-ig", 0, PRED) + _ssim("in-ig", 1, PRED)) / 2)
    page = out.with_suffix(".md").read_text()
    assert "| spring | 4, 3, 5 | piga | 1,263,203 | 0.945 ± 0.007 | 0.905 ± 0.007 |" in page
    assert "with fewer parameters than piga's on every system" in page
    assert f"`python benchmarks/prediction.py {' '.join(argv)}`" in page and "seeds 0, 1" in page
    assert (out.parent / "prediction-ssim.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in (out.parent / "prediction_runs" / "records").iterdir())[0] == "gravity-in-ig-s0.json"

    calls.clear()
    assert prediction.main(argv) == 0  # every record kept: nothing collected or trained
    assert calls == [] and json.loads(out.with_suffix(".json").read_text())["summary"] == record["summary"]
    assert prediction.main([*argv[:-4], "--budget-steps", "9", "--models", "piga", "--jobs", "1"]) == 0
    assert sorted(c[c.index("--out") + 1].rsplit("/", 1)[1] for c in calls if c[0] == "piga-train-model") == [
        "gravity-piga-s0", "gravity-piga-s1", "spring-piga-s0", "spring-piga-s1"]  # another budget: trained again


def test_a_failed_job_ends_with_one_line_and_keeps_the_records_before(prediction, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    _stand_ins(prediction, monkeypatch, fail="spring-piga-s0")
    out = tmp_path / "prediction"
    with pytest.raises(SystemExit) as info:
        prediction.main(["--out", str(out), "--systems", "spring", "--jobs", "1"])
    assert info.value.code == 1
    err = capsys.readouterr().err
    log = out.parent / "prediction_runs" / "spring-piga-s0.log"
    assert err == (f"prediction.py: error: job spring-piga-s0 failed: RuntimeError: 'piga-train-model --model piga' "
                   f"failed (exit 2); see {log}\n")
    assert sorted(p.stem for p in (out.parent / "prediction_runs" / "records").iterdir()) == [
        "spring-in-ig-s0", "spring-video-lstm-s0"]  # the slower models ran first
    assert not out.with_suffix(".md").exists()


def test_an_abbreviated_option_is_refused(prediction) -> None:
    with pytest.raises(SystemExit):
        prediction.parser().parse_args(["--budget", "5"])


def test_the_capacity_variant_trains_a_wider_video_lstm(prediction) -> None:
    job = prediction.Job("spring-video-lstm-x2-s0", "spring", "video-lstm-x2", 0, 7, Path("d.h5"), Path("run"))
    command = prediction.train_command(job)
    assert command[command.index("--model") + 1] == "video-lstm" and command[command.index("--video-lstm-scale") + 1] == "2"
    assert prediction.parser().parse_args(["--models", "video-lstm-x2"]).models == ["video-lstm-x2"]
