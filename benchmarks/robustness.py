"""Benchmark: piga's default recipe, unchanged, on data files it was not tuned on.

Each row is one data file and one training run with the default command, run as a user runs it::

    piga-train-model FILE --out RUN --threads 1 --quiet            # (--seed S on the seed rows)

The files are collected with ``piga-collect`` (data seed 200, not the 100 of ``systems.py`` and
``train_accuracy.py``, so that no file is one the recipe was checked on) and changed one thing at a
time: the number of sequences and of frames, the balls' radius, colours and background, the
pendulum's image size and true g and a, and, made by this script on a copy of the default file,
Gaussian pixel noise and a round trip through H.264 (see :func:`add_noise` and :func:`h264_roundtrip`).
Ten training seeds on one spring file and one gravity file check that the recipe does not depend on
its seed.

    python benchmarks/robustness.py --list                                  # the rows, their cost, what is done
    python benchmarks/robustness.py --out results/robustness                # every row (resumable)
    python benchmarks/robustness.py --rows 'pendulum/*' 'seeds/spring-*'    # a subset (shell patterns)

Each row's record (exit code, last stderr line, wall time, learned parameters and their errors, the
run's ``converged`` report, SSIM, object tracking errors, verdict) is saved atomically to
``WORK/records/ROW.json`` as soon as the row ends, and ``OUT.md`` and ``OUT.json`` are rewritten from
all records after each row, so an interrupted benchmark loses one row at most and continues where it
stopped. A row with a record is skipped; delete the record (and ``WORK/runs/RUN.run.json``) to rerun it. In a
new ``--work`` (another machine), the rows that ``OUT.json`` already holds are taken from it, so a
benchmark spread over several machines or days continues where the published page stops.

A last row, ``own/spring-opencv``, trains on a spring file that piga did not draw: this script's own
numpy simulation of the published convention, its balls drawn by OpenCV (:func:`render_spring_opencv`).
Whether the encoder found every object is judged from the run's checkpoint against ``/states`` (balls:
mean distance under 1 px; pendulum: metrics.json's angle error under 5°; :func:`object_errors`).

    python benchmarks/robustness.py --workers 2                             # two rows at once, one thread each

Rows are jobs of piga's job runner (:func:`piga.io.pool.run_pool`): ``--workers`` processes of this machine
(default 1: one row at a time), or with ``--ray auto|HOST:PORT`` tasks of a Ray cluster (``--work`` then one
folder shared by every machine). Rows that share a data file or a run wait for each other through a lock
file next to it, so each file is made and each run trained once. A row that raises for another reason than
a file that could not be made stops the benchmark with one line naming it, keeping the rows finished before.

Data and runs go to ``--work`` (default ``runs/robustness``, ignored by git). A row whose file cannot
be made (``piga-collect`` refuses the options) is reported at the end and gets no record (exit status 1).

Verdicts (:func:`score`): ``pass`` when every learned parameter is within 2% and the run did not report
``converged: false``; ``flagged`` when the run exited non-zero or reported ``converged: false`` (a
correct refusal when the file cannot identify the parameters); ``FAIL`` when it exited 0, did not
report ``converged: false``, and a parameter is more than 5% off; ``miss`` otherwise (2-5%).
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import re
import shlex
import shutil
import signal
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from filelock import FileLock

from common import add_ray_option, farm_main, job_command, machine, machine_words, out_prefix, ray_backend, work_folder
from piga.cli.common import ArgumentParser, PigaError, NOT_CONVERGED, positive_int
from piga.io.atomic import atomic_output, write_json, written_together
from piga.io.pool import git_commit, run_pool
from piga.data.schema import DatasetWriter

#: ``piga-collect --seed`` of every file: not the 100 that systems.py and train_accuracy.py check the recipe on.
DATA_SEED = 200
#: A learned parameter within this relative error passes.
PASS_ERROR = 0.02
#: Beyond this relative error, a run that exits 0 and does not report ``converged: false`` FAILs.
FAIL_ERROR = 0.05
#: A ball scene's object is found when the encoder's position of it is this close to the truth on
#: average (pixels, test split, best assignment of encoder slots to balls; the balls' radius is 3).
FOUND_PX = 1.0
#: The pendulum's rod is found when the encoder's angle is this close on average (degrees, after the
#: best constant offset; metrics.json's ``angle.mean_abs_error_after_best_offset_deg``).
FOUND_DEG = 5.0
#: Training seeds of the seed rows, and the floors on how many must find the objects and be within 2%.
SEEDS = tuple(range(10))
SEED_FLOORS = {"spring": 10, "gravity": 9}
#: Training milliseconds per window (one thread, at the scene's native image size), measured on the
#: lead's 2-core machine (results/train_accuracy.json, results/systems.json); for ``--list`` only.
MS_PER_WINDOW = {"pendulum": 6.2, "spring": 2.5, "gravity": 6.0}
#: Seconds per frame to collect (one worker); seconds per sequence (two ffmpeg processes) and per pixel
#: of an encoded frame to pass a sequence through H.264 (one ffmpeg thread, measured on a loaded 2-core machine).
COLLECT_S_PER_FRAME = {"pendulum": 1e-3, "spring": 5e-4, "gravity": 6e-4}
H264_S_PER_SEQUENCE, H264_S_PER_PIXEL = 0.3, 3e-7
#: Frames a second of the H.264 files (a phone's; x264's CRF depends on it only weakly).
H264_FPS = 30
VERDICTS = ("pass", "flagged", "miss", "FAIL")


# --------------------------------------------------------------------------------------------- rows
@dataclass(frozen=True)
class Row:
    """One data file and one training run."""

    name: str
    """``GROUP/CASE``; GROUP is the system, ``seeds``, or ``own`` (another renderer)."""
    system: str
    """``pendulum``, ``spring`` or ``gravity`` (``piga-collect --system``)."""
    collect: tuple[str, ...] = ()
    """``piga-collect`` options besides ``--system``, ``--seed`` and ``--out``."""
    post: str = ""
    """What this script does to the collected file: "" nothing, ``noise:S`` (σ = S/255), or
    ``h264:crf=C`` / ``h264:crf=C:scale=K`` (see :func:`postprocess`)."""
    seed: int | None = None
    """``piga-train-model --seed``; None: the option is not passed (the default, 0)."""
    renderer: str = ""
    """"": the file comes from ``piga-collect``; "opencv": from this script's own simulation and
    OpenCV drawing (:func:`render_spring_opencv`; spring only, ``collect`` unused)."""

    @property
    def group(self) -> str:
        return self.name.split("/", 1)[0]

    @property
    def source_name(self) -> str:
        """The stem of the collected file (shared by rows with the same collection)."""
        if self.renderer:
            return f"{self.system}-{self.renderer}"
        return "-".join([self.system, *(_slug(a) for a in self.collect)]) if self.collect else f"{self.system}-default"

    @property
    def data_name(self) -> str:
        """The stem of the file the row trains on."""
        return f"{self.source_name}+{_slug(self.post)}" if self.post else self.source_name

    @property
    def run_name(self) -> str:
        """The run folder's name: rows on one file with one seed share it (seed 0 is the default)."""
        return f"{self.data_name}-seed{self.seed or 0}"

    def collect_command(self, out: Path) -> list[str]:
        if self.renderer:
            return ["benchmarks/robustness.py:render_spring_opencv", str(out)]
        return ["piga-collect", "--system", self.system, *self.collect, "--seed", str(DATA_SEED), "--workers", "1",
                "--quiet", "--out", str(out)]

    def train_command(self, data: Path, run: Path) -> list[str]:
        seed = [] if self.seed is None else ["--seed", str(self.seed)]
        # one retry for a scene: the records were made with it (piga-train-model's default was 1); a pendulum's model
        # has no object slots to check, and piga-train-model refuses the option there
        retries = [] if self.system == "pendulum" else ["--seed-retries", "1"]
        return ["piga-train-model", str(data), "--out", str(run), *retries, "--threads", "1", "--quiet", *seed]

    def describe(self) -> str:
        """What differs from the system's default file, in words."""
        parts = [" ".join(self.collect)] if self.collect else []
        if self.renderer:
            parts.append("another renderer: this script's numpy simulation, balls drawn by OpenCV (anti-aliased)")
        if self.post:
            parts.append(_describe_post(self.post))
        if self.seed is not None:
            parts.append(f"training --seed {self.seed}")
        return "; ".join(parts) or "the default file"


def _slug(text: str) -> str:
    """A file-name part: "--colors" -> "colors", "#401a4d" -> "401a4d", "h264:crf=23" -> "h264crf23"."""
    return re.sub(r"[^A-Za-z0-9.]+", "", text.lstrip("-"))


def _case(post: str) -> str:
    """A row's name for a post-processing: "h264:crf=23:scale=4" -> "h264-crf23-x4"."""
    return post.replace(":", "-").replace("=", "").replace("scale", "x")


def rows() -> list[Row]:
    """Every row of the benchmark, in the order they run."""
    post = ["noise:10", "noise:25", "h264:crf=23", "h264:crf=28", "h264:crf=23:scale=4"]
    out: list[Row] = []
    ball_looks = {
        "spring": [("radius2", ("--radius", "2")), ("radius5", ("--radius", "5")),
                   ("colors", ("--colors", "gold", "turquoise")),
                   ("background-dark", ("--background", "#401a4d")), ("background-light", ("--background", "#d9d9d9")),
                   ("k3-l8", ("--k", "3", "--l", "8"))],
        # 4.5: piga-collect refuses radius 5 for three balls in 36 px ("need at least 40 px")
        "gravity": [("radius2", ("--radius", "2")), ("radius4.5", ("--radius", "4.5")),
                    ("colors", ("--colors", "gold", "turquoise", "magenta")),
                    ("background-dark", ("--background", "#401a4d")), ("background-light", ("--background", "#d9d9d9")),
                    ("g45", ("--g", "45"))],
    }
    for system, native_steps in (("spring", 30), ("gravity", 40)):
        out.append(Row(f"{system}/default", system))
        out += [Row(f"{system}/sequences{n}", system, ("--sequences", str(n))) for n in (200, 5000)]
        out += [Row(f"{system}/steps{t}", system, ("--steps", str(t))) for t in (10, 12, 20, 30) if t != native_steps]
        out += [Row(f"{system}/{case}", system, options) for case, options in ball_looks[system]]
        out += [Row(f"{system}/{_case(p)}", system, post=p) for p in post]
    out.append(Row("pendulum/default", "pendulum"))
    out += [Row(f"pendulum/sequences{n}", "pendulum", ("--sequences", str(n))) for n in (50, 200, 2000)]
    out += [Row(f"pendulum/steps{t}", "pendulum", ("--steps", str(t))) for t in (10, 20)]
    out += [Row(f"pendulum/size{s}", "pendulum", ("--image-size", str(s))) for s in (32, 96)]
    out += [Row(f"pendulum/g{g}", "pendulum", ("--gravity", str(g))) for g in (7, 13)]
    out += [Row(f"pendulum/a{a}", "pendulum", ("--actuation-gain", str(a))) for a in (0.6, 1.4)]
    out.append(Row("pendulum/g13-a0.6", "pendulum", ("--gravity", "13", "--actuation-gain", "0.6")))
    # Gray frames keep full resolution through 4:2:0 (only colour is subsampled): no x4 row for the pendulum.
    out += [Row(f"pendulum/{_case(p)}", "pendulum", post=p) for p in post if "scale" not in p]
    out += [Row(f"seeds/{system}-seed{s}", system, seed=s) for system in ("spring", "gravity") for s in SEEDS]
    out.append(Row("own/spring-opencv", "spring", renderer="opencv"))
    return out


def select(all_rows: list[Row], patterns: list[str] | None) -> list[Row]:
    """The rows whose name matches one of the shell patterns (all rows when there are none)."""
    if not patterns:
        return all_rows
    chosen = [r for r in all_rows if any(fnmatch.fnmatchcase(r.name, p) for p in patterns)]
    if not chosen:
        raise PigaError(f"--rows {' '.join(patterns)}: no row matches; see --list")
    return chosen


# ---------------------------------------------------------------------------------------- estimates
def _option(row: Row, name: str) -> str | None:
    return row.collect[row.collect.index(name) + 1] if name in row.collect else None


def file_shape(row: Row) -> tuple[int, int, int]:
    """(sequences, frames per sequence, image side) of the row's file: its options, else ``piga-collect``'s defaults."""
    from envs.scenes import scene_config
    from piga.data.collect import CollectConfig
    from piga.data.collect_scenes import SCENE_PRESETS, SCENE_STEPS

    if row.system == "pendulum":
        base = CollectConfig()
        n, t, size = base.sequences, base.steps, base.env.image_size
    else:
        n, t, size = SCENE_PRESETS["default"].sequences, SCENE_STEPS[row.system], scene_config(row.system).image_size
    return (int(_option(row, "--sequences") or n), int(_option(row, "--steps") or t), int(_option(row, "--image-size") or size))


def recipe_windows(row: Row) -> tuple[int, Any, int]:
    """(L + T_pred, the recipe's TrainConfig, window stride) of the default recipe for the row's system,
    with T_pred as training shortens it for the row's sequence length."""
    from piga.training.train import PRESETS, SCENE_PRESETS, pred_frames_for

    recipe = PRESETS["fast"] if row.system == "pendulum" else SCENE_PRESETS[row.system]["fast"]
    window = recipe.model.input_frames + pred_frames_for(recipe.model, file_shape(row)[1])
    return window, recipe.train, recipe.train.window_stride


def estimate_minutes(row: Row) -> dict[str, float]:
    """Rough minutes on one core: ``data`` (collect and post-process the file) and ``train`` (0.1: refused)."""
    n, t, size = file_shape(row)
    native = file_shape(Row("x", row.system))[2]
    data = n * t * COLLECT_S_PER_FRAME[row.system] / 60
    if row.post.startswith("h264"):
        scale = int(_parse_post(row.post)[1]["scale"])
        data += n * (H264_S_PER_SEQUENCE + t * (scale * size) ** 2 * H264_S_PER_PIXEL) / 60
    from piga.training.train import plan_training

    window, config, stride = recipe_windows(row)
    windows = int(0.8 * n) * len(range(0, t - window + 1, stride))
    if windows < config.batch_size:
        return {"data": data, "train": 0.1}  # refused at once
    seen = plan_training(config, windows).total_steps * config.batch_size  # windows the planned run trains on
    train = seen * MS_PER_WINDOW[row.system] * (size / native) ** 2 / 60000 + 0.5
    return {"data": data, "train": train}


# ---------------------------------------------------------------------------------- post-processing
def _parse_post(spec: str) -> tuple[str, dict[str, float]]:
    """``noise:10`` -> ("noise", {"sigma": 10}); ``h264:crf=23:scale=4`` -> ("h264", {"crf": 23, "scale": 4})."""
    kind, *fields = spec.split(":")
    if kind == "noise":
        try:
            (value,) = fields
            return kind, {"sigma": float(value.removeprefix("sigma="))}
        except ValueError:
            raise ValueError(f"post-processing {spec!r}: write noise:S, S the σ in 1/255 units") from None
    if kind == "h264":
        params = {"crf": 23.0, "scale": 1.0}
        for item in fields:
            key, sep, value = item.partition("=")
            if not sep or key not in params:
                raise ValueError(f"post-processing {spec!r}: write h264:crf=C[:scale=K]")
            params[key] = float(value)
        if params["scale"] < 1 or params["scale"] != int(params["scale"]):
            raise ValueError(f"post-processing {spec!r}: the scale must be an integer >= 1")
        return kind, params
    raise ValueError(f"post-processing {spec!r}: unknown kind {kind!r}; known: noise, h264")


def _describe_post(spec: str) -> str:
    kind, p = _parse_post(spec)
    if kind == "noise":
        return f"Gaussian pixel noise σ = {p['sigma']:g}/255, rounded and clipped to uint8"
    scale = int(p["scale"])
    return (f"H.264 (libx264 CRF {p['crf']:g}, yuv420p" + (f", at {scale}x the size: nearest-neighbour up, "
                                                            f"{scale}x{scale} mean down" if scale > 1 else "") + ")")


def add_noise(frames: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """uint8 frames plus Gaussian noise of σ ``sigma`` (in 0-255 units), rounded and clipped to uint8."""
    noisy = frames.astype(np.float32) + rng.normal(0.0, sigma, frames.shape).astype(np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def h264_roundtrip(frames: np.ndarray, crf: float = 23, scale: int = 1, fps: int = H264_FPS) -> np.ndarray:
    """One sequence's frames (uint8 (T, H, W) gray or (T, H, W, 3)) encoded with libx264 and decoded back.

    The sequence is one clip, as a phone records one: one MP4 file, x264's ``medium`` preset at CRF
    ``crf``, 4:2:0 chroma (each 2x2 block of pixels shares one colour), one key frame at the start.
    libx264 needs even sides: an odd side is padded by repeating the edge and cropped after. With
    ``scale`` K > 1 each frame is first blown up K times (nearest neighbour) and the decoded frame is
    brought back by the mean of each KxK block, so that without the codec the round trip is exact:
    compression at a phone-like size rather than at 32x32, where 4:2:0 alone smears a 3-pixel ball's colour.
    """
    import imageio_ffmpeg

    if frames.dtype != np.uint8 or frames.ndim not in (3, 4) or (frames.ndim == 4 and frames.shape[-1] != 3):
        raise ValueError(f"h264_roundtrip: need uint8 (T, H, W) or (T, H, W, 3), got {frames.dtype} {frames.shape}")
    t, h, w = frames.shape[:3]
    x = np.repeat(np.repeat(frames, scale, axis=1), scale, axis=2) if scale > 1 else frames
    big_h, big_w = x.shape[1:3]
    pad = ((0, 0), (0, big_h % 2), (0, big_w % 2)) + (((0, 0),) if x.ndim == 4 else ())
    x = np.pad(x, pad, mode="edge")
    pix_fmt, bpp = ("rgb24", 3) if x.ndim == 4 else ("gray", 1)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "clip.mp4")
        writer = imageio_ffmpeg.write_frames(path, (x.shape[2], x.shape[1]), pix_fmt_in=pix_fmt, pix_fmt_out="yuv420p",
                                             fps=fps, codec="libx264", quality=None, macro_block_size=1,
                                             ffmpeg_log_level="error",
                                             output_params=["-crf", f"{crf:g}", "-preset", "medium", "-threads", "1"])
        writer.send(None)  # start ffmpeg
        for frame in x:
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        reader = imageio_ffmpeg.read_frames(path, pix_fmt=pix_fmt, bpp=bpp, input_params=["-threads", "1"])
        next(reader)  # metadata
        shape = x.shape[1:]
        decoded = np.stack([np.frombuffer(buffer, np.uint8).reshape(shape) for buffer in reader])
    if len(decoded) != t:
        raise RuntimeError(f"h264_roundtrip: encoded {t} frames, decoded {len(decoded)}")
    decoded = decoded[:, :big_h, :big_w]
    if scale > 1:
        decoded = np.rint(decoded.reshape(t, h, scale, w, scale, *decoded.shape[3:]).mean(axis=(2, 4))).astype(np.uint8)
    return decoded


def postprocess(source: Path, target: Path, spec: str, seed: int = DATA_SEED, chunk: int = 64,
                progress: Callable[[int], None] | None = None) -> None:
    """Writes ``target``: ``source`` with its frames changed by ``spec`` (``noise:S`` or ``h264:crf=C[:scale=K]``).

    Everything else is kept: ``/actions``, ``/states``, ``/rewards``, ``/split`` and every file
    attribute. The attr ``postprocess`` (JSON) says what was done, to which file, and with what.
    The file is written atomically by :class:`piga.data.schema.DatasetWriter`, in chunks of sequences.
    """
    kind, params = _parse_post(spec)
    rng = np.random.default_rng(seed)
    with h5py.File(source, "r") as f:
        extra = set(f) - {"frames", "actions", "states", "rewards", "split"}
        if extra:
            raise ValueError(f"{source}: datasets {sorted(extra)} are not in piga's schema; postprocess would drop them")
        frames = f["frames"]
        n, t = frames.shape[:2]
        image_shape = tuple(frames.shape[2:])
        attrs = dict(f.attrs)
        attrs["postprocess"] = {"spec": spec, "kind": kind, **params, "seed": seed, "what": _describe_post(spec),
                                "source": str(source), "by": "benchmarks/robustness.py"}
        has_states, has_rewards = "states" in f, "rewards" in f
        state_dim = int(f["states"].shape[2]) if has_states else None
        with DatasetWriter(target, n, t, image_shape, int(f["actions"].shape[2]), state_dim, attrs, overwrite=True,
                           rewards=has_rewards) as writer:
            for start in range(0, n, chunk):
                stop = min(start + chunk, n)
                block = frames[start:stop]  # (n, T, H, W[, C])
                if kind == "noise":
                    out = add_noise(block, params["sigma"], rng)
                else:
                    squeeze = block.ndim == 5 and block.shape[-1] == 1
                    seqs = block[..., 0] if squeeze else block
                    out = np.stack([h264_roundtrip(s, params["crf"], int(params["scale"])) for s in seqs])
                    out = out[..., None] if squeeze else out
                writer.write(start, out, f["actions"][start:stop], f["states"][start:stop] if has_states else None,
                             f["rewards"][start:stop] if has_rewards else None)
                if progress:
                    progress(stop - start)
            writer.set_split(f["split"][()])


# ------------------------------------------------------------------------------------ own renderer
def simulate_spring(p0: np.ndarray, v0: np.ndarray, steps: int, k: float = 4.0, ell: float = 6.0, dt: float = 0.3,
                    substeps: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Balls on springs, the published convention (GUIDE section 2): the force on ball i is
    -k (|d| - 2 l) d / |d| summed over the others, d = p_i - p_j, unit masses, ``substeps``
    semi-implicit Euler steps per frame.

    Args:
        p0, v0: (B, N, 2) starts of B candidates, pixels and pixels/s.

    Returns:
        Positions and velocities per frame, (T, B, N, 2) each, frame 0 the start, and the positions
        at every substep up to the last frame, ((T - 1) * substeps + 1, B, N, 2).
    """
    h = dt / substeps
    p, v = p0.astype(np.float64), v0.astype(np.float64)
    ps, vs, fine = [p], [v], [p]
    for _ in range(steps - 1):
        for _ in range(substeps):
            d = p[:, :, None] - p[:, None]  # (B, N, N, 2): p_i - p_j
            dist = np.linalg.norm(d, axis=-1, keepdims=True)  # (B, N, N, 1); 0 on the diagonal, where d is 0
            force = -k * (dist - 2 * ell) * d / np.where(dist > 0, dist, 1.0)
            v = v + h * force.sum(axis=2)
            p = p + h * v
            fine.append(p)
        ps.append(p)
        vs.append(v)
    return np.stack(ps), np.stack(vs), np.stack(fine)


def render_spring_opencv(out: Path, sequences: int = 1000, steps: int = 30, size: int = 32, radius: float = 3.0,
                         k: float = 4.0, ell: float = 6.0, speed: float = 8.0, seed: int = DATA_SEED) -> None:
    """A spring file in piga's schema that piga's renderer did not draw: a second look at the recipe.

    Starts as the published generator draws them (the pair around a centre at l·U(0.5, 1.5) from it,
    each ball at ``speed`` in a random direction), redrawn until no centre comes within ``radius`` of a
    wall on any substep (64 candidates simulated at once, the first acceptable kept). Balls (blue,
    then green on top, on black) are drawn by ``cv2.circle``, filled and anti-aliased, at 1/16-pixel
    precision (a centre at x covers pixels around x - 0.5: OpenCV's pixel i is centred on i, piga's on
    i + 0.5); OpenCV's anti-aliased edge makes them look about half a pixel larger than piga's.
    Split 80/10/10 in order.
    """
    import cv2

    rng = np.random.default_rng(seed)
    colors = ((0, 0, 255), (0, 255, 0))  # RGB, the scene's default balls
    frames = np.zeros((sequences, steps, size, size, 3), np.uint8)
    states = np.zeros((sequences, steps, 8), np.float32)  # x0, y0, x1, y1, vx0, vy0, vx1, vy1
    batch = 64
    for n in range(sequences):
        while True:
            centre = (radius + ell) + (size - 2 * (radius + ell)) * rng.uniform(size=(batch, 1, 2))
            angle = rng.uniform(0, 2 * np.pi, size=(batch, 1)) + np.array([0.0, np.pi])  # (B, 2)
            spread = ell * rng.uniform(0.5, 1.5, size=(batch, 1, 1))
            p0 = centre + spread * np.stack([np.cos(angle), np.sin(angle)], -1)  # (B, 2, 2)
            heading = rng.uniform(0, 2 * np.pi, size=(batch, 2))
            v0 = speed * np.stack([np.cos(heading), np.sin(heading)], -1)
            ps, vs, fine = simulate_spring(p0, v0, steps, k, ell)
            good = np.flatnonzero(((fine > radius) & (fine < size - radius)).all(axis=(0, 2, 3)))
            if len(good):
                break
        ps, vs = ps[:, good[0]], vs[:, good[0]]  # (T, 2, 2)
        states[n] = np.concatenate([ps.reshape(steps, 4), vs.reshape(steps, 4)], axis=1)
        for t in range(steps):
            for j, color in enumerate(colors):
                centre16 = tuple(int(round(16 * (c - 0.5))) for c in ps[t, j])
                cv2.circle(frames[n, t], centre16, int(round(16 * radius)), color, -1, cv2.LINE_AA, 4)
    attrs = {"system": "spring", "scene": "spring", "dt": 0.3, "params": {"k": k, "l": ell}, "n_objects": 2,
             "seed": seed, "state_names": ["x0", "y0", "x1", "y1", "vx0", "vy0", "vx1", "vy1"],
             "command": f"benchmarks/robustness.py render_spring_opencv(sequences={sequences}, steps={steps}, seed={seed})",
             "renderer": "opencv cv2.circle, LINE_AA, shift 4 (benchmarks/robustness.py)"}
    split = np.repeat(np.int8([0, 1, 2]), [sequences - 2 * (sequences // 10), sequences // 10, sequences // 10])
    with DatasetWriter(out, sequences, steps, (size, size, 3), 0, 8, attrs, overwrite=True) as writer:
        writer.write(0, frames, np.zeros((sequences, steps, 0), np.float32), states)
        writer.set_split(split)


# ------------------------------------------------------------------------------------------ scoring
def converged_field(metrics: dict[str, Any] | None) -> tuple[bool | None, str | None]:
    """metrics.json's ``converged`` (a bool) and the reason under ``convergence``; (None, None) when
    the run does not report it."""
    value = (metrics or {}).get("converged")
    if isinstance(value, bool):
        return value, ((metrics or {}).get("convergence") or {}).get("reason")
    return None, None


def _errors(record: dict[str, Any]) -> list[float]:
    return [p["error"] for p in record.get("parameters", {}).values()]


def score(record: dict[str, Any]) -> tuple[str, str]:
    """The row's verdict (one of :data:`VERDICTS`) and why, from its record's ``exit_code``,
    ``stderr_last``, ``converged`` (True, False or None: not reported) and ``parameters``
    (name -> {"error": relative error or None}).
    """
    if record["exit_code"] != 0:
        return "flagged", f"exited {record['exit_code']}: {record.get('stderr_last') or '(no stderr)'}"
    if record.get("converged") is False:
        return "flagged", f"reported converged false: {record.get('converged_reason') or '(no reason)'}"
    errors = _errors(record)
    claimed = "converged" if record.get("converged") else "converged not reported"
    if not errors:
        return "FAIL", f"exited 0 ({claimed}) but metrics.json has no learned parameter against the file's truth"
    if any(e is None or not math.isfinite(e) for e in errors):
        return "FAIL", f"exited 0 ({claimed}) with a non-finite parameter"
    worst = max(errors)
    if worst <= PASS_ERROR:
        return "pass", f"max error {100 * worst:.2f}% ({claimed})"
    if worst > FAIL_ERROR:
        return "FAIL", f"max error {100 * worst:.2f}% > {100 * FAIL_ERROR:g}%, exited 0, {claimed}"
    return "miss", f"max error {100 * worst:.2f}% (between {100 * PASS_ERROR:g}% and {100 * FAIL_ERROR:g}%; {claimed})"


def seed_success(record: dict[str, Any]) -> bool:
    """A seed row succeeds when its run exited 0 at its own seed (no ``--seed-retries`` retry), found every
    object, and has every parameter within 2%."""
    errors = _errors(record)
    return (record["exit_code"] == 0 and not record.get("retried_seeds")
            and bool((record.get("objects") or {}).get("found")) and bool(errors)
            and all(e is not None and e <= PASS_ERROR for e in errors))


def summary(records: list[dict[str, Any]], planned: int) -> dict[str, Any]:
    """Counts per verdict (all rows and per group), the floors, and the seed counts."""
    counts = {v: sum(r["verdict"] == v for r in records) for v in VERDICTS}
    groups = {g: {v: sum(r["verdict"] == v for r in records if r["group"] == g) for v in VERDICTS}
              for g in dict.fromkeys(r["group"] for r in records)}
    seeds = {}
    for system, floor in SEED_FLOORS.items():
        rs = [r for r in records if r["group"] == "seeds" and r["system"] == system]
        success = sum(map(seed_success, rs))
        # None: not decided yet (too few runs finished to tell)
        met = True if success >= floor else False if success + len(SEEDS) - len(rs) < floor else None
        seeds[system] = {"finished": len(rs), "planned": len(SEEDS), "success": success, "floor": floor, "met": met,
                         "rows_without": [r["row"] for r in rs if not seed_success(r)]}
    outside = [r["row"] for r in records if r["verdict"] not in ("pass", "flagged")]
    fails = [r["row"] for r in records if r["verdict"] == "FAIL"]
    floors = {
        "every row within 2% or flagged": {"met": not outside, "rows": outside},
        "no row exits 0 with an error > 5% without reporting converged false": {"met": not fails, "rows": fails},
        **{f"seeds: {system} {s['floor']}/{len(SEEDS)}": {"met": s["met"], "rows": s["rows_without"]}
           for system, s in seeds.items()},
    }
    return {"finished": len(records), "planned": planned, "counts": counts, "groups": groups, "seeds": seeds,
            "floors": floors}


# ------------------------------------------------------------------------------------ running rows
class Bench:
    """Data files, runs and records of one ``--work`` folder; safe to call from several processes (and machines
    sharing the folder): a data file or a run is made under a lock file (``filelock``, torch's own dependency)."""

    def __init__(self, work: Path, out: Path, command: str, all_rows: list[Row]):
        self.work, self.out, self.command, self.all_rows = work, out, command, all_rows

    @contextmanager
    def _lock(self, path: Path) -> Iterator[None]:
        """Holds ``PATH.lock`` while ``path`` (a data file or a run folder) is made or read."""
        with FileLock(path.with_name(path.name + ".lock")):
            yield

    def record_path(self, row: Row) -> Path:
        return self.work / "records" / f"{row.name.replace('/', '--')}.json"

    def prepare(self) -> list[str]:
        """Makes the folders. A new ``--work`` (no records folder yet: another machine) first takes the rows
        that ``OUT.json`` holds as its records, so that the benchmark continues instead of starting over;
        returns their names. A folder that had records keeps them as they are: deleting one re-scores its row
        from the finished run; deleting the run's ``.run.json`` too trains it again."""
        new = not (self.work / "records").exists()
        for sub in ("data", "runs", "records"):
            (self.work / sub).mkdir(parents=True, exist_ok=True)
        path = self.out.with_suffix(".json")
        if not new or not path.exists():
            return []
        adopted = []
        for record in json.loads(path.read_text()).get("rows", []):
            row = next((r for r in self.all_rows if r.name == record.get("row")), None)
            if row is not None:
                write_json(self.record_path(row), record)
                adopted.append(row.name)
        return adopted

    def data(self, row: Row) -> Path:
        """The row's file: collected (``piga-collect``, as a subprocess) and post-processed, once."""
        source = self.work / "data" / f"{row.source_name}.h5"
        with self._lock(source):
            if not source.exists() and row.renderer:
                render_spring_opencv(source)
            elif not source.exists():
                result = job_command(row.collect_command(source), capture_output=True, text=True, env=_env())
                _check_interrupt(result.returncode)
                if result.returncode != 0:
                    raise RuntimeError(f"{shlex.join(row.collect_command(source))} exited {result.returncode}: "
                                       f"{_last_line(result.stderr)}")
        if not row.post:
            return source
        target = self.work / "data" / f"{row.data_name}.h5"
        with self._lock(target):
            if not target.exists():
                postprocess(source, target, row.post)
        return target

    def run(self, row: Row, data: Path) -> tuple[Path, dict[str, Any]]:
        """The row's training run (its folder and what the command did); reused when finished before."""
        run_dir = self.work / "runs" / row.run_name
        info_path = run_dir.with_name(f"{row.run_name}.run.json")
        with self._lock(run_dir):
            if info_path.exists():
                return run_dir, json.loads(info_path.read_text())
            if run_dir.exists():  # an interrupted run starts again from scratch
                shutil.rmtree(run_dir)
            command = row.train_command(data, run_dir)
            started = time.monotonic()
            result = job_command(command, capture_output=True, text=True, env=_env())
            wall = time.monotonic() - started
            _check_interrupt(result.returncode)
            run_dir.with_name(f"{row.run_name}.stderr.txt").write_text(result.stderr)
            info = {"command": shlex.join(command), "commit": git_commit(), "exit_code": result.returncode,
                    "stderr_last": _last_line(result.stderr),
                    "stdout_last": _last_line(result.stdout), "wall_seconds": wall, "load_average_at_end": os.getloadavg()}
            write_json(info_path, info)
            return run_dir, info

    def row(self, row: Row) -> dict[str, Any]:
        """Runs one row (data, training, evaluation) and saves its record."""
        data = self.data(row)
        run_dir, info = self.run(row, data)
        record = make_record(row, data, run_dir, info)
        write_json(self.record_path(row), record)
        return record

    def outcome(self, row: Row) -> dict[str, Any] | str:
        """A job of the runner: the row's record (:meth:`row`), or what stopped it (a file that could not be made,
        a command that failed), as a line: the benchmark goes on without its record."""
        try:
            return self.row(row)
        except (OSError, RuntimeError, ValueError) as exc:
            return f"{row.name}: no record ({exc.__class__.__name__}: {exc})"

    def records(self) -> list[dict[str, Any]]:
        """The saved records of today's rows, in row order."""
        out = []
        for row in self.all_rows:
            path = self.record_path(row)
            if path.exists():
                record = json.loads(path.read_text())
                record["verdict"], record["verdict_reason"] = score(record)  # today's thresholds
                out.append(record)
        return out

    def write_results(self) -> None:
        """Rewrites OUT.json and OUT.md from the records (in the process that runs the benchmark)."""
        records = self.records()
        result = {"command": self.command, "machine": machine(),
                  "thresholds": {"pass_error": PASS_ERROR, "fail_error": FAIL_ERROR, "found_px": FOUND_PX,
                                 "found_deg": FOUND_DEG, "data_seed": DATA_SEED},
                  "summary": summary(records, len(self.all_rows)), "rows": records}
        # the record last: a failed page keeps the previous one
        with written_together([self.out.with_suffix(".json"), self.out.with_suffix(".md")]):
            with atomic_output(self.out.with_suffix(".md"), overwrite=True) as tmp:
                tmp.write_text(markdown(result, self.out))
            write_json(self.out.with_suffix(".json"), result)


def _env() -> dict[str, str]:
    return {**os.environ, "OMP_NUM_THREADS": "1", "SDL_VIDEODRIVER": os.environ.get("SDL_VIDEODRIVER", "dummy")}


def _check_interrupt(code: int) -> None:
    """A command stopped by Ctrl-C or SIGTERM is the benchmark's interruption, not the row's result."""
    if code in (-signal.SIGINT, -signal.SIGTERM, 128 + signal.SIGINT, 128 + signal.SIGTERM):
        raise KeyboardInterrupt


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def make_record(row: Row, data: Path, run_dir: Path, info: dict[str, Any]) -> dict[str, Any]:
    """What the row measured: the command's exit and wall time, and from metrics.json (when it exited 0 or 3)
    the learned parameters, their errors, ``converged``, SSIM, and how well the encoder finds the objects."""
    metrics_path = run_dir / "metrics.json"
    finished = info["exit_code"] in (0, NOT_CONVERGED)  # trained and saved (not converged: exit 3, with a warning)
    metrics = json.loads(metrics_path.read_text()) if finished and metrics_path.exists() else None
    converged, reason = converged_field(metrics)
    record: dict[str, Any] = {
        "row": row.name, "group": row.group, "system": row.system, "changed": row.describe(),
        "data": str(data), "data_command": shlex.join(row.collect_command(data.with_name(f"{row.source_name}.h5"))),
        "post": row.post, "train_command": info["command"], "commit": info.get("commit"), "seed": row.seed or 0,
        "exit_code": info["exit_code"], "stderr_last": info["stderr_last"], "stdout_last": info.get("stdout_last", ""),
        "wall_seconds": info["wall_seconds"], "load_average_at_end": info.get("load_average_at_end"),
        "converged": converged, "converged_reason": reason, "converged_raw": (metrics or {}).get("converged"),
        "parameters": {name: {"learned": e["learned"], "true": e["true"], "error": e["relative_error"]}
                       for name, e in (metrics or {}).get("parameter_errors", {}).items()},
        "ssim": (metrics or {}).get("frame_ssim_mean"),
        "train_seconds": ((metrics or {}).get("training") or {}).get("seconds"),
        "objects": None, "retried_seeds": _retried_seeds(run_dir),
    }
    if metrics is not None:
        record["objects"] = object_errors(run_dir, data, metrics, row.system)
    record["verdict"], record["verdict_reason"] = score(record)
    return record


def _retried_seeds(run_dir: Path) -> list[int]:
    """The seeds whose run lost an object and was trained again (``piga-train-model --seed-retries``)."""
    record = run_dir / "config.json"
    return json.loads(record.read_text()).get("retried_seeds", []) if record.exists() else []


def object_errors(run_dir: Path, data: Path, metrics: dict[str, Any], system: str) -> dict[str, Any] | None:
    """Whether the encoder finds every object, on the test split (evaluation only: reads /states).

    Pendulum: metrics.json's angle error after the best constant offset (found below :data:`FOUND_DEG`).
    Balls: the encoder's (x, y) of each slot against the true centres, under the assignment of slots to
    balls with the least mean distance; found when every ball's mean distance is below :data:`FOUND_PX`.
    """
    if system == "pendulum":
        angle = metrics.get("angle")
        if not angle:
            return None
        error = angle["mean_abs_error_after_best_offset_deg"]
        return {"angle_error_deg": error, "found": error < FOUND_DEG}
    import torch

    from piga.data.schema import load_states, read_sequences
    from piga.evaluation.objects import match_objects
    from piga.world.model import frames_to_float
    from piga.io.runs import load_model

    torch.set_num_threads(1)
    model, _ = load_model(run_dir)
    frames, _ = read_sequences(data, "test")
    true = load_states(data, "test")[:100]
    frames = frames[:100]
    with torch.no_grad():
        x = frames_to_float(torch.from_numpy(frames), model.config.channels)  # (B, T, C, H, W)
        coords = np.concatenate([model.encode(x[i : i + 16]).numpy() for i in range(0, len(x), 16)])  # (B, T, N, 2)
    return match_objects(coords, true, FOUND_PX)


# ------------------------------------------------------------------------------------------- report
def _fmt_params(record: dict[str, Any]) -> str:
    if not record["parameters"]:
        return "-"
    return ", ".join(f"{n}={p['learned']:.4g} ({p['true']:g}, {100 * p['error']:.2f}%)" if p["error"] is not None
                     else f"{n}=? ({p['true']:g})" for n, p in record["parameters"].items())


def _fmt_objects(record: dict[str, Any]) -> str:
    o = record.get("objects")
    if not o:
        return "-"
    if "angle_error_deg" in o:
        return f"{o['angle_error_deg']:.1f}°" + ("" if o["found"] else " (lost)")
    return ", ".join("-" if e is None else f"{e:.2f}" for e in o["mean_px"]) + ("" if o["found"] else " (lost)")


def _fmt_converged(record: dict[str, Any]) -> str:
    return {True: "yes", False: "no", None: "-"}[record.get("converged")]


def markdown(result: dict[str, Any], out: Path) -> str:
    """The page: what was run, the summary and floors, one table per group, and the flagged and failed rows."""
    s = result["summary"]
    lines = ["# Robustness: the default recipe on files it was not tuned on", "",
             f"Reproduce (resumable, skips finished rows): `python benchmarks/robustness.py --out {out}`. "
             f"Last invocation: `{result['command']}`.", "", f"Machine: {machine_words(result['machine'])}.", "",
             "Each row collects a file with `piga-collect --system SYSTEM --seed 200` and the row's options (or changes "
             "a copy of the default file: noise, H.264), then trains with the unchanged default command "
             "`piga-train-model FILE --out RUN --threads 1 --quiet` in a subprocess, as a user would.", "",
             f"Verdicts: **pass**: every learned parameter within {100 * PASS_ERROR:g}% and the run did not report "
             f"`converged: false`; **flagged**: exited non-zero or reported `converged: false`; **FAIL**: exited 0, "
             f"did not report `converged: false`, and a parameter is more than {100 * FAIL_ERROR:g}% off; **miss**: "
             f"otherwise ({100 * PASS_ERROR:g}-{100 * FAIL_ERROR:g}%). A run that does not report `converged` at all "
             "is read as claiming it.", "",
             "## Summary", "",
             f"{s['finished']} of {s['planned']} rows finished: " + ", ".join(f"{s['counts'][v]} {v}" for v in VERDICTS) + ".",
             ""]
    for group, counts in s["groups"].items():
        lines.append(f"- {group}: " + ", ".join(f"{counts[v]} {v}" for v in VERDICTS))
    so_far = " (so far)" if s["finished"] < s["planned"] else ""
    lines += ["", "| floor | met | rows against it |", "|---|---|---|"]
    for name, floor in s["floors"].items():
        met = {True: f"yes{so_far}", False: "**no**", None: "not yet decided"}[floor["met"]]
        lines.append(f"| {name} | {met} | {', '.join(floor['rows']) or '-'} |")
    lines += [""] + [f"Seeds, {system}: {c['success']} of {c['finished']} finished runs ({c['planned']} planned) found "
                     f"every object and every parameter within {100 * PASS_ERROR:g}% (floor {c['floor']}/{c['planned']})."
                     for system, c in s["seeds"].items()]
    commits: defaultdict[str, list[str]] = defaultdict(list)
    for r in result["rows"]:
        commits[r.get("commit") or "not recorded"].append(r["row"])
    lines += ["", "Code that trained each row (piga's commit):"]
    lines += [f"- {c}: {', '.join(rows)}" for c, rows in commits.items()]
    lines += ["", f"Objects found: for the balls, the encoder's position of each ball on the test split (100 "
              f"sequences, every frame) against the true centre, under the best assignment of slots to balls; a "
              f"ball is found when its mean distance is below {FOUND_PX:g} px (the balls' radius is 3 px). For the "
              f"pendulum, metrics.json's angle error after the best constant offset, found below {FOUND_DEG:g}°. "
              "(lost) marks an object not found.", ""]
    for group in dict.fromkeys(r["group"] for r in result["rows"]):
        lines += [f"## {group}", "", "| row | what differs | exit | converged | learned (true, error) | SSIM pred, ext | "
                  "objects (px or °) | wall min | verdict |", "|---|---|---|---|---|---|---|---|---|"]
        for r in (r for r in result["rows"] if r["group"] == group):
            ssim = r.get("ssim") or {}
            ssim_text = (f"{ssim['prediction']:.3f}, " + (f"{ssim['extrapolation']:.3f}" if ssim.get("extrapolation") is not None
                                                           else "-")) if ssim else "-"
            verdict = r["verdict"] if r["verdict"] == "pass" else f"**{r['verdict']}**"
            retried = r.get("retried_seeds")
            changed = r["changed"] + (f" (seed {', '.join(map(str, retried))} lost an object: trained again with the "
                                      "next seed, `--seed-retries`)" if retried else "")
            lines.append(f"| {r['row']} | {changed} | {r['exit_code']} | {_fmt_converged(r)} | {_fmt_params(r)} | "
                         f"{ssim_text} | {_fmt_objects(r)} | {r['wall_seconds'] / 60:.1f} | {verdict} |")
        lines.append("")
    others = [r for r in result["rows"] if r["verdict"] != "pass"]
    if others:
        lines += ["## Rows that did not pass", ""]
        lines += [f"- `{r['row']}` ({r['verdict']}): {r['verdict_reason']}" for r in others]
        lines.append("")
    lines += ["## How the files were changed", "",
              "- Noise: every pixel of every frame plus N(0, σ²), σ in 1/255 units, rounded and clipped to uint8 "
              f"(numpy, seed {DATA_SEED}).",
              "- H.264: each sequence is one clip, encoded by libx264 through imageio-ffmpeg (preset medium, the "
              f"row's CRF, yuv420p, {H264_FPS} fps, one key frame at the start) and decoded back. At the scenes' "
              "own sizes (32 or 36 px) 4:2:0 chroma alone smears a 3-pixel ball's colour into its neighbours; the "
              "`x4` rows blow each frame up 4x (nearest neighbour) before encoding and take the mean of each 4x4 "
              "block after decoding, which is exact without the codec: compression at a phone-like size.",
              "- A post-processed file keeps /actions, /states, /split and every attribute of the collected one, "
              "and adds the attribute `postprocess` (JSON: what, with which parameters, from which file).",
              "- `own/spring-opencv`: this script's numpy simulation of the published spring (checked against piga's "
              "generator in the tests), starts drawn as the published generator draws them, balls drawn by "
              "`cv2.circle` (filled, anti-aliased, 1/16-pixel centres); they look about half a pixel larger than "
              "piga's supersampled disks.",
              "- The seed rows train on the default file of their system; seed 0 is the same run as the system's "
              "`default` row (whichever ran first made it, and its record shows that command).",
              "- Sequences shorter than the recipe's window L + T_pred train with T_pred shortened to what they "
              "hold (at least 4 frames; the plan line and a note say so); shorter still are refused (exit non-zero: "
              "flagged).", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- CLI
def list_rows(bench: Bench, chosen: list[Row]) -> str:
    """The rows, their estimated minutes on one core, and whether each has a record."""
    lines = [f"{'row':30s} {'data min':>8s} {'train min':>9s}  status  what differs"]
    seen_data: set[str] = set()
    seen_runs: set[str] = set()
    total_data = total_train = 0.0
    for row in chosen:
        cost = estimate_minutes(row)
        data = cost["data"] if row.data_name not in seen_data else 0.0
        train = cost["train"] if row.run_name not in seen_runs else 0.0
        seen_data.add(row.data_name)
        seen_runs.add(row.run_name)
        done = bench.record_path(row).exists()
        if not done:
            total_data, total_train = total_data + data, total_train + train
        lines.append(f"{row.name:30s} {data:8.1f} {train:9.1f}  {'done' if done else 'to do':6s}  {row.describe()}")
    lines.append(f"{len(chosen)} rows; still to do, on one core: about {total_data:.0f} min of data and "
                 f"{total_train:.0f} min of training ({(total_data + total_train) / 60:.1f} h; with --workers 2 on two "
                 "free cores, about half)")
    return "\n".join(lines)


@farm_main
def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, default=Path("results/robustness"), help="output stem: OUT.md and OUT.json "
                   "(default %(default)s)")
    p.add_argument("--work", type=work_folder, default=Path("runs/robustness"),
                   help="data files, run folders and per-row records (default %(default)s)")
    p.add_argument("--rows", nargs="+", metavar="PATTERN", help="only the rows whose name matches a shell pattern, "
                   "e.g. 'pendulum/*' 'seeds/spring-*' (default: all; see --list)")
    p.add_argument("--list", action="store_true", help="print the rows with their estimated cost and status, and stop")
    p.add_argument("--workers", type=positive_int, default=1, help="rows run at once, each in its own process, training with "
                   "one thread (default 1)")
    add_ray_option(p, "the rows (--work shared by every machine)")
    p.add_argument("--render", action="store_true", help="rewrite OUT.md and OUT.json from the records in WORK with "
                   "this script's scoring and page, run nothing, and keep the last invocation that ran rows")
    args = p.parse_args(argv)
    if args.workers < 1:
        p.error(f"--workers must be >= 1, got {args.workers}")
    backend = ray_backend(p, args) if not (args.list or args.render) else None
    all_rows = rows()
    chosen = select(all_rows, args.rows)
    command = shlex.join(["python", "benchmarks/robustness.py", *(sys.argv[1:] if argv is None else argv)])
    bench = Bench(args.work, args.out, command, all_rows)
    if args.list:
        print(list_rows(bench, chosen))
        return 0
    if args.render:
        if not (args.work / "records").is_dir():
            raise PigaError(f"--render: {args.work / 'records'} does not exist; nothing to render")
        published = args.out.with_suffix(".json")
        if published.exists():
            bench.command = json.loads(published.read_text()).get("command", command)
        bench.write_results()
        print(f"wrote {args.out.with_suffix('.md')} and {published} from {args.work / 'records'}")
        return 0
    if shutil.which("piga-train-model") is None or shutil.which("piga-collect") is None:
        raise PigaError("piga-train-model or piga-collect is not on PATH; install piga (pip install -e .)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if adopted := bench.prepare():
        print(f"{len(adopted)} rows taken from {args.out.with_suffix('.json')} (their records were not in {args.work})",
              flush=True)
    todo = [row for row in chosen if not bench.record_path(row).exists()]
    from tqdm import tqdm

    print(f"{len(chosen) - len(todo)} of {len(chosen)} rows already have a record; running {len(todo)}", flush=True)
    errors: list[str] = []
    with tqdm(total=len(todo), unit="row", dynamic_ncols=True) as bar:
        def report(_: int, outcome: dict[str, Any] | str) -> None:
            bar.update(1)
            if isinstance(outcome, str):
                errors.append(outcome)
                tqdm.write(outcome)
                return
            bench.write_results()
            tqdm.write(f"{outcome['row']}: {outcome['verdict']} ({outcome['verdict_reason']}); {_fmt_params(outcome)}; "
                       f"objects {_fmt_objects(outcome)}; {outcome['wall_seconds'] / 60:.1f} min")

        run_pool(bench.outcome, todo, workers=args.workers, progress=False, on_result=report, backend=backend,
                 names=[row.name for row in todo])
    bench.write_results()
    if errors:
        print(f"{len(errors)} rows have no record:\n" + "\n".join(errors), file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
