"""Where a model trains: the ``--device`` choice, and the torch device it stands for.

| choice | device |
|---|---|
| ``"auto"`` | the first CUDA device when torch sees one, else the CPU (without a word) |
| ``"cpu"`` | the CPU |
| ``"cuda"`` | the first CUDA device; without one, a one-line ``ValueError`` |

The device is how a run is computed, not part of its recipe: a run trained on a GPU resumes on the
CPU and the other way round, and every checkpoint is read onto the CPU first
(:func:`piga.io.checkpoint.read_checkpoint`), where control and diagnosis run. Random draws come
from CPU generators on every device, so a run's sampling does not depend on where it trains.

This module imports torch only when a device is resolved, so that command lines build their
parsers quickly.
"""

from __future__ import annotations

import itertools
import os
import warnings
from typing import TYPE_CHECKING, Any, Literal, get_args

if TYPE_CHECKING:
    import torch

__all__ = ["DEVICES", "DEVICE_HELP", "Device", "MAX_THREADS", "cuda_available", "module_device", "resolve_device",
           "set_threads"]

Device = Literal["auto", "cpu", "cuda"]
"""A device choice (the module docstring's table)."""
#: The device choices, in the order the help lists them.
DEVICES: tuple[Device, ...] = get_args(Device)
#: Most torch CPU threads a run takes: this machine's CPUs (more only slows it down, and a huge count crashed torch's
#: thread pool).
MAX_THREADS = max(1, os.cpu_count() or 1)
#: The help of every ``--device`` option.
DEVICE_HELP = ("where to train: auto (a CUDA GPU when torch sees one, else the CPU), cpu, or cuda (refused without a "
               "GPU); not part of the recipe, so --resume may change it")


def cuda_available() -> bool:
    """Whether torch sees a CUDA device. Quiet: a CUDA build of torch on a machine without a driver
    warns when asked, and ``auto`` must say nothing on a CPU-only machine."""
    import torch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bool(torch.cuda.is_available())


def resolve_device(choice: str) -> torch.device:
    """The torch device of a choice of :data:`DEVICES`.

    Raises:
        ValueError: an unknown choice, or ``"cuda"`` on a machine where torch sees no CUDA device
            (one line naming ``--device`` and the way out).
    """
    import torch

    if choice not in DEVICES:
        raise ValueError(f"--device must be one of {', '.join(DEVICES)}; got {choice!r}")
    if choice == "cpu":
        return torch.device("cpu")
    if cuda_available():
        return torch.device("cuda", torch.cuda.current_device())
    if choice == "cuda":
        raise ValueError("--device cuda: no CUDA device is available (torch.cuda.is_available() is False); "
                         "use --device cpu or auto")
    return torch.device("cpu")


def set_threads(threads: int, owner: str) -> None:
    """Sets torch's CPU threads for a run (0: torch's default). More than this machine's CPUs is refused, naming
    ``owner``'s field: it only slows a run down, and a huge count crashed torch's thread pool (a segfault at 100000,
    libgomp's "Thread creation failed" at 20000), where the commands' ``--threads`` had refused it."""
    import torch

    if threads > MAX_THREADS:
        raise ValueError(f"{owner}.threads must be at most this machine's {MAX_THREADS} CPUs (0: torch's choice), got "
                         f"{threads}")
    if threads:
        torch.set_num_threads(threads)


def module_device(module: Any) -> torch.device:
    """The device of a module's first parameter (or buffer); the CPU for a module that has neither."""
    import torch

    for tensor in itertools.chain(module.parameters(), module.buffers()):
        return tensor.device
    return torch.device("cpu")
