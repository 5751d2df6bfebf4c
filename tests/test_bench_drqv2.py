"""benchmarks/drqv2_curves.py and published_scores.py: the published curve read at a run's frames, a DMC run's
steps counted as frames, and scores outside the published seeds' range marked; DrQ-v2's precision benchmark."""

from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import drqv2_curves  # noqa: E402
import published_scores  # noqa: E402

#: Two published seeds: linear from 0 to 100 and to 300 over 100,000 env steps.
SEEDS = [{"task": "dmc_pendulum_swingup", "method": "drqv2", "seed": s, "xs": [0, 100_000], "ys": [0, top]}
         for s, top in ((0, 100), (1, 300))] + [{"task": "dmc_cheetah_run", "method": "drqv2", "seed": 0, "xs": [0], "ys": [0]}]


def _record(env: str | None, curve: list[tuple[int, float]], **config: object) -> dict[str, object]:
    return {"command": "piga-baseline ddpg --out RUN", "commit": "abc",
            "config": {"steps": 50_000, **({"env": env} if env else {}), **config},
            "learning_curve": [{"step": s, "eval_mean_return": r, "seconds": 1.0} for s, r in curve], "train_seconds": 120.0}


def test_the_published_curve_is_read_per_seed_and_runs_are_set_beside_it(tmp_path: Path) -> None:
    scores = tmp_path / "scores.json.gz"
    with gzip.open(scores, "wt") as f:
        json.dump(SEEDS, f)
    published = tmp_path / "published.json"
    assert published_scores.main([str(scores), "--task", "dmc_pendulum_swingup", "--source", "test", "--out", str(published)]) == 0
    assert [s["seed"] for s in json.loads(published.read_text())["seeds"]] == [0, 1]
    assert published_scores.main([str(scores), "--task", "nope", "--source", "t", "--out", str(tmp_path / "n.json")]) == 1
    at = drqv2_curves.published_at(json.loads(published.read_text()), 50_000)
    assert (at["mean"], at["min"], at["max"], at["above_200"]) == (100.0, 50.0, 150.0, 0)

    runs = tmp_path / "dmc.json"  # 25,000 env steps are 50,000 frames: the range there is 50-150
    runs.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(25_000, 160.0), (50_000, 250.0)], encoder_precision="bfloat16",
                                     learning_starts=2000, view="fixed")))
    pixel = tmp_path / "pixel.json"  # a run from before --env and --encoder-precision: the pixel pendulum, float32
    pixel.write_text(json.dumps(_record(None, [(5000, -900.0), (10_000, -150.0)], learning_starts=4000)))
    out = tmp_path / "page"
    reference = tmp_path / "reference.json"
    reference.write_text(json.dumps({"command": "python benchmarks/reference_policies.py", "eval_episodes": 2,
                                     "scores": {"piga/DMCPendulum-v0": {"no torque": [1.0, 2.0, 30.0]}}}))
    assert drqv2_curves.main(["--out", str(out), "--published", str(published), "--runs", str(runs), str(pixel),
                              "--reference", str(reference)]) == 0
    page = out.with_suffix(".md").read_text()
    assert "same 2 evaluation starts" in page and ": no torque 1.5. A run's score" in page
    assert "| 50,000 | 160.0 (above) | 100 ± 50 | 50–150 | 0 of 2 |" in page
    assert "| 100,000 | 250.0 | 200 ± 100 | 100–300 | 1 of 2 |" in page
    assert "| dmc | piga/DMCPendulum-v0 | camera 0, 64x64 gray | auto, bfloat16 | 4,000 | 50,000 (50,000) | 250.0 | 50,000 (mark 200) | 2 |" in page
    assert "| pixel | piga/PixelPendulum-v0 | Gymnasium's render, 64x64 gray | auto, float32 | 4,000 | 10,000 (50,000) | −150.0 | 10,000 (mark -200) | 2 |" in page
    assert out.with_suffix(".png").stat().st_size > 0


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_the_precision_benchmark_times_both_and_compares_one_update(tmp_path: Path) -> None:
    import drqv2_precision

    out = tmp_path / "precision"
    assert drqv2_precision.main(["--out", str(out), "--fill", "300", "--repeats", "1", "--updates", "1", "--warmup", "0"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert set(record["timing"]) == {"float32", "bfloat16"} and record["speedup"] > 0
    assert 0.9 < record["agreement"]["encoder_gradient_cosine"] <= 1.0 + 1e-6
    with pytest.raises(SystemExit):
        drqv2_precision.main(["--out", str(out), "--fill", "10"])


@pytest.mark.slow  # two checkpoints of a pixel run, each way: about 15 s
def test_the_checkpoint_memory_benchmark_measures_both_ways(tmp_path: Path) -> None:
    import checkpoint_memory

    out = tmp_path / "memory"
    assert checkpoint_memory.main(["--out", str(out), "--buffer-size", "600"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert set(record["ways"]) == {"bytes", "file"}
    for way in record["ways"].values():
        assert way["buffer_gb"] > 0 and way["checkpoint_gb"] >= way["buffer_gb"] and way["write_peak_over_gb"] >= 0
    assert "its own file, streamed (piga's)" in out.with_suffix(".md").read_text()


@pytest.mark.slow  # 5 rendered episodes of each reference policy: about 17 s
def test_policies_that_learned_nothing_are_scored_at_the_runs_evaluation_starts(tmp_path: Path) -> None:
    import reference_policies

    out = tmp_path / "reference"
    assert reference_policies.main(["--out", str(out), "--envs", "piga/PixelPendulum-v0", "--episodes", "5"]) == 0
    scores = json.loads(out.with_suffix(".json").read_text())["scores"]["piga/PixelPendulum-v0"]
    assert set(scores) == set(reference_policies.POLICIES) and all(len(r) == 5 for r in scores.values())
    assert all(sum(returns) / 5 < -200 for returns in scores.values())  # none of them swings up
    # the same seed plays the same starts: the runs' evaluation is seeded, and so is the random policy
    again = reference_policies.scores("piga/PixelPendulum-v0", "uniform random", 0, 5)
    assert again == scores["uniform random"]
    with pytest.raises(SystemExit):
        reference_policies.main(["--out", str(out), "--episodes", "2"])


@pytest.mark.parametrize("which, content, needle", [
    ("runs", [1, 2], "must be a learning_curve.py record"),
    ("runs", {"config": {"steps": 10}, "learning_curve": [{"step": "5", "eval_mean_return": 1.0}]}, "'learning_curve' as a list"),
    ("runs", {"config": {"steps": 10}, "learning_curve": [], "train_seconds": "60"}, "'train_seconds' as a number"),
    ("published", {"source": "s", "seeds": [{"xs": ["0"], "ys": [1]}]}, "must give 'seeds'"),
    ("published", {"seeds": []}, "must be a published_scores.py record"),
    ("reference", {"command": "c", "eval_episodes": 5, "scores": {"e": {"p": ["x"]}}}, "must give 'scores'"),
])
def test_the_curves_page_refuses_records_of_another_shape(which: str, content: object, needle: str, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Each was an internal error (a TypeError or a KeyError deep inside)."""
    good_run = tmp_path / "run.json"
    good_run.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(2500, 1.0)])))
    published = tmp_path / "published.json"
    published.write_text(json.dumps({"source": "s", "seeds": [{"xs": [0, 10], "ys": [0, 1]}]}))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(content))
    paths = {"runs": good_run, "published": published, "reference": None, which: bad}
    argv = ["--out", str(tmp_path / "page"), "--runs", str(paths["runs"]), "--published", str(paths["published"])]
    assert drqv2_curves.main(argv + (["--reference", str(bad)] if which == "reference" else [])) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{bad}: " in err and needle in err, err
    assert not (tmp_path / "page.md").exists()


def test_the_curves_page_refuses_to_write_over_its_input(tmp_path: Path) -> None:
    run = tmp_path / "page.json"
    run.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(2500, 1.0)])))
    with pytest.raises(SystemExit):
        drqv2_curves.main(["--out", str(tmp_path / "page"), "--runs", str(run), "--published", str(run)])
    assert json.loads(run.read_text())["config"]["steps"] == 50_000  # untouched


@pytest.mark.parametrize("content, needle", [(b"\x1f\x8b\x08\x00garbage", "published_scores.py: error:"),
                                             (b"", "published_scores.py: error:")])
def test_the_published_scores_refuse_a_damaged_file(content: bytes, needle: str, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    scores = tmp_path / "scores.json.gz"
    scores.write_bytes(content)
    assert published_scores.main([str(scores), "--task", "t", "--source", "s", "--out", str(tmp_path / "o.json")]) == 1
    assert needle in capsys.readouterr().err and not (tmp_path / "o.json").exists()
    with gzip.open(scores, "wt") as f:
        json.dump([{"task": "t", "method": "m", "seed": 0, "xs": [0, 1], "ys": ["a", 1]}], f)
    assert published_scores.main([str(scores), "--task", "t", "--source", "s", "--out", str(tmp_path / "o.json")]) == 1
    assert "each curve of t must give" in capsys.readouterr().err


def test_a_page_of_dmc_runs_only_draws_without_a_warning(tmp_path: Path) -> None:
    """The pixel pendulum's empty axis warned "No artists with labels found to put in legend" on stderr."""
    import warnings

    run = tmp_path / "run.json"
    run.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(2500, 1.0)])))
    published = tmp_path / "published.json"
    published.write_text(json.dumps({"source": "s", "seeds": [{"xs": [0, 10_000], "ys": [0, 1]}]}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert drqv2_curves.main(["--out", str(tmp_path / "page"), "--runs", str(run), "--published", str(published)]) == 0
    # its one point (5,000 frames: 1.0 against the seeds' 0.5) is above every seed: the page says so in words
    assert "run is above every published seed from 5,000 frames on" in (tmp_path / "page.md").read_text()


def test_a_point_below_every_published_seed_is_named_with_how_low_the_seeds_go_next(tmp_path: Path) -> None:
    """A run under the seeds' range is said so in words, beside the lowest seed there and at the later points; the
    buffer sentence is the runs' own, and says every transition was kept only when each buffer held its run."""
    run = tmp_path / "run.json"  # 2,500 env steps are 5,000 frames (seeds 5 and 10 there); 5,000 are 10,000 (0 and 20)
    run.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(2500, 1.0), (5000, 4.0)], buffer_size=50_000)))
    published = tmp_path / "published.json"
    published.write_text(json.dumps({"source": "s", "seeds": [{"xs": [0, 5000, 10_000], "ys": [0, 5, 0]},
                                                              {"xs": [0, 5000, 10_000], "ys": [0, 10, 20]}]}))
    assert drqv2_curves.main(["--out", str(tmp_path / "page"), "--runs", str(run), "--published", str(published)]) == 0
    page = (tmp_path / "page.md").read_text()
    assert "run is below every published seed at 1 point(s): 1.0 at 5,000 frames (the lowest seed 5.0; 0.0 at 10,000)." in page
    assert "a replay buffer of 50,000 transitions (its 1e6; each holds every transition of its run)" in page
    run.write_text(json.dumps(_record("piga/DMCPendulum-v0", [(2500, 1.0)], buffer_size=10_000)))  # under its 50,000 steps
    assert drqv2_curves.main(["--out", str(tmp_path / "page"), "--runs", str(run), "--published", str(published)]) == 0
    page = (tmp_path / "page.md").read_text()
    assert "a replay buffer of 10,000 transitions (its 1e6); 5" in page


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_the_step_time_benchmark_times_each_part_and_the_whole_loop(tmp_path: Path) -> None:
    import drqv2_step_time

    out = tmp_path / "step"
    assert drqv2_step_time.main(["--out", str(out), "--fill", "300", "--repeats", "1", "--loop", "2"]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    parts = record["result"]["parts_ms"]
    assert set(parts) == {"env_step", "act", "sample", "update"} and all(v > 0 for v in parts.values())
    assert parts["update"] > parts["sample"]  # the update samples its batch, then trains on it
    assert record["result"]["loop_ms_per_step"] > 0 and "env steps per second" in out.with_suffix(".md").read_text()
