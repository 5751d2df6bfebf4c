"""A camera effect in only part of a recording: in some of its sequences, or in the frames from some index on.

The camera candidates (:mod:`piga.diagnostics.vision`) are fitted on frames of every sequence and every frame index.
Where only part of the frames has the effect, the fit reads a value that no frame has (blur 1.5 px in the even
sequences was read "blur 0.798 px (0.566..1.03)"; a 3 px shift from frame 12 on "1.45 px right (1.43..1.47)"). Such a
camera improves the matched residual of the frames that have the effect and worsens that of the others, while a camera
of the whole recording improves nearly every sequence and every frame index. :func:`partial_camera` groups the fit
frames by sequence and by frame index, and where the candidate camera both improves and worsens a share of the groups
(:attr:`~piga.diagnostics.vision.CameraConfig.min_split_share`), refits it on the groups it improves and names it
there only (:class:`PartialCamera`); :func:`match_partial` reads every frame's angle through it where it applies.
Where the other groups show a camera effect of their own (a shift of 2 px in the odd sequences and a blur of 1.5 px in
the even ones, read as one camera for all "blur 0.869 px; shift 1.49 px right, 1.45 px down" and a gain of 0.713 that
the recording does not have), it is fitted on them and read there (:attr:`PartialCamera.other`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from piga.diagnostics.vision import (Camera, CameraConfig, _flat, angle_table, camera_interval, empty_mask, fit_camera,
                                     fit_exposure, match)
from piga.world.model import PhysicsModel


@dataclass(frozen=True)
class PartialCamera:
    """A camera effect that only some sequences, or only some frame indices, of a recording show."""

    camera: Camera
    """The camera read on the frames that show it."""
    by: str
    """"sequences": it shows in the sequences ``groups``; "frames": in the frame indices ``groups`` of every sequence."""
    groups: tuple[int, ...]
    """The sequences (of the whole file) or the frame indices that show it."""
    total: int
    """Sequences in the file ("sequences") or frames per sequence ("frames")."""
    split: float
    """The share of groups that the whole-recording fit improved and worsened, the smaller of the two
    (:func:`split_share`)."""
    other: Camera = Camera()
    """The camera read on the other groups (all zero: none)."""

    def where(self) -> str:
        """A phrase for the verdict: "in 25 of 50 sequences (the even ones)", "from frame 12 on"."""
        return _where(self.by, list(self.groups), self.total, "another camera" if self.other != Camera() else "none")

    def elsewhere(self) -> str:
        """The same phrase for the other groups, where :attr:`other` is read: "in 23 of 45 sequences (the odd ones; in
        the others, another camera)"."""
        rest = [i for i in range(self.total) if i not in set(self.groups)]
        return _where(self.by, rest, self.total, "another camera")

    def note(self) -> str:
        """The report's note on it."""
        groups = "sequences" if self.by == "sequences" else "frame indices"
        if self.other != Camera():
            return (f"the {groups} disagree on the camera: fitted on all the frames, one camera improved the matched "
                    f"residual of some {groups} and worsened that of others (of {100 * self.split:.0f}% of them each, "
                    f"at least), values that no frame has; one camera is read {self.where()}, another "
                    f"{self.elsewhere()}, and the dynamics are fitted on angles matched to the decoder's renders "
                    "through each where it shows, not on the encoder's angles")
        return (f"the camera effect shows in part of the recording only: fitted on all the frames, the camera improved "
                f"the matched residual of some {groups} and worsened that of others (of {100 * self.split:.0f}% of them "
                f"each, at least), a value that no frame has; it is read on the frames that show it, {self.where()}, "
                "and the dynamics are fitted on angles matched to the decoder's renders through it there and with no "
                "camera elsewhere, not on the encoder's angles")

    def shows(self, seqs: np.ndarray, times: np.ndarray) -> np.ndarray:
        """(M,) bool: whether the frames of sequences ``seqs`` (M,) at frame indices ``times`` (M,) show it."""
        return np.isin(seqs if self.by == "sequences" else times, self.groups)

    def mask(self, n: int, t: int) -> np.ndarray:
        """(n, t) bool: the frames of the file that show it."""
        out = np.zeros((n, t), bool)
        if self.by == "frames":
            out[:, list(self.groups)] = True
        else:
            out[list(self.groups)] = True
        return out


def _where(by: str, g: list[int], total: int, others: str) -> str:
    """Where groups ``g`` of ``total`` (sequences or frame indices, ``by``) are, and what the others show."""
    if by == "frames":
        if g and g == list(range(g[0], total)):
            return f"from frame {g[0]} on (in the frames before it, {others})"
        return f"in frames {_ranges(g)} of every sequence (in the others, {others})"
    which = ("the even ones" if all(i % 2 == 0 for i in g) and len(g) == (total + 1) // 2 else
             "the odd ones" if all(i % 2 == 1 for i in g) and len(g) == total // 2 else
             f"sequences {_ranges(g)}")
    return f"in {len(g)} of {total} sequences ({which}; in the others, {others})"


def _ranges(values: list[int]) -> str:
    """0, 1, 2, 5, 7, 8 -> "0-2, 5, 7-8" (the first 8 runs, then "...")."""
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    text = [f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:8]]
    return ", ".join(text) + (", ..." if len(runs) > 8 else "")


def group_drops(before: np.ndarray, after: np.ndarray, groups: np.ndarray,
                min_frames: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The groups (G,) with at least ``min_frames`` frames, and each one's relative drop of the mean matched residual
    (G,), 1 - mean(after) / mean(before), from per-frame residuals ``before`` and ``after`` (M,) of frames in
    ``groups`` (M,)."""
    ids, inverse, counts = np.unique(groups, return_inverse=True, return_counts=True)
    b = np.bincount(inverse, weights=before, minlength=len(ids))
    a = np.bincount(inverse, weights=after, minlength=len(ids))
    keep = (counts >= min_frames) & (b > 0)
    return ids[keep], 1 - a[keep] / b[keep]


def split_share(drops: np.ndarray, min_drop: float) -> float:
    """The smaller of the shares of groups whose residual a camera lowers by more than ``min_drop`` and raises by more
    than ``min_drop``: near 0 for a camera of the whole recording (it improves every group), about the smaller part
    for a camera that only part of the groups have."""
    if len(drops) == 0:
        return 0.0
    return float(min((drops > min_drop).mean(), (drops < -min_drop).mean()))


def _refit(model: PhysicsModel, like: Camera, frames: np.ndarray, still: np.ndarray, x: Tensor,
           renders: tuple[Tensor, Tensor], config: CameraConfig) -> Camera:
    """The effects of camera ``like`` (its exposure, blur and/or shift) fitted anew on uint8 frames (M, H, W), flattened
    in ``x`` (M, P)."""
    material = like.material(config)
    cam = fit_exposure(model, frames, still, x, renders, config.min_exposure)[0] if "exposure" in material else Camera()
    if {"blur", "shift"} & material:
        cam = fit_camera(model, x, blur="blur" in material, shift="shift" in material, renders=renders, base=cam)
    return cam


@torch.no_grad()
def partial_camera(model: PhysicsModel, candidates: list[Camera], frames: np.ndarray, x: Tensor, seqs: np.ndarray,
                   times: np.ndarray, still: np.ndarray, renders: tuple[Tensor, Tensor], config: CameraConfig,
                   ) -> tuple[PartialCamera | None, float]:
    """The camera effect that only part of the fit frames show, where one does, and the largest :func:`split_share`.

    Args:
        candidates: the camera candidates fitted on all the frames (only those with a material effect are tried).
        frames: (M, H, W) uint8 fit frames, flattened in ``x`` (M, P); ``seqs`` (M,), ``times`` (M,) their sequences
            and frame indices.
        still: (H, W) the pixels the pendulum never reaches (:func:`~piga.diagnostics.vision.static_pixels`).
    Returns:
        A :class:`PartialCamera` whose ``groups`` are, for "sequences", the fit sequences that show it (the file's
        others are told by :func:`match_partial`), or None; and the largest split share over the candidates and the two
        groupings.
    """
    base = match(angle_table(model, Camera(), renders=renders), x)[1].double().numpy()  # (M,)
    best: tuple[float, Camera, str, np.ndarray] | None = None
    for cam in candidates:
        if not cam.material(config):
            continue
        seen = match(angle_table(model, cam, renders=renders), x)[1].double().numpy()
        for by, groups in (("sequences", seqs), ("frames", times)):
            ids, drops = group_drops(base, seen, groups)
            share = split_share(drops, config.min_drop)
            if best is None or share > best[0]:
                best = (share, cam, by, ids[drops > 0])
    if best is None:
        return None, 0.0
    share, cam, by, shown = best
    if share < config.min_split_share:
        return None, share
    groups = seqs if by == "sequences" else times
    on = np.isin(groups, shown)  # (M,) the frames the whole-recording fit improves
    camera = _refit(model, cam, frames[on], still, x[on], renders, config)
    if not camera.material(config):
        return None, share
    ids, drops = group_drops(base, match(angle_table(model, camera, renders=renders), x)[1].double().numpy(), groups)
    shown = ids[drops > config.min_drop]
    if len(shown) == 0 or len(shown) == len(ids):
        return None, share
    other = other_camera(model, x[torch.from_numpy(~np.isin(groups, shown))], base[~np.isin(groups, shown)], renders,
                         config)
    return PartialCamera(camera, by, tuple(int(i) for i in shown), 0, share, other), share


def other_camera(model: PhysicsModel, x: Tensor, before: np.ndarray, renders: tuple[Tensor, Tensor],
                 config: CameraConfig) -> Camera:
    """The blur and shift of the frames ``x`` (M, P) that a part-of-file camera leaves, where they are material and
    lower these frames' mean matched residual (``before`` (M,), with no camera) by more than ``min_drop``; else no
    camera. Measured: a shift of 2 px in the odd sequences left the even ones' blur of 1.5 px, read 1.5 here; the
    clean frames beside a blur of 1.5 or 2 px from frame 12 on, a blur of 1.5 px in the even sequences, a shift of
    3 px from frame 12 on and an exposure in part of the file read no camera."""
    if len(x) < 4:
        return Camera()
    cam = fit_camera(model, x, renders=renders)
    if not cam.material(config):
        return Camera()
    after = match(angle_table(model, cam, renders=renders), x)[1].double().numpy()
    return cam if 1 - after.mean() / max(before.mean(), 1e-12) > config.min_drop else Camera()


@torch.no_grad()
def match_partial(model: PhysicsModel, path: str, partial: PartialCamera,
                  batch: int = 64) -> tuple[np.ndarray, PartialCamera]:
    """(N, T) angles of every frame of ``path``, matched through ``partial.camera`` where it shows and with no camera
    elsewhere, unwrapped along time; and ``partial`` with its groups over the whole file: for "sequences", those
    whose frames match closer through its camera than through :attr:`PartialCamera.other` (none, where none is read; the
    fit split's are only a sample)."""
    from piga.data.schema import open_data_file

    plain, seen = angle_table(model, partial.other), angle_table(model, partial.camera)
    with open_data_file(path) as f:
        ds = f["frames"]
        n, t = ds.shape[:2]
        out = np.empty((n, t))
        shows = np.zeros(n, bool)
        for start in range(0, n, batch):
            raw = ds[start : start + batch]
            x = _flat(raw.reshape(-1, *raw.shape[2:]), model.config.channels)
            th0, e0 = (v.double().numpy().reshape(len(raw), t) for v in match(plain, x))
            th1, e1 = (v.double().numpy().reshape(len(raw), t) for v in match(seen, x))
            if partial.by == "frames":
                use = np.zeros((len(raw), t), bool)
                use[:, list(partial.groups)] = True
            else:
                shows[start : start + len(raw)] = e1.mean(1) < e0.mean(1)
                use = np.repeat(shows[start : start + len(raw), None], t, axis=1)
            out[start : start + len(raw)] = np.where(use, th1, th0)
    groups = tuple(int(i) for i in np.flatnonzero(shows)) if partial.by == "sequences" else partial.groups
    total = n if partial.by == "sequences" else t
    return np.unwrap(out, axis=1), PartialCamera(partial.camera, partial.by, groups, total, partial.split, partial.other)


@torch.no_grad()
def partial_error(model: PhysicsModel, partial: PartialCamera, x: Tensor, seqs: np.ndarray, times: np.ndarray,
                  renders: tuple[Tensor, Tensor]) -> float:
    """The mean matched residual of frames ``x`` (M, P) of sequences ``seqs`` (M,) at frame indices ``times`` (M,),
    each through ``partial.camera`` where it shows (:func:`match_partial` told its groups) and through
    ``partial.other`` elsewhere."""
    e0 = match(angle_table(model, partial.other, renders=renders), x)[1]
    e1 = match(angle_table(model, partial.camera, renders=renders), x)[1]
    on = torch.from_numpy(partial.shows(seqs, times))
    return float(torch.where(on, e1, e0).mean()) if len(x) else 0.0


@torch.no_grad()
def partial_empty(model: PhysicsModel, partial: PartialCamera, x: Tensor, seqs: np.ndarray, times: np.ndarray,
                  renders: tuple[Tensor, Tensor], min_contrast: float = 0.0) -> float:
    """The fraction of frames ``x`` (M, P) of sequences ``seqs`` (M,) at frame indices ``times`` (M,) in which the
    pendulum is not in view (:func:`~piga.diagnostics.vision.empty_frames`, with ``min_contrast``), each seen through
    ``partial.camera`` where it shows and through ``partial.other`` elsewhere (with no camera, a blur of 2.5 px from
    frame 8 on hid it in 64% of them)."""
    if not len(x):
        return 0.0
    on = torch.from_numpy(partial.shows(seqs, times))
    empty = torch.where(on, empty_mask(model, partial.camera, x, renders, min_contrast),
                        empty_mask(model, partial.other, x, renders, min_contrast))
    return float(empty.double().mean())


def partial_effects(model: PhysicsModel, partial: PartialCamera, x: Tensor, seqs: np.ndarray, times: np.ndarray,
                    config: CameraConfig, own_exposure: float) -> list[dict]:
    """The named effects of ``partial`` (blur, shift, exposure), each with its 95% interval on the fit frames ``x``
    (M, P) that show it (of sequences ``seqs`` (M,), frame indices ``times`` (M,)), and where it shows; then those of
    its :attr:`~PartialCamera.other` camera, on the other frames. An exposure is named relative to the model's own
    frames' (``own_exposure``)."""
    on = partial.shows(seqs, times)  # (M,)
    effects = _effects(model, partial.camera, x[torch.from_numpy(on)], seqs[on], partial.where(), config, own_exposure)
    if partial.other != Camera():
        effects += _effects(model, partial.other, x[torch.from_numpy(~on)], seqs[~on], partial.elsewhere(), config,
                            own_exposure)
    return effects


def _effects(model: PhysicsModel, cam: Camera, x: Tensor, seqs: np.ndarray, where: str, config: CameraConfig,
             own_exposure: float) -> list[dict]:
    """The named effects of ``cam`` where it shows (``where``), with intervals on its frames ``x`` (M, P) of sequences
    ``seqs`` (M,)."""
    effects: list[dict] = []
    material = cam.material(config)
    if "blur" in material:
        effects.append({"effect": "blur", "value": cam.blur, "unit": "px (Gaussian σ)",
                        "interval": camera_interval(model, cam, "blur", x, seqs), "where": where})
    if "shift" in material:
        ix, iy, length = (camera_interval(model, cam, k, x, seqs) for k in ("dx", "dy", "shift"))
        effects.append({"effect": "shift", "value": float(np.hypot(cam.dx, cam.dy)), "dx": cam.dx, "dy": cam.dy,
                        "dx_interval": ix, "dy_interval": iy, "unit": "px (length of the shift; dx right, dy down)",
                        "interval": length, "where": where})
    if "exposure" in material and 255 * abs(cam.exposure / own_exposure - 1) > config.min_exposure:
        lo, hi = camera_interval(model, cam, "exposure", x, seqs, step=0.01)
        effects.append({"effect": "exposure", "value": cam.exposure / own_exposure, "unit": "factor on every gray level",
                        "interval": [lo / own_exposure, hi / own_exposure], "where": where})
    return effects
