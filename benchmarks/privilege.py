"""Benchmark: piga without its privileges, one at a time (an ablation of what the baselines comparison gives it).

In the baselines comparison (benchmarks/baselines.py) piga is given what the baselines learn from data or never get:
Gymnasium's exact cost as its planning objective, the camera geometry (the centroid readout with the angle offset
frozen at 0, the fast recipe's) and, at gravity x1.4, the multiplier itself. Each row takes one away:

| row | planning objective | readout and angle offset | told gravity x1.4 |
|---|---|---|---|
| ``default`` | Gymnasium's cost | centroid, offset frozen | yes |
| ``learned-reward`` | a reward head learned from the file's ``/rewards`` (:mod:`agents.reward_head`) | centroid, offset frozen | yes |
| ``paper-readout`` | Gymnasium's cost | the paper's location network (``readout="regress"``), offset learned | yes |
| ``not-told`` | Gymnasium's cost | centroid, offset frozen | no: plans with its learned g (``piga-control --not-told``) |

The data and evaluation are the baselines table's: its smallest piga point (``--sequences``, 25 random-action
sequences of 40 frames, data seed 100, nested subsets of one collection: :func:`baselines.data_file`), the budget
preset's training (``piga-train-model``'s recipe, at least 3000 steps: :func:`baselines.train_piga`), and its
episodes (:func:`baselines.episode_config_for`: 200 steps, the same starts and seeds, success = upright held over the
last 20 steps). Every row is scored over ``--episodes`` episodes at x1.0 and x1.4 (``not-told`` at x1.4 only: at
x1.0 there is nothing to tell, so it is ``default``).

    python benchmarks/privilege.py --out results/privilege               # seed 0 (about 30 min on one core)
    python benchmarks/privilege.py --out results/privilege --seeds 0 1 2

Each trained model is one job of piga's job runner (:func:`piga.io.pool.run_recorded`, one torch thread): ``piga``
(the fast recipe's model: rows ``default``, ``learned-reward`` and ``not-told``) and ``paper-readout``, per seed.
Its record, ``OUT_runs/records/NAME.json`` (settings, each row's scores, training seconds, learned parameters, the
reward head's errors, machine and commit), is kept while its settings are unchanged, so the same command continues a
stopped benchmark; checkpoints and data are not needed once the records exist. Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, get_args

from baselines import PRESETS, data_file, evaluate, piga_epochs, train_piga
from common import farm_main, machine, machine_words, out_prefix, signed, write_page

from agents.reward_head import RewardHeadConfig
from piga.cli.common import ArgumentParser, positive_int, seed_int
from piga.io.pool import JobRecords, RecordedJob, run_recorded

Row = Literal["default", "learned-reward", "paper-readout", "not-told"]
ROWS: tuple[str, ...] = get_args(Row)

#: What each row is given, in words (the page's column).
GIVEN: dict[str, str] = {
    "default": "Gymnasium's exact cost; the camera geometry (centroid readout, angle offset frozen at 0); told x1.4",
    "learned-reward": "a reward head regressing the file's /rewards on its own encoded (θ, θ̇) and the action, "
                      "planned against instead of Gymnasium's cost; centroid readout, offset frozen; told x1.4",
    "paper-readout": "Gymnasium's exact cost; the paper's location network (regress readout) with a learned angle "
                     "offset, no camera geometry; told x1.4",
    "not-told": "Gymnasium's exact cost; centroid readout, offset frozen; NOT told x1.4: plans with its learned g",
}

#: The model a job trains: "piga" (the fast recipe: rows default, learned-reward, not-told) or "paper-readout".
Model = Literal["piga", "paper-readout"]


@dataclass(frozen=True)
class BenchConfig:
    """The ablation's settings; a job's record is kept while its part of them is unchanged."""

    sequences: int = 25
    """Training sequences (a point of the baselines table's piga rows)."""
    seeds: tuple[int, ...] = (0,)
    """Training seeds (each model, each seed: one job)."""
    episodes: int = 20
    """Episodes per evaluation (each row at x1.0 and x1.4)."""
    gravity: float = 1.4
    """The changed gravity multiplier."""
    reward_head: RewardHeadConfig = field(default_factory=RewardHeadConfig)
    """The learned-reward row's head and its training."""
    baselines_preset: str = "budget"
    """The baselines preset whose data, training and episodes are used (``tiny`` checks the pipeline only)."""

    @property
    def baselines(self) -> Any:
        """The baselines benchmark's config: its preset at this data size and these episodes, one process."""
        return replace(PRESETS[self.baselines_preset], sizes=(self.sequences,), seeds=self.seeds, episodes=self.episodes,
                       workers=1)


DEFAULTS = BenchConfig()


@dataclass(frozen=True)
class Job:
    """One trained model of one seed, and the rows it is scored as."""

    name: str
    model: str
    seed: int
    cfg: BenchConfig
    folder: Path


def job_name(model: str, n: int, seed: int) -> str:
    """The baselines' run name for the fast recipe (``piga-n25-s0``), so the model is the same run's."""
    return f"{model}-n{n}-s{seed}"


def model_config(model: str) -> Any:
    """The model a job trains: None (the fast recipe's) or the paper's readout with a learned offset."""
    if model == "piga":
        return None
    from piga.world.model import ModelConfig
    from piga.world.physics import PendulumOptions

    return ModelConfig(readout="regress", system_options=PendulumOptions(learn_offset=True))


def rows_of(model: str) -> tuple[str, ...]:
    return ("paper-readout",) if model == "paper-readout" else ("default", "learned-reward", "not-told")


def job_spec(job: Job) -> dict[str, Any]:
    """What a job's record was measured with (JSON types)."""
    cfg, base = job.cfg, job.cfg.baselines
    spec: dict[str, Any] = {"model": job.model, "seed": job.seed, "sequences": cfg.sequences, "episodes": cfg.episodes,
                            "episode_steps": base.episode_steps, "gravity": cfg.gravity, "data_seed": base.data_seed,
                            "frames": base.steps, "epochs": piga_epochs(base, cfg.sequences), "preset": cfg.baselines_preset}
    if job.model == "piga":
        spec["reward_head"] = asdict(cfg.reward_head)
    return spec


def jobs_for(cfg: BenchConfig, folder: Path) -> list[RecordedJob]:
    out = []
    for seed in cfg.seeds:
        for model in get_args(Model):
            name = job_name(model, cfg.sequences, seed)
            job = Job(name, model, seed, cfg, folder)
            out.append(RecordedJob(name, job_spec(job), job))
    return out


def run_job(job: Job) -> dict[str, Any]:
    """Trains the job's model (continuing a stopped run), then scores each of its rows at x1.0 and x1.gravity."""
    import torch

    torch.set_num_threads(1)
    cfg, base = job.cfg, job.cfg.baselines
    run = job.folder / job.name
    data = data_file(base, job.folder, cfg.sequences)
    record: dict[str, Any] = {"machine": machine(),
                              "train_seconds": train_piga(data, run, job.seed, base, cfg.sequences, model_config(job.model))}
    from piga.io.runs import load_model

    model, ckpt = load_model(run)
    record["physical_parameters"] = model.physical_parameters()
    record["model_config"] = {k: ckpt["model_config"].get(k) for k in ("readout", "system_options")}
    rows: dict[str, dict[str, Any]] = {}
    if job.model == "piga":
        head = learned_reward_head(model, data, run, cfg.reward_head)
        record["reward_head"] = head["metrics"]
        rows["default"] = {f"{m:g}": evaluate("piga", run, base, m) for m in (1.0, cfg.gravity)}
        rows["learned-reward"] = {f"{m:g}": evaluate("piga", run, base, m, reward_head=head["path"])
                                  for m in (1.0, cfg.gravity)}
        rows["not-told"] = {f"{cfg.gravity:g}": evaluate("piga", run, base, cfg.gravity, told=False)}
    else:
        rows["paper-readout"] = {f"{m:g}": evaluate("piga", run, base, m) for m in (1.0, cfg.gravity)}
    record["rows"] = rows
    print(f"done {job.name}: " + ", ".join(f"{row} x{m} {100 * s['success_rate']:.0f}%" for row, cells in rows.items()
                                           for m, s in cells.items()), flush=True)
    return record


def learned_reward_head(model: Any, data: Path, run: Path, config: RewardHeadConfig) -> dict[str, Any]:
    """Trains the learned-reward row's head on the model's own encoded states (frames, actions, rewards only) and
    saves it in the run folder; its path and metrics."""
    from agents.reward_head import save_reward_head, train_reward_head

    head, metrics = train_reward_head(model, data, config)
    path = run / "reward_head.pt"
    save_reward_head(path, head, metrics)
    return {"path": str(path), "metrics": metrics}


def _pct(values: list[float]) -> str:
    return ", ".join(f"{100 * v:.0f}%" for v in values)


def summary(records: dict[str, dict[str, Any]], cfg: BenchConfig) -> list[dict[str, Any]]:
    """A row per ablation: per-seed success and mean return (mean over seeds) at x1.0 and x1.gravity."""
    out = []
    for row in ROWS:
        model = "paper-readout" if row == "paper-readout" else "piga"
        runs = [records[job_name(model, cfg.sequences, seed)] for seed in cfg.seeds]
        entry: dict[str, Any] = {"row": row, "given": GIVEN[row], "seeds": list(cfg.seeds),
                                 "train_seconds": [r["train_seconds"] for r in runs]}
        for m in (1.0, cfg.gravity):
            key = f"{m:g}"
            source = "default" if row == "not-told" and m == 1.0 else row  # x1.0: nothing to tell
            cells = [r["rows"][source][key] for r in runs]
            entry[key] = {"success_per_seed": [c["success_rate"] for c in cells],
                          "mean_return": statistics.fmean(c["mean_return"] for c in cells),
                          "same_as": "default" if source != row else None}
        out.append(entry)
    return out


def markdown(record: dict[str, Any]) -> str:
    cfg, b = record["config"], record["baselines"]
    g = f"{cfg['gravity']:g}"
    lines = ["# piga without its privileges", "",
             f"Reproduce (resumable: kept job records are reused): `{record['command']}`.", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Data and evaluation are the baselines table's (results/baselines.md, `benchmarks/baselines.py --preset "
             f"{cfg['baselines_preset']}`) at one of its piga points: {cfg['sequences']} random-action sequences of "
             f"{b['steps']} frames (data seed {b['data_seed']}), piga's fast recipe for at least {b['piga_min_steps']} "
             f"steps, and {cfg['episodes']} episodes of {b['episode_steps']} steps per cell with the same starts, seeds "
             f"and success rule (the goal held over the last {min(20, b['episode_steps'])} steps). "
             f"Seeds {', '.join(map(str, cfg['seeds']))}; success per seed, mean return averaged over seeds.", "",
             f"| row | what it is given | success x1.0 | mean return x1.0 | success x{g} | mean return x{g} | training min |",
             "|---|---|---|---|---|---|---|"]
    for e in record["summary"]:
        cells = []
        for key in ("1", g):
            c = e[key]
            note = f" (= {c['same_as']})" if c["same_as"] else ""
            cells += [_pct(c["success_per_seed"]) + note, signed(c["mean_return"])]
        minutes = ", ".join(f"{s / 60:.0f}" for s in e["train_seconds"])
        lines.append(f"| {e['row']} | {e['given']} | {' | '.join(cells)} | {minutes} |")
    heads = [(name, r["reward_head"]) for name, r in record["runs"].items() if "reward_head" in r]
    params = [(name, r["physical_parameters"]) for name, r in record["runs"].items()]
    lines += ["", "`learned-reward` and `not-told` use the `default` row's trained model (so do their training "
              "minutes); `paper-readout` is a model of its own, trained with `ModelConfig(readout=\"regress\", "
              "system_options=PendulumOptions(learn_offset=True))` and the same schedule.", "",
              "Learned parameters (true g = 10 and a = 1; the offset is 0 for the centroid readout, whose angle is "
              "anchored by the image, while the regress readout's angle convention is its own, so its offset has no "
              "single true value): "
              + "; ".join(f"{name}: " + ", ".join(f"{k} {v:.3g}" for k, v in p.items()) for name, p in params) + ".", ""]
    if heads:
        lines += ["Reward head (agents/reward_head.py, trained in seconds on the `default` model's encoded states): "
                  "mean absolute error of the reward on the validation split's transitions, against a constant guess "
                  "of the train split's mean: "
                  + "; ".join(f"{name}: {m['valid_abs_error']:.3f} (constant {m['valid_abs_error_mean_guess']:.3f})"
                              for name, m in heads if m.get("valid_abs_error") is not None) + ".", ""]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/privilege"),
                   help="output prefix: OUT.json, OUT.md; runs and records in OUT_runs/ (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=DEFAULTS.sequences,
                   help="training sequences (default %(default)s)")
    p.add_argument("--seeds", nargs="+", type=seed_int, default=list(DEFAULTS.seeds), help="training seeds (default %(default)s)")
    p.add_argument("--episodes", type=positive_int, default=DEFAULTS.episodes,
                   help="episodes per row and gravity (default %(default)s)")
    p.add_argument("--preset", choices=sorted(PRESETS), default=DEFAULTS.baselines_preset,
                   help="the baselines preset whose training and episodes are used; tiny checks the pipeline only "
                        "(default %(default)s)")
    return p


@farm_main
def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    cfg = BenchConfig(sequences=args.sequences, seeds=tuple(dict.fromkeys(args.seeds)), episodes=args.episodes,
                      baselines_preset=args.preset)
    folder = args.out.parent / f"{args.out.name}_runs"
    folder.mkdir(parents=True, exist_ok=True)
    done = run_recorded(run_job, jobs_for(cfg, folder), JobRecords(folder / "records"), 1, progress=False)
    record = {"command": " ".join(["python", "benchmarks/privilege.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": next(iter(done.values()))["machine"], "config": asdict(cfg),
              "baselines": {k: v for k, v in asdict(cfg.baselines).items() if k not in ("sizes", "planet_sizes", "seeds")},
              "runs": done,
              "summary": summary(done, cfg)}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
