"""The memory a training run of ``piga-train-model`` needs, checked before the model is built.

The model's parameters grow with the frames' pixels (the encoder's first layer reads every pixel), and so do the
activations that a training window keeps for its backward pass: frames of 1024x1024 took 24 GB with a batch of 4
before the kernel killed the process without a word. The need, refused before anything is allocated:

- per parameter: :data:`piga.io.resources.TRAINING_BYTES_PER_PARAMETER` (weights, gradients, Adam's two moments),
  4 bytes more for the averaged copy of the final steps (``TrainConfig.average_fraction``), 4 for the backward
  pass's temporaries (a weight's gradient is made beside the one it adds to), and 8 for Adam's step (torch's CPU
  Adam makes the square root of a weight's second moment and its quotient, each the size of the weight; the
  encoder's first layer holds most of the parameters at large frames);
- per window of the batch: twice the bytes autograd saves (:func:`piga.world.variants.activation_bytes`), the
  gradients of those activations being made as the backward pass frees them;
- the process itself: torch, the libraries and the command before its model (:data:`PROCESS_BYTES`);
- all of it times :data:`ALLOCATOR_SLACK`.

Checked by ``benchmarks/training_memory.py`` (results/training_memory.md) against the peak resident memory of whole
``piga-train-model`` runs (fast preset, one thread, four steps: the count is 1.12 to 1.22 times their peak, from
512x512 to 64x64) and of single forward and backward passes (1.23 to 1.32 times). The count for one pass alone
(8 bytes per parameter and the activations) missed Adam's step: frames of 1024x1024 and a batch of 2, counted at
20.9 GiB, were killed by the kernel at 23.9 GB.
"""

from __future__ import annotations

from piga.io import resources
from piga.io.resources import TRAINING_BYTES_PER_PARAMETER, ResourceError, format_apart, format_bytes

#: Bytes per parameter beyond :data:`TRAINING_BYTES_PER_PARAMETER`: the backward pass's temporaries.
BACKWARD_BYTES_PER_PARAMETER = 4
#: Bytes per parameter of the averaged copy, where the run averages its last steps.
AVERAGE_BYTES_PER_PARAMETER = 4
#: Bytes per parameter of Adam's step: the square root of the second moment, and its quotient by the bias correction.
OPTIMISER_STEP_BYTES_PER_PARAMETER = 8
#: The command's own resident memory beside its model: torch, the libraries, the data and the plan (the 64x64 whole run
#: of results/training_memory.md peaks at 0.72 GiB, of which its parameters and activations are under 0.3 GiB).
PROCESS_BYTES = 2**29
#: The count times this: the memory allocator's slack (freed blocks it keeps, pages in use in part). Without it the
#: count is 1.02 to 1.11 times the whole runs' peaks (results/training_memory.md's ratios over 1.1), a margin of 2% at
#: 512x512, where the parameters weigh most.
ALLOCATOR_SLACK = 1.1
#: The activations' bytes in the backward pass, per byte that autograd saves.
ACTIVATION_FACTOR = 2


def training_need(parameters: int, activations: int, batch: int, averaged: bool) -> tuple[float, float]:
    """(the parameters' and the process's part, the batch's part) of a training run's memory, in bytes, for
    ``parameters`` trainable parameters and ``activations`` saved bytes per window (``averaged``: the run keeps an
    averaged copy)."""
    per_parameter = (TRAINING_BYTES_PER_PARAMETER + BACKWARD_BYTES_PER_PARAMETER + OPTIMISER_STEP_BYTES_PER_PARAMETER
                     + (AVERAGE_BYTES_PER_PARAMETER if averaged else 0))
    return (ALLOCATOR_SLACK * (parameters * per_parameter + PROCESS_BYTES),
            ALLOCATOR_SLACK * ACTIVATION_FACTOR * activations * batch)


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
    shown_need, shown_available = format_apart(fixed + batched, available)
    raise ResourceError(f"training on frames of {frames} needs about {shown_need} of memory (the "
                        f"model's {parameters / 1e6:.3g}M parameters, which grow with the frames' pixels, with their "
                        f"gradients, Adam's moments and its step, and the process itself: {format_bytes(fixed)}; the "
                        f"activations of a batch of {batch}: {format_bytes(batched)}), but {shown_available} is "
                        f"available; {advice}")


__all__ = ["ACTIVATION_FACTOR", "ALLOCATOR_SLACK", "AVERAGE_BYTES_PER_PARAMETER", "BACKWARD_BYTES_PER_PARAMETER",
           "OPTIMISER_STEP_BYTES_PER_PARAMETER", "PROCESS_BYTES", "check_training_fits", "training_need"]
