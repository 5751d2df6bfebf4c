"""A camera effect in part of a recording only (piga.diagnostics.partial), on a drawn rod: no trained model needed."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from piga.diagnostics.partial import PartialCamera, group_drops, match_partial, partial_camera, split_share
from piga.diagnostics.results import Effect
from piga.diagnostics.vision import Camera, CameraConfig, decoder_renders

SIZE = 32


def _rod(angles: torch.Tensor) -> torch.Tensor:
    """(K, 1, 1) angles -> (K, 1, SIZE, SIZE) a dark rod of length 12 px from the centre on white, antialiased."""
    a = angles.reshape(-1, 1, 1)
    rows, cols = torch.meshgrid(torch.arange(SIZE, dtype=torch.float32), torch.arange(SIZE, dtype=torch.float32),
                                indexing="ij")
    y, x = rows - SIZE / 2, cols - SIZE / 2
    ux, uy = torch.sin(a), -torch.cos(a)  # angle 0: up
    along = (x * ux + y * uy).clamp(0, 12)
    dist = torch.hypot(x - along * ux, y - along * uy)
    return (1 - (2.0 - dist).clamp(0, 1))[:, None] * 0.9 + 0.1 * (dist >= 2.0)[:, None]


MODEL = SimpleNamespace(decoder=_rod, config=SimpleNamespace(channels=1))


def _recording(seqs: int = 24, t: int = 12, seed: int = 0) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """(seqs·t, 1, H, W) frames of a swinging rod, and each frame's sequence and frame index."""
    rng = np.random.default_rng(seed)
    start, speed = rng.uniform(-math.pi, math.pi, seqs), rng.uniform(-0.5, 0.5, seqs)
    angles = torch.tensor(start[:, None] + speed[:, None] * np.arange(t), dtype=torch.float32).flatten()
    return _rod(angles), np.repeat(np.arange(seqs), t), np.tile(np.arange(t), seqs)


def _uint8(frames: torch.Tensor) -> np.ndarray:
    return (frames[:, 0].numpy() * 255).round().astype(np.uint8)


def _stage(frames: np.ndarray, seqs: np.ndarray, times: np.ndarray, tried: list[Camera]):  # noqa: ANN202
    renders = decoder_renders(MODEL, 180)
    x = torch.from_numpy(frames.astype(np.float32) / 255).flatten(1)
    still = np.zeros(frames.shape[1:], bool)
    still[:3, :3] = True  # a corner the rod never reaches
    return partial_camera(MODEL, tried, frames, x, seqs, times, still, renders, CameraConfig())


def test_split_share_tells_a_whole_file_camera_from_one_in_half_the_groups() -> None:
    before = np.ones(40)
    groups = np.repeat(np.arange(10), 4)
    ids, drops = group_drops(before, np.full(40, 0.5), groups)
    assert list(ids) == list(range(10)) and split_share(drops, 0.1) == 0.0  # every group improves
    after = np.where(groups % 2 == 0, 0.5, 1.5)  # the even groups improve, the others worsen
    assert split_share(group_drops(before, after, groups)[1], 0.1) == 0.5
    assert len(group_drops(before, after, groups, min_frames=5)[0]) == 0  # groups of 4 frames are too few


def test_a_blur_in_half_the_sequences_is_read_there_and_a_whole_file_blur_is_not_split() -> None:
    clean, seqs, times = _recording(seqs=16, t=8)
    blurred = Camera(blur=1.5).apply(clean)
    half = torch.where(torch.from_numpy(seqs % 2 == 0)[:, None, None, None], blurred, clean)
    # what a fit on all the frames reads: a blur between 0 and 1.5, which no frame has
    partial, share = _stage(_uint8(half), seqs, times, [Camera(blur=0.8)])
    assert share >= 0.4 and partial is not None and partial.by == "sequences"
    assert partial.groups == tuple(range(0, 16, 2))
    assert abs(partial.camera.blur - 1.5) < 0.1, partial.camera
    whole, share = _stage(_uint8(blurred), seqs, times, [Camera(blur=1.5)])
    assert whole is None and share < CameraConfig().min_split_share


def test_a_shift_from_a_frame_on_is_read_on_those_frames() -> None:
    clean, seqs, times = _recording()
    late = torch.where(torch.from_numpy(times >= 6)[:, None, None, None], Camera(dx=3.0).apply(clean), clean)
    partial, _ = _stage(_uint8(late), seqs, times, [Camera(dx=1.5)])
    assert partial is not None and partial.by == "frames" and partial.groups == tuple(range(6, 12))
    assert abs(partial.camera.dx - 3.0) < 0.2 and abs(partial.camera.dy) < 0.3, partial.camera
    assert PartialCamera(partial.camera, "frames", partial.groups, 12, 0.5).where().startswith("from frame 6 on")


def test_match_partial_tells_every_sequence_of_the_file(tmp_path: Path) -> None:
    import h5py

    clean, seqs, times = _recording(seqs=8, t=6)
    dark = Camera(exposure=0.7).apply(clean)
    frames = torch.where(torch.from_numpy(seqs < 3)[:, None, None, None], dark, clean)
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as f:
        f["frames"] = _uint8(frames).reshape(8, 6, SIZE, SIZE)
    # the fit sample saw sequences 0 and 1 only: the file's sequence 2 is told by its own frames
    theta, partial = match_partial(MODEL, str(path), PartialCamera(Camera(exposure=0.7), "sequences", (0, 1), 0, 0.5))
    assert partial.groups == (0, 1, 2) and partial.total == 8
    assert partial.where() == "in 3 of 8 sequences (sequences 0-2; in the others, none)"
    assert partial.mask(8, 6)[:3].all() and not partial.mask(8, 6)[3:].any()
    assert theta.shape == (8, 6)
    err = np.angle(np.exp(1j * (theta - _truth(8, 6))))  # every frame read within 3 deg, the dark ones too
    assert np.abs(err).max() < math.radians(3), np.abs(err).max()


def _truth(seqs: int, t: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    start, speed = rng.uniform(-math.pi, math.pi, seqs), rng.uniform(-0.5, 0.5, seqs)
    return (start[:, None] + speed[:, None] * np.arange(t)).astype(np.float32)


@pytest.mark.parametrize(("groups", "total", "text"), [
    ((0, 2, 4), 6, "in 3 of 6 sequences (the even ones; in the others, none)"),
    ((1, 3), 5, "in 2 of 5 sequences (the odd ones; in the others, none)"),
    ((0, 1, 2, 7), 10, "in 4 of 10 sequences (sequences 0-2, 7; in the others, none)"),
])
def test_where_a_partial_camera_shows(groups: tuple[int, ...], total: int, text: str) -> None:
    assert PartialCamera(Camera(blur=1.0), "sequences", groups, total, 0.5).where() == text


def test_an_effect_says_where_it_shows() -> None:
    e = Effect("blur", 1.5, "px (Gaussian σ)", [1.4, 1.6], where="in 25 of 50 sequences (the even ones)")
    assert e.describe().endswith("in 25 of 50 sequences (the even ones)")
    assert e.to_dict()["where"] == "in 25 of 50 sequences (the even ones)"
    assert "where" not in Effect("blur", 1.5, "px").to_dict()


def test_two_cameras_in_two_halves_are_each_read_where_they_show() -> None:
    # a shift of 3 px in the odd sequences, a blur of 1.5 px in the even ones: a fit on all the frames reads both at
    # once ("blur 1.11, shift 2.26 right, 2.16 down"), which improves every sequence; its shift alone splits them, and
    # the blur is read on the others
    clean, seqs, times = _recording(seqs=16, t=8)
    odd = torch.from_numpy(seqs % 2 == 1)[:, None, None, None]
    frames = torch.where(odd, Camera(dx=3.0, dy=3.0).apply(clean), Camera(blur=1.5).apply(clean))
    both = Camera(blur=1.1, dx=2.2, dy=2.2)
    assert _stage(_uint8(frames), seqs, times, [both])[0] is None
    partial, share = _stage(_uint8(frames), seqs, times, [both, Camera(blur=1.1), Camera(dx=2.2, dy=2.2)])
    assert partial is not None and partial.by == "sequences" and share >= 0.4
    assert partial.groups == tuple(range(1, 16, 2))
    assert abs(partial.camera.dx - 3) < 0.2 and abs(partial.camera.dy - 3) < 0.2 and partial.camera.blur < 0.3
    assert abs(partial.other.blur - 1.5) < 0.15 and max(abs(partial.other.dx), abs(partial.other.dy)) < 0.3
    named = PartialCamera(partial.camera, "sequences", partial.groups, 16, share, partial.other)
    assert named.where() == "in 8 of 16 sequences (the odd ones; in the others, another camera)"
    assert named.elsewhere() == "in 8 of 16 sequences (the even ones; in the others, another camera)"
    assert named.note().startswith("the sequences disagree on the camera")


def test_clean_frames_beside_a_partial_camera_read_no_other_camera() -> None:
    clean, seqs, times = _recording(seqs=16, t=8)
    late = torch.where(torch.from_numpy(times >= 4)[:, None, None, None], Camera(blur=1.5).apply(clean), clean)
    partial, _ = _stage(_uint8(late), seqs, times, [Camera(blur=0.8)])
    assert partial is not None and partial.groups == (4, 5, 6, 7) and partial.other == Camera()
    assert PartialCamera(partial.camera, "frames", partial.groups, 8, 0.5, partial.other).where() == \
        "from frame 4 on (in the frames before it, none)"


def test_frames_are_in_view_through_the_partial_camera_they_show() -> None:
    from piga.diagnostics.partial import partial_empty
    from piga.diagnostics.vision import empty_frames

    clean, seqs, times = _recording(seqs=8, t=8)
    late = times >= 4
    frames = torch.where(torch.from_numpy(late)[:, None, None, None], Camera(blur=3.0).apply(clean), clean)
    x = torch.from_numpy(_uint8(frames).astype(np.float32) / 255).flatten(1)
    renders = decoder_renders(MODEL, 180)
    # with no camera the blurred frames lie nearer the empty scene than any sharp rod
    assert empty_frames(MODEL, Camera(), x, renders) > 0.3
    seen = PartialCamera(Camera(blur=3.0), "frames", tuple(range(4, 8)), 8, 0.5)
    assert partial_empty(MODEL, seen, x, seqs, times, renders, 0.1) == 0.0
    # a camera that leaves too little of the rod's contrast shows no frame with it in view (blank frames read through
    # one are no camera's)
    assert empty_frames(MODEL, Camera(blur=3.0), x, renders, 0.99) == 1.0
    assert empty_frames(MODEL, [Camera(), Camera(blur=3.0)], x, renders) == 0.0  # in view through one of them


def test_frames_in_view_through_another_camera_are_not_refused_as_empty() -> None:
    from piga.diagnostics.diagnose import NotTheSceneError, check_in_view

    config = CameraConfig()
    check_in_view(SimpleNamespace(missing=0.01, unseen=0.01), config)
    with pytest.raises(NotTheSceneError, match="camera seems to differ between parts") as differs:
        check_in_view(SimpleNamespace(missing=0.64, unseen=0.0), config)
    assert "cut frames" not in str(differs.value)
    with pytest.raises(NotTheSceneError, match="cut frames without it out"):
        check_in_view(SimpleNamespace(missing=0.5, unseen=0.5), config)
