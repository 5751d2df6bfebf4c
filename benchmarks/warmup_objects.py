"""Benchmark: when a scene run loses its objects: the object check at the end of the autoencoder warm-up.

On the half spring data of ``benchmarks/regions.py`` (the balls stay in the top half of the image) some training seeds
end with each object's template drawing its ball twice, side by side, and the object check fails (exit 1). This
trains each scene's ``fast`` recipe (the same as ``piga-train-model DATA --seed SEED``) on that file and on each scene's
own collection of the same size and seed, stops each run at its first checkpoint after the autoencoder warm-up (before
the physics has trained for long), and measures there the object check of :mod:`piga.evaluation.objects` on the test
split: the residual peak over the content peak (above 0.5 an object counts as lost at the end of a run). It also
draws each half-data seed's templates at that point.

    python benchmarks/warmup_objects.py --out results/regions_warmup --seeds 0 1 2 3

Writes OUT.json, OUT.md and OUT-templates-sSEED.png (half data); data files and runs go in OUT_runs/.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from common import farm_main, logged_command, machine, machine_words, out_prefix, write_page
from piga.cli.common import ArgumentParser, seed_int

SEQUENCES, DATA_SEED = 100, 100
"""The collection of ``benchmarks/regions.py`` (its defaults), for every data set."""
DATA_SETS = {"spring-half": ["--system", "spring", "--half"], "spring": ["--system", "spring"],
             "bouncing": ["--system", "bouncing"], "gravity": ["--system", "gravity"],
             "digits-spring": ["--system", "digits-spring"]}
"""``piga-collect``'s options of each data set: the half spring data, and each scene's default collection."""
HALF = "spring-half"


class _WarmupDone(Exception):
    """Raised from the training's checkpoint hook once the warm-up is over: the run stops there."""


def collect_command(name: str, path: Path) -> list[str]:
    return ["piga-collect", *DATA_SETS[name], "--sequences", str(SEQUENCES), "--seed", str(DATA_SEED), "--out",
            str(path), "--quiet"]


def data_file(name: str, folder: Path) -> Path:
    """The data set ``name``, collected once with ``piga-collect``."""
    path = folder / f"{name}.h5"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        code = logged_command(collect_command(name, path), path.with_suffix(".log"))
        if code:
            raise RuntimeError(f"piga-collect failed (exit {code}); see {path.with_suffix('.log')}")
    return path


def at_warmup_end(data: Path, seed: int, run_dir: Path, templates: Path | None) -> dict[str, Any]:
    """Trains the fast recipe with ``seed`` on ``data`` up to the first checkpoint after the warm-up; the object check
    (and the templates figure, to ``templates``) there."""
    from piga.data.schema import inspect_dataset
    from piga.evaluation.plots import save_figure, templates_figure
    from piga.training.report import scene_objects, template_images
    from piga.training.train import preset_for, train

    recipe = preset_for("fast", inspect_dataset(data))
    seen: dict[str, Any] = {}

    def hook(state: Any, model: Any) -> None:
        plan = state.plan  # TrainPlan's fields
        if state.step >= plan["warmup_steps"]:
            model = model.cpu().eval()  # the run stops here
            seen.update(step=state.step, warmup_steps=plan["warmup_steps"], total_steps=plan["epochs"] * plan["steps_per_epoch"],
                        check=scene_objects(model, data).to_dict())  # what piga-train-model checks there
            if templates is not None:
                save_figure(templates_figure(*template_images(model)), templates)
            raise _WarmupDone

    try:
        train(data, run_dir, replace(recipe.train, seed=seed, threads=1), recipe.model, progress=False, on_epoch=hook)
    except _WarmupDone:
        pass
    if not seen:
        raise RuntimeError(f"the run on {data} ended before its warm-up did")
    return seen


def markdown(record: dict[str, Any]) -> str:
    names = list(record["runs"])
    lines = ["# When a scene run loses its objects: the object check at the end of the warm-up", "",
             f"Command: `{record['command']}`", "",
             f"Machine: {machine_words(record['machine'])}.", "",
             f"Data: `{' '.join(collect_command(HALF, Path(HALF + '.h5')))}` (the half data of [regions](regions.md)), "
             "and each scene's own collection of the same size and seed (`piga-collect --system SCENE ...`). Each run is "
             "the scene's `fast` recipe (`piga-train-model DATA --seed SEED`), stopped at its first checkpoint after the "
             "autoencoder warm-up; the ratio is the object check's residual peak over the content peak on the test split "
             "(a finished run fails the check above 0.5). Steps: the checkpoint's, then the warm-up's and the run's.", "",
             "| seed | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for seed in record["seeds"]:
        cells = [f"{r['check']['ratio']:.3f} ({r['step']}; {r['warmup_steps']} of {r['total_steps']})"
                 for r in (record["runs"][name][str(seed)] for name in names)]
        lines.append(f"| {seed} | {' | '.join(cells)} |")
    lines.append("")
    if HALF in record["runs"]:
        for seed in record["seeds"]:
            lines.append(f"![half data, seed {seed}: templates at the end of the warm-up]"
                         f"({record['out_name']}-templates-s{seed}.png)")
    return "\n".join(lines) + "\n"


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/regions_warmup"), help="output prefix (default %(default)s)")
    p.add_argument("--seeds", type=seed_int, nargs="+", default=[0, 1, 2, 3], help="training seeds (default %(default)s)")
    p.add_argument("--data-sets", nargs="+", choices=list(DATA_SETS), default=list(DATA_SETS),
                   help="default %(default)s")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from piga.io.pool import git_commit

    commit = git_commit()  # the code that runs (read before the runs: commits made meanwhile do not count)
    folder = args.out.parent / f"{args.out.name}_runs"
    seeds = list(dict.fromkeys(args.seeds))
    runs: dict[str, dict[str, Any]] = {name: {} for name in dict.fromkeys(args.data_sets)}
    for name in runs:
        data = data_file(name, folder)
        for seed in seeds:
            templates = args.out.parent / f"{args.out.name}-templates-s{seed}.png" if name == HALF else None
            r = at_warmup_end(data, seed, folder / f"{name}-s{seed}", templates)
            runs[name][str(seed)] = r
            print(f"{name}, seed {seed}: object check ratio {r['check']['ratio']:.3f} at step {r['step']} "
                  f"(warm-up {r['warmup_steps']})", flush=True)
    record = {"command": " ".join(["python", "benchmarks/warmup_objects.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": machine(), "commit": commit, "seeds": seeds, "out_name": args.out.name, "runs": runs}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
