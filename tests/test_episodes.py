"""The episode runner's typed results give the numbers the code gave before they were typed: episodes of the
oracle, of a PlaNet-style run and of SB3 DDPG and SAC runs (trained here with fixed seeds), and a DMC episode.

RECORDED holds what ``run_job`` returned (summary and episodes, plan times left out) when it returned dicts;
the comparison is exact.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from agents.config import CEMConfig
from agents.mpc import MPCConfig
from agents.protocol import Agent
from piga.control.episodes import EpisodeConfig
from piga.control.jobs import ControlJob, build_agent, run_job, run_split
from piga.evaluation.episodes import EpisodeBatch, EpisodeSummary
from tests.test_dmc import needs_dmc

MPC = MPCConfig(cem=CEMConfig(horizon=8, iterations=2, candidates=30, elites=5))
EPISODES = EpisodeConfig(episodes=3, steps=25, hold_steps=5, seed=2)

RECORDED: dict[str, tuple[dict[str, Any], list[dict[str, Any]]]] = {
    "oracle": ({'agent': 'oracle', 'episodes': 3, 'success_rate': 0.0, 'mean_return': -150.67928704893484, 'final_angle_error_mean': 1.4794764718044302, 'time_to_goal_steps_median': None, 'gravity_mult': 1.0, 'goal_angle': 0.0},
       [
        {'start': [3.141592653589793, 0.0], 'return': -181.04908005077448, 'success': False, 'final_angle_error': 2.610099409850953, 'final_speed': 1.394561939808175, 'time_to_goal_steps': None},
        {'start': [-1.497835135494595, -0.4030177131717534], 'return': -127.79031967523002, 'success': False, 'final_angle_error': 0.6196858876298847, 'final_speed': 1.4262045726361536, 'time_to_goal_steps': None},
        {'start': [1.9743385564396059, -0.8161681157298062], 'return': -143.1984614208, 'success': False, 'final_angle_error': 1.2086441179324527, 'final_speed': 0.9588442157393862, 'time_to_goal_steps': None},
       ]),
    "oracle_g14": ({'agent': 'oracle', 'task': 'x', 'episodes': 3, 'success_rate': 0.0, 'mean_return': -155.23710756678713, 'final_angle_error_mean': 1.9699028990788896, 'time_to_goal_steps_median': None, 'gravity_mult': 1.4, 'goal_angle': 0.5},
       [
        {'start': [3.141592653589793, 0.0], 'return': -205.4662685112057, 'success': False, 'final_angle_error': 2.366988367814251, 'final_speed': 3.156862149681051, 'time_to_goal_steps': None},
        {'start': [-1.497835135494595, -0.4030177131717534], 'return': -122.96426812378208, 'success': False, 'final_angle_error': 0.9818605709084496, 'final_speed': 3.132555563519543, 'time_to_goal_steps': None},
        {'start': [1.9743385564396059, -0.8161681157298062], 'return': -137.28078606537358, 'success': False, 'final_angle_error': 2.560859758513968, 'final_speed': 3.861910327291099, 'time_to_goal_steps': None},
       ]),
    "oracle_long": ({'agent': 'oracle', 'episodes': 2, 'success_rate': 1.0, 'mean_return': -253.21133288039064, 'final_angle_error_mean': 0.009187191090416214, 'time_to_goal_steps_median': 51.0, 'gravity_mult': 1.0, 'goal_angle': 0.0},
       [
        {'start': [3.141592653589793, 0.0], 'return': -379.70347687242247, 'success': True, 'final_angle_error': 0.013985309904304799, 'final_speed': 0.06160723209684658, 'time_to_goal_steps': 68},
        {'start': [0.8605556614246863, -0.4604265724722594], 'return': -126.7191888883588, 'success': True, 'final_angle_error': 0.004389072276527628, 'final_speed': 0.04619569112476225, 'time_to_goal_steps': 34},
       ]),
    "planet": ({'agent': 'planet', 'episodes': 3, 'success_rate': 0.0, 'mean_return': -53.77065476664874, 'final_angle_error_mean': 2.9259376535112978, 'time_to_goal_steps_median': None, 'gravity_mult': 1.0, 'goal_angle': 0.0},
       [
        {'start': [3.141592653589793, 0.0], 'return': -77.73590416952746, 'success': False, 'final_angle_error': 3.0326984099881216, 'final_speed': 0.49793520377196665, 'time_to_goal_steps': None},
        {'start': [-1.497835135494595, -0.4030177131717534], 'return': -43.36074082943599, 'success': False, 'final_angle_error': 3.044466043377702, 'final_speed': 6.102975100965185, 'time_to_goal_steps': None},
        {'start': [1.9743385564396059, -0.8161681157298062], 'return': -40.21531930098277, 'success': False, 'final_angle_error': 2.7006485071680704, 'final_speed': 3.4327047882316135, 'time_to_goal_steps': None},
       ]),
    "ddpg": ({'agent': 'ddpg', 'episodes': 3, 'success_rate': 0.0, 'mean_return': -177.60711366499052, 'final_angle_error_mean': 2.859750774529939, 'time_to_goal_steps_median': None, 'gravity_mult': 1.0, 'goal_angle': 0.0},
       [
        {'start': [3.141592653589793, 0.0], 'return': -179.76849098927534, 'success': False, 'final_angle_error': 2.7207002122385706, 'final_speed': 1.4737599317606143, 'time_to_goal_steps': None},
        {'start': [-1.497835135494595, -0.4030177131717534], 'return': -172.3989316593977, 'success': False, 'final_angle_error': 2.803273629230974, 'final_speed': 8.0, 'time_to_goal_steps': None},
        {'start': [1.9743385564396059, -0.8161681157298062], 'return': -180.65391834629852, 'success': False, 'final_angle_error': 3.055278482120272, 'final_speed': 2.2739746828952034, 'time_to_goal_steps': None},
       ]),
    "sac": ({'agent': 'ddpg', 'episodes': 3, 'success_rate': 0.0, 'mean_return': -175.26880455576563, 'final_angle_error_mean': 2.517285326243625, 'time_to_goal_steps_median': None, 'gravity_mult': 1.0, 'goal_angle': 0.0},
       [
        {'start': [3.141592653589793, 0.0], 'return': -244.77174326887098, 'success': False, 'final_angle_error': 3.133682187726352, 'final_speed': 0.04357003059152994, 'time_to_goal_steps': None},
        {'start': [-1.497835135494595, -0.4030177131717534], 'return': -127.29705111880378, 'success': False, 'final_angle_error': 1.7816428680090208, 'final_speed': 3.6966725255771022, 'time_to_goal_steps': None},
        {'start': [1.9743385564396059, -0.8161681157298062], 'return': -153.73761927962212, 'success': False, 'final_angle_error': 2.6365309229955027, 'final_speed': 3.8293701498537214, 'time_to_goal_steps': None},
       ]),
}


def _without_timing(batch: EpisodeBatch) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    record = batch.to_dict()
    return ({k: v for k, v in record["summary"].items() if not k.startswith("plan_ms")},
            [{k: v for k, v in e.items() if not k.startswith("plan_ms")} for e in record["episodes"]])


@pytest.fixture(scope="module")
def runs(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A PlaNet-style run and SB3 DDPG and SAC runs from the state, trained with fixed seeds."""
    from agents.planet.config import PlanetTrainConfig, RSSMConfig
    from agents.planet.train import train_planet
    from agents.sb3.config import SB3Config
    from agents.sb3.train import train_sb3

    folder = tmp_path_factory.mktemp("runs")
    train_planet(tiny_data, folder / "planet",
                 PlanetTrainConfig(steps=4, batch_size=4, chunk_length=8, checkpoint_every=2, threads=1, device="cpu"),
                 RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=1), progress=False)
    tiny = {"steps": 400, "learning_starts": 100, "eval_every": 200, "eval_episodes": 1, "batch_size": 16, "net_arch": (16, 16),
            "buffer_size": 1000, "device": "cpu"}  # the CPU, where piga-control acts: the recorded episodes are its own
    for algo in ("ddpg", "sac"):
        train_sb3(SB3Config(algo=algo, **tiny), folder / algo, progress=False)  # type: ignore[arg-type]
    return {"planet": folder / "planet", "ddpg": folder / "ddpg", "sac": folder / "sac"}


@pytest.mark.parametrize("name, job", [
    ("oracle", ControlJob("oracle", EPISODES, MPC)),
    ("oracle_g14", ControlJob("oracle", replace(EPISODES, gravity_mult=1.4, goal_angle=0.5), replace(MPC, goal_angle=0.5),
                              tags=(("task", "x"),))),
    ("oracle_long", ControlJob("oracle", EpisodeConfig(episodes=2, steps=100, hold_steps=10, seed=0),
                               MPCConfig(cem=CEMConfig(horizon=15, iterations=3, candidates=60, elites=6)))),
])
def test_the_oracles_episodes_are_the_recorded_ones(name: str, job: ControlJob) -> None:
    torch.set_num_threads(1)
    assert isinstance(build_agent(job), Agent)
    assert _without_timing(run_job(job)) == RECORDED[name]


def test_a_batch_split_over_workers_is_the_recorded_one() -> None:
    assert _without_timing(run_split(ControlJob("oracle", EPISODES, MPC), workers=2, progress=False)) == RECORDED["oracle"]


@pytest.mark.parametrize("name, kind, steps", [("planet", "planet", 8), ("ddpg", "ddpg", 25), ("sac", "ddpg", 25)])
@pytest.mark.slow
def test_the_baselines_episodes_are_the_recorded_ones(name: str, kind: str, steps: int, runs: dict[str, Path]) -> None:
    torch.set_num_threads(1)
    job = ControlJob(kind, replace(EPISODES, steps=steps), MPC, model_dir=str(runs[name]))
    assert isinstance(build_agent(job), Agent)
    # the trained networks act in float32, whose kernels round differently on another CPU (vector widths): returns
    # moved by 1e-9 relative on an Intel Xeon against records made on an AMD EPYC; every other field is exact
    _assert_close(_without_timing(run_job(job)), RECORDED[name], rel=1e-6)


def _assert_close(value: Any, recorded: Any, rel: float) -> None:
    """``value == recorded``, but floats within ``rel`` (nested tuples, lists and dicts)."""
    if isinstance(recorded, float):
        assert value == pytest.approx(recorded, rel=rel)
    elif isinstance(recorded, dict):
        assert isinstance(value, dict) and value.keys() == recorded.keys()
        for key in recorded:
            _assert_close(value[key], recorded[key], rel)
    elif isinstance(recorded, (list, tuple)):
        assert isinstance(value, (list, tuple)) and len(value) == len(recorded)
        for v, r in zip(value, recorded):
            _assert_close(v, r, rel)
    else:
        assert value == recorded


def test_a_summary_survives_its_json_record() -> None:
    import json

    summary = run_job(ControlJob("oracle", replace(EPISODES, episodes=1, steps=5), MPC, tags=(("task", "x"),))).summary
    record = json.loads(json.dumps(summary.to_dict()))
    assert list(record)[:3] == ["agent", "task", "episodes"]  # the labels first, then the numbers
    assert EpisodeSummary.from_dict(record) == summary and summary.labels == {"agent": "oracle", "task": "x"}
    assert list(summary.labelled(agent="piga").to_dict().items())[:2] == [("agent", "piga"), ("task", "x")]


@pytest.mark.slow  # one DMC episode; its score, 842, is checked by default through piga-control in
# tests/test_dmc_control.py::test_piga_control_dmc_oracle_scores_and_refuses_gymnasium_options
@needs_dmc
def test_dmc_scores_are_the_episodes_returns() -> None:
    """The oracle's DMC episode from reset seed 2 scored 842 (of 1000) in DMC's units before the runners were one."""
    from piga.control.dmc import DMCControlConfig, OracleSwingUp, dmc_record, run_dmc_episodes

    torch.set_num_threads(1)
    config = DMCControlConfig(episodes=1, seed=2)
    batch = run_dmc_episodes(OracleSwingUp(config.env, config.planner), "oracle", config)
    assert dmc_record(batch) == {"agent": "oracle", "scores": [842.0], "mean": 842.0, "std": 0.0}
    assert batch.summary.labels == {"agent": "oracle"} and np.isfinite(batch.episodes[0].final_angle_error)
