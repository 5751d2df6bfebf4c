"""Did the autoencoder find every object of a scene? A check that needs no labels.

An object the encoder and decoder never took up (measured: one of the three balls of a gravity file on
a dark background, which the learned background smeared into a faint ring) leaves the physics to fit
the others, and g came out 89% off with little other sign: g moved 1.5% over the run's last tenth, and
its frames' SSIM was within the range of a noisy file's. What gives it away is the reconstruction of
single frames: a ball that no object renders stays in the residual, frame after frame, as a blob as
strong as the balls themselves.
Pixel noise and lossy compression leave residuals too, but spread over the frame, which a blur of about
a ball's size averages out.

:func:`check_objects` measures, on a file's frames, the typical peak of the blurred reconstruction
residual against the typical peak of the blurred moving content (each frame against the per-pixel median
of all, the static background). Measured on the robustness benchmark's 30 seed-0 scene runs and the
dark-background gravity run at seed 0 trained without the retry (``benchmarks/object_check.py``,
``results/object_check.md``): 0.013-0.164 on the 30 that found every object (0.164 under Gaussian
pixel noise of σ = 25/255, 0.10 under H.264 at CRF 28), 0.63 for the lost ball.

The converse, a slot that renders nothing (a model given more slots than the scene has objects, with
``piga-train-model --objects``), is as silent and as harmful: the physics still moves the empty slot, and
its pull or its springs bend the learned parameters (measured: g 79% off with 4 slots for 3 balls, k 52%
off with 4 slots for 2, at exit 0 before this check). Its sign needs no labels either: take the slot out of
the reconstruction (park it off the picture) and the frames do not change. :func:`check_objects` measures,
for each slot, the typical peak of the blurred change that removing it makes, against the same content
peak, and calls a slot empty below :data:`EMPTY_RATIO`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import cv2
import numpy as np
import torch

from scipy.optimize import linear_sum_assignment

from piga.io.device import module_device
from piga.world.model import ObjectModel, frames_to_float

#: Residual peak over content peak above which an object counts as lost.
LOST_RATIO = 0.5
#: Peak change on removing a slot over content peak below which the slot renders nothing.
EMPTY_RATIO = 0.25
#: Gaussian blur σ as a fraction of the image size (1.5 px on the scenes' 36 px frames: about a ball's radius).
BLUR_FRACTION = 1 / 24


@dataclass(frozen=True)
class ObjectCheck:
    """The measures of :func:`check_objects`."""

    residual_peak: float
    """Median over frames of the largest blurred reconstruction residual (mean over channels, in [0, 1])."""
    content_peak: float
    """Median over frames of the largest blurred difference from the static background."""
    ratio: float
    """``residual_peak / content_peak``."""
    lost: bool
    """``ratio`` above :data:`LOST_RATIO`: a moving object that no object of the model renders."""
    slots: int | None = None
    """The model's object slots N (None: not compared with the scene's count)."""
    scene_objects: int | None = None
    """The objects the data file says its scene has (its ``n_objects`` attribute; None: not known)."""
    slot_ratios: tuple[float, ...] | None = None
    """Per slot: the median over frames of the largest blurred change that taking the slot out of the
    reconstruction makes, over ``content_peak`` (None: not measured)."""

    @property
    def empty_slots(self) -> list[int]:
        """The slots that render nothing (:data:`EMPTY_RATIO`): the frames are the same without them."""
        return [i for i, r in enumerate(self.slot_ratios or ()) if r < EMPTY_RATIO]

    @property
    def too_few_slots(self) -> bool:
        """The model has fewer slots than the scene has objects: some object cannot be found, whatever the seed."""
        return self.slots is not None and self.scene_objects is not None and self.slots < self.scene_objects

    def with_counts(self, slots: int, scene_objects: int | None) -> ObjectCheck:
        """This check, knowing the model's slots and the scene's objects."""
        return replace(self, slots=slots, scene_objects=scene_objects)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "too_few_slots": self.too_few_slots, "too_many_slots": self.too_many_slots,
                "empty_slots": self.empty_slots}

    def reason(self) -> str:
        """The one-line cause of a lost object, with the fix."""
        if self.too_few_slots:
            slots = f"{self.slots} object slot{'s' if self.slots != 1 else ''}"
            return (f"an object was not found: the model has {slots} for the scene's {self.scene_objects} objects (a "
                    f"moving blob {self.ratio:.2f}x as strong as the objects is left unrendered); train with --objects "
                    f"{self.scene_objects} to model them all")
        blob = (f"an object was not found: the reconstruction of single frames leaves a moving blob "
                f"{self.ratio:.2f}x as strong as the scene's objects (at most {LOST_RATIO:g} when every object is found)")
        if self.too_many_slots:  # the spare slots may have split an object between them: the count is the first fix
            return (f"{blob}; the model has {self.slots} object slots for the scene's {self.scene_objects} objects (the "
                    f"file's n_objects): train with --objects {self.scene_objects} (or without --objects), or with "
                    "another --seed (and --overwrite, or another --out)")
        return f"{blob}; train again with another --seed or more --seed-retries (and --overwrite, or another --out)"

    @property
    def too_many_slots(self) -> bool:
        """The model has more slots than the scene has objects (as the file says): some slot has nothing to draw."""
        return self.slots is not None and self.scene_objects is not None and self.slots > self.scene_objects

    def empty_reason(self) -> str:
        """The one-line cause of empty slots, with the fix."""
        empty, ratios = self.empty_slots, self.slot_ratios or ()
        many = len(empty) > 1
        slots = self.slots if self.slots is not None else len(ratios)
        cause = (f"slot{'s' if many else ''} {', '.join(map(str, empty))} of {slots} render{'' if many else 's'} nothing "
                 f"(taking {'them' if many else 'it'} out changes the frames by at most "
                 f"{max(ratios[i] for i in empty):.2f}x the objects' contrast, at least {EMPTY_RATIO:g} for a slot that "
                 f"draws an object), yet the physics still moves {'them' if many else 'it'}, so its parameters are bent")
        if self.scene_objects is not None and not self.too_many_slots:
            return (f"{cause}; the scene has {self.scene_objects} objects (the file's n_objects), so a slot that should draw "
                    "one did not: train again with another --seed (and --overwrite, or another --out)")
        count = self.scene_objects if self.too_many_slots else max(slots - len(empty), 1)
        said = (f"the scene has {self.scene_objects} objects (the file's n_objects)" if self.too_many_slots
                else f"{count} slot{'s' if count != 1 else ''} draw the scene")
        return f"{cause}: {said}; train with --objects {count}"


def _peaks(diff: np.ndarray, sigma: float) -> np.ndarray:
    """(F,) the largest value of each frame's |blurred difference| (mean over channels) of (F, C, H, W) ``diff``.

    The signed difference is blurred, channel by channel, before its size is taken: zero-mean pixel noise
    averages out over a ball's area, a missing ball does not."""
    # OpenCV's blur, plane by plane: the maps are small, and it is the library the data pipeline uses already
    f, c, h, w = diff.shape
    planes = diff.reshape(f * c, h, w).astype(np.float32)
    blurred = np.stack([cv2.GaussianBlur(p, (0, 0), sigma) for p in planes]).reshape(f, c, h, w)
    return np.abs(blurred).mean(1).max(axis=(1, 2))


def compare(frames: np.ndarray, reconstructed: np.ndarray, sigma: float,
            without: list[np.ndarray] | None = None) -> ObjectCheck:
    """The check on (F, C, H, W) float ``frames`` in [0, 1] and their ``reconstructed`` single frames, and,
    given ``without`` (per slot, the (F, C, H, W) reconstruction with that slot taken out), each slot's share."""
    residual = _peaks(frames - reconstructed, sigma)  # (F,)
    background = np.median(frames, axis=0)  # (C, H, W): the static scene
    content = _peaks(frames - background, sigma)  # (F,)
    r, c = float(np.median(residual)), float(np.median(content))
    ratio = r / c if c > 0 else 0.0
    slots = None
    if without is not None:
        slots = tuple(float(np.median(_peaks(reconstructed - w, sigma))) / c if c > 0 else 0.0 for w in without)
    return ObjectCheck(r, c, ratio, bool(ratio > LOST_RATIO), slot_ratios=slots)


@torch.no_grad()
def check_objects(model: ObjectModel, frames: np.ndarray, max_frames: int = 400) -> ObjectCheck:
    """Reconstructs single frames of (B, T, H, W[, C]) uint8 ``frames`` (at most ``max_frames``, spread over
    the sequences) through the model's encoder and decoder, with every slot and with each slot taken out (parked
    far off the picture), and :func:`compare` s them."""
    cfg = model.config
    x = frames_to_float(torch.from_numpy(np.ascontiguousarray(frames)), cfg.channels).flatten(0, 1)  # (F, C, H, W)
    x = x[np.linspace(0, len(x) - 1, min(max_frames, len(x))).astype(int)]
    coords = model.encode(x[:, None].to(module_device(model)))[:, 0]  # (F, N, 2), on the model's device
    rec = model.decoder(coords).cpu().numpy()  # (F, C, H, W)
    without = []
    for i in range(coords.shape[1]):
        parked = coords.clone()
        parked[:, i] = -10.0 * cfg.image_size  # off the picture: the slot draws nothing
        without.append(model.decoder(parked).cpu().numpy())  # (F, C, H, W)
    return compare(x.numpy(), rec, BLUR_FRACTION * cfg.image_size, without)


def match_objects(coords: np.ndarray, states: np.ndarray, found_px: float) -> dict[str, Any]:
    """The encoder's (x, y) per slot, (B, T, N, 2) ``coords``, against a scene's true centres, read from its
    (B, T, 4·M) ``states`` (x0, y0, x1, y1, ..., then the velocities; evaluation only), under the assignment of
    slots to objects with the least mean distance (SciPy's Hungarian solver, exact for any N and M: with N = M it
    is the best permutation). N may differ from M (``piga-train-model --objects``): with fewer slots some objects
    have none, with more some slots match none.

    Returns ``mean_px`` and ``p90_px`` (per true object; None for an object no slot matches), ``slots`` (the slot
    matched to each true object, or None), ``unmatched_slots``, and ``found``: every object has a slot within a
    mean distance of ``found_px`` pixels."""
    b, t, n, _ = coords.shape
    m = states.shape[-1] // 4
    true = states[..., : 2 * m].reshape(b, t, m, 2)  # (B, T, M, 2)
    distance = np.linalg.norm(coords[:, :, :, None] - true[:, :, None], axis=-1).reshape(b * t, n, m)  # (B*T, N, M)
    slots, objects = linear_sum_assignment(distance.mean(axis=0))
    slot_of: list[int | None] = [None] * m
    mean: list[float | None] = [None] * m
    p90: list[float | None] = [None] * m
    for i, j in zip(slots.tolist(), objects.tolist()):
        slot_of[j], mean[j], p90[j] = i, float(distance[:, i, j].mean()), float(np.percentile(distance[:, i, j], 90))
    return {"mean_px": mean, "p90_px": p90, "slots": slot_of, "unmatched_slots": sorted(set(range(n)) - set(slots.tolist())),
            "found": all(e is not None and e < found_px for e in mean)}
