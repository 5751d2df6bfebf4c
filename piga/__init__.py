"""piga: physics-as-inverse-graphics. Learn a system's parameters and states from video.

A small public API, loaded on first use so that ``import piga`` stays cheap (torch, Gymnasium
and h5py are imported only when a name that needs them is used)::

    import torch

    import piga

    model, checkpoint = piga.load_model("runs/pendulum")  # a piga-train-model run folder
    frames, actions = piga.read_sequences("data/pendulum.h5", "test")  # uint8 (N, T, H, W), (N, T, A)
    x = piga.frames_to_float(torch.from_numpy(frames[:, :4]), channels=1)  # (N, 4, 1, H, W)
    theta = model.encode(x)  # (N, 4, 1, 1): the angle read from each frame
    future = model.predict(theta, torch.from_numpy(actions[:, 3:13]), steps=10)  # (N, 10, 1, 1)

The subpackages (``piga.world``, ``piga.data``, ``piga.training``, ...) are importable as attributes
too, and hold the details.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_API: dict[str, str] = {
    # runs and the model
    "load_model": "piga.io.runs",
    "PhysicsModel": "piga.world.model",
    "ModelConfig": "piga.world.model",
    "frames_to_float": "piga.world.model",
    "rollout": "piga.world.physics",
    # data
    "collect": "piga.data.collect",
    "CollectConfig": "piga.data.collect",
    "train": "piga.training.train",
    "TrainConfig": "piga.training.train",
    "write_run_report": "piga.training.report",
    "inspect_dataset": "piga.data.schema",
    "read_sequences": "piga.data.schema",
    "load_states": "piga.data.schema",
    "DatasetInfo": "piga.data.schema",
    "DataFormatError": "piga.data.schema",
    "SequenceWindows": "piga.data.windows",
    # environments
    "make_pixel_pendulum": "envs.pendulum",
    "PixelPendulumConfig": "envs.pendulum",
    "make_dmc_pendulum": "envs.dmc",
    "DMCPendulumConfig": "envs.dmc",
}

__all__ = ["__version__", *_API]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names load lazily (__getattr__)
    from envs.dmc import DMCPendulumConfig, make_dmc_pendulum
    from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
    from piga.data.collect import CollectConfig, collect
    from piga.data.schema import DataFormatError, DatasetInfo, inspect_dataset, load_states, read_sequences
    from piga.world.model import ModelConfig, PhysicsModel, frames_to_float
    from piga.world.physics import rollout
    from piga.io.runs import load_model
    from piga.training.report import write_run_report
    from piga.training.train import TrainConfig, train
    from piga.data.windows import SequenceWindows


def __getattr__(name: str) -> Any:
    """Loads a public name, or a subpackage (``piga.data``, ``piga.training``, ...), on first use."""
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
