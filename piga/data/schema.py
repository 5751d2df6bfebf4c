"""piga's one HDF5 schema for videos with actions, and how to read and write it.

| dataset | dtype and shape | meaning |
|---|---|---|
| ``/frames`` | uint8 [N, T, H, W] (gray) or [N, T, H, W, C] (colour) | the frames |
| ``/actions`` | float32 [N, T, A] | ``actions[n, t]`` is applied after ``frames[n, t]``; A = 0 if unactuated |
| ``/states`` | float32 [N, T, S] | optional ground truth, **for evaluation only** |
| ``/rewards`` | float32 [N, T] | optional: the env's reward for the action after ``frames[n, t]`` (reward-based baselines) |
| ``/split`` | int8 [N] | 0 train, 1 valid, 2 test |

File attributes: ``system`` (str), ``dt`` (float, seconds between frames), ``params`` (JSON: the
physical parameters used), ``seed`` (int, -1 if unknown), ``piga_version``, ``command`` (the
command line that made the file), and optionally ``env_config``, ``state_names`` and ``effects``
(JSON, from ``piga-collect``; see :mod:`envs.effects`) or ``source``, ``source_actions``,
``source_frames`` and ``dropped_frames`` (from ``piga-import``; see :mod:`piga.data.importer`).

Training code reads only frames and actions: :class:`piga.data.windows.SequenceWindows` (a torch
Dataset, in its own module so that reading and writing files does not pay torch's import) serves
those and nothing else. Ground-truth states come out only through :func:`load_states`, which
evaluation code calls explicitly. Rewards come out only through :func:`load_rewards`, which only the
reward-based baselines (:mod:`agents.planet`) call; piga's own training never reads them.
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import typing
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import h5py
import numpy as np
from piga import __version__
from piga.data.header_check import remember_written, unreadable_header
from piga.io.atomic import atomic_output, link_loop, loop_message

SPLITS: dict[str, int] = {"train": 0, "valid": 1, "test": 2}
"""Split name -> code stored in ``/split``."""

#: Largest root seed: a data file stores it as a 64-bit integer (and numpy's and torch's generators take
#: seeds up to it).
MAX_SEED = 2**63 - 1


def _entries(count: int) -> str:
    """``count`` entries of an array, in the singular for one."""
    return f"{count} entr{'y' if count == 1 else 'ies'}"


def legacy_seed(seed: int) -> int:
    """``seed`` for the generators that take 32 bits only (numpy's global ``np.random.seed``, which SB3's
    ``set_random_seed`` calls): a seed below 2^32 as it is, a larger one hashed into 32 bits by numpy's
    ``SeedSequence``, so that every seed up to :data:`MAX_SEED` runs and runs the same each time."""
    return seed if 0 <= seed < 2**32 else int(np.random.SeedSequence(seed).generate_state(1)[0])


REQUIRED_ATTRS = ("system", "dt")
DATASETS = ("frames", "actions", "split", "states", "rewards")
"""The datasets of the schema, in the order they are checked."""

#: The smallest frame side, in pixels, that piga's models and data take (the encoder's and the SSIM's windows).
MIN_IMAGE_SIZE = 8

#: Accepted frame intervals ``dt``, in seconds: a 100 kHz camera to one frame per 10 s (beyond, a swinging
#: pendulum's frames no longer follow each other). Files and ``piga-import --dt`` are held to it.
MIN_DT, MAX_DT = 1e-5, 10.0

#: How ``/frames`` is stored: chunked one sequence per chunk, with a lossless filter (HDF5's gzip at a
#: level, or LZF) or none. Files of any of them read the same; older unchunked files read too.
FrameCodec = Literal["gzip-1", "gzip-4", "gzip-9", "lzf", "none"]
#: What piga writes (chosen by ``benchmarks/storage.py``, results/storage.md).
FRAME_CODEC: FrameCodec = "gzip-4"


def codec_options(codec: FrameCodec) -> dict[str, Any]:
    """h5py's ``create_dataset`` keywords of a :data:`FrameCodec`, e.g. ``{"compression": "gzip", "compression_opts": 4}``."""
    if codec not in typing.get_args(FrameCodec):
        raise ValueError(f"unknown frame codec {codec!r}; expected one of {', '.join(typing.get_args(FrameCodec))}")
    if codec == "none":
        return {}
    if codec == "lzf":
        return {"compression": "lzf"}
    return {"compression": "gzip", "compression_opts": int(codec.split("-")[1])}


def write_margin(sequences: int) -> float:
    """The free space a :class:`DatasetWriter` keeps beyond the bytes of the slice it writes next, in a file of
    ``sequences`` sequences: room for HDF5's metadata as it grows and is flushed at close
    (:data:`~piga.io.resources.HDF5_WRITE_HEADROOM` and :func:`~piga.io.resources.hdf5_file_overhead`). HDF5 that runs
    out of disk mid-write leaves objects whose deallocation fails (h5py printed dozens of tracebacks, then the process
    segfaulted), so the writer stops first. The frames hold no room of their own: the writer keeps no chunk cache, so
    each slice is on disk, compressed, once written."""
    from piga.io.resources import HDF5_WRITE_HEADROOM, hdf5_file_overhead

    return HDF5_WRITE_HEADROOM + hdf5_file_overhead(sequences)


def write_room(slice_bytes: float, sequences: int) -> float:
    """The free space a :class:`DatasetWriter` asks for before it writes a slice that takes ``slice_bytes`` on disk
    into a file of ``sequences`` sequences: the slice and :func:`write_margin`. A command's disk check before its work
    adds it to the file's size, so that the writer's own check does not refuse after the work."""
    return slice_bytes + write_margin(sequences)


def check_data_disk(out: str | Path, file_bytes: float, slice_bytes: float, sequences: int, what: str,
                    advice: str = "ask for less") -> None:
    """Refuses, before a command makes its data, a file ``out`` whose disk cannot take it as a
    :class:`DatasetWriter` writes it: the file (about ``file_bytes`` once compressed) and the room it keeps free to
    write each slice (:func:`write_room` of a slice of about ``slice_bytes`` on disk in a file of ``sequences``), so
    that the writer does not refuse after the work. The message gives the two parts: the need is an upper bound.

    Raises:
        piga.io.resources.ResourceError: as :func:`piga.io.resources.check_disk`.
    """
    from piga.io.resources import check_disk, format_bytes

    room = write_room(slice_bytes, sequences)
    check_disk(out, file_bytes + room, what, advice, bound="up to",
               detail=f" as it writes (a file of about {format_bytes(file_bytes)} once compressed, and "
                      f"{format_bytes(room)} kept free as it writes: about {format_bytes(slice_bytes)} for the next "
                      "sequences, and room for HDF5's metadata)")


#: Files whose frames need less memory than this are loaded whole by default when training.
IN_MEMORY_LIMIT_BYTES = 2 * 1024**3


class DataFormatError(ValueError):
    """A file does not follow piga's schema. The message names the dataset or attribute at fault."""


class BlankFramesError(DataFormatError):
    """Frames that are all blank (:func:`blank_error`): nothing to learn from, but a viewer still draws them."""


class StillFramesError(DataFormatError):
    """Frames in which nothing moves (:func:`still_error`): a writer that knows why (an effect that repeats frames)
    can name that cause instead of the generic advice."""


#: Largest |action| accepted in a file. Far beyond any torque of the systems here (the pendulum's
#: is clipped to ±2); larger values are a unit or recording error, and they overflow the physics.
MAX_ABS_ACTION = 1e6


def check_actions(actions: np.ndarray, path: str | os.PathLike[str]) -> None:
    """Refuses actions that no physics can use: NaN, infinite, or beyond ±:data:`MAX_ABS_ACTION`.

    Raises:
        DataFormatError: naming the file, the first bad entry (sequence, step) and its value.
    """
    actions = np.asarray(actions, np.float64)  # float16 holds no 1e6: compare in float64
    bad = ~np.isfinite(actions) | (np.abs(np.nan_to_num(actions, nan=0.0)) > MAX_ABS_ACTION)
    if bad.any():
        n, t = (int(i) for i in np.argwhere(bad)[0][:2])
        value = actions[(n, t, *np.argwhere(bad)[0][2:])]
        what = "NaN or infinite values" if not np.isfinite(value) else f"values beyond ±{MAX_ABS_ACTION:g}"
        raise DataFormatError(f"{path}: /actions holds {what} ({_entries(int(bad.sum()))}; the first: sequence {n}, "
                              f"step {t}: {value}); fix the recording's actions")


def check_actions_file(path: str | os.PathLike[str]) -> np.ndarray:
    """:func:`check_actions` on a whole file's ``/actions`` (float32 [N, T, A], small next to the frames); returns
    them."""
    with open_data_file(path) as f:
        with read_rows(f["actions"], "every sequence"):
            actions = np.asarray(f["actions"][()])
    check_actions(actions, path)
    return actions


@dataclass(frozen=True)
class DatasetInfo:
    """What a validated file holds (no arrays)."""

    path: Path
    """The file."""
    n_sequences: int
    """N."""
    steps: int
    """T, frames per sequence."""
    image_shape: tuple[int, ...]
    """(H, W) or (H, W, C)."""
    action_dim: int
    """A."""
    has_states: bool
    """Whether ``/states`` exists (evaluation only)."""
    system: str
    """Attribute ``system``."""
    dt: float
    """Attribute ``dt``."""
    params: dict[str, Any]
    """Attribute ``params`` parsed from JSON."""
    split_counts: dict[str, int]
    """Sequences per split name."""
    attrs: dict[str, Any] = field(repr=False)
    """All file attributes (JSON strings parsed)."""
    has_rewards: bool = False
    """Whether ``/rewards`` exists (reward-based baselines only)."""

    @property
    def channels(self) -> int:
        """Colour channels of a frame: (H, W) and (H, W, 1) are gray, (H, W, 3) colour."""
        return self.image_shape[2] if len(self.image_shape) == 3 else 1

    @property
    def named(self) -> str:
        """The file's system as a user named it: its scene where that is not the system's own name ("digits-spring",
        whose system is "spring"), else its system."""
        scene = self.attrs.get("scene")
        return scene if isinstance(scene, str) and scene else self.system

    @property
    def sequence_bytes(self) -> int:
        """Bytes of one sequence's frames, uncompressed (T·H·W[·C])."""
        return self.steps * int(np.prod(self.image_shape))


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, (np.float16, np.float32)):  # the decimal written: float32's 0.05 is 0.0500000007, a 'dt' that
        return float(str(value))  # was refused as not Gymnasium's 0.05 s ("set 'dt' to 0.05")
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, str) and value[:1] in "{[":
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    return value


def _check_frames_not_odd_one_out(f: h5py.File, path: Path, n: int, t: int) -> None:
    """Where /actions, /split and the optional arrays agree with each other on the number of sequences (or of steps) and
    only /frames differs, names /frames: the checks that follow would blame /actions."""
    sizes: dict[str, tuple[int, ...]] = {}
    for name, ndim in (("actions", 3), ("split", 1), ("states", 3), ("rewards", 2)):
        try:
            found = f.get(name)
        except (KeyError, OSError):  # a link that does not resolve: named by the checks that follow
            continue
        if isinstance(found, h5py.Dataset) and found.ndim == ndim:
            sizes[name] = found.shape
    if "actions" not in sizes or "split" not in sizes:
        return
    counts = {shape[0] for shape in sizes.values()}
    if len(counts) == 1 and (other := counts.pop()) != n:
        names = ", ".join(f"/{name}" for name in sorted(sizes))
        raise DataFormatError(f"{path}: /frames holds {n} sequence{'s' * (n != 1)} but {names} hold {other}; every array "
                              "needs one row per sequence")
    steps = {shape[1] for name, shape in sizes.items() if name != "split"}
    if len(steps) == 1 and (other := steps.pop()) != t and len(sizes) > 2:
        names = ", ".join(f"/{name}" for name in sorted(sizes) if name != "split")
        raise DataFormatError(f"{path}: /frames holds {t} frame{'s' * (t != 1)} per sequence but {names} hold {other}; "
                              "every array needs one entry per frame")


def _validate(f: h5py.File, path: Path) -> DatasetInfo:
    def need(name: str) -> h5py.Dataset:
        found = optional(name)
        if found is None:
            raise DataFormatError(f"{path}: missing dataset /{name}")
        return found

    def optional(name: str) -> h5py.Dataset | None:
        """``/name``, None if absent; a link that does not resolve (an external file that is gone) is named."""
        if name not in f:
            return None
        try:
            found = f[name]
        except KeyError:
            link = f.get(name, getlink=True)  # (h5py's repr of an external link leaves its "<" unclosed)
            if isinstance(link, h5py.HardLink):  # the file's own dataset, not found: its index is damaged (it was
                # "a link that does not resolve (to <h5py._hl.group.HardLink object at 0x7f...>)")
                raise DataFormatError(f"{path}: not a readable HDF5 file (damaged: its index names /{name}, but it "
                                      "cannot be found); collect, import or copy it again") from None
            external = isinstance(link, h5py.ExternalLink)
            to = f"{link.path} in {link.filename}" if external else getattr(link, "path", link)
            raise DataFormatError(f"{path}: /{name} is a link that does not resolve (to {to})") from None
        if not isinstance(found, h5py.Dataset):
            raise DataFormatError(f"{path}: missing dataset /{name} (it is a {type(found).__name__.lower()})")
        return found

    frames = need("frames")
    if frames.dtype != np.uint8 or frames.ndim not in (4, 5):
        raise DataFormatError(
            f"{path}: /frames must be uint8 [N, T, H, W] or [N, T, H, W, C], got {frames.dtype} {frames.shape}"
        )
    if frames.ndim == 5 and frames.shape[-1] not in (1, 3):
        raise DataFormatError(f"{path}: /frames colour axis must have 1 or 3 channels, got {frames.shape}")
    n, t = frames.shape[:2]
    if min(frames.shape) < 1:
        raise DataFormatError(f"{path}: /frames is empty, shape {frames.shape}")
    _check_frames_not_odd_one_out(f, path, n, t)
    actions = need("actions")
    if not np.issubdtype(actions.dtype, np.floating):
        raise DataFormatError(f"{path}: /actions must be float [N={n}, T={t}, A], got {actions.dtype} {actions.shape}")
    if actions.ndim != 3 or actions.shape[:2] != (n, t):  # (it read "must be float ..., got float32 (24, 10, 1)")
        raise DataFormatError(f"{path}: /actions has shape {actions.shape}, but /frames holds {n} sequences of {t} "
                              f"frames; /actions must be [N={n}, T={t}, A]: one action row per frame")
    states = optional("states")
    has_states = states is not None
    if states is not None and (states.ndim != 3 or not (np.issubdtype(states.dtype, np.floating)
                                                        or np.issubdtype(states.dtype, np.integer))):
        raise DataFormatError(f"{path}: /states must be real numbers [N={n}, T={t}, S], got {states.dtype} {states.shape}")
    if states is not None and states.shape[:2] != (n, t):
        # (it was refused as "must be real numbers" for a file cut to fewer sequences with /states left whole). The
        # training report scores the encoder against /states row by row, so a /states of other rows would misreport
        raise DataFormatError(f"{path}: /states has shape {states.shape}, but /frames and /actions hold {n} sequences of "
                              f"{t} frames {tuple(frames.shape[:2])}; /states must be [N={n}, T={t}, S]: cut it the same "
                              "way or drop it (ground truth is optional, and piga-diagnose never reads it)")
    rewards = optional("rewards")
    has_rewards = rewards is not None
    if rewards is not None and (rewards.shape != (n, t) or not np.issubdtype(rewards.dtype, np.floating)):
        raise DataFormatError(f"{path}: /rewards must be float32 [N={n}, T={t}], got {rewards.dtype} {rewards.shape}")
    split = need("split")
    if split.shape != (n,) or not np.issubdtype(split.dtype, np.integer):
        raise DataFormatError(f"{path}: /split must be int8 [N={n}], got {split.dtype} {split.shape}")
    codes = split[()]
    if not np.isin(codes, list(SPLITS.values())).all():
        raise DataFormatError(f"{path}: /split holds codes other than 0 (train), 1 (valid), 2 (test)")
    attrs = {key: _attr(value) for key, value in f.attrs.items()}
    for key in REQUIRED_ATTRS:
        if key not in attrs:
            raise DataFormatError(f"{path}: missing file attribute '{key}'")
    if not isinstance(attrs["system"], str) or not attrs["system"]:  # (an array of one name was shown, and then refused)
        raise DataFormatError(f"{path}: attribute 'system' must be one string naming the system (e.g. 'pendulum'), got "
                              f"{_shown(attrs['system'])}")
    try:
        dt = float("nan") if isinstance(attrs["dt"], bool) else float(attrs["dt"])
    except (TypeError, ValueError):
        dt = float("nan")
    if not MIN_DT <= dt <= MAX_DT:
        raise DataFormatError(f"{path}: attribute 'dt' must be the seconds between frames, {MIN_DT:g} to {MAX_DT:g}, "
                              f"got {attrs['dt']!r}")
    params = attrs.get("params", {})
    if not isinstance(params, dict):
        raise DataFormatError(f"{path}: attribute 'params' must be a JSON object, got {params!r}")
    for name, value in params.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite_float(value):
            raise DataFormatError(f"{path}: attribute 'params' must give each parameter as a finite number, got "
                                  f"{name}={_shown(value)}")  # (JSON integers are unbounded)
        _check_true_parameter(path, name, float(value))
    return DatasetInfo(
        path=path,
        n_sequences=n,
        steps=t,
        image_shape=tuple(frames.shape[2:]),
        action_dim=actions.shape[2],
        has_states=has_states,
        system=str(attrs["system"]),
        dt=dt,
        params=params,
        split_counts={name: int((codes == code).sum()) for name, code in SPLITS.items()},
        attrs=attrs,
        has_rewards=has_rewards,
    )


def _shown(value: Any) -> str:
    """An attribute's value in a message: its repr (escapes for a damaged byte), cut to 40 characters."""
    return repr(value) if len(repr(value)) <= 40 else f"{repr(value)[:37]}..."


def open_data_file(path: str | os.PathLike[str]) -> h5py.File:
    """``path`` opened for reading, or :class:`DataFormatError` (:class:`FileNotFoundError` where it is missing) saying
    in words why it cannot be: every command's way into a data file, so that one whose header crashes or hangs HDF5
    is refused before this process reads it (:func:`piga.data.header_check.unreadable_header`)."""
    p = Path(path)
    if not p.exists():
        loop = link_loop(p)  # exists() is False for a link that loops
        raise FileNotFoundError(f"{p}: no such file" if loop is None else loop_message(p, loop))
    if p.is_dir():
        raise DataFormatError(f"{p}: is a folder, not an HDF5 file")
    if not p.is_file():  # a FIFO's open waits for a writer for ever; a device is no file to read
        raise DataFormatError(f"{p}: is not a regular file (a pipe, a socket or a device), not an HDF5 file")
    if (damage := unreadable_header(p, DATASETS)) is not None:  # before this process meets a crash or a hang there
        raise DataFormatError(f"{p}: not a readable HDF5 file ({damage}); collect, import or copy it again")
    try:
        return h5py.File(p, "r")
    except BlockingIOError:  # HDF5's lock: the file is open for writing elsewhere (errno EAGAIN, "unable to lock file")
        raise DataFormatError(f"{p}: another process has it open for writing (HDF5 locks a file while it is written); "
                              "wait for that process to end, or close the file there, and run the command again") from None
    except OSError:  # what the file is, in words rather than the exception's name (h5py's signature test)
        what = ("it cannot be read (no permission)" if not os.access(p, os.R_OK) else
                "it is empty" if p.stat().st_size == 0 else
                "damaged or cut short: it starts as an HDF5 file, but cannot be read" if h5py.is_hdf5(p) else
                "another kind of file: an HDF5 file (.h5) from piga-collect or piga-import is needed")
        raise DataFormatError(f"{p}: not a readable HDF5 file ({what})") from None


def inspect_dataset(path: str | os.PathLike[str]) -> DatasetInfo:
    """Opens and validates a file; raises :class:`DataFormatError` naming what is wrong.

    Beyond the schema (shapes, types, the split, the required attributes), it checks attributes
    against the arrays and that ``/states`` is finite (:func:`_check_attrs_agree`; the states are
    small). Whether the frames carry a signal is a separate check, :func:`check_frames_have_signal`,
    which the commands that learn from or diagnose the frames run.
    """
    with open_data_file(path) as f:
        try:
            info = _validate(f, Path(path))
            _check_attrs_agree(info, f)
            _check_virtual_sources(f, Path(path))
            _check_frames_written(f, Path(path))
        except (FileNotFoundError, DataFormatError):
            raise
        except (RuntimeError, OSError, ValueError, TypeError):  # HDF5's own reading of damaged metadata: "Error
            # iterating over attributes (ran off end of input buffer while decoding)", "Unable to synchronously check
            # link existence (...)", a damaged datatype ("Insufficient precision in available types to represent")
            raise DataFormatError(f"{path}: not a readable HDF5 file (damaged: it opens, but its attributes or its "
                                  "index of datasets cannot be read); collect, import or copy it again") from None
        return info


def _check_frames_written(f: h5py.File, path: Path) -> None:
    """Refuses chunked frames of which some chunks were never written (a writer cut short, outside piga's atomic
    writes): they read as the fill value, blank sequences that trained and scored without a word (a test split of
    blank frames gave "SSIM 0.000, encoder angle error 109.54 deg"). A chunk written with zeros is stored; only one
    never written is missing from the file's chunk index."""
    ds = f.get("frames")
    if not isinstance(ds, h5py.Dataset) or ds.chunks is None or ds.is_virtual or ds.external or ds.size == 0:
        return
    expected = int(np.prod([-(-size // chunk) for size, chunk in zip(ds.shape, ds.chunks)]))
    try:
        stored = ds.id.get_num_chunks()
    except (AttributeError, RuntimeError):  # an HDF5 older than 1.10.5 has no chunk index query
        return
    if stored < expected:
        raise DataFormatError(f"{path}: /frames holds {stored} of its {expected} chunks; the rest were never written "
                              "(a write cut short?) and would read as blank frames: collect, import or copy the file "
                              "again")


def _check_virtual_sources(f: h5py.File, path: Path) -> None:
    """A virtual dataset (HDF5's VDS) whose source file is missing reads as its fill value: the frames of a moved
    file looked blank ("every frame is blank"), the actions zero. Each source is named instead; so is the file of a
    dataset in HDF5's external raw storage that is not found from the current folder (it was "the file is damaged")."""
    for name in DATASETS:
        ds = f.get(name)
        if isinstance(ds, h5py.Dataset) and ds.external:  # HDF5's external raw storage, found from the current folder
            for source, _, _ in ds.external:
                where = Path(source.decode() if isinstance(source, bytes) else source)
                if not where.exists():
                    raise DataFormatError(f"{path}: /{name} keeps its data in the external file {where}, which is not "
                                          "found from the current folder (HDF5 looks for it there); run from the folder "
                                          "that holds it, or write a file that holds the data")
        if not isinstance(ds, h5py.Dataset) or not ds.is_virtual:
            continue
        for source in ds.virtual_sources():
            where = Path(source.file_name)
            # HDF5 looks for a relative source beside the file, then from the current folder
            if source.file_name != "." and not any(c.exists() for c in ((where,) if where.is_absolute() else
                                                                         (path.parent / where, where))):
                raise DataFormatError(f"{path}: /{name} is a virtual dataset whose source file {source.file_name} is "
                                      "missing (moved or deleted); put it back, or write a file that holds the data")


def _check_scene_attr(info: DatasetInfo) -> None:
    """Refuses a ``scene`` attribute (or ``scene_config``'s ``physics``) whose physics is not the file's ``system``:
    the recipe follows the scene and the model the system, so a hand-edited one trained a mix of the two."""
    path, attrs = info.path, info.attrs
    scene = attrs.get("scene")
    if scene is not None:
        from envs.scenes import SCENES  # (only for a scene file: reading a pendulum file does not pay for it)

        if not isinstance(scene, str) or scene not in SCENES:
            raise DataFormatError(f"{path}: attribute 'scene' must name one of the scenes ({', '.join(SCENES)}), got "
                                  f"{str(scene)[:40]!r}; fix it or drop it")
        if SCENES[scene]["physics"] != info.system:
            raise DataFormatError(f"{path}: attribute 'scene' is {scene!r}, a {SCENES[scene]['physics']} scene, but "
                                  f"'system' says {info.system!r}; fix one of them")
    physics = attrs.get("scene_config", {}).get("physics") if isinstance(attrs.get("scene_config"), dict) else None
    if physics is not None and physics != info.system:
        raise DataFormatError(f"{path}: attribute 'scene_config' has physics {str(physics)[:40]!r}, but 'system' says "
                              f"{info.system!r}; fix one of them")


def _frames_text(shape: tuple[int, ...]) -> str:
    """``64x64 gray`` or ``64x64 with 3 channels``: frames of ``shape`` (H, W) or (H, W, C) in an error."""
    gray = len(shape) == 2 or shape[2] == 1
    return f"{shape[0]}x{shape[1]}" + (" gray" if gray else f" with {shape[2]} channels")


def _image_size_fix(side: int) -> str:
    """What to change where env_config's image_size contradicts square frames of ``side`` pixels: that image_size,
    where an env can render it (frames of 2048 px were sent to an image_size that every command then refused)."""
    from envs.pendulum import MAX_IMAGE_SIZE  # (on this error only: the schema is read without gymnasium's import)

    if MIN_IMAGE_SIZE <= side <= MAX_IMAGE_SIZE:
        return f"set env_config's image_size to {side}, or collect the file again"
    return (f"frames {side} px a side are outside the envs' {MIN_IMAGE_SIZE} to {MAX_IMAGE_SIZE} px: resize them (as "
            "piga-import --image-size does), or collect the file again")


def _check_env_attrs(info: DatasetInfo) -> None:
    """Refuses a pendulum file whose ``env_config``, ``env_id``, ``dt`` or ``params`` contradict each other: frames of
    another size than env_config's ``image_size``; an ``env_id`` that names no env of piga's, or another env than the one
    whose settings ``env_config`` holds; a ``dt`` that the env its ``env_id`` names cannot step (Gymnasium's pixel
    pendulum steps 0.05 s; dm_control's env_config's ``action_repeat`` x 0.02 s, or any whole multiple of 0.02 s
    where it names none); ``params`` (the true values that training scores against) other than those env_config's
    physics makes (what piga-control reads). An edited 'dt' trained g for the wrong interval, and only piga-control
    refused the model. A file without ``env_config`` (an imported recording, or one of another env) has nothing to
    contradict; one from before env ids (no ``env_id``) has its frames and ``params`` checked, not its ``dt``."""
    path, attrs, config = info.path, info.attrs, info.attrs.get("env_config")
    if info.system != "pendulum" or not isinstance(config, dict):
        return
    size, shape = config.get("image_size"), info.image_shape
    if isinstance(size, int) and not isinstance(size, bool) and shape[:2] != (size, size):
        fix = _image_size_fix(shape[0]) if shape[0] == shape[1] else "collect the file again"
        look = "RGB" if config.get("color") == "rgb" else "gray"  # (dm_control's pendulum renders either)
        raise DataFormatError(f"{path}: attribute 'env_config' says the env renders {size}x{size} {look} frames "
                              f"(image_size {size}), but the file's frames are {_frames_text(shape)}; {fix}")
    rgb, gray = config.get("color") == "rgb", len(shape) == 2 or shape[2] == 1
    if gray == rgb:  # (dm_control's pendulum renders either; Gymnasium's, gray) a model would read other frames
        raise DataFormatError(f"{path}: attribute 'env_config' says the env renders {'RGB' if rgb else 'gray'} frames"
                              f"{' (color rgb)' if rgb else ''}, but the file's frames are {_frames_text(shape)}; "
                              "collect the file again")
    from envs import DMC_PENDULUM, ENV_IDS, PENDULUM_DT, PIXEL_PENDULUM  # (only for a file of an env: an import pays nothing)
    from envs.dmc import DMC_PHYSICS_DT, MAX_ACTION_REPEAT

    env_id = attrs.get("env_id")
    settings_of, fields_named = _settings_env(config)
    if env_id is not None and (env_id not in ENV_IDS or settings_of not in (None, env_id)):
        held = (f"holds {settings_of}'s settings ({', '.join(fields_named)})" if settings_of
                else "holds the settings of one of piga's envs")
        if env_id in ENV_IDS:
            raise DataFormatError(f"{path}: attribute 'env_id' says {env_id}, but 'env_config' {held}; set 'env_id' to "
                                  f"{settings_of}, or collect the file again")
        fix = f"set 'env_id' to {settings_of}" if settings_of else f"set 'env_id' to the one that made it ({', '.join(ENV_IDS)})"
        raise DataFormatError(f"{path}: attribute 'env_id' says {env_id}, which is none of piga's envs, but 'env_config' "
                              f"{held}; {fix}, or drop 'env_config' if the file is a recording of another env")
    repeat = config.get("action_repeat")
    step, how = None, ""
    if env_id == PIXEL_PENDULUM:
        step = PENDULUM_DT
    elif env_id == DMC_PENDULUM and isinstance(repeat, int) and not isinstance(repeat, bool) and repeat >= 1:
        step, how = repeat * DMC_PHYSICS_DT, f" at env_config's action_repeat {repeat} ({repeat} x {DMC_PHYSICS_DT:g} s)"
    fits = round(info.dt / DMC_PHYSICS_DT)  # dm_control: the action repeat that steps the file's dt
    repeats = 1 <= fits <= MAX_ACTION_REPEAT and math.isclose(fits * DMC_PHYSICS_DT, info.dt, rel_tol=1e-9)
    if env_id == DMC_PENDULUM and step is None and not repeats:  # no action repeat named: no repeat makes this dt
        near = min(max(fits, 1), MAX_ACTION_REPEAT) * DMC_PHYSICS_DT
        other = f" or 'env_id' to {PIXEL_PENDULUM}" if math.isclose(info.dt, PENDULUM_DT, rel_tol=1e-9) else ""
        raise DataFormatError(f"{path}: attribute 'dt' says the frames are {info.dt:g} s apart, but {env_id} (its "
                              f"'env_id') steps a whole multiple of {DMC_PHYSICS_DT:g} s (action_repeat 1 to "
                              f"{MAX_ACTION_REPEAT}); set 'dt' to {near:g}{other}, or collect the file again")
    if step is not None and not math.isclose(info.dt, step, rel_tol=1e-9):
        other = f" or env_config's action_repeat to {fits}" if how and repeats else ""
        raise DataFormatError(f"{path}: attribute 'dt' says the frames are {info.dt:g} s apart, but {env_id} (its "
                              f"'env_id') steps {step:g} s{how}; set 'dt' to {step:g}{other}, or collect the file again")
    _check_params_agree(info, config, env_id if env_id is not None else settings_of)
    _check_effects_agree(info, config)
    _check_env_config_values(info, config, env_id if env_id is not None else settings_of)


def _check_env_config_values(info: DatasetInfo, config: dict[str, Any], env_id: str | None) -> None:
    """Refuses an ``env_config`` whose fields the config of the env it holds (``env_id``'s) refuses: a value of the wrong
    kind or out of range (``"gravity": "ten"``, ``null``, ``"max_speed": "fast"`` were read by piga-show, training,
    piga-control and piga-diagnose's ``--env``, and only PlaNet-style's iterative mode refused them). Fields that config
    does not know are left alone (another version's)."""
    from dataclasses import fields

    from envs import DMC_PENDULUM, PIXEL_PENDULUM, DMCPendulumConfig, PixelPendulumConfig

    kind = {PIXEL_PENDULUM: PixelPendulumConfig, DMC_PENDULUM: DMCPendulumConfig}.get(env_id or "")
    if kind is None:
        return
    known = {f.name for f in fields(kind)}
    try:
        kind(**{k: v for k, v in config.items() if k in known})  # (JSON's lists of pairs are effects it takes)
    except (TypeError, ValueError) as exc:
        raise DataFormatError(f"{info.path}: attribute 'env_config' is not a valid {kind.__name__} ({exc}); fix it, or "
                              "collect the file again") from None


def _check_effects_agree(info: DatasetInfo, config: dict[str, Any]) -> None:
    """Refuses an ``effects`` attribute, or ``env_config``'s effects, that piga-collect could not have made (an unknown
    effect, a value out of its range, a passive torque Pendulum-v1's step cannot integrate), and an ``effects``
    attribute other than the effects ``env_config`` holds (none where it holds no ``effects``): training scores the
    learned gain against 'effects' (a ``gain`` effect scales the true a) while piga-control and piga-diagnose's
    ``--env`` make the system from 'env_config'. A file without the attribute has nothing to contradict."""
    from envs import PixelPendulumConfig
    from envs.constants import PENDULUM_DT
    from envs.effects import explicit_step_problem, normalize_effects

    recorded, held = info.attrs.get("effects"), config.get("effects", [])
    if recorded is None:
        return
    checked = []
    for name, effects in (("attribute 'effects' is", recorded), ("the effects in 'env_config' are", held)):
        try:
            if not isinstance(effects, (dict, list)):
                raise TypeError(f"expected a JSON object of name: value, got {str(effects)[:40]!r}")
            checked.append(dict(normalize_effects(effects)))
        except (TypeError, ValueError) as exc:
            raise DataFormatError(f"{info.path}: {name} not effects piga-collect makes ({exc}); fix it, or collect "
                                  "the file again") from None
    said, made = checked
    try:  # (fields that are no numbers are refused next, by _check_env_config_values, which names them)
        gravity = float(config.get("gravity", PixelPendulumConfig.gravity)) * float(config.get("gravity_mult", 1.0))
    except (TypeError, ValueError):
        gravity = PixelPendulumConfig.gravity
    if (unstable := explicit_step_problem(made, gravity, PENDULUM_DT)) is not None:
        raise DataFormatError(f"{info.path}: the effects in 'env_config' are not effects piga-collect makes ({unstable}); "
                              "fix them, or collect the file again")
    if said.keys() == made.keys() and all(math.isclose(said[k], made[k], rel_tol=1e-6, abs_tol=1e-12) for k in said):
        return

    def text(effects: dict[str, float]) -> str:
        return ", ".join(f"{k}={v:g}" for k, v in effects.items()) or "none"

    raise DataFormatError(f"{info.path}: attribute 'effects' says {text(said)}, but 'env_config' holds effects "
                          f"{text(made)}; fix the attribute that is wrong (training scores against 'effects', "
                          "piga-control reads 'env_config'), or collect the file again")


def _settings_env(config: dict[str, Any]) -> tuple[str | None, list[str]]:
    """The env whose settings ``env_config`` holds, told by the fields only its config has (the pixel pendulum's
    ``gravity``, dm_control's ``action_repeat``), and those fields; (None, []) where none, or both envs', are there."""
    from dataclasses import fields

    from envs import DMC_PENDULUM, PIXEL_PENDULUM, DMCPendulumConfig, PixelPendulumConfig

    pixel, dmc = ({f.name for f in fields(kind)} for kind in (PixelPendulumConfig, DMCPendulumConfig))
    own = {PIXEL_PENDULUM: [k for k in config if k in pixel - dmc], DMC_PENDULUM: [k for k in config if k in dmc - pixel]}
    found = [env for env, named in own.items() if named]
    return (found[0], own[found[0]]) if len(found) == 1 else (None, [])


#: The fields of each env's ``env_config`` that make each true parameter of its ``params``.
_PARAM_SOURCES = {
    "piga/PixelPendulum-v0": {"g": ("gravity", "gravity_mult"), "gravity": ("gravity",),
                              "gravity_mult": ("gravity_mult",), "actuation_gain": ("actuation_gain",)},
    "piga/DMCPendulum-v0": {"g": ("mass", "length"), "actuation_gain": ("mass", "length"),
                            "damping": ("damping", "mass", "length"), "actuation_sign": ("flip",)},
}


def _check_params_agree(info: DatasetInfo, config: dict[str, Any], env: str | None) -> None:
    """Refuses ``params`` other than those that the physics of ``env_config`` makes in ``env`` (a field it lacks at its
    default, as piga-control reads it): training scored g against 'params' (true 10) while piga-control warned that
    the file was collected at g = 5, read from 'env_config'. Fields that are no numbers are refused where they are
    read."""
    from envs import DMC_PENDULUM, PIXEL_PENDULUM, DMCPendulumConfig, PixelPendulumConfig

    kind = {PIXEL_PENDULUM: PixelPendulumConfig, DMC_PENDULUM: DMCPendulumConfig}.get(str(env))
    if kind is None:
        return
    sources = _PARAM_SOURCES[str(env)]
    fields = {k: config.get(k, getattr(kind, k)) for names in sources.values() for k in names}
    try:
        if kind is PixelPendulumConfig:
            gravity, mult, gain = (float(fields[k]) for k in ("gravity", "gravity_mult", "actuation_gain"))
            made = {"g": gravity * mult, "gravity": gravity, "gravity_mult": mult, "actuation_gain": gain}
        else:
            made = DMCPendulumConfig(**fields).piga_params()
    except (TypeError, ValueError):
        return
    for name, value in made.items():
        given = info.params.get(name)
        if given is None or math.isclose(float(given), value, rel_tol=1e-6, abs_tol=1e-12):
            continue
        read = ", ".join(f"{k} {v if isinstance(v, str) else f'{float(v):.6g}'}"
                         for k, v in fields.items() if k in sources[name])
        raise DataFormatError(f"{info.path}: attribute 'params' says {name} = {float(given):.6g}, but "
                              f"'env_config' ({read}) makes {name} = {value:.6g}; fix the attribute that is "
                              "wrong (training scores against 'params', piga-control reads 'env_config'), or collect the "
                              "file again")


def _check_attrs_agree(info: DatasetInfo, f: h5py.File) -> None:
    """Refuses attributes that contradict the arrays (``n_objects``, ``state_names``, ``split_counts``) or are not the
    JSON objects they should be (``env_config``, ``scene_config``), and non-finite ``/states``."""
    path, attrs = info.path, info.attrs
    for key in ("env_config", "scene_config"):
        if key in attrs and not isinstance(attrs[key], dict):
            raise DataFormatError(f"{path}: attribute '{key}' must be a JSON object, got {str(attrs[key])[:80]!r}")
    _check_scene_attr(info)
    _check_env_attrs(info)
    states_dim = f["states"].shape[2] if info.has_states else None
    if "n_objects" in attrs:
        n = attrs["n_objects"]
        if isinstance(n, bool) or not isinstance(n, (int, float)) or not float(n).is_integer() or n < 1:
            raise DataFormatError(f"{path}: attribute 'n_objects' must be an integer >= 1, got {n!r}")
        n = int(n)
        recorded = attrs.get("scene_config", {}).get("n_objects") if isinstance(attrs.get("scene_config"), dict) else None
        if recorded is not None and recorded != n:
            raise DataFormatError(f"{path}: attribute 'n_objects' is {n} but 'scene_config' says {recorded}; fix the attribute")
        if info.system == "pendulum" and n != 1:
            raise DataFormatError(f"{path}: attribute 'n_objects' is {n}, but a pendulum file holds one object")
        if states_dim is not None and info.system != "pendulum" and states_dim != STATE_DIM_PER_OBJECT * n:
            raise DataFormatError(f"{path}: attribute 'n_objects' is {n}, but /states holds {states_dim} values per frame "
                                  f"({STATE_DIM_PER_OBJECT} per object: {states_dim / STATE_DIM_PER_OBJECT:g} objects); "
                                  "fix the attribute")
    recorded_split = attrs.get("split_counts")
    if recorded_split is not None and not isinstance(recorded_split, dict):  # (a damaged byte: its text, not JSON)
        raise DataFormatError(f"{path}: attribute 'split_counts' must be a JSON object of sequences per split, got "
                              f"{_shown(recorded_split)}; fix the attribute or drop it (/split is what is read)")
    if recorded_split is not None and recorded_split != info.split_counts:
        raise DataFormatError(f"{path}: attribute 'split_counts' says {recorded_split}, but /split holds "
                              f"{info.split_counts}; fix the attribute or drop it (/split is what is read)")
    names = attrs.get("state_names")
    if names is not None:
        if not isinstance(names, list):
            raise DataFormatError(f"{path}: attribute 'state_names' must be a JSON list, got {names!r}")
        if states_dim is not None and len(names) != states_dim:
            raise DataFormatError(f"{path}: attribute 'state_names' names {len(names)} values, but /states holds "
                                  f"{states_dim} per frame")
        if "n_objects" in attrs and info.system != "pendulum" and len(names) != STATE_DIM_PER_OBJECT * int(attrs["n_objects"]):
            raise DataFormatError(f"{path}: attribute 'n_objects' is {attrs['n_objects']}, but 'state_names' names "
                                  f"{len(names)} values ({STATE_DIM_PER_OBJECT} per object); fix the attribute")
    if info.has_states:
        with read_rows(f["states"], "every sequence"):
            states = f["states"][()].astype(np.float64)  # read as float32: beyond its range is as useless as inf
        bad = ~np.isfinite(states) | (np.abs(np.nan_to_num(states)) > np.finfo(np.float32).max)
        if bad.any():
            n, t, k = (int(i) for i in np.argwhere(bad)[0])
            raise DataFormatError(f"{path}: /states holds NaN or infinite values ({_entries(int(bad.sum()))}; the first: "
                                  f"sequence {n}, step {t}, value {k}: {states[n, t, k]}); fix or drop /states "
                                  "(ground truth is optional)")


#: Values per object in a scene file's ``/states``: x, y, vx, vy (:func:`envs.scenes.state_names`).
STATE_DIM_PER_OBJECT = 4


def frames_have_signal(frames: np.ndarray) -> bool:
    """Whether any frame of ``frames`` (uint8 [N, T, H, W] or [N, T, H, W, C], the schema's) is not
    blank, blank meaning one flat level (or colour) over the whole frame."""
    flat = frames.reshape(frames.shape[0] * frames.shape[1], -1)  # (N·T, H·W[·C])
    return bool((flat.max(-1) != flat.min(-1)).any())


def frames_move(frames: np.ndarray) -> bool:
    """Whether any sequence of ``frames`` (uint8 [N, T, H, W] or [N, T, H, W, C]) holds a frame that differs
    from its first; a sequence of one frame shows no motion either way, and counts as moving."""
    return frames.shape[1] < 2 or bool((frames[:, 1:] != frames[:, :1]).any())


def _flat_levels(low: int, high: int) -> str:
    """The level of blank frames in words: "one flat level, 0", or, where it changes from frame to frame, "each one
    flat level, from 0 to 255"."""
    return f"one flat level, {low}" if low == high else f"each one flat level, from {low} to {high}"


def blank_error(path: str | os.PathLike[str], low: int, high: int, recorded: bool = False) -> BlankFramesError:
    """Frames that are all blank, their flat levels from ``low`` to ``high``; ``recorded``: a recording's frames
    (``piga-import``), whose advice is not a simulation's."""
    check = ("check the recording (the right file, the camera's exposure, a lens cap)" if recorded else
             "check that the objects are drawn (their size, and colours against the background)")
    return BlankFramesError(f"{path}: every frame is blank ({_flat_levels(low, high)}): the video carries no signal to "
                           f"learn from; {check}")


def still_error(path: str | os.PathLike[str], recorded: bool = False) -> StillFramesError:
    """Frames in which nothing moves; ``recorded`` as :func:`blank_error`."""
    check = ("check the recording (a frozen camera, or one frame repeated)" if recorded else
             "check its source (a recording: a frozen camera, or one frame repeated; a simulation: starts at rest, and "
             "actions too weak to move it)")
    return StillFramesError(f"{path}: nothing moves: in every sequence each frame is the same picture as its first, so "
                           f"the video carries no motion to learn from; {check}")


def _check_frames_signal(frames: h5py.Dataset, path: str | os.PathLike[str], motion: bool) -> None:
    signal, moves = False, not motion
    low, high = 255, 0  # the flat levels of blank frames seen
    for start in range(len(frames)):  # one sequence (one chunk) at a time: a good file stops at the first
        with read_rows(frames, f"sequence {start}"):
            sequence = frames[start : start + 1]  # (1, T, H, W[, C])
        signal = signal or frames_have_signal(sequence)
        moves = moves or frames_move(sequence)
        if signal and moves:
            return
        if not signal:
            low, high = min(low, int(sequence.min())), max(high, int(sequence.max()))
    raise blank_error(path, low, high) if not signal else still_error(path)


def check_frames_have_signal(path: str | os.PathLike[str], motion: bool = True) -> None:
    """Refuses a file whose frames are all blank (each one flat level), which no model can learn
    from and no diagnosis can read, and (``motion``) one in which nothing moves: every sequence one
    picture repeated. Training (:class:`piga.data.windows.SequenceWindows`), the baselines and
    ``piga-diagnose`` run it when they open a file; :class:`DatasetWriter` runs the same test before
    it keeps a file; ``piga-show`` draws a still video (``motion=False``). It reads one sequence of a
    good file: it stops at the first that is not blank and moves.

    Raises:
        DataFormatError: naming the file and the level, or saying that nothing moves.
    """
    with open_data_file(path) as f:
        _check_frames_signal(f["frames"], path, motion)


def check_pixel_pendulum_file(info: DatasetInfo, use: str) -> None:
    """Refuses a file whose frames Gymnasium's pixel pendulum did not render (with the ``env_config``
    that piga-collect records), for ``use``: a baseline that learns from the file and then acts in
    that env, so frames of another env (dm_control's, a scene, an imported recording) would teach it
    pictures it never sees.

    Raises:
        DataFormatError: naming the file, ``use`` and the file's system and env; or frames of another size
            than its ``env_config``'s ``image_size`` (or colour frames): the env would render others.
    """
    from envs import PIXEL_PENDULUM  # here: the schema is read without gymnasium's import

    env_id = info.attrs.get("env_id", PIXEL_PENDULUM)  # files from before env ids hold none
    give = f"give a file that piga-collect wrote of {PIXEL_PENDULUM} (piga-collect --out DATA.h5)"
    if info.system != "pendulum" or env_id != PIXEL_PENDULUM:
        raise DataFormatError(f"{info.path}: {use}; this file is {info.named} from {env_id}: {give}")
    if "env_config" not in info.attrs:
        raise DataFormatError(f"{info.path}: {use}; this file is {info.named} without the 'env_config' that "
                              f"piga-collect records (an imported recording?): {give}")
    config = info.attrs["env_config"]  # a JSON object (inspect_dataset checked it)
    size = config.get("image_size") if isinstance(config, dict) else None
    shape = info.image_shape
    if isinstance(size, int) and not isinstance(size, bool) and shape not in ((size, size), (size, size, 1)):
        gray = len(shape) == 2 or shape[2] == 1
        frames = _frames_text(shape)
        fix = (_image_size_fix(shape[0]) if gray and shape[0] == shape[1]
               else "collect the file again with piga-collect")
        raise DataFormatError(f"{info.path}: attribute 'env_config' says the env renders {size}x{size} gray frames "
                              f"(image_size {size}), but the file's frames are {frames}; {use}: {fix}")


#: How :func:`fingerprint` marks a hash of every frame. A fingerprint without it (16 hex digits alone) hashes the
#: first sequence's frames only: runs of earlier versions keep such ones, and a file is compared with them by it.
FINGERPRINT_MARK = "2:"

#: The frames :func:`fingerprint` reads at a time: whole sequences, about this many bytes decoded.
_FINGERPRINT_BLOCK_BYTES = 64 * 2**20


def fingerprint(path: str | os.PathLike[str], legacy: bool = False) -> str:
    """A short hash of what a file holds, not of where it lies: its /actions, /split and every frame (sha256, hex,
    after :data:`FINGERPRINT_MARK`). A moved or copied file keeps it; another file of the same shape (another seed,
    another recording), or this one with any frame edited in place, does not. It decodes the whole of /frames, a
    block of sequences at a time (0.04 s for 50 default sequences of 40 frames).

    ``legacy``: hashed as earlier versions did (:func:`is_legacy_fingerprint`), the first sequence's frames only (a
    sequence after it edited in place kept the fingerprint, and a resumed run trained on the edited frames). Compare a
    kept fingerprint with :func:`has_fingerprint`."""
    with open_data_file(path) as f:
        frames = f["frames"]
        if legacy:
            with read_rows(frames, "sequence 0"):
                first = frames[0]
            return _digest(f["actions"][()], f["split"][()], first)
        import hashlib

        digest = hashlib.sha256()
        for array in (f["actions"][()], f["split"][()]):
            _update(digest, array)
        digest.update(str((frames.dtype.str, frames.shape)).encode())
        n = frames.shape[0]
        per_sequence = max(1, math.prod(frames.shape[1:]) * frames.dtype.itemsize)
        block = max(1, _FINGERPRINT_BLOCK_BYTES // per_sequence)
        for start in range(0, n, block):
            stop = min(start + block, n)
            try:
                with read_rows(frames, f"sequences {start}..{stop - 1}"):
                    digest.update(np.ascontiguousarray(frames[start:stop]).tobytes())
            except DataFormatError:  # a damaged chunk: named by its sequence
                for i in range(start, stop):
                    with read_rows(frames, f"sequence {i}"):
                        frames[i]  # (read only to find the first that does not decode)
                raise
        return FINGERPRINT_MARK + digest.hexdigest()[:16]


def is_legacy_fingerprint(kept: object) -> bool:
    """Whether a run's ``kept`` fingerprint was taken by an earlier version (no :data:`FINGERPRINT_MARK`): of the
    first sequence's frames only, so that a file is compared with it hashed that way."""
    return isinstance(kept, str) and not kept.startswith(FINGERPRINT_MARK)


def has_fingerprint(path: str | os.PathLike[str], kept: object) -> bool:
    """Whether the file ``path`` holds what a run's ``kept`` fingerprint (:func:`fingerprint`) was taken of, hashed as
    that one was."""
    return isinstance(kept, str) and fingerprint(path, legacy=is_legacy_fingerprint(kept)) == kept


def rewards_fingerprint(path: str | os.PathLike[str]) -> str | None:
    """A short hash of the file's /rewards (as :func:`fingerprint`'s; None without them): what the PlaNet-style
    baseline's reward head learns from, beside the frames and actions that :func:`fingerprint` covers."""
    with open_data_file(path) as f:
        return _digest(f["rewards"][()]) if "rewards" in f else None


def _digest(*arrays: np.ndarray) -> str:
    """sha256 of the arrays' dtypes, shapes and bytes, in order: 16 hex digits."""
    import hashlib

    digest = hashlib.sha256()
    for array in arrays:
        _update(digest, array)
    return digest.hexdigest()[:16]


def _update(digest: Any, array: np.ndarray) -> None:
    """Adds ``array``'s dtype, shape and bytes to the hash ``digest`` (a ``hashlib`` object)."""
    digest.update(str((array.dtype.str, array.shape)).encode())
    digest.update(np.ascontiguousarray(array).tobytes())


#: The true physical parameters that training scores a model against (a relative error each), and that may be signed:
#: the actuation gain is negative for a motor wired the other way. Gravity g, damping, a spring's k and half rest
#: length l and a mass m are >= 0 in piga's conventions (docs/conventions.md: θ = 0 is upright, so g > 0 pulls the
#: pendulum down; a negative damping would feed the motion energy; the scenes' springs and masses are positive).
SIGNED_PARAMETERS = ("actuation_gain",)
NONNEGATIVE_PARAMETERS = ("g", "damping", "k", "l", "m")
#: The largest magnitude a true parameter may have: far beyond what any collection writes (the strongest, a dm_control
#: pendulum's damping term at its lightest tip, shortest pole and strongest damping, is about 3e7), and far enough
#: below float's range that the relative error, the scores and the learning-curve figure stay finite (1e308 overflowed
#: them). Small magnitudes are kept: a weak effect is a valid truth to score against.
MAX_TRUE_PARAMETER = 1e12
#: The smallest magnitude a true gravity or actuation gain may have, but 0: piga-collect's own least (``--gravity-mult``
#: and ``--actuation-gain`` reach 1e-6). Below it, a training's relative error is no number a person reads (g = 1e-30
#: printed "error 105122959613800041538990471380992.00%").
MIN_TRUE_PARAMETER = 1e-6
#: The true parameters that :data:`MIN_TRUE_PARAMETER` bounds (a damping, a weak effect, may be as small as it is).
BOUNDED_BELOW = ("g", "actuation_gain")


def _check_true_parameter(path: str, name: str, value: float) -> None:
    """Refuses a finite true parameter of a file's ``params`` that no model could be scored against: a sign piga's
    conventions do not give it, a magnitude above :data:`MAX_TRUE_PARAMETER`, or a gravity or gain of a magnitude
    below :data:`MIN_TRUE_PARAMETER` (0 is accepted: it has no relative error, and the scores say so)."""
    if name not in SIGNED_PARAMETERS and name not in NONNEGATIVE_PARAMETERS:
        return
    if name in NONNEGATIVE_PARAMETERS and value < 0:
        raise DataFormatError(f"{path}: attribute 'params' gives {name}={value:g}; {name} is >= 0 in piga's conventions "
                              f"(only {', '.join(SIGNED_PARAMETERS)} may be negative)")
    if abs(value) > MAX_TRUE_PARAMETER:
        from envs.fields import number_text  # here: the schema is read without gymnasium's import

        raise DataFormatError(f"{path}: attribute 'params' gives {name}={number_text(value)}, beyond any physical value "
                              f"(at most {MAX_TRUE_PARAMETER:g} in magnitude)")
    if name in BOUNDED_BELOW and 0 < abs(value) < MIN_TRUE_PARAMETER:
        raise DataFormatError(f"{path}: attribute 'params' gives {name}={value:g}, below any physical value (at least "
                              f"{MIN_TRUE_PARAMETER:g} in magnitude, or 0)")


def _finite_float(value: int | float) -> bool:
    """Whether ``value`` is a finite float64: a JSON integer beyond it (10**400) overflows instead of being inf."""
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def split_indices(path: str | os.PathLike[str], split: str) -> np.ndarray:
    """Sequence indices (sorted, int64) that belong to ``split`` ("train", "valid" or "test")."""
    code = _split_code(split)
    with open_data_file(path) as f:
        _validate(f, Path(path))
        return np.flatnonzero(f["split"][()] == code)


def _split_code(split: str) -> int:
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {sorted(SPLITS)}")
    return SPLITS[split]


def _count(limit: int | None) -> int | None:
    """A ``limit`` of sequences: None (all) or a count >= 0 (a negative one sliced from the end: [:-1] read all but one)."""
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 0):
        raise ValueError(f"limit must be None (every sequence) or a count >= 0, got {limit!r}")
    return limit


def read_sequences(path: str | os.PathLike[str], split: str, limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All frames (uint8 [n, T, H, W(, C)]) and actions (float32 [n, T, A]) of one split, in memory; with
    ``limit``, only the split's first ``limit`` sequences are read (a file larger than memory is not loaded
    to evaluate a few of them)."""
    idx = split_indices(path, split)[:_count(limit)]
    with open_data_file(path) as f:
        return _take(f["frames"], idx), _take(f["actions"], idx).astype(np.float32)


def load_actions(path: str | os.PathLike[str], split: str, limit: int | None = None) -> np.ndarray:
    """Actions (float32 [n, T, A]) of one split (its first ``limit`` sequences with ``limit``), without its
    frames: for a reader that streams the frames."""
    idx = split_indices(path, split)[:_count(limit)]
    with open_data_file(path) as f:
        return _take(f["actions"], idx).astype(np.float32)


def load_states(path: str | os.PathLike[str], split: str, limit: int | None = None) -> np.ndarray:
    """Ground-truth states (float32 [n, T, S]) of one split (its first ``limit`` sequences with ``limit``).
    **For evaluation only.**

    Training code must never call this; the test suite trains on a file without ``/states``.

    Raises:
        DataFormatError: the file has no ``/states``.
    """
    idx = split_indices(path, split)
    with open_data_file(path) as f:
        if "states" not in f:
            raise DataFormatError(f"{path}: has no /states (ground truth is optional in the schema)")
        return _take(f["states"], idx[:_count(limit)]).astype(np.float32)


#: The largest reward magnitude a file may hold: a batch's summed squared reward errors stay far inside float32 (a
#: reward of 1e30 made the PlaNet-style loss infinite at its first step; 1e6 trained, if to nothing useful).
MAX_REWARD = 1e15


def load_rewards(path: str | os.PathLike[str], split: str, limit: int | None = None) -> np.ndarray:
    """Rewards (float32 [n, T]) of one split (its first ``limit`` sequences with ``limit``): ``rewards[n, t]``
    is the env's reward for the action after ``frames[n, t]``. For reward-based baselines only; piga's own
    training never calls this.

    Raises:
        DataFormatError: the file has no ``/rewards`` (optional in the schema; ``piga-collect`` writes it),
            or they hold NaN or infinite values, or values beyond :data:`MAX_REWARD` (naming the first: sequence,
            step).
    """
    idx = split_indices(path, split)[:_count(limit)]
    with open_data_file(path) as f:
        if "rewards" not in f:
            if "source_frames" in f.attrs:  # piga-import's: a recording holds no rewards, and none can be collected for it
                raise DataFormatError(f"{path}: has no /rewards, as no imported recording has: reward-based baselines "
                                      "learn from the env's rewards, so they train on files of piga-collect's envs only")
            raise DataFormatError(f"{path}: has no /rewards (reward-based baselines need them; files from "
                                  "piga-collect have them)")
        rewards = _take(f["rewards"], idx).astype(np.float64)  # (n, T); checked before the cast (1e300 overflows float32)
    bad = ~np.isfinite(rewards) | (np.abs(np.nan_to_num(rewards)) > np.finfo(np.float32).max)
    if bad.any():
        i, t = (int(k) for k in np.argwhere(bad)[0])
        raise DataFormatError(f"{path}: /rewards holds NaN or infinite values ({_entries(int(bad.sum()))}; the first: "
                              f"sequence {int(idx[i])}, step {t}: {rewards[i, t]}); fix or recompute the rewards")
    huge = np.abs(rewards) > MAX_REWARD
    if huge.any():  # finite, but a reward head's squared error of them is not (the loss became inf at step 0)
        i, t = (int(k) for k in np.argwhere(huge)[0])
        raise DataFormatError(f"{path}: /rewards holds values beyond ±{MAX_REWARD:.0e} ({_entries(int(huge.sum()))}; the "
                              f"first: sequence {int(idx[i])}, step {t}: {rewards[i, t]:.3g}), whose squared errors "
                              "overflow a reward model's float32 loss; rescale the rewards")
    return rewards.astype(np.float32)


def _take(ds: h5py.Dataset, idx: np.ndarray) -> np.ndarray:
    """Rows ``idx`` of ``ds``; one contiguous read when the rows are a range (none: an empty array).

    Raises:
        DataFormatError: a row cannot be read (:func:`read_rows`)."""
    if not len(idx):
        return np.empty((0, *ds.shape[1:]), ds.dtype)
    with read_rows(ds, f"sequences {int(idx[0])} to {int(idx[-1])}"):
        if idx[-1] - idx[0] + 1 == len(idx):
            return ds[int(idx[0]) : int(idx[-1]) + 1]
        return ds[()][idx] if len(idx) > len(ds) // 4 else np.stack([ds[int(i)] for i in idx])


@contextmanager
def read_rows(ds: h5py.Dataset, which: str) -> Iterator[None]:
    """Names the file, the dataset and ``which`` rows when HDF5 cannot read them: a damaged chunk fails its
    decompression filter with an OSError that names neither.

    Raises:
        DataFormatError: in place of that OSError."""
    try:
        yield
    except OSError:
        raise DataFormatError(f"{ds.file.filename}: {ds.name} of {which} cannot be read (HDF5 cannot decode it): the "
                              "file is damaged; collect, import or copy it again") from None


class DatasetWriter:
    """Writes a file of piga's schema atomically, in slices, so that N can exceed memory.

    Use as a context manager. The file appears at ``path`` only when the block exits without
    error. Before that it is a hidden ``.NAME.partial-PID`` sibling, removed on failure. A file
    whose frames are all blank, or in which nothing moves, is not kept either (:class:`DataFormatError`, as
    :func:`check_frames_have_signal`).

    Args:
        path: target file.
        n_sequences, steps, image_shape, action_dim: N, T, (H, W[, C]), A.
        state_dim: S, or None for a file without ``/states``.
        rewards: whether the file has ``/rewards`` (float32 [N, T]); then :meth:`write` needs them.
        attrs: file attributes; dicts and lists are stored as JSON. ``system`` and ``dt`` are required.
        overwrite: allow replacing an existing file.
        compression: how ``/frames`` is stored (:data:`FrameCodec`; :data:`FRAME_CODEC` by default), one sequence per chunk.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        n_sequences: int,
        steps: int,
        image_shape: tuple[int, ...],
        action_dim: int,
        state_dim: int | None,
        attrs: dict[str, Any],
        overwrite: bool = False,
        compression: FrameCodec = FRAME_CODEC,
        rewards: bool = False,
    ):
        missing = [key for key in REQUIRED_ATTRS if key not in attrs]
        if missing:
            raise ValueError(f"DatasetWriter: attrs lack required keys {missing}")
        if n_sequences < 1 or steps < 1:
            raise ValueError(f"DatasetWriter: need N >= 1 and T >= 1, got N={n_sequences}, T={steps}")
        self.path = Path(path)
        self.shape = (n_sequences, steps)
        self.image_shape = tuple(image_shape)
        self.action_dim, self.state_dim = action_dim, state_dim
        self.attrs = {"seed": -1, "piga_version": __version__, "command": "", "params": {}, **attrs}
        self.overwrite = overwrite
        codec_options(compression)  # refuses an unknown codec before anything is written
        self.compression = compression
        self.rewards = rewards
        self._ctx: Any = None
        self._file: h5py.File | None = None
        self._written = np.zeros(n_sequences, dtype=bool)
        self._split_set = False
        self._signal = False
        self._moves = False
        self._levels = (255, 0)  # the lowest and highest flat level of the blank frames written

    def __enter__(self) -> DatasetWriter:
        self._ctx = atomic_output(self.path, overwrite=self.overwrite)
        tmp = self._ctx.__enter__()
        n, t = self.shape
        # no chunk cache: each slice's chunks (one sequence each, written whole) go to disk compressed as written, so
        # the disk check before a slice counts every byte the file has taken (a cache of 1 MiB a dataset held
        # chunks back until close, and the check had to keep that room free on top)
        f = h5py.File(tmp, "w", rdcc_nbytes=0)
        self._file = f
        opts = codec_options(self.compression)
        f.create_dataset("frames", (n, t, *self.image_shape), dtype=np.uint8, chunks=(1, t, *self.image_shape), **opts)
        f.create_dataset("actions", (n, t, self.action_dim), dtype=np.float32)
        if self.state_dim is not None:
            f.create_dataset("states", (n, t, self.state_dim), dtype=np.float32)
        if self.rewards:
            f.create_dataset("rewards", (n, t), dtype=np.float32)
        f.create_dataset("split", (n,), dtype=np.int8)
        for key, value in self.attrs.items():
            f.attrs[key] = json.dumps(value) if isinstance(value, (dict, list, tuple)) else value
        return self

    def write(self, start: int, frames: np.ndarray, actions: np.ndarray, states: np.ndarray | None = None,
              rewards: np.ndarray | None = None) -> None:
        """Writes sequences ``start .. start + len(frames)``; arrays as in the schema."""
        assert self._file is not None, "DatasetWriter.write outside its `with` block"
        stop = start + len(frames)
        if frames.shape[1:] != (self.shape[1], *self.image_shape):
            raise ValueError(f"frames slice has shape {frames.shape}, expected (n, {self.shape[1]}, {self.image_shape})")
        chunks = self._chunks(frames)
        frame_bytes = frames.nbytes if chunks is None else sum(len(chunk) for chunk in chunks)
        self._check_room(frame_bytes + sum(a.nbytes for a in (actions, states, rewards) if a is not None), len(frames))
        if chunks is None:
            self._file["frames"][start:stop] = frames
        else:  # each sequence's chunk as compressed for the check, not compressed by HDF5 a second time
            corner = (0,) * (frames.ndim - 1)
            for i, chunk in enumerate(chunks):
                self._file["frames"].id.write_direct_chunk((start + i, *corner), chunk)
        self._file["actions"][start:stop] = actions
        if self.state_dim is not None:
            if states is None:
                raise ValueError("this file has /states; pass them to write()")
            self._file["states"][start:stop] = states
        if self.rewards:
            if rewards is None:
                raise ValueError("this file has /rewards; pass them to write()")
            self._file["rewards"][start:stop] = rewards
        self._written[start:stop] = True
        if not self._signal and len(frames):
            self._signal = frames_have_signal(frames)
            self._levels = (min(self._levels[0], int(frames.min())), max(self._levels[1], int(frames.max())))
        self._moves = self._moves or (len(frames) > 0 and frames_move(frames))

    def _chunks(self, frames: np.ndarray) -> list[bytes] | None:
        """With gzip, each sequence of ``frames`` (n, T, ...) as its chunk in the file: compressed by zlib at the
        codec's level, the stream HDF5's deflate filter writes (its only filter here), so that the disk check counts
        the bytes written and HDF5 takes them as they are (``write_direct_chunk``). None otherwise: HDF5 stores the
        frames raw, or with LZF at most about their raw size."""
        if not self.compression.startswith("gzip"):
            return None
        level = int(self.compression.split("-")[1])
        return [zlib.compress(np.ascontiguousarray(sequence, dtype=np.uint8).data, level) for sequence in frames]

    def _check_room(self, disk_bytes: int, sequences: int) -> None:
        """Refuses a slice of ``sequences`` where the file's disk has less free space than :func:`write_room` (the
        ``disk_bytes`` the slice takes in the file, and :func:`write_margin`), before HDF5 runs out.

        Raises:
            piga.io.resources.ResourceError: the free space and the need, in numbers (the disk need not be full).
        """
        from piga.io.resources import ResourceError, format_apart, format_bytes

        assert self._file is not None
        free = shutil.disk_usage(Path(self._file.filename).parent).free
        margin = write_margin(self.shape[0])
        if free < disk_bytes + margin:
            shown_need, shown_free = format_apart(disk_bytes + margin, free)
            raise ResourceError(f"{self.path}: its disk has {shown_free} free, less than the "
                                f"{shown_need} that writing the next {sequences} sequences "
                                f"takes ({format_bytes(disk_bytes)} in the file, and {format_bytes(margin)} kept free "
                                "for HDF5's metadata, which must not run out mid-write); free some space, or write "
                                "elsewhere")

    def set_split(self, split: np.ndarray) -> None:
        """Sets ``/split`` (int8 [N], codes of :data:`SPLITS`)."""
        assert self._file is not None, "DatasetWriter.set_split outside its `with` block"
        self._file["split"][:] = np.asarray(split, dtype=np.int8)
        self._split_set = True

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        assert self._file is not None and self._ctx is not None
        try:
            self._file.close()
        except (OSError, RuntimeError) as closing:  # its last flush failed (a full disk): the file is not kept
            if exc_type is None:
                error = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path)) if "errno = 28" in str(closing) \
                    else closing
                self._ctx.__exit__(type(error), error, None)
                raise error from None
        if exc_type is not None:  # removes the partial file; the exception propagates
            self._ctx.__exit__(exc_type, exc, tb)
            return
        if not (self._written.all() and self._split_set):
            error = RuntimeError(
                f"DatasetWriter closed with {int((~self._written).sum())} unwritten sequences"
                + ("" if self._split_set else " and no split")
            )
            self._ctx.__exit__(RuntimeError, error, None)
            raise error
        if not (self._signal and self._moves):  # nothing to learn from: the file is not kept (check_frames_have_signal)
            blank = blank_error(self.path, *self._levels) if not self._signal else still_error(self.path)
            self._ctx.__exit__(DataFormatError, blank, None)
            raise blank
        self._ctx.__exit__(None, None, None)
        remember_written(self.path)

