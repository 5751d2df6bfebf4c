"""A scene's look (ball radius, colours, background) from the command line, for held-out checks."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from piga.cli.collect import main as collect_main
from piga.data.schema import load_states
from tests.helpers import assert_one_line, run_in_process


def test_look_options_change_the_picture_not_the_physics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "look.h5"
    code, _, err = run_in_process("piga-collect", collect_main, "--system", "spring", "--out", str(out), "--sequences", "3",
                                  "--steps", "6", "--workers", "1", "--split", "1,1,1", "--radius", "4", "--colors",
                                  "gold", "#33e5e5", "--background", "#401a4d", "--quiet", capsys=capsys)
    assert code == 0, err
    with h5py.File(out) as f:
        frames = f["frames"][()]  # (N, T, H, W, 3)
    states = load_states(out, "train")[0, 0]  # x0, y0, x1, y1, ...
    background = np.round(np.array([0x40, 0x1A, 0x4D]))
    np.testing.assert_allclose(frames[0, 0, 0, 0], background, atol=1)  # a corner: balls keep off the walls
    for j, rgb in enumerate([(255, 215, 0), (0x33, 0xE5, 0xE5)]):
        x, y = states[2 * j : 2 * j + 2]
        np.testing.assert_allclose(frames[0, 0, int(y), int(x)], rgb, atol=1)  # the centre pixel is the ball's colour
        # radius 4: about π·(4 - 0.7)² = 34 pixels lie wholly inside a ball (radius 3 gives about 17)
        full = (np.abs(frames[0, 0].astype(int) - rgb).max(axis=-1) <= 1).sum()
        assert full > 25, full


@pytest.mark.parametrize("argv, needles", [
    (["--system", "spring", "--colors", "gold"], ["--colors", "2 objects", "1 colour"]),
    (["--system", "spring", "--colors", "gold", "not-a-colour"], ["not a colour", "not-a-colour"]),
    (["--system", "spring", "--background", "nope"], ["not a colour", "nope"]),
    (["--system", "digits-spring", "--background", "white"], ["digits", "texture"]),
    (["--radius", "4"], ["--radius", "scenes"]),
    (["--system", "spring", "--radius", "20"], ["too small"]),
])
def test_bad_look_is_one_line(argv: list[str], needles: list[str], tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process("piga-collect", collect_main, "--out", str(tmp_path / "x.h5"), *argv, capsys=capsys)
    assert_one_line(code, err, *needles)
    assert not (tmp_path / "x.h5").exists()
