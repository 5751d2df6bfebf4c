"""Control episodes' typed results and their tables: one episode (:class:`EpisodeResult`), a batch's
summary (:class:`EpisodeSummary`) and a batch (:class:`EpisodeBatch`), as the episode runner
(:mod:`piga.control.episodes`) returns them for any agent and environment.

An episode succeeds when, for each of its last ``hold_steps`` steps, the angle is within a tolerance
of the goal and the speed below one (:class:`piga.control.episodes.EpisodeConfig`). Its return is the
sum of the env's rewards: on dm_control's pendulum that is DMC's own score.

This module imports neither torch nor the environments.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

__all__ = ["SUMMARY_COLUMNS", "EpisodeBatch", "EpisodeResult", "EpisodeSummary", "Recording", "summarize", "summary_markdown",
           "summary_row"]


@dataclass(frozen=True)
class EpisodeResult:
    """One episode's scores."""

    start: tuple[float, ...]
    """The start state (θ, θ̇); empty where the env drew it."""
    return_: float
    """Sum of the env's rewards (``"return"`` in JSON)."""
    success: bool
    """The goal was held for the last ``hold_steps`` steps."""
    final_angle_error: float
    """|wrap(θ - θ_goal)| at the end (rad)."""
    final_speed: float
    """|θ̇| at the end (rad/s)."""
    time_to_goal_steps: int | None
    """The first step from which the goal held until the end (None: it did not hold at the end)."""
    plan_ms_median: float
    """Median milliseconds per plan."""
    plan_ms: tuple[float, ...] = ()
    """Milliseconds of each plan, where kept (for :meth:`EpisodeBatch.merge`)."""

    def to_dict(self) -> dict[str, Any]:
        """The JSON record (without the per-plan times)."""
        return {"start": list(self.start), "return": self.return_, "success": self.success,
                "final_angle_error": self.final_angle_error, "final_speed": self.final_speed,
                "time_to_goal_steps": self.time_to_goal_steps, "plan_ms_median": self.plan_ms_median}


@dataclass(frozen=True)
class EpisodeSummary:
    """A batch of episodes in one row: the numbers the tables show, and the row's labels."""

    episodes: int
    """Number of episodes."""
    success_rate: float
    """Fraction that succeeded."""
    mean_return: float
    """Mean of their returns."""
    final_angle_error_mean: float
    """Mean final |wrap(θ - θ_goal)| (rad)."""
    time_to_goal_steps_median: float | None
    """Median time to the goal over the successful episodes (None: none succeeded)."""
    plan_ms_median: float
    """Median milliseconds per plan, over all plans."""
    plan_ms_p95: float
    """95th percentile of the milliseconds per plan."""
    gravity_mult: float
    """The environment's gravity multiplier."""
    goal_angle: float
    """θ_goal of the scoring (rad)."""
    labels: Mapping[str, Any] = field(default_factory=dict)
    """What the row is ("agent", and a job's tags such as "task" or "physics"), shown in tables as extra columns."""

    def labelled(self, **labels: Any) -> EpisodeSummary:
        """This summary with ``labels`` added before its own (a label given again takes the new value)."""
        return replace(self, labels={**labels, **{k: v for k, v in self.labels.items() if k not in labels}})

    def to_dict(self) -> dict[str, Any]:
        """The JSON record: the labels, then the numbers."""
        numbers = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "labels"}
        return {**self.labels, **numbers}

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> EpisodeSummary:
        """The summary of :meth:`to_dict`'s record (keys that are not numbers are labels)."""
        names = {f.name for f in fields(cls)} - {"labels"}
        return cls(**{k: v for k, v in record.items() if k in names},
                   labels={k: v for k, v in record.items() if k not in names})


@dataclass(frozen=True)
class Recording:
    """What an episode showed and did."""

    frames: np.ndarray
    """uint8 (T+1, H, W): the newest frame after reset and after each step."""
    states: np.ndarray
    """(T+1, S): the true state after reset and after each step."""
    actions: np.ndarray
    """(T,): the actions."""


@dataclass(frozen=True)
class EpisodeBatch:
    """A batch of episodes of one agent: the summary, each episode, and the recorded ones."""

    summary: EpisodeSummary
    episodes: tuple[EpisodeResult, ...]
    recordings: tuple[Recording, ...] = ()

    @property
    def returns(self) -> list[float]:
        """Each episode's return (on dm_control's pendulum, DMC's score)."""
        return [e.return_ for e in self.episodes]

    def labelled(self, **labels: Any) -> EpisodeBatch:
        """This batch without recordings, its summary labelled (:meth:`EpisodeSummary.labelled`)."""
        return EpisodeBatch(self.summary.labelled(**labels), self.episodes)

    def to_dict(self) -> dict[str, Any]:
        """The JSON record: summary and episodes (recordings are not saved)."""
        return {"summary": self.summary.to_dict(), "episodes": [e.to_dict() for e in self.episodes]}

    @classmethod
    def merge(cls, parts: Sequence[EpisodeBatch], gravity_mult: float, goal_angle: float) -> EpisodeBatch:
        """One batch from consecutive batches of the same episodes (each with its per-plan times), as one
        run of them all would give (recordings dropped)."""
        episodes = tuple(e for part in parts for e in part.episodes)
        return cls(summarize(episodes, gravity_mult, goal_angle), tuple(replace(e, plan_ms=()) for e in episodes))


def summarize(episodes: Sequence[EpisodeResult], gravity_mult: float, goal_angle: float) -> EpisodeSummary:
    """The summary of ``episodes``, which must hold their per-plan times; ``gravity_mult`` and ``goal_angle`` label the row."""
    all_plan = np.concatenate([e.plan_ms for e in episodes])
    swing = [e.time_to_goal_steps for e in episodes if e.success]
    return EpisodeSummary(
        episodes=len(episodes),
        success_rate=float(np.mean([e.success for e in episodes])),
        mean_return=float(np.mean([e.return_ for e in episodes])),
        final_angle_error_mean=float(np.mean([e.final_angle_error for e in episodes])),
        time_to_goal_steps_median=float(np.median(swing)) if swing else None,
        plan_ms_median=float(np.median(all_plan)),
        plan_ms_p95=float(np.percentile(all_plan, 95)),
        gravity_mult=gravity_mult,
        goal_angle=goal_angle,
    )


SUMMARY_COLUMNS: tuple[tuple[str, str], ...] = (
    ("agent", "agent"),
    ("gravity_mult", "gravity x"),
    ("goal_deg", "goal (deg)"),
    ("episodes", "episodes"),
    ("success_rate", "success"),
    ("mean_return", "mean return"),
    ("final_angle_error_deg", "final angle error (deg)"),
    ("time_to_goal_steps_median", "steps to goal (median)"),
    ("plan_ms_median", "plan ms (median)"),
    ("plan_ms_p95", "plan ms (p95)"),
)


def summary_row(summary: EpisodeSummary) -> dict[str, Any]:
    """A summary's record with the derived display fields (degrees) added."""
    return {**summary.to_dict(), "goal_deg": math.degrees(summary.goal_angle),
            "final_angle_error_deg": math.degrees(summary.final_angle_error_mean)}


def summary_markdown(summaries: Sequence[EpisodeSummary], extra: Sequence[tuple[str, str]] = ()) -> str:
    """A Markdown table of episode summaries, one row each; ``extra`` adds (label, header) columns first."""
    columns = [*extra, *SUMMARY_COLUMNS]
    lines = ["| " + " | ".join(h for _, h in columns) + " |", "|" + "---|" * len(columns)]
    for s in map(summary_row, summaries):
        cells = []
        for key, _ in columns:
            v = s.get(key)
            if key == "success_rate":
                cells.append(f"{100 * v:.0f}%")
            elif key == "gravity_mult":  # as the command line gives it: x0.001 and x1.001 are not "0.00" and "1.00"
                cells.append(f"{v:g}")
            elif isinstance(v, float):
                cells.append(f"{v:.2f}" if abs(v) < 100 else f"{v:.1f}")
            else:
                cells.append("–" if v is None else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
