"""Running control episodes on the pixel pendulum and scoring them.

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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum

if TYPE_CHECKING:
    from agents.mpc import MPCConfig


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
    x1.4 (README, results/control.md); without it, all succeeded. Training data keep the arrow."""

    def __post_init__(self) -> None:
        if self.episodes < 1 or self.steps < self.hold_steps or self.hold_steps < 1:
            raise ValueError(f"need episodes >= 1 and steps >= hold_steps >= 1, got {self}")
        if not (self.gravity_mult > 0 and math.isfinite(self.gravity_mult)):
            raise ValueError(f"gravity_mult must be finite and > 0, got {self.gravity_mult}")


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % (2 * np.pi) - np.pi


def run_episodes(agent: Agent, config: EpisodeConfig, record: int = 0, progress: bool = False,
                 on_episode_end: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Runs the episodes; returns per-episode results and a summary.

    Args:
        agent: controller; gets the last L frames (uint8 (L, H, W)) and the true state (which only
            the oracle may use).
        config: see :class:`EpisodeConfig`.
        record: keep the frames, states and actions of the first ``record`` episodes (for videos).
        on_episode_end: called with the episode index after each episode.
    """
    from tqdm.auto import tqdm

    env = make_pixel_pendulum(PixelPendulumConfig(frame_stack=config.frame_stack, gravity_mult=config.gravity_mult,
                                                  episode_length=config.steps, effects=config.effects,
                                                  draw_torque_arrow=config.torque_arrow))
    rng = np.random.default_rng(config.seed)
    episodes: list[dict[str, Any]] = []
    recordings: list[dict[str, np.ndarray]] = []
    for ep in tqdm(range(config.episodes), desc="episodes", disable=not progress):
        if ep == 0 and config.hang_first:
            start = np.array([math.pi, 0.0])
        else:
            start = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-1, 1)])
        obs, info = env.reset(seed=config.seed * 1000 + ep, options={"state": start})
        agent.reset()
        states, actions, rewards, plan_times, frames = [info["state"]], [], [], [], [obs[-1]]
        for _ in range(config.steps):
            t0 = time.perf_counter()
            u = np.asarray(agent.act(obs, info["state"]), dtype=np.float32).reshape(1)
            plan_times.append(time.perf_counter() - t0)
            obs, reward, _, _, info = env.step(u)
            states.append(info["state"])
            actions.append(float(u[0]))
            rewards.append(float(reward))
            if ep < record:
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
            on_episode_end(ep)
        if ep < record:
            recordings.append({"frames": np.array(frames), "states": s, "actions": np.array(actions)})
    env.close()
    all_plan = np.concatenate([e.pop("plan_ms") for e in episodes])
    swing = [e["time_to_goal_steps"] for e in episodes if e["success"]]
    summary = {
        "episodes": config.episodes,
        "success_rate": float(np.mean([e["success"] for e in episodes])),
        "mean_return": float(np.mean([e["return"] for e in episodes])),
        "final_angle_error_mean": float(np.mean([e["final_angle_error"] for e in episodes])),
        "time_to_goal_steps_median": float(np.median(swing)) if swing else None,
        "plan_ms_median": float(np.median(all_plan)),
        "plan_ms_p95": float(np.percentile(all_plan, 95)),
        "gravity_mult": config.gravity_mult,
        "goal_angle": config.goal_angle,
    }
    return {"summary": summary, "episodes": episodes, "recordings": recordings}


def _default_mpc() -> MPCConfig:
    from agents.mpc import MPCConfig

    return MPCConfig()


@dataclass(frozen=True)
class ControlJob:
    """One batch of episodes for one agent: all a worker process needs to rebuild and run it.

    The agent's goal (``mpc.goal_angle``, what it is told, for example read from a goal image) and
    the scoring goal (``episodes.goal_angle``, the truth) are kept apart on purpose.
    """

    agent: str
    """"piga" (frames -> learned model) or "oracle" (true state, true g = 10 x multiplier, a = 1)."""
    episodes: EpisodeConfig
    """The episodes; its ``gravity_mult`` is the environment's."""
    mpc: MPCConfig = field(default_factory=_default_mpc)
    """The planner; its ``goal_angle`` is the agent's goal."""
    model_dir: str | None = None
    """The run folder of ``piga-train-model`` (for "piga")."""
    tags: tuple[tuple[str, Any], ...] = ()
    """Extra (key, value) pairs copied into the result's summary (labels for tables)."""
    corrected: Any = None
    """For "piga": plan with this physics from ``piga-diagnose`` (:class:`piga.diagnostics.fit.Model`)."""
    camera: Any = None
    """For "piga": read angles by matching frames to the decoder's renders through this camera
    (:class:`piga.diagnostics.vision.Camera`, from ``piga-diagnose``) instead of the encoder."""

    def __post_init__(self) -> None:
        if self.agent not in ("piga", "oracle"):
            raise ValueError(f"agent must be 'piga' or 'oracle', got {self.agent!r}")
        if self.agent == "piga" and not self.model_dir:
            raise ValueError("a 'piga' job needs model_dir")


def build_agent(job: ControlJob) -> Any:
    """The agent a job describes (loads the model for "piga")."""
    from agents.mpc import OracleAgent, PigaMPCAgent

    told = job.episodes.gravity_mult  # the agent is told the environment's multiplier
    if job.agent == "oracle":
        return OracleAgent(g=10.0 * told, a=1.0, config=job.mpc)
    from piga.runs import load_model

    model, _ = load_model(job.model_dir)
    return PigaMPCAgent(model, job.mpc, gravity_mult=told, corrected=job.corrected, camera=job.camera)


def run_job(job: ControlJob) -> dict[str, Any]:
    """Runs one job in this process with one torch thread; returns :func:`run_episodes`' result
    (without recordings), its summary extended with ``agent`` and the job's tags."""
    import torch

    torch.set_num_threads(1)  # small tensors: one thread plans fastest, and workers share the cores
    agent = build_agent(job)
    episodes = job.episodes
    if job.agent == "piga":
        from dataclasses import replace

        episodes = replace(episodes, frame_stack=agent.input_frames)
    result = run_episodes(agent, episodes)
    result.pop("recordings")
    result["summary"] = {"agent": job.agent, **dict(job.tags), **result["summary"]}
    return result


def _worker_init() -> None:
    """A pool worker ends quietly when the pool terminates it (the CLI's SIGTERM handler is for the parent)."""
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is handled by the parent, which then terminates the pool


def run_jobs(jobs: Sequence[ControlJob], workers: int = 1, progress: bool = True) -> list[dict[str, Any]]:
    """Runs jobs, in ``workers`` processes when > 1 (results in the order of ``jobs``)."""
    from tqdm.auto import tqdm

    if workers <= 1 or len(jobs) <= 1:
        return [run_job(j) for j in tqdm(jobs, desc="control jobs", disable=not progress)]
    import multiprocessing as mp

    # fork, as torch's DataLoader does: with spawn, torch's import makes the resource tracker warn
    # about leaked semaphores. The parent has rendered nothing; each child sets one torch thread.
    method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
    with mp.get_context(method).Pool(min(workers, len(jobs)), initializer=_worker_init) as pool:
        return list(tqdm(pool.imap(run_job, jobs), total=len(jobs), desc="control jobs", disable=not progress))


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
