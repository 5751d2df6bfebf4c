"""Control episodes on the pixel pendulum: running and scoring them with any agent, and their tables.

Jobs, batches of episodes for the named agents run in worker processes, are in :mod:`piga.control.jobs`.
This module does not import torch (command lines read :class:`EpisodeConfig`'s defaults quickly).

Success is defined precisely. An episode of ``steps`` steps (200 by default) succeeds when, for
each of its last ``hold_steps`` steps (20), |wrap(θ - θ_goal)| < ``angle_tolerance`` (0.2 rad)
and |θ̇| < ``speed_tolerance`` (1 rad/s).

Its time to swing up is the first step from which that condition holds until the end (None
otherwise).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from tqdm.auto import tqdm

from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum


class Agent(Protocol):
    """What an episode needs from a controller."""

    def reset(self) -> None: ...

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class EpisodeConfig:
    """How episodes are run and scored."""

    episodes: int = 5
    """Number of episodes."""
    steps: int = 200
    """Steps per episode."""
    seed: int = 0
    """Seed of the start states."""
    gravity_mult: float = 1.0
    """The environment's gravity multiplier."""
    goal_angle: float = 0.0
    """θ_goal for scoring (Gymnasium's convention)."""
    hang_first: bool = True
    """Episode 0 starts hanging straight down at rest; the others start at θ ~ U(-π, π), θ̇ ~ U(-1, 1)."""
    hold_steps: int = 20
    """Success needs the goal held for this many final steps."""
    angle_tolerance: float = 0.2
    """Success: |wrap(θ - θ_goal)| below this (rad)."""
    speed_tolerance: float = 1.0
    """Success: |θ̇| below this (rad/s)."""
    frame_stack: int = 4
    """Frames the agent sees per step (the model's L)."""
    effects: tuple[tuple[str, float], ...] = ()
    """Unmodelled effects of the environment (a simulated real system; :mod:`envs.effects`)."""
    torque_arrow: bool = False
    """Whether the frames show Gymnasium's torque arrow. Off by default: in closed loop the arrow is
    the controller's own output drawn into its input, right where the pendulum is read near
    upright. With it, 2 of 6 trained models misread the angle there by ~1.5° and failed at gravity
    x1.4 (docs/commands/control.md, results/control.md); without it, all succeeded. Training data keep the arrow."""
    first_episode: int = 0
    """Index of the first episode run: episodes ``first_episode`` to ``first_episode + episodes - 1``
    of the sequence this seed gives, each with its own start and env seed, so a batch split across
    workers (:func:`piga.control.jobs.run_split`) runs the very episodes one process would."""

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"need at least 1 episode, got {self.episodes}")
        if self.first_episode < 0:
            raise ValueError(f"first_episode must be >= 0, got {self.first_episode}")
        if self.hold_steps < 1 or self.steps < self.hold_steps:
            raise ValueError(f"an episode of {self.steps} steps is too short: success needs the goal held for its last "
                             f"{self.hold_steps} steps (hold_steps >= 1, steps >= hold_steps)")
        if not (self.gravity_mult > 0 and math.isfinite(self.gravity_mult)):
            raise ValueError(f"gravity_mult must be finite and > 0, got {self.gravity_mult}")

    def env_config(self) -> PixelPendulumConfig:
        """The environment the episodes run in (the one place its true parameters come from)."""
        return PixelPendulumConfig(frame_stack=self.frame_stack, gravity_mult=self.gravity_mult,
                                   episode_length=self.steps, effects=self.effects, draw_torque_arrow=self.torque_arrow)


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % (2 * np.pi) - np.pi


def _start(config: EpisodeConfig, episode: int, rng: np.random.Generator) -> np.ndarray:
    """Episode ``episode``'s start (θ, θ̇), drawn from ``rng`` (which must have drawn those of the earlier ones)."""
    if episode == 0 and config.hang_first:
        return np.array([math.pi, 0.0])
    return np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-1, 1)])


def run_episodes(agent: Agent, config: EpisodeConfig, record: int = 0, progress: bool = False,
                 on_episode_end: Callable[[int], None] | None = None, keep_plan_ms: bool = False) -> dict[str, Any]:
    """Runs the episodes; returns per-episode results and a summary.

    Args:
        agent: controller; gets the last L frames (uint8 (L, H, W)) and the true state (which only
            the oracle may use).
        config: see :class:`EpisodeConfig`.
        record: keep the frames, states and actions of the first ``record`` episodes (for videos).
        on_episode_end: called with the episode's position in this run (0, 1, ...) after each episode.
        keep_plan_ms: keep each episode's per-step plan times (``plan_ms``, for :func:`merge_results`).
            An agent with a ``planned`` attribute (one that holds an action for several steps) is
            timed only at the steps where it planned: plan times are per plan.
    """
    env = make_pixel_pendulum(config.env_config())
    rng = np.random.default_rng(config.seed)
    for skipped in range(config.first_episode):  # the earlier episodes' starts, drawn and dropped
        _start(config, skipped, rng)
    episodes: list[dict[str, Any]] = []
    recordings: list[dict[str, np.ndarray]] = []
    for index in tqdm(range(config.episodes), desc="episodes", disable=not progress):
        ep = config.first_episode + index
        start = _start(config, ep, rng)
        obs, info = env.reset(seed=config.seed * 1000 + ep, options={"state": start})
        agent.reset()
        states, actions, rewards, plan_times, frames = [info["state"]], [], [], [], [obs[-1]]
        for _ in range(config.steps):
            t0 = time.perf_counter()
            u = np.asarray(agent.act(obs, info["state"]), dtype=np.float32).reshape(1)
            if getattr(agent, "planned", True):  # an agent that holds an action for some steps says when it planned
                plan_times.append(time.perf_counter() - t0)
            obs, reward, _, _, info = env.step(u)
            states.append(info["state"])
            actions.append(float(u[0]))
            rewards.append(float(reward))
            if index < record:
                frames.append(obs[-1])
        s = np.array(states)
        err = np.abs(_wrap(s[1:, 0] - config.goal_angle))
        inside = (err < config.angle_tolerance) & (np.abs(s[1:, 1]) < config.speed_tolerance)
        held_from = None
        if inside[-1]:
            outside = np.flatnonzero(~inside)
            held_from = int(outside[-1] + 1) if len(outside) else 0
        success = bool(inside[-config.hold_steps :].all())
        episodes.append({
            "start": start.tolist(),
            "return": float(np.sum(rewards)),
            "success": success,
            "final_angle_error": float(err[-1]),
            "final_speed": float(abs(s[-1, 1])),
            "time_to_goal_steps": held_from,
            "plan_ms_median": float(1000 * np.median(plan_times)),
            "plan_ms": [float(1000 * t) for t in plan_times],
        })
        if on_episode_end is not None:
            on_episode_end(index)
        if index < record:
            recordings.append({"frames": np.array(frames), "states": s, "actions": np.array(actions)})
    env.close()
    return {"summary": summarize(episodes, config, keep_plan_ms), "episodes": episodes, "recordings": recordings}


def summarize(episodes: Sequence[dict[str, Any]], config: EpisodeConfig, keep_plan_ms: bool = False) -> dict[str, Any]:
    """The summary of episodes (dicts of :func:`run_episodes`, with their ``plan_ms``, which it
    removes unless ``keep_plan_ms``); ``config`` gives the gravity and the goal."""
    all_plan = np.concatenate([e["plan_ms"] if keep_plan_ms else e.pop("plan_ms") for e in episodes])
    swing = [e["time_to_goal_steps"] for e in episodes if e["success"]]
    return {
        "episodes": len(episodes),
        "success_rate": float(np.mean([e["success"] for e in episodes])),
        "mean_return": float(np.mean([e["return"] for e in episodes])),
        "final_angle_error_mean": float(np.mean([e["final_angle_error"] for e in episodes])),
        "time_to_goal_steps_median": float(np.median(swing)) if swing else None,
        "plan_ms_median": float(np.median(all_plan)),
        "plan_ms_p95": float(np.percentile(all_plan, 95)),
        "gravity_mult": config.gravity_mult,
        "goal_angle": config.goal_angle,
    }


def merge_results(config: EpisodeConfig, parts: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One result from :func:`run_episodes` results (``keep_plan_ms``) of consecutive batches of
    ``config``'s episodes, as one run of them all would give (recordings dropped)."""
    episodes = [e for part in parts for e in part["episodes"]]
    if len(episodes) != config.episodes:
        raise ValueError(f"the parts hold {len(episodes)} episodes, the config {config.episodes}")
    return {"summary": summarize(episodes, config), "episodes": episodes, "recordings": []}


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


def summary_row(summary: dict[str, Any]) -> dict[str, Any]:
    """A summary with the derived display fields (degrees) added."""
    return {**summary, "goal_deg": math.degrees(summary["goal_angle"]),
            "final_angle_error_deg": math.degrees(summary["final_angle_error_mean"])}


def summary_markdown(summaries: Sequence[dict[str, Any]], extra: Sequence[tuple[str, str]] = ()) -> str:
    """A Markdown table of episode summaries, one row each; ``extra`` adds (key, header) columns first."""
    columns = [*extra, *SUMMARY_COLUMNS]
    lines = ["| " + " | ".join(h for _, h in columns) + " |", "|" + "---|" * len(columns)]
    for s in map(summary_row, summaries):
        cells = []
        for key, _ in columns:
            v = s.get(key)
            if key == "success_rate":
                cells.append(f"{100 * v:.0f}%")
            elif isinstance(v, float):
                cells.append(f"{v:.2f}" if abs(v) < 100 else f"{v:.1f}")
            else:
                cells.append("–" if v is None else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def parse_range(text: str) -> list[float]:
    """``"0.5:1.8:0.1"`` -> [0.5, 0.6, ..., 1.8] (both ends included, rounded to 10 decimals).

    Raises:
        ValueError: not START:STOP:STEP with START <= STOP and STEP > 0, or more than 1000 values.
    """
    parts = text.split(":")
    try:
        start, stop, step = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"expected START:STOP:STEP such as 0.5:1.8:0.1, got {text!r}") from None
    if not all(map(math.isfinite, (start, stop, step))) or step <= 0 or stop < start:
        raise ValueError(f"need finite START <= STOP and STEP > 0, got {text!r}")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    if n > 1000:
        raise ValueError(f"{text!r} gives {n} values; at most 1000")
    return [round(start + i * step, 10) for i in range(n)]
