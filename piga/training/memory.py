"""The memory a training run of ``piga-train-model`` needs, checked before the model is built.

The model's parameters grow with the frames' pixels (the encoder's first layer reads every pixel), and so do the
activations that a training window keeps for its backward pass: frames of 1024x1024 took 24 GB with a batch of 4
before the kernel killed the process without a word. The need, refused before anything is allocated:

- per parameter: :data:`piga.io.resources.TRAINING_BYTES_PER_PARAMETER` (weights, gradients, Adam's two moments),
  4 bytes more for the averaged copy of the final steps (``TrainConfig.average_fraction``), and 4 for the backward
  pass's temporaries (a weight's gradient is made beside the one it adds to);
- per window of the batch: twice the bytes autograd saves (:func:`piga.world.variants.activation_bytes`), the
  gradients of those activations being made as the backward pass frees them.

Checked against one real forward and backward pass (fast preset, one thread) by ``benchmarks/training_memory.py``
(results/training_memory.md): the count for the same pass is 1.08 to 1.62 times the rise of the process's resident
memory, from 64x64 frames with a batch of 32 to 1024x1024 with a batch of 1.
"""

from __future__ import annotations

from piga.io import resources
from piga.io.resources import TRAINING_BYTES_PER_PARAMETER, ResourceError, format_bytes

#: Bytes per parameter beyond :data:`TRAINING_BYTES_PER_PARAMETER`: the backward pass's temporaries.
BACKWARD_BYTES_PER_PARAMETER = 4
#: Bytes per parameter of the averaged copy, where the run averages its last steps.
AVERAGE_BYTES_PER_PARAMETER = 4
#: The activations' bytes in the backward pass, per byte that autograd saves.
ACTIVATION_FACTOR = 2


def training_need(parameters: int, activations: int, batch: int, averaged: bool) -> tuple[float, float]:
    """(the parameters' part, the batch's part) of a training run's memory, in bytes, for ``parameters`` trainable
    parameters and ``activations`` saved bytes per window (``averaged``: the run keeps an averaged copy)."""
    per_parameter = (TRAINING_BYTES_PER_PARAMETER + BACKWARD_BYTES_PER_PARAMETER
                     + (AVERAGE_BYTES_PER_PARAMETER if averaged else 0))
    return float(parameters * per_parameter), float(ACTIVATION_FACTOR * activations * batch)


def check_training_fits(parameters: int, activations: int | None, batch: int, averaged: bool, frames: str,
                        sizes: tuple[str, ...] = ()) -> None:
    """Refuses a run whose parameters and batch (:func:`training_need`) need more memory than is available, saying
    which to lower: ``--batch-size`` where a smaller batch fits, the frames' size (``frames``, e.g. "1024x1024"), and
    the model's size options that the user raised (``sizes``, e.g. ("--video-lstm-scale",)).

    Raises:
        ResourceError: one line, with the need, its parts and what is available.
    """
    available = resources.available_memory()
    if available is None:
        return
    fixed, batched = training_need(parameters, activations or 0, batch, averaged)
    if fixed + batched <= available:
        return
    per_window = batched / batch
    fits = int((available - fixed) // per_window) if per_window and available > fixed + per_window else 0
    lower = ([f"--batch-size to {fits} or less"] if fits else []) + list(sizes)
    frames_advice = "collect or import the frames at a smaller --image-size (piga-collect, piga-import)"
    advice = f"lower {' or '.join(lower)}, or {frames_advice}" if lower else frames_advice
    raise ResourceError(f"training on frames of {frames} needs about {format_bytes(fixed + batched)} of memory (the "
                        f"model's {parameters / 1e6:.3g}M parameters, which grow with the frames' pixels, with their "
                        f"gradients and Adam's moments: {format_bytes(fixed)}; the activations of a batch of {batch}: "
                        f"{format_bytes(batched)}), but {format_bytes(available)} is available; {advice}")


__all__ = ["ACTIVATION_FACTOR", "AVERAGE_BYTES_PER_PARAMETER", "BACKWARD_BYTES_PER_PARAMETER", "check_training_fits",
           "training_need"]
