"""benchmarks/baselines.py's job records: what lets the comparison continue across invocations and machines."""

from __future__ import annotations

import importlib.util
import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from piga.atomic import write_json

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
    assert len(names) == len(set(names)) == 12 + 5 + 5 + 1 + 1  # piga 4 x 3, planet 3 + 2, DDPG 3 + 1 + 1, SAC 1, oracle
    assert "planet-n2000-s1" in names and "ddpg-pixels-s0" in names and "sac-pixels-s0" in names and names[-1] == "oracle"


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
    assert json.loads(bench.record_path(tmp_path, bench.jobs_for(cfg)[0]).read_text())["name"] == "piga-n25-s0"


def test_the_summary_table_has_a_row_per_agent_and_size_over_its_seeds(bench) -> None:
    cfg = bench.PRESETS["budget"]
    records = {}
    for job in bench.jobs_for(cfg):
        success = 0.5 if job.name == "planet-n500-s1" else 1.0
        control = {"success_rate": success, "mean_return": -200.0 if job.name == "planet-n500-s1" else -160.0}
        record = {"control": control, "sweep": {"1.4": {"success_rate": 0.0 if job.agent in ("planet", "ddpg") else 1.0}}}
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
    assert len(rows) == 4 + 3 + 3 + 1 + 1  # piga's 4 sizes, PlaNet-style's 3, DDPG's 3 observations, SAC's 1, the oracle
    assert [r[0] for r in rows[-3:]] == ["| DDPG from pixels", "| SAC from pixels", "| oracle (true state and physics)"]
    planet_500 = next(r for r in rows if r[0] == "| PlaNet-style" and r[1].startswith("500 "))
    assert planet_500[1:6] == ["500 random-action sequences (2 seeds)", "10\u201320 min", "100%, 50%", "\u2212180.0",
                               "0%, 0% (not told)"]
    assert planet_500[7] == "100 ms (50x piga) |"  # 300 ms a plan, one plan per 3 env steps, piga 2 ms a step
    piga_25 = rows[0]
    assert piga_25[5:8] == ["100%, 100%, 100% (told)", "2 goals, 75%", "2.0 ms |"]
    latent = next(r for r in rows if "latent" in r[0])
    assert latent[2] == "15 min (autoencoder included)" and latent[6] == "refused (no goal input)"
