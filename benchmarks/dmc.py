"""Benchmark: dm_control's pendulum-swingup, identified and swung up from pixels, against published pixel-RL scores.

For each seed (and each variant of the pendulum given with ``--variant``), as a user would, with
the commands themselves:

1. ``piga-collect --env piga/DMCPendulum-v0``: ``--sequences`` x ``--steps`` random-action frames
   (u ~ U(-1, 1), no reward is read), 64x64 gray from the face-on camera, dt 0.04 s;
2. ``piga-train-model --preset continuous`` (RK4 within the frame, velocities through it, a
   learnable damping; g, a, b start at 1, 0.3, 0.01); the learned g, a, b against the truth in
   piga's form;
3. ``piga-control --env piga/DMCPendulum-v0 --model RUN --oracle``: 10 DMC episodes (1000 physics
   steps of 0.02 s, DMC's reward summed, max 1000) for the piga agent and for the oracle (true
   state, true physics, the same planner).

    python benchmarks/dmc.py --work runs/dmc --out results/dmc
    python benchmarks/dmc.py --work runs/dmc --out results/dmc --seeds 0 1 2 --variant mass=1.5 --variant damping=0.3

Finished steps are kept in ``--work`` and skipped when the benchmark is run again, so an
interrupted run continues. ``OUT.json`` holds every number, ``OUT.md`` the tables, with the
published scores next to piga's point.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from common import machine
from piga.atomic import atomic_output, write_json

#: Published pixel-based scores on DMC pendulum-swingup, read from the score files that DreamerV3's
#: authors publish for it and its baselines (github.com/danijar/dreamerv3, ``scores/dmc_vision-{dreamerv3,
#: drqv2,curl,sac}.json.gz``, commit e3f0224): per seed, the curve ``ys`` linearly interpolated at
#: ``xs`` = x (the last point where a curve ends short of 1M: 993,984 for DreamerV3, 980,000 for
#: DrQ-v2), then mean ± std over seeds. ``xs`` counts environment steps of 0.02 s (DMC's control
#: step); DreamerV3's series holds every episode (noisy: its nearest point to 100k gives 296 ± 350).
SCORE_FILES = "github.com/danijar/dreamerv3 scores/dmc_vision-*.json.gz (commit e3f0224)"
PUBLISHED: list[dict[str, object]] = [
    {"method": "DreamerV3", "steps": 100_000, "score": 336, "std": 324, "seeds": 10,
     "source": "Hafner et al., Mastering Diverse Domains through World Models (2023)"},
    {"method": "DrQ-v2", "steps": 100_000, "score": 235, "std": 212, "seeds": 9,
     "source": "Yarats et al., Mastering Visual Continuous Control (2021)"},
    {"method": "CURL", "steps": 100_000, "score": 38, "std": 64, "seeds": 10,
     "source": "Laskin et al., CURL (ICML 2020)"},
    {"method": "pixel SAC", "steps": 100_000, "score": 99, "std": 148, "seeds": 9,
     "source": "SAC from pixels, as in Laskin et al. (2020)"},
    {"method": "DreamerV3", "steps": 1_000_000, "score": 733, "std": 269, "seeds": 10,
     "source": "Hafner et al. (2023)"},
    {"method": "DrQ-v2", "steps": 1_000_000, "score": 838, "std": 36, "seeds": 9,
     "source": "Yarats et al. (2021)"},
]


def sh(*args: str, log: Path) -> None:
    """Runs a piga command as a user would; its output goes to ``log``; a failure stops the benchmark."""
    with log.open("a") as f:
        f.write("$ " + " ".join(args) + "\n")
        f.flush()
        code = subprocess.run(list(args), stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
    if code:
        sys.exit(f"dmc benchmark: '{' '.join(args[:2])} ...' failed (exit {code}); see {log}")


def run_case(work: Path, seed: int, variant: list[str], args: argparse.Namespace) -> dict[str, object]:
    """Collect, train and control for one seed and variant; returns its numbers."""
    name = f"seed{seed}" + "".join(f"-{v.replace('=', '')}" for v in variant)
    folder = work / name
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "log.txt"
    options = [x for v in variant for x in ("--env-option", v)]
    data, run = folder / "data.h5", folder / "run"
    if not data.exists():
        sh("piga-collect", "--env", "piga/DMCPendulum-v0", *options, "--out", str(data), "--sequences",
           str(args.sequences), "--steps", str(args.steps), "--seed", str(1000 + seed), "--workers", "1", "--quiet", log=log)
    if not (run / "metrics.json").exists():
        resume = ["--resume"] if (run / "checkpoint.pt").exists() else []
        sh("piga-train-model", str(data), "--out", str(run), "--preset", "continuous", "--epochs", str(args.epochs),
           "--seed", str(seed), "--threads", "1", "--quiet", *resume, log=log)
    control = folder / "control"
    if not control.with_name("control.json").exists():
        sh("piga-control", "--env", "piga/DMCPendulum-v0", *options, "--model", str(run), "--oracle", "--episodes",
           str(args.episodes), "--seed", str(args.control_seed), "--quiet", "--out", str(control), log=log)
    metrics = json.loads((run / "metrics.json").read_text())
    control_json = json.loads(control.with_name("control.json").read_text())
    return {"case": name, "seed": seed, "variant": variant, "frames": args.sequences * args.steps,
            "parameters": metrics["parameter_errors"], "encoder_angle_error_deg": metrics.get("angle", {}).get("mean_abs_error_deg"),
            "control": {r["agent"]: r for r in control_json["results"]}}


def markdown(cases: list[dict[str, object]], command: str, info: dict[str, object]) -> str:
    lines = [f"Command: `{command}`", "", f"Machine: {info['cpu']} ({info['cores']} cores), torch {info['torch']}.", "",
             "## Identification (piga-train-model --preset continuous, no labels)", "",
             "Truth in piga's form θ̈ = 1.5·g·sin θ + 3·a·u − 3·b·θ̇: g = m·g·l / (1.5·I), a = gear / (3·I), "
             "b = d / (3·I).", "",
             "| case | frames | g learned (true, error) | a learned (true, error) | b learned (true, error) |",
             "|---|---|---|---|---|"]
    for c in cases:
        cells = []
        for key in ("g", "a", "b"):
            p = c["parameters"].get(key)
            cells.append("–" if p is None else f"{p['learned']:.4g} ({p['true']:.4g}, {100 * p['relative_error']:.2f}%)")
        lines.append(f"| {c['case']} | {c['frames']} | " + " | ".join(cells) + " |")
    lines += ["", "## Swing-up from pixels, in DMC's score (10 episodes of 1000 physics steps, max 1000)", "",
              "| case | piga mean ± std | oracle mean ± std | piga / oracle |", "|---|---|---|---|"]
    for c in cases:
        piga, oracle = c["control"].get("piga"), c["control"].get("oracle")
        ratio = f"{100 * piga['mean'] / oracle['mean']:.1f}%" if piga and oracle and oracle["mean"] > 0 else "–"
        fmt = lambda r: "–" if r is None else f"{r['mean']:.1f} ± {r['std']:.1f}"  # noqa: E731
        lines.append(f"| {c['case']} | {fmt(piga)} | {fmt(oracle)} | {ratio} |")
    lines += ["", "## Against published pixel-based scores (pendulum-swingup)", "",
              f"Published curves read from {SCORE_FILES}; x is in environment steps of 0.02 s, the files' unit. "
              "piga learns its model from random-action frames only (no reward) at an action repeat of 2: its x "
              "counts the physics steps those frames span (2 per frame).", "",
              "| method | environment steps | score (mean ± std) | seeds | source |", "|---|---|---|---|---|"]
    rows = [(str(p["method"]), int(p["steps"]), f"{p['score']} ± {p['std']}", str(p["seeds"]), str(p["source"]))
            for p in PUBLISHED]
    for c in cases:
        piga = c["control"].get("piga")
        if piga and not c["variant"]:
            rows.append((f"piga ({c['case']}, {c['frames']:,} frames)", 2 * int(c["frames"]),
                         f"{piga['mean']:.0f} ± {piga['std']:.0f}", "1 model, 10 episodes", "this table"))
    for method, steps, score, seeds, source in sorted(rows, key=lambda r: (r[1], r[0])):
        lines.append(f"| {method} | {steps:,} | {score} | {seeds} | {source} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", required=True, help="folder for data and runs (kept, reused on a rerun)")
    p.add_argument("--out", required=True, help="OUT.json and OUT.md are written")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--variant", action="append", default=[], metavar="KEY=VALUE",
                   help="also run the pendulum with this --env-option (repeatable; each one is its own case)")
    p.add_argument("--sequences", type=int, default=500)
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--epochs", type=int, default=16)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--control-seed", type=int, default=0)
    args = p.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    work = Path(args.work)
    cases = []
    for seed in args.seeds:
        for variant in [[], *([v] for v in args.variant)]:
            cases.append(run_case(work, seed, variant, args))
    command = "python benchmarks/dmc.py " + " ".join(sys.argv[1:])
    info = machine()
    out = Path(args.out)
    write_json(out.with_suffix(".json"), {"command": command, "machine": info, "cases": cases, "published": PUBLISHED})
    with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
        tmp.write_text(markdown(cases, command, info))
    print(f"wrote {out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
