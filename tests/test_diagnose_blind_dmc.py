"""benchmarks/diagnose_blind_dmc.py: its cases, its truth, its label stripping and its scoring (fast);
its whole pipeline on two tiny cases (slow, needs dm_control)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the script imports its sibling modules common, diagnose_blind
    try:
        spec = importlib.util.spec_from_file_location("bench_blind_dmc", ROOT / "benchmarks" / "diagnose_blind_dmc.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop("bench_blind_dmc", None)
        sys.path.remove(str(ROOT / "benchmarks"))


def test_cases_are_seeded_and_cover_the_variants_and_effects(bench) -> None:
    cases = bench.draw_cases(24, 0)
    assert cases == bench.draw_cases(24, 0) and cases != bench.draw_cases(24, 1)
    assert len(cases) == 24 and [c["case"] for c in cases] == list(range(24))
    added = {name for c in cases for name in c["effects"]}
    assert added == set(bench.ADDED) and sum(not c["effects"] for c in cases) == 6
    variants = [c["variant"] for c in cases]
    assert {v["action_repeat"] for v in variants} == {1, 2, 3, 4}
    assert {v["flip"] for v in variants} >= {"none", "camera", "motor"}
    assert len({v["mass"] for v in variants}) > 20 and len({v["camera_distance"] for v in variants}) > 20
    seeds = [c[k] for c in cases for k in ("nominal_seed", "data_seed")]
    assert len(set(seeds)) == len(seeds)


def test_the_truth_holds_what_the_variant_has_and_the_fast_model_lacks(bench) -> None:
    case = {"variant": {"mass": 1.0, "length": 0.5, "damping": 0.1, "action_repeat": 2, "camera_distance": 1.0,
                        "flip": "motor"}, "effects": {"friction": 0.5}}
    true = bench.truth(case)
    assert true["effects"] == ["damping", "flip", "friction", "within_frame"]
    assert true["a"] < 0 and abs(true["b"] - 0.1 / (3 * 1.0 * (0.25 + 0.4 * 0.05**2))) < 1e-9
    single = {**case, "variant": {**case["variant"], "action_repeat": 1, "flip": "none", "damping": 0.0}, "effects": {}}
    assert bench.truth(single)["effects"] == []


def _report(effects: list[str], ambiguity: list[str] | None = None, corrected: dict | None = None) -> dict:
    gap = {"free_run_closure": 0.5, "free_run_gap_closure": 0.9, "closure_basis": "state",
           "mean_free_run_gap_closure": None, "typical_free_run_closure": 0.9}
    return {"verdict_class": "ambiguous" if ambiguity else "+".join(sorted(effects)) or "none",
            "verdict": "v", "effects": [{"effect": e, "value": 1.0} for e in effects], "gap": gap,
            "ambiguity": {"between": ambiguity} if ambiguity else None,
            "corrected": corrected or {"g": 13.08, "a": 1.3289, "b": 0.1329}}


def test_scoring_counts_ambiguity_right_only_with_the_truth_in_it(bench) -> None:
    case = {"variant": {"mass": 1.0, "length": 0.5, "damping": 0.1, "action_repeat": 2, "camera_distance": 1.0,
                        "flip": "none"}, "effects": {}}
    ok = bench.score(case, _report(["damping"], ["within_frame", "speed_clip"]))
    assert ok["top1"] and ok["ambiguous"]
    wrong = bench.score(case, _report([], ["speed_clip", "friction"]))
    assert not wrong["top1"]
    clipped = bench.score(case, _report(["speed_clip", "damping"]))
    assert not clipped["top1"] and clipped["false_effects"] == ["speed_clip"]
    right = bench.score(case, _report(["damping", "within_frame"], corrected={"g": 13.08, "a": 1.3289, "b": 0.1329,
                                                                               "substeps": 2}))
    assert right["top1"] and right["false_effects"] == [] and max(right["parameter_error"].values()) < 0.01
    refused = bench.refused(case, "piga-diagnose: error: refitting g and a diverged")
    assert not refused["top1"] and refused["verdict"].startswith("refused: ")
    summary = bench.summarize([{"score": s} for s in (ok, wrong, clipped, right, refused)])
    assert summary["top1_accuracy"] == 0.4 and summary["ambiguous_rate"] == 0.4 and summary["false_effects"] == 1
    assert summary["refused"] == 1 and summary["parameters_within_3pct"] == 1.0  # of the clear, answered cases


def test_an_explicit_reading_is_scored_under_mujocos_implicit_damping(bench) -> None:
    """One Euler step per frame reads g, a and b low by 1 - h·3b (the explicit convention); the scorer compares
    the same frames' implicit values, from the report's ``damping_convention`` or, in an older report, the
    same conversion."""
    case = {"variant": {"mass": 1.0, "length": 0.5, "damping": 0.1, "action_repeat": 1, "camera_distance": 1.0,
                        "flip": "none"}, "effects": {}}
    true = bench.truth(case)
    factor = 1 / (1 + 0.02 * 3 * true["b"])  # what an exact explicit reading gives (h = 0.02 s)
    explicit = {k: true[k] * factor for k in ("g", "a", "b")}
    older = bench.score(case, _report(["damping"], corrected=explicit))
    assert max(older["parameter_error"].values()) < 1e-9
    report = _report(["damping"], corrected=explicit)
    report["damping_convention"] = {"taken": "explicit", "values": {k: v * 1.01 for k, v in explicit.items()}}
    assert bench.score(case, report)["parameter_error"]["g"] == pytest.approx(abs(1.01 * explicit["g"] / true["g"] - 1))
    assert bench.mujoco_values(case, {**report, "damping_convention": None})["g"] == explicit["g"]  # no damping, no change


def test_every_label_and_hint_is_deleted(bench, tmp_path: Path) -> None:
    path = tmp_path / "case.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("states", data=np.zeros((2, 3, 2)))
        for key, value in {"effects": "{}", "command": "piga-collect", "env_id": "piga/DMCPendulum-v0",
                           "env_config": json.dumps({"action_repeat": 2}), "params": "{}", "dt": 0.04}.items():
            f.attrs[key] = value
    bench.strip_provenance(path)
    with h5py.File(path, "r") as f:
        assert set(f.attrs) == {"dt"} and "states" not in f


@pytest.mark.slow
def test_the_quick_run_goes_through_the_whole_pipeline(bench, tmp_path: Path) -> None:
    pytest.importorskip("dm_control")
    out = tmp_path / "results" / "blind_dmc"
    assert bench.main(["--quick", "--out", str(out), "--work", str(tmp_path / "work")]) == 0
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["summary"]["cases"] == 2 and len(record["runs"]) == 2
    assert "| top-1" in out.with_suffix(".md").read_text()
    with h5py.File(tmp_path / "work" / "case00.h5", "r") as f:
        assert not {"effects", "env_id", "env_config", "params", "command"} & set(f.attrs) and "states" not in f


def test_a_nominal_model_is_kept_only_for_the_same_case_and_recipe(bench, tmp_path: Path, monkeypatch) -> None:
    """Step 1 (collect and train) is skipped for a model that it trained for the same case, file shape and
    training arguments, and redone otherwise."""
    trained: list[list[str]] = []

    class Done:
        returncode, stderr = 0, ""

    def fake_run(command: list[str], **_: object) -> Done:
        trained.append(command)
        run_dir = Path(command[command.index("--out") + 1])
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "checkpoint.pt").write_bytes(b"")
        return Done()

    monkeypatch.setattr(bench, "collect", lambda *a, **k: None)
    monkeypatch.setattr(bench.subprocess, "run", fake_run)
    case = bench.draw_cases(4, 0)[0]
    bench.nominal_model(case, tmp_path, 40, 16, [])
    bench.nominal_model(case, tmp_path, 40, 16, [])
    assert len(trained) == 1
    bench.nominal_model(case, tmp_path, 40, 20, [])  # another file shape
    bench.nominal_model({**case, "nominal_seed": case["nominal_seed"] + 1}, tmp_path, 40, 20, [])  # another file
    assert len(trained) == 3


def test_an_added_friction_acts_at_every_physics_step(bench) -> None:
    """The case's friction is computed from the speed before each physics step (4 per frame here), as a
    real friction acts: the same as driving MuJoCo's steps by hand with the torque set before each."""
    pytest.importorskip("dm_control")
    from envs.dmc import DMCPendulumConfig, DMCPendulumEnv

    config = DMCPendulumConfig(action_repeat=4, damping=0.1)
    env = bench.HingeTorque(DMCPendulumEnv(config), "friction", 2.0)
    seen: list[float] = []
    torque = env.unwrapped.hinge_torque
    env.unwrapped.hinge_torque = lambda q, v: (seen.append(v), torque(q, v))[1]
    env.reset(seed=0, options={"state": [0.3, 0.05]})
    env.step(np.array([0.5], np.float32))
    state = env.unwrapped._state()
    assert len(seen) == 4 and len(set(seen)) == 4 and seen[0] == 0.05
    by_hand = DMCPendulumEnv(config)
    by_hand.reset(seed=0, options={"state": [0.3, 0.05]})
    for _ in range(4):
        data = by_hand.physics.data
        data.qfrc_applied[0] = 3.0 * config.inertia * -2.0 * np.tanh(float(data.qvel[0]) / 0.1)
        by_hand._env.step(np.array([0.5]))
    assert np.allclose(by_hand._state(), state, rtol=0, atol=1e-12)
    held = DMCPendulumEnv(config)  # held over the frame at its first speed, as before: another state
    held.reset(seed=0, options={"state": [0.3, 0.05]})
    held.physics.data.qfrc_applied[0] = 3.0 * config.inertia * -2.0 * np.tanh(0.05 / 0.1)
    held.step(np.array([0.5]))
    assert abs(held._state()[1] - state[1]) > 1e-3
