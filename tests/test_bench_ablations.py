"""benchmarks/ablations.py: the page, the slots figure and the JSON from its jobs' records, a rerun that reuses them,
and a failed job's one line. ``piga-collect`` and ``piga-train-model`` are stand-ins (a training writes a metrics.json
whose scores are known, and the run's inspection returns a known reconstruction loss and templates): the benchmark's
bookkeeping is tested, not the models."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The stand-in's prediction MSE per variant, and its learned g.
MSE = {"joint": 0.001, "pred-only": 0.02, "separate": 0.03, "mlp": 0.015, "slots2": 0.01, "slots4": 0.005, "slots5": 0.006}
G = {"joint": 59.0, "pred-only": 3.0, "separate": 12.0, "mlp": 1.0, "slots2": 40.0, "slots4": 55.0, "slots5": 50.0}


@pytest.fixture
def ablations():
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the script imports its sibling modules common and prediction
    spec = importlib.util.spec_from_file_location("bench_ablations", ROOT / "benchmarks" / "ablations.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        for name in (spec.name, "prediction", "common"):
            sys.modules.pop(name, None)
        sys.path.remove(str(ROOT / "benchmarks"))


def _variant(args: list[str]) -> str:
    if "--decoder" in args:
        return "mlp"
    if "--objects" in args:
        return "slots" + args[args.index("--objects") + 1]
    return args[args.index("--loss") + 1]


def _stand_ins(ablations: Any, monkeypatch: pytest.MonkeyPatch, fail: str | None = None) -> list[list[str]]:
    """Commands are recorded, not run: piga-collect writes its file, piga-train-model its metrics.json (or exits 2
    for a run named ``fail``); the run's inspection gives slot images of the run's slot count."""
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
        v = _variant(args)
        out.mkdir(parents=True, exist_ok=True)
        lost, empty = v == "slots2", v == "slots4"
        metrics = {"split": "test", "input_frames": 4, "pred_frames": 12, "extrapolate_frames": 24,
                   "frame_ssim_mean": {"prediction": 1 - 10 * MSE[v], "extrapolation": 1 - 20 * MSE[v]},
                   "frame_mse_mean": {"prediction": MSE[v], "extrapolation": 2 * MSE[v]},
                   "parameters": {"g": G[v]},
                   "parameter_errors": {"g": {"learned": G[v], "true": 60.0, "relative_error": abs(G[v] - 60) / 60}},
                   "objects": {"ratio": 0.9 if lost else 0.1, "lost": lost, "empty_slots": [3] if empty else []},
                   "converged": not (lost or empty), "convergence": {"outcome": "untrained" if lost or empty else "converged"},
                   "training": {"seconds": 60.0, "steps": int(args[args.index("--budget-steps") + 1])}}
        (out / "metrics.json").write_text(json.dumps(metrics))
        return 1 if lost or empty else 0

    def inspect_run(run_dir: Path, data: Path) -> dict[str, Any]:
        v = run_dir.name.split("-", 1)[1].rsplit("-", 1)[0]
        slots = int(v[len("slots"):]) if v.startswith("slots") else 3
        if v == "mlp":
            return {"reconstruction_mse": 0.002}
        import base64
        import io

        buffer = io.BytesIO()
        np.savez_compressed(buffer, objects=np.full((slots, 6, 6, 3), 128, np.uint8), masks=np.zeros((slots, 6, 6), np.uint8))
        return {"reconstruction_mse": 0.001, "templates": base64.b64encode(buffer.getvalue()).decode("ascii")}

    monkeypatch.setattr(sys.modules["prediction"], "logged_command", logged)  # the collection and trainings it runs
    monkeypatch.setattr(ablations, "inspect_run", inspect_run)
    return calls


@pytest.mark.slow
def test_the_page_figure_and_json_are_written_and_a_rerun_reuses_the_records(ablations, tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _stand_ins(ablations, monkeypatch)
    out = tmp_path / "results" / "ablations"
    argv = ["--out", str(out), "--budget-steps", "7", "--jobs", "1"]
    assert ablations.main(argv) == 0
    trained = [c for c in calls if c[0] == "piga-train-model"]
    assert [_variant(c) for c in trained] == ["joint", "pred-only", "separate", "mlp", "slots2", "slots4"]
    assert all(c[c.index("--budget-steps") + 1] == "7" and c[c.index("--seed-retries") + 1] == "0" for c in trained)
    assert [c[2] for c in calls if c[0] == "piga-collect"] == ["gravity"]
    record = json.loads(out.with_suffix(".json").read_text())
    rows = record["summary"]["gravity"]
    assert rows["separate"]["ratio_to_joint"] == pytest.approx(30.0) and rows["joint"]["ratio_to_joint"] == 1.0
    assert rows["mlp"]["mse_reconstruction"] == 0.002 and rows["slots2"]["objects_lost"] == [True]
    page = out.with_suffix(".md").read_text()
    assert "| separate gradients | `--loss separate` | 0.03000 | 30.00 | 0.00100 | g = 12 (80.0% off 60) |" in page
    assert "| 2 | g = 40 (33.3% off 60) | 0.900 | 0.01000 | 0.02000 | 0.00100 | 0.90 (lost; none) | 1 (untrained) |" in page
    assert "| 0.10 (all found; 3) | 1 (untrained) |" in page  # 4 slots: slot 3 empty
    assert f"`python benchmarks/ablations.py {' '.join(argv)}`" in page and "28.1, 0.22" in page
    assert (out.parent / "ablations-slots.png").read_bytes()[:4] == b"\x89PNG"

    calls.clear()
    assert ablations.main(argv) == 0  # every record kept: nothing collected or trained
    assert calls == [] and json.loads(out.with_suffix(".json").read_text())["summary"]["gravity"] == rows
    assert ablations.main([*argv, "--slots", "5"]) == 0  # a new slot count: only it trains
    assert [_variant(c) for c in calls if c[0] == "piga-train-model"] == ["slots5"]


def test_without_slot_runs_no_slots_figure_is_written(ablations, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _stand_ins(ablations, monkeypatch)
    out = tmp_path / "ablations"
    assert ablations.main(["--out", str(out), "--jobs", "1", "--slots", "--schemes", "joint"]) == 0
    assert out.with_suffix(".md").exists() and not (out.parent / "ablations-slots.png").exists()
    assert "-slots.png" not in out.with_suffix(".md").read_text()


def test_a_failed_job_ends_with_one_line_and_keeps_the_records_before(ablations, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    _stand_ins(ablations, monkeypatch, fail="gravity-separate-s0")
    out = tmp_path / "ablations"
    with pytest.raises(SystemExit) as info:
        ablations.main(["--out", str(out), "--jobs", "1", "--slots"])
    assert info.value.code == 1
    err = capsys.readouterr().err
    log = out.parent / "ablations_runs" / "gravity-separate-s0.log"
    assert err == (f"ablations.py: error: job gravity-separate-s0 failed: RuntimeError: 'piga-train-model --loss "
                   f"separate' failed (exit 2); see {log}\n")
    assert sorted(p.stem for p in (out.parent / "ablations_runs" / "records").iterdir()) == [
        "gravity-joint-s0", "gravity-pred-only-s0"]
    assert not out.with_suffix(".md").exists()


def test_an_abbreviated_option_is_refused(ablations) -> None:
    with pytest.raises(SystemExit):
        ablations.parser().parse_args(["--budget", "5"])


def test_no_curriculum_trains_every_run_at_the_full_horizon_and_says_so(ablations, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _stand_ins(ablations, monkeypatch)
    out = tmp_path / "results" / "ablations"
    assert ablations.main(["--out", str(out), "--jobs", "1", "--slots", "--schemes", "pred-only", "--no-curriculum"]) == 0
    trained = [c for c in calls if c[0] == "piga-train-model"]
    assert [_variant(c) for c in trained] == ["joint", "pred-only"]
    assert all(c[c.index("--warmup-fraction") + 1] == "0" and c[c.index("--curriculum-fraction") + 1] == "0"
               for c in trained)
    page = out.with_suffix(".md").read_text()
    assert "| only L_pred | `--loss pred-only --warmup-fraction 0 --curriculum-fraction 0` |" in page
    assert "without the fast recipe's autoencoder warm-up and rollout curriculum" in page
    calls.clear()
    assert ablations.main(["--out", str(out), "--jobs", "1", "--slots", "--schemes", "pred-only"]) == 0
    assert len([c for c in calls if c[0] == "piga-train-model"]) == 2  # the records of the other recipe are not reused
    assert "rollout curriculum" not in out.with_suffix(".md").read_text()
