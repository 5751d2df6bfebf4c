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
