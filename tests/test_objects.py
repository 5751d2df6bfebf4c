"""The object check (:mod:`piga.evaluation.objects`): a ball that no object renders stays in the residual, and a slot
that renders nothing leaves the frames the same when it is taken out."""

from __future__ import annotations

import numpy as np

from piga.evaluation.objects import EMPTY_RATIO, LOST_RATIO, compare


def scene(frames: int = 60, size: int = 32, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3, H, W) frames of two moving balls (red, blue) on a static dark background, and the same without the
    blue ball."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    background = np.zeros((3, size, size)) + np.array([0.25, 0.1, 0.3])[:, None, None]
    both, red_only = [], []
    for _ in range(frames):
        img = background.copy()
        centres = rng.uniform(6, size - 6, (2, 2))
        for (cy, cx), colour in zip(centres, ([1.0, 0, 0], [0, 0, 1.0])):
            disk = (yy - cy) ** 2 + (xx - cx) ** 2 <= 9
            img[:, disk] = np.array(colour)[:, None]
            if colour[0]:
                red_only.append(img.copy())
        both.append(img)
    return np.stack(both), np.stack(red_only)


def test_a_ball_left_out_of_the_reconstruction_is_lost() -> None:
    frames, red_only = scene()
    lost = compare(frames, red_only, sigma=1.5)
    assert lost.lost and lost.ratio > 1.5 * LOST_RATIO
    assert "another --seed" in lost.reason() and "--objects" not in lost.reason()
    # more slots than the file's objects (--objects 3 for 2 balls): the count is named before another seed
    assert "--objects 2 (or without --objects)" in lost.with_counts(3, 2).reason()


def test_found_balls_under_pixel_noise_are_not_lost() -> None:
    """Noise in the frames (σ = 25/255) leaves a residual everywhere, which the blur averages out."""
    frames, _ = scene()
    noisy = np.clip(frames + np.random.default_rng(1).normal(0, 25 / 255, frames.shape), 0, 1)
    check = compare(noisy, frames, sigma=1.5)
    assert not check.lost and check.ratio < LOST_RATIO / 2
    assert compare(frames, frames, sigma=1.5).ratio == 0



def test_a_slot_that_draws_nothing_is_empty_and_the_fix_fits_the_counts() -> None:
    frames, red_only = scene()
    # slot 0 draws the blue ball (without it: red only); slot 1 draws nothing (without it: the same frames)
    check = compare(frames, frames, sigma=1.5, without=[red_only, frames + 0.002])
    assert check.empty_slots == [1] and check.slot_ratios[0] > 2 * EMPTY_RATIO and not check.lost
    assert check.to_dict()["empty_slots"] == [1]
    assert check.with_counts(3, 2).too_many_slots and "--objects 2" in check.with_counts(3, 2).empty_reason()
    assert "another --seed" in check.with_counts(2, 2).empty_reason()  # the scene has an object for it
    assert "--objects 1" in check.with_counts(2, None).empty_reason()  # the file does not say: the slots that draw
    assert compare(frames, frames, sigma=1.5).empty_slots == []  # not measured: nothing to call empty
