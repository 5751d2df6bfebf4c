"""benchmarks/identify_time.py: its 'before' recipe is the fast preset as it was, on the default file."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import identify_time  # noqa: E402
from piga.training.train import TrainConfig, plan_training  # noqa: E402


def test_before_is_the_old_fast_recipe_on_the_default_file() -> None:
    plan = plan_training(identify_time.recipe("before", 0), 400 * 27)  # 400 train sequences x 27 windows
    assert (plan.epochs, plan.steps_per_epoch, plan.warmup_steps, plan.curriculum_steps, plan.average_steps) == \
        (16, 337, 200, 600, 337)


def test_recipes_by_name() -> None:
    assert identify_time.recipe("today", 2) == TrainConfig(threads=2, device="cpu")  # the CPU's times on any machine
    assert identify_time.recipe("budget-1500", 0).budget_steps == 1500
    with pytest.raises(ValueError, match="unknown recipe"):
        identify_time.recipe("fastest", 0)


def test_error_curve_is_relative_to_the_truth() -> None:
    curve = identify_time.error_curve([[10, 5.0, 0.5], [20, 10.0, 1.1]], ["g", "a"], {"g": 10.0, "a": 1.0})
    assert curve["step"] == [10, 20] and curve["g"] == [0.5, 0.0] and curve["a"] == pytest.approx([0.5, 0.1])
