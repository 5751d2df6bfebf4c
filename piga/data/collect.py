"""Collecting pixel-pendulum videos with random actions into piga's HDF5 schema.

Determinism: sequence n draws its reset seed and its actions from ``SeedSequence(seed).spawn(N)[n]``.
The arrays therefore depend only on ``seed`` and the settings, not on the number of workers or on
which worker ran the sequence. Workers are Gymnasium vector envs: ``AsyncVectorEnv``, or
``SyncVectorEnv`` for one worker.

Sequence n holds frames x_0..x_{T-1}, where x_0 is the frame after reset. The actions are
u_0..u_{T-1} ~ U(-2, 2) (U(-1, 1) for the DMC pendulum, :mod:`envs.dmc`), and u_t is applied after x_t.
All T actions are applied, so each stored action really acted, even though the frame after the last
one is not stored. ``/rewards[n, t]`` is Gymnasium's reward for u_t (computed from the state of x_t),
for reward-based baselines; piga's own training never reads it.

Unmodelled effects (``env.effects``, :mod:`envs.effects`) change the frames and states only. The
stored actions are the commanded u, and the effects are recorded in the attrs ``effects`` (a JSON
object, name -> value, empty without effects) and ``env_config``.
"""

from __future__ import annotations

import contextlib
import functools
import math
import multiprocessing
import shlex
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import gymnasium as gym
import numpy as np

from envs.dmc import DMCPendulumConfig, make_dmc_pendulum
from envs.fields import counted, number_text
from envs.pendulum import MAX_ACTION, PENDULUM_DT, PixelPendulumConfig, make_pixel_pendulum
from piga.io.atomic import check_writable_target
from piga.io.progress import progress_bar
from piga.data.schema import MAX_SEED, SPLITS, BlankFramesError, DatasetWriter, StillFramesError, check_data_disk
from piga.io.worker_signals import die_with_parent, quiet_worker_signals
from piga.io.choices import check_types

#: Ranges of the paper's pendulum data: θ ~ U(-π, π), θ̇ ~ U(-6, 6).
PAPER_MAX_SPEED = 6.0


@dataclass(frozen=True)
class CollectConfig:
    """What ``piga-collect`` gathers. The defaults take about a minute on 2 cores."""

    sequences: int = 500
    """N, the number of sequences."""
    steps: int = 40
    """T, frames per sequence (the pendulum model needs at least L + T_pred = 14)."""
    env: PixelPendulumConfig | DMCPendulumConfig = field(default_factory=PixelPendulumConfig)
    """The environment: Gymnasium's pixel pendulum, or dm_control's (:class:`DMCPendulumConfig`). Reset ranges are Gymnasium's, θ ~ U(-π, π) and θ̇ ~ U(-1, 1): the paper's
    θ̇ ~ U(-6, 6) makes Gymnasium's ±8 speed clip act on ~2% of steps, which biases a least-squares
    actuation gain by about −2% (the clip is not in the model; results/speed_clip_bias.md). The
    'paper' preset restores ±6."""
    seed: int = 0
    """Root seed of every random draw."""
    workers: int = 2
    """Parallel environment processes (1 runs in this process)."""
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)
    """Train/valid/test, as fractions summing to 1 or as counts summing to ``sequences``."""
    batch: int = 64
    """Sequences gathered between writes to disk (bounds memory)."""

    def __post_init__(self) -> None:
        check_types(self)  # a number given as text fails here, naming the field, not at a comparison below
        if not isinstance(self.env, (PixelPendulumConfig, DMCPendulumConfig)):
            raise TypeError(f"CollectConfig.env must be a PixelPendulumConfig or a DMCPendulumConfig, got {self.env!r}")
        if getattr(self.env, "color", "gray") != "gray":
            raise ValueError("piga's data files hold gray frames; the DMC pendulum's color='rgb' is a baseline's view "
                             "(piga-baseline ddpg --view drqv2)")
        check_collect_sizes(self.sequences, self.steps, self.workers, self.seed, self.batch, self.split, type(self).__name__)
        effects = dict(getattr(self.env, "effects", ()))
        if effects.get("delay", 0) >= self.steps - 1:
            raise ValueError(f"effect delay={effects['delay']:g} steps is not shorter than a sequence's {self.steps - 1} "
                             "actions: no action would reach a frame; lower it or raise --steps")
        if effects.get("frame_delay", 0) >= self.steps - 1:
            raise ValueError(f"effect frame_delay={effects['frame_delay']:g} steps is not shorter than a sequence's "
                             f"{self.steps - 1} steps (between its {self.steps} frames): they would all show the reset; "
                             "lower it or raise --steps")
        # The action after frame 0 moves the state of step delay + 1, which the camera shows frame_delay steps later:
        # each alone can pass its check while together they push every action past the last frame.
        delay, frame_delay = effects.get("delay", 0), effects.get("frame_delay", 0)
        if delay and frame_delay and delay + frame_delay >= self.steps - 1:
            raise ValueError(f"effects delay={delay:g} and frame_delay={frame_delay:g} add up to {delay + frame_delay:g} "
                             f"steps, not shorter than a sequence's {self.steps - 1} steps (between its {self.steps} "
                             "frames): no action would reach a frame; lower one of them or raise --steps")


def check_collect_sizes(sequences: int, steps: int, workers: int, seed: int, batch: int,
                        split: tuple[float, float, float], owner: str = "CollectConfig") -> None:
    """ValueError unless the sizes of a collection make sense (shared by the pendulum's and the scenes' configs);
    the message names the field as ``owner.field`` (the command line shows it as its flag)."""
    if sequences < 1:
        raise ValueError(f"{owner}.sequences must be >= 1, got {sequences}")
    if steps < 2:
        raise ValueError(f"{owner}.steps must be >= 2 (a video needs two frames), got {steps}")
    if workers < 1:
        raise ValueError(f"{owner}.workers must be >= 1, got {workers}")
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"{owner}.seed must be >= 0 and <= {MAX_SEED} (2^63 - 1, the largest a data file stores), got {seed}")
    if batch < 1:
        raise ValueError(f"{owner}.batch must be >= 1, got {batch}")
    split_counts(sequences, split)  # validates


def split_counts(n: int, split: Sequence[float]) -> tuple[int, int, int]:
    """Train/valid/test counts from fractions (sum 1) or counts (sum n)."""
    shown = f"({', '.join(map(number_text, split))})"  # as its errors write it: (2, 1, 0), not (2.0, 1.0, 0.0)
    if len(split) != 3 or any(not math.isfinite(x) or x < 0 for x in split):
        raise ValueError(f"split needs three non-negative numbers (train, valid, test), got {shown}")
    if all(float(x).is_integer() for x in split) and sum(split) == n and sum(split) != 1:
        train, valid, test = (int(x) for x in split)
    elif abs(sum(split) - 1.0) < 1e-6:
        if split[0] == 0:  # (else the rounding of valid and test below could leave one sequence to train on)
            raise ValueError(f"split {shown} gives the training split no share of the {counted(n, 'sequence')}")
        valid, test = round(split[1] * n), round(split[2] * n)
        train = n - valid - test
    elif sum(split) == n:  # they add up, but a sequence is not split in parts
        raise ValueError(f"split {shown} sums to {n} as counts must, but the counts must be whole numbers")
    else:
        raise ValueError(f"split {shown} must be fractions summing to 1 or counts summing to {n}")
    if train < 1:
        raise ValueError(f"split {shown} leaves no training sequence out of {n}")
    return train, valid, test


def empty_split_warning(split: Sequence[float], counts: dict[str, int], frames: int | None = None,
                        named: str | None = None) -> str | None:
    """A warning when the split asked for valid or test sequences and their share rounded to none, else None.
    ``frames``: an imported recording's frames, which piga-import cuts into sequences of --steps frames: the advice is
    then a shorter --steps (or a longer recording), as it has no count of sequences to raise. ``named``: what the
    split is called (a preset's), where not "the split" with its values."""
    empty = [name for name, share in zip(("valid", "test"), split[1:]) if share > 0 and not counts.get(name)]
    if not empty:
        return None
    n = sum(counts.values())
    wanted = [share > 0 for share in split[1:]]  # (valid, test)
    fewest = fewest_filling(split)
    if frames is not None:  # the sequences are the recording cut into --steps frames each
        steps = frames // fewest if fewest is not None else 0
        advice = (f"cut the recording into {fewest} sequences or more with --steps {steps} or fewer, or import a longer one"
                  if steps >= 2 else "import a longer recording")
    else:
        advice = f"give {fewest} sequences or more" if fewest is not None else "give more sequences"
    if n > sum(wanted):  # counts that keep a training sequence and give each asked-for split one
        advice += f", or counts such as --split {n - sum(wanted)},{int(wanted[0])},{int(wanted[1])}"
    # what each empty split costs: piga-train-model measures on the test split, the PlaNet-style baseline validates on
    # the valid split; each falls back to the train split, which is not held out
    cost = {"test": "piga-train-model's metrics", "valid": "the PlaNet-style baseline's validation"}
    whose = " and ".join(cost[name] for name in empty)
    named = named or f"the split {','.join(f'{x:g}' for x in split)}"
    return (f"{named} of {counted(n, 'sequence')} leaves {' and '.join(empty)} empty, so "
            f"{whose} will come from the train split, which is not held out ({advice})")


def fewest_filling(split: Sequence[float]) -> int | None:
    """The fewest sequences whose split by these fractions, rounded as :func:`split_counts` rounds them, gives each
    of valid and test with a share at least one sequence (None if a short search past the first candidate finds none,
    as for a training share too small to keep a sequence)."""
    def fills(n: int) -> bool:
        try:
            counts = split_counts(n, split)
        except ValueError:  # (too few to keep a training sequence)
            return False
        return all(count > 0 for share, count in zip(split[1:], counts[1:]) if share > 0)

    # round(share * n) is 0 up to n = 0.5 / share, so no smaller count can fill a split: start just below that
    start = max(1, *(math.floor(0.5 / share) for share in split[1:] if share > 0))
    return next((n for n in range(start, start + 1000) if fills(n)), None)


#: Gymnasium's Pendulum-v1 draws its rod in this colour on a white background.
ROD_RGB = (204, 77, 77)


def rod_contrast() -> int:
    """The gray levels between the pixel pendulum's rod and its white background, in piga's gray frames (the rod's
    colour through :data:`piga.data.scene.GRAY_WEIGHTS`, truncated as the frames are: 255 - 103 = 152)."""
    from piga.data.scene import GRAY_WEIGHTS

    return 255 - int(np.dot(ROD_RGB, GRAY_WEIGHTS))


def buried_noise_warning(env: PixelPendulumConfig | DMCPendulumConfig) -> str | None:
    """A warning where ``--effect noise`` buries the pendulum, else None. Its standard deviation at or above the
    rod's contrast with the background (:func:`rod_contrast`) makes a rod pixel differ from a background pixel by
    less than the noise of either, and clips about half of all pixels to 0 or 255 (the background is 255 itself;
    noise=1000 clipped 90%): the frames are mostly noise, with the pendulum barely in them. A warning, not a refusal:
    the range up to 1000 is the effect's documented one."""
    noise = dict(getattr(env, "effects", ())).get("noise")
    if not noise or noise < (contrast := rod_contrast()):
        return None
    return (f"--effect noise={number_text(noise)} is at least the pendulum's contrast with the background ({contrast} gray "
            "levels): about half the pixels are clipped to 0 or 255 and the pendulum is buried in the noise, so a model "
            f"learns little from these frames; give a noise below {contrast}")


#: ``piga-collect``'s presets: 'default' is :class:`CollectConfig`'s defaults; 'paper' the paper's pendulum
#: data set, 5000 / 500 / 500 sequences of 14 frames with θ̇ drawn from U(-6, 6) at reset. The command's
#: seed, workers and env settings other than the reset speed are its own options.
PRESETS: dict[str, CollectConfig] = {
    "default": CollectConfig(),
    "paper": CollectConfig(sequences=6000, steps=14, split=(5000, 500, 500), env=PixelPendulumConfig(max_speed=PAPER_MAX_SPEED)),
}


def _episode_env(env_config: PixelPendulumConfig | DMCPendulumConfig) -> gym.Env:
    if multiprocessing.parent_process() is not None:
        # A worker of AsyncVectorEnv. Ctrl-C reaches the whole process group; the parent alone
        # handles it (one line, partial file removed) and terminates the workers, which must not
        # print KeyboardInterrupt tracebacks of their own.
        quiet_worker_signals()
        die_with_parent()  # a parent killed outright (SIGKILL, the OOM killer) left them printing pipe tracebacks
    if isinstance(env_config, DMCPendulumConfig):
        return make_dmc_pendulum(env_config)
    return make_pixel_pendulum(env_config)


def env_attrs(env_config: PixelPendulumConfig | DMCPendulumConfig) -> tuple[float, float, dict[str, float]]:
    """The env's frame dt, its action bound and its true parameters in piga's form, for the file's attrs."""
    if isinstance(env_config, DMCPendulumConfig):
        return env_config.dt, 1.0, env_config.piga_params()
    params = {
        "g": env_config.effective_gravity,
        "actuation_gain": env_config.actuation_gain,
        "gravity": env_config.gravity,
        "gravity_mult": env_config.gravity_mult,
    }
    return PENDULUM_DT, MAX_ACTION, params


def sequence_rng(seed: int, n: int) -> tuple[int, np.random.Generator]:
    """Sequence n's reset seed for the env and its action generator, from ``SeedSequence(seed)``'s n-th child.

    The child is built directly (``spawn_key=(n,)``), which is what ``SeedSequence(seed).spawn(N)[n]``
    gives, so that memory does not grow with the number of sequences.
    """
    child = np.random.SeedSequence(seed, spawn_key=(n,))
    return int(child.generate_state(1, dtype=np.uint32)[0]), np.random.default_rng(child.spawn(1)[0])


def check_resources(config: CollectConfig, out: str | Path) -> None:
    """Refuses sizes that cannot fit in memory or on disk, before any env is made.

    Memory: one batch of frames, the env workers' render buffers (the renderer's resize and gray
    conversion take ~40 bytes per output pixel) and 2 bytes per sequence of bookkeeping. Disk:
    frames gzip-compressed (:data:`piga.io.resources.RENDERED_FRAME_COMPRESSION`), actions, states and rewards raw.

    Raises:
        piga.io.resources.ResourceError: naming what is needed and what is available.
    """
    from piga.io.resources import check_memory

    n, t, pixels = config.sequences, config.steps, config.env.image_size**2
    workers = min(config.workers, n)
    what = f"{n} sequences x {t} frames of {config.env.image_size}x{config.env.image_size}"
    check_memory(_batch_rows(config) * t * (pixels + 12) + (workers + 1) * 48 * pixels + 2 * n, what)
    # with the room the writer keeps free as it writes the last batch, so that it does not refuse later
    check_data_disk(out, *disk_need(config), what, advice=COLLECT_DISK_ADVICE)


def _batch_rows(config: CollectConfig) -> int:
    """The sequences collected and written at a time: ``config.batch``, a whole number of rounds of the workers."""
    workers = min(config.workers, config.sequences)
    return min(max(config.batch, workers) // workers * workers, config.sequences)


#: What to change where a collection's file does not fit on its disk (piga-collect's options).
COLLECT_DISK_ADVICE = "free some space, write --out elsewhere, or give fewer --sequences or --steps or a smaller --image-size"


def disk_need(config: CollectConfig) -> tuple[float, float, int]:
    """The disk the data file of ``config`` takes, for :func:`piga.data.schema.check_data_disk`: the file once
    compressed (frames shrunk by :data:`piga.io.resources.RENDERED_FRAME_COMPRESSION`, or the shaded frames'
    :data:`~piga.io.resources.SHADED_FRAME_COMPRESSION`; actions, states and rewards raw; HDF5's own bytes,
    :func:`~piga.io.resources.hdf5_file_overhead`), a batch as it takes the disk, and the sequences."""
    from piga.io.resources import RENDERED_FRAME_COMPRESSION, SHADED_FRAME_COMPRESSION, hdf5_file_overhead

    n, t, pixels = config.sequences, config.steps, config.env.image_size**2
    shrink = SHADED_FRAME_COMPRESSION if isinstance(config.env, DMCPendulumConfig) else RENDERED_FRAME_COMPRESSION
    step_bytes = pixels / shrink + 16  # a frame compressed, and its action, state (2 values) and reward raw
    return n * t * step_bytes + hdf5_file_overhead(n), _batch_rows(config) * t * step_bytes, n


def collect(
    config: CollectConfig,
    out: str | Path,
    overwrite: bool = False,
    command: str | None = None,
    progress: bool = True,
    make_env: Callable[[PixelPendulumConfig | DMCPendulumConfig], gym.Env] | None = None,
) -> Path:
    """Gathers ``config.sequences`` random-action sequences and writes them to ``out`` atomically.

    ``make_env`` builds each worker's env from the config (with ``episode_length`` and
    ``frame_stack`` set for collection) instead of piga's own, e.g. to wrap dm_control's pendulum
    in effects from outside it; it must return what that env returns (gray frames, ``info["state"]``).

    Returns:
        The path written.
    """
    if not isinstance(config, CollectConfig):
        raise TypeError(f"config must be a CollectConfig, got {type(config).__name__}")
    if make_env is not None and not callable(make_env):  # (functools said "the first argument must be callable")
        raise TypeError(f"make_env must be a function from the env config to an env, or None; got {type(make_env).__name__}")
    check_writable_target(out, overwrite)  # before any setup work
    check_resources(config, out)
    n, t = config.sequences, config.steps
    # Pendulum's own TimeLimit must not end an episode inside a sequence of T applied actions.
    env_config = replace(config.env, episode_length=t + 1, frame_stack=1)
    counts = split_counts(n, config.split)
    workers = min(config.workers, n)
    factory: Callable[[], gym.Env] = functools.partial(make_env or _episode_env, env_config)
    size = env_config.image_size
    dt, max_action, params = env_attrs(env_config)
    dmc = isinstance(env_config, DMCPendulumConfig)
    attrs = {
        "system": "pendulum",
        "dt": dt,
        "params": params,
        "env_config": env_config.to_dict(),
        "env_id": "piga/DMCPendulum-v0" if dmc else "piga/PixelPendulum-v0",
        "effects": {} if dmc else dict(env_config.effects),
        "state_names": ["theta", "theta_dot"],
        "seed": config.seed,
        "command": command if command is not None else shlex.join(sys.argv),
        "split_counts": dict(zip(SPLITS, counts)),
    }
    vec = _vector_env(factory, workers, fresh=dmc)
    try:
        # the bar outside the writer: one that refuses the file as it closes (frames in which nothing moves) clears it
        with progress_bar(total=n, desc="collect", unit="seq", disable=not progress) as bar, \
                DatasetWriter(out, n, t, (size, size), 1, 2, attrs, overwrite=overwrite, rewards=True) as writer:
            batch = max(config.batch, workers) // workers * workers
            for start in range(0, n, batch):
                stop = min(start + batch, n)
                frames = np.zeros((stop - start, t, size, size), np.uint8)
                actions = np.zeros((stop - start, t, 1), np.float32)
                states = np.zeros((stop - start, t, 2), np.float32)
                rewards = np.zeros((stop - start, t), np.float32)
                for group in range(start, stop, workers):
                    ids = list(range(group, min(group + workers, stop)))
                    reset_seeds, action_rngs = zip(*(sequence_rng(config.seed, i) for i in ids))
                    # Spare envs of the last group replay sequence ids[0]; their output is dropped.
                    seeds = list(reset_seeds) + [reset_seeds[0]] * (workers - len(ids))
                    obs, info = vec.reset(seed=seeds)
                    u = np.stack([rng.uniform(-max_action, max_action, size=(t, 1)) for rng in action_rngs]).astype(np.float32)
                    rows = np.arange(len(ids))
                    local = np.asarray(ids) - start
                    for step in range(t):
                        frames[local, step] = obs[rows, -1]
                        states[local, step] = info["state"][rows]
                        actions[local, step] = u[:, step]
                        step_u = np.zeros((workers, 1), np.float32)
                        step_u[rows] = u[:, step]
                        obs, reward, _, _, info = vec.step(step_u)
                        rewards[local, step] = reward[rows]  # Gymnasium's reward for u_t
                    bar.update(len(ids))
                writer.write(start, frames, actions, states, rewards)
            writer.set_split(np.repeat(np.arange(3, dtype=np.int8), counts))
    except BaseException as exc:  # interrupted or failed: stop the workers now, without waiting for their step
        _force_close(vec)
        if isinstance(exc, (EOFError, ConnectionError)):  # a worker's pipe closed: the worker died (a signal, the OOM
            # killer) under a step; it was an internal error with Gymnasium's traceback
            raise ChildProcessError(f"a collection worker process ended in the middle of a step (killed by a signal, "
                                    f"or out of memory?); nothing was written to {out}: run the command again") from None
        drop = dict(attrs["effects"]).get("frame_drop")
        if isinstance(exc, StillFramesError) and drop:  # the camera repeated the reset frame, not a still pendulum
            raise StillFramesError(
                f"{out}: nothing moves: --effect frame_drop={number_text(drop)} dropped every frame after the first in "
                f"every sequence (each of the {t - 1} later frames is dropped with probability {number_text(drop)}), "
                "so the video shows no motion; lower --effect frame_drop") from None
        exposure = dict(attrs["effects"]).get("exposure")
        if isinstance(exc, BlankFramesError) and exposure:  # not the drawing's fault: the camera's
            raise BlankFramesError(
                f"{str(exc).split('; check')[0]}; --effect exposure={number_text(exposure)} turns "
                + ("the pendulum as white as the background" if exposure > 1 else "the whole picture black")
                + ": give a factor nearer 1") from None
        raise
    vec.close()
    return Path(out)


def _force_close(vec: gym.vector.VectorEnv) -> None:
    """Closes ``vec`` at once, terminating its workers. Where a worker died, Gymnasium's close first waits for the
    pending step on its closed pipe and raises EOFError; then the workers are terminated here, and the env marked
    closed, so that its ``__del__`` does not close it again (it printed that EOFError's traceback at exit)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vec.close(terminate=True)
    except (EOFError, OSError):
        processes = getattr(vec, "processes", [])
        for process in processes:
            if process.is_alive():
                process.terminate()
        for pipe in getattr(vec, "parent_pipes", []):
            with contextlib.suppress(OSError):
                pipe.close()
        for process in processes:
            process.join(timeout=10)
        vec.closed = True


def _vector_env(factory: Callable[[], gym.Env], workers: int, fresh: bool = False) -> gym.vector.VectorEnv:
    """One env in this process, or ``workers`` env processes that leave Ctrl-C to this one.

    The workers are started with SIGINT blocked, and then ignore it (:func:`_episode_env`), so that a
    Ctrl-C, which reaches the whole process group, never interrupts them even during start-up.

    ``fresh``: the workers come from a fresh interpreter (multiprocessing's forkserver), not a fork of this
    process. The DMC pendulum renders through EGL, and AsyncVectorEnv makes one env here first (to read its
    spaces), which renders a frame: workers forked after that waited for ever in their own first render.
    """
    if workers == 1:
        return gym.vector.SyncVectorEnv([factory])
    block = hasattr(signal, "pthread_sigmask")
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if block else None
    try:
        return gym.vector.AsyncVectorEnv([factory] * workers, shared_memory=True,
                                         context="forkserver" if fresh else None)
    finally:
        if previous is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)
