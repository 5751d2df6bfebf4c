"""Control episodes: the one episode runner (:func:`run_agent`) for any agent (:class:`agents.protocol.Agent`)
in any environment whose ``info["state"]`` is the true (θ, θ̇), and the pixel pendulum's episodes (:func:`run_episodes`).

Jobs, batches of episodes for the named agents run in worker processes, are in :mod:`piga.control.jobs`;
the typed results and their tables in :mod:`piga.evaluation.episodes`. This module does not import
torch (command lines read :class:`EpisodeConfig`'s defaults quickly).

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
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from tqdm.auto import tqdm

from agents.protocol import Agent
from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
from piga.evaluation.episodes import EpisodeBatch, EpisodeResult, Recording, summarize
from piga.io.choices import check_ranges, check_types

__all__ = ["EpisodeConfig", "EpisodeStart", "Scoring", "merge_results", "parse_range", "run_agent", "run_episodes"]


@dataclass(frozen=True)
class Scoring:
    """How an episode is scored (module docstring), and the environment's gravity multiplier that labels its summary."""

    gravity_mult: float = 1.0
    """The environment's gravity multiplier."""
    goal_angle: float = 0.0
    """θ_goal for scoring (Gymnasium's convention: 0 upright)."""
    hold_steps: int = 20
    """Success needs the goal held for this many final steps."""
    angle_tolerance: float = 0.2
    """Success: |wrap(θ - θ_goal)| below this (rad)."""
    speed_tolerance: float = 1.0
    """Success: |θ̇| below this (rad/s)."""


@dataclass(frozen=True)
class EpisodeStart:
    """How an episode starts: ``env.reset(seed=seed, options={"state": state})`` (no options without a state)."""

    seed: int
    """The env's reset seed."""
    state: tuple[float, ...] | None = None
    """The start (θ, θ̇); None: the env draws it."""


@dataclass(frozen=True)
class EpisodeConfig(Scoring):
    """How episodes are run on the pixel pendulum, and scored (the fields of :class:`Scoring`)."""

    episodes: int = 5
    """Number of episodes."""
    steps: int = 200
    """Steps per episode."""
    seed: int = 0
    """Seed of the start states."""
    hang_first: bool = True
    """Episode 0 starts hanging straight down at rest; the others start at θ ~ U(-π, π), θ̇ ~ U(-1, 1)."""
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

    MAX_EPISODES: ClassVar[int] = 10_000
    """Most episodes one run plays (each is a swing-up of seconds to minutes: more would run for days)."""
    MAX_STEPS: ClassVar[int] = 100_000
    """Most steps per episode (500 times Gymnasium's 200: one such episode already plans for many minutes)."""
    MAX_TOTAL_STEPS: ClassVar[int] = 2_000_000
    """Most control steps one command plays over all its episodes (and a sweep's multipliers and agents): 10,000 of
    Gymnasium's episodes, about 45 min of planning at the default settings; 10,000 episodes of 100,000 steps each
    passed both caps above and would have planned for two weeks without a word."""
    MAX_TOTAL_MODEL_STEPS: ClassVar[float] = 4e10
    """Most imagined model steps one command plans over all its control steps (plans x candidates x horizon x
    iterations): the default planner over :data:`MAX_TOTAL_STEPS`, about 45 min; the largest planner per plan (1e7)
    over 100 episodes of 100,000 steps was weeks."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if not 1 <= self.episodes <= self.MAX_EPISODES:
            raise ValueError(f"episodes must be in [1, {self.MAX_EPISODES}], got {self.episodes}")
        if self.steps > self.MAX_STEPS:
            raise ValueError(f"steps must be at most {self.MAX_STEPS} per episode, got {self.steps}")
        if self.first_episode < 0:
            raise ValueError(f"first_episode must be >= 0, got {self.first_episode}")
        if self.hold_steps < 1 or self.steps < self.hold_steps:
            raise ValueError(f"an episode of {self.steps} steps is too short: success needs the goal held for its last "
                             f"{self.hold_steps} steps (hold_steps >= 1, steps >= hold_steps)")
        if not (self.gravity_mult > 0 and math.isfinite(self.gravity_mult)):
            raise ValueError(f"gravity_mult must be finite and > 0, got {self.gravity_mult}")
        if self.frame_stack < 1:
            raise ValueError(f"frame_stack must be >= 1, got {self.frame_stack}")
        check_ranges(self, {"goal_angle": (-2 * math.pi, 2 * math.pi), "angle_tolerance": (0, math.pi),
                            "speed_tolerance": (0, math.inf)}, above=("angle_tolerance", "speed_tolerance"))

    def starts(self) -> list[EpisodeStart]:
        """Its episodes' starts: episode e (``first_episode`` onwards) from (θ, θ̇) drawn in order from
        ``seed`` and reset with seed ``seed · 1000 + e``."""
        rng = np.random.default_rng(self.seed)
        drawn = [_start(self, e, rng) for e in range(self.first_episode + self.episodes)]  # the earlier ones drawn and dropped
        return [EpisodeStart(self.seed * 1000 + e, tuple(drawn[e].tolist()))
                for e in range(self.first_episode, self.first_episode + self.episodes)]

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


def run_agent(agent: Agent, env: Any, starts: Sequence[EpisodeStart], scoring: Scoring, steps: int | None = None,
              record: int = 0, progress: bool = False, on_episode_end: Callable[[int], None] | None = None,
              keep_plan_ms: bool = False, desc: str = "episodes") -> EpisodeBatch:
    """Runs ``agent`` for one episode from each start in ``env`` (a Gymnasium env whose ``info["state"]``
    is the true (θ, θ̇)) and scores them.

    Args:
        agent: gets the env's observation (the last L frames, uint8 (L, H, W)) and the true state (which
            only an oracle may use); reset after the env at each start.
        steps: steps per episode; None: until the env truncates it.
        record: keep the frames, states and actions of the first ``record`` episodes (for videos).
        on_episode_end: called with the episode's position in this run (0, 1, ...) after each episode.
        keep_plan_ms: keep each episode's per-plan times (for :meth:`EpisodeBatch.merge`). An agent with a
            ``planned`` attribute (one that holds an action for several steps) is timed only at the steps
            where it planned: plan times are per plan.
    """
    episodes: list[EpisodeResult] = []
    recordings: list[Recording] = []
    for index, start in enumerate(tqdm(starts, desc=desc, disable=not progress)):
        obs, info = env.reset(seed=start.seed, options=None if start.state is None else {"state": np.array(start.state)})
        agent.reset()
        states, actions, rewards, plan_times, frames = [info["state"]], [], [], [], [obs[-1]]
        truncated = False
        while (steps is None and not truncated) or (steps is not None and len(actions) < steps):
            t0 = time.perf_counter()
            u = np.asarray(agent.act(obs, info["state"]), dtype=np.float32).reshape(1)
            if getattr(agent, "planned", True):  # an agent that holds an action for some steps says when it planned
                plan_times.append(time.perf_counter() - t0)
            obs, reward, _, truncated, info = env.step(u)
            states.append(info["state"])
            actions.append(float(u[0]))
            rewards.append(float(reward))
            if index < record:
                frames.append(obs[-1])
        episodes.append(_score(np.array(states), rewards, plan_times, start, scoring))
        if on_episode_end is not None:
            on_episode_end(index)
        if index < record:
            recordings.append(Recording(np.array(frames), np.array(states), np.array(actions)))
    summary = summarize(episodes, scoring.gravity_mult, scoring.goal_angle)
    if not keep_plan_ms:
        episodes = [replace(e, plan_ms=()) for e in episodes]
    return EpisodeBatch(summary, tuple(episodes), tuple(recordings))


def _score(s: np.ndarray, rewards: list[float], plan_times: list[float], start: EpisodeStart, scoring: Scoring) -> EpisodeResult:
    """One episode's result from its states (T+1, S), rewards (T,) and plan seconds."""
    err = np.abs(_wrap(s[1:, 0] - scoring.goal_angle))
    inside = (err < scoring.angle_tolerance) & (np.abs(s[1:, 1]) < scoring.speed_tolerance)
    held_from = None
    if inside[-1]:
        outside = np.flatnonzero(~inside)
        held_from = int(outside[-1] + 1) if len(outside) else 0
    return EpisodeResult(
        start=() if start.state is None else start.state,
        return_=float(np.sum(rewards)),
        success=bool(inside[-scoring.hold_steps:].all()),
        final_angle_error=float(err[-1]),
        final_speed=float(abs(s[-1, 1])),
        time_to_goal_steps=held_from,
        plan_ms_median=float(1000 * np.median(plan_times)),
        plan_ms=tuple(float(1000 * t) for t in plan_times),
    )


def run_episodes(agent: Agent, config: EpisodeConfig, record: int = 0, progress: bool = False,
                 on_episode_end: Callable[[int], None] | None = None, keep_plan_ms: bool = False) -> EpisodeBatch:
    """Runs ``config``'s episodes on the pixel pendulum (:func:`run_agent`, with :meth:`EpisodeConfig.starts`)."""
    env = make_pixel_pendulum(config.env_config())
    try:
        return run_agent(agent, env, config.starts(), config, config.steps, record, progress, on_episode_end,
                         keep_plan_ms)
    finally:
        env.close()


def merge_results(config: EpisodeConfig, parts: Sequence[EpisodeBatch]) -> EpisodeBatch:
    """One result from :func:`run_episodes` results (``keep_plan_ms``) of consecutive batches of
    ``config``'s episodes, as one run of them all would give (recordings dropped)."""
    n = sum(len(part.episodes) for part in parts)
    if n != config.episodes:
        raise ValueError(f"the parts hold {n} episodes, the config {config.episodes}")
    return EpisodeBatch.merge(parts, config.gravity_mult, config.goal_angle)


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
    count = (stop - start) / step + 1e-9  # (1e308 - 1) / 1e-308 is infinite: no int() of it
    if not count < 1000:
        raise ValueError(f"{text!r} gives {'more than 1000' if not math.isfinite(count) else int(count) + 1} values; "
                         "at most 1000")
    return [round(start + i * step, 10) for i in range(int(math.floor(count)) + 1)]
