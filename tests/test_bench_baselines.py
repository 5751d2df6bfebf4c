"""benchmarks/baselines.py's job records: what lets the comparison continue across invocations and machines."""

from __future__ import annotations

import importlib.util
import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from piga.io.atomic import write_json

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the script imports its sibling module common
    try:
        spec = importlib.util.spec_from_file_location("bench_baselines", ROOT / "benchmarks" / "baselines.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # dataclasses look their module up there
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop("bench_baselines", None)
        sys.path.remove(str(ROOT / "benchmarks"))


def test_the_budget_preset_has_one_job_per_run(bench) -> None:
    names = [job.name for job in bench.jobs_for(bench.PRESETS["budget"])]
    assert len(names) == len(set(names)) == 21 + 8 + 5 + 1 + 2 + 1  # piga 7 x 3, planet 5 + 3, DDPG 3 + 1 + 1, SAC 1, DrQ-v2 2, oracle
    assert {"planet-n1000-s1", "planet-n2000-s1", "ddpg-pixels-s0", "sac-pixels-s0"} <= set(names) and names[-1] == "oracle"
    assert "drqv2-pixels-s0" in names


def test_the_committed_records_are_kept_by_the_budget_preset(bench) -> None:
    """A change to the preset or to a job's spec must not silently discard hours of committed runs."""
    cfg = bench.PRESETS["budget"]
    folder = ROOT / "results" / "baselines_runs"
    committed = {path.stem for path in (folder / "records").glob("*.json")}
    jobs = [job for job in bench.jobs_for(cfg) if job.name in committed]
    assert len(jobs) == len(committed) >= 17  # every committed record is a job of the preset
    assert [job.name for job in jobs if bench.kept_record(folder, job, cfg) is None] == []


def test_a_record_is_reused_only_for_the_same_settings(bench, tmp_path: Path) -> None:
    cfg = bench.PRESETS["budget"]
    planet, piga = (next(j for j in bench.jobs_for(cfg) if j.name == name) for name in ("planet-n500-s1", "piga-n25-s0"))
    for job in (planet, piga):
        path = bench.record_path(tmp_path, job)
        path.parent.mkdir(exist_ok=True)
        write_json(path, {"spec": bench.job_spec(job, cfg), "control": {"success_rate": 1.0}})
        assert bench.kept_record(tmp_path, job, cfg)["control"] == {"success_rate": 1.0}
    longer = replace(cfg, planet_steps=cfg.planet_steps + 1)
    assert bench.kept_record(tmp_path, planet, longer) is None  # trained further: run (continue) it again
    assert bench.kept_record(tmp_path, piga, longer) is not None  # piga's runs do not depend on it
    assert bench.kept_record(tmp_path, piga, replace(cfg, episodes=cfg.episodes + 1)) is None


def test_run_all_returns_kept_records_without_collecting_data(bench, tmp_path: Path) -> None:
    cfg = bench.PRESETS["budget"]
    for job in bench.jobs_for(cfg):
        bench.record_path(tmp_path, job).parent.mkdir(exist_ok=True)
        write_json(bench.record_path(tmp_path, job), {"spec": bench.job_spec(job, cfg), "name": job.name})
    records = bench.run_all(cfg, tmp_path)
    assert all(kept["name"] == name for name, kept in records.items())
    assert not list(tmp_path.glob("*.h5"))
    (tmp_path / "records" / "oracle.json").unlink()
    assert bench.run_all(cfg, tmp_path, only=("piga", "ddpg-state-s0"))["oracle"] is None  # not asked for: left to another invocation
    assert json.loads(bench.record_path(tmp_path, bench.jobs_for(cfg)[0]).read_text())["name"] == "piga-n2-s0"


def test_the_summary_table_has_a_row_per_agent_and_size_over_its_seeds(bench) -> None:
    cfg = bench.PRESETS["budget"]
    records = {}
    for job in bench.jobs_for(cfg):
        success = 0.5 if job.name == "planet-n500-s1" else 1.0
        control = {"success_rate": success, "mean_return": -200.0 if job.name == "planet-n500-s1" else -160.0, "episodes": 20}
        record = {"control": control, "sweep": {"1.4": {"success_rate": 0.0 if job.agent in ("planet", "ddpg") else 1.0}},
                  "machine": {"cpu_family_model": "25/17"}}
        if job.agent != "oracle":
            record["train_seconds"] = 600.0 * (1 + job.seed)
        if job.agent == "piga":
            record.update(plan_ms=2.0, goals=[{"piga": {"success_rate": 1.0}}, {"piga": {"success_rate": 0.5}}])
        if job.agent == "planet":
            record.update(plan_ms=300.0, action_repeat=3)
        if job.agent == "ddpg":
            record["metrics"] = {"autoencoder_train_seconds": 300.0} if job.obs == "latent" else {}
        records[job.name] = record
    rows = [line.split(" | ") for line in bench.summary_table(records, cfg).splitlines()[2:]]
    assert len(rows) == 7 + 5 + 3 + 1 + 1 + 1  # piga's 7 sizes, PlaNet-style's 5, DDPG's 3 observations, SAC's 1, DrQ-v2's 1, the oracle
    assert [r[0] for r in rows[-4:]] == ["| DDPG from pixels", "| SAC from pixels", "| DrQ-v2 from pixels",
                                         "| oracle (true state and physics)"]
    planet_500 = next(r for r in rows if r[0] == "| PlaNet-style" and r[1].startswith("500 "))
    assert planet_500[1:6] == ["500 random-action sequences (2 seeds)", "10\u201320 min", "100%, 50%", "\u2212180.0",
                               "0%, 0% (not told)"]
    assert planet_500[7] == "100 ms (50x piga) |"  # 300 ms a plan, one plan per 3 env steps, piga 2 ms a step
    piga_2 = rows[0]
    assert piga_2[5:8] == ["100%, 100%, 100% (told)", "2 goals, 75%", "2.0 ms |"]
    latent = next(r for r in rows if "latent" in r[0])
    assert latent[2] == "15 min (autoencoder included)" and latent[6] == "refused (no goal input)"


def _records(bench, cfg) -> dict:
    """A full set of synthetic job records, with every field the results page reads."""
    machine = {"cpu": "record CPU", "cpu_family_model": "1/2", "cores": 2, "torch": "2.13.0+cpu"}
    sweep_keys = [f"{m:g}" for m in bench.parse_range(cfg.sweep)]
    records = {}
    for job in bench.jobs_for(cfg):
        success = 0.5 if job.agent == "planet" and job.sequences < 2000 else 1.0
        record = {"machine": machine, "control": {"success_rate": success, "mean_return": -170.0, "episodes": 20},
                  "sweep": {k: {"success_rate": 1.0 if job.agent in ("piga", "oracle") else 0.0} for k in sweep_keys}}
        if job.agent != "oracle":
            record["train_seconds"] = 600.0
        if job.agent == "piga":
            record.update(plan_ms=2.0, goals=[{"goal_deg": 10.0, "read_deg": 10.1, "piga": {"success_rate": 1.0},
                                               "planet": "refused: no goal input", "ddpg": "refused: no goal input"}])
        if job.agent == "planet":
            record.update(plan_ms=300.0, action_repeat=2)
        if job.agent == "ddpg":
            record["metrics"] = {"learning_curve": [{"step": 1000, "eval_mean_return": -1200.0}, {"step": 2000, "eval_mean_return": -190.0}],
                                 "first_step_reaching_minus_200": 2000, "final_eval_mean_return": -190.0, "steps": job.steps,
                                 "train_seconds": 600.0}
        records[job.name] = record
    return records


def _page(bench, cfg, records, tmp_path: Path) -> tuple[dict, str]:
    record = {"command": "python benchmarks/baselines.py --out X --preset budget", "preset": "budget",
              "config": bench.asdict(cfg), "machine": {"cpu": "test CPU", "cores": 2, "torch": "2"}, "wall_seconds": 1.0,
              **bench.aggregate(records, cfg)}
    record["figures"] = bench.figures(record, tmp_path / "b")
    return record, bench.markdown(record)


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_a_page_written_part_way_names_the_runs_still_to_run(bench, tmp_path: Path) -> None:
    """The page is written from the records there are (a PlaNet-style run takes hours), and says what it lacks."""
    cfg = bench.PRESETS["budget"]
    records = _records(bench, cfg)
    record, page = _page(bench, cfg, records, tmp_path)
    assert record["pending"] == [] and "Part-way" not in page and "pending" not in page
    assert [f["met"] for f in record["floors"]] == [True, True, True, True, True]  # PlaNet-style: 80% first at 2000
    # the data needed at equal success: PlaNet-style crosses 80% between 1000 (50%) and 2000 (100%), piga is at 100%
    # from its smallest size, so the ratio is a lower bound
    at_80 = record["data_ratio"][0]
    assert at_80["numerator"]["value"] == pytest.approx(1000 * 2 ** 0.6) and at_80["denominator"]["bound"] == "at_most"
    assert at_80["ratio"]["bound"] == "at_least" and at_80["ratio"]["value"] == pytest.approx(1000 * 2 ** 0.6 / 2)
    assert "## Data needed at equal success" in page and record["data_ratio_claim"].startswith(
        "At 80% success, the PlaNet-style model needs 1,516 (95%: ") and "at least 758x the data" in record["data_ratio_claim"]

    for name in ("planet-n2000-s0", "planet-n2000-s1", "ddpg-state-s1", "sac-pixels-s0"):
        records[name] = None
    records["planet-n100-s0"] = {**records["planet-n100-s0"], "machine": {"cpu": "other CPU", "cpu_family_model": "9/9", "cores": 2, "torch": "2.13.0+cpu"}}
    record, page = _page(bench, cfg, records, tmp_path)
    assert record["pending"] == ["planet-n2000-s0", "planet-n2000-s1", "ddpg-state-s1", "sac-pixels-s0"]
    assert "**Part-way: 33 of 37 runs have a record.**" in page
    assert "Machines: 2 (each run's under Compute), torch 2.13.0+cpu," in page  # the records', not the invocation's ("test CPU")
    assert "test CPU" not in page and "- other CPU (family/model 9/9), 2 cores: planet-n100-s0" in page
    floors = {f["floor"][:20]: f for f in record["floors"]}
    planet = floors["PlaNet-style >= 80% "]
    assert (planet["measured"], planet["met"]) == ("at no size", False)  # on the records there are, and says it may change
    assert planet["pending"] == ["planet-n2000-s0", "planet-n2000-s1"] and "no (so far: 2 runs pending)" in page
    assert floors["DDPG from state reac"]["measured"] == "2 of 2" and floors["DDPG from state reac"]["pending"] == ["ddpg-state-s1"]
    row = next(r for r in record["summary_table"].splitlines() if r.startswith("| PlaNet-style | 2000 "))
    assert row.split(" | ")[3:5] == ["pending, pending", "pending"]
    assert "| DDPG from the true state | 30k env steps (3 seeds) | 10 min | 100%, pending, 100% |" in record["summary_table"]
    assert record["sweep"]["runs"]["planet"] == "planet-n1000-s0"  # the best among those with a record (a tie: the most data)
    # plan times are compared on the same CPU only: piga was not timed on planet-n100-s0's
    assert [(row["cpu"], row["ratio_per_step"]) for row in record["plan_time"]] == [("1/2", 75.0), ("9/9", None)]
    assert "| 150 ms (piga not timed on its CPU) |" in record["summary_table"] and "| 150 ms (75x piga) |" in record["summary_table"]
    # a row whose seeds ran on two CPUs gives each CPU's plan time: no median across machines
    records["planet-n500-s1"] = {**records["planet-n500-s1"], "plan_ms": 100.0, "machine": records["planet-n100-s0"]["machine"]}
    row = next(r for r in _page(bench, cfg, records, tmp_path)[0]["summary_table"].splitlines() if r.startswith("| PlaNet-style | 500 "))
    assert row.endswith("| 150 ms (75x piga) on CPU 1/2; 50 ms (piga not timed on its CPU) on CPU 9/9 |")
    assert floors["piga plans >= 20x fa"]["measured"] == "75.0x on CPU 1/2"

    for job in bench.jobs_for(cfg):  # nothing but the oracle: a page still, of what there is
        if job.agent != "oracle":
            records[job.name] = None
    record, page = _page(bench, cfg, records, tmp_path)
    assert record["sweep"]["agents"] == ["oracle"] and record["goals"] == []
    assert record["plan_time"] == [] and record["floors"][-1]["measured"] == "no CPU with both timed yet"
    assert record["data_ratio"] == [] and record["data_ratio_claim"] == "" and "Data needed" not in page


def test_the_readme_baselines_table_is_the_committed_summary() -> None:
    """The README's Baselines table is results/baselines.json's summary_table, verbatim (regenerate, then paste)."""
    summary = json.loads((ROOT / "results" / "baselines.json").read_text())["summary_table"]
    assert summary in (ROOT / "README.md").read_text()


def test_the_readme_data_claim_is_the_committed_one() -> None:
    """The README's sentence on the data each agent needs is results/baselines.json's, verbatim (regenerate, then paste)."""
    claim = json.loads((ROOT / "results" / "baselines.json").read_text())["data_ratio_claim"]
    assert claim and claim in " ".join((ROOT / "README.md").read_text().split())


def test_a_record_holds_the_commit_and_every_setting_and_is_not_run_again(bench, tmp_path: Path) -> None:
    """The tiny preset's oracle job, end to end through the shared runner: its record names the code's commit
    and the episodes' and planner's settings in full; a second invocation keeps it."""
    from dataclasses import asdict

    from agents.mpc import MPCConfig
    from piga.io.pool import git_commit

    cfg = replace(bench.PRESETS["tiny"], workers=1)
    records = bench.run_all(cfg, tmp_path, only=("oracle",))
    record = records["oracle"]
    assert [name for name, r in records.items() if r is not None] == ["oracle"]
    saved = json.loads(bench.record_path(tmp_path, bench.Job("oracle", "oracle")).read_text())
    assert saved == record and record["spec"] == bench.job_spec(bench.Job("oracle", "oracle"), cfg)
    assert record["commit"] == git_commit() and {"machine", "control", "sweep", "config"} <= set(record)
    assert record["config"]["planner"] == json.loads(json.dumps(asdict(MPCConfig())))
    assert record["config"]["episodes"] == json.loads(json.dumps(asdict(bench.episode_config_for("oracle", cfg))))
    assert record["config"]["episodes"]["steps"] == cfg.episode_steps
    mtime = bench.record_path(tmp_path, bench.Job("oracle", "oracle")).stat().st_mtime_ns
    assert bench.run_all(cfg, tmp_path, only=("oracle",))["oracle"] == record  # kept, not run again
    assert bench.record_path(tmp_path, bench.Job("oracle", "oracle")).stat().st_mtime_ns == mtime


def test_a_piga_record_holds_its_runs_training_configs(bench, tiny_data: Path, tmp_path: Path) -> None:
    from dataclasses import fields

    from piga.world.model import ModelConfig

    cfg = bench.PRESETS["tiny"]
    run = tmp_path / "piga-n8-s0"
    seconds = bench.train_piga(tiny_data, run, 0, cfg, 8)
    assert seconds > 0
    configs = bench.hyperparameters(bench.Job("piga-n8-s0", "piga", 8, 0), cfg, run)
    assert configs["train"]["epochs"] == bench.piga_epochs(cfg, 8) and configs["train"]["batch_size"] == 16
    assert set(configs["model"]) == {f.name for f in fields(ModelConfig)} and configs["model"]["pred_frames"] == 4
    assert {"episodes", "planner"} <= set(configs)


def test_the_estimate_of_some_jobs_is_theirs(bench) -> None:
    cfg = bench.PRESETS["budget"]
    jobs = bench.jobs_for(cfg)
    assert bench.estimate(cfg, jobs) == bench.estimate(cfg)
    two = [job for job in jobs if job.name in ("piga-n5-s0", "piga-n10-s0")]
    part = bench.estimate(cfg, two)
    assert part["planet episodes (core-s)"] == 0 and 0 < part["wall"] < bench.estimate(cfg)["wall"] / 20
    assert part["train (core-s)"] == sum(bench.job_train_cost(cfg, job) for job in two)


@pytest.mark.slow  # a tiny run of the benchmark's training or timing (5-15 s): opt-in, as the
# benchmark itself is
def test_drqv2_is_a_third_model_free_row_scored_as_ddpgs_runs(bench, tmp_path: Path) -> None:
    """DrQ-v2 from pixels: its own jobs, spec, cost, rows and pending cells, beside DDPG's and SAC's runs."""
    cfg = bench.PRESETS["budget"]
    jobs = {job.name: job for job in bench.jobs_for(cfg)}
    job = jobs["drqv2-pixels-s0"]
    assert (job.agent, job.algo, job.obs, job.steps, job.seed) == ("ddpg", "drqv2", "pixels", 12000, 0)
    assert [j.name for j in bench.jobs_for(bench.PRESETS["full"]) if j.algo == "drqv2"] == [f"drqv2-pixels-s{s}" for s in (0, 1, 2)]
    assert [(j.name, j.steps) for j in bench.jobs_for(bench.PRESETS["tiny"]) if j.algo == "drqv2"] == [("drqv2-pixels-s0", 400)]
    assert bench.job_spec(job, cfg)["algo"] == "drqv2" and "algo" not in bench.job_spec(jobs["ddpg-pixels-s0"], cfg)
    # its 4000 warm-up steps render only; one run fits 90 min of one core
    cost = bench.job_train_cost(cfg, job)
    assert cost == pytest.approx(4000 * bench.COST_S["ddpg_pixels_warmup_step"] + 8000 * bench.COST_S["drqv2_pixels_step"])
    assert cost < 90 * 60
    tiny = bench.PRESETS["tiny"]
    assert bench.job_train_cost(tiny, bench.Job("drqv2-pixels-s0", "ddpg", obs="pixels", steps=400, algo="drqv2")) == pytest.approx(
        100 * bench.COST_S["ddpg_pixels_warmup_step"] + 300 * bench.COST_S["drqv2_pixels_step"])  # the tiny preset's warm-up

    records = _records(bench, cfg)
    for name in ("drqv2-pixels-s0", "drqv2-pixels-s1"):
        records[name] = {**records[name], "control": {"success_rate": 1.0, "mean_return": -150.0, "episodes": 20}}
    record, page = _page(bench, cfg, records, tmp_path)
    assert [(r["algo"], r["obs"]) for r in record["ddpg"]][-3:] == [("sac", "pixels"), ("drqv2", "pixels"), ("drqv2", "pixels")]
    assert record["sweep"]["runs"]["ddpg"].startswith("ddpg-")  # DDPG's sweep is DDPG's own best run, however DrQ-v2 did
    assert "| DrQ-v2 | pixels | 0 | 12000 | 2000 | -190.0 | 100% | 600 |" in page
    assert "| DrQ-v2 from pixels | 12k env steps (2 seeds) | 10 min | 100%, 100% | \u2212150.0 | 0%, 0% (not told) | refused (no goal input) |  |" in page
    records["drqv2-pixels-s0"] = records["drqv2-pixels-s1"] = None
    record, page = _page(bench, cfg, records, tmp_path)
    assert record["pending"] == ["drqv2-pixels-s0", "drqv2-pixels-s1"] and "\nPending: drqv2-pixels-s0, drqv2-pixels-s1.\n" in page
    assert "| DrQ-v2 from pixels | 12k env steps (2 seeds) |  | pending, pending | pending | pending, pending (not told) |" \
        in record["summary_table"]
    assert [f["pending"] for f in record["floors"]] == [[]] * 5  # no floor waits for it


def test_the_page_says_what_the_invocation_that_wrote_it_ran(bench) -> None:
    assert "ran no job: it read the records" in bench._invocation_line({"jobs_run": [], "wall_seconds": 1.0})
    line = bench._invocation_line({"jobs_run": ["planet-n1000-s1"], "wall_seconds": 5400.0})
    assert "90.0 min, running planet-n1000-s1 (records kept" in line
    assert "102.2 min (records kept" in bench._invocation_line({"wall_seconds": 6132.0})  # a record from before the field
