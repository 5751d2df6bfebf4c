"""Benchmark: control from pixels with the learned model, against the oracle (with the control floors).

It runs, with a model trained by ``piga-train-model`` (default preset, default data):

1. upright swing-up at gravity x1.0: the piga agent and the oracle, ``--episodes`` each (50);
2. zero-shot gravity x1.4: both agents are told the multiplier, ``--episodes`` each;
3. the sweep 0.5:1.8:0.1, ``--sweep-episodes`` each (10), with a plot;
4. goals given as images, spread over the feasible range (within 0.9 x asin(4a/g) of upright and
   of hanging down): a goal image is written with Gymnasium's renderer at each true angle, the
   agent reads its goal from the image with its encoder, and its final error is measured against
   the true angle; the oracle, told the true angle, is the reference;
5. plan time of the tuned planner next to PlaNet's CEM defaults (H 12, 10 iterations, 1000
   candidates, top 100, no warm start), ``--planet-episodes`` each (10).

Episode 0 of each batch starts hanging straight down at rest; the others start at θ ~ U(-π, π),
θ̇ ~ U(-1, 1). Success: |θ - θ_goal| < 0.2 rad and |θ̇| < 1 rad/s for each of the last 20 of 200
steps. Jobs run in ``--workers`` processes, one torch thread each, so plan times are per core
with the other core busy; or with ``--ray auto|HOST:PORT`` as tasks of a Ray cluster (the same episodes
and scores; the plan times are those of the cluster's CPUs).

    python benchmarks/control.py --model RUN_DIR --out results/control

Writes OUT.json, OUT.md (tables and checks against the floors) and OUT-sweep.png.
"""

from __future__ import annotations

import math
import shlex
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from common import add_ray_option, check_page_target, farm_main, machine, out_prefix, ray_backend
from agents.cem import CEMConfig
from agents.mpc import MPCConfig
from piga.io.atomic import atomic_output, write_json, written_together
from piga.control.episodes import EpisodeConfig, parse_range
from piga.control.jobs import ControlJob, run_jobs
from piga.evaluation.episodes import EpisodeSummary, summary_markdown
from piga.evaluation.plots import save_figure, sweep_figure
from piga.io.runs import convergence_warning
from piga.cli.common import ArgumentParser, positive_int, seed_int

#: PlaNet's CEM (Hafner et al., 2019), re-planned from scratch each step.
PLANET = MPCConfig(cem=CEMConfig(), warm_start=False)


def goal_angles(g: float, a: float, count: int = 7) -> list[float]:
    """True goal angles (deg) spread over the feasible range: ``count`` around upright and around hanging."""
    limit = math.degrees(math.asin(min(1.0, 4 * a / g)))
    span = [0.9 * limit * (2 * i / (count - 1) - 1) for i in range(count)]  # -0.9 limit .. 0.9 limit
    return [round(x, 2) for x in span] + [round(math.remainder(180 + x, 360), 2) for x in span]


@farm_main
def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model")
    p.add_argument("--out", type=out_prefix, default="results/control", help="output prefix (default %(default)s)")
    p.add_argument("--episodes", type=positive_int, default=50)
    p.add_argument("--sweep", default="0.5:1.8:0.1")
    p.add_argument("--sweep-episodes", type=positive_int, default=10)
    p.add_argument("--goal-episodes", type=positive_int, default=3)
    p.add_argument("--planet-episodes", type=positive_int, default=10)
    p.add_argument("--workers", type=positive_int, default=2)
    add_ray_option(p, "the control jobs")
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument("--torque-arrow", action="store_true", help="frames show Gymnasium's torque arrow (off by default)")
    p.add_argument("--extra-models", nargs="*", default=[],
                   help="more run folders (other training seeds): upright at x1.0 and x1.4, --sweep-episodes each")
    args = p.parse_args()
    backend = ray_backend(p, args)
    from piga.control.goal import goal_from_image, render_goal_image
    from piga.io.runs import load_model

    check_page_target(Path(args.out), "-sweep.png")  # before the jobs: the pages are written after them
    model, ckpt = load_model(args.model)
    for extra in args.extra_models:  # each is read only inside its jobs, after the others' minutes
        load_model(extra)
    learned = model.physical_parameters()
    tuned = MPCConfig(seed=args.seed)
    planet = replace(PLANET, seed=args.seed)

    def job(agent: str, mult: float, episodes: int, mpc: MPCConfig = tuned, goal: float = 0.0, model_dir: str = args.model,
            **tags: object) -> ControlJob:
        return ControlJob(agent, EpisodeConfig(episodes=episodes, seed=args.seed, gravity_mult=mult, goal_angle=goal,
                                               torque_arrow=args.torque_arrow),
                          mpc, model_dir=model_dir if agent == "piga" else None, tags=tuple(tags.items()))

    jobs: list[ControlJob] = []
    for mult in (1.0, 1.4):
        jobs += [job(agent, mult, args.episodes, part="main") for agent in ("piga", "oracle")]
    jobs += [job("piga", 1.0, args.planet_episodes, planet, part="planet", planner="PlaNet defaults")]
    jobs += [job(agent, m, args.sweep_episodes, part="sweep") for m in parse_range(args.sweep) for agent in ("piga", "oracle")]
    jobs += [job("piga", m, args.sweep_episodes, part="seeds", model_dir=extra, model=extra)
             for extra in args.extra_models for m in (1.0, 1.4)]
    goals = goal_angles(learned["g"], learned["a"])
    read: dict[float, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        import imageio.v3 as iio

        for angle in goals:
            path = Path(tmp) / f"goal_{angle:+.2f}.png"
            iio.imwrite(path, render_goal_image(angle))
            estimate = goal_from_image(model, ckpt, path)
            read[angle] = math.degrees(estimate.angle)
            jobs.append(job("piga", 1.0, args.goal_episodes, replace(tuned, goal_angle=estimate.angle), math.radians(angle),
                            part="goal", read_goal_deg=round(read[angle], 3)))
            jobs.append(job("oracle", 1.0, args.goal_episodes, replace(tuned, goal_angle=math.radians(angle)),
                            math.radians(angle), part="goal"))
    for run_dir in dict.fromkeys(j.model_dir for j in jobs if j.model_dir is not None):  # once per run, in order
        if (warning := convergence_warning(run_dir)) is not None:
            print(warning, file=sys.stderr)
    t0 = time.time()
    results = run_jobs(jobs, workers=args.workers, backend=backend)
    minutes = (time.time() - t0) / 60
    s = [r.summary for r in results]

    def pick(part: str, agent: str | None = None, mult: float | None = None) -> list[EpisodeSummary]:
        return [x for x in s if x.labels["part"] == part and (agent is None or x.labels["agent"] == agent)
                and (mult is None or abs(x.gravity_mult - mult) < 1e-9)]

    main_rows = pick("main")
    (p1,), (o1,) = pick("main", "piga", 1.0), pick("main", "oracle", 1.0)
    (p14,), (o14,) = pick("main", "piga", 1.4), pick("main", "oracle", 1.4)
    (pl,) = pick("planet")
    goal_piga, goal_oracle = pick("goal", "piga"), pick("goal", "oracle")
    goal_err = sum(math.degrees(x.final_angle_error_mean) for x in goal_piga) / len(goal_piga)
    goal_err_oracle = sum(math.degrees(x.final_angle_error_mean) for x in goal_oracle) / len(goal_oracle)
    return_gap = abs(p1.mean_return - o1.mean_return) / abs(o1.mean_return)
    checks = [
        ("x1.0 success >= 95%", f"{100 * p1.success_rate:.0f}%", p1.success_rate >= 0.95),
        ("x1.0 mean return within 5% of the oracle's", f"{100 * return_gap:.1f}% ({p1.mean_return:.1f} vs {o1.mean_return:.1f})",
         return_gap <= 0.05),
        ("x1.4 success within 5 points of the oracle's", f"{100 * p14.success_rate:.0f}% vs {100 * o14.success_rate:.0f}%",
         p14.success_rate >= o14.success_rate - 0.05),
        ("goal images: mean final angle error <= 3 deg", f"{goal_err:.2f} deg (oracle told the true goal: {goal_err_oracle:.2f})",
         goal_err <= 3.0),
        ("plan time <= 2 ms per step (median) and <= 4 ms (p95), encoding included",
         f"{p1.plan_ms_median:.2f} ms (p95 {p1.plan_ms_p95:.2f})", p1.plan_ms_median <= 2.0 and p1.plan_ms_p95 <= 4.0),
    ]
    out = Path(args.out)
    plot = out.with_name(out.name + "-sweep.png")
    save_figure(sweep_figure([x.to_dict() for x in pick("sweep")]), plot)
    command = shlex.join(["python", *sys.argv])
    where = machine()
    runner = f"{args.workers} worker processes" if backend.kind == "local" else f"the tasks of {backend}"
    lines = [
        "# Control from pixels: piga MPC vs the oracle", "",
        f"Command: `{command}`", "",
        f"Model: `{args.model}`, learned g = {learned['g']:.4f}, a = {learned['a']:.4f}. "
        f"Machine: {where['cpu']}, {where['cores']} cores; {runner}, 1 torch thread each; "
        f"{minutes:.1f} min in all. Frames {'with' if args.torque_arrow else 'without'} Gymnasium's torque arrow.", "",
        "Success: |θ − θ_goal| < 0.2 rad and |θ̇| < 1 rad/s for each of the last 20 of 200 steps. Episode 0 of each row "
        "starts hanging down; the others at θ ~ U(−π, π), θ̇ ~ U(−1, 1).", "",
        "## Checks", "", "| floor | measured | met |", "|---|---|---|",
        *[f"| {name} | {value} | {'yes' if ok else '**no**'} |" for name, value, ok in checks], "",
        "## Upright, gravity x1.0 and x1.4 (told to the agent, no retraining)", "", summary_markdown(main_rows),
        "## Planner settings: tuned defaults vs PlaNet's", "",
        f"Tuned: CEM H {tuned.cem.horizon}, {tuned.cem.iterations} iterations, {tuned.cem.candidates} candidates, top "
        f"{tuned.cem.elites}, warm start (std {tuned.warm_init_std}), executes the CEM mean. PlaNet: H 12, 10 iterations, "
        "1000 candidates, top 100, no warm start.", "",
        summary_markdown([p1.labelled(planner="tuned"), pl], extra=[("planner", "planner")]),
        f"## Gravity sweep {args.sweep} ({args.sweep_episodes} episodes per row)", "", f"![sweep]({plot.name})", "",
        summary_markdown(pick("sweep")),
        *(["## Other models (other training seeds), upright", "",
            summary_markdown(pick("seeds"), extra=[("model", "model")])] if args.extra_models else []),
        "## Goals given as images", "",
        "True goal angles span 0.9 x the feasible range around upright and around hanging. The piga agent reads its goal "
        "from a 500x500 render of the goal (no torque arrow) with its encoder; the oracle is told the true angle.", "",
        summary_markdown(goal_piga + goal_oracle, extra=[("read_goal_deg", "goal read from image (deg)")]),
    ]
    md = "\n".join(lines)
    with written_together([out.with_suffix(".json"), out.with_suffix(".md")]):
        with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp_md:
            tmp_md.write_text(md)
        write_json(out.with_suffix(".json"), {"command": command, "machine": where, "backend": str(backend),
                                              "model": args.model, "learned": learned, "minutes": minutes,
                                              "checks": [{"floor": n, "measured": v, "met": ok} for n, v, ok in checks],
                                              "results": [r.to_dict() for r in results]}, overwrite=True)
    print("\n".join(f"{'PASS' if ok else 'FAIL'}  {n}: {v}" for n, v, ok in checks))
    print(f"wrote {out.with_suffix('.md')}, {out.with_suffix('.json')}, {plot}")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
