"""The calibration page's verdicts and separations, on made-up records."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import convergence_calibration as cc  # noqa: E402


def _record(case: str, errors: dict[str, float], pred: float, hold: float, profile: dict[str, Any], code: int) -> dict[str, Any]:
    return {"case": case, "seed": 0, "parameter_errors": errors, "frame_mse_prediction": pred, "frame_mse_background": 0.01,
            "frame_mse_hold": hold, "profile": profile, "exit": code}


def test_the_page_says_which_ratio_separates_the_runs_and_reads_a_blown_up_profile_as_worst() -> None:
    good = _record("good", {"g": 0.01}, 0.001, 0.01, {"g": {"lower": 3.0, "upper": None}}, 0)  # None: blew up
    short = _record("short", {"g": 0.5}, 0.002, 0.012, {"g": {"lower": 1.1, "upper": 0.9}}, 3)
    flat = _record("flat", {"g": 0.7}, 0.008, 0.012, {"g": {"lower": 1.0, "upper": 1.0}}, 0)
    assert cc.lowest_profile(good) == 3.0 and cc.lowest_profile(short) == 0.9
    assert [cc.verdict(r) for r in (good, short, flat)] == ["identified", "not identified", "not identified"]
    lines = "\n".join(cc.summary([good, short, flat]))
    assert "MSE / background: identified runs at most **0.100** (1 runs); runs not identified at least **0.200**" in lines
    assert "the ratio separates them." in lines
    assert "short of its value by the profile: 1; short s0 (not identified)." in lines
    assert "Runs not identified that exit 0 (converged): 1 (flat s0); identified runs that exit 1 or 3: 0." in lines


def test_the_page_gives_the_fastest_tail_of_each_group_where_records_keep_it() -> None:
    """The speed rule's threshold (``speed_tolerance``) is read off these records: each group's fastest tail."""
    good = _record("good", {"g": 0.01}, 0.001, 0.01, {}, 0) | {"tail_speed": {"g": 0.12, "a": -0.4}}
    bad = _record("bad", {"g": 0.5}, 0.002, 0.012, {}, 3) | {"tail_speed": {"g": 1.28, "a": None}}
    old = _record("old", {"g": 0.6}, 0.002, 0.012, {}, 3)  # a record from before the speed was kept
    lines = "\n".join(cc.summary([good, bad, old]))
    assert "The fastest tail of a run identified: 0.40x the sum of its learning rate there (good s0;" in lines
    assert "The fastest tail of a run not identified: 1.28x the sum of its learning rate there (bad s0;" in lines
