"""``piga-diagnose`` on recordings imported from H.264 video: on the encoder's angles, and on angles matched to renders.

Each case collects 50 sequences of 40 frames with ``piga-collect`` (an effect the model lacks, the case's own seed;
Gymnasium's picture with its torque arrow, as the model was trained on), writes them one after another to an H.264
``.mp4`` (libx264 at the case's crf, yuv420p, one encoder thread) and the actions to a CSV, and imports both with
``piga-import``: a file whose ``source`` names a lossy video, as a user's would. It is diagnosed twice, in this
process, with the defaults but for one field: as ``piga-diagnose`` does (``codec_reading_ratio`` 1.5), and with every
step on the encoder's angles (the ratio set out of reach; the chosen effects' values are still read on matched
angles, as the default ``--matched-angles`` does). The collected file's states, read here and never by the
diagnosis, measure how far each reading errs (RMS over every frame, after the mean offset).

    python benchmarks/codec_imports.py --model runs/bench/default-seed0 --out results/codec_imports --work runs/codec_imports
"""

from __future__ import annotations

import json
import math
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from pathlib import Path
from typing import NamedTuple

import h5py
import imageio.v2 as imageio
import numpy as np

from common import check_piga_model, checked_command, machine, out_prefix, work_folder, write_page
from piga.cli.common import ArgumentParser, positive_int
from piga.io.atomic import write_json


class Case(NamedTuple):
    effects: dict
    """Effects in the env (``envs.effects``)."""
    crf: int
    """x264's constant rate factor (0 lossless, 51 worst)."""
    seed: int
    """piga-collect's seed."""
    truth: str
    """The verdict class a right reading gives (effects joined by "+" in name order, as the verdict class)."""


CASES: list[Case] = [
    Case({}, 10, 16503, "none"),
    Case({}, 14, 16503, "none"),
    Case({}, 18, 16503, "none"),
    Case({}, 28, 16503, "none"),
    Case({"friction": 0.3}, 18, 16500, "friction"),
    Case({"friction": 0.3}, 26, 16500, "friction"),
    Case({"friction": 0.3}, 26, 16509, "friction"),
    Case({"friction": 0.15}, 26, 16507, "friction"),
    Case({"damping": 0.1}, 26, 16504, "damping"),
    Case({"damping": 0.15, "bias": 0.1}, 24, 16511, "bias+damping"),
    Case({"deadzone": 0.3}, 28, 16501, "deadzone"),
    Case({"deadzone": 0.3}, 28, 16508, "deadzone"),
    Case({"saturation": 0.8}, 28, 16502, "saturation"),
    Case({"saturation": 0.8}, 28, 16510, "saturation"),
    Case({"gain": 0.8}, 28, 16505, "gain"),
    Case({"delay": 2}, 28, 16506, "delay"),
]

#: The two diagnoses, in words.
WAYS = {"default": "by default", "encoder": "on the encoder's angles"}
#: A ``codec_reading_ratio`` that no recording reaches: every step on the encoder's angles.
ENCODER_ONLY = 1e9


def collected(case: Case, work: Path) -> Path:
    """The case's file of ``piga-collect`` (cases of the same effects and seed share it), collected where missing."""
    raw = work / (("_".join(f"{k}{v}" for k, v in case.effects.items()) or "clean") + f"_s{case.seed}_raw.h5")
    if not raw.exists():
        checked_command(["piga-collect", "--out", str(raw), "--sequences", "50", "--steps", "40", "--seed", str(case.seed),
                         "--quiet", "--workers", "1", *[a for k, v in case.effects.items() for a in ("--effect", f"{k}={v}")]])
    return raw


def imported(case: Case, work: Path) -> Path:
    """Where the case's imported file goes."""
    raw = collected(case, work)
    return raw.with_name(raw.name.removesuffix("_raw.h5") + f"_crf{case.crf}.h5")


def record(case: Case, work: Path) -> tuple[Path, Path]:
    """Writes the case's collected file to video and CSV and imports them; returns (the collected file, the imported)."""
    raw, data = collected(case, work), imported(case, work)
    stem = raw.with_name(raw.name.removesuffix("_raw.h5"))
    with h5py.File(raw, "r") as f:
        frames, actions = f["frames"][()], f["actions"][()]  # (N, T, H, W) uint8, (N, T, 1)
    video = data.with_suffix(".mp4")
    # (imageio-ffmpeg writes the frames through ffmpeg's libx264; one thread, so that the encoding does not depend on
    # the machine's cores)
    writer = imageio.get_writer(video, fps=20, codec="libx264", quality=None, pixelformat="yuv420p", macro_block_size=16,
                                output_params=["-crf", str(case.crf), "-preset", "medium", "-threads", "1"])
    for frame in frames.reshape(-1, *frames.shape[2:]):
        writer.append_data(np.repeat(frame[..., None], 3, axis=2))
    writer.close()
    csv = stem.with_name(stem.name + ".csv")
    np.savetxt(csv, actions.reshape(-1, actions.shape[-1])[:, 0], header="u", comments="")
    checked_command(["piga-import", str(video), str(csv), "--dt", "0.05", "--out", str(data), "--overwrite"])
    return raw, data


def reading_error(theta: np.ndarray, states: np.ndarray) -> float:
    """RMS (deg) of (N, T) angles against the (N, T) true ones, after each reading's mean offset, wrapped."""
    e = np.remainder(theta - states + math.pi, 2 * math.pi) - math.pi
    e = np.remainder(e - np.median(e) + math.pi, 2 * math.pi) - math.pi
    return float(np.degrees(np.sqrt(np.mean(e ** 2))))


def reading(diagnosis: dict, truth: str) -> str:
    """"right": the verdict names the truth; "ambiguous": an ambiguity between "none" and the truth, said aloud;
    "wrong": anything else (another effect named, the truth missed, "not explained")."""
    if diagnosis["verdict_class"] == truth:
        return "right"
    if diagnosis["verdict_class"] == "ambiguous" and diagnosis["verdict"].startswith(f"ambiguous between none and {truth} "):
        return "ambiguous"
    return "wrong"


def readings(model: object, path: Path, states: np.ndarray) -> dict:
    """How far the encoder's angles and the matched ones of the file ``path`` err against the (N, T) ``states``, and
    the ratio that decides between them (:func:`piga.diagnostics.diagnose.codec_reading_ratio`)."""
    import torch

    from piga.diagnostics.diagnose import codec_reading_ratio
    from piga.diagnostics.observe import observe
    from piga.diagnostics.vision import Camera, match_file
    from piga.io.runs import nominal_of

    with torch.no_grad():
        obs = observe(model, path)
        matched = match_file(model, str(path), Camera())
    return {"encoder_error_deg": reading_error(obs.theta, states), "matched_error_deg": reading_error(matched, states),
            "ratio": codec_reading_ratio(obs, matched, nominal_of(model))}


def uncompressed(model_dir: str, case: Case, work: Path) -> dict:
    """:func:`readings` of the case's collected file itself (no codec), kept in --work beside it."""
    import torch

    from piga.io.runs import load_model

    torch.set_num_threads(1)
    raw = collected(case, work)
    done = raw.with_suffix(".readings.json")
    if not done.exists():
        with h5py.File(raw, "r") as f:
            states = f["states"][()][..., 0]  # (N, T): evaluation only
        write_json(done, readings(load_model(model_dir)[0], raw, states), overwrite=True)
    return json.loads(done.read_text())


def run_case(model_dir: str, case: Case, work: Path) -> dict:
    """Records, imports and diagnoses one case both ways."""
    import torch

    from piga.diagnostics import DiagnoseConfig
    from piga.diagnostics.diagnose import diagnose
    from piga.io.runs import load_model, with_training_file

    torch.set_num_threads(1)
    t0 = time.time()
    done = imported(case, work).with_suffix(".json")  # (a case diagnosed before, by this script: a rerun goes on there)
    if done.exists():
        return json.loads(done.read_text())
    raw, data = record(case, work)
    model, checkpoint = load_model(model_dir)
    checkpoint = with_training_file(checkpoint, model_dir, None)
    with h5py.File(raw, "r") as f:
        states = f["states"][()][..., 0]  # (N, T): evaluation only
    row = {"effects": case.effects, "crf": case.crf, "seed": case.seed, "truth": case.truth, "data": str(data),
           **readings(model, data, states)}
    for name, config in (("default", DiagnoseConfig()), ("encoder", replace(DiagnoseConfig(), codec_reading_ratio=ENCODER_ONLY))):
        d = diagnose(model, data, config, checkpoint=checkpoint)
        row[name] = {"verdict": d.verdict, "verdict_class": d.verdict_class, "effects": [asdict(e) for e in d.effects],
                     "notes": d.notes}
    row["seconds"] = time.time() - t0
    write_json(done, row, overwrite=True)
    print(f"{case.effects or 'clean'} crf {case.crf} seed {case.seed}: {row['default']['verdict'][:90]} | "
          f"encoder: {row['encoder']['verdict'][:90]}", flush=True)
    return row


def short(verdict: str) -> str:
    """The verdict up to its first colon or parenthesis of detail, for the table."""
    for cut in (" (95%", ": ", " (ΔBIC"):
        verdict = verdict.split(cut)[0]
    return verdict


def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (the identified model)")
    p.add_argument("--out", type=out_prefix, default="results/codec_imports")
    p.add_argument("--work", type=work_folder, default="runs/codec_imports", help="folder for the recordings and data files")
    p.add_argument("--jobs", type=positive_int, default=2, help="cases at once, one torch thread each")
    args = p.parse_args()
    check_piga_model(args.model)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    for case in CASES:  # (before the jobs: two cases of one file would collect it at once)
        collected(case, work)
    with ProcessPoolExecutor(args.jobs) as pool:
        runs = list(pool.map(run_case, [args.model] * len(CASES), CASES, [work] * len(CASES)))
        # each collected file once, uncompressed: how the two readings compare without a codec
        firsts = list({(json.dumps(c.effects), c.seed): c for c in CASES}.values())
        plain = dict(zip([(json.dumps(c.effects), c.seed) for c in firsts],
                         pool.map(uncompressed, [args.model] * len(firsts), firsts, [work] * len(firsts))))
    for r in runs:
        r["uncompressed"] = plain[(json.dumps(r["effects"]), r["seed"])]
    truths = {(json.dumps(c.effects), c.crf, c.seed): c.truth for c in CASES}
    for r in runs:  # (judged here, not in the job: a case's record in --work keeps only what the diagnosis said)
        truth = truths[(json.dumps(r["effects"]), r["crf"], r["seed"])]
        r["truth"] = truth
        for way in WAYS:
            r[way]["reading"] = reading(r[way], truth)
    info = {"command": shlex.join(["python", *sys.argv]), "model": args.model, "machine": machine()}
    count = {k: {r: sum(x[k]["reading"] == r for x in runs) for r in ("right", "ambiguous", "wrong")}
             for k in ("default", "encoder")}
    lines = ["# piga-diagnose on recordings imported from H.264 video", "", f"Command: `{info['command']}`", "",
             f"Model: `{args.model}`. Each recording: `piga-collect` with an effect, 50 sequences of 40 frames (64x64, "
             "the torque arrow drawn), written to H.264 (libx264, yuv420p, one thread) at the crf given, and imported "
             "with `piga-import --dt 0.05`. Diagnosed with the defaults (every step on angles matched to the decoder's "
             "renders where the encoder reads the codec's errors, `codec_reading_ratio` 1.5), and with every step on "
             "the encoder's angles. Reading errors: RMS against the states, which only this script reads. Machine: "
             f"{info['machine']['cpu']}, {info['machine']['cores']} cores.", "",
             *[f"- {WAYS[k]}: {c['right']} right, {c['ambiguous']} ambiguous between none and the truth, {c['wrong']} "
               f"wrong, of {len(runs)}" for k, c in count.items()], "",
             "| effect | crf | seed | encoder's error (deg) | matched (deg) | ratio | uncompressed: encoder's, matched, ratio "
             "| default verdict | on the encoder's angles |", "|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        effect = ", ".join(f"{k} {v}" for k, v in r["effects"].items()) or "none"
        u = r["uncompressed"]
        cell = lambda k: short(r[k]["verdict"]) + (" (**wrong**)" if r[k]["reading"] == "wrong" else "")  # noqa: E731
        lines.append(f"| {effect} | {r['crf']} | {r['seed']} | {r['encoder_error_deg']:.2f} | {r['matched_error_deg']:.2f} | "
                     f"{r['ratio']:.2f} | {u['encoder_error_deg']:.2f}, {u['matched_error_deg']:.2f}, {u['ratio']:.2f} | "
                     f"{cell('default')} | {cell('encoder')} |")
    write_page(Path(args.out), {**info, "runs": runs}, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
