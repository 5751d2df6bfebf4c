"""The unseen-region spring data (``piga-collect --system spring --half``, the paper's Appendix D)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from envs.scenes import SceneError, scene_config
from piga.cli.collect import main as collect_main
from piga.cli.common import run_cli


def _ball_rows(frames: np.ndarray) -> np.ndarray:
    """Rows (…, H) that hold any ball pixel (the background is black): (…, H) bool."""
    return frames.max(axis=(-1, -2)) > 0  # frames (…, H, W, 3)


@pytest.mark.slow
def test_half_file_shows_the_bottom_half_only_in_the_test_extrapolation(tmp_path):
    path = tmp_path / "half.h5"
    args = ["--system", "spring", "--half", "--sequences", "8", "--split", "4,2,2", "--seed", "3", "--workers", "1",
            "--quiet", "--out"]
    assert collect_main([*args, str(path)]) == 0
    with h5py.File(path, "r") as f:
        frames, split = f["frames"][()], f["split"][()]  # (N, T, H, W, 3), (N,)
        assert f.attrs["scene_config"] and '"half": true' in f.attrs["scene_config"]
    half = frames.shape[2] // 2
    kept = scene_config("spring", half=True).half_frames
    rows = _ball_rows(frames)  # (N, T, H)
    assert rows[split < 2, :, :half].any()  # the balls are drawn at all
    assert not rows[split < 2, :, half:].any(), "a train or valid frame has ball pixels in the bottom half"
    assert not rows[split == 2, :kept, half:].any(), "a test input or prediction frame shows the bottom half"
    assert all(rows[n, kept:, half:].any() for n in np.flatnonzero(split == 2)), "a test sequence never goes down"
    again = tmp_path / "again.h5"
    assert collect_main([*args, str(again)]) == 0
    with h5py.File(again, "r") as f:
        assert np.array_equal(f["frames"][()], frames)  # the same seed gives the same data


def test_half_is_for_the_ball_spring_only():
    with pytest.raises(SceneError, match="spring scene"):
        scene_config("gravity", half=True)
    assert scene_config("spring", half=True).speed < scene_config("spring").speed  # the half speed, unless given
    assert scene_config("spring", half=True, speed=3.0).speed == 3.0


def test_half_refused_for_the_pendulum(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:  # run_cli turns the error into one line
        run_cli("piga-collect", collect_main, ["--half", "--out", str(tmp_path / "p.h5")])
    assert exc.value.code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--half" in err[0]
