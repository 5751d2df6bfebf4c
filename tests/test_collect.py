"""piga-collect's library side: determinism, splits and presets."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from piga.data.collect import PAPER_MAX_SPEED, PRESETS, CollectConfig, collect, empty_split_warning, split_counts
from piga.data.schema import inspect_dataset
from tests.helpers import run_in_process


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in ("frames", "actions", "states", "rewards", "split")}


def test_same_seed_same_bytes_whatever_the_workers(tmp_path: Path) -> None:
    base = CollectConfig(sequences=5, steps=6, seed=11, split=(3, 1, 1))
    one = collect(base, tmp_path / "w1.h5", progress=False, command="t")
    from dataclasses import replace

    two = collect(replace(base, workers=2, batch=2), tmp_path / "w2.h5", progress=False, command="t")
    other = collect(replace(base, seed=12), tmp_path / "s12.h5", progress=False, command="t")
    a, b, c = _arrays(one), _arrays(two), _arrays(other)
    for key in a:
        assert a[key].tobytes() == b[key].tobytes(), key
    assert not np.array_equal(a["frames"], c["frames"])
    assert not np.array_equal(a["actions"], c["actions"])


def test_contents_match_the_schema(tiny_data: Path) -> None:
    info = inspect_dataset(tiny_data)
    assert (info.n_sequences, info.steps, info.image_shape, info.action_dim) == (12, 16, (64, 64), 1)
    assert info.split_counts == {"train": 8, "valid": 2, "test": 2}
    assert info.system == "pendulum" and info.dt == 0.05
    assert info.params["g"] == 10.0 and info.params["actuation_gain"] == 1.0
    assert info.attrs["seed"] == 3 and info.attrs["command"] == "test"
    a = _arrays(tiny_data)
    assert a["actions"].min() >= -2 and a["actions"].max() <= 2 and a["actions"].std() > 0.5
    # consecutive states obey Pendulum-v1's step with the stored action (where the clip is idle)
    th, thd, u = a["states"][..., 0], a["states"][..., 1], a["actions"][..., 0]
    pred = thd[:, :-1] + (15 * np.sin(th[:, :-1]) + 3 * u[:, :-1]) * 0.05
    free = np.abs(pred) < 8
    assert np.allclose(thd[:, 1:][free], pred[free], atol=1e-4)


def test_rewards_are_gymnasiums_for_the_action_after_each_frame(tiny_data: Path) -> None:
    from piga.data.schema import load_rewards

    assert inspect_dataset(tiny_data).has_rewards
    a = _arrays(tiny_data)
    assert a["rewards"].dtype == np.float32 and a["rewards"].shape == a["frames"].shape[:2]
    th, thd, u = a["states"][..., 0], a["states"][..., 1], a["actions"][..., 0]
    wrapped = (th + np.pi) % (2 * np.pi) - np.pi
    expected = -(wrapped**2 + 0.1 * thd**2 + 0.001 * u**2)  # Pendulum-v1's reward from the state of frame t and u_t
    assert np.allclose(a["rewards"], expected, atol=1e-4)
    train = a["split"] == 0
    assert np.array_equal(load_rewards(tiny_data, "train"), a["rewards"][train])


def test_split_counts() -> None:
    assert split_counts(100, (0.8, 0.1, 0.1)) == (80, 10, 10)
    assert split_counts(6000, (5000, 500, 500)) == (5000, 500, 500)
    assert split_counts(10, (1.0, 0.0, 0.0)) == (10, 0, 0)
    for bad in [(0.5, 0.5), (0.5, 0.4, 0.4), (0, 0.5, 0.5), (-1, 1, 1), (5, 5, 5)]:
        with pytest.raises(ValueError):
            split_counts(10, bad)
    with pytest.raises(ValueError, match="no share"):  # rounding would have left it one sequence
        split_counts(5, (0, 0.5, 0.5))


def test_empty_split_warned() -> None:
    assert "valid and test empty" in empty_split_warning((0.8, 0.1, 0.1), {"train": 4, "valid": 0, "test": 0})
    assert "--split 2,1,1" in empty_split_warning((0.8, 0.1, 0.1), {"train": 4, "valid": 0, "test": 0})
    assert "test empty" in empty_split_warning((0.5, 0.5, 0.0001), {"train": 1, "valid": 1, "test": 0})
    # each empty split says whose numbers fall back to the train split: train-model measures on test only
    valid_only = empty_split_warning((0.05, 0.05, 0.9), {"train": 1, "valid": 0, "test": 9}) or ""
    assert "leaves valid empty, so the PlaNet-style baseline's validation will come from the train split" in valid_only
    assert "piga-train-model" not in valid_only
    assert "test empty, so piga-train-model's metrics will" in empty_split_warning((0.5, 0.5, 0.0001),
                                                                                  {"train": 1, "valid": 1, "test": 0})
    assert empty_split_warning((1, 0, 0), {"train": 4, "valid": 0, "test": 0}) is None  # as asked
    assert empty_split_warning((0.8, 0.1, 0.1), {"train": 8, "valid": 1, "test": 1}) is None


def test_empty_split_advice_fills_the_split() -> None:
    # the advised count, rounded as the collection rounds it, fills valid and test, and one fewer does not; so do the
    # advised counts
    for split in [(0.8, 0.1, 0.1), (0.9, 0.1, 0.0), (0.98, 0.01, 0.01)]:
        for n in (1, 2, 3, 5):
            warning = empty_split_warning(split, {"train": n, "valid": 0, "test": 0}) or ""
            fewest = int(re.search(r"give (\d+) sequences or more", warning).group(1))
            wanted = [share > 0 for share in split[1:]]
            assert [count > 0 for count in split_counts(fewest, split)[1:]] == wanted, (split, n, warning)
            assert [count > 0 for count in split_counts(fewest - 1, split)[1:]] != wanted, (split, n, warning)
            if (counts := re.search(r"--split (\d+),(\d+),(\d+)", warning)) is not None:
                asked = tuple(int(x) for x in counts.groups())
                assert [count > 0 for count in split_counts(n, asked)[1:]] == wanted, (split, n, warning)
            else:
                assert n <= sum(wanted), (split, n, warning)
    assert "give 6 sequences or more, or counts such as --split 1,1,1)" in (
        empty_split_warning((0.8, 0.1, 0.1), {"train": 3, "valid": 0, "test": 0}) or "")


def test_collect_warns_of_an_empty_split(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import collect as cli

    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(tmp_path / "a.h5"), "--sequences", "4",
                                  "--steps", "4", "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0 and err.count("\n") == 1 and "warning: the default preset's split 0.8,0.1,0.1 of 4 sequences" in err
    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(tmp_path / "b.h5"), "--sequences", "4",
                                  "--steps", "4", "--split", "0.5,0.1,0.4", "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0 and "warning: the split 0.5,0.1,0.4 of 4 sequences leaves valid empty" in err, err
    # a scene's paper preset, in counts, read "the split 0.833333,0.0833333,0.0833333", which no option had given
    code, _, err = run_in_process("piga-collect", cli.main, "--system", "spring", "--preset", "paper", "--out",
                                  str(tmp_path / "s.h5"), "--sequences", "6", "--steps", "4", "--workers", "1", "--quiet",
                                  capsys=capsys)
    assert code == 0 and ("warning: the paper preset's split 5000,500,500 (as proportions, 0.833,0.0833,0.0833) of 6 "
                          "sequences leaves valid and test empty") in err, err


def test_collect_warns_of_noise_that_buries_the_pendulum(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--effect noise=1000 clipped 90% of the pixels to 0 or 255 without a word, where a blanking exposure or too much
    blur is refused: noise at least the rod's contrast with the background is warned of; noise below it is not."""
    from piga.cli import collect as cli
    from piga.data.collect import rod_contrast
    from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum

    frame = make_pixel_pendulum(PixelPendulumConfig(draw_torque_arrow=False)).reset(seed=0)[0][-1]
    values, counts = np.unique(frame[frame < 255], return_counts=True)
    assert 255 - values[np.argmax(counts)] == rod_contrast() == 152  # the rod's own gray, measured on a frame
    for noise, warned in (("1000", True), ("152", True), ("151", False)):
        code, _, err = run_in_process("piga-collect", cli.main, "--out", str(tmp_path / "n.h5"), "--sequences", "4",
                                      "--steps", "4", "--split", "2,1,1", "--workers", "1", "--effect", f"noise={noise}",
                                      "--overwrite", "--quiet", capsys=capsys)
        assert code == 0 and err.count("\n") == int(warned), err
        assert (f"piga-collect: warning: --effect noise={noise} is at least the pendulum's contrast with the background "
                "(152 gray levels)" in err) is warned, err
    with h5py.File(tmp_path / "n.h5", "r") as f:  # the frames of noise 151: about half the pixels clipped
        frames = f["frames"][()]
    assert 0.4 < np.isin(frames, (0, 255)).mean() < 0.65


def test_preset_applies_and_explicit_options_win(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import collect as cli

    out = tmp_path / "p.h5"
    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(out), "--preset", "paper", "--sequences", "3",
                                  "--split", "1,1,1", "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0, err
    info = inspect_dataset(out)
    assert (info.n_sequences, info.steps) == (3, PRESETS["paper"].steps)  # --sequences wins, steps from the preset
    assert info.attrs["env_config"]["max_speed"] == PAPER_MAX_SPEED != CollectConfig().env.max_speed
    # --sequences alone keeps the preset's split in counts (5000,500,500) as its proportions
    out = tmp_path / "q.h5"
    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(out), "--preset", "paper", "--sequences", "12",
                                  "--steps", "3", "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0, err
    assert inspect_dataset(out).split_counts == {"train": 10, "valid": 1, "test": 1}


def test_max_angle_takes_pi_as_written() -> None:
    """The help gave the default as 3.142, which was then refused as out of range (above pi): pi rounded up to a few
    digits, and the word, are pi; a value beyond that rounding is left for the env to refuse."""
    import argparse
    import math

    from piga.cli.collect import angle_up_to_pi

    assert angle_up_to_pi("3.142") == angle_up_to_pi("3.1416") == angle_up_to_pi("pi") == math.pi
    assert angle_up_to_pi("3.15") == 3.15 and angle_up_to_pi("1.5") == 1.5
    with pytest.raises(argparse.ArgumentTypeError):
        angle_up_to_pi("a lot")


@pytest.mark.parametrize("sequences, steps, size", [(4, 8, 32), (12, 16, 64)])
def test_the_disk_check_names_about_the_size_the_file_takes(sequences: int, steps: int, size: int,
                                                           tmp_path: Path) -> None:
    """A refusal on a small disk called a 13.2 KiB file "about 130.0 KiB once compressed": HDF5's own bytes were a
    fixed 128 KiB, ten times what a small file holds."""
    from envs.pendulum import PixelPendulumConfig
    from piga.data.collect import disk_need

    config = CollectConfig(sequences=sequences, steps=steps, seed=5, workers=1, split=(sequences - 2, 1, 1),
                           env=PixelPendulumConfig(image_size=size))
    written = collect(config, tmp_path / "d.h5", progress=False, command="test").stat().st_size
    assert 0.9 < disk_need(config)[0] / written < 1.5, (disk_need(config)[0], written)


@pytest.mark.parametrize("scene", ["spring", "digits-spring"])
def test_the_disk_check_of_a_scene_names_about_the_size_the_file_takes(scene: str, tmp_path: Path) -> None:
    """Ball scenes were sized as if their frames shrank 4x, as digits' do; they shrink 24-28x."""
    if scene == "digits-spring":
        pytest.importorskip("sklearn", reason="the digits are scikit-learn's")
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene, scene_disk_need

    config = SceneCollectConfig(scene=scene_config(scene), sequences=6, steps=8, seed=5, split=(4, 1, 1))
    written = collect_scene(config, tmp_path / "d.h5", progress=False, command="test").stat().st_size
    assert 0.9 < scene_disk_need(config)[0] / written < 2.5, (scene_disk_need(config)[0], written)
