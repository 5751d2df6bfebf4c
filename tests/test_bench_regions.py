"""benchmarks/regions.py: the page, strip and JSON from its jobs' records, a rerun that reuses them, and a failed
job's one line. ``piga-collect`` gives a real small half-spring file; ``piga-train-model`` and the scoring of
its run are stand-ins with known scores: the benchmark's bookkeeping is tested, not the decoders."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from piga.cli.collect import main as collect_main
from tests.helpers import benchmark_module

SSIM = {"st": 0.95, "deconv": 0.5, "broadcast": 0.6, "mlp": 0.4}  # the stand-in's bottom-half SSIM by decoder


@pytest.fixture
def regions():
    with benchmark_module("regions") as module:
        yield module


@pytest.fixture(scope="session")
def half_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real half-spring file of 10 sequences, collected once (its starts are drawn by rejection: seconds)."""
    path = tmp_path_factory.mktemp("half") / "spring-half.h5"
    assert collect_main(["--system", "spring", "--half", "--sequences", "10", "--seed", "100", "--out", str(path),
                         "--workers", "1", "--quiet"]) == 0
    return path


def _stand_ins(regions: Any, monkeypatch: pytest.MonkeyPatch, half_file: Path,
               fail: str | None = None) -> list[list[str]]:
    """piga-collect copies ``half_file`` (a real file of the command's kind); piga-train-model writes a metrics.json
    (or exits 2 for the run named ``fail``) and the scoring returns the decoder's known scores."""
    calls: list[list[str]] = []

    def logged(args: list[str], log: Path) -> int:
        calls.append(args)
        out = Path(args[args.index("--out") + 1])
        if args[0] == "piga-collect":
            assert args[args.index("--sequences") + 1] == "10" and "--half" in args
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(half_file, out)
            return 0
        if out.name == fail:
            return 2
        out.mkdir(parents=True, exist_ok=True)
        metrics = {"parameter_errors": {"k": {"learned": 4.1}, "l": {"learned": 5.9}},
                   "training": {"seconds": 60.0, "steps": int(args[args.index("--budget-steps") + 1])}}
        (out / "metrics.json").write_text(json.dumps(metrics))
        seed = int(args[args.index("--seed") + 1])
        retried = [seed] if "-st-" in out.name else []  # the ST run lost a ball once and found both with the next seed
        (out / "config.json").write_text(json.dumps({"train": {"seed": seed + len(retried)}, "retried_seeds": retried}))
        return 0

    def score(run_dir: Path, data: Path, strip: tuple[int, tuple[int, ...]]) -> dict[str, Any]:
        decoder = run_dir.name.split("-")[2]
        value = SSIM[decoder]
        return {"decoder_parameters": 1000, "input_frames": 4, "pred_frames": 6, "extrapolate_frames": 20,
                "test_sequences": 1, "bottom_frames": 5, "ssim_per_step": {"whole": [value], "bottom": [value]},
                "scores": {"ssim_prediction": 0.99, "ssim_extrapolation": value, "mse_extrapolation": 1 - value,
                           "ssim_bottom_extrapolation": value, "mse_bottom_extrapolation": 1 - value,
                           "ssim_bottom_with_ball": value, "mse_bottom_with_ball": 1 - value},
                "strip": regions.encode_frames(np.full((len(strip[1]), 32, 32, 3), int(value * 255), np.uint8))}

    monkeypatch.setattr(regions, "logged_command", logged)  # the collection
    monkeypatch.setattr(sys.modules["prediction"], "logged_command", logged)  # the trainings (its run_training)
    monkeypatch.setattr(regions, "score_run", score)
    return calls


@pytest.mark.slow
def test_the_page_strip_and_json_are_written_and_a_rerun_reuses_the_records(regions, tmp_path: Path, half_file: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _stand_ins(regions, monkeypatch, half_file)
    out = tmp_path / "results" / "regions"
    argv = ["--out", str(out), "--sequences", "10", "--budget-steps", "7", "--jobs", "1"]
    assert regions.main(argv) == 0
    trained = [c for c in calls if c[0] == "piga-train-model"]
    assert [c[c.index("--decoder") + 1] for c in trained] == ["st", "deconv", "broadcast", "mlp"]
    assert all(c[c.index("--budget-steps") + 1] == "7" for c in trained)
    assert [c[:4] for c in calls if c[0] == "piga-collect"] == [["piga-collect", "--system", "spring", "--half"]]
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["summary"]["broadcast"]["ssim_bottom_with_ball"]["mean"] == pytest.approx(0.6)
    sequence, steps = record["strip"]
    assert steps and all(6 <= s < 26 for s in steps)  # extrapolation steps, chosen where a ball is in the bottom half
    assert 0 < record["empty_bottom"]["mse_bottom_with_ball"] and record["empty_bottom"]["ssim_bottom_with_ball"] < 1
    page = out.with_suffix(".md").read_text()
    assert "| st | 1,000 | 0.990 | 0.950 | 0.950 | 0.950 | 0.0500 | 0.0500 | k 4.10, l 5.90 | 1.0 | 0.0 | 0 |" in page
    assert f"`python benchmarks/regions.py {' '.join(argv)}`" in page and "--budget-steps 7" in page
    assert "spring-half-st-s0: 0, 1; spring-half-deconv-s0: 0;" in page  # the seeds each job trained
    assert (out.parent / "regions-strip.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in (out.parent / "regions_runs" / "records").iterdir())[0] == "spring-half-broadcast-s0.json"

    calls.clear()
    assert regions.main(argv) == 0  # every record kept and the data there: nothing collected or trained
    assert calls == [] and json.loads(out.with_suffix(".json").read_text())["summary"] == record["summary"]
    assert regions.main([*argv[:-4], "--budget-steps", "9", "--decoders", "st", "--jobs", "1"]) == 0
    assert [c[c.index("--decoder") + 1] for c in calls if c[0] == "piga-train-model"] == ["st"]  # another budget


def test_a_failed_job_ends_with_one_line(regions, tmp_path: Path, half_file: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    _stand_ins(regions, monkeypatch, half_file, fail="spring-half-deconv-s0")
    out = tmp_path / "regions"
    with pytest.raises(SystemExit) as info:
        regions.main(["--out", str(out), "--sequences", "10", "--jobs", "1"])
    assert info.value.code == 1
    log = out.parent / "regions_runs" / "spring-half-deconv-s0.log"
    assert capsys.readouterr().err == (f"regions.py: error: job spring-half-deconv-s0 failed: RuntimeError: "
                                       f"'piga-train-model --decoder deconv' failed (exit 2); see {log}\n")
    assert sorted(p.stem for p in (out.parent / "regions_runs" / "records").iterdir()) == ["spring-half-st-s0"]
    assert not out.with_suffix(".md").exists()


def test_an_abbreviated_option_is_refused(regions) -> None:
    with pytest.raises(SystemExit):
        regions.parser().parse_args(["--budget", "5"])


def test_the_wider_broadcast_variant_is_a_decoder_option_pair(regions) -> None:
    job = regions.Job("spring-half-broadcast-w32-s0", "broadcast-w32", 0, 7, Path("d.h5"), Path("run"), (0, (1,)))
    command = regions.train_command(job)
    assert command[command.index("--decoder") + 1] == "broadcast" and command[command.index("--broadcast-width") + 1] == "32"
    assert regions.parser().parse_args(["--decoders", "st", "broadcast-w32"]).decoders == ["st", "broadcast-w32"]
    from piga.cli.train import build_parser

    build_parser().parse_args(["d.h5", *command[command.index("--out"):]])  # every option is piga-train-model's


def test_the_retry_count_is_the_pages_one_unless_given_and_then_part_of_a_jobs_settings(regions) -> None:
    """The pages were made with one retry: their records carry no retry count and stay valid; another count is
    another job (its records are not reused)."""
    strip = (0, (1,))
    kept = regions.jobs_for(regions.BenchConfig(decoders=("st",)), Path("runs"), strip)[0]
    assert "seed_retries" not in kept.spec
    command = regions.train_command(kept.args)
    assert command[command.index("--seed-retries") + 1] == "1"
    more = regions.jobs_for(regions.BenchConfig(decoders=("st",), seed_retries=3), Path("runs"), strip)[0]
    assert more.spec["seed_retries"] == 3 and kept.spec == {k: v for k, v in more.spec.items() if k != "seed_retries"}
    command = regions.train_command(more.args)
    assert command[command.index("--seed-retries") + 1] == "3"
    assert regions.parser().parse_args(["--seed-retries", "3"]).seed_retries == 3
