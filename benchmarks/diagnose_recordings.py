"""``piga-diagnose`` on recordings, as a user would bring them: a video file and a CSV of actions.

Each case runs the pendulum with an effect the model lacks as *one long episode* (no resets:
sequences are cut from the recording, so none starts at a reset), writes Gymnasium's full-size
render as an H.264 ``.mp4`` (lossy, as a camera would record it) without the torque arrow, and the
actions as a CSV. ``piga-import`` turns them into a data file, and ``piga-diagnose`` runs on it in
a fresh process; the effect is known only to this script.

A dropped frame is recorded here by writing the previous render again (a full-size frame, before
the import's resize), with the same probability per step as ``envs.effects.FrameDrop``. A soft lens
is a Gaussian blur of the full-size render (σ = 8 of its 500 pixels, about 1 pixel of the 64 the
import keeps).

    python benchmarks/diagnose_recordings.py --model RUN_DIR --out results/diagnose_recordings
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path
from typing import NamedTuple

import cv2
import imageio.v2 as imageio
import numpy as np

from common import (add_diagnose_options, check_piga_model, checked_command, diagnose_options, machine, out_prefix,
                    work_folder, write_page)
from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
from piga.cli.common import ArgumentParser, seed_int

class Case(NamedTuple):
    effects: dict
    """Effects in the env (``envs.effects``)."""
    drop: float
    """Probability that the camera delivers the previous picture again."""
    blur: float
    """Gaussian σ of a soft lens, in pixels of the full-size render (0: sharp)."""
    truth: str
    """The expected verdict class."""


CASES: list[Case] = [
    Case({}, 0.0, 0.0, "none"),
    Case({"damping": 0.2}, 0.0, 0.0, "damping"),
    Case({"delay": 2}, 0.0, 0.0, "delay"),
    Case({"friction": 0.15}, 0.0, 0.0, "friction"),
    Case({"bias": -0.2}, 0.0, 0.0, "bias"),
    Case({"cogging": 0.4}, 0.0, 0.0, "unexplained"),
    Case({}, 0.1, 0.0, "frame_drop"),
    Case({"damping": 0.15}, 0.1, 0.0, "damping+frame_drop"),
    Case({"saturation": 1.0}, 0.0, 0.0, "saturation"),
    Case({"deadzone": 0.5}, 0.0, 0.0, "deadzone"),
    Case({"gain": 0.8}, 0.0, 0.0, "gain"),
    Case({}, 0.0, 8.0, "blur"),
]


def record(effects: dict, drop: float, blur: float, frames: int, seed: int, out: Path) -> tuple[Path, Path]:
    """Writes ``out``.mp4 and ``out``.csv: one episode of random actions u ~ U(-2, 2)."""
    env = make_pixel_pendulum(PixelPendulumConfig(effects=tuple(effects.items()), episode_length=10 * frames,
                                                  draw_torque_arrow=False))
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    video, actions, last = [], [], None
    for _ in range(frames):
        shown = env.render()
        if blur:
            shown = cv2.GaussianBlur(shown, (0, 0), blur)
        if last is not None and rng.random() < drop:
            shown = last  # the camera delivers the previous picture again
        video.append(shown)
        last = shown
        u = float(rng.uniform(-2, 2))
        actions.append(u)
        env.step(np.array([u], np.float32))
    env.close()
    imageio.mimwrite(out.with_suffix(".mp4"), video, fps=20, quality=8, macro_block_size=1)
    np.savetxt(out.with_suffix(".csv"), np.array(actions), header="u", comments="")
    return out.with_suffix(".mp4"), out.with_suffix(".csv")


def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (the identified model)")
    p.add_argument("--out", type=out_prefix, default="results/diagnose_recordings")
    p.add_argument("--work", type=work_folder, default="runs/recordings", help="folder for the recordings, data files and reports")
    p.add_argument("--frames", type=int, default=4000, help="frames per recording (100 sequences of 40)")
    p.add_argument("--seed", type=seed_int, default=5)
    add_diagnose_options(p)
    args = p.parse_args()
    options = diagnose_options(args)
    check_piga_model(args.model)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    runs = []
    for i, (effects, drop, blur, truth) in enumerate(CASES):
        t0 = time.time()
        stem = work / f"recording{i}"
        video, csv = record(effects, drop, blur, args.frames, args.seed + i, stem)
        data = stem.with_suffix(".h5")
        checked_command(["piga-import", str(video), str(csv), "--dt", "0.05", "--out", str(data), "--overwrite"])
        report_dir = work / f"report{i}"
        checked_command(["piga-diagnose", "--model", args.model, "--data", str(data), "--out", str(report_dir), "--overwrite",
                         "--quiet", *options])
        report = json.loads((report_dir / "report.json").read_text())
        runs.append({"case": i, "effects": effects, "frame_drop": drop, "blur_full_size_px": blur, "truth": truth,
                     "verdict": report["verdict"],
                     "verdict_class": report["verdict_class"], "correct": report["verdict_class"] == truth,
                     "effects_found": report["effects"], "closure": report["gap"]["free_run_gap_closure"],
                     "closure_basis": report["gap"]["closure_basis"], "notes": report["notes"],
                     "seconds": time.time() - t0})
        print(f"recording {i}: {effects or 'none'}, drop {drop}, blur {blur} -> {report['verdict']}", flush=True)
    info = {"command": shlex.join(["python", *sys.argv]), "model": args.model, "frames": args.frames, "machine": machine()}
    pct = lambda v: "–" if v is None else f"{100 * v:.0f}%"  # noqa: E731
    lines = ["# piga-diagnose on imported video recordings", "", f"Command: `{info['command']}`", "",
             f"Model: `{args.model}`. Each recording: one episode of {args.frames} frames of random actions, Gymnasium's "
             "render without the torque arrow, H.264 mp4 (imageio-ffmpeg, quality 8), imported with `piga-import --dt 0.05` "
             f"(sequences of 40 frames cut from the recording). Machine: {info['machine']['cpu']}, {info['machine']['cores']} cores.",
             "", f"Correct verdicts: {sum(r['correct'] for r in runs)}/{len(runs)}.", "",
             "| recording | effect (hidden from the diagnosis) | verdict | correct | closure (basis) |", "|---|---|---|---|---|"]
    for r in runs:
        eff = ", ".join(f"{k}={v}" for k, v in r["effects"].items()) or "none"
        eff += f", frame_drop={r['frame_drop']}" if r["frame_drop"] else ""
        eff += f", lens blur σ={r['blur_full_size_px']:g} px of the full-size render" if r.get("blur_full_size_px") else ""
        lines.append(f"| {r['case']} | {eff} | {r['verdict']} | {'yes' if r['correct'] else '**no**'} | "
                     f"{pct(r['closure'])} ({r['closure_basis']}) |")
    write_page(Path(args.out), {**info, "runs": runs}, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
