"""Control jobs: batches of episodes for the piga agent or the oracle, run in worker processes.

A :class:`ControlJob` holds all a worker needs to rebuild its agent (a run folder, not a model),
so that jobs pickle; :func:`run_jobs` runs them through the one job runner (:func:`piga.io.pool.run_pool`:
local processes or a Ray cluster), one torch thread each, and no worker outlives an interrupted command.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, Protocol

import torch
from agents.dynamics import Dynamics
from agents.protocol import Agent
from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent, StateReader
from piga.control.episodes import EpisodeConfig, merge_results, run_episodes
from piga.evaluation.episodes import EpisodeBatch
from piga.io.checkpoint import RunKind, read_run_record
from piga.world.model import PhysicsModel
from piga.io.choices import check_choices
from piga.io.runs import load_model
from piga.io.pool import Backend, run_pool


class AgentCorrection(Protocol):
    """What changes a piga agent's physics and the way it reads frames (for example a diagnosis:
    :class:`piga.control.corrected.Correction`). Built into the agent in the worker process
    from the loaded model, so it must pickle."""

    def dynamics(self, model: PhysicsModel, gravity_mult: float) -> Dynamics:
        """The dynamics to plan with, for ``model``'s agent told gravity changed by ``gravity_mult``."""
        ...

    def reader(self, model: PhysicsModel) -> StateReader | None:
        """The state reader to use, or None to keep the model's encoder."""
        ...


@dataclass(frozen=True)
class ControlJob:
    """One batch of episodes for one agent: all a worker process needs to rebuild and run it.

    The agent's goal (``mpc.goal_angle``, what it is told, for example read from a goal image) and
    the scoring goal (``episodes.goal_angle``, the truth) are kept apart on purpose.
    """

    agent: Literal["piga", "oracle", "planet", "ddpg"]
    """"piga" (frames -> learned model), "oracle" (true state, the environment's true g and a), or a
    baseline's kind, "planet" or "ddpg" (:class:`~piga.io.checkpoint.RunKind`; not told of a gravity change)."""
    episodes: EpisodeConfig
    """The episodes; its ``gravity_mult`` is the environment's."""
    mpc: MPCConfig = field(default_factory=MPCConfig)
    """The planner; its ``goal_angle`` is the agent's goal."""
    model_dir: str | None = None
    """The run folder of ``piga-train-model`` (for "piga") or of ``piga-baseline`` (for a baseline)."""
    tags: tuple[tuple[str, Any], ...] = ()
    """Extra (key, value) pairs copied into the result's summary (labels for tables)."""
    correction: AgentCorrection | None = None
    """For "piga": plan with this correction's dynamics and read frames with its reader (from ``piga-diagnose``)."""
    told: bool = True
    """For "piga": whether the agent is told the environment's gravity multiplier (``episodes.gravity_mult``) and
    scales its learned g by it; False plans with the learned g unscaled (``piga-control --not-told``)."""
    reward_head: str | None = None
    """For "piga": plan against this learned reward head (:func:`agents.reward_head.save_reward_head`'s file)
    instead of Gymnasium's cost."""

    def __post_init__(self) -> None:
        check_choices(self)  # "oracle" or a RunKind's value
        if self.agent != "piga" and (not self.told or self.reward_head is not None):
            raise ValueError(f"told=False and reward_head are the piga agent's; got agent {self.agent!r}")
        if self.agent != "oracle" and not self.model_dir:
            raise ValueError(f"a {self.agent!r} job needs model_dir")
        if self.agent != "oracle" and RunKind(self.agent).is_baseline and self.correction is not None:
            raise ValueError(f"a {self.agent!r} job runs as trained; it takes no correction")
        if self.agent == "oracle" and self.correction is not None:
            raise ValueError("an 'oracle' job plans with the true physics; it takes no correction")

    @property
    def name(self) -> str:
        """The job in words, for a line that names it: agent, gravity, episodes and tags."""
        e = self.episodes
        tags = "".join(f", {key} {value}" for key, value in self.tags)
        return f"{self.agent} at gravity x{e.gravity_mult:g}, episodes {e.first_episode}-{e.first_episode + e.episodes - 1}{tags}"


def build_agent(job: ControlJob) -> Agent:
    """The agent a job describes (loads the model for "piga" and the baselines). The piga agent is
    told the environment's gravity multiplier (unless ``told`` is False) and plans against Gymnasium's cost
    or its ``reward_head``; the oracle takes the environment's true g and a; a
    baseline runs as trained."""
    if job.agent == "oracle":
        return OracleAgent.for_env(job.episodes.env_config(), job.mpc)
    if RunKind(job.agent).is_baseline:
        from piga.control.registry import baseline_agent

        assert job.model_dir is not None
        return baseline_agent(RunKind(job.agent), job.model_dir, seed=job.mpc.seed)
    assert job.model_dir is not None
    model, _ = load_model(job.model_dir)
    told = job.episodes.gravity_mult if job.told else 1.0
    cost = None
    if job.reward_head is not None:
        from agents.reward_head import LearnedCost, load_reward_head

        cost = LearnedCost(load_reward_head(job.reward_head))
    if job.correction is None:
        return PigaMPCAgent(model, job.mpc, gravity_mult=told, cost=cost)
    return PigaMPCAgent(model, job.mpc, gravity_mult=told, dynamics=job.correction.dynamics(model, told),
                        reader=job.correction.reader(model), cost=cost)


def run_job(job: ControlJob, keep_plan_ms: bool = False) -> EpisodeBatch:
    """Runs one job in this process with one torch thread; returns :func:`run_episodes`' result
    (without recordings), its summary extended with ``agent`` and the job's tags (``keep_plan_ms``:
    each episode keeps its per-step plan times, for :func:`run_split`'s merge)."""
    torch.set_num_threads(1)  # small tensors: one thread plans fastest, and workers share the cores
    agent = build_agent(job)
    episodes = job.episodes
    if not isinstance(agent, OracleAgent):
        episodes = replace(episodes, frame_stack=agent.input_frames)  # type: ignore[attr-defined]
    return _tagged(job, run_episodes(agent, episodes, keep_plan_ms=keep_plan_ms))


def agent_name(agent: str, model_dir: str | None) -> str:
    """A table's name of an agent: its kind, but for a "ddpg" run the algorithm its record names (``sac``,
    ``drqv2``: all are ``piga-baseline ddpg`` runs)."""
    if agent != RunKind.DDPG.value or model_dir is None:
        return agent
    algo = (read_run_record(model_dir)[0].get("ddpg") or {}).get("algo")
    return algo if isinstance(algo, str) and algo.isidentifier() else agent


def _tagged(job: ControlJob, result: EpisodeBatch) -> EpisodeBatch:
    """``result`` without recordings, its summary labelled with ``agent`` (``piga (not told)`` for a piga agent not told
    the gravity multiplier: a row of its own in a table; a DDPG run's algorithm, :func:`agent_name`) and the job's
    tags."""
    name = agent_name(job.agent, job.model_dir)
    return result.labelled(**{"agent": name if job.told else f"{name} (not told)", **dict(job.tags)})


def split_job(job: ControlJob, parts: int) -> list[ControlJob]:
    """``job``'s episodes as up to ``parts`` jobs of consecutive episodes (sizes differing by at most one)."""
    n, first = job.episodes.episodes, job.episodes.first_episode
    parts = max(1, min(parts, n))
    sizes = [n // parts + (i < n % parts) for i in range(parts)]
    starts = [first + sum(sizes[:i]) for i in range(parts)]
    return [replace(job, episodes=replace(job.episodes, first_episode=s, episodes=k)) for s, k in zip(starts, sizes)]


def run_split(job: ControlJob, workers: int = 1, progress: bool = True, backend: Backend | None = None) -> EpisodeBatch:
    """Runs ``job``'s episodes split into ``workers`` jobs: processes, or on a Ray ``backend``, tasks
    (:func:`run_jobs`). The result is the one :func:`run_job` gives in one process (the same episodes, starts,
    seeds and scores; each agent is reset per episode), except the plan times, which are measured with the
    jobs sharing the machines."""
    on_ray = backend is not None and backend.kind == "ray"
    if not on_ray and (workers <= 1 or job.episodes.episodes <= 1):
        return run_job(job)
    results = run_jobs(split_job(job, workers), workers, progress, keep_plan_ms=True, backend=backend)
    return _tagged(job, merge_results(job.episodes, results))


def run_jobs(jobs: Sequence[ControlJob], workers: int = 1, progress: bool = True, keep_plan_ms: bool = False,
             backend: Backend | None = None) -> list[EpisodeBatch]:
    """Runs jobs in ``workers`` processes when > 1, or on ``backend`` (:func:`piga.io.pool.run_pool`); the results
    in the order of ``jobs`` (``keep_plan_ms`` as for :func:`run_job`).

    On KeyboardInterrupt (Ctrl-C, or SIGTERM turned into it by :func:`piga.cli.common.run_cli`) the
    pool terminates its workers (Ray: cancels its tasks) before the exception propagates; a worker whose
    parent is killed ends too. It prints nothing: the command that loaded the run warns once if it did not converge.
    """
    return run_pool(functools.partial(run_job, keep_plan_ms=keep_plan_ms), jobs, workers, progress, desc="control jobs",
                    backend=backend)
