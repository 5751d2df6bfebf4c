"""Reading a training run: the model in ``RUN_DIR/checkpoint.pt`` and what the run says about it.

A run folder is written by :func:`piga.training.train.train`. Everything that *uses* a trained model (control,
goal images, the gap diagnosis, benchmarks) reads it through this module, never through the
training code:

- :func:`load_model`: the model (eval mode) and its checkpoint;
- :func:`training_reconstruction_mse`: the autoencoder's own per-frame error in its last epoch;
- :func:`training_steps`: how many optimiser steps the run took;
- :func:`training_blank_mse`: the error of drawing no object on the run's training frames (its error scale);
- :func:`training_arrow`: whether the training frames showed Gymnasium's torque arrow;
- :func:`nominal_of`: the identified physics (:class:`Nominal`) that a diagnosis starts from.
"""

from __future__ import annotations

import functools
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, overload

import torch

from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint, recorded_data_path, unreadable
from piga.io.choices import check_choices
from piga.world.model import FrameModel, ModelConfig, PhysicsModel
from piga.world.variants import NO_PHYSICS, build_model


@dataclass(frozen=True)
class Nominal:
    """The identified model's pendulum physics: θ̈ = 1.5·g·sin(θ + φ) + 3·a·u − 3·b·θ̇, ``substeps`` steps of
    ``integrator`` per frame."""

    g: float
    """Gravity."""
    a: float
    """Actuation gain."""
    offset: float
    """φ: Gymnasium's θ = model θ + φ."""
    dt: float
    """Seconds per frame."""
    substeps: int = 1
    """Integrator substeps per frame."""
    b: float = 0.0
    """The model's own viscous damping (1/s; 0: none learned): θ̈ = ... − 3·b·θ̇."""
    integrator: Literal["euler", "rk4"] = "euler"
    """"euler" (semi-implicit) or "rk4", as :mod:`piga.world.physics`."""
    velocity_hold: bool = False
    """The model reads the velocity at a frame through its integrator (``ModelConfig.velocity_hold``)."""

    def __post_init__(self) -> None:
        check_choices(self)


@overload
def load_model(run_dir: str | os.PathLike[str], any_model: Literal[False] = False) -> tuple[PhysicsModel, dict[str, Any]]: ...


@overload
def load_model(run_dir: str | os.PathLike[str], any_model: bool) -> tuple[FrameModel, dict[str, Any]]: ...


def load_model(run_dir: str | os.PathLike[str], any_model: bool = False) -> tuple[FrameModel, dict[str, Any]]:
    """Rebuilds a trained model from ``RUN_DIR/checkpoint.pt``; returns it (eval mode) and the checkpoint.

    Everything that uses the identified physics (control, goal images, diagnosis, the benchmarks) reads
    a run this way, so a run of a baseline without physical parameters (``piga-train-model --model
    video-lstm`` or ``in-ig``) is refused here with one line. ``any_model``: return such a model too (for
    resuming and evaluating it).

    Raises:
        ValueError: a baseline's run without ``any_model``, or an unreadable checkpoint.
    """
    ckpt = read_checkpoint(run_dir, RunKind.PIGA)
    try:
        model = build_model(ModelConfig.from_dict(ckpt["model_config"]))
        model.load_state_dict(ckpt["model"])
    except Exception as exc:  # a foreign or damaged payload
        raise unreadable(Path(run_dir) / CHECKPOINT, RunKind.PIGA, exc) from None
    # Training stops at a non-finite loss before it saves, so such weights mean a damaged file; they would
    # plan, diagnose or resume with NaN physics (g = nan reached the physics' own check, unnamed).
    bad = [name for name, value in model.state_dict().items() if value.is_floating_point() and not torch.isfinite(value).all()]
    if bad:
        raise ValueError(f"{Path(run_dir) / CHECKPOINT}: holds NaN or infinite weights ({', '.join(bad[:3])}"
                         f"{', ...' if len(bad) > 3 else ''}); the file is damaged: train the run again")
    # finite weights can still give physics that is not (a log g of 800 is g = inf, which planned, exit 0)
    infinite = {name: value for name, value in model.physical_parameters().items() if not math.isfinite(value)}
    if infinite:
        raise ValueError(f"{Path(run_dir) / CHECKPOINT}: its physical parameters are not finite numbers ("
                         f"{', '.join(f'{name} = {value}' for name, value in infinite.items())}); the file is damaged: "
                         "train the run again")
    if not (any_model or model.has_physics):
        raise ValueError(f"{run_dir} holds a piga-train-model --model {model.config.architecture} run: "
                         f"{NO_PHYSICS[model.config.architecture].split(': ')[0]}, without the physical parameters "
                         "(g, a, ...) that this needs; give a run trained with --model piga")
    model.eval()
    return model, ckpt


def _checkpoint_step(path: Path) -> int | None:
    """The optimiser step that a piga checkpoint holds, or None where it cannot say (no file, unreadable: the
    commands that load the model say why). Memory-mapped: only the entries read are."""
    if not path.is_file():  # (a pipe in its place would be waited on for ever: the loader refuses it)
        return None
    try:
        state = torch.load(path, map_location="cpu", weights_only=False, mmap=True).get("state")
    except Exception:  # any unreadable file: the loader of the model names the cause
        return None
    step = state.get("step") if isinstance(state, dict) else None
    return step if isinstance(step, int) and not isinstance(step, bool) else None


def convergence_warning(run_dir: str | os.PathLike[str]) -> str | None:
    """One line when the run's metrics.json says it did not converge (``converged: false``), else None.

    Every command and benchmark that reads a run prints it, so a run that did not identify its
    parameters cannot pass unnoticed. A run with a checkpoint but without the record was stopped before its end
    (interrupted, or killed) and never checked: that is said too (a run still training is told apart by its lock,
    :func:`piga.cli.common.warn_if_unconverged`). A record that cannot be read gives a line saying that its
    convergence is unknown.

    Raises:
        ValueError: ``metrics.json`` is a pipe, a device or a folder (:func:`~piga.io.checkpoint.check_run_file`).
    """
    import json

    from piga.io.checkpoint import CHECKPOINT, check_run_file, divergence_warning, unreadable_record

    path = Path(run_dir) / "metrics.json"
    check_run_file(path)
    try:
        metrics = json.loads(path.read_text())
    except FileNotFoundError:
        if not (Path(run_dir) / CHECKPOINT).exists():
            return None
        if not (Path(run_dir) / "config.json").exists():  # piga.train writes neither record (piga-train-model both)
            return (f"warning: the run {run_dir} has no metrics.json, so it was never checked for convergence (a run "
                    "trained through the library's piga.train is checked by piga.write_run_report, which writes it)")
        if (diverged := divergence_warning(run_dir)) is not None:
            return f"warning: {diverged}"
        return (f"warning: the run {run_dir} has no metrics.json: it stopped before its end (interrupted, or its report "
                "not written) and was never checked for convergence; this used its last checkpoint (continue it with "
                "--resume)")
    except (OSError, ValueError) as exc:
        return f"warning: {path} cannot be read ({unreadable_record(exc)}); whether the run converged is unknown"
    if not isinstance(metrics, dict):
        return f"warning: {path} is not a metrics record; whether the run converged is unknown"
    if "converged" not in metrics:  # an edited record ({}): it was taken as converged
        return f"warning: {path} does not say whether the run converged (it has no 'converged'); whether it did is unknown"
    converged = metrics["converged"]
    if not isinstance(converged, bool):  # an edited record: "no" would read as converged
        return f"warning: {path} gives 'converged' as {converged!r}, not true or false; whether the run converged is unknown"
    training = metrics.get("training")
    steps = training.get("steps") if isinstance(training, dict) else None
    held = _checkpoint_step(Path(run_dir) / CHECKPOINT)
    if isinstance(steps, int) and not isinstance(steps, bool) and held is not None and steps != held:
        # another run's checkpoint put beside this record: its verdict was taken for a model it never judged
        return (f"warning: {path} judged a model of {steps:,} steps, but {CHECKPOINT} holds one of {held:,} (another "
                "run's, or replaced since); whether this model converged is unknown")
    if converged:
        return None
    convergence = metrics.get("convergence")
    reason = convergence.get("reason") if isinstance(convergence, dict) else None
    reason = reason if isinstance(reason, str) else "no reason recorded"
    return f"warning: the run {run_dir} did not converge: {reason}"


def training_reconstruction_mse(model: PhysicsModel, checkpoint: dict[str, Any] | None) -> float:
    """The model's own per-frame reconstruction MSE in its last training epoch (0 if unknown)."""
    try:
        history = checkpoint["state"]["history"]  # type: ignore[index]
        frames = model.config.input_frames if model.config.rec_frames == "input" else model.config.window
        return float(history[-1]["loss_rec"]) / frames
    except (TypeError, KeyError, IndexError):
        return 0.0


def training_steps(checkpoint: dict[str, Any] | None) -> int | None:
    """Optimiser steps the run took (None: the checkpoint does not say)."""
    try:
        return int(checkpoint["state"]["step"])  # type: ignore[index]
    except (TypeError, KeyError, ValueError):
        return None


def training_data_path(checkpoint: dict[str, Any] | None) -> str | None:
    """The training file that the checkpoint names, if it is still there and still the run's own (else None).

    The path is as training was given it, relative to the folder it ran in, which the checkpoint records beside it
    (:func:`~piga.io.checkpoint.recorded_data_path`); an older checkpoint does not, and from another folder its path
    can name another file (a diagnosis read its "own training file" reference off a file of other effects). So the
    file must also have the fingerprint the checkpoint keeps (:func:`piga.data.schema.fingerprint`), where it keeps
    one. :func:`with_training_file` finds it where the run was moved with it."""
    data = (checkpoint or {}).get("data") or {}
    path = recorded_data_path(data)
    return path if path is not None and _is_training_file(path, data) else None


def _is_training_file(path: str | os.PathLike[str], data: dict[str, Any]) -> bool:
    """Whether ``path`` is a file with the fingerprint that the checkpoint's ``data`` record keeps (where it keeps one)."""
    if not (str(path) and os.path.isfile(path)):
        return False
    return "fingerprint" not in data or _file_fingerprint(path, data["fingerprint"]) == data["fingerprint"]


def _file_fingerprint(path: str | os.PathLike[str], like: object = None) -> str | None:
    """:func:`_fingerprint` of the file ``path`` as it is now, hashed as the kept fingerprint ``like`` was."""
    from piga.data.schema import is_legacy_fingerprint

    stat = os.stat(path)
    return _fingerprint(str(path), stat.st_ino, stat.st_size, stat.st_mtime_ns, is_legacy_fingerprint(like))


def with_training_file(checkpoint: dict[str, Any], run_dir: str | os.PathLike[str],
                       given: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """``checkpoint`` with its training file's path as found from here (a copy; the file on disk is not changed).

    The path is recorded as training was given it, with the folder it ran in (:func:`training_data_path`). Where it
    does not lead to the file from here, these are tried, each only if it has the fingerprint the checkpoint keeps:
    the file's name beside the run folder or inside it (runs are often moved with their data), and the recorded
    path read from the run folder's parent. ``given`` (a command's ``--training-data``) is taken first.

    Raises:
        ValueError: ``given`` is not the file the run was trained on (another fingerprint), or not a file.
    """
    data = dict(checkpoint.get("data") or {})
    recorded = recorded_data_path(data)
    if given is not None:
        if os.path.isdir(given):
            raise ValueError(f"{given} is a folder: give the data file the model was trained on")
        if not os.path.isfile(given):
            raise ValueError(f"{given}: no such file (give the data file the model was trained on)")
        if "fingerprint" in data and _file_fingerprint(given, data["fingerprint"]) is None:
            raise ValueError(f"{given} is not a piga data file (HDF5 with /frames and /actions): give the file the "
                             "model was trained on")
        if not _is_training_file(given, data):
            raise ValueError(f"{given} is not the file {run_dir} was trained on (its content differs from the one "
                             f"recorded at training{'' if recorded is None else f', {recorded}'})")
        return {**checkpoint, "data": {**data, "path": os.path.abspath(given)}}  # (absolute: whatever its "folder")
    if recorded is None or training_data_path(checkpoint) is not None or "fingerprint" not in data:
        return checkpoint  # found as recorded, or nothing to find it by
    run = Path(run_dir)
    name = Path(recorded).name
    for candidate in (run.parent / name, run / name, run.parent / data["path"]):
        if _is_training_file(candidate, data):
            return {**checkpoint, "data": {**data, "path": os.path.abspath(candidate)}}
    return checkpoint


@functools.lru_cache(maxsize=8)
def _fingerprint(path: str, inode: int, size: int, mtime_ns: int, legacy: bool = False) -> str | None:
    """:func:`piga.data.schema.fingerprint` of ``path`` as it is now (its inode, size and time key the cache: a
    command asks for its run's training file several times), or None where it is not a data file any more. With
    ``legacy``, hashed as a run of an earlier version hashed its file (the first sequence's frames only)."""
    from piga.data.schema import fingerprint

    try:
        return fingerprint(path, legacy=legacy)
    except (OSError, ValueError, KeyError):
        return None


def training_blank_mse(model: PhysicsModel, checkpoint: dict[str, Any] | None, max_sequences: int = 64) -> float | None:
    """The scale of the run's reconstruction error: the per-frame MSE of its training frames against
    the model's own background (the per-pixel median it subtracts, :mod:`piga.world.encoder`), i.e. the
    error of a render that draws no object at all. Read from the first ``max_sequences`` train
    sequences of the training file named in the checkpoint; None if that file is gone or unreadable."""
    import numpy as np

    from piga.data.schema import open_data_file, split_indices
    from piga.world.model import frames_to_float

    path = training_data_path(checkpoint)
    if path is None:
        return None
    try:
        rows = split_indices(path, "train")[:max_sequences]
        with open_data_file(path) as f:
            raw = f["frames"][np.sort(rows)]
    except (OSError, KeyError, ValueError):
        return None
    if len(raw) == 0:
        return None
    x = frames_to_float(torch.from_numpy(raw), model.config.channels)  # (n, T, C, H, W)
    if x.shape[2:] != model.encoder.background.shape:
        return None
    return float(((x - model.encoder.background) ** 2).mean())


def training_env_config(checkpoint: dict[str, Any] | None) -> dict[str, Any]:
    """The ``env_config`` of the run's training file: as the checkpoint keeps it, else (an older checkpoint) read from
    the file it names, if that file is still there and has one, else {} (a file of another source, or gone)."""
    from piga.data.schema import open_data_file

    kept = ((checkpoint or {}).get("data") or {}).get("env_config")
    if isinstance(kept, dict):
        return kept
    path = training_data_path(checkpoint)
    if path is None:
        return {}
    try:
        with open_data_file(path) as f:
            config = json.loads(f.attrs["env_config"])
    except (OSError, KeyError, ValueError):
        return {}
    return config if isinstance(config, dict) else {}


def training_arrow(checkpoint: dict[str, Any] | None) -> bool:
    """Whether the data the model was identified on showed Gymnasium's torque arrow: from the training file's
    ``env_config`` (:func:`training_env_config`), else True (Gymnasium's own picture, the pixel pendulum's default)."""
    return bool(training_env_config(checkpoint).get("draw_torque_arrow", True))


def nominal_of(model: PhysicsModel) -> Nominal:
    """The identified model's physics: g, a, φ, dt, substeps, and its damping b and integrator."""
    p = model.physical_parameters()
    return Nominal(p["g"], p["a"], p.get("offset", 0.0), model.config.dt, model.config.substeps,
                   float(p.get("b", 0.0)), model.config.integrator, bool(model.config.velocity_hold))


__all__ = ["Nominal", "convergence_warning", "load_model", "nominal_of", "training_arrow", "training_env_config", "training_blank_mse",
           "training_reconstruction_mse", "training_steps"]
