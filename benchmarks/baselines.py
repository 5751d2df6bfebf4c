"""Benchmark: piga against the PlaNet-style world model and SB3 DDPG, side by side (the paper's Figure 5).

Every agent is scored by the same episodes (:mod:`piga.control.episodes`: starts, seeds, success), on the
same machine:

1. **Sample efficiency**: success rate and mean return against the number of training sequences,
   for piga (``piga-train-model``'s recipe) and the PlaNet-style model trained on the same files
   (nested subsets of one random-action collection), over seeds; the oracle as a line.
2. **DDPG learning curves**: EvalCallback's mean return against env steps, from pixels, from an
   autoencoder's latent and from the true state, with the first step at which each reached -200;
   SAC, DDPG's stronger sibling, from pixels, where DDPG's actor saturates; and DrQ-v2 (DDPG from
   pixels with an augmented encoder trained by the critic, 3-step returns; :mod:`agents.sb3.drqv2`).
3. **Zero-shot gravity sweep**: piga told the multiplier, the oracle, PlaNet-style and DDPG not told.
4. **Goal images**: piga reaches them; the baselines refuse (no goal input), as recorded.
5. **Plan time per step**: piga's CEM against PlaNet-style latent CEM, measured in this run.
6. **Compute**: training wall time of each agent, and the machine.

    python benchmarks/baselines.py --out results/baselines --preset budget  # what 2 CPU cores allow (hours)
    python benchmarks/baselines.py --out results/baselines                  # the full comparison (days on 2 cores)
    python benchmarks/baselines.py --out runs/check --preset tiny          # the pipeline end to end, in minutes
    python benchmarks/baselines.py --out X --preset budget --estimate      # the cost estimate only

Each run is a job: train (continuing a stopped run), then measure everything the comparison reads
from it, in the same process: control at x1.0, the gravity sweep, the plan time (piga, PlaNet-style:
one episode, beside whatever else runs) and the goal images (piga). Jobs run ``--workers`` at a time
(default 2, one torch thread each; :func:`piga.io.pool.run_recorded`), longest first, or with ``--ray
auto|HOST:PORT`` as tasks of a Ray cluster (on several machines, ``OUT_runs`` must be one shared folder:
the data files are collected there first, by this process). A job ends by writing
its record, ``OUT_runs/records/NAME.json`` (its settings, measurements, training seconds, machine, the code's
git commit and every hyperparameter of its training and evaluation; a few kB).
A job whose record has the same settings is not run again, so an interrupted benchmark continues
where it stopped, on this machine or another; the checkpoints are needed only until the record
exists (for ``results/baselines`` the records are committed, the checkpoints and data are not).
``--only piga,oracle`` runs those kinds of job only, ``--only planet-n2000-s1`` that job. ``OUT.json``, ``OUT.md`` and the figures
``OUT-sample_efficiency.png``, ``OUT-ddpg.png`` and ``OUT-sweep.png`` are written (atomically) at the
end of every invocation; they read the records only, those there are: while some jobs have none, the
page names them, their cells read "pending", and each floor names the pending runs that could change it. Each agent's sweep, goal images and plan time
are those of its best run at x1.0.

**Cost.** :data:`COST_S` holds the CPU seconds of one unit of each kind of work (one process, one
torch thread) on a 2-core AMD EPYC, measured as process CPU time while other jobs shared the
machine, so roughly what an idle core takes: a PlaNet-style training step 0.54 s (16 x 20 model steps
of 2 frames), a piga training step 0.145 s, latent CEM 0.17 s per control step (one plan of ~0.34 s
per 2 steps), a DDPG step from pixels 0.37 s once learning starts, from the latent 0.020 s,
from the state 0.011 s; SAC from pixels about 0.6 s; DrQ-v2 from pixels 0.49 s. One run each:
PlaNet-style 108 min (12000 steps, whatever the data size) and its episodes 23 min (x1.0 and the
sweep); piga 7-8 min (at least 3000 steps) on up to 250 sequences, 16 min on 500 (16 epochs); DDPG
from the state 5 min (30k), from the latent 12 min (30k, autoencoder included), from pixels 64 min
(20k); SAC from pixels about 3 h (20k); DrQ-v2 from pixels 46-66 min (12k). An older CPU takes longer
(the records name each job's machine).
``--estimate`` adds them up (jobs packed longest first on ``--workers`` cores):

| preset | what | collect | training (core-h) | PlaNet-style episodes (core-h) | other episodes (core-h) | wall on 2 idle cores |
|---|---|---|---|---|---|---|
| ``budget`` | piga at 2/5/10/25/50/100/250 sequences x 3 seeds (at least 3000 steps each); PlaNet-style at 100/250/500/1000/2000 x 1 seed, and a second seed at 500, 1000 and 2000 (12000 steps each); DDPG state 30k x 3 seeds, latent 30k x 1, pixels 20k x 1; SAC pixels 20k x 1; DrQ-v2 pixels 12k x 2 seeds; 20 episodes per evaluation; sweep x0.6, 1.0, 1.4, 1.8 with 5 episodes each | 0.2 h | 24.0 | 2.7 | 0.6 | 13.9 h |
| ``full`` | the full design: piga at 2/5/10/25/50/100/250/500/1000/2000 sequences and PlaNet-style at 100/250/500/1000/2000, 3 seeds each, DDPG 30k/80k/80k x 3 seeds, SAC and DrQ-v2 pixels 80k x 3 seeds each, 20 episodes, 14 multipliers x 10 episodes | 0.2 h | 128.0 | 21.4 | 3.2 | 76.5 h |

The budget preset answers every question of the comparison with what it can afford, and says what
it cut: PlaNet-style has one seed per point and a second at 500, 1000 and 2000 sequences (its 12000 steps
are almost two hours each), its points are where it might reach 80% rather than where piga does, DDPG
from pixels gets 20k steps (10k of them the zoo's random warm-up, so 10k of learning; the paper's DDPG
from pixels failed), SAC from pixels 20k (learning from step 100), DrQ-v2 from pixels 12k (4k of them
its random warm-up; it passed -200 at 10k in results/drqv2.md) and DDPG from the latent 30k, not the
paper's 80k. The results page states the budget spent (training seconds per run).

Numbers of the ``tiny`` preset check the pipeline only; they are no result.
"""

from __future__ import annotations

import json
import math
import shlex
import statistics
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from common import ALGO_LABELS, add_ray_option, farm_main, machine, out_prefix, ray_backend, signed as _num
from efficiency import Point, data_ratio

from agents.planet.config import PlanetTrainConfig
from piga.io.atomic import atomic_output, write_json, written_together
from piga.io.checkpoint import CHECKPOINT
from piga.io.pool import Backend, JobRecords, RecordedJob, run_recorded
from piga.control.episodes import parse_range
from piga.cli.common import ArgumentParser, positive_int


@dataclass(frozen=True)
class BenchConfig:
    """What the comparison runs."""

    sizes: tuple[int, ...] = (2, 5, 10, 25, 50, 100, 250, 500, 1000, 2000)
    """Training sequences per point of the sample-efficiency sweep (piga's). 2 is the fewest that piga's recipe trains
    on: one 40-frame sequence gives 27 training windows, fewer than its batch of 32."""
    planet_sizes: tuple[int, ...] | None = None
    """The PlaNet-style model's points (None: ``sizes``); its training cost does not grow with them."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """piga's training seeds per point."""
    planet_seeds: tuple[int, ...] | None = None
    """The PlaNet-style model's training seeds per point (None: ``seeds``)."""
    planet_more_seeds: tuple[tuple[int, tuple[int, ...]], ...] = ()
    """Extra PlaNet-style seeds at some points, (sequences, seeds) pairs: an hour of training each, so
    the budget preset spends them where one seed left the result in doubt."""
    steps: int = 40
    """Frames per collected sequence (piga-collect's default)."""
    data_seed: int = 100
    """Seed of the one random-action collection that every subset is cut from."""
    piga_epochs: int = 16
    """piga-train-model's epochs (its default)."""
    piga_min_steps: int = 0
    """At least this many optimiser steps for piga (more epochs on small subsets; 0: ``piga_epochs`` only).
    With 16 epochs of 50 sequences piga takes ~670 steps, fewer than its 800-step warm-up and
    curriculum, so a small subset would measure an unfinished recipe rather than too little data."""
    planet_steps: int = PlanetTrainConfig().steps
    """PlaNet-style optimiser steps (piga-baseline planet's default), whatever the subset's size."""
    ddpg_runs: tuple[tuple[str, int, tuple[int, ...]], ...] = (("state", 30000, (0, 1, 2)), ("latent", 80000, (0, 1, 2)),
                                                                ("pixels", 80000, (0, 1, 2)))
    """DDPG (observation, env steps, seeds) (the paper's budgets: proprioception 30k, latent 80k)."""
    sac_runs: tuple[tuple[str, int, tuple[int, ...]], ...] = (("pixels", 80000, (0, 1, 2)),)
    """SB3's SAC (observation, env steps, seeds): DDPG's stronger sibling, where DDPG's actor saturates
    (from pixels; results/ddpg_tuning.md). Scored as DDPG's runs are, in their tables and curves."""
    drqv2_runs: tuple[tuple[str, int, tuple[int, ...]], ...] = (("pixels", 80000, (0, 1, 2)),)
    """DrQ-v2 (observation, env steps, seeds; pixels only): DDPG from pixels made to work (an encoder trained by the
    critic on shifted frames, 3-step returns; results/drqv2.md). Scored as DDPG's runs are, in their tables and curves."""
    episodes: int = 20
    """Control episodes per evaluation of piga, the oracle and DDPG."""
    planet_episodes: int | None = None
    """Control episodes per evaluation of the PlaNet-style agent (None: ``episodes``); its latent CEM
    takes ~0.5 s a step, ~100 s an episode."""
    sweep: str = "0.5:1.8:0.1"
    """Gravity multipliers of the zero-shot sweep."""
    sweep_episodes: int = 10
    """Episodes per multiplier (the PlaNet-style agent: at most ``planet_episodes``)."""
    goal_angles: tuple[float, ...] = (-20.0, 10.0, 20.0)
    """Goal images (degrees from upright) for piga, within 0.9 x the holdable range: holding angle θ takes
    torque (g / 2a) sin θ ≤ 2, so |θ| ≤ asin(4a / g) = 23.6 deg at x1.0 (benchmarks/control.py spreads
    more goals over that range)."""
    episode_steps: int = 200
    """Steps per control episode."""
    workers: int = 2
    """Processes: trainings run side by side, and each evaluation's episodes are split over them
    (the same episodes and scores as one process; plan times are measured with one process)."""
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Extra settings per stage (the tiny preset shrinks the models)."""

    @property
    def planet_size_list(self) -> tuple[int, ...]:
        return self.sizes if self.planet_sizes is None else self.planet_sizes

    @property
    def planet_seed_list(self) -> tuple[int, ...]:
        return self.seeds if self.planet_seeds is None else self.planet_seeds

    def planet_seeds_at(self, n: int) -> tuple[int, ...]:
        """The PlaNet-style model's seeds at ``n`` sequences: ``planet_seed_list`` and any extra ones."""
        extra = tuple(seed for size, seeds in self.planet_more_seeds if size == n for seed in seeds)
        return self.planet_seed_list + tuple(seed for seed in extra if seed not in self.planet_seed_list)

    def piga_seeds_at(self, n: int) -> tuple[int, ...]:
        """piga's seeds at ``n`` sequences."""
        return self.seeds

    @property
    def planet_episode_count(self) -> int:
        return self.episodes if self.planet_episodes is None else self.planet_episodes


#: CPU seconds of one unit of work in one process with one torch thread, on the 2-core AMD EPYC:
#: process CPU time, measured while other jobs shared the machine (so roughly an idle core's wall
#: time; cache sharing makes them, if anything, high), except ``ddpg_state_step``, the wall time of
#: 30k-step runs with one other job on the machine.
COST_S = {
    "piga_train_step": 0.145,  # piga-train-model at its defaults, batch 32 (33 steps, startup included)
    "planet_train_step": 0.54,  # piga-baseline planet, 16 x 20 model steps of 2 frames (6000 steps in 53.9 min)
    "planet_plan_step": 0.17,  # per env step: latent CEM with PlaNet's settings, the Imagination engine, one plan per 2 steps
    "piga_episode_step": 0.008,  # a control step with rendering (the oracle's 200-step episode: 1.65 s)
    "ddpg_state_step": 0.0106,  # Pendulum-v1 without rendering, warm-up included (5.3 min per 30k)
    "ddpg_latent_warmup_step": 0.0068,  # rendering + autoencoder code, random actions
    "ddpg_latent_step": 0.020,  # the same + one MLP gradient step
    "ddpg_pixels_warmup_step": 0.012,  # rendering, random actions
    "ddpg_pixels_step": 0.372,  # rendering + one CnnPolicy gradient step on 256 stacks of 4 frames
    "sac_state_step": 0.023,  # SAC from the state: 20k steps in 7.8 min beside two other jobs (results/ddpg_tuning.md)
    "sac_pixels_step": 0.6,  # SAC from pixels (two critics, separate CNNs): ~10 min per 1000 steps beside other jobs, a partial run
    # DrQ-v2 from pixels, its encoder in bfloat16 ("auto" on a CPU with bfloat16 hardware), an update every 2 steps: wall time of
    # results/drqv2_runs/records/pixels-cpu-s0.json, 20k steps in 7903 s, less its 4000 warm-up steps (ddpg_pixels_warmup_step);
    # the budget preset's drqv2-pixels-s0 took 0.34 s a step (12k in 2763 s on the Zen 4), so this is an upper bound
    "drqv2_pixels_step": 0.49,
    "autoencoder_step": 0.135,  # agents.sb3.autoencoder, 2000 steps before DDPG from the latent
    "collect_sequence": 0.25,  # piga-collect, 40 frames
}


PRESETS: dict[str, BenchConfig] = {
    "full": BenchConfig(planet_sizes=(100, 250, 500, 1000, 2000)),
    "budget": BenchConfig(sizes=(2, 5, 10, 25, 50, 100, 250), seeds=(0, 1, 2), planet_sizes=(100, 250, 500, 1000, 2000),
                          planet_seeds=(0,),
                          planet_more_seeds=((500, (1,)), (1000, (1,)), (2000, (1,))),
                          piga_min_steps=3000,
                          ddpg_runs=(("state", 30000, (0, 1, 2)), ("latent", 30000, (0,)), ("pixels", 20000, (0,))),
                          sac_runs=(("pixels", 20000, (0,)),), drqv2_runs=(("pixels", 12000, (0, 1)),),
                          sweep="0.6:1.8:0.4", sweep_episodes=5),
    "tiny": BenchConfig(sizes=(8, 16), seeds=(0,), planet_sizes=(16,), steps=16, piga_epochs=1, planet_steps=4,
                        ddpg_runs=(("state", 400, (0,)), ("latent", 400, (0,)), ("pixels", 400, (0,))),
                        sac_runs=(("pixels", 400, (0,)),), drqv2_runs=(("pixels", 400, (0,)),), episodes=2,
                        sweep="1.0:1.4:0.4", sweep_episodes=1, goal_angles=(15.0,), episode_steps=20,
                        overrides={"planet": {"batch_size": 2, "chunk_length": 8}, "rssm": {"deter_size": 8, "stoch_size": 4},
                                   "piga": {"batch_size": 16, "warmup_fraction": 0.1, "curriculum_fraction": 0.1},
                                   "ddpg": {"learning_starts": 100, "eval_every": 200, "eval_episodes": 1, "batch_size": 16,
                                            "buffer_size": 1000},
                                   "autoencoder": {"steps": 20}, "cem": {"horizon": 3, "iterations": 2, "candidates": 20, "elites": 4}}),
}


def _piga_steps_per_epoch(cfg: BenchConfig, n: int) -> int:
    from piga.world.model import ModelConfig

    window = ModelConfig().window  # the pendulum's L + T_pred
    return max(1, n * (cfg.steps - window + 1) // cfg.overrides.get("piga", {}).get("batch_size", 32))


def piga_epochs(cfg: BenchConfig, n: int) -> int:
    """piga's epochs on ``n`` sequences: ``piga_epochs``, or more to reach ``piga_min_steps``."""
    return max(cfg.piga_epochs, math.ceil(cfg.piga_min_steps / _piga_steps_per_epoch(cfg, n)))


def train_cost(cfg: BenchConfig, agent: str, n: int = 0, steps: int = 0) -> float:
    """Estimated core-seconds of one training (:data:`COST_S`): "piga" or "planet" on ``n`` sequences,
    or "ALGO_OBS" (an SB3 run: "ddpg_pixels", "sac_pixels", "drqv2_pixels") for ``steps`` env steps."""
    if agent == "piga":
        return piga_epochs(cfg, n) * _piga_steps_per_epoch(cfg, n) * COST_S["piga_train_step"]
    if agent == "planet":
        return cfg.planet_steps * COST_S["planet_train_step"]
    if agent.endswith("_state"):
        return steps * COST_S[f"{agent}_step"]
    from agents.sb3.autoencoder import AutoencoderConfig
    from agents.sb3.config import SB3Config

    algo, obs = agent.split("_")
    warmup = min(steps, SB3Config(obs=obs, algo=algo, **cfg.overrides.get("ddpg", {})).learning_starts)
    seconds = warmup * COST_S[f"ddpg_{obs}_warmup_step"] + (steps - warmup) * COST_S[f"{agent}_step"]  # warm-up: the env's work only
    if obs == "latent":
        seconds += cfg.overrides.get("autoencoder", {}).get("steps", AutoencoderConfig.steps) * COST_S["autoencoder_step"]
    return seconds


def estimate(cfg: BenchConfig, jobs: list[Job] | None = None) -> dict[str, float]:
    """Core-seconds per part from :data:`COST_S` (upper bounds: measured under load), and the wall
    time on ``workers`` cores (jobs packed longest first, a PlaNet-style run's episodes with its
    training; the other episodes, a few minutes, spread evenly), of ``jobs`` (None: the whole preset)."""
    jobs = jobs_for(cfg) if jobs is None else jobs
    runs = {agent: [job for job in jobs if job.agent == agent] for agent in AGENTS}
    piga, planet, ddpg = ([job_train_cost(cfg, job) for job in runs[agent]] for agent in ("piga", "planet", "ddpg"))
    step = cfg.episode_steps
    sweep = [m for m in parse_range(cfg.sweep) if m != 1.0]  # x1.0 is the run's own evaluation

    def episodes(agent: str) -> int:  # per run: x1.0, the sweep, the plan-time episode, the goal images
        own = cfg.planet_episode_count if agent == "planet" else cfg.episodes
        return (own + len(sweep) * sweep_episodes(cfg, agent) + (agent in ("piga", "planet"))
                + (agent == "piga") * len(cfg.goal_angles) * max(1, cfg.episodes // 5))

    per_planet = episodes("planet") * step * COST_S["planet_plan_step"]  # one PlaNet-style run's episodes
    planet_eval = len(runs["planet"]) * per_planet
    others = [(agent, len(runs[agent])) for agent in ("piga", "oracle", "ddpg")]
    other_eval = sum(count * episodes(agent) for agent, count in others) * step * COST_S["piga_episode_step"]
    sizes = {job.sequences for job in jobs if job.agent in ("piga", "planet")}  # (the data files they collect)
    collect = sum(n * 1.2 for n in sizes) * COST_S["collect_sequence"] / cfg.workers
    costs = piga + [t + per_planet for t in planet] + ddpg  # a PlaNet-style run's episodes follow its training
    cores = [0.0] * cfg.workers
    for seconds in sorted(costs, reverse=True):  # longest first, each to the least loaded core
        cores[cores.index(min(cores))] += seconds
    parts = {"collect": collect, "train (core-s)": sum(piga + planet + ddpg), "planet episodes (core-s)": planet_eval,
             "other episodes (core-s)": other_eval}
    parts["wall"] = collect + max(cores) + other_eval / cfg.workers
    return parts


AGENTS = ("piga", "planet", "ddpg", "oracle")
"""The kinds of job, as ``--only`` takes them (besides job names); "ddpg" are the SB3 runs, SAC's and DrQ-v2's included."""


@dataclass(frozen=True)
class Job:
    """One run of the comparison: trained (unless ``agent`` is "oracle"), then measured."""

    name: str
    """Its folder in ``OUT_runs/`` and its record ``OUT_runs/records/NAME.json``."""
    agent: str
    """"piga", "planet", "ddpg" or "oracle"."""
    sequences: int = 0
    """Training sequences (piga, planet)."""
    seed: int = 0
    obs: str = ""
    """DDPG's observation."""
    steps: int = 0
    """DDPG's env steps."""
    algo: str = "ddpg"
    """The algorithm of a "ddpg" job (an SB3 run, ``piga-baseline ddpg --algo ALGO``): "ddpg", "sac" or "drqv2"."""


def jobs_for(cfg: BenchConfig) -> list[Job]:
    """Every run of the comparison, the oracle included."""
    jobs = [Job(f"{agent}-n{n}-s{seed}", agent, n, seed)
            for agent, sizes, seeds_at in (("piga", cfg.sizes, cfg.piga_seeds_at), ("planet", cfg.planet_size_list, cfg.planet_seeds_at))
            for n in sizes for seed in seeds_at(n)]
    jobs += [Job(f"{algo}-{obs}-s{seed}", "ddpg", seed=seed, obs=obs, steps=steps, algo=algo)
             for algo, runs in (("ddpg", cfg.ddpg_runs), ("sac", cfg.sac_runs), ("drqv2", cfg.drqv2_runs))
             for obs, steps, seeds in runs for seed in seeds]
    return jobs + [Job("oracle", "oracle")]


def job_train_cost(cfg: BenchConfig, job: Job) -> float:
    """:func:`train_cost` of one job (0 for the oracle, which is not trained)."""
    if job.agent in ("piga", "planet"):
        return train_cost(cfg, job.agent, job.sequences)
    return train_cost(cfg, f"{job.algo}_{job.obs}", steps=job.steps) if job.agent == "ddpg" else 0.0


def job_spec(job: Job, cfg: BenchConfig) -> dict[str, Any]:
    """What a job's record was measured with: a kept record counts only if this is unchanged (JSON types)."""
    spec: dict[str, Any] = {**asdict(job), "episodes": cfg.planet_episode_count if job.agent == "planet" else cfg.episodes,
                            "episode_steps": cfg.episode_steps, "sweep": parse_range(cfg.sweep),
                            "sweep_episodes": sweep_episodes(cfg, job.agent)}
    if job.algo == "ddpg":  # named only where it is not the kind's own algorithm, as the DDPG records were written
        del spec["algo"]
    if job.agent in ("piga", "planet"):
        spec.update(data_seed=cfg.data_seed, frames=cfg.steps)
    if job.agent == "piga":
        spec.update(epochs=piga_epochs(cfg, job.sequences), goal_angles=list(cfg.goal_angles))
    if job.agent == "planet":
        spec["planet_steps"] = cfg.planet_steps
    if cfg.overrides:
        spec["overrides"] = cfg.overrides
    return json.loads(json.dumps(spec))


def sweep_episodes(cfg: BenchConfig, agent: str) -> int:
    """Episodes per multiplier of the sweep (the PlaNet-style agent: at most ``planet_episodes``)."""
    return min(cfg.sweep_episodes, cfg.planet_episode_count) if agent == "planet" else cfg.sweep_episodes


def job_records(folder: Path) -> JobRecords:
    """The jobs' records, ``folder/records/NAME.json``."""
    return JobRecords(folder / "records")


def record_path(folder: Path, job: Job) -> Path:
    return job_records(folder).path(job.name)


def kept_record(folder: Path, job: Job, cfg: BenchConfig) -> dict[str, Any] | None:
    """The job's record if one was kept for the same settings (:func:`job_spec`), else None."""
    return job_records(folder).kept(job.name, job_spec(job, cfg))


def data_path(folder: Path, n: int) -> Path:
    return folder / f"data-n{n}.h5"


def data_file(cfg: BenchConfig, folder: Path, n: int) -> Path:
    """The data file of ``n`` training sequences, collected if missing: the first n sequences of one
    collection are its train split (nested subsets: sequence k depends only on (data_seed, k)), plus
    10% more for valid and test."""
    from piga.data.collect import CollectConfig, collect

    path = data_path(folder, n)
    extra = max(1, n // 10)
    if not path.exists():
        collect(CollectConfig(sequences=n + 2 * extra, steps=cfg.steps, seed=cfg.data_seed, workers=cfg.workers,
                              split=(n, extra, extra)), path, progress=False, command=f"benchmarks/baselines.py (n={n})")
    return path


def evaluate(kind: str, run: Path | None, cfg: BenchConfig, gravity_mult: float = 1.0, episodes: int | None = None,
             workers: int = 1, seed: int = 0, torque_arrow: bool = False, **job_fields: Any) -> dict[str, Any]:
    """piga.control.episodes' summary for one agent (kind "piga", "planet", "ddpg" or "oracle"), its episodes
    split over ``workers`` processes (the same episodes and scores as one); ``seed``: the episodes' (0, the
    table's); ``torque_arrow``: whether the frames show Gymnasium's torque arrow (the table's: not);
    ``job_fields``: more fields of its :class:`~piga.control.jobs.ControlJob` (the piga agent's ``told`` and
    ``reward_head``)."""
    from piga.control.jobs import ControlJob, run_split

    episode_config = replace(episode_config_for(kind, cfg, gravity_mult, episodes, seed), torque_arrow=torque_arrow)
    job = ControlJob(kind, episode_config, model_dir=str(run) if run else None, **job_fields)
    if kind == "planet" and "cem" in cfg.overrides:  # tiny preset only: PlaNet's planner, shrunk
        from agents.planet.planner import PlanetAgent
        from agents.planet.run import load_planet
        from piga.control.episodes import run_episodes

        agent = PlanetAgent(load_planet(run)[0], planet_planner(cfg))
        return run_episodes(agent, replace(episode_config, frame_stack=1)).summary.to_dict()
    return run_split(job, workers, progress=False).summary.to_dict()


#: The gravity multiplier of the table's changed-gravity column (the PlaNet-style model is not told it).
TABLE_GRAVITY = 1.4


def planet_scores(run: Path, cfg: BenchConfig, workers: int = 1) -> dict[str, Any]:
    """A PlaNet-style run scored as the table's runs are: ``x1`` on its episodes at x1.0, ``x1.4`` on the sweep's at
    :data:`TABLE_GRAVITY` (:func:`evaluate`'s summaries; benchmarks that set a variant beside the table's runs)."""
    return {"x1": evaluate("planet", run, cfg, workers=workers),
            "x1.4": evaluate("planet", run, cfg, TABLE_GRAVITY, sweep_episodes(cfg, "planet"), workers=workers)}


def planet_table_runs(runs: Path, sequences: int, gravity: float = TABLE_GRAVITY) -> dict[str, dict[str, Any]]:
    """The table's PlaNet-style records at ``sequences`` in ``runs/records``, by name: seed, scores at x1.0 and at
    ``gravity`` (the sweep's), training seconds (benchmarks that set a variant beside the table's runs)."""
    out = {}
    for path in sorted((runs / "records").glob(f"planet-n{sequences}-s*.json")):
        record = json.loads(path.read_text())
        out[path.stem] = {"seed": record["spec"]["seed"], "x1": record["control"],
                          "x1.4": record["sweep"][f"{gravity:g}"], "train_seconds": record["train_seconds"]}
    return out


def recorded_scores(run: Path) -> dict[str, Any] | None:
    """A run's table scores (``x1`` and ``x1.4``, :func:`evaluate`'s summaries) from its benchmark record,
    ``records/NAME.json`` beside its folder (the baselines benchmark's ``control``/``sweep`` layout, or a
    PlaNet-variant benchmark's ``x1``/``x1.4``); None without one."""
    path = run.parent / "records" / f"{run.name}.json"
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    x1 = record.get("control") or record.get("x1")
    sweep = record.get("sweep", {}).get(f"{TABLE_GRAVITY:g}") or record.get("x1.4")
    return {"x1": x1, "x1.4": sweep} if x1 and sweep else None


def episode_config_for(kind: str, cfg: BenchConfig, gravity_mult: float = 1.0, episodes: int | None = None,
                       seed: int = 0) -> Any:
    """The :class:`piga.control.episodes.EpisodeConfig` of one evaluation of ``kind``'s agent, on the episodes of
    ``seed`` (the table's: 0)."""
    from piga.control.episodes import EpisodeConfig

    if episodes is None:
        episodes = cfg.planet_episode_count if kind == "planet" else cfg.episodes
    return EpisodeConfig(episodes=episodes, steps=cfg.episode_steps, hold_steps=min(20, cfg.episode_steps),
                         gravity_mult=gravity_mult, seed=seed)


def planet_planner(cfg: BenchConfig) -> Any:
    """The PlaNet-style agent's planner settings: PlaNet's (:func:`piga.control.registry.baseline_agent`), or the
    tiny preset's shrunk CEM."""
    from agents.config import CEMConfig
    from agents.planet.config import LatentPlannerConfig

    return LatentPlannerConfig(cem=CEMConfig(**cfg.overrides["cem"])) if "cem" in cfg.overrides else LatentPlannerConfig()


def hyperparameters(job: Job, cfg: BenchConfig, run: Path | None) -> dict[str, Any]:
    """Every setting of the job's run, as the run used it: its training configs (read back from the run folder,
    so a continued run reports what it trained with) and its evaluation's episodes and planner."""
    from agents.mpc import MPCConfig

    configs: dict[str, Any] = {"episodes": asdict(episode_config_for(job.agent, cfg))}
    if job.agent == "piga":
        from piga.io.runs import load_model

        ckpt = load_model(run)[1]
        configs.update(train=ckpt["train_config"], model=ckpt["model_config"], planner=asdict(MPCConfig()))
    elif job.agent == "planet":
        saved = json.loads((run / "config.json").read_text())
        configs.update(train=saved["train"], rssm=saved["rssm"], planner=asdict(planet_planner(cfg)))
    elif job.agent == "ddpg":
        from agents.sb3.autoencoder import AutoencoderConfig

        configs["train"] = json.loads((run / "config.json").read_text())["ddpg"]
        if job.obs == "latent":
            configs["autoencoder"] = asdict(AutoencoderConfig(seed=job.seed, **cfg.overrides.get("autoencoder", {})))
    else:
        configs["planner"] = asdict(MPCConfig())
    return json.loads(json.dumps(configs))


def evaluate_kept(folder: Path, kind: str, run: Path | None, cfg: BenchConfig, gravity_mult: float = 1.0,
                  episodes: int | None = None) -> dict[str, Any]:
    """:func:`evaluate` in one process, its summary kept in ``folder/evals/`` so that a job stopped during
    its evaluations continues there. A kept summary older than the run's checkpoint (a run trained
    further since) is evaluated again."""
    if episodes is None:
        episodes = cfg.planet_episode_count if kind == "planet" else cfg.episodes
    path = folder / "evals" / f"{run.name if run else kind}-x{gravity_mult:g}-e{episodes}-s{cfg.episode_steps}.json"
    checkpoint = run / CHECKPOINT if run else None
    if path.exists() and not (checkpoint and checkpoint.exists() and checkpoint.stat().st_mtime > path.stat().st_mtime):
        return json.loads(path.read_text())
    summary = evaluate(kind, run, cfg, gravity_mult, episodes)
    path.parent.mkdir(exist_ok=True)
    write_json(path, summary)
    return summary


def train_piga(data: Path, run: Path, seed: int, cfg: BenchConfig, n: int, model: Any = None) -> float:
    """Trains (unless done) and returns the run's training seconds; ``model``: a
    :class:`~piga.world.model.ModelConfig` instead of the fast recipe's (benchmarks/privilege.py's paper readout)."""
    from piga.io.runs import load_model
    from piga.training.train import TrainConfig, train

    # device="cpu": the comparison's training times are the CPU's, on every machine
    config = TrainConfig(epochs=piga_epochs(cfg, n), seed=seed, threads=1, device="cpu",
                         **cfg.overrides.get("piga", {}))
    started = (run / "checkpoint.pt").exists()
    state = load_model(run)[1]["state"] if started else None
    if state is None or state["epoch"] < config.epochs:  # not begun, or stopped part-way: resume
        from piga.world.model import ModelConfig

        if "piga" in cfg.overrides:  # tiny preset: shrunk
            model = replace(model or ModelConfig(), rec_frames="input", pred_frames=4)
        state = asdict(train(data, run, config, model, resume=started, progress=False)[1])
    return float(state["elapsed"])


def train_planet_run(data: Path, run: Path, seed: int, cfg: BenchConfig, n: int, device: str = "cpu") -> float:
    """Trains (unless done: a run of fewer steps is continued to ``cfg.planet_steps``, on ``device``) and returns the
    run's training seconds."""
    from agents.planet.train import rssm_config_for, train_planet
    from piga.data.schema import inspect_dataset

    metrics = run / "metrics.json"
    if not metrics.exists() or json.loads(metrics.read_text())["steps"] < cfg.planet_steps:
        config = PlanetTrainConfig(steps=cfg.planet_steps, seed=seed, threads=1, device=device,
                                   **cfg.overrides.get("planet", {}))
        rssm = rssm_config_for(inspect_dataset(data), cfg.overrides.get("rssm"))
        resume = (run / "checkpoint.pt").exists()  # metrics.json comes last: resume a stopped or shorter run
        # the record piga-baseline planet writes (so that it can --resume this run too), with the steps now asked for
        record = json.loads((run / "config.json").read_text()) if resume else {"kind": "planet", "data": str(data)}
        run.mkdir(parents=True, exist_ok=True)
        write_json(run / "config.json", {"rssm": rssm.to_dict(), **record, "train": config.to_dict()})  # a recorded rssm wins
        train_planet(data, run, config, rssm, resume=resume, progress=False)
    return float(json.loads(metrics.read_text())["train_seconds"])


def _autoencoder_seconds(metrics: dict[str, Any]) -> str:
    """" + N s autoencoder" for a latent run whose autoencoder recorded its training time, else ""."""
    seconds = metrics.get("autoencoder_train_seconds")
    return "" if seconds is None else f" + {seconds:.0f} autoencoder"


def train_ddpg_run(obs: str, steps: int, seed: int, data: Path, run: Path, cfg: BenchConfig, algo: str = "ddpg") -> dict[str, Any]:
    """Trains an SB3 run (``algo``: "ddpg", "sac" or "drqv2"; unless done) and returns its metrics (learning curve, seconds)."""
    from agents.sb3.autoencoder import AutoencoderConfig, train_autoencoder
    from agents.sb3.config import SB3Config
    from agents.sb3.run import AUTOENCODER
    from agents.sb3.train import train_sb3

    if not (run / "metrics.json").exists():
        config = SB3Config(obs=obs, algo=algo, steps=steps, seed=seed, device="cpu", **cfg.overrides.get("ddpg", {}))
        run.mkdir(parents=True, exist_ok=True)
        autoencoder = None
        if obs == "latent":
            autoencoder = run / AUTOENCODER
            if not autoencoder.exists():
                train_autoencoder(data, AutoencoderConfig(seed=seed, **cfg.overrides.get("autoencoder", {})), autoencoder,
                                  progress=False, device=config.device)
        train_sb3(config, run, autoencoder, resume=(run / "checkpoint.pt").exists(), progress=False)
        write_json(run / "config.json", {"kind": "ddpg", "data": str(data), "ddpg": config.to_dict()})
    return json.loads((run / "metrics.json").read_text())


def run_job(job: Job, cfg: BenchConfig, folder: Path, data: Path | None) -> dict[str, Any]:
    """Trains the job's run (continuing a stopped one) and measures everything the comparison reads from
    it, in this process: control at x1.0, the gravity sweep, the plan time (piga, planet) and the goal
    images (piga). Returns its record's fields (JSON types; :func:`run_all` adds the spec and the commit and
    writes it). The aggregate reads records only, so a run's checkpoint is needed only until its record exists."""
    run = None if job.agent == "oracle" else folder / job.name
    record: dict[str, Any] = {"machine": machine()}  # jobs may run on different machines
    if job.agent == "piga":
        record["train_seconds"] = train_piga(data, run, job.seed, cfg, job.sequences)
    elif job.agent == "planet":
        record["train_seconds"] = train_planet_run(data, run, job.seed, cfg, job.sequences)
    elif job.agent == "ddpg":
        record["metrics"] = train_ddpg_run(job.obs, job.steps, job.seed, data, run, cfg, job.algo)
        record["train_seconds"] = record["metrics"]["train_seconds"]
    record["control"] = evaluate_kept(folder, job.agent, run, cfg)
    # the x1.0 cell of the sweep is the x1.0 evaluation (its first sweep_episodes episodes are the sweep's own)
    record["sweep"] = {f"{m:g}": record["control"] if m == 1.0 else
                       evaluate_kept(folder, job.agent, run, cfg, m, sweep_episodes(cfg, job.agent))
                       for m in parse_range(cfg.sweep)}
    if job.agent in ("piga", "planet"):  # one episode, one process, beside whatever else the machine runs
        record["plan_ms"] = evaluate(job.agent, run, cfg, episodes=1)["plan_ms_median"]
    if job.agent == "planet":
        from agents.planet.run import load_planet

        record["action_repeat"] = load_planet(run)[0].config.action_repeat  # PlaNet-style plans every R-th env step
    if job.agent == "piga":
        record["goals"] = goal_images(run, cfg, folder)
    record["config"] = hyperparameters(job, cfg, run)
    return record


def _run_task(args: tuple[Job, BenchConfig, Path, Path | None]) -> dict[str, Any]:
    """:func:`run_job` with one torch thread (the worker pool's setting, here for one process too)."""
    import torch

    torch.set_num_threads(1)
    record = run_job(*args)
    print(f"done {args[0].name}", flush=True)
    return record


def run_all(cfg: BenchConfig, folder: Path, only: tuple[str, ...] = AGENTS,
            backend: Backend | None = None) -> dict[str, dict[str, Any] | None]:
    """Every job's record: kept ones as they are, the others of the ``only`` agents (or job names) run ``cfg.workers``
    at a time (or on ``backend``), longest first (None for a job not run). Only the data files of jobs still to
    run are collected (first, in this process)."""
    jobs = jobs_for(cfg)
    kept = {job.name: kept_record(folder, job, cfg) for job in jobs}
    todo = [job for job in jobs if (job.agent in only or job.name in only) and kept[job.name] is None]
    if todo:  # what this invocation runs (the preset's whole cost is printed before): the jobs asked for, not kept
        print(f"this invocation: {len(todo)} job(s) to run, wall {estimate(cfg, todo)['wall'] / 3600:.1f} h on "
              f"{cfg.workers} core(s)", flush=True)
    largest = max(cfg.sizes + cfg.planet_size_list)
    needs = {job.sequences or largest for job in todo if job.agent in ("piga", "planet") or job.obs == "latent"}
    files = {n: data_file(cfg, folder, n) for n in sorted(needs)}
    recorded = [RecordedJob(job.name, job_spec(job, cfg), (job, cfg, folder, None if job.agent == "oracle" else
                                                           files.get(job.sequences or largest, data_path(folder, largest))))
                for job in sorted(todo, key=lambda j: -job_train_cost(cfg, j))]
    done = run_recorded(_run_task, recorded, job_records(folder), cfg.workers, progress=False, backend=backend)
    return {**kept, **done}


def best_run(record: dict[str, Any], agent: str) -> str | None:
    """The name of ``agent``'s run ("piga", "planet" or "ddpg") with the highest success at x1.0 (then the
    highest mean return, then the most data): the one the gravity sweep, the goal images and the plan
    times use, so that each agent is shown at its best. The PlaNet-style runs differ by more than data
    size (a run on 500 sequences beat one on 2000 in the budget preset), so "the largest" would not do.
    None while none of the agent's runs has a record."""
    if agent == "ddpg":  # DDPG's own runs (the paper's baseline), not SAC's or DrQ-v2's
        runs = [(f"ddpg-{r['obs']}-s{r['seed']}", r["control"], 0) for r in record["ddpg"] if r["algo"] == "ddpg"]
    else:
        runs = [(f"{agent}-n{row['sequences']}-s{run['seed']}", run["control"], row["sequences"])
                for row in record["sample_efficiency"] if row["agent"] == agent for run in row["runs"]]
    return max(runs, key=lambda r: (r[1]["success_rate"], r[1]["mean_return"], r[2]))[0] if runs else None


def goal_images(piga_run: Path, cfg: BenchConfig, folder: Path) -> list[dict[str, Any]]:
    """piga reaching goal images; the baselines have no goal input (refused by piga-control)."""
    import imageio.v3 as iio

    from agents.mpc import MPCConfig, PigaMPCAgent
    from piga.control.episodes import EpisodeConfig, run_episodes
    from piga.control.goal import goal_from_image, render_goal_image
    from piga.io.runs import load_model

    model, ckpt = load_model(piga_run)
    rows = []
    for angle in cfg.goal_angles:
        path = folder / "goals" / f"goal{angle:g}.png"
        path.parent.mkdir(exist_ok=True)
        with atomic_output(path, overwrite=True) as tmp:  # jobs run side by side
            iio.imwrite(tmp, render_goal_image(angle), extension=".png")
        estimate = goal_from_image(model, ckpt, path)
        agent = PigaMPCAgent(model, replace(MPCConfig(), goal_angle=estimate.angle))
        summary = run_episodes(agent, EpisodeConfig(episodes=max(1, cfg.episodes // 5), steps=cfg.episode_steps,
                                                    hold_steps=min(20, cfg.episode_steps), goal_angle=math.radians(angle),
                                                    frame_stack=agent.input_frames)).summary.to_dict()
        rows.append({"goal_deg": angle, "read_deg": math.degrees(estimate.angle), "piga": summary,
                     "planet": "refused: no goal input", "ddpg": "refused: no goal input"})
    return rows


def figures(record: dict[str, Any], out: Path) -> dict[str, str]:
    """The comparison's figures next to OUT.md: sample efficiency, DDPG learning curves, gravity sweep.
    Returns their file names by part."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from piga.evaluation.plots import save_figure

    names = {part: f"{out.name}-{part}.png" for part in ("sample_efficiency", "ddpg", "sweep")}
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained")
    for agent, color in (("piga", "C0"), ("planet", "C1")):
        rows = [r for r in record["sample_efficiency"] if r["agent"] == agent and r["runs"]]  # sizes with a record
        label = "piga" if agent == "piga" else "PlaNet-style"
        for ax, key, mean_key in ((axes[0], "success_rate", "success_mean"), (axes[1], "mean_return", "return_mean")):
            scale = 100 if key == "success_rate" else 1
            for r in rows:
                ax.scatter([r["sequences"]] * len(r["runs"]), [scale * run["control"][key] for run in r["runs"]], color=color, s=12, alpha=0.5)
            ax.plot([r["sequences"] for r in rows], [scale * r[mean_key] for r in rows], "-o", color=color, label=label)
    oracle = record["oracle"]
    if oracle is not None:
        axes[0].axhline(100 * oracle["success_rate"], color="gray", ls="--", label="oracle")
        axes[1].axhline(oracle["mean_return"], color="gray", ls="--", label="oracle")
    sizes = sorted({r["sequences"] for r in record["sample_efficiency"] if r["runs"]})
    axes[0].set_ylim(-5, 105)
    for ax, ylabel in ((axes[0], "success (%)"), (axes[1], "mean return")):
        ax.set_xscale("log")
        # (thousands as "1k": the labels "1000" and "2000" ran together)
        ax.set_xticks(sizes, [f"{n // 1000}k" if n >= 1000 and n % 1000 == 0 else str(n) for n in sizes])
        ax.minorticks_off()
        ax.set_xlabel("training sequences")
        ax.set_ylabel(ylabel)
    axes[0].legend(fontsize=7)
    waiting = f"; part-way, {len(record['pending'])} runs pending" if record["pending"] else ""
    fig.suptitle(f"sample efficiency at gravity x1.0 (dots: seeds; line: mean{waiting})", fontsize=9)
    save_figure(fig, out.with_name(names["sample_efficiency"]))
    fig, ax = plt.subplots(figsize=(5, 3.4))
    for i, (algo, obs) in enumerate(dict.fromkeys((r["algo"], r["obs"]) for r in record["ddpg"])):
        runs = [r for r in record["ddpg"] if (r["algo"], r["obs"]) == (algo, obs)]
        for r in runs:
            curve = r["metrics"]["learning_curve"]
            ax.plot([c["step"] for c in curve], [c["eval_mean_return"] for c in curve], color=f"C{i}", alpha=0.8,
                    ls={"ddpg": "-", "sac": ":"}.get(algo, "-."), label=f"{ALGO_LABELS[algo]}, {obs}" if r is runs[0] else None)
    ax.axhline(-200, color="gray", ls="--", lw=0.8)
    ax.set_xlabel("env steps")
    ax.set_ylabel("evaluation mean return")
    if record["ddpg"]:
        ax.legend(fontsize=7, title="SB3 agent, from", title_fontsize=7)
    save_figure(fig, out.with_name(names["ddpg"]))
    fig, ax = plt.subplots(figsize=(5, 3.4))
    ax.set_ylim(-5, 105)
    sweep = record["sweep"]
    for j, agent in enumerate(sweep["agents"]):
        told = agent in ("piga", "oracle")
        wide = agent in ("piga", "planet")  # drawn wide under the thin oracle and DDPG, so that equal lines both show
        ax.plot(sweep["multipliers"], [100 * row[j] for row in sweep["success"]], "-o" if told else "--s",
                lw=4 if wide else 1.5, ms=9 if wide else 5, alpha=0.55 if wide else 1.0, zorder=1 if wide else 2,
                label=f"{agent} ({'told' if told else 'not told'})")
    ax.set_xlabel("gravity multiplier")
    ax.set_ylabel("success (%)")
    ax.legend(fontsize=7)
    save_figure(fig, out.with_name(names["sweep"]))
    return names


def floors(record: dict[str, Any], cfg: BenchConfig, pending: tuple[Job, ...] = ()) -> list[dict[str, Any]]:
    """The comparison's floors (the bars a fair result must clear), each with what the runs with a record
    measured, and the ``pending`` jobs (still without a record) that could change it."""
    def smallest(agent: str, rate: float) -> int | None:
        sizes = [row["sequences"] for row in record["sample_efficiency"]
                 if row["agent"] == agent and row["runs"] and row["success_mean"] >= rate]
        return min(sizes) if sizes else None

    def floor(text: str, measured: str, met: bool, agents: tuple[str, ...], **match: str) -> dict[str, Any]:
        waiting = [job.name for job in pending if job.agent in agents and all(getattr(job, k) == v for k, v in match.items())]
        return {"floor": text, "measured": measured, "met": met, "pending": waiting}

    planet_n, piga_n = smallest("planet", 0.8), smallest("piga", 0.95)
    out = [floor(f"PlaNet-style >= 80% success at x1.0 ({cfg.planet_episode_count} episodes)",
                 f"first at {planet_n} sequences" if planet_n else "at no size", planet_n is not None, ("planet",)),
           floor("piga >= 95% with at most half the sequences PlaNet-style needs for 80%",
                 f"piga {piga_n or 'never'}, PlaNet-style {planet_n or 'never'}",
                 bool(piga_n and planet_n and piga_n <= planet_n / 2), ("piga", "planet"))]
    state = [r for r in record["ddpg"] if (r["algo"], r["obs"]) == ("ddpg", "state")]
    reached = [r for r in state if (r["metrics"]["first_step_reaching_minus_200"] or math.inf) <= 30000]
    out.append(floor("DDPG from state reaches -200 within 30k steps in >= 2 of 3 seeds", f"{len(reached)} of {len(state)}",
                     len(reached) >= 2, ("ddpg",), algo="ddpg", obs="state"))
    sweep = record["sweep"]
    at = [i for i, m in enumerate(sweep["multipliers"]) if abs(m - 1.4) < 1e-9]
    if at:
        cells = dict(zip(sweep["agents"], sweep["success"][at[0]]))
        shown = {agent: f"{100 * cells[agent]:.0f}%" if agent in cells else "no record yet" for agent in ("piga", "oracle", "planet")}
        out.append(floor("at x1.4 piga within 5 points of the oracle (PlaNet-style: measured, not told)",
                         f"piga {shown['piga']}, oracle {shown['oracle']}, PlaNet-style {shown['planet']}",
                         "piga" in cells and "oracle" in cells and cells["piga"] >= cells["oracle"] - 0.05,
                         ("piga", "oracle", "planet")))
    ratios = [(row["ratio_per_step"], row["cpu"]) for row in record["plan_time"] if row["ratio_per_step"]]
    out.append(floor("piga plans >= 20x faster per env step (timed on the same CPU)",
                     ", ".join(f"{ratio:.1f}x on CPU {cpu}" for ratio, cpu in ratios) or "no CPU with both timed yet",
                     bool(ratios) and min(ratio for ratio, _ in ratios) >= 20, ("piga", "planet")))
    return out


AGENT_LABELS = {"piga": "piga", "planet": "PlaNet-style", "oracle": "oracle (true state and physics)"}
"""The agents' names in the summary table; an SB3 run's is "ALGO from" its observation's (:data:`OBS_LABELS`)."""
OBS_LABELS = {"state": "the true state", "latent": "an autoencoder's latent", "pixels": "pixels"}


def agent_label(key: str) -> str:
    """The summary table's name of an agent key: "piga", "planet", "oracle" or "ALGO-OBS" ("sac-pixels")."""
    if key in AGENT_LABELS:
        return AGENT_LABELS[key]
    algo, obs = key.split("-")
    return f"{ALGO_LABELS[algo]} from {OBS_LABELS[obs]}"


def _per_seed(values: list[float | None]) -> str:
    """Success rates, one per seed, None for a run still without a record: "100%, 40%", "100%, pending"."""
    return ", ".join("pending" if v is None else f"{100 * v:.0f}%" for v in values)


def _minutes(seconds: list[float]) -> str:
    """Training minutes over seeds: "54 min" or "16-22 min"."""
    lo, hi = round(min(seconds) / 60), round(max(seconds) / 60)
    return f"{lo} min" if lo == hi else f"{lo}\u2013{hi} min"


def cpu_of(record: dict[str, Any]) -> str:
    """The CPU a record was measured on, as its family/model ("AMD EPYC" names generations of different speeds)."""
    return record["machine"].get("cpu_family_model", "?")


def plan_times(records: dict[str, dict[str, Any] | None], cfg: BenchConfig) -> list[dict[str, Any]]:
    """piga's and PlaNet-style's plan times per env step (median over their runs; PlaNet-style plans once
    every action-repeat steps), a row per CPU their records were measured on, with the ratio where both
    were timed on the same CPU: runs on different machines are not compared."""
    per_cpu: dict[str, dict[str, list[tuple[str, dict[str, Any]]]]] = {}
    for job in jobs_for(cfg):
        record = records[job.name]
        if record and job.agent in ("piga", "planet"):
            per_cpu.setdefault(cpu_of(record), {"piga": [], "planet": []})[job.agent].append((job.name, record))
    rows = []
    for cpu, runs in per_cpu.items():
        piga = statistics.median(r["plan_ms"] for _, r in runs["piga"]) if runs["piga"] else None
        planet = statistics.median(r["plan_ms"] / r["action_repeat"] for _, r in runs["planet"]) if runs["planet"] else None
        rows.append({"cpu": cpu, "piga_runs": [name for name, _ in runs["piga"]], "planet_runs": [name for name, _ in runs["planet"]],
                     "piga_ms": piga, "planet_ms_per_step": planet,
                     "planet_ms_per_plan": statistics.median(r["plan_ms"] for _, r in runs["planet"]) if runs["planet"] else None,
                     "ratio_per_step": planet / piga if piga and planet else None})
    return rows


def _plan_cell(runs: list[dict[str, Any]], per_step: Callable[[dict[str, Any]], float], piga_ms: dict[str, float], digits: int, ratio: bool = False) -> str:
    """A summary cell of plan time per env step: the median of ``per_step(record)`` over the runs of each CPU
    (their family/model named where the runs span several), with the ratio to piga's median on that CPU
    (``ratio``): a median over runs on different machines would mean nothing."""
    by_cpu: dict[str, list[float]] = {}
    for r in runs:
        by_cpu.setdefault(cpu_of(r), []).append(per_step(r))
    cells = []
    for cpu, values in by_cpu.items():
        ms = statistics.median(values)
        cell = f"{ms:.{digits}f} ms"
        if ratio:
            cell += f" ({ms / piga_ms[cpu]:.0f}x piga)" if cpu in piga_ms else " (piga not timed on its CPU)"
        cells.append(cell + (f" on CPU {cpu}" if len(by_cpu) > 1 else ""))
    return "; ".join(cells)


def summary_table(records: dict[str, dict[str, Any] | None], cfg: BenchConfig) -> str:
    """The README's Baselines table, from the job records alone: a row per agent and data size (piga,
    PlaNet-style), per DDPG observation and for the oracle, each cell over the row's seeds. x1.4 is each
    run's own sweep cell; the plan time is the median over the row's runs, per env step (PlaNet-style
    plans once every action-repeat steps), per CPU, with its ratio to piga's median on the same CPU
    (:func:`plan_times`), none where piga was not timed on it.
    A job still without a record (None) is "pending" in its seed's cells, and left out of the others."""
    groups: dict[tuple[str, int], list[dict[str, Any] | None]] = {}  # (agent label key, sequences or env steps): the seeds' records
    for job in jobs_for(cfg):
        key = f"{job.algo}-{job.obs}" if job.agent == "ddpg" else job.agent
        groups.setdefault((key, job.sequences or job.steps), []).append(records[job.name])
    piga_ms = {row["cpu"]: row["piga_ms"] for row in plan_times(records, cfg) if row["piga_ms"]}
    sweep_at = "1.4" if "1.4" in (f"{m:g}" for m in parse_range(cfg.sweep)) else None  # the records' sweep keys

    def counts(others: int, planet: int) -> str:
        return f"{others} episode{'s' * (others != 1)}" + ("" if planet == others else f", PlaNet-style {planet}")

    lines = [f"| agent | training data | training time (one thread) | success x1.0 ({counts(cfg.episodes, cfg.planet_episode_count)}; "
             f"per seed) | mean return | success x1.4 ({counts(cfg.sweep_episodes, sweep_episodes(cfg, 'planet'))}) | goal images "
             "| plan time per env step |", "|---|---|---|---|---|---|---|---|"]
    for (agent, size), all_runs in groups.items():
        runs = [r for r in all_runs if r is not None]
        seeds = f" ({len(all_runs)} seeds)" if len(all_runs) > 1 else ""
        told = " (told)" if agent in ("piga", "oracle") else " (not told)"
        if agent in ("piga", "planet"):
            data = f"{size} random-action sequences{seeds}"
        elif agent == "oracle":
            data = ""
        else:
            data = f"{size // 1000 if size % 1000 == 0 else size / 1000:g}k env steps{seeds}"
        seconds = [r["train_seconds"] + r.get("metrics", {}).get("autoencoder_train_seconds", 0.0) for r in runs if "train_seconds" in r]
        train = _minutes(seconds) if seconds else ""
        if agent.endswith("-latent") and seconds:
            train += " (autoencoder included)"
        x14 = _per_seed([r and r["sweep"][sweep_at]["success_rate"] for r in all_runs]) + told if sweep_at else ""
        if agent == "piga" and runs:
            goals = [g["piga"]["success_rate"] for r in runs for g in r["goals"]]
            goal = f"{len(runs[0]['goals'])} goal{'s' * (len(runs[0]['goals']) != 1)}, {100 * sum(goals) / len(goals):.0f}%"
            plan = _plan_cell(runs, lambda r: r["plan_ms"], piga_ms, digits=1)
        elif agent in ("piga", "oracle"):
            goal = plan = ""
        else:
            goal, plan = "refused (no goal input)", ""
        if agent == "planet" and runs:
            plan = _plan_cell(runs, lambda r: r["plan_ms"] / r["action_repeat"], piga_ms, digits=0, ratio=True)
        mean_return = _num(statistics.mean(r["control"]["mean_return"] for r in runs)) if runs else "pending"
        cells = [agent_label(agent), data, train, _per_seed([r and r["control"]["success_rate"] for r in all_runs]),
                 mean_return, x14, goal, plan]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _pending_note(record: dict[str, Any]) -> list[str]:
    """The page's warning while some jobs have no record: which, and that the tables cover the others only."""
    if not record["pending"]:
        return []
    total = record["job_count"]
    return [f"**Part-way: {total - len(record['pending'])} of {total} runs have a record.** Still to run: "
            + ", ".join(f"`{name}`" for name in record["pending"])
            + ". Every table and figure below reads the runs with a record only, and a floor that a pending run "
              "could change says so. The same command continues the rest.\n"]


def _invocation_line(record: dict[str, Any]) -> str:
    """What the invocation that wrote the page ran, and its wall time (a record without ``jobs_run`` predates it)."""
    ran = record.get("jobs_run")
    if ran == []:
        return ("\nThe invocation that wrote this page ran no job: it read the records that earlier invocations kept "
                "(each run's training time is its own record's).\n")
    what = f", running {', '.join(ran)}" if ran else ""
    return (f"\nWall time of the invocation that wrote this page: {record['wall_seconds'] / 60:.1f} min{what} (records "
            "kept from earlier invocations are not run again).\n")


def markdown(record: dict[str, Any]) -> str:
    """The results page."""
    lines = [f"# Baselines: piga, PlaNet-style and DDPG\n\nCommand: `{record['command']}` (preset `{record['preset']}`)\n",
             *_pending_note(record),
             # the records' machines, not the invocation's: a page is written from runs made on several
             (f"Machines: {len(record['job_machines'])} (each run's under Compute), torch "
              f"{', '.join(record['torch_versions'])}, each training on one torch thread.\n"),
             "## Summary\n\nThe README's table. A row per agent and data size, each cell over the row's seeds; x1.4 is "
             "each run's own sweep cell; the plan time is the median of the row's runs on each CPU, per env step, and "
             "its ratio to piga's median on the same CPU (none where piga was not timed on it).\n", record["summary_table"],
             "## Sample efficiency (gravity x1.0)\n",
             f"![sample efficiency]({record['figures']['sample_efficiency']})\n",
             "| sequences | agent | seeds | success (mean) | mean return | train s (mean) |", "|---|---|---|---|---|---|"]
    for row in record["sample_efficiency"]:
        seeds = str(len(row["runs"])) + (f" ({len(row['pending_seeds'])} pending)" if row["pending_seeds"] else "")
        if row["runs"]:
            lines.append(f"| {row['sequences']} | {row['agent']} | {seeds} | {100 * row['success_mean']:.0f}% | "
                         f"{row['return_mean']:.1f} | {row['train_seconds_mean']:.0f} |")
        else:
            lines.append(f"| {row['sequences']} | {row['agent']} | {seeds} | pending | pending | pending |")
    o = record["oracle"]
    lines += ["\nOracle: " + ("pending" if o is None else f"{100 * o['success_rate']:.0f}% success, mean return {o['mean_return']:.1f}") + ".\n",
              *data_ratio_lines(record),
              "## DDPG (and SAC, its stronger sibling, and DrQ-v2)\n", f"![DDPG learning curves]({record['figures']['ddpg']})\n",
              "| algorithm | observation | seed | steps | first step at >= -200 | final eval return | success | train s |",
              "|---|---|---|---|---|---|---|---|"]
    for r in record["ddpg"]:
        final = r["metrics"]["final_eval_mean_return"]
        lines.append(f"| {ALGO_LABELS[r['algo']]} | {r['obs']} | {r['seed']} | {r['metrics']['steps']} | "
                     f"{r['metrics']['first_step_reaching_minus_200'] or 'never'} | "
                     f"{'n/a' if final is None else f'{final:.1f}'} | {100 * r['control']['success_rate']:.0f}% | "
                     f"{r['metrics']['train_seconds']:.0f}" + _autoencoder_seconds(r['metrics']) + " |")
    sb3_pending = [name for name in record["pending"] if name.startswith(tuple(f"{algo}-" for algo in ALGO_LABELS))]
    if sb3_pending:
        lines.append(f"\nPending: {', '.join(sb3_pending)}.")
    lines += ["\n## Zero-shot gravity sweep (piga and the oracle told the multiplier; baselines not told)\n",
              f"![gravity sweep]({record['figures']['sweep']})\n",
              "Runs (each agent's best at x1.0 among the runs with a record; they also give the goal images and plan times): "
              + ", ".join(f"{agent} `{Path(run).name}`" for agent, run in record["sweep"]["runs"].items()) + ".\n",
              "| gravity x | " + " | ".join(record["sweep"]["agents"]) + " |", "|---|" + "---|" * len(record["sweep"]["agents"])]
    for m, cells in zip(record["sweep"]["multipliers"], record["sweep"]["success"]):
        lines.append(f"| {m:g} | " + " | ".join(f"{100 * c:.0f}%" for c in cells) + " |")
    lines += ["\n## Goal images\n", "| goal (deg) | read (deg) | piga success | PlaNet-style | DDPG |", "|---|---|---|---|---|"]
    for g in record["goals"]:
        lines.append(f"| {g['goal_deg']:g} | {g['read_deg']:.2f} | {100 * g['piga']['success_rate']:.0f}% | {g['planet']} | {g['ddpg']} |")
    lines += [f"\n## Plan time (median per env step; each run timed over one {record['config']['episode_steps']}-step episode "
              "in one process after its training, beside whatever else ran)\n",
              "piga plans at every env step, PlaNet-style once every action-repeat steps. Plan times are compared only "
              "on the same CPU (family/model). Where the records leave a CPU without piga, `benchmarks/plan_time.py "
              "--model PIGA_RUN --planet PLANET_RUN` times both agents in one process (results/plan_time_planet.md).\n",
              "| CPU | piga runs | piga ms per step | PlaNet-style runs | PlaNet-style ms per plan | per env step | ratio per env step |",
              "|---|---|---|---|---|---|---|"]
    for row in record["plan_time"]:
        def ms(x: float | None, digits: int) -> str:
            return "" if x is None else f"{x:.{digits}f}"
        lines.append(f"| {row['cpu']} | {len(row['piga_runs'])} | {ms(row['piga_ms'], 2)} | {len(row['planet_runs'])} | "
                     f"{ms(row['planet_ms_per_plan'], 1)} | {ms(row['planet_ms_per_step'], 1)} | "
                     + ("" if row["ratio_per_step"] is None else f"{row['ratio_per_step']:.1f}x") + " |")
    lines.append("")
    lines += ["## Floors\n", "| floor | measured | met |", "|---|---|---|",
              *[f"| {f['floor']} | {f['measured']} | {'yes' if f['met'] else 'no'}"
                + (f" (so far: {len(f['pending'])} run{'s' * (len(f['pending']) != 1)} pending)" if f["pending"] else "") + " |"
                for f in record["floors"]], "",
              ("## Compute\n\nTraining seconds are in the tables, one torch thread per run, most runs beside a second job on "
               "the machine's other core (jobs of one invocation, or invocations with `--workers 1` side by side). "
               "Each run's record names the machine it ran on:\n"),
              *[f"- {m}: {', '.join(names)}" for m, names in record["job_machines"].items()],
              _invocation_line(record)]
    return "\n".join(lines) + "\n"


def aggregate(records: dict[str, dict[str, Any] | None], cfg: BenchConfig) -> dict[str, Any]:
    """The comparison from the job records (:func:`run_all`; None for a job still to run): sample
    efficiency, the oracle, the SB3 runs, the sweep of each agent's best run, its goal images, the plan
    times, the machines, the floors and the README's table. Every part reads only the records there are,
    and ``pending`` names the jobs still to run, so that a page written part-way says what it lacks."""
    pending = tuple(job for job in jobs_for(cfg) if records[job.name] is None)
    out: dict[str, Any] = {"pending": [job.name for job in pending], "job_count": len(records)}
    rows = []
    for agent, sizes, seeds_at in (("piga", cfg.sizes, cfg.piga_seeds_at), ("planet", cfg.planet_size_list, cfg.planet_seeds_at)):
        for n in sizes:
            kept = {seed: records[f"{agent}-n{n}-s{seed}"] for seed in seeds_at(n)}
            runs = [{"seed": seed, "train_seconds": r["train_seconds"], "control": r["control"]} for seed, r in kept.items() if r]
            row: dict[str, Any] = {"sequences": n, "agent": agent, "runs": runs,
                                   "pending_seeds": [seed for seed, r in kept.items() if r is None]}
            if runs:
                row.update(success_mean=statistics.mean(r["control"]["success_rate"] for r in runs),
                           return_mean=statistics.mean(r["control"]["mean_return"] for r in runs),
                           train_seconds_mean=statistics.mean(r["train_seconds"] for r in runs))
            rows.append(row)
    out["sample_efficiency"] = rows
    out["data_ratio"] = data_ratios(rows)
    out["data_ratio_claim"] = data_ratio_claim(out["data_ratio"])
    out["oracle"] = records["oracle"]["control"] if records["oracle"] else None
    out["ddpg"] = [{"algo": job.algo, "obs": job.obs, "seed": job.seed, "metrics": kept["metrics"], "control": kept["control"]}
                   for job in jobs_for(cfg) if job.agent == "ddpg" and (kept := records[job.name])]
    best = {agent: run for agent in ("piga", "planet", "ddpg") if (run := best_run(out, agent))}
    runs = {"piga": best.get("piga"), "oracle": "oracle" if records["oracle"] else None,
            "planet": best.get("planet"), "ddpg": best.get("ddpg")}
    sweep_agents = [agent for agent, run in runs.items() if run]
    multipliers = parse_range(cfg.sweep)
    out["sweep"] = {"agents": sweep_agents, "multipliers": multipliers, "runs": best,
                    "success": [[records[runs[a]]["sweep"][f"{m:g}"]["success_rate"] for a in sweep_agents] for m in multipliers]}
    out["goals"] = records[best["piga"]]["goals"] if "piga" in best else []
    out["plan_time"] = plan_times(records, cfg)
    machines: dict[str, list[str]] = {}
    torch_versions: set[str] = set()
    for name, kept in records.items():
        if kept:
            m = kept["machine"]
            machines.setdefault(f"{m['cpu']} (family/model {m.get('cpu_family_model', '?')}), {m['cores']} cores", []).append(name)
            torch_versions.add(m["torch"])
    out["job_machines"] = machines
    out["torch_versions"] = sorted(torch_versions)
    out["floors"] = floors(out, cfg, pending)
    out["summary_table"] = summary_table(records, cfg)
    return out


#: Success thresholds at which the two agents' data needs are compared (the floors' 80% and 95%).
RATIO_THRESHOLDS = (0.8, 0.95)


def data_ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """At each of :data:`RATIO_THRESHOLDS`, the sequences piga and the PlaNet-style model need and their ratio
    with bootstrap intervals (:func:`efficiency.data_ratio`), from the sample-efficiency rows with runs; none
    until both agents have one."""
    points = {agent: [Point(row["sequences"], tuple((round(r["control"]["success_rate"] * r["control"]["episodes"]),
                                                     r["control"]["episodes"]) for r in row["runs"]))
                      for row in rows if row["agent"] == agent and row["runs"]] for agent in ("piga", "planet")}
    if not points["piga"] or not points["planet"]:
        return []
    return [data_ratio(points["planet"], points["piga"], threshold) for threshold in RATIO_THRESHOLDS]


def need_cell(need: dict[str, Any]) -> str:
    """A need of :func:`efficiency.data_ratio` in words: its sequences and interval, or the bound it is."""
    interval, share = f"95%: {need['low']:,.0f}–{need['high']:,.0f}", need["bounded_draws"]
    if need["bound"] != "exact":
        what = "at most" if need["bound"] == "at_most" else "more than"
        where = "smallest" if need["bound"] == "at_most" else "largest"
        return f"{what} {need['value']:,.0f} (its {where} size; " + ("in every draw)" if share == 1 else f"{interval})")
    part = "under 1%" if share < 0.005 else f"{100 * share:.0f}%"
    return f"{need['value']:,.0f} ({interval}" + (f"; {part} of draws a bound)" if share else ")")


def ratio_cell(ratio: dict[str, Any], what: str = "") -> str:
    """A ratio of :func:`efficiency.data_ratio` in words (``what`` after the "x"): its value, bound and interval."""
    prefix = {"exact": "", "at_least": "at least ", "at_most": "at most ", "undefined": "undefined: "}[ratio["bound"]]
    return f"{prefix}{ratio['value']:,.0f}x{what} (95%: {ratio['low']:,.0f}–{ratio['high']:,.0f}x)"


def data_ratio_claim(ratios: list[dict[str, Any]]) -> str:
    """The README's data-efficiency sentence, from :func:`data_ratios` (empty until both agents have runs)."""
    if not ratios:
        return ""
    first, *rest = ratios
    text = (f"At {100 * first['threshold']:.0f}% success, the PlaNet-style model needs "
            f"{need_cell(first['numerator'])} sequences and piga {need_cell(first['denominator'])}: "
            f"{ratio_cell(first['ratio'], ' the data')}")
    more = "; ".join(f"At {100 * r['threshold']:.0f}%, {ratio_cell(r['ratio'])}" for r in rest)
    return text + "." + (f" {more}." if more else "")


def data_ratio_lines(record: dict[str, Any]) -> list[str]:
    """The results page's section on the data each agent needs at equal success."""
    if not record["data_ratio"]:
        return []
    draws = record["data_ratio"][0]["draws"]
    seeds = {agent: sorted({len(row["runs"]) for row in record["sample_efficiency"] if row["agent"] == agent and row["runs"]})
             for agent in ("piga", "planet")}
    spread = {agent: f"{min(n)}–{max(n)}" if min(n) != max(n) else f"{n[0]}" for agent, n in seeds.items()}
    lines = ["## Data needed at equal success\n",
             "The sequences each agent needs to reach a success rate at x1.0, read off its curve above (the mean over "
             "seeds at each size) where it first reaches the rate, interpolated in log(sequences) between the grid "
             "points around it; and the PlaNet-style model's need over piga's. A curve already at the rate at its "
             "smallest size gives only an upper bound on that agent's need, so the ratio is then a lower bound (and its "
             f"interval the bound's). Intervals: 95% percentiles over {draws:,} bootstrap draws that resample each "
             "size's seeds, then each seed's episodes (`benchmarks/efficiency.py`), on one data draw"
             + ("; the runs still to run are not in them" if record["pending"] else "") +
             f". Seeds per point: piga {spread['piga']}, PlaNet-style {spread['planet']}; with so few, the "
             "intervals understate the spread between seeds.\n",
             "| success | piga needs (sequences) | PlaNet-style needs (sequences) | PlaNet-style / piga |", "|---|---|---|---|"]
    for row in record["data_ratio"]:
        lines.append(f"| {100 * row['threshold']:.0f}% | {need_cell(row['denominator'])} | {need_cell(row['numerator'])} | "
                     f"{ratio_cell(row['ratio'])} |")
    return lines + ["", f"The README's sentence: {record['data_ratio_claim']}\n"]


@farm_main
def main() -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="writes OUT.json, OUT.md, OUT-*.png; runs in OUT_runs/")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    p.add_argument("--workers", type=positive_int, help="processes (default: the preset's, 2)")
    add_ray_option(p, "the jobs (OUT_runs shared by every machine)")
    p.add_argument("--estimate", action="store_true", help="print the estimated cost of the preset and exit")
    p.add_argument("--only", default=",".join(AGENTS), metavar="JOBS",
                   help=f"run only these jobs, comma-separated: kinds ({', '.join(AGENTS)}) or names (planet-n500-s1); "
                        "the results are written from every record there is, the jobs still to run named")
    args = p.parse_args()
    cfg = PRESETS[args.preset] if args.workers is None else replace(PRESETS[args.preset], workers=args.workers)
    only = tuple(args.only.split(","))
    unknown = set(only) - set(AGENTS) - {job.name for job in jobs_for(cfg)}
    if unknown:
        p.error(f"--only takes {', '.join(AGENTS)} or the preset's job names, not {', '.join(sorted(unknown))}")
    cost = estimate(cfg)
    print(f"estimate (COST_S): {', '.join(f'{k} {v / 3600:.1f} h' for k, v in cost.items())}", flush=True)
    if args.estimate:
        return 0
    import time

    import torch

    backend = ray_backend(p, args)
    torch.set_num_threads(1)
    started = time.monotonic()
    out = Path(args.out)
    folder = out.with_name(out.name + "_runs")
    folder.mkdir(parents=True, exist_ok=True)
    # the command that writes the whole page (any --only runs some jobs only), and this invocation's own
    command = ["python", "benchmarks/baselines.py", "--out", str(args.out), "--preset", args.preset]
    record: dict[str, Any] = {"command": shlex.join(command), "invocation": shlex.join(["python", *sys.argv]),
                              "preset": args.preset, "config": asdict(cfg), "machine": machine(), "estimate_seconds": cost}
    kept = {job.name for job in jobs_for(cfg) if kept_record(folder, job, cfg) is not None}
    records = run_all(cfg, folder, only, backend)
    record["jobs_run"] = [name for name, kept_or_run in records.items() if kept_or_run is not None and name not in kept]
    record.update(aggregate(records, cfg))
    if record["pending"]:
        print(f"{len(records) - len(record['pending'])} of {len(records)} jobs have a record; still to run: "
              f"{', '.join(record['pending'])}. {out.with_suffix('.md')} is written from the records there are.", flush=True)
    record["wall_seconds"] = time.monotonic() - started
    record["figures"] = figures(record, out)
    with written_together([out.with_suffix(".json"), out.with_suffix(".md")]):
        write_json(out.with_suffix(".json"), record)
        with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
            tmp.write_text(markdown(record))
    print(f"wrote {out.with_suffix('.json')}, {out.with_suffix('.md')} and the figures {', '.join(record['figures'].values())}")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
