"""Blind check of ``piga-diagnose`` on dm_control's MuJoCo pendulum: variants it was not tuned for.

Cases are drawn with a seeded RNG over the variant (mass, length, hinge damping, action repeat 1-4,
camera distance, a flipped camera or motor) and over an effect added by a wrapper outside
dm_control (Coulomb ``friction``, actuator ``delay``, ``deadzone``, torque ``bias``, ``frame_drop``,
motion ``blur``), or none. For each case the script

1. collects a nominal file of the variant (its camera, no added effect) and trains the nominal
   model on it with the default fast preset, as a user would (``piga-train-model --preset fast``);
   when that run exits 1 saying the actuation faded (a flipped camera or motor), it retrains with
   the ``--signed-actuation`` that the line names, as a user would;
2. collects the case's "real" file of the same variant with the added effect;
3. deletes every label from that file: the ``effects`` attribute, the command line, ``/states``
   (as :func:`diagnose_blind.strip_labels`), and the provenance hints ``env_id``, ``env_config``
   and ``params`` (so that nothing here rests on the diagnosis excluding effects by provenance);
4. runs ``piga-diagnose --model RUN --data CASE.h5 --out REPORT`` in a fresh process;
5. scores the report against the hidden truth, with :mod:`diagnose_blind`'s scorer.

The truth of a case is the added effect plus what the variant itself has and the fast model
lacks: its hinge ``damping`` (if any), ``within_frame`` (an action held over 2+ physics steps),
and ``flip`` (a mirrored camera or reversed motor). Naming any of them is right; naming anything
else is a false effect.

    python benchmarks/diagnose_blind_dmc.py --out results/diagnose_blind_dmc --jobs 2   # 24 cases (hours)
    python benchmarks/diagnose_blind_dmc.py --quick --out /tmp/dmc_quick --work /tmp/w  # 2 tiny cases
    python benchmarks/diagnose_blind_dmc.py --models-only --only 2 3  # step 1 ahead, for cases 2 and 3

Floors (reported in OUT.md): top-1 ≥ 90% (an "ambiguous" verdict counts as right only when the
truth holds one of its two; at most 10% ambiguous), no named effect that the case does not have,
and the corrected g, a, b within 3% of the variant's when the verdict is not ambiguous. MuJoCo
takes the hinge damping implicitly; a report that reads the damping explicitly (one Euler step per
frame, Gymnasium's convention) gives the same frames' values under MuJoCo's (its
``damping_convention``), and those are scored. Cases run ``--jobs`` at a time in local processes, or with
``--ray auto|HOST:PORT`` as tasks of a Ray cluster (the same records, bar the wall times). Each finished case
is appended to OUT.json, so an interrupted run continues where it stopped.
"""

from __future__ import annotations

import functools
import json
import math
import shlex
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import h5py
import numpy as np

from common import (add_diagnose_options, add_ray_option, diagnose_options, farm_main, job_command, machine,
                    out_prefix, ray_backend, work_folder)
from diagnose_blind import run_diagnose, save, strip_labels
from diagnose_blind import score as score_gym
from envs.dmc import DMCPendulumConfig, DMCPendulumEnv
from piga.cli.common import (ArgumentParser, NOT_CONVERGED, PigaError, nonnegative_float, nonnegative_int, positive_int,
                             seed_int)
from piga.data.collect import CollectConfig, collect
from piga.io.pool import run_pool

#: Effects added outside dm_control, and how their magnitudes are drawn (rng -> value). friction
#: and bias are in piga's units (rad/s², torque per m·l²), applied to the hinge as 3·I times that.
ADDED = {
    "friction": lambda r: round(float(r.uniform(0.3, 0.8)), 3),
    "bias": lambda r: round(float(r.choice([-1, 1]) * r.uniform(0.3, 0.8)), 3),
    "delay": lambda r: int(r.integers(1, 4)),
    "deadzone": lambda r: round(float(r.uniform(0.2, 0.4)), 3),
    "frame_drop": lambda r: round(float(r.uniform(0.05, 0.2)), 3),
    "blur": lambda r: round(float(r.uniform(0.8, 2.0)), 3),
}
#: Provenance attrs deleted on top of :func:`diagnose_blind.strip_labels`.
PROVENANCE = ("env_id", "env_config", "params")


def draw_variant(rng: np.random.Generator) -> dict[str, Any]:
    """A dm_control pendulum variant (fields of :class:`envs.dmc.DMCPendulumConfig`)."""
    length = round(float(rng.uniform(0.35, 0.55)), 3)
    return {"mass": round(float(rng.uniform(0.7, 1.5)), 3), "length": length,
            "damping": round(float(rng.uniform(0.05, 0.3)), 3), "action_repeat": int(rng.integers(1, 5)),
            "camera_distance": round(float(rng.uniform(max(1.0, (length + 0.1) / 0.7), 1.3)), 3),
            "flip": str(rng.choice(["none", "none", "none", "camera", "motor"]))}


def draw_cases(n: int, seed: int) -> list[dict[str, Any]]:
    """``n`` cases: about 1/4 with no added effect, the rest one added effect (every one when n >= 8), shuffled.

    Case i collects its nominal file with seed 1000·(seed + 1) + 2i and its real file with 2i + 1.
    """
    rng = np.random.default_rng(seed)
    n_none = max(1, n // 4)
    names = list(ADDED)
    added: list[dict[str, Any]] = [{} for _ in range(n_none)]
    added += [{names[i % len(names)]: ADDED[names[i % len(names)]](rng)} for i in range(n - n_none)]
    order = rng.permutation(n)
    base = 1000 * (seed + 1)
    return [{"case": i, "variant": draw_variant(rng), "effects": added[j], "nominal_seed": base + 2 * i,
             "data_seed": base + 2 * i + 1} for i, j in enumerate(order)]


def inherent(variant: dict[str, Any]) -> set[str]:
    """What the variant has and the fast nominal model lacks, in the diagnosis' names."""
    return ({"damping"} if variant["damping"] > 0 else set()) | ({"within_frame"} if variant["action_repeat"] > 1 else set()) \
        | ({"flip"} if variant["flip"] != "none" else set())


def truth(case: dict[str, Any]) -> dict[str, Any]:
    """The true values in piga's form (g, a, b) and every effect the case has."""
    config = DMCPendulumConfig(**case["variant"])
    p = config.piga_params()
    return {"g": p["g"], "a": p["actuation_gain"] * p["actuation_sign"], "b": p["damping"],
            "effects": sorted(inherent(case["variant"]) | set(case["effects"]))}


class HingeTorque(gym.Wrapper):
    """Friction −c·tanh(θ̇ / 0.1) or a bias τ0 (piga's units) on dm_control's hinge, from outside it.

    Computed from the state before each *physics step* (:attr:`envs.dmc.DMCPendulumEnv.hinge_torque`) and
    applied as MuJoCo's generalized force (``qfrc_applied``, 3·I times piga's value): a friction that acts
    within the frame as a real one does, not one held over the frame's physics steps at the frame's first
    speed; no clip on the action, unlike a torque added to u.
    """

    def __init__(self, env: gym.Env, kind: str, value: float):
        super().__init__(env)
        if kind not in ("friction", "bias"):
            raise ValueError(f"HingeTorque: kind must be 'friction' or 'bias', got {kind!r}")
        if not isinstance(env.unwrapped, DMCPendulumEnv):
            raise TypeError(f"HingeTorque wraps the DMC pendulum, got {env.unwrapped}")
        self.kind, self.value = kind, float(value)
        self.scale = 3.0 * env.unwrapped.config.inertia  # piga's torque per m·l² -> N·m
        self.inner = env.unwrapped.hinge_torque  # another HingeTorque's, which this one adds to
        env.unwrapped.hinge_torque = self.torque

    def torque(self, theta: float, speed: float) -> float:
        """The hinge torque (N·m) at angular speed ``speed`` (rad/s), with the inner wrapper's."""
        own = self.scale * (-self.value * math.tanh(speed / 0.1) if self.kind == "friction" else self.value)
        return own + (self.inner(theta, speed) if self.inner is not None else 0.0)


def make_case_env(effects: dict[str, Any], config: DMCPendulumConfig) -> gym.Env:
    """dm_control's pendulum with ``effects`` added from outside it, gray frames, ``frame_stack`` 1."""
    from gymnasium.wrappers import FrameStackObservation, GrayscaleObservation

    from envs.effects import ActionDeadzone, ActionDelay, FrameBlur, FrameDrop

    env: gym.Env = DMCPendulumEnv(config)
    for kind in ("friction", "bias"):
        if kind in effects:
            env = HingeTorque(env, kind, float(effects[kind]))
    if "deadzone" in effects:
        env = ActionDeadzone(env, float(effects["deadzone"]))
    if "delay" in effects:
        env = ActionDelay(env, int(effects["delay"]))
    env = GrayscaleObservation(env, keep_dim=False)
    if "blur" in effects:
        env = FrameBlur(env, float(effects["blur"]))
    if "frame_drop" in effects:
        env = FrameDrop(env, float(effects["frame_drop"]))
    return FrameStackObservation(env, config.frame_stack)


def strip_provenance(path: Path) -> None:
    """Every label and hint (:func:`diagnose_blind.strip_labels`, then :data:`PROVENANCE`), in place."""
    strip_labels(path)
    with h5py.File(path, "r+") as f:
        for key in PROVENANCE:
            if key in f.attrs:
                del f.attrs[key]


def mujoco_values(case: dict[str, Any], report: dict[str, Any]) -> dict[str, Any]:
    """The report's corrected values under MuJoCo's implicit damping: as they are when the report took the
    damping implicitly (within-frame substeps), else the same frames' implicit values that the report gives
    (``damping_convention``). A report from before that field is converted the same way
    (:func:`piga.diagnostics.diagnose.damping_convention`: x 1 / (1 - h·3b), h the frame's step)."""
    corrected = dict(report["corrected"])
    convention = report.get("damping_convention", "absent")
    if convention == "absent" and corrected.get("b", 0) > 0 and not corrected.get("substeps"):
        h = DMCPendulumConfig(**case["variant"]).dt  # the nominal fast model's one Euler step per frame
        factor = 1 / (1 - h * 3 * corrected["b"])
        convention = {"taken": "explicit", "values": {k: corrected[k] * factor for k in ("g", "a", "b")}}
    if isinstance(convention, dict) and convention["taken"] == "explicit":
        corrected.update(convention["values"])
    return corrected


def score(case: dict[str, Any], report: dict[str, Any]) -> dict[str, Any]:
    """:func:`diagnose_blind.score` against the added effect, plus what this benchmark's floors need."""
    true = truth(case)
    base = score_gym({**case, "effects": case["effects"]}, report)
    named = [e["effect"] for e in report["effects"]]
    ambiguity = report.get("ambiguity")
    if ambiguity:  # right only when the truth holds one of the two
        top1 = any(set(side.split("+")) <= set(true["effects"]) for side in ambiguity["between"])
    elif report["verdict_class"] == "unexplained":
        top1 = False
    elif not named:
        top1 = not true["effects"]
    else:
        top1 = named[0] in true["effects"]
    corrected = mujoco_values(case, report)
    relative = lambda key: None if corrected.get(key) is None else abs(corrected[key] / true[key] - 1)  # noqa: E731
    errors = {"g": relative("g"), "a": relative("a")}
    if "b" in corrected and true["b"] > 0:
        errors["b"] = relative("b")
    found = {e["effect"]: e.get("value") for e in report["effects"]}
    added_error = {}  # the added effect's fitted size against the truth (a mirrored camera or motor flips a bias)
    for name, value in case["effects"].items():
        if name in found and name != "delay" and isinstance(found[name], (int, float)):
            fitted = abs(found[name]) if case["variant"]["flip"] != "none" else found[name]
            added_error[name] = abs(fitted - (abs(value) if case["variant"]["flip"] != "none" else value)) / abs(value)
    gap = report["gap"]
    closure = gap.get("free_run_gap_closure")
    # a closure is reported above a valid floor (the twin's), within [0, 105%], or marked as having none
    closure_valid = closure is None or (bool(gap.get("gap_above_floor")) and -0.05 <= closure <= 1.05)
    return {**base, "truth_effects": true["effects"], "named": named, "top1": bool(top1),
            "ambiguous": bool(ambiguity), "false_effects": sorted(set(named) - set(true["effects"])),
            "parameter_error": errors, "added_error": added_error, "closure": closure, "closure_valid": closure_valid}


def worst_error(score: dict[str, Any]) -> float | None:
    """The largest relative error of the corrected g, a, b (None: none, or one was not finite)."""
    errors = list(score["parameter_error"].values())
    return None if not errors or None in errors else float(max(errors))


def summarize(runs: list[dict[str, Any]]) -> dict[str, Any]:
    s = [r["score"] for r in runs]
    clear = [x for x in s if not x["ambiguous"]]
    worst = [worst_error(x) for x in clear if x["predicted"] != "refused"]
    return {
        "cases": len(s),
        "refused": int(sum(x["predicted"] == "refused" for x in s)),
        "top1_accuracy": float(np.mean([x["top1"] for x in s])) if s else None,
        "ambiguous_rate": float(np.mean([x["ambiguous"] for x in s])) if s else None,
        "false_effects": int(sum(len(x["false_effects"]) for x in s)),
        "parameters_within_3pct": float(np.mean([w is not None and w <= 0.03 for w in worst])) if worst else None,
        "parameter_error_max": None if not worst or None in worst else float(max(worst)),
        "added_error_max": max((e for x in s for e in x.get("added_error", {}).values()), default=None),
        "closures_valid": int(sum(x.get("closure_valid", False) for x in s if x["predicted"] != "refused")),
        "closure_median": float(np.median(c)) if (c := [x["closure"] for x in s if x.get("closure") is not None]) else None,
    }


def markdown(runs: list[dict[str, Any]], summary: dict[str, Any], command: str, info: dict[str, Any]) -> str:
    pct = lambda v: "–" if v is None or not np.isfinite(v) else f"{100 * v:.0f}%"  # noqa: E731
    pct1 = lambda v: "–" if v is None or not np.isfinite(v) else f"{100 * v:.1f}%"  # noqa: E731
    lines = [
        "# Blind check of piga-diagnose on dm_control's pendulum", "", f"Command: `{command}`", "",
        f"{info['sequences']} sequences x {info['steps']} frames per file; nominal model: `piga-train-model --preset fast` "
        f"on a nominal file of each variant{info['train_note']} (with `--signed-actuation` where the first run exits 1 "
        f"asking for it: cases {', '.join(str(r['case']) for r in runs if r.get('signed_actuation')) or 'none'}). Machine: {info['machine']['cpu']}, "
        f"{info['machine']['cores']} cores.", "",
        "g, a and b are compared under MuJoCo's convention, which takes the hinge damping implicitly: where the "
        "report reads the damping explicitly (one Euler step per frame, Gymnasium's way), the same frames' values "
        "under the implicit convention, which the report gives (`damping_convention`), are scored.", "",
        "| measure | value | floor |", "|---|---|---|",
        f"| cases | {summary['cases']} ({summary['refused']} refused by piga-diagnose, counted wrong) | ≥ 24 |",
        f"| top-1 (first named effect is one the case has; ambiguous right only if the truth is one of the two) | "
        f"{pct(summary['top1_accuracy'])} | ≥ 90% |",
        f"| ambiguous verdicts | {pct(summary['ambiguous_rate'])} | ≤ 10% |",
        f"| named effects the case does not have | {summary['false_effects']} | 0 |",
        f"| corrected g, a, b within 3% (verdicts not ambiguous) | {pct(summary['parameters_within_3pct'])} "
        f"(worst {pct1(summary['parameter_error_max'])}) | all |",
        f"| closures above a valid floor or marked as having none | {summary.get('closures_valid', '–')} of "
        f"{summary['cases'] - summary['refused']} (median closure {pct(summary.get('closure_median'))}) | all |",
        f"| the added effect's size, worst error (a flip mirrors a bias: its size is compared) | "
        f"{pct(summary.get('added_error_max'))} | |", "",
        "| case | variant | added (hidden) | truth | verdict | top-1 | worst of g, a, b | gap closure |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        v, sc = r["variant"], r["score"]
        variant = ", ".join(f"{k}={val}" for k, val in v.items())
        added = ", ".join(f"{k}={val}" for k, val in r["effects"].items()) or "none"
        worst = worst_error(sc)
        closure = "none" if sc.get("closure") is None else pct(sc["closure"])
        lines.append(f"| {r['case']} | {variant} | {added} | {'+'.join(sc['truth_effects']) or 'none'} | {sc['verdict']} | "
                     f"{'yes' if sc['top1'] else '**no**'} | {pct1(worst)} | {closure} |")
    return "\n".join(lines) + "\n"


def collect_config(case: dict[str, Any], sequences: int, steps: int) -> CollectConfig:
    """The collection of a case's files: its variant, ``sequences`` x ``steps``, one worker (the seed is the file's)."""
    return replace(CollectConfig(), sequences=sequences, steps=steps, env=DMCPendulumConfig(**case["variant"]), workers=1)


def nominal_model(case: dict[str, Any], work: Path, sequences: int, steps: int, train_args: list[str]) -> tuple[Path, bool]:
    """Collects the case's nominal file and trains its nominal model (step 1); returns the run's folder
    and whether it needed ``--signed-actuation``.

    A model that this step already trained for the same case, file shape and training arguments
    (its ``nominal.json`` stamp) is kept: the training is most of a case's time, and it does not
    depend on the diagnosis being checked.
    """
    nominal = work / f"case{case['case']:02d}_nominal.h5"
    run_dir = work / f"case{case['case']:02d}_model"
    work.mkdir(parents=True, exist_ok=True)  # on a machine of a cluster, the first case there makes it
    stamp = {"variant": case["variant"], "nominal_seed": case["nominal_seed"], "sequences": sequences, "steps": steps,
             "train_args": train_args}
    stamp_path = run_dir / "nominal.json"
    if stamp_path.exists() and (run_dir / "checkpoint.pt").exists():
        kept = json.loads(stamp_path.read_text())
        if {k: kept.get(k) for k in stamp} == stamp:
            return run_dir, bool(kept["signed_actuation"])
    collect(replace(collect_config(case, sequences, steps), seed=case["nominal_seed"]), nominal, overwrite=True,
            command="", progress=False)
    command = ["piga-train-model", str(nominal), "--out", str(run_dir), "--preset", "fast", "--threads", "1",
               "--overwrite", "--quiet", *train_args]
    trained = job_command(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    signed = trained.returncode == 1 and "--signed-actuation" in trained.stderr
    if signed:  # as a user would: the line says the frames show the actuation reversed, and names the flag
        trained = job_command([*command, "--signed-actuation"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    # not converged: a warning, which the report shows; not identified (exit 1, the run kept): the diagnosis refuses the
    # model, and the case is scored refused (the --quick recipe's tiny model, on 40 sequences of 16 frames)
    untrained = trained.returncode == 1 and "did not identify" in trained.stderr and (run_dir / "checkpoint.pt").exists()
    if trained.returncode not in (0, NOT_CONVERGED) and not untrained:
        raise RuntimeError(f"piga-train-model failed on case {case['case']}: {trained.stderr.strip()}")
    stamp_path.write_text(json.dumps({**stamp, "signed_actuation": signed}))
    return run_dir, signed


def run_case(case: dict[str, Any], work: Path, sequences: int, steps: int, train_args: list[str],
             diagnose_options: tuple[str, ...] = ()) -> dict[str, Any]:
    """Collects, trains, strips, diagnoses (``piga-diagnose`` with ``diagnose_options``) and scores one case;
    returns its record."""
    t0 = time.time()
    run_dir, signed = nominal_model(case, work, sequences, steps, train_args)
    real, report_dir = work / f"case{case['case']:02d}.h5", work / f"case{case['case']:02d}"
    collect(replace(collect_config(case, sequences, steps), seed=case["data_seed"]), real, overwrite=True, command="",
            progress=False, make_env=functools.partial(make_case_env, case["effects"]))
    strip_provenance(real)
    report = run_diagnose(run_dir, real, report_dir, case["case"], threads=1, options=diagnose_options)
    return {**case, "seconds": time.time() - t0, "signed_actuation": signed,
            "score": refused(case, report) if isinstance(report, str) else score(case, report)}


def refused(case: dict[str, Any], message: str) -> dict[str, Any]:
    """The score of a case that piga-diagnose refused: wrong, with its one line as the verdict."""
    return {"truth": "+".join(truth(case)["effects"]) or "none", "predicted": "refused", "verdict": f"refused: {message}",
            "truth_effects": truth(case)["effects"], "named": [], "top1": False, "ambiguous": False,
            "false_effects": [], "parameter_error": {}}


def true_angle_fit(case: dict[str, Any], work: Path, sequences: int, steps: int, noise: float = 0.0,
                   fit_starts: bool = False) -> dict[str, Any]:
    """Outside the blind protocol: the diagnosis' candidate physics fitted to the case's *true* angles.

    The case's file is collected again with its labels kept (``WORK/caseNN_true.h5``), and
    :func:`piga.diagnostics.analyse` runs on ``/states`` instead of the encoder's angles, against the
    nominal model's g and a. What it gets wrong is the candidates' physics, not the vision. ``noise``
    (rad) adds independent Gaussian errors to every angle (seed 0): what a reading error alone does;
    ``fit_starts``: the fits take the windows' start angles as data (``DiagnoseConfig.fit_starts``).
    """
    from piga.diagnostics import DiagnoseConfig, Observations, analyse
    from piga.io.runs import load_model, nominal_of

    path = work / f"case{case['case']:02d}_true.h5"
    if not path.exists():
        collect(replace(collect_config(case, sequences, steps), seed=case["data_seed"]), path, overwrite=True, command="",
                progress=False, make_env=functools.partial(make_case_env, case["effects"]))
    nominal = nominal_of(load_model(work / f"case{case['case']:02d}_model")[0])
    with h5py.File(path, "r") as f:
        theta = np.unwrap(f["states"][:, :, 0].astype(np.float64), axis=1)  # (N, T)
        actions = f["actions"][:, :, 0].astype(np.float64)
    if case["variant"]["flip"] == "camera":  # the frames show the angle mirrored; /states does not
        theta = -theta
    theta = theta + np.random.default_rng(0).normal(0.0, noise, theta.shape)
    n, t = theta.shape
    obs = Observations(theta, actions, np.zeros((n, t)), np.arange(n) < int(0.75 * n), nominal.dt,
                       np.zeros((0, t, 8, 8), np.uint8), np.zeros(0, int), from_gymnasium=False)
    d = analyse(obs, nominal, DiagnoseConfig(bootstrap=0, fit_starts=fit_starts))
    true = truth(case)
    return {"case": case["case"], "angle_noise_rad": noise, "fit_starts": fit_starts, "verdict": d.verdict,
            "corrected": d.corrected,
            "signed_error": {k: d.corrected[k] / true[k] - 1 for k in ("g", "a", "b") if k in d.corrected and true[k]}}


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default="results/diagnose_blind_dmc")
    p.add_argument("--work", type=work_folder, default="runs/blind_dmc", help="folder for the case data, models and reports")
    p.add_argument("--cases", type=positive_int, default=24)
    p.add_argument("--sequences", type=positive_int, default=300)
    p.add_argument("--steps", type=positive_int, default=40)
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument("--quick", action="store_true",
                   help="2 cases of 40 sequences x 16 frames, a 6-epoch tiny model: checks the pipeline, not the diagnosis")
    p.add_argument("--models-only", action="store_true",
                   help="only collect the nominal files and train the nominal models (step 1), for a later run to keep")
    p.add_argument("--only", type=int, nargs="*", default=None, help="run only these case numbers")
    p.add_argument("--jobs", type=positive_int, default=1,
                   help="cases run at once, each in its own process with one torch thread (a machine's cores)")
    add_ray_option(p, "the cases")
    p.add_argument("--true-angles", type=nonnegative_int, default=None, metavar="CASE",
                   help="outside the blind protocol: fit the candidates to case CASE's true angles and print the verdict "
                        "and the signed errors of g, a, b (what the physics gets wrong without the vision)")
    p.add_argument("--angle-noise", type=nonnegative_float, default=0.0, metavar="RAD",
                   help="with --true-angles: add independent Gaussian errors of this rms (rad) to the true angles")
    add_diagnose_options(p, {"--fit-starts": "; with --true-angles: DiagnoseConfig.fit_starts, off unless given"})
    p.add_argument("--rescore", action="store_true",
                   help="score the finished cases' reports (in --work) again with this script's scorer, and rewrite OUT")
    args = p.parse_args(argv)
    if args.angle_noise and args.true_angles is None:  # (it was ignored in silence)
        p.error("--angle-noise goes with --true-angles (errors added to the true angles)")
    if args.quick:
        args.cases, args.sequences, args.steps = min(args.cases, 2), 40, 16
    # --quick: a tiny model (the tests' recipe), which may well be refused: it checks the pipeline
    train_args = ["--epochs", "6", "--batch-size", "8", "--warmup-fraction", "0.1", "--lr", "3e-3"] if args.quick else []
    out, work = Path(args.out), Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    command = shlex.join(["python", *(sys.argv if argv is None else ["benchmarks/diagnose_blind_dmc.py", *argv])])
    json_path = out.with_suffix(".json")
    done: list[dict[str, Any]] = json.loads(json_path.read_text())["runs"] if json_path.exists() else []
    info = {"sequences": args.sequences, "steps": args.steps, "seed": args.seed, "machine": machine(), "jobs": args.jobs,
            "train_note": " (a tiny model: --quick)" if args.quick else ""}
    if args.rescore:  # the command that ran the cases stays the one recorded
        command = json.loads(json_path.read_text())["command"] if json_path.exists() else command
        cases = {c["case"]: c for c in draw_cases(args.cases, args.seed)}
        for r in done:
            report_path = work / f"case{r['case']:02d}" / "report.json"
            if r["score"]["predicted"] != "refused" and report_path.exists():
                r["score"] = score(cases[r["case"]], json.loads(report_path.read_text()))
        save(out, command, info, done, summarize, markdown)
        print(json.dumps(summarize(done), indent=2))
        return 0
    cases = [c for c in draw_cases(args.cases, args.seed) if args.only is None or c["case"] in args.only]
    if args.true_angles is not None:
        case = next((c for c in cases if c["case"] == args.true_angles), None)
        if case is None:
            raise PigaError(f"--true-angles: no case {args.true_angles} among the {args.cases} drawn")
        print(json.dumps(true_angle_fit(case, work, args.sequences, args.steps, args.angle_noise, bool(args.fit_starts)),
                         indent=2))
        return 0
    backend = ray_backend(p, args)
    if args.models_only:
        run_pool(functools.partial(nominal_model, work=work, sequences=args.sequences, steps=args.steps,
                                   train_args=train_args), cases, workers=args.jobs, progress=False,
                 on_result=lambda i, _: print(f"case {cases[i]['case']}: nominal model trained", flush=True),
                 backend=backend, names=[f"case {c['case']}" for c in cases])
        return 0
    todo = [c for c in cases if not any(r["case"] == c["case"] and r["variant"] == c["variant"]
                                        and r["effects"] == c["effects"] for r in done)]

    def finished(_: int, run: dict[str, Any]) -> None:  # saved as each case ends, so that a stopped run continues
        done.append(run)
        done.sort(key=lambda r: r["case"])
        print(f"case {run['case']}: {run['variant']} + {run['effects'] or 'none'} -> {run['score']['verdict']} "
              f"({'ok' if run['score']['top1'] else 'WRONG'})", flush=True)
        save(out, command, info, done, summarize, markdown)

    run_pool(functools.partial(run_case, work=work, sequences=args.sequences, steps=args.steps, train_args=train_args,
                               diagnose_options=diagnose_options(args)),
             todo, workers=args.jobs, progress=False, on_result=finished, backend=backend,
             names=[f"case {c['case']}" for c in todo])
    if done and args.only is None:  # a run over every case records its command
        save(out, command, info, done, summarize, markdown)
    print(json.dumps(summarize(done), indent=2))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
