"""Benchmark: the paper's Table 1 from pixels. Each scene is collected, trained on with its ``fast``
preset for several seeds, and evaluated on held-out sequences.

For each system it collects one data set with ``piga-collect --system SYSTEM`` (the scene's
defaults: 1000 sequences, split 800/100/100, data seed 100), trains with ``piga-train-model``'s
``fast`` preset (chosen by the file's scene; it never reads /states, and k, l, g start at 1), and
records the learned parameters against the truth and against the paper's learned values, SSIM
and MSE per predicted and extrapolated step, and the training minutes.

    python benchmarks/systems.py --out results/systems                       # 5 cases x 3 seeds
    python benchmarks/systems.py --out results/systems --systems spring --seeds 0
    python benchmarks/systems.py --out results/systems --heldout             # and the held-out table

The cases are the four systems and ``gravity-m``, the paper's m run: the gravity data again, with g
held at the value they were collected with (60, the user's knowledge, given as ``--fixed-g``) and the
shared mass m learned from 1/60. ``--heldout`` adds one seed each of the same fast preset on data
collected at other values (:data:`HELDOUT`): the spring at other k, l and with another look (ball
radius, colours, background), gravity at another g, the digits at other k, l.

Runs are resumable: a finished run (its RUN_DIR/metrics.json) is read, not retrained, and each
finished run is saved to ``OUT.json`` at once. A finished run whose model was built with another recipe
than today's fast preset stops the benchmark with one line (remove it, or use another ``--work``); one
evaluated with fewer extrapolated frames than its recipe's T_ext is re-evaluated from its checkpoint. The data sets
are collected first; then the runs are jobs of piga's job runner (:func:`piga.io.pool.run_pool`), each training
with one thread: one at a time by default, so that its minutes are measured on one core of the machine (recorded
in OUT.json), under whatever else runs; ``--jobs N`` trains N at once in processes of this machine, and
``--ray auto|HOST:PORT`` as tasks of a Ray cluster (``--work`` then one folder shared by every machine). The
learned values do not depend on where a run trained; its minutes do. A run that raises stops the benchmark with
one line naming it, keeping the runs finished before it.
Writes ``OUT.json``, ``OUT.md``, ``OUT-ssim.png`` (SSIM per step) and ``OUT-rollout-SYSTEM.png``.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

from common import add_ray_option, farm_main, machine, out_prefix, ray_backend, work_folder

from envs.scenes import scene_config
from piga.io.atomic import write_json
from piga.data.collect_scenes import SCENE_PRESETS as DATA_PRESETS
from piga.data.collect_scenes import SCENE_STEPS, SceneCollectConfig, collect_scene
from piga.data.schema import inspect_dataset
from piga.io.pool import run_pool
from piga.training.report import write_run_report
from piga.training.train import preset_for, train
from piga.cli.common import ArgumentParser, positive_int, seed_int

#: Case -> the paper's learned values (its Table 1; none for bouncing). A case is a system, or
#: "gravity-m": the gravity data with g held at the collection's value and the mass m learned
#: (``piga-train-model --fixed-g 60``).
PAPER_LEARNED: dict[str, dict[str, float]] = {
    "spring": {"k": 4.26, "l": 6.17},
    "digits-spring": {"k": 2.18, "l": 12.24},
    "gravity": {"g": 65.7},
    "gravity-m": {"m": 0.95},
    "bouncing": {},
}
SYSTEMS = list(PAPER_LEARNED)
DATA_SEED = 100
#: Case -> (the scene whose data it trains on, system options (``ModelConfig.with_options``) on top of the fast
#: preset). The m run's g is the value the data were collected with: what the user knows, given on the command line.
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    **{system: (system, {}) for system in SYSTEMS if system != "gravity-m"},
    "gravity-m": ("gravity", {"fixed_g": scene_config("gravity").params["g"]}),
}

#: Held-out data (``--heldout``): the same fast preset, unchanged, on other parameter values and, for
#: the spring, another look (the renderer's other colours, ball radius and background; colours as
#: matplotlib names them, as ``piga-collect --colors`` takes them). Name -> the scene and its collection
#: overrides (:func:`envs.scenes.scene_config`).
HELDOUT: dict[str, tuple[str, dict[str, Any]]] = {
    "spring-k5-l7-look": ("spring", {"params": {"k": 5.0, "l": 7.0}, "radius": 4.0, "colors": ("gold", "turquoise"),
                                     "background": "#401a4d"}),
    "gravity-g40": ("gravity", {"params": {"g": 40.0}}),
    "digits-spring-k3-l10": ("digits-spring", {"params": {"k": 3.0, "l": 10.0}}),
}


def _collect(name: str, scene: str, overrides: dict[str, Any], folder: Path) -> Path:
    """A data set (collected once, with the scene's defaults and ``overrides``)."""
    from matplotlib.colors import to_rgb

    path = folder / f"{name}.h5"
    if not path.exists():
        look = {"colors": tuple(map(to_rgb, overrides["colors"]))} if "colors" in overrides else {}
        if "background" in overrides:
            look["background"] = to_rgb(overrides["background"])
        config = SceneCollectConfig(scene=scene_config(scene, **{**overrides, **look}),
                                    sequences=DATA_PRESETS["default"].sequences,
                                    steps=SCENE_STEPS[scene], seed=DATA_SEED, workers=2)
        collect_scene(config, path, command=f"piga-collect --system {scene} --seed {DATA_SEED} {_look(overrides)} "
                      f"--out {path}", progress=False)
    return path


def _data(system: str, folder: Path) -> Path:
    """The data set of a case of :data:`CASES` (one per scene, with the scene's defaults)."""
    scene = CASES[system][0]
    return _collect(scene, scene, {}, folder)


def _run(case: str, seed: int, data: Path, folder: Path, overrides: dict[str, Any] | None = None,
         name: str | None = None) -> dict[str, Any]:
    """One training run with the fast preset (plus ``overrides`` of its system options); reused if its metrics exist.

    A finished run whose metrics extrapolate fewer frames than its recipe's T_ext (a run made before
    gravity's T_ext was 24) is re-evaluated from its checkpoint, not retrained.
    """
    import json

    from piga.evaluation.evaluate import EvalConfig
    from piga.io.runs import load_model
    from piga.training.train import TrainState

    run_dir = folder / f"{name or case}-seed{seed}"
    metrics_path = run_dir / "metrics.json"
    info = inspect_dataset(data)
    preset = preset_for("fast", info)
    model_config = preset.model.with_options(**(overrides or {}))
    if not metrics_path.exists():
        config = replace(preset.train, seed=seed, threads=1)
        if run_dir.exists():
            shutil.rmtree(run_dir)  # an interrupted run restarts from scratch
        model, state = train(data, run_dir, config, model_config, progress=False)
        write_run_report(model, state, data, run_dir)
        (run_dir / "load.json").write_text(json.dumps({"load_average_at_end": os.getloadavg()}))
    _check_recipe(run_dir, info, model_config)
    metrics = json.loads(metrics_path.read_text())
    t_ext = model_config.extrapolate_frames
    expected = min(t_ext, info.steps - metrics["input_frames"] - metrics["pred_frames"])
    if metrics["extrapolate_frames"] < expected:
        model, ckpt = load_model(run_dir)
        seconds = metrics["training"]["seconds"]  # the training time, measured when it trained
        metrics = write_run_report(model, TrainState(**ckpt["state"]), data, run_dir,
                                   EvalConfig(extrapolate_frames=t_ext))
        metrics["training"]["seconds"] = seconds
        write_json(metrics_path, metrics)
    load = json.loads((run_dir / "load.json").read_text())["load_average_at_end"] if (run_dir / "load.json").exists() else None
    return {"system": case, "seed": seed, "run": str(run_dir), "metrics": metrics, "load_average_at_end": load}


def _check_recipe(run_dir: Path, info: Any, model_config: Any) -> None:
    """Refuses to reuse a finished run whose model was built with another recipe than today's fast preset
    (T_ext aside: only evaluation uses it, and :func:`_run` re-evaluates)."""
    import torch

    from piga.training.train import model_config_for

    from piga.world.model import ModelConfig

    saved = ModelConfig.from_dict(torch.load(run_dir / "checkpoint.pt", map_location="cpu",  # a field newer than the
                                             weights_only=False)["model_config"]).to_dict()  # run: its default
    wanted = model_config_for(info, model_config).to_dict()
    changed = [k for k in wanted if k != "extrapolate_frames" and json.dumps(saved[k]) != json.dumps(wanted[k])]
    if changed:
        raise ValueError(f"{run_dir} was trained with another recipe ({', '.join(f'{k}: {saved.get(k)} -> {wanted[k]}' for k in changed)}); "
                         "remove it (or use another --work) to retrain it")


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def summary(runs: list[dict[str, Any]], cases: list[str] | None = None,
            paper: dict[str, dict[str, float]] | None = None) -> dict[str, Any]:
    """Per case: learned values per seed, median error, max error, SSIM per step (mean over seeds), minutes."""
    out: dict[str, Any] = {}
    for system in cases or SYSTEMS:
        rows = [r for r in runs if r["system"] == system]
        if not rows:
            continue
        errors = rows[0]["metrics"]["parameter_errors"]
        params: dict[str, Any] = {}
        for name in errors:
            learned = [r["metrics"]["parameter_errors"][name]["learned"] for r in rows]
            rel = [r["metrics"]["parameter_errors"][name]["relative_error"] for r in rows]
            params[name] = {"true": errors[name]["true"], "learned": learned, "median_learned": _median(learned),
                            "relative_errors": rel, "max_relative_error": max(rel),
                            "within_5pct": sum(e <= 0.05 for e in rel),
                            "paper_learned": (PAPER_LEARNED if paper is None else paper).get(system, {}).get(name)}
        steps = len(rows[0]["metrics"]["frame_ssim_per_step"])
        ssim = [statistics.fmean(r["metrics"]["frame_ssim_per_step"][t] for r in rows) for t in range(steps)]
        mse = [statistics.fmean(r["metrics"]["frame_mse_per_step"][t] for r in rows) for t in range(steps)]
        m0 = rows[0]["metrics"]
        out[system] = {
            "seeds": [r["seed"] for r in rows],
            "parameters": params,
            "input_frames": m0["input_frames"], "pred_frames": m0["pred_frames"],
            "extrapolate_frames": m0["extrapolate_frames"],
            "ssim_per_step": ssim, "mse_per_step": mse,
            "ssim_prediction": statistics.fmean(ssim[: m0["pred_frames"]]),
            "ssim_extrapolation": statistics.fmean(ssim[m0["pred_frames"]:]) if steps > m0["pred_frames"] else None,
            "ssim_min_extrapolation": min(ssim[m0["pred_frames"]:]) if steps > m0["pred_frames"] else None,
            "train_minutes": [r["metrics"]["training"]["seconds"] / 60 for r in rows],
            "load_average_at_end": [r.get("load_average_at_end") for r in rows],
        }
    return out


def markdown(record: dict[str, Any], out: Path) -> str:
    """Table 1 (learned vs true vs the paper), then prediction quality and minutes."""
    s = record["summary"]
    lines = ["# The paper's scenes from pixels (Table 1)", "",
             f"Reproduce (resumable): `python benchmarks/systems.py --out {out}`. Last invocation: "
             f"`{record['command']}`.", "", f"Machine: {record['machine']}", "",
             "Each system: one data set (`piga-collect --system SYSTEM --seed 100`, 800/100/100 sequences), "
             "trained with the `fast` preset for each seed; parameters start at 1, far from the truth. gravity-m is the "
             "paper's m run on the gravity data: g held at 60 (`piga-train-model --fixed-g 60`), the shared mass m "
             "learned from 1/60, so that the force g·m starts at 1 as in the g run.", "",
             "| system | parameter | true | learned (per seed) | max error | within 5% | paper's learned (error) |",
             "|---|---|---|---|---|---|---|"]
    for system, row in s.items():
        for name, p in row["parameters"].items():
            paper = p["paper_learned"]
            paper_text = f"{paper:g} ({100 * abs(paper - p['true']) / p['true']:.1f}%)" if paper else "-"
            lines.append(f"| {system} | {name} | {p['true']:g} | {', '.join(f'{v:.3f}' for v in p['learned'])} | "
                         f"{100 * p['max_relative_error']:.2f}% | {p['within_5pct']}/{len(p['learned'])} | {paper_text} |")
        if not row["parameters"]:
            lines.append(f"| {system} | (none) | | | | | |")
    lines += ["", "| system | L, T_pred, T_ext | SSIM prediction | SSIM extrapolation (mean, min) | train minutes (per seed) |",
              "|---|---|---|---|---|"]
    for system, row in s.items():
        ext = (f"{row['ssim_extrapolation']:.3f}, {row['ssim_min_extrapolation']:.3f}"
               if row["ssim_extrapolation"] is not None else "-")
        lines.append(f"| {system} | {row['input_frames']}, {row['pred_frames']}, {row['extrapolate_frames']} | "
                     f"{row['ssim_prediction']:.3f} | {ext} | {', '.join(f'{m:.1f}' for m in row['train_minutes'])} |")
    lines += ["", "Training minutes are wall-clock with one torch thread. The machine (2 cores) may be shared: "
              "the 1, 5, 15-minute load averages at the end of each run are in the JSON "
              "(`load_average_at_end`; absent for runs made before it was recorded).", "",
              f"![SSIM per step]({out.name}-ssim.png)", ""]
    lines += [f"![{system}]({out.name}-rollout-{system}.png)" for system in s]
    return "\n".join(lines) + "\n"


def ssim_figure(s: dict[str, Any]) -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.2))
    for system, row in s.items():
        steps = range(1, len(row["ssim_per_step"]) + 1)
        (line,) = ax.plot(steps, row["ssim_per_step"], marker=".", label=system)
        ax.axvline(row["pred_frames"] + 0.5, color=line.get_color(), ls=":", lw=1)
    ax.set_xlabel("step after the input frames (dotted: end of T_pred)")
    ax.set_ylabel("SSIM (test split, mean over seeds)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def heldout_markdown(record: dict[str, Any]) -> str:
    """The held-out table: learned against true on data the preset was not chosen on (one seed each)."""
    lines = ["## Held out", "",
             "The same `fast` preset, unchanged, on data collected at other parameter values and, for the spring, "
             "with another look (ball radius, colours and background unlike the training data's). "
             "One training seed each (seed 0).", "",
             "| data | collected with | parameter | true | learned | error | SSIM prediction, extrapolation |",
             "|---|---|---|---|---|---|---|"]
    for name, run in record["heldout"].items():
        m = run["metrics"]
        ssim = m["frame_ssim_mean"]
        ext = f"{ssim['extrapolation']:.3f}" if ssim["extrapolation"] is not None else "-"
        for param, e in m["parameter_errors"].items():
            lines.append(f"| {name} | `{run['collected_with']}` | {param} | {e['true']:g} | {e['learned']:.3f} | "
                         f"{100 * e['relative_error']:.2f}% | {ssim['prediction']:.3f}, {ext} |")
    return "\n".join(lines) + "\n"


def _look(overrides: dict[str, Any]) -> str:
    """A held-out collection's overrides as piga-collect options."""
    parts = [f"--{k} {v:g}" for k, v in overrides.get("params", {}).items()]
    if "radius" in overrides:
        parts.append(f"--radius {overrides['radius']:g}")
    if "colors" in overrides:
        parts.append("--colors " + " ".join(f"'{c}'" for c in overrides["colors"]))
    if "background" in overrides:
        parts.append(f"--background '{overrides['background']}'")
    return " ".join(parts)


class RunJob(NamedTuple):
    """One training run of the benchmark (the arguments of :func:`_run`)."""

    case: str
    seed: int
    data: Path
    folder: Path
    overrides: dict[str, Any] | None = None
    name: str | None = None


def run_job(job: RunJob) -> dict[str, Any]:
    """A job of the runner: :func:`_run` of ``job``."""
    return _run(*job)


def _errors_line(run: dict[str, Any], true: bool = False) -> str:
    """A run's learned values and errors, e.g. "k=4.0123 (0.31%)" (with ``true``: "k=5.0123 (true 5, 0.25%)")."""
    errors = run["metrics"]["parameter_errors"]
    return ", ".join(f"{n}={e['learned']:.4f} (" + (f"true {e['true']:g}, " if true else "")
                     + f"{100 * e['relative_error']:.2f}%)" for n, e in errors.items())


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.json, OUT.md, OUT-*.png")
    p.add_argument("--systems", nargs="+", choices=SYSTEMS, default=SYSTEMS,
                   help="cases: the systems, and gravity-m (the gravity data, g held at 60, m learned)")
    p.add_argument("--seeds", nargs="+", type=seed_int, default=[0, 1, 2])
    p.add_argument("--work", type=work_folder, default=Path("runs/systems"), help="data and run folders (default %(default)s)")
    p.add_argument("--heldout", action="store_true",
                   help="also train once (seed 0) on each held-out data set of HELDOUT and add its table")
    p.add_argument("--jobs", type=positive_int, default=1, help="runs trained at once, each in its own process with one torch "
                   "thread (default 1: one at a time, so that the training minutes are one core's)")
    add_ray_option(p, "the training runs (--work shared by every machine)")
    args = p.parse_args(argv)
    if args.jobs < 1:
        p.error(f"--jobs must be >= 1, got {args.jobs}")
    backend = ray_backend(p, args)
    from piga.evaluation.plots import save_figure

    args.work.mkdir(parents=True, exist_ok=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    record: dict[str, Any] = {"command": " ".join(["python", "benchmarks/systems.py", *(argv or sys.argv[1:])]),
                              "machine": machine(), "runs": []}
    cases = [c for c in SYSTEMS if c in args.systems]
    jobs = [RunJob(system, seed, _data(system, args.work), args.work, CASES[system][1])
            for system in cases for seed in args.seeds]
    heldout = list(HELDOUT.items()) if args.heldout else []
    jobs += [RunJob(scene, 0, _collect(name, scene, overrides, args.work), args.work, name=name)
             for name, (scene, overrides) in heldout]
    if args.heldout:
        record["heldout"] = {}
    runs: dict[int, dict[str, Any]] = {}  # by job
    heldout_runs: dict[str, dict[str, Any]] = {}

    def finished(i: int, run: dict[str, Any]) -> None:  # saved as each run ends, so that a stopped benchmark continues
        job = jobs[i]
        if job.name is None:
            runs[i] = run
            record["runs"] = [runs[j] for j in sorted(runs)]
            record["summary"] = summary(record["runs"], cases)
            print(f"{job.case} seed {job.seed}: {_errors_line(run)}", flush=True)
        else:
            run["collected_with"] = f"piga-collect --system {job.case} {_look(HELDOUT[job.name][1])}"
            heldout_runs[job.name] = run
            record["heldout"] = {name: heldout_runs[name] for name, _ in heldout if name in heldout_runs}
            print(f"held out {job.name}: {_errors_line(run, true=True)}", flush=True)
        write_json(args.out.with_suffix(".json"), record)

    run_pool(run_job, jobs, workers=args.jobs, progress=False, on_result=finished, backend=backend,
             names=[f"{job.name or job.case} seed {job.seed}" for job in jobs])
    for system in cases:
        first = next(r for r in record["runs"] if r["system"] == system)
        shutil.copyfile(Path(first["run"]) / "rollout.png", args.out.parent / f"{args.out.name}-rollout-{system}.png")
    save_figure(ssim_figure(record["summary"]), args.out.parent / f"{args.out.name}-ssim.png")
    from piga.io.atomic import atomic_output

    text = markdown(record, args.out) + ("\n" + heldout_markdown(record) if args.heldout else "")
    with atomic_output(args.out.with_suffix(".md"), overwrite=True) as tmp:
        Path(tmp).write_text(text)
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
