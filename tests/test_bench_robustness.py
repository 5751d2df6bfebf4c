"""benchmarks/robustness.py: its rows, its post-processing of data files, its verdicts, and its records (no training)."""

from __future__ import annotations

import importlib
import json
import os
import stat
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from piga.data.schema import inspect_dataset

from .helpers import ENV, run

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    """The script as a module (it imports its sibling module common, so benchmarks/ goes on the path)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        yield importlib.import_module("robustness")
    finally:
        sys.modules.pop("robustness", None)
        sys.path.remove(str(ROOT / "benchmarks"))


@pytest.fixture(scope="module")
def spring_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 spring sequences x 8 frames (colour, 32 px, with /states)."""
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene

    path = tmp_path_factory.mktemp("spring") / "spring.h5"
    collect_scene(SceneCollectConfig(scene=scene_config("spring"), sequences=6, steps=8, seed=1, workers=1, split=(4, 1, 1)),
                  path, command="test spring", progress=False)
    return path


def test_the_rows_cover_the_issue(bench) -> None:
    rows = bench.rows()
    names = [r.name for r in rows]
    assert len(names) == len(set(names))
    for system in ("spring", "gravity"):
        shapes = {bench.file_shape(r) for r in rows if r.group == system and not r.post}
        assert {n for n, _, _ in shapes} >= {200, 1000, 5000}
        assert {t for _, t, _ in shapes} >= {10, 12, 20, 30}
        options = {o for r in rows if r.group == system for o in r.collect}
        assert {"--radius", "--colors", "--background"} <= options
        posts = {r.post for r in rows if r.group == system}
        assert {"noise:10", "noise:25", "h264:crf=23", "h264:crf=28"} <= posts
    pendulum = [r for r in rows if r.group == "pendulum"]
    shapes = {bench.file_shape(r) for r in pendulum if not r.post}
    assert {n for n, _, _ in shapes} >= {50, 200, 2000} and {t for _, t, _ in shapes} >= {10, 20, 40}
    assert {s for _, _, s in shapes} >= {32, 64, 96}
    assert any("--gravity" in r.collect for r in pendulum) and any("--actuation-gain" in r.collect for r in pendulum)
    assert {"noise:10", "noise:25", "h264:crf=23", "h264:crf=28"} <= {r.post for r in pendulum}
    for system in ("spring", "gravity"):
        seeds = [r for r in rows if r.group == "seeds" and r.system == system]
        assert sorted(r.seed for r in seeds) == list(range(10)) and {r.data_name for r in seeds} == {f"{system}-default"}
    assert [r.name for r in rows if r.renderer] == ["own/spring-opencv"]
    # the records' command (one retry, as they were made): only --seed is added, on the seed rows
    row = next(r for r in rows if r.name == "spring/noise-10")
    assert row.train_command(Path("f.h5"), Path("run")) == ["piga-train-model", "f.h5", "--out", "run", "--seed-retries", "1", "--threads", "1", "--quiet"]
    assert next(r for r in rows if r.name == "seeds/spring-seed3").train_command(Path("f"), Path("r"))[-2:] == ["--seed", "3"]
    # a pendulum's model has no object slots to check: piga-train-model refuses --seed-retries there
    assert "--seed-retries" not in next(r for r in rows if r.name == "pendulum/sequences50").train_command(Path("f"), Path("r"))
    assert bench.select(rows, ["pendulum/size*"]) == [r for r in rows if r.name in ("pendulum/size32", "pendulum/size96")]
    short = next(r for r in rows if r.name == "pendulum/steps10")  # 10 frames < L + T_pred: training shortens T_pred
    assert bench.recipe_windows(short)[0] == 10 and bench.estimate_minutes(short)["train"] > 1
    assert bench.recipe_windows(next(r for r in rows if r.name == "pendulum/default"))[0] == 14


def _assert_same_but_frames(source: Path, target: Path, spec: str) -> np.ndarray:
    with h5py.File(source) as a, h5py.File(target) as b:
        assert set(a) == set(b)
        for name in a:
            assert a[name].shape == b[name].shape and a[name].dtype == b[name].dtype, name
            if name != "frames":
                np.testing.assert_array_equal(a[name][()], b[name][()])
        assert {k: v for k, v in b.attrs.items() if k != "postprocess"} == dict(a.attrs)
        assert json.loads(b.attrs["postprocess"])["spec"] == spec
        changed = a["frames"][()].astype(int) - b["frames"][()]
    inspect_dataset(target)  # valid schema
    assert np.abs(changed).mean() > 0
    return changed


def test_noise_changes_only_the_frames(bench, spring_file: Path, tmp_path: Path) -> None:
    target = tmp_path / "noisy.h5"
    bench.postprocess(spring_file, target, "noise:10")
    changed = _assert_same_but_frames(spring_file, target, "noise:10")
    assert 6 < changed[changed != 0].std() < 14  # σ = 10 levels, less what clipping at 0 removes


@pytest.mark.parametrize("spec", ["h264:crf=28", "h264:crf=23:scale=4"])
def test_h264_changes_only_the_frames(bench, spring_file: Path, tmp_path: Path, spec: str) -> None:
    target = tmp_path / "h264.h5"
    bench.postprocess(spring_file, target, spec)
    changed = _assert_same_but_frames(spring_file, target, spec)
    assert np.abs(changed).mean() < 20  # lossy, yet still the picture


@pytest.mark.slow
def test_h264_of_gray_frames_and_odd_sizes(bench, tiny_data: Path, tmp_path: Path) -> None:
    target = tmp_path / "h264.h5"
    bench.postprocess(tiny_data, target, "h264:crf=23", chunk=5)
    _assert_same_but_frames(tiny_data, target, "h264:crf=23")
    odd = np.random.default_rng(0).integers(0, 256, (5, 33, 35), dtype=np.uint8)
    assert bench.h264_roundtrip(odd, crf=28).shape == odd.shape
    assert bench.h264_roundtrip(np.zeros((4, 9, 7, 3), np.uint8), scale=3).shape == (4, 9, 7, 3)
    with pytest.raises(ValueError, match="h264:crf=C"):
        bench._parse_post("h264:qp=3")


def test_the_own_renderer_simulates_as_piga_and_writes_a_valid_file(bench, tmp_path: Path) -> None:
    from envs.scenes import scene_config, simulate

    rng = np.random.default_rng(0)
    p0, v0 = rng.uniform(10, 20, (3, 2, 2)), rng.normal(0, 8, (3, 2, 2))  # (B, N, 2)
    positions, velocities, fine = bench.simulate_spring(p0, v0, 12)
    expected = simulate(scene_config("spring"), p0, v0, 12)  # piga's generator, written apart
    np.testing.assert_allclose(positions, expected[0], atol=1e-9)
    np.testing.assert_allclose(velocities, expected[1], atol=1e-9)
    assert fine.shape == (11 * 10 + 1, 3, 2, 2)
    path = tmp_path / "own.h5"
    bench.render_spring_opencv(path, sequences=10, steps=6)
    info = inspect_dataset(path)
    assert info.image_shape == (32, 32, 3) and info.split_counts == {"train": 8, "valid": 1, "test": 1}
    assert info.params == {"k": 4.0, "l": 6.0} and info.attrs["scene"] == "spring"
    with h5py.File(path) as f:
        frames, states = f["frames"][()], f["states"][()]
    x, y = np.rint(states[0, 0, :2] - 0.5).astype(int)  # the blue ball's centre pixel
    assert frames[0, 0, y, x, 2] > 200 and frames[0, 0, y, x, :2].max() == 0
    assert ((states[..., :4] > 3) & (states[..., :4] < 29)).all()  # clear of the walls


def _record(exit_code: int = 0, errors: tuple[float, ...] = (0.01,), converged: bool | None = None,
            found: bool = True) -> dict:
    return {"exit_code": exit_code, "stderr_last": "ValueError: too short", "converged": converged,
            "converged_reason": "k still moving" if converged is False else None,
            "parameters": {f"p{i}": {"learned": 1.0, "true": 1.0, "error": e} for i, e in enumerate(errors)},
            "objects": {"found": found}}


@pytest.mark.parametrize("record, verdict", [
    (_record(errors=(0.01, 0.019), converged=True), "pass"),
    (_record(errors=(0.01,)), "pass"),  # converged not reported: read as claimed
    (_record(exit_code=1, errors=()), "flagged"),
    (_record(errors=(0.30,), converged=False), "flagged"),
    (_record(errors=(0.01,), converged=False), "flagged"),
    (_record(errors=(0.01, 0.06), converged=True), "FAIL"),
    (_record(errors=(0.30,)), "FAIL"),
    (_record(errors=()), "FAIL"),  # exit 0 and nothing to judge
    (_record(errors=(0.03,), converged=True), "miss"),
    (_record(errors=(0.05,)), "miss"),
])
def test_score(bench, record: dict, verdict: str) -> None:
    assert bench.score(record)[0] == verdict


def test_converged_field_is_read_from_metrics(bench) -> None:
    assert bench.converged_field({"converged": False, "convergence": {"reason": "flat"}}) == (False, "flat")
    assert bench.converged_field({"converged": True, "convergence": {"reason": "ok"}}) == (True, "ok")
    assert bench.converged_field({}) == (None, None) and bench.converged_field(None) == (None, None)


def test_summary_floors_and_seed_counts(bench) -> None:
    records = []
    for i in range(10):
        for system in ("spring", "gravity"):
            r = _record(errors=(0.01,), found=not (system == "gravity" and i == 0))
            records.append({**r, "row": f"seeds/{system}-seed{i}", "group": "seeds", "system": system})
    records.append({**_record(errors=(0.03,)), "row": "pendulum/x", "group": "pendulum", "system": "pendulum"})
    for r in records:
        r["verdict"] = bench.score(r)[0]
    s = bench.summary(records, len(records))
    assert s["seeds"]["spring"]["success"] == 10 and s["seeds"]["gravity"]["success"] == 9
    assert s["seeds"]["spring"]["met"] and s["seeds"]["gravity"]["met"]
    floors = s["floors"]
    assert floors["every row within 2% or flagged"] == {"met": False, "rows": ["pendulum/x"]}
    assert floors["no row exits 0 with an error > 5% without reporting converged false"]["met"]
    assert s["counts"] == {"pass": 20, "flagged": 0, "miss": 1, "FAIL": 0}
    assert floors["seeds: gravity 9/10"] == {"met": True, "rows": ["seeds/gravity-seed0"]}
    partial = bench.summary(records[:8], len(records))["seeds"]  # 4 runs of each finished: too early to tell
    assert partial["spring"]["met"] is None and partial["gravity"]["met"] is None
    lost = [r for r in records if r["system"] == "gravity"][:2]
    assert bench.summary([{**r, "objects": {"found": False}} for r in lost], 2)["seeds"]["gravity"]["met"] is False


def _command(path: Path, body: str) -> None:
    path.write_text(f"#!{sys.executable}\nimport sys\n{body}")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


@pytest.mark.slow
def test_a_refused_row_is_recorded_and_not_rerun(bench, spring_file: Path, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole flow, as a user would see it, with stand-ins for the commands: piga-collect copies a tiny file,
    piga-train-model refuses it (exit 1)."""
    folder = tmp_path / "bin"
    folder.mkdir()
    calls = tmp_path / "calls"
    _command(folder / "piga-collect", f"import shutil\nshutil.copy({str(spring_file)!r}, sys.argv[sys.argv.index('--out') + 1])\n")
    _command(folder / "piga-train-model", f"open({str(calls)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')\n"
             "print('piga-train-model: error: sequences have 10 frames; training needs 10', file=sys.stderr)\n"
             "sys.exit(1)\n")
    env = {**ENV, "PATH": f"{folder}{os.pathsep}{ENV['PATH']}"}
    out, work = tmp_path / "results" / "robustness", tmp_path / "work"
    args = ("python", str(ROOT / "benchmarks" / "robustness.py"), "--rows", "spring/steps10", "--out", str(out),
            "--work", str(work))
    result = run(*args, env=env)
    assert result.returncode == 0, result.stderr
    record = json.loads(out.with_suffix(".json").read_text())["rows"][0]
    assert record["row"] == "spring/steps10" and record["verdict"] == "flagged" and record["exit_code"] == 1
    assert record["stderr_last"].endswith("training needs 10")
    assert record["train_command"].startswith("piga-train-model ") and "--threads 1 --quiet" in record["train_command"]
    page = out.with_suffix(".md").read_text()
    assert "spring/steps10" in page and "1 flagged" in page and "--rows spring/steps10" in page
    listing = bench.list_rows(bench.Bench(work, out, "", bench.rows()), bench.select(bench.rows(), ["spring/steps1*"]))
    assert "spring/steps10" in listing and " done " in listing and " to do " in listing and "2 rows" in listing
    monkeypatch.setenv("PATH", env["PATH"])
    assert bench.main(list(args[2:])) == 0  # again, in this process
    assert len(calls.read_text().splitlines()) == 1  # the second invocation skipped the finished row
    assert record["commit"]  # the code that trained the row (this checkout's commit)
    fresh = [*args[2:-1], str(tmp_path / "elsewhere")]  # another machine: the published page's rows are kept
    assert bench.main(fresh) == 0
    assert len(calls.read_text().splitlines()) == 1
    assert (tmp_path / "elsewhere" / "records" / "spring--steps10.json").exists()
    (work / "records" / "spring--steps10.json").unlink()  # a deleted record reruns its row, as documented
    (work / "runs" / "spring-steps-10-seed0.run.json").unlink(missing_ok=True)
    assert bench.main(list(args[2:])) == 0
    assert len(calls.read_text().splitlines()) == 2
    out.with_suffix(".md").write_text("stale")  # --render rewrites the page from the records, running nothing
    assert bench.main(["--out", str(out), "--work", str(work), "--render"]) == 0
    assert len(calls.read_text().splitlines()) == 2
    page = out.with_suffix(".md").read_text()
    assert "spring/steps10" in page and "--rows spring/steps10" in page and "--render" not in page
    assert "Machine: " in page and "{" not in page.split("Machine: ")[1].splitlines()[0]  # in words, not a dict


def _stand_ins(tmp_path: Path, spring_file: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Path]:
    """Stand-ins for the commands on PATH (as in the test above): piga-collect copies a tiny file and logs each call,
    piga-train-model refuses the file (exit 1) and logs each call. Returns the two logs."""
    folder = tmp_path / "bin"
    folder.mkdir()
    collected, trained = tmp_path / "collected", tmp_path / "trained"
    _command(folder / "piga-collect", f"import shutil\nopen({str(collected)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')\n"
             f"shutil.copy({str(spring_file)!r}, sys.argv[sys.argv.index('--out') + 1])\n")
    _command(folder / "piga-train-model", f"open({str(trained)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')\n"
             "print('piga-train-model: error: sequences have 10 frames; training needs 10', file=sys.stderr)\n"
             "sys.exit(1)\n")
    monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ['PATH']}")
    return collected, trained


def _comparable(record: dict, work: Path) -> dict:
    """A record without what depends on where and when it ran (the work folder, the wall time, the load)."""
    text = json.dumps({k: v for k, v in record.items() if k not in ("wall_seconds", "load_average_at_end")})
    return json.loads(text.replace(str(work), "WORK"))


def test_rows_in_processes_give_the_records_of_one_process_and_share_their_data_file(
        bench, spring_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two seed rows on one data file, run by the job runner in two processes and in this one: the file is
    collected once (the rows wait on its lock), and the records are the same."""
    collected, trained = _stand_ins(tmp_path, spring_file, monkeypatch)
    records = {}
    for workers in ("2", "1"):
        out, work = tmp_path / f"out{workers}" / "robustness", tmp_path / f"work{workers}"
        assert bench.main(["--rows", "seeds/spring-seed[12]", "--out", str(out), "--work", str(work),
                           "--workers", workers]) == 0
        rows = json.loads(out.with_suffix(".json").read_text())["rows"]
        records[workers] = [_comparable(r, work) for r in rows]
        assert len(collected.read_text().splitlines()) == (1 if workers == "2" else 2)  # once per work folder
    assert len(trained.read_text().splitlines()) == 4
    assert [r["row"] for r in records["2"]] == ["seeds/spring-seed1", "seeds/spring-seed2"]
    assert records["2"] == records["1"]


def test_a_row_that_raises_ends_the_benchmark_with_one_line_and_keeps_the_rows_before(
        bench, spring_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A row that raises for another reason than a file that could not be made (here a bug in scoring) is a
    failed job: one line naming the row, exit 1, no traceback; the row that finished before it keeps its
    record and its page, and the same command continues from there."""
    _stand_ins(tmp_path, spring_file, monkeypatch)
    make_record = bench.make_record

    def broken(row, *args):
        if row.name == "seeds/spring-seed2":
            raise KeyError("verdict")
        return make_record(row, *args)

    monkeypatch.setattr(bench, "make_record", broken)
    out, work = tmp_path / "robustness", tmp_path / "work"
    argv = ["--rows", "seeds/spring-seed[12]", "--out", str(out), "--work", str(work)]
    with pytest.raises(SystemExit) as info:
        bench.main(argv)
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err  # the progress bar's lines, then the one line
    assert err.strip().splitlines()[-1] == "robustness.py: error: job seeds/spring-seed2 failed: KeyError: 'verdict'"
    assert sorted(p.name for p in (work / "records").iterdir()) == ["seeds--spring-seed1.json"]
    assert [r["row"] for r in json.loads(out.with_suffix(".json").read_text())["rows"]] == ["seeds/spring-seed1"]
    monkeypatch.setattr(bench, "make_record", make_record)
    assert bench.main(argv) == 0
    assert len(json.loads(out.with_suffix(".json").read_text())["rows"]) == 2


@pytest.mark.slow
def test_a_tiny_row_end_to_end(tmp_path: Path) -> None:
    """The real commands on the smallest row (pendulum, 50 sequences: a few minutes on one core)."""
    out = tmp_path / "robustness"
    result = run("python", str(ROOT / "benchmarks" / "robustness.py"), "--rows", "pendulum/sequences50", "--out", str(out),
                 "--work", str(tmp_path / "work"), timeout=1200)
    assert result.returncode == 0, result.stderr
    record = json.loads(out.with_suffix(".json").read_text())["rows"][0]
    assert record["exit_code"] == 0 and set(record["parameters"]) == {"g", "a"} and record["objects"]["found"]
    assert record["verdict"] in ("pass", "miss", "flagged")
