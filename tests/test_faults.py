"""A fault corpus, by command: bad input exits 1 (a usage error 2) with one line on stderr that says
what to change, never a traceback, and leaves nothing that blocks a rerun.

Each case runs the command's ``main`` in this process (through ``run_cli``, as its script does) on
tiny files derived from the session's ``tiny_data``, and checks the exit code, the one line and
what is on disk afterwards.
"""

from __future__ import annotations

import json
import math
import re
import os
import shutil
import signal
import sys
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from piga.cli import baseline, collect, control, demo, diagnose, importer, show, train
from tests.helpers import ENV, assert_one_line, assert_planet_run_finished, assert_sb3_run_finished, run_in_process
from tests.test_dmc import needs_dmc

TINY_PLANET = ("--steps", "2", "--batch-size", "2", "--chunk-length", "8", "--deter-size", "8", "--stoch-size", "4",
               "--threads", "1", "--quiet")
TINY_DDPG = ("--steps", "200", "--eval-every", "200", "--eval-episodes", "1", "--learning-starts", "100", "--batch-size", "32",
             "--threads", "1", "--quiet")
MAINS: dict[str, Callable[[Sequence[str] | None], int]] = {
    "piga-collect": collect.main, "piga-import": importer.main, "piga-baseline": baseline.main, "piga-control": control.main,
    "piga-diagnose": diagnose.main, "piga-train-model": train.main, "piga-demo": demo.main, "piga-show": show.main,
}


# ---------------------------------------------------------------------------------------------
# Helpers: derived files, and one refused command
# ---------------------------------------------------------------------------------------------


def _variant(src: Path, dst: Path, edit: Callable[[h5py.File], None]) -> Path:
    """A copy of the data file ``src`` at ``dst``, changed in place by ``edit``."""
    shutil.copyfile(src, dst)
    with h5py.File(dst, "a") as f:
        edit(f)
    return dst


def _replace(f: h5py.File, name: str, data: np.ndarray) -> None:
    del f[name]
    f[name] = data


def _blank(f: h5py.File) -> None:
    f["frames"][...] = 0


def _nan_state(f: h5py.File) -> None:
    states = f["states"][()]
    states[1, 2, 0] = np.nan
    f["states"][...] = states


def _nan_reward(f: h5py.File) -> None:
    rewards = f["rewards"][()]
    rewards[1, 2] = np.nan
    f["rewards"][...] = rewards


def _colour(f: h5py.File) -> None:
    _replace(f, "frames", np.repeat(f["frames"][()][..., None], 3, axis=-1))


def _colour_recording(f: h5py.File) -> None:
    """Colour frames in a file of no env (a recording): refused where the env is known, on open."""
    _colour(f)
    del f.attrs["env_config"]


def _channel_axis(f: h5py.File) -> None:
    _replace(f, "frames", f["frames"][()][..., None])


def _two_actions(f: h5py.File) -> None:
    _replace(f, "actions", np.repeat(f["actions"][()], 2, axis=-1))


def _no_actions(f: h5py.File) -> None:
    _replace(f, "actions", np.zeros((*f["actions"].shape[:2], 0), np.float32))


def _unknown_env_field(f: h5py.File) -> None:
    config = json.loads(f.attrs["env_config"])
    f.attrs["env_config"] = json.dumps({**config, "bogus": 1})


def _five_objects(f: h5py.File) -> None:
    f.attrs["n_objects"] = 5


def _labelled_spring(f: h5py.File) -> None:
    f.attrs["system"] = "spring"


def _still(f: h5py.File) -> None:
    """Each sequence its first frame repeated: a frozen camera."""
    frames = f["frames"][()]
    f["frames"][...] = np.repeat(frames[:, :1], frames.shape[1], axis=1)


def _text_env_field(f: h5py.File) -> None:
    config = json.loads(f.attrs["env_config"])
    f.attrs["env_config"] = json.dumps({**config, "gravity": "ten"})


def _labelled_dmc(f: h5py.File) -> None:
    """Said to be dm_control's, with its settings, step and true parameters (a bare 'env_id' is refused on open)."""
    from envs.dmc import DMCPendulumConfig

    config = DMCPendulumConfig()
    f.attrs.update({"env_id": "piga/DMCPendulum-v0", "env_config": json.dumps(config.to_dict()), "dt": config.dt,
                    "params": json.dumps(config.piga_params())})


def _env_renders_32(f: h5py.File) -> None:
    """``env_config`` says 32 px frames beside the file's 64 px ones."""
    config = json.loads(f.attrs["env_config"])
    f.attrs["env_config"] = json.dumps({**config, "image_size": 32})


def _cropped_63(f: h5py.File) -> None:
    _replace(f, "frames", f["frames"][()][:, :, :63, :63])
    del f.attrs["env_config"]  # (its 64 px frames contradict these, which is refused on open)


VARIANTS: dict[str, Callable[[h5py.File], None]] = {
    "blank": _blank, "nan_state": _nan_state, "nan_reward": _nan_reward, "colour": _colour, "channel_axis": _channel_axis,
    "two_actions": _two_actions, "no_actions": _no_actions, "unknown_env_field": _unknown_env_field,
    "labelled_spring": _labelled_spring, "still": _still, "text_env_field": _text_env_field, "labelled_dmc": _labelled_dmc,
    "env_renders_32": _env_renders_32, "cropped_63": _cropped_63, "colour_recording": _colour_recording,
}


@pytest.fixture(scope="module")
def files(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``tiny_data`` (12 pendulum sequences x 16 frames) and its faulty variants, by name; "balls5":
    a spring scene whose ``n_objects`` says 5 for its 2 balls."""
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene

    root = tmp_path_factory.mktemp("faults")
    made = {"tiny": tiny_data, **{name: _variant(tiny_data, root / f"{name}.h5", edit) for name, edit in VARIANTS.items()}}
    balls = collect_scene(SceneCollectConfig(scene=scene_config("spring"), sequences=4, steps=6, workers=1, split=(2, 1, 1)),
                          root / "balls.h5", progress=False, command="t")
    made["balls5"] = _variant(balls, root / "balls5.h5", _five_objects)
    made["scene_gravity"] = _variant(balls, root / "scene_gravity.h5", _scene_gravity)
    return made


def _scene_gravity(f: h5py.File) -> None:
    """A spring file whose 'scene' says gravity: the recipe followed the scene, the model the system."""
    f.attrs["scene"] = "gravity"


@pytest.fixture(scope="module")
def gravity_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny 3-body gravity scene: 4 sequences x 6 frames."""
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene

    return collect_scene(SceneCollectConfig(scene=scene_config("gravity"), sequences=4, steps=6, workers=1, split=(2, 1, 1)),
                         tmp_path_factory.mktemp("gravity") / "gravity.h5", progress=False, command="t")


@pytest.fixture(scope="module")
def baseline_runs(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A tiny PlaNet-style run and a tiny DDPG run (from the state)."""
    root = tmp_path_factory.mktemp("runs")
    runs = {"planet": root / "planet", "ddpg": root / "ddpg"}
    for argv in (("planet", str(tiny_data), "--out", str(runs["planet"]), *TINY_PLANET),
                 ("ddpg", "--obs", "state", "--out", str(runs["ddpg"]), *TINY_DDPG)):
        code = _exit_code(baseline.main, argv)
        assert code in (0, 1), argv  # 1: the tiny run did not learn (its outputs stay)
    return runs


def _exit_code(main: Callable[[Sequence[str] | None], int], argv: Sequence[str]) -> int:
    from piga.cli.common import run_cli

    saved = signal.getsignal(signal.SIGTERM)
    try:
        with pytest.raises(SystemExit) as info:
            run_cli("fixture", main, list(argv))
    finally:
        signal.signal(signal.SIGTERM, saved)
    return int(info.value.code or 0)


def _listing(folder: Path) -> list[str]:
    """Every path under ``folder``, relative, sorted (hidden partial files included)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def refused(prog: str, argv: Sequence[str], capsys: pytest.CaptureFixture[str], *needles: str, code: int = 1) -> str:
    """Runs ``prog`` with ``argv`` in this process; asserts exit ``code``, one stderr line holding each
    needle and no traceback; returns the line."""
    got, _, err = run_in_process(prog, MAINS[prog], *argv, capsys=capsys)
    return assert_one_line(got, err, *needles, status=code)


def _once(base: Sequence[str], given: Sequence[str]) -> list[str]:
    """``base``'s options without those ``given`` writes (each with its value, if it has one), then ``given``: every
    command refuses an option given twice."""
    flags = {word for word in given if word.startswith("--")}
    out: list[str] = []
    skip = False
    for word in base:
        if word.startswith("--"):
            skip = word in flags
        if not skip:
            out.append(word)
    return [*out, *given]


def _run_copy(run: Path, dst: Path, edit: Callable[[Path], None] | None = None) -> Path:
    shutil.copytree(run, dst)
    if edit is not None:
        edit(dst)
    return dst


def _edit_record(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def edit(run: Path) -> None:
        record = json.loads((run / "config.json").read_text())
        change(record)
        (run / "config.json").write_text(json.dumps(record))

    return edit


class _Usage:
    """What ``shutil.disk_usage`` returns, on a full disk."""

    total, used, free = 10**9, 10**9, 0


def _full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "disk_usage", lambda path: _Usage())


# ---------------------------------------------------------------------------------------------
# Every parser: no abbreviations
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("prog, argv, needle", [
    ("piga-control", ["--oracle", "--gravity", "14"], "unrecognized arguments: --gravity 14"),
    ("piga-collect", ["--out", "x.h5", "--grav", "14"], "unrecognized arguments: --grav 14"),
    ("piga-baseline", ["planet", "x.h5", "--out", "r", "--free", "3"], "unrecognized arguments: --free 3"),
    ("piga-baseline", ["ddpg", "--obs", "state", "--out", "r", "--learning", "1"], "unrecognized arguments: --learning 1"),
    ("piga-demo", ["--seq", "3"], "unrecognized arguments: --seq 3"),
    # a required option abbreviated was refused as missing ("required: --out"), with no word of the abbreviation
    ("piga-collect", ["--ou", "x.h5"], "unrecognized argument --ou: options are taken only as spelt in full; give --out"),
    ("piga-import", ["v", "a.csv", "--d", "0.05", "--out", "x.h5"], "unrecognized argument --d: options are taken "
                                                                   "only as spelt in full; give --dt"),
    ("piga-baseline", ["planet", "x.h5", "--ou=r"], "unrecognized argument --ou: options are taken only as spelt in "
                                                    "full; give --out"),
    # "--" ends the options: it was taken for an abbreviation of --out, which was given (after it)
    ("piga-show", ["--", "x.h5", "--out", "s.png"], "--out comes after '--', which ends the options (what follows it is "
                                                   "taken as file names); give the options before '--'"),
    ("piga-import", ["--", "v", "a.csv", "--dt", "0.05", "--out", "x.h5"], "--dt and --out come after '--'"),
    ("piga-baseline", ["planet", "--", "x.h5", "--out", "r"], "--out comes after '--'"),
    ("piga-demo", ["--", "--out", "d"], "--out comes after '--'"),  # (no required option: "unrecognized arguments")
    ("piga-control", ["--", "--oracle"], "--oracle comes after '--'"),
    # a positional argument written as an option: "unrecognized arguments: --data", with no word of its place
    ("piga-baseline", ["planet", "--data", "x.h5", "--out", "r"], "unrecognized argument --data: data is given without "
                                                                  "a flag, by its place (piga-baseline planet data ...)"),
    ("piga-train-model", ["--data", "x.h5", "--out", "r"], "unrecognized argument --data: data is given without a flag, "
                                                          "by its place (piga-train-model data ...)"),
    ("piga-import", ["v", "a.csv", "--dt", "0.05", "--out", "x.h5", "--actions=b.csv"],
     "unrecognized argument --actions: actions is given without a flag, by its place (piga-import recording actions"),
])
def test_abbreviations_are_refused(prog: str, argv: list[str], needle: str, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    refused(prog, argv, capsys, needle)
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("prog, argv, needle", [
    ("piga-import", ["v.mp4", "a.csv", "--out", "o.h5", "--dt", "0.05", "--dt", "0.1"], "--dt is given twice (0.05, then 0.1)"),
    ("piga-import", ["v.mp4", "a.csv", "--dt", "0.05", "--out=o1.h5", "--out", "o2.h5"], "--out is given twice (o1.h5, then o2.h5)"),
    ("piga-show", ["x.h5", "--out", "a.png", "--split", "train", "--split=test"], "--split is given twice (train, then test)"),
    ("piga-collect", ["--out", "x.h5", "--quiet", "--quiet"], "--quiet is given twice: give it once"),
    ("piga-collect", ["--out", "x.h5", "--env", "piga/DMCPendulum-v0", "--env-option", "mass=2", "--env-option", "mass=3"],
     "--env-option mass is given twice (2, then 3)"),
    ("piga-demo", ["--sequences", "3", "--sequences", "4"], "--sequences is given twice (3, then 4)"),
    ("piga-train-model", ["x.h5", "--out", "r", "--out", "s"], "--out is given twice (r, then s)"),
    ("piga-control", ["--oracle", "--episodes", "1", "--episodes", "2"], "--episodes is given twice (1, then 2)"),
    ("piga-control", ["--oracle", "--warm-start", "--no-warm-start"], "--warm-start/--no-warm-start is given twice"),
    ("piga-diagnose", ["--model", "r", "--data", "x.h5", "--out", "d", "--model", "s"], "--model is given twice (r, then s)"),
    ("piga-baseline", ["planet", "x.h5", "--out", "r", "--batch-size", "2", "--batch-size=3"], "--batch-size is given twice (2, then 3)"),
    ("piga-baseline", ["ddpg", "--obs", "state", "--out", "r", "--obs", "pixels"], "--obs is given twice (state, then pixels)"),
])
def test_an_option_given_twice_is_refused(prog: str, argv: list[str], needle: str, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The last of two values silently winning is a mistake waiting to be made; options meant to repeat still may."""
    monkeypatch.chdir(tmp_path)
    line = refused(prog, argv, capsys, needle, "give it once")
    assert line.startswith(f"{prog}: error: ")
    assert _listing(tmp_path) == []


def test_script_parsers_are_pigas_one_line_parser() -> None:
    """The benchmarks' parsers are piga's ArgumentParser: a usage error is one line (argparse's own prints the usage
    first) and no option is taken by an abbreviation of its name. The examples, which show the plain API, use
    argparse's with abbreviations off."""
    root = Path(__file__).parents[1]
    assert [p.name for p in sorted(root.glob("benchmarks/*.py")) if "argparse.ArgumentParser(" in p.read_text()] == []
    assert [p.name for p in sorted(root.glob("examples/*.py")) if "ArgumentParser(" in p.read_text()
            and "allow_abbrev=False" not in p.read_text()] == []


def test_a_failed_allocation_is_out_of_memory(capsys: pytest.CaptureFixture[str]) -> None:
    """torch's CPU allocator raises a RuntimeError (here its words for piga-baseline planet --deter-size
    100000000): one line that says so, exit 1, not an internal error."""
    def allocate(argv: object) -> int:
        raise RuntimeError("[enforce fail at alloc_cpu.cpp:127] err == 0. DefaultCPUAllocator: can't allocate memory: "
                           "you tried to allocate 120000000000 bytes. Error code 12 (Cannot allocate memory)")

    code, _, err = run_in_process("piga-baseline", allocate, capsys=capsys)
    assert code == 1 and err == "piga-baseline: error: out of memory (an array of 111.8 GiB did not fit); choose smaller " \
                                "sizes\n", err


# ---------------------------------------------------------------------------------------------
# piga-collect
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("argv, needles, code", [
    (["--effect", "delay=1000000000"], ["delay must be an integer >= 1 and <= 1000"], 1),
    (["--effect", "noise=1e30"], ["noise must be in [1e-06, 1000]"], 1),
    (["--system", "spring", "--radius", "1e-9"], ["radius must be at least 0.5 px"], 1),
    (["--image-size", "7"], ["--image-size=7 is out of range (--image-size in [8, 1024])"], 1),  # it said "sizes ... >= 1"
    (["--max-speed", "-1"], ["--max-speed=-1 is out of range (--max-speed in [0, 8])"], 1),  # it listed every field's range
    (["--env", "piga/DMCPendulum-v0", "--image-size", "7"], ["--image-size=7 is out of range (--image-size in [8, 1024]"], 1),
    (["--system", "digits-spring", "--background", "black"], ["--background: digits-spring draws its digits over a texture"], 1),
    # an OverflowError, then "need at least inf px"
    (["--system", "bouncing", "--radius", "1e308"], ["radius 1e+308 need images larger than 1024 px", "smaller radius"], 1),
    (["--system", "gravity", "--radius", "1e200"], ["radius 1e+200 need images larger than 1024 px", "smaller radius"], 1),
    (["--system", "bouncing", "--colors", "black", "black"], ["is the background's", "invisible"], 1),
    (["--system", "bouncing", "--colors", "red", "white", "--background", "white"], ["object 1's colour"], 1),
    (["--system", "spring", "--k", "1e6"], ["k = 1e+06 is too stiff", "below 2222.2222 "], 1),
    # the pendulum's largest frames bound the scenes too: 2000 px spring frames were written, then needed 147 GiB to train
    (["--system", "spring", "--image-size", "1025"], ["--image-size must be at most 1024 px", "got 1025"], 1),
    (["--system", "gravity", "--image-size", "5000"], ["--image-size must be at most 1024 px", "got 5000"], 1),
    (["--seed", "9" * 25], ["--seed: expected an integer in [0, 2^63 - 1]"], 1),
    (["--actuation-gain", "1e39"], ["--actuation-gain=1e+39 is out of range", "at most 1e+06"], 1),
    (["--gravity", "1e39"], ["--gravity x --gravity-mult = 1e+39 is out of range", "at most 1066"], 1),
    (["--gravity", "1100"], ["--gravity x --gravity-mult = 1100 is out of range", "at most 1066",
                             "explicit step of 0.05 s is unstable"], 1),  # a recording of the integrator's flip-flop
    (["--gravity", "1e-300"], ["--gravity x --gravity-mult = 1e-300 is out of range: at least 1e-06 m/s²",
                               "under a hundredth of a pixel in a 200-step episode"], 1),  # data with no gravity in them
    (["--gravity-mult", "1e-300"], ["--gravity x --gravity-mult = 1e-299 is out of range: at least 1e-06"], 1),
    (["--actuation-gain", "1e-300"], ["--actuation-gain=1e-300 is out of range: at least 1e-06", "a hundredth of a pixel"], 1),
    (["--effect", "delay=5"], ["delay=5 steps is not shorter than a sequence's 5 actions", "raise --steps"], 1),
    (["--effect", "frame_delay=7"], ["frame_delay=7 steps is not shorter", "all show the reset"], 1),
    (["--effect", "blur=900"], ["blur=900 px would blur the pendulum away in a 64 px frame", "at most 8 px"], 1),
    (["--effect", "blur=9"], ["at most 8 px"], 1),  # half the frame (32 px) was allowed: frames of 5 gray levels
    (["--env", "piga/DMCPendulum-v0", "--k", "3"], ["is for the scenes", "--env-option (mass, length, damping"], 1),
    (["--effect", "shift=-64"], ["shift=-64 px would move the pendulum out of a 64 px frame"], 1),
    (["--system", "bouncing", "--colors", "#000001", "white"], ["object 0's colour", "is within 0.1 of the background's"], 1),
    (["--env", "piga/DMCPendulum-v0", "--max-speed", "1e308"], ["--max-speed=1e+308 is out of range", "--max-speed in [0, π/0.02 ≈ 157.0796]"], 1),
    (["--env", "piga/DMCPendulum-v0", "--env-option", "damping=1e300"], ["damping=1e+300 is out of range", "damping in [0, 100]"], 1),
    (["--system", "gravity", "--g", "1e308"], ["weaker forces than g = 1e+308, m = 1 (the scene's own: g = 60, m = 1)"], 1),
    (["--system", "spring", "--k", "0.01", "--steps", "12", "--image-size", "20"], ["stronger forces than k = 0.01"], 1),
    # balls that overlap at rest: one hid the other at t = 0, "wrote"
    (["--system", "spring", "--l", "0.01"], ["spring: at l = 0.01 the balls rest with their centres 2l = 0.02 px apart",
                                             "diameter 2r = 6 px plus 1 px", "give l of at least 3.5 (r + 0.5)"], 1),
    (["--gravity", "-nan"], ["argument --gravity: expected a finite number > 0, got -nan"], 1),  # "expected one argument"
    (["--system", "gravity", "--g", "1e-300"], ["the forces move no ball by 0.01 px from a straight line in 6 frames",
                                                "the scene's own: g = 60, m = 1"], 1),  # straight lines, "wrote"
    (["--system", "gravity", "--m", "1e-10"], ["with g = 60, m = 1e-10 the forces move no ball by 0.01 px"], 1),
    (["--env", "piga/DMCPendulum-v0", "--env-option", "action_repeat=1.5"],
     ["--env-option action_repeat=1.5: expected an integer"], 1),  # it said "expected a int"
    (["--effect", "speed_clip=1e-9"], ["speed_clip must be in [0.0001, 8)"], 1),  # a still pendulum, "wrote"
    (["--env", "piga/DMCPendulum-v0", "--env-option", "damping=1e-320"],
     ["damping=1e-320 is below the smallest normal number", "give 0 or a larger value"], 1),  # MuJoCo: "too large"
    (["--env", "piga/DMCPendulum-v0", "--env-option", "length=1e-320"], ["length=1e-320 is out of range (length in [0.05"], 1),
    # an OverflowError in the mass's bound (exit 70), the mass blamed, and MuJoCo's "fromto points too close"
    (["--env", "piga/DMCPendulum-v0", "--env-option", "length=1e300"], ["length=1e+300 is out of range (length in [0.05"], 1),
    (["--env", "piga/DMCPendulum-v0", "--env-option", "length=1e20"], ["length=1e+20 is out of range",
                                                                        "the tip leaves the camera's view"], 1),
    (["--env", "piga/DMCPendulum-v0", "--env-option", "length=1e-300"], ["length=1e-300 is out of range",
                                                                          "hidden under its tip"], 1),
    # an option that does not apply, written at its default value: the file recorded it and ignored it
    (["--env", "piga/DMCPendulum-v0", "--gravity", "10"], ["--gravity is an option of piga/PixelPendulum-v0 only"], 1),
    (["--env", "piga/DMCPendulum-v0", "--gravity-mult", "1"], ["--gravity-mult is an option of piga/PixelPendulum-v0"], 1),
    (["--env", "piga/DMCPendulum-v0", "--actuation-gain", "1"], ["--actuation-gain is an option of"], 1),
    (["--system", "spring", "--env", "piga/PixelPendulum-v0"], ["--env: pendulum option(s), not for --system spring"], 1),
    (["--system", "spring", "--effect", "damping=0.1"], ["--effect: pendulum option(s), not for --system spring"], 1),  # ignored
    (["--system", "spring", "--g", "3"], ["--g: not a parameter of --system spring; it takes --k, --l"], 1),  # "['g']"
    (["--system", "gravity", "--gravity", "5"], ["--gravity: pendulum option(s), not for --system gravity; its "
                                                 "gravitational constant is --g (default 60)"], 1),
    (["--env", "piga/DMCPendulum-v0", "--env-option", "flip=sideways"], ["--env-option flip='sideways' is out of range"], 1),
])
def test_collect_refuses(argv: list[str], needles: list[str], code: int, tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-collect", _once(["--out", str(tmp_path / "d.h5"), "--sequences", "4", "--steps", "6", "--workers", "1",
                                   "--split", "2,1,1", "--quiet"], argv), capsys, *needles, code=code)
    assert _listing(tmp_path) == []


def test_collect_into_a_path_through_a_file_names_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "afile").write_text("x")
    refused("piga-collect", ["--out", str(tmp_path / "afile" / "x.h5"), "--quiet"], capsys, "afile is a file, not a folder")
    assert _listing(tmp_path) == ["afile"]


@pytest.mark.parametrize("prog, argv", [("piga-collect", ["--quiet"]), ("piga-show", ["data.h5"]),
                                        ("piga-control", ["run"])])
def test_an_output_file_named_as_a_folder_is_refused(prog: str, argv: list[str], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    # x.h5/ would write x.h5: the path's separator is dropped by the file system, not by the user
    refused(prog, [*argv, "--out", str(tmp_path / "x.h5") + "/"], capsys, "--out", "expected a file name")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("frames, needle", [
    (np.full((2, 3, 8, 8), 7, np.uint8), "every frame is blank"),
    (np.repeat(np.arange(128, dtype=np.uint8).reshape(2, 1, 8, 8), 3, axis=1), "nothing moves"),  # a frozen camera: it was kept
])
def test_blank_or_still_frames_are_never_kept(frames: np.ndarray, needle: str, tmp_path: Path) -> None:
    from piga.data.schema import DataFormatError, DatasetWriter

    with pytest.raises(DataFormatError, match=needle):
        with DatasetWriter(tmp_path / "d.h5", 2, 3, (8, 8), 1, None, {"system": "x", "dt": 1.0}) as writer:
            writer.write(0, frames, np.zeros((2, 3, 1), np.float32))
            writer.set_split(np.zeros(2))
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# piga-import
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def frame_folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Folders of 12 PNGs: "moving" (a square that moves), "blank" (all black), "sizes" (as "moving",
    but its 6th frame is 30x50)."""
    import imageio.v3 as iio

    root = tmp_path_factory.mktemp("recordings")
    folders = {"moving": root / "moving", "blank": root / "blank", "sizes": root / "sizes"}
    for name, folder in folders.items():
        folder.mkdir()
        for i in range(12):
            frame = np.zeros((30, 50) if name == "sizes" and i == 5 else (32, 32), np.uint8)
            if name != "blank":
                frame[i : i + 6, 8:14] = 220
            iio.imwrite(folder / f"f{i}.png", frame)
    return folders


@pytest.mark.parametrize("folder, values, argv, needles", [
    ("moving", ["1e300"] * 12, (), ["line 1: the action 1e300 is beyond ±1e+06"]),
    ("moving", ["0.5"] * 11 + ["-3e7"], (), ["line 12: the action -3e7"]),
    ("blank", ["0.5"] * 12, (), ["every frame is blank"]),
    ("moving", ["0.5"] * 12, ("--dt", "1e9"), ["dt must be the seconds between frames, 1e-05 to 10, got 1e+09"]),
    ("moving", ["0.5"] * 12, ("--dt", "1e-12"), ["dt must be the seconds between frames"]),
    ("moving", ["0.5"] * 12, ("--dt", "10.000001"), ["1e-05 to 10, got 10.000001"]),  # it said "got 10"
    ("sizes", ["0.5"] * 12, (), ["f5.png: 50x30 px (width x height), but f0.png is 32x32", "share one size"]),
])
def test_import_refuses(folder: str, values: list[str], argv: tuple[str, ...], needles: list[str],
                        frame_folders: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "u.csv"
    csv.write_text("\n".join(values) + "\n")
    dt = () if "--dt" in argv else ("--dt", "0.05")  # an option is given once
    refused("piga-import", [str(frame_folders[folder]), str(csv), *dt, "--steps", "4", "--image-size", "32",
                            "--split", "1,1,1", "--out", str(tmp_path / "out.h5"), *argv], capsys, *needles)
    assert _listing(tmp_path) == ["u.csv"]


# ---------------------------------------------------------------------------------------------
# piga-show
# ---------------------------------------------------------------------------------------------


def _grey(f: h5py.File) -> None:
    f["frames"][...] = 128


def _nan_action(f: h5py.File) -> None:
    actions = f["actions"][()]
    actions[2, 3, 0] = np.nan
    f["actions"][...] = actions


def test_show_refuses_a_file_with_a_nan_action(tiny_data: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    data = _variant(tiny_data, tmp_path / "d.h5", _nan_action)
    refused("piga-show", [str(data), "--out", str(tmp_path / "s.png")], capsys, "/actions holds NaN", "sequence 2, step 3")
    assert _listing(tmp_path) == ["d.h5"]


def test_show_draws_a_blank_file_with_a_warning(tiny_data: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Training refuses it; a viewer is how one finds out that the frames are blank."""
    from piga.cli.show import main

    data = _variant(tiny_data, tmp_path / "d.h5", _grey)
    code, _, err = run_in_process("piga-show", main, str(data), "--out", str(tmp_path / "s.png"), capsys=capsys)
    assert code == 0 and err.count("\n") == 1 and "warning: " in err and "every frame is blank (one flat level, 128)" in err
    assert _listing(tmp_path) == ["d.h5", "s.png"]


def test_show_draws_a_small_object_of_a_large_frame_and_says_it_is_faint(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Frames of 1024 px were handed whole to matplotlib, whose resampling left 6 px balls a few gray levels above
    black, without a word. Each frame is drawn area-averaged to its cell (the blob's light kept, spread over a pixel or
    two of the strip), and a note says that objects under a pixel of the strip show faint."""
    from piga.cli.show import main
    from piga.evaluation.plots import frame_strip

    frames = np.zeros((2, 2, 1024, 1024), np.uint8)  # [N, T, H, W]: a 6 px square moving right
    frames[:, 0, 500:506, 300:306] = frames[:, 1, 500:506, 310:316] = 255
    data = tmp_path / "big.h5"
    with h5py.File(data, "w") as f:
        f["frames"], f["actions"], f["split"] = frames, np.zeros((2, 2, 1), np.float32), np.zeros(2, np.int8)
        f.attrs.update({"system": "pendulum", "dt": 0.05})
    drawn = frame_strip(frames).axes[0].images[0].get_array()
    assert drawn.shape == (68, 68) and drawn.max() > 0  # the frame at the cell's size, the blob in it
    assert float(drawn.sum()) == pytest.approx(36 * 255 * (68 / 1024) ** 2, rel=0.1)  # its light, averaged
    code, out, err = run_in_process("piga-show", main, str(data), "--out", str(tmp_path / "s.png"), capsys=capsys)
    assert code == 0 and err == "" and out.count("\n") == 2, (out, err)
    assert "note: the frames are 1024x1024 px (width x height), drawn 68 px a side: each pixel of the strip averages " \
           "15.1x15.1 of theirs, and objects smaller than that show faint or not at all" in out


def _dangling_frames(f: h5py.File) -> None:
    del f["frames"]
    f["frames"] = h5py.ExternalLink("gone.h5", "/frames")


def _attr_edit(key: str, value: Any) -> Callable[[h5py.File], None]:
    return lambda f: f.attrs.__setitem__(key, value)


def _dmc_labelled(action_repeat: int | None, dt: float) -> Callable[[h5py.File], None]:
    """The file said to be dm_control's, at ``action_repeat`` (None: its env_config names none) and ``dt``, with its
    true parameters at the default physics."""
    from envs.dmc import DMCPendulumConfig

    def edit(f: h5py.File) -> None:
        config = {} if action_repeat is None else {"action_repeat": action_repeat}
        f.attrs.update({"env_id": "piga/DMCPendulum-v0", "env_config": json.dumps(config), "dt": dt,
                        "params": json.dumps(DMCPendulumConfig().piga_params())})
    return edit


def _env_config_edit(**fields: Any) -> Callable[[h5py.File], None]:
    """``env_config`` with ``fields`` changed."""
    return lambda f: f.attrs.__setitem__("env_config", json.dumps({**json.loads(f.attrs["env_config"]), **fields}))


@pytest.mark.parametrize("edit, needles", [
    (_dangling_frames, ["/frames is a link that does not resolve (to /frames in gone.h5)"]),
    (lambda f: _replace(f, "states", np.full(f["states"].shape, b"x", "S1")), ["/states must be real numbers"]),
    (lambda f: _replace(f, "states", f["states"][()].astype(np.complex64)), ["/states must be real numbers", "complex64"]),
    (lambda f: _replace(f, "states", f["states"][()].astype(np.float64) * 1e300), ["/states holds NaN or infinite values"]),
    (lambda f: _replace(f, "frames", np.zeros((*f["frames"].shape[:2], 0, 0), np.uint8)), ["/frames is empty"]),
    (_attr_edit("system", np.array(["pendulum"], dtype=h5py.string_dtype())), ["attribute 'system' must be one string",
                                                                              "got array(["]),
    (_attr_edit("system", ""), ["attribute 'system' must be one string naming the system", "got ''"]),
    (_attr_edit("system", 3), ["attribute 'system' must be one string", "got 3"]),
    (_attr_edit("dt", np.inf), ["attribute 'dt' must be the seconds between frames, 1e-05 to 10, got inf"]),
    (_attr_edit("dt", 1e-300), ["attribute 'dt' must be the seconds between frames"]),
    (_attr_edit("dt", True), ["attribute 'dt' must be"]),
    (_attr_edit("params", '{"g": null, "actuation_gain": 1}'), ["'params' must give each parameter as a finite number", "g=None"]),
    (_attr_edit("params", '{"g": "ten"}'), ["'params' must give each parameter as a finite number", "g='ten'"]),
    (_attr_edit("params", '{"g": NaN}'), ["'params' must give each parameter as a finite number", "g=nan"]),
    (_attr_edit("params", '{"g": 1e308, "actuation_gain": 1}'), ["'params' gives g=1e+308, beyond any physical value"]),
    (_attr_edit("params", '{"g": 10, "actuation_gain": -1e13}'), ["'params' gives actuation_gain=-1e+13", "at most 1e+12"]),
    (_attr_edit("params", '{"damping": 2e12}'), ["'params' gives damping=2e+12, beyond"]),
    (_attr_edit("params", '{"g": 1e-30, "actuation_gain": 1}'), ["'params' gives g=1e-30, below any physical value",
                                                                 "at least 1e-06 in magnitude, or 0"]),
    (_attr_edit("params", '{"g": 10, "actuation_gain": -1e-9}'), ["'params' gives actuation_gain=-1e-09, below"]),
    (_attr_edit("params", '{"g": -9.8}'), ["'params' gives g=-9.8; g is >= 0 in piga's conventions"]),
    (_attr_edit("params", '{"m": -1}'), ["'params' gives m=-1; m is >= 0"]),
    # attributes that contradict the env that made the file: g was trained for the wrong interval, without a word
    (_attr_edit("dt", 0.1), ["'dt' says the frames are 0.1 s apart, but piga/PixelPendulum-v0 (its 'env_id') steps "
                             "0.05 s; set 'dt' to 0.05, or collect the file again"]),
    (_env_renders_32, ["attribute 'env_config' says the env renders 32x32 gray frames (image_size 32), but the file's "
                       "frames are 64x64 gray; set env_config's image_size to 64"]),
    # colour frames where the env renders gray ones: trained on, and refused only by piga-diagnose
    (lambda f: _replace(f, "frames", np.repeat(f["frames"][()][..., None], 3, -1)),
     ["attribute 'env_config' says the env renders gray frames, but the file's frames are 64x64 with 3 channels; "
      "collect the file again"]),
    # frames of a size no env renders: "set env_config's image_size to 2048", which every command then refused
    (lambda f: _replace(f, "frames", f["frames"][()][:, :, :4, :4]),
     ["the file's frames are 4x4 gray; frames 4 px a side are outside the envs' 8 to 1024 px: resize them (as "
      "piga-import --image-size does), or collect the file again"]),
    (_dmc_labelled(2, 0.05), ["'dt' says the frames are 0.05 s apart, but piga/DMCPendulum-v0 (its 'env_id') steps 0.04 "
                              "s at env_config's action_repeat 2 (2 x 0.02 s); set 'dt' to 0.04, or collect"]),
    (_dmc_labelled(2, 0.06), ["steps 0.04 s at env_config's action_repeat 2", "set 'dt' to 0.04 or env_config's "
                              "action_repeat to 3, or collect"]),
    # an env_id that contradicts the file's settings and step: trained, then refused by piga-control
    (_attr_edit("env_id", "piga/DMCPendulum-v0"), ["attribute 'env_id' says piga/DMCPendulum-v0, but 'env_config' holds "
                                                   "piga/PixelPendulum-v0's settings (gravity, gravity_mult",
                                                   "set 'env_id' to piga/PixelPendulum-v0"]),
    # actions of fewer steps than the frames: "must be float ..., got float32 (12, 10, 1)" blamed their type
    (lambda f: _replace(f, "actions", f["actions"][()][:, :10]),
     ["/actions has shape (12, 10, 1), but /frames holds 12 sequences of 16 frames; /actions must be [N=12, T=16, A]: "
      "one action row per frame"]),
    # split_counts whose JSON a flipped byte broke: its text was quoted with the byte in it
    (_attr_edit("split_counts", '{"train": 8, "valid": 2, "test":\x012}'),
     ["attribute 'split_counts' must be a JSON object of sequences per split, got '{\"train\": 8, \"valid\": 2, "
      "\"test\":\\x012}'; fix the attribute or drop it"]),
    (_attr_edit("env_id", "Foo-v9"), ["attribute 'env_id' says Foo-v9, which is none of piga's envs",
                                      "set 'env_id' to piga/PixelPendulum-v0, or drop 'env_config'"]),
    (_dmc_labelled(None, 0.05), ["'dt' says the frames are 0.05 s apart, but piga/DMCPendulum-v0 (its 'env_id') steps a "
                                 "whole multiple of 0.02 s", "set 'dt' to 0.04 or 'env_id' to piga/PixelPendulum-v0"]),
    # env_config's physics against params: training scored g against one, piga-control read the other
    (_env_config_edit(gravity=5.0), ["attribute 'params' says g = 10, but 'env_config' (gravity 5, gravity_mult 1) "
                                     "makes g = 5", "fix the attribute that is wrong"]),
    (_env_config_edit(gravity_mult=2), ["'params' says g = 10, but 'env_config' (gravity 10, gravity_mult 2) makes g = 20"]),
    (_env_config_edit(actuation_gain=0.5), ["'params' says actuation_gain = 1, but 'env_config' (actuation_gain 0.5)"]),
    (lambda f: (_dmc_labelled(3, 0.06)(f), _env_config_edit(action_repeat=3, mass=2.0)(f)),
     ["'params' says actuation_gain = 1.32802, but 'env_config' (mass 2, length 0.5) makes actuation_gain = 0.664011"]),
    # the effects attribute against env_config's: training scored a against one, piga-control made the other
    (_attr_edit("effects", '{"gain": 0.5}'), ["attribute 'effects' says gain=0.5, but 'env_config' holds effects none",
                                              "fix the attribute that is wrong"]),
    (lambda f: (_env_config_edit(effects=[["damping", 0.3]])(f), f.attrs.__setitem__("effects", '{"damping": 0.2}')),
     ["attribute 'effects' says damping=0.2, but 'env_config' holds effects damping=0.3"]),
    # effects that env_config does not hold at all, and effects that piga-collect cannot make (accepted everywhere)
    (lambda f: (f.attrs.__setitem__("env_config", json.dumps({k: v for k, v in json.loads(f.attrs["env_config"]).items()
                                                              if k != "effects"})),
                f.attrs.__setitem__("effects", '{"damping": 0.5}')),
     ["attribute 'effects' says damping=0.5, but 'env_config' holds effects none"]),
    (lambda f: (_env_config_edit(effects=[["warp", 1]])(f), f.attrs.__setitem__("effects", '{"warp": 1}')),
     ["attribute 'effects' is not effects piga-collect makes (unknown effect 'warp'"]),
    (lambda f: (_env_config_edit(effects=[["damping", 50]])(f), f.attrs.__setitem__("effects", '{"damping": 50}')),
     ["the effects in 'env_config' are not effects piga-collect makes (effect damping=50", "use damping below 13.2"]),
    (_attr_edit("effects", "garbage"), ["attribute 'effects' is not effects piga-collect makes (expected a JSON object"]),
    # env_config's values that its env's config refuses (read by show, training, control and --env before)
    (_env_config_edit(gravity="ten"), ["attribute 'env_config' is not a valid PixelPendulumConfig", "gravity"]),
    (_env_config_edit(gravity=None), ["attribute 'env_config' is not a valid PixelPendulumConfig", "gravity"]),
    (_env_config_edit(max_speed="fast"), ["attribute 'env_config' is not a valid PixelPendulumConfig", "max_speed"]),
    (_env_config_edit(max_angle=7.0), ["attribute 'env_config' is not a valid PixelPendulumConfig", "max_angle"]),
])
def test_a_file_that_breaks_the_schema_is_named_on_open(edit: Callable[[h5py.File], None], needles: list[str],
                                                        tiny_data: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Dangling links, states that are not real numbers, frames of no pixels, a frame interval of no meaning and
    true parameters that no error can be scored against: one line on open (they were internal errors, or a
    run that trained before failing on them, or one whose scores read nan)."""
    data = _variant(tiny_data, tmp_path / "d.h5", edit)
    refused("piga-show", [str(data), "--out", str(tmp_path / "s.png")], capsys, *needles)
    assert _listing(tmp_path) == ["d.h5"]


@pytest.mark.parametrize("edit", [_dmc_labelled(3, 0.06), _dmc_labelled(None, 0.06),
                                  lambda f: (f.attrs.__setitem__("env_id", "elsewhere/Pendulum-v9"),
                                             f.attrs.__delitem__("env_config")),
                                  lambda f: f.attrs.__delitem__("env_id")])
def test_a_file_whose_dt_fits_its_env_is_read(edit: Callable[[h5py.File], None], tiny_data: Path,
                                              tmp_path: Path) -> None:
    """dm_control's frames at another action repeat (named or not), a recording of an env piga does not know (no
    'env_config' of piga's envs), a file from before env ids: their 'dt' is not refused (nor is an imported
    recording's, which names no env)."""
    from piga.data.schema import inspect_dataset

    data = _variant(tiny_data, tmp_path / "d.h5", lambda f: (edit(f), f.attrs.__setitem__("dt", 0.06)))
    assert inspect_dataset(data).dt == 0.06


def test_effects_that_env_config_also_holds_are_read(tiny_data: Path, tmp_path: Path) -> None:
    """The same effects in both attributes, in either order and as integers or floats, are not a contradiction."""
    from piga.data.schema import inspect_dataset

    data = _variant(tiny_data, tmp_path / "d.h5", lambda f: (
        _env_config_edit(effects=[["damping", 0.3], ["delay", 1]])(f),
        f.attrs.__setitem__("effects", '{"delay": 1.0, "damping": 0.3}')))
    assert inspect_dataset(data).attrs["effects"] == {"delay": 1.0, "damping": 0.3}
    data = _variant(tiny_data, tmp_path / "e.h5", lambda f: (  # env_config's effects as an object, as a user writes them
        _env_config_edit(effects={"delay": 1})(f), f.attrs.__setitem__("effects", '{"delay": 1}')))
    assert inspect_dataset(data).attrs["effects"] == {"delay": 1}


def test_one_bad_action_is_counted_in_the_singular() -> None:
    """It read "(1 entries; the first: sequence 0, step 2: nan)"."""
    from piga.data.schema import DataFormatError, check_actions

    actions = np.zeros((2, 4, 1), np.float32)
    actions[0, 2, 0] = np.nan
    with pytest.raises(DataFormatError, match=r"\(1 entry; the first: sequence 0, step 2: nan\)"):
        check_actions(actions, "a.h5")
    actions[1, 3, 0] = np.inf
    with pytest.raises(DataFormatError, match=r"\(2 entries; the first"):
        check_actions(actions, "a.h5")


def test_half_precision_actions_and_huge_rewards_are_read_without_warnings(tiny_data: Path, tmp_path: Path) -> None:
    """float16 actions were compared with ±1e6 in float16 (an overflow warning on stderr); float64 rewards
    beyond float32's range overflowed in the cast before the check named them."""
    import warnings

    from piga.data.schema import DataFormatError, check_actions, load_rewards

    data = _variant(tiny_data, tmp_path / "d.h5", lambda f: _replace(f, "rewards", f["rewards"][()].astype(np.float64) * 1e300))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_actions(np.ones((2, 3, 1), np.float16), "a.h5")
        with pytest.raises(DataFormatError, match="/rewards holds NaN or infinite values"):
            load_rewards(data, "train")
    # finite, but beyond what a reward loss can square: "training diverged: loss became inf at step 1", no fix named
    for scale, fine in ((1e30, False), (1e17, False), (1e6, True)):
        data = _variant(tiny_data, tmp_path / f"r{scale:g}.h5", lambda f: _replace(
            f, "rewards", np.where(np.arange(f["rewards"].shape[1]) == 3, -scale, f["rewards"][()])))
        if fine:
            assert load_rewards(data, "train").min() == -scale
        else:
            with pytest.raises(DataFormatError, match=r"/rewards holds values beyond ±1e\+15 .*rescale the rewards"):
                load_rewards(data, "train")


def test_a_true_parameter_of_zero_is_scored_infinitely_off() -> None:
    """A file's true g = 0 divided the relative error by zero (an internal error after training)."""
    import math

    from piga.evaluation.evaluate import parameter_errors
    from piga.world.model import ModelConfig, PhysicsModel

    errors = parameter_errors(PhysicsModel(ModelConfig()), {"g": 0.0, "actuation_gain": 1.0})
    assert math.isinf(errors["g"]["relative_error"]) and math.isfinite(errors["a"]["relative_error"])


@pytest.mark.parametrize("params", [{"g": 0, "actuation_gain": -1.0, "damping": 0.0}, {"g": 1e12, "actuation_gain": 1e-6},
                                    {"g": 1e-6, "actuation_gain": -1e12, "gravity": 1e15}])
def test_true_parameters_in_range_are_read_and_drawn_without_warnings(params: dict[str, float], tiny_data: Path,
                                                                      tmp_path: Path) -> None:
    """0, a signed actuation gain and the range's ends are accepted, and the learning curves draw them quietly (a true
    g of 1e308 overflowed in matplotlib, two lines on stderr); a parameter nothing scores (gravity) is not bounded."""
    import warnings

    import matplotlib.pyplot as plt

    from piga.data.schema import inspect_dataset
    from piga.evaluation.plots import curves_figure

    # without 'env_config', whose physics such params would contradict (refused on open): a file of another source
    data = _variant(tiny_data, tmp_path / "d.h5",
                    lambda f: (_attr_edit("params", json.dumps(params))(f), f.attrs.__delitem__("env_config")))
    assert inspect_dataset(data).params == params
    history = [{"epoch": e, "loss": 1.0 / e, "loss_pred": 0.5 / e, "loss_rec": 0.5 / e, "g": 9.0 + e, "a": 0.5 + e}
               for e in (1, 2)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = curves_figure(history, {"g": params["g"], "a": params["actuation_gain"]})
        fig.canvas.draw()
    plt.close(fig)


def test_a_true_parameter_of_zero_is_printed_without_an_error() -> None:
    """``learned: g=1.0179 (true 0, error inf%)``: a true 0 has no relative error; metrics.json stores null."""
    from piga.evaluation.evaluate import summary_line

    metrics = {"parameter_errors": {"g": {"learned": 1.0179, "true": 0.0, "relative_error": math.inf},
                                    "a": {"learned": 1.01, "true": 1.0, "relative_error": 0.01},
                                    "b": {"learned": 0.02, "true": 0.0, "relative_error": None}}}
    assert summary_line(metrics) == "g=1.0179 (true 0), a=1.0100 (true 1, error 1.00%), b=0.0200 (true 0)"


# ---------------------------------------------------------------------------------------------
# piga-baseline planet
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("data, argv, needles", [
    ("colour", (), ["'env_config' says the env renders gray frames", "64x64 with 3 channels"]),
    ("two_actions", (), ["has 2 action dimensions", "takes one"]),
    ("no_actions", (), ["has 0 action dimensions", "takes one"]),  # it said "RSSMConfig.action_dim must be >= 1"
    ("blank", (), ["every frame is blank"]),
    ("nan_state", (), ["/states holds NaN", "sequence 1, step 2"]),
    ("nan_reward", (), ["/rewards holds NaN", "sequence 1, step 2"]),
    ("tiny", ("--free-nats", "1e308"), ["--free-nats must be", "at most 1000"]),
    ("unknown_env_field", ("--iterative", "1", "--episode-steps", "16"), ["'env_config' has unknown field(s) bogus"]),
    ("tiny", ("--stoch-size", "50000000"), ["world model of these sizes needs about", "ask for less"]),
    ("tiny", ("--deter-size", "99999999999"), ["more weights than torch can index", "ask for less"]),  # an internal error
    ("tiny", ("--reward-units", "1" + "0" * 20), ["more weights than torch can index"]),  # beyond int64: a TypeError
    ("tiny", ("--steps", "9" * 20), ["--steps must be at most 10,000,000"]),  # it trained for ever
    ("tiny", ("--iterative", "1", "--round-steps", "99999999999"), ["rounds x steps_per_round", "at most 10,000,000"]),
    ("tiny", ("--reward-layers", "100000"), ["--reward-layers must be at most 100"]),  # it trained for hours
    ("still", (), ["nothing moves", "no motion to learn from"]),  # it trained and exited 0
    ("text_env_field", ("--iterative", "1", "--episode-steps", "16"),
     ["'env_config' is not a valid PixelPendulumConfig", "gravity must be a number, got 'ten'"]),  # "can't multiply sequence"
    # it trained, then the planner's episodes of 32 px frames failed in a convolution (exit 70), leaving the run behind
    ("env_renders_32", ("--iterative", "1", "--episode-steps", "16"),
     ["env_renders_32.h5: attribute 'env_config' says the env renders 32x32 gray frames", "the file's frames are 64x64 gray",
      "set env_config's image_size to 64"]),
])
def test_planet_refuses_before_touching_out(data: str, argv: tuple[str, ...], needles: list[str], files: dict[str, Path],
                                            tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-baseline", ["planet", str(files[data]), "--out", str(tmp_path / "run"), *_once(TINY_PLANET, argv)], capsys, *needles)
    assert _listing(tmp_path) == []


def test_planet_trains_on_frames_with_a_channel_axis(files: dict[str, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Gray frames stored as [N, T, H, W, 1]: the open-loop check after the first checkpoint works."""
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(files["channel_axis"]), "--out",
                                  str(tmp_path / "run"), *TINY_PLANET, capsys=capsys)
    assert_planet_run_finished(code, err)
    assert {"checkpoint.pt", "config.json", "metrics.json", "openloop.png"} <= set(_listing(tmp_path / "run"))


def test_planet_refuses_a_reward_term_that_drowns_the_frames(tiny_data: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """--reward-scale 1e308 was refused only after the run started, as "training diverged: loss became inf"."""
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), "--reward-scale", "1e308",
                              "--quiet"], capsys, "error: --reward-scale must be at most 1e+06")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("scale", [0.0, 1e-300, 9e-4])
def test_planet_refuses_a_reward_term_of_no_weight(scale: float, tiny_data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """--reward-scale 0 trained a reward head that never learned, which the planner then ranked its plans by (exit 0);
    1e-300 got past that check and made the term exactly 0 in float32."""
    from agents.planet.config import PlanetTrainConfig

    with pytest.raises(ValueError, match=r"reward_scale \(--reward-scale\) must be at least 0.001, got .*: below it the "
                                         r"reward head barely learns"):
        PlanetTrainConfig(reward_scale=scale)
    if scale:
        refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), "--reward-scale", str(scale),
                                  "--quiet"], capsys, "error: --reward-scale must be at least 0.001")
        assert _listing(tmp_path) == []


def test_planet_on_a_full_disk(tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                               monkeypatch: pytest.MonkeyPatch) -> None:
    _full_disk(monkeypatch)
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), *TINY_PLANET], capsys,
            "of disk, but", "0 B free")
    assert _listing(tmp_path) == []


def _disk_with_free(monkeypatch: pytest.MonkeyPatch, free: int) -> None:
    """Every disk has ``free`` bytes free."""
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=free))


def test_an_overwrite_counts_the_checkpoint_it_has_set_aside(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A baseline's --overwrite checks its disk after moving the replaced run into RUN/.replaced: counted there too, or
    the run that fit was refused its own --overwrite again."""
    from piga.io.replaced import ReplacedRun
    from piga.io.resources import RUN_DISK_MARGIN, check_run_disk

    run = tmp_path / "run"
    run.mkdir()
    checkpoint = 10 * 2**20
    with open(run / "checkpoint.pt", "wb") as f:
        f.truncate(checkpoint)
    ReplacedRun().set_aside(run)
    _disk_with_free(monkeypatch, checkpoint + RUN_DISK_MARGIN + 2**20)
    check_run_disk(run, checkpoint, "the PlaNet-style run", overwrite=True)


def test_a_resumed_run_counts_the_checkpoint_it_replaces(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run that started on a disk was refused its own --resume there: the check asked again for two checkpoints,
    counting the one the resume replaces as used, and offered "give another --out", which continues nothing."""
    from piga.io.resources import RUN_DISK_MARGIN, ResourceError, check_run_disk

    run = tmp_path / "run"
    run.mkdir()
    checkpoint = 10 * 2**20
    with open(run / "checkpoint.pt", "wb") as f:
        f.truncate(checkpoint)
    _disk_with_free(monkeypatch, checkpoint + RUN_DISK_MARGIN + 2**20)  # the first run's need less its checkpoint
    check_run_disk(run, checkpoint, "the training run", resume=True)
    # --overwrite replaces it too: the run that fit there was refused its own --overwrite ("needs about 84.0 MiB")
    check_run_disk(run, checkpoint, "the training run", overwrite=True)
    with pytest.raises(ResourceError, match=r"needs about 84\.0 MiB of disk, .*; free some space, or give another --out$"):
        check_run_disk(run, checkpoint, "the training run")
    _disk_with_free(monkeypatch, 60 * 2**20)
    # an old checkpoint larger than the new one's: the new one is still written beside it first
    with pytest.raises(ResourceError, match=r"needs about 65\.0 MiB of disk beyond the 10\.0 MiB"):
        check_run_disk(run, 2**20, "the training run", overwrite=True)
    with pytest.raises(ResourceError) as info:
        check_run_disk(run, checkpoint, "the training run", resume=True)
    assert str(info.value).startswith(f"the training run needs about 74.0 MiB of disk beyond the 10.0 MiB of {run} that "
                                      "it replaces, but "), str(info.value)
    assert str(info.value).endswith("has 60.0 MiB free; free some space"), str(info.value)


def test_a_demo_overwritten_counts_the_checkpoint_it_replaces(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """piga-demo --overwrite was refused on the disk where the same demo had fit: its checkpoint counted as taken."""
    import re

    import torch

    from piga.cli.demo import DEMO_RUN, check_demo_disk
    from piga.data.collect import CollectConfig
    from piga.io.resources import ResourceError, adam_checkpoint_bytes
    from piga.training.train import PRESETS
    from piga.world.variants import build_model

    out = tmp_path / "demo"
    (out / DEMO_RUN).mkdir(parents=True)
    with torch.device("meta"):
        checkpoint = adam_checkpoint_bytes(build_model(PRESETS["fast"].model))
    with open(out / DEMO_RUN / "checkpoint.pt", "wb") as f:
        f.truncate(checkpoint)
    _disk_with_free(monkeypatch, 0)
    with pytest.raises(ResourceError) as plain:
        check_demo_disk(out, CollectConfig(), resume=False)
    need = float(re.search(r"needs about ([\d.]+) MiB", str(plain.value)).group(1)) * 2**20
    _disk_with_free(monkeypatch, int(need - checkpoint / 2))
    check_demo_disk(out, CollectConfig(), resume=False, overwrite=True)
    with pytest.raises(ResourceError):  # (without --overwrite the checkpoint is not replaced)
        check_demo_disk(out, CollectConfig(), resume=False)


@pytest.mark.parametrize("prog, head", [("piga-train-model", []), ("piga-baseline", ["planet"])])
@pytest.mark.slow
def test_resume_on_a_small_disk_counts_the_runs_checkpoint(prog: str, head: list[str], tiny_run: Path,
                                                           baseline_runs: dict[str, Path], tiny_data: Path,
                                                           tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(tiny_run if prog == "piga-train-model" else baseline_runs["planet"], tmp_path / "run")
    _disk_with_free(monkeypatch, 2**20)
    more = ["--epochs", "2"] if prog == "piga-train-model" else ["--steps", "8"]
    refused(prog, [*head, str(tiny_data), "--out", str(run), "--resume", *more, "--quiet"], capsys,
            "of disk beyond the", f"of {run} that it replaces, but", "1.0 MiB free; free some space")


@pytest.mark.parametrize("prog, argv, needles", [
    ("piga-show", ["{data}", "--out", "{tmp}/s.png"],
     ["the strip keeps at least 4.0 MiB of disk free (what it writes takes under 2 MiB), but"]),
    ("piga-control", ["--write-goal-image", "{tmp}/g.png", "--angle", "10"],
     ["--write-goal-image", "keeps at least 4.0 MiB of disk free (what it writes takes under 2 MiB)"]),
    ("piga-collect", ["--out", "{tmp}/c.h5", "--sequences", "300", "--steps", "40", "--workers", "1"],
     ["needs up to 3.3 MiB of disk as it writes (a file of about 2.6 MiB once compressed, and 715.4 KiB kept free as "
      "it writes: about 552.0 KiB for the next sequences, and room for HDF5's metadata)"]),
    ("piga-demo", ["--out", "{tmp}/demo", "--sequences", "12"],
     ["needs about 144.1 MiB of disk for the whole demo (the data file, about 116.4 KiB; the training run, 140.0 MiB",
      "and 4.0 MiB kept free for its pictures and table), but", "free some space, or give another --out"]),
])
def test_disk_refusals_state_the_whole_need_or_the_headroom(prog: str, argv: list[str], needles: list[str],
                                                            tiny_data: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """On a 2 MiB disk the commands that write figures said "needs about 4.0 MiB" for files of some KiB, piga-demo
    said 4.0 MiB and then, on a larger disk, 140 MiB for its training, and piga-collect stated a write margin as the
    file's need."""
    _disk_with_free(monkeypatch, 2 * 2**20)
    refused(prog, [a.format(data=tiny_data, tmp=tmp_path) for a in argv], capsys, *needles)
    assert _listing(tmp_path) == []


def test_a_resumed_demo_counts_its_data_and_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    (out / "model").mkdir(parents=True)
    for path, size in ((out / "pendulum.h5", 2**20), (out / "model" / "checkpoint.pt", 38 * 2**20)):
        with open(path, "wb") as f:
            f.truncate(size)
    _disk_with_free(monkeypatch, 2 * 2**20)
    refused("piga-demo", ["--out", str(out), "--sequences", "12", "--resume"], capsys,
            "needs about 106.0 MiB of disk for the whole demo (the training run, 102.0 MiB for its checkpoints of "
            "38.0 MiB, metrics and figures, less the checkpoint it replaces;", "2.0 MiB free; free some space")


@pytest.mark.parametrize("argv, edit, needles", [
    (("--batch-size", "4"), None, ["--resume keeps the run's recipe; drop --batch-size"]),
    (("--seed", "3", "--free-nats", "2"), None, ["drop --free-nats, --seed"]),
    (("--iterative", "2"), None, ["--iterative:", "was trained without --iterative"]),
    (("--rounds", "3"), None, ["--rounds:", "was trained without --iterative"]),  # it was ignored
    (("--iterative", "2"), lambda run: (run / "config.json").unlink(),
     ["config.json is missing, and the checkpoint does not hold the --iterative settings", "--overwrite"]),
    ((), _edit_record(lambda r: r["train"].pop("steps")), ["'train' settings lack steps"]),
    ((), _edit_record(lambda r: r["train"].__setitem__("steps", "many")),
     ["'train' settings give steps as 'many', not an integer"]),  # "'<' not supported between instances of 'str' and 'int'"
])
def test_planet_resume_refuses(argv: tuple[str, ...], edit: Callable[[Path], None] | None, needles: list[str],
                               baseline_runs: dict[str, Path], tiny_data: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", edit)
    before = _listing(run)
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), "--resume", "--steps", "4", "--quiet", *argv],
            capsys, *needles)
    assert _listing(run) == before


@pytest.mark.parametrize("record", [{"zz": 1}, "drop kind"])
def test_planet_resume_judges_a_record_without_kind_by_its_checkpoint(record: Any, baseline_runs: dict[str, Path],
                                                                      tiny_data: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A planet run whose config.json was a JSON object without 'kind' was called "a piga-train-model run"; it is
    rebuilt from its planet checkpoint (here up to the recipe check), and a piga-train-model run is named by its own."""
    edit = _edit_record(lambda r: r.pop("kind")) if record == "drop kind" else (
        lambda run: (run / "config.json").write_text(json.dumps(record)))
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", edit)
    argv = ["planet", str(tiny_data), "--resume", "--steps", "4", "--quiet", "--batch-size", "4"]
    line = refused("piga-baseline", [*argv, "--out", str(run)], capsys, "drop --batch-size")
    assert "piga-train-model" not in line


def test_planet_resume_names_a_piga_run_by_its_checkpoint(tiny_run: Path, tiny_data: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(tiny_run, tmp_path / "run", lambda run: (run / "config.json").write_text('{"zz": 1}'))
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), "--resume", "--steps", "4", "--quiet"], capsys,
            f"--resume: {run} is a piga-train-model run (its checkpoint.pt), not a planet run (piga-baseline planet)")


@pytest.mark.parametrize("drop", [("train",), ("data", "data_fingerprint")])
def test_planet_resume_of_a_record_without_its_settings_takes_them_from_the_checkpoint(
        drop: tuple[str, ...], baseline_runs: dict[str, Path], tiny_data: Path, files: dict[str, Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A record whose 'train' settings were removed advised only --overwrite, which loses the run, and one without its
    data file resumed on any file, unchecked: both take what they lack from the checkpoint, saying so, and are then
    checked as a whole record is."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: [r.pop(key) for key in drop]))
    argv = ["--out", str(run), "--resume", "--steps", "4", "--quiet"]
    if drop == ("train",):
        refused("piga-baseline", ["planet", str(tiny_data), *argv, "--batch-size", "4"], capsys, "drop --batch-size")
    else:
        refused("piga-baseline", ["planet", str(files["two_actions"]), *argv], capsys, "was trained on", "give that file")
    code, out, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run),
                                    "--resume", "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert f"lacks its {', '.join(repr(key) for key in drop if key != 'data_fingerprint')} settings" in out, out
    assert "taken from the checkpoint" in out, out


def test_planet_resume_names_a_record_edited_to_another_kind(baseline_runs: dict[str, Path], tiny_data: Path,
                                                             tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A planet run whose config.json was edited to name ddpg was called "a ddpg run" (and ddpg --resume then advised
    --overwrite, which would lose it): its checkpoint says it is a planet run."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: r.update(kind="ddpg")))
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), "--resume", "--steps", "4", "--quiet"], capsys,
            f"--resume: {run / 'config.json'} names a ddpg run, but checkpoint.pt is a planet run's; restore its "
            "config.json, or delete it to resume from the checkpoint")


@pytest.mark.parametrize("change, needle", [
    (lambda r: r["train"].__setitem__("free_nats", 0.5), "(free_nats 0.5 there, "),
    (lambda r: r["train"].__setitem__("chunk_length", 6), "(chunk_length 6 there, 8 in the checkpoint)"),
    (lambda r: r["rssm"].__setitem__("deter_size", 16), "(deter_size 16 there, 8 in the checkpoint)"),
], ids=["free_nats", "chunk_length", "deter_size"])
def test_planet_resume_names_a_record_that_does_not_describe_its_checkpoint(change: Callable[[dict[str, Any]], None],
                                                                            needle: str, baseline_runs: dict[str, Path],
                                                                            tiny_data: Path, tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A planet run resumed with an edited free_nats or chunk_length trained on the edited value without a word, and
    its checkpoint then held it: a run never started with it. The record is named, with both values, before the command
    line is judged against it (the starting command's --chunk-length 8 is not blamed), and nothing is written."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(change))
    before = {path: path.read_bytes() for path in run.rglob("*") if path.is_file()}
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), "--resume", "--steps", "4", "--chunk-length",
                              "8", "--quiet"], capsys,
            f"{run / 'config.json'} does not describe the run its checkpoint holds " + needle,
            "restore the record's values, or delete it to resume from the checkpoint's")
    assert {path: path.read_bytes() for path in run.rglob("*") if path.is_file()} == before


@pytest.mark.parametrize("kind", ["planet", "ddpg"])
def test_resume_takes_the_runs_own_values_written_out(kind: str, baseline_runs: dict[str, Path], tiny_data: Path,
                                                       tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--seed 0 on a run of seed 0 was refused ("drop --seed") unless its starting command had written it, while
    piga-train-model took it: the run's own values may be named on --resume, another is refused."""
    run = _run_copy(baseline_runs[kind], tmp_path / "run")
    section = "train" if kind == "planet" else "ddpg"
    assert json.loads((run / "config.json").read_text())[section]["seed"] == 0
    head = ["planet", str(tiny_data)] if kind == "planet" else ["ddpg", "--obs", "state"]
    more = ["--steps", "4"] if kind == "planet" else ["--steps", "400"]
    code, _, err = run_in_process("piga-baseline", baseline.main, *head, "--out", str(run), "--resume", *more, "--seed",
                                  "0", "--threads", "1", "--quiet", capsys=capsys)
    assert code in (0, 1) and "drop" not in err and "Traceback" not in err, err
    refused("piga-baseline", [*head, "--out", str(run), "--resume", *more, "--seed", "5", "--quiet"], capsys,
            "drop --seed")


def test_ddpg_resume_names_an_edited_record_and_another_runs_buffer(baseline_runs: dict[str, Path], tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A record whose recipe no longer matched its checkpoint was blamed on the checkpoint ("may be truncated"), and
    another run's replay buffer failed at the first step in numpy's words ("could not broadcast")."""
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.save_util import save_to_pkl

    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", _edit_record(lambda r: r["ddpg"].__setitem__("gamma", 0.5)))
    argv = ["ddpg", "--obs", "state", "--out", str(run), "--resume", "--steps", "400", "--quiet"]
    refused("piga-baseline", argv, capsys, "config.json does not describe the run its checkpoint holds (gamma 0.5 "
            "there, 0.98 in the checkpoint): restore the record's values")
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run2")
    (buffer,) = (run / "replay_buffers").iterdir()
    import gymnasium as gym

    other = ReplayBuffer(10, gym.spaces.Box(-1, 1, (4,)), gym.spaces.Box(-1, 1, (1,)), device="cpu")
    save_to_pkl(buffer, other)
    refused("piga-baseline", [*argv[:4], str(run), *argv[5:]], capsys, f"{buffer} is the replay buffer of another run "
            "(observations (4,), this run's (3,))")


@pytest.mark.parametrize("key, value, held", [("obs", "pixels", "'state'"), ("env", "piga/DMCPendulum-v0", None)])
def test_ddpg_resume_names_a_record_whose_obs_or_env_was_edited(key: str, value: str, held: str | None,
                                                                 baseline_runs: dict[str, Path], tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """An edited obs read "dd was trained with --obs pixels, not state" (the command line blamed: --obs pixels then
    met the record's mismatch), and an edited env "not usable ...; start the run again with --overwrite": the record is
    compared with the checkpoint first."""
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", _edit_record(lambda r: r["ddpg"].__setitem__(key, value)))
    line = refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(run), "--resume", "--steps", "400", "--quiet"],
                   capsys, "config.json does not describe the run its checkpoint holds (", f"{key} {value!r} there, ",
                   "restore the record's values")
    assert held is None or f"there, {held} in the checkpoint" in line, line
    assert "--overwrite" not in line and "trained with --obs" not in line, line


def test_planet_resume_takes_a_fingerprint_that_is_not_text_as_none(baseline_runs: dict[str, Path], tiny_data: Path,
                                                                     tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A data_fingerprint edited to null read "tiny.h5 has changed since the run trained on it" of an untouched file:
    the file is then known by its path, as a run's from before fingerprints."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: r.update(data_fingerprint=None)))
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert "has changed" not in err, err


@pytest.mark.slow
def test_resume_on_the_same_contents_rewrites_the_records_data_name(baseline_runs: dict[str, Path], tiny_data: Path,
                                                                     tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A record whose "data" was edited to another file (or whose file was moved) resumed on the file given, matched by
    its contents, and went on naming the other one; a DDPG run from the state kept a data file it never read."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: r.update(data="other.h5")))
    moved = tmp_path / "moved.h5"
    shutil.copy(tiny_data, moved)
    code, out, err = run_in_process("piga-baseline", baseline.main, "planet", str(moved), "--out", str(run), "--resume",
                                    "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert f"named other.h5; {moved} holds the same data, and the record now names it" in out, out
    record = json.loads((run / "config.json").read_text())
    assert (record["data"], record["data_folder"]) == (str(moved), os.getcwd())
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "ddpg", _edit_record(lambda r: r.update(data="other.h5")))
    code, out, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(run),
                                    "--resume", "--steps", "400", "--threads", "1", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert "named other.h5 as its data file; --obs state reads none" in out, out
    assert json.loads((run / "config.json").read_text())["data"] is None


def test_planet_resume_takes_the_model_sizes_from_its_checkpoint(baseline_runs: dict[str, Path], tiny_data: Path,
                                                                 tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A config.json whose 'rssm' was edited into a list was an internal error (AttributeError); the checkpoint holds
    the sizes, and the record is rewritten with them."""
    own = json.loads((baseline_runs["planet"] / "config.json").read_text())["rssm"]
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: r.__setitem__("rssm", [1])))
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run), "--resume",
                                  "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((run / "config.json").read_text())["rssm"] == own


def test_planet_resume_refuses_another_data_file(baseline_runs: dict[str, Path], files: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    refused("piga-baseline", ["planet", str(files["two_actions"]), "--out", str(run), "--resume", "--steps", "4"], capsys,
            "was trained on", "two_actions.h5", "give that file")


def test_planet_resume_names_its_file_from_the_current_folder(baseline_runs: dict[str, Path], files: dict[str, Path],
                                                             tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """config.json records the data file as its command gave it and the folder that command ran in: the refusal
    names the file from the current folder, not by a path relative to another."""
    assert json.loads((baseline_runs["planet"] / "config.json").read_text())["data_folder"]

    def moved(record: dict[str, Any]) -> None:
        record.update({"data": "../moved.h5", "data_folder": str(tmp_path / "a" / "b")})

    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(moved))
    monkeypatch.chdir(tmp_path)
    refused("piga-baseline", ["planet", str(files["two_actions"]), "--out", str(run), "--resume", "--steps", "4"], capsys,
            f"was trained on {Path('a') / 'moved.h5'}, not ", "give that file")


@pytest.mark.parametrize("edit", ["actions", "later frames"])
def test_planet_resume_refuses_its_file_written_over_in_place(edit: str, baseline_runs: dict[str, Path], tiny_data: Path,
                                                              tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The file's contents were compared only when its path differed: a file collected again under the same name
    resumed the run on other data, exit 0 (piga-train-model refused it). So did a file whose sequences after the
    first were reversed in time (the fingerprint read the first sequence's frames only)."""
    data = tmp_path / "d.h5"
    shutil.copyfile(tiny_data, data)
    run = _run_copy(baseline_runs["planet"], tmp_path / "run",
                    _edit_record(lambda r: r.__setitem__("data", str(data))))
    with h5py.File(data, "a") as f:
        if edit == "actions":
            f["actions"][0] = -f["actions"][0]
        else:
            f["frames"][5:] = f["frames"][5:][:, ::-1]
    refused("piga-baseline", ["planet", str(data), "--out", str(run), "--resume", "--steps", "4", "--quiet"], capsys,
            f"{data} has changed since", "put the trained file back")


def test_planet_resume_refuses_rewards_written_over_in_place(baseline_runs: dict[str, Path], tiny_data: Path,
                                                             tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """/rewards, which the reward head learns from, changed in place: the resume trained on them (the fingerprint
    reads the actions, the split and the first sequence's frames only)."""
    data = tmp_path / "d.h5"
    shutil.copyfile(tiny_data, data)
    run = _run_copy(baseline_runs["planet"], tmp_path / "run",
                    _edit_record(lambda r: r.__setitem__("data", str(data))))
    assert "rewards_fingerprint" in json.loads((run / "config.json").read_text())
    with h5py.File(data, "a") as f:
        f["rewards"][3] = f["rewards"][3] + 1
    refused("piga-baseline", ["planet", str(data), "--out", str(run), "--resume", "--steps", "4", "--quiet"], capsys,
            f"{data} has changed since", "put the trained file back")


# ---------------------------------------------------------------------------------------------
# piga-baseline ddpg
# ---------------------------------------------------------------------------------------------


def test_ddpg_that_diverges_stops_with_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.sb3.config

    monkeypatch.setattr(agents.sb3.config, "MAX_LEARNING_RATE", math.inf)  # a rate the command refuses, to diverge
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG, "--learning-rate", "1e30"],
            capsys, "training diverged", "became", "no checkpoint was written yet")
    assert _listing(tmp_path) == []


def test_an_actor_critics_disk_check_counts_its_networks(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The check counted two replay buffers and a margin: a pixel run of --buffer-size 1000 passed it on a 150 MiB disk
    (126.5 MiB asked) and filled it at its second checkpoint, two buffers and three policy zips (about 37 MiB each)."""
    _disk_with_free(monkeypatch, 66 * 2**20)  # the buffers (1000 x 40 bytes) and the margin fit; the networks do not
    line = refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG,
                                     "--buffer-size", "1000"], capsys, "DDPG's run (a replay buffer of 1000) needs about")
    assert float(re.search(r"needs about ([\d.]+) MiB", line).group(1)) > 66, line
    assert _listing(tmp_path) == []


def test_a_checkpoint_that_fails_to_write_leaves_no_replay_buffer_astray(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk at the second checkpoint left its buffer (400.pkl, 33 MB of a pixel run) beside the one the
    checkpoint names, which a --resume then counted against the disk."""
    import errno

    import agents.sb3.train as sb3_train

    write, calls = sb3_train.write_checkpoint, []

    def full_the_second_time(*args: Any, **kwargs: Any) -> None:
        calls.append(1)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        write(*args, **kwargs)

    monkeypatch.setattr(sb3_train, "write_checkpoint", full_the_second_time)
    run = tmp_path / "run"
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(run), "--steps", "400", *TINY_DDPG[2:]], capsys,
            "the disk is full")
    assert sorted(p.name for p in (run / "replay_buffers").iterdir()) == ["200.pkl"]


def test_an_actor_critic_whose_policy_turns_nan_after_a_checkpoint_is_said_to_have_diverged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """SAC at --learning-rate 0.2: torch.distributions refused the NaN policy as it sampled ("Expected parameter loc
    ... found invalid values", not "training diverged", no checkpoint named); piga-control then called the run
    interrupted and sent it to --resume, which diverges again (an exact resume)."""
    from stable_baselines3 import DDPG

    from piga.cli.control import baseline_unfinished

    learn, calls = DDPG.learn, []

    def nan_on_the_second_chunk(self: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        if len(calls) == 2:
            raise ValueError("Expected parameter loc (Tensor of shape (1, 1)) of distribution Normal(loc: "
                             "tensor([[nan]])) to satisfy the constraint Real(), but found invalid values")
        return learn(self, *args, **kwargs)

    monkeypatch.setattr(DDPG, "learn", nan_on_the_second_chunk)
    run = tmp_path / "run"
    argv = ["ddpg", "--obs", "state", "--out", str(run), "--steps", "400", *TINY_DDPG[2:]]  # (TINY_DDPG's --steps 200)
    line = refused("piga-baseline", argv, capsys, "training diverged: the policy's action distribution became NaN by "
                   "step 200", f"last good checkpoint: {run / 'checkpoint.pt'}")
    assert json.loads((run / "config.json").read_text())["diverged"] == line.split("error: ", 1)[1]
    warning = baseline_unfinished(run)
    assert warning is not None and "diverged" in warning and "--overwrite and a lower learning rate" in warning
    calls.clear()
    calls.append(1)  # the resume's first chunk is the run's second: it diverges again, and the record says so still
    refused("piga-baseline", [*argv, "--resume"], capsys, "training diverged")
    assert "diverged" in json.loads((run / "config.json").read_text())
    monkeypatch.setattr(DDPG, "learn", learn)  # a resume that gets past the step: the record no longer says it
    code, _, err = run_in_process("piga-baseline", baseline.main, *argv, "--resume", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert "diverged" not in json.loads((run / "config.json").read_text())


@pytest.mark.parametrize("data, needles", [
    ("blank", ["every frame is blank"]),
    ("colour", ["'env_config' says the env renders gray frames", "64x64 with 3 channels"]),
    # the autoencoder learnt MuJoCo's frames, then DDPG ran on the pixel pendulum's (exit 0)
    ("labelled_dmc", ["--obs latent learns its codes from the file's frames", "acts on piga/PixelPendulum-v0",
                      "this file is pendulum from piga/DMCPendulum-v0",
                      "give a file that piga-collect wrote of piga/PixelPendulum-v0 (piga-collect --out DATA.h5)"]),
    ("env_renders_32", ["attribute 'env_config' says the env renders 32x32 gray frames", "the file's frames are 64x64 gray"]),
])
def test_ddpg_latent_refuses_unusable_frames(data: str, needles: list[str], files: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-baseline", ["ddpg", "--obs", "latent", "--data", str(files[data]), "--out", str(tmp_path / "run"),
                              *TINY_DDPG], capsys, *needles)
    assert _listing(tmp_path) == []


def test_ddpg_on_a_full_disk(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    _full_disk(monkeypatch)
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG], capsys,
            "replay buffer", "of disk, but")
    assert _listing(tmp_path) == []


def test_ddpg_refuses_a_replay_buffer_beyond_the_memory(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3 allocates the buffer untouched and fills it as the run goes: refused before the run, not killed hours in."""
    from piga.io import resources

    monkeypatch.setattr(resources, "available_memory", lambda: 10**6)
    refused("piga-baseline", ["ddpg", "--obs", "pixels", "--out", str(tmp_path / "run"), *TINY_DDPG], capsys,
            "DDPG's replay buffer of", "(--buffer-size) needs about", "of memory, but 976.6 KiB is available; ask for less")
    assert _listing(tmp_path) == []


def _truncate(run: Path) -> None:
    with open(run / "checkpoint.pt", "r+b") as f:
        f.truncate(100)


@pytest.mark.parametrize("argv, edit, needles", [
    (("--batch-size", "64"), None, ["--resume keeps the run's recipe; drop --batch-size"]),
    (("--learning-rate", "0.1", "--torque-arrow"), None, ["drop --learning-rate, --torque-arrow"]),
    ((), _edit_record(lambda r: r["ddpg"].pop("net_arch")), ["'ddpg' settings lack net_arch"]),
    (("--batch-size", "64"), _edit_record(lambda r: r.pop("ddpg")), ["drop --batch-size"]),  # taken from the checkpoint
    ((), _truncate, ["checkpoint.pt: not a readable DDPG checkpoint", "truncated"]),
    ((), _edit_record(lambda r: r["ddpg"].__setitem__("learning_rate", "fast")),
     # "'>' not supported between instances of 'str' and 'int'"; then "give learning_rate as 'fast', not a number
     # (edited); start the run again with --overwrite", where the checkpoint holds the value to restore
     ["config.json does not describe the run its checkpoint holds (learning_rate 'fast' there, 0.001 in the checkpoint): "
      "restore the record's values"]),
])
def test_ddpg_resume_refuses(argv: tuple[str, ...], edit: Callable[[Path], None] | None, needles: list[str],
                             baseline_runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", edit)
    before = _listing(run)
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(run), "--resume", "--steps", "400", "--quiet", *argv],
            capsys, *needles)
    assert _listing(run) == before


def test_ddpg_resume_takes_the_starting_command_again(baseline_runs: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The command that started a run, plus --resume, continues it: its recipe flags at the values it was started with
    are no change (they were refused: "drop --eval-every, --eval-episodes, ..."); a flag at another value still is."""
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run")
    start = ["ddpg", "--obs", "state", "--out", str(run), *TINY_DDPG, "--resume"]
    other = [("64" if word == "32" else word) for word in start]  # --batch-size 64
    refused("piga-baseline", other, capsys, "--resume keeps the run's recipe; drop --batch-size")
    code, stdout, err = run_in_process("piga-baseline", baseline.main, *start, capsys=capsys)
    assert "recipe" not in err and "training DDPG from state for 200 env steps" in stdout, err


@pytest.mark.parametrize("obs", ["state", "latent"])
def test_ddpg_interrupted_before_its_first_checkpoint_leaves_nothing(obs: str, tiny_data: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C in the autoencoder, or in DDPG after TensorBoard's folder appeared: the rerun is not refused."""
    import agents.sb3.autoencoder as autoencoder
    import agents.sb3.train as ddpg

    def interrupted_autoencoder(data: Any, config: Any, out: Path, progress: bool = True, device: str = "auto") -> None:
        Path(out).write_bytes(b"half an autoencoder")
        raise KeyboardInterrupt

    def interrupted_ddpg(config: Any, run_dir: Path, *args: Any, **kwargs: Any) -> None:
        (Path(run_dir) / "tensorboard" / "ddpg_1").mkdir(parents=True)
        raise KeyboardInterrupt

    monkeypatch.setattr(autoencoder, "train_autoencoder", interrupted_autoencoder)
    monkeypatch.setattr(ddpg, "train_sb3", interrupted_ddpg)
    out = tmp_path / "runs" / "run"
    data = ["--data", str(tiny_data)] if obs == "latent" else []
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", obs, *data, "--out", str(out), *TINY_DDPG,
                                  capsys=capsys)
    assert code == 130 and err.strip() == "piga-baseline: interrupted; nothing was written", err
    assert _listing(tmp_path) == []


def test_a_resume_interrupted_before_its_next_checkpoint_keeps_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """It said "nothing was written" beside a run folder of hours of training, as if the run were lost."""
    import agents.sb3.train as ddpg

    out = tmp_path / "run"
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(out), *TINY_DDPG,
                                  capsys=capsys)
    assert_sb3_run_finished(code, err)
    before = _listing(tmp_path)

    def interrupted_ddpg(config: Any, run_dir: Path, *args: Any, **kwargs: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(ddpg, "train_sb3", interrupted_ddpg)
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(out), "--resume",
                                  "--steps", "400", capsys=capsys)
    assert code == 130 and err.strip() == (f"piga-baseline: interrupted; {out / 'checkpoint.pt'} is as it was (stopped "
                                           "before the next checkpoint); continue with --resume"), err
    assert _listing(tmp_path) == before


@pytest.mark.slow
def test_ddpg_ctrl_c_in_a_real_run_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = subprocess.Popen(["piga-baseline", "ddpg", "--obs", "state", "--out", str(out), "--steps", "100000",
                             "--eval-every", "50000", "--learning-starts", "100", "--threads", "1", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    deadline = time.monotonic() + 120
    while not (out / "tensorboard").exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert (out / "tensorboard").exists(), "TensorBoard's folder never appeared"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.strip() == "piga-baseline: interrupted; nothing was written", err
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# piga-control
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fake_planet_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder that says it is a PlaNet-style run (commands must refuse it before reading its checkpoint)."""
    run = tmp_path_factory.mktemp("fake") / "planet"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"kind": "planet"}))
    (run / "checkpoint.pt").write_bytes(b"not read")
    return run


@pytest.mark.parametrize("argv, needles", [
    (["--oracle", "--goal-angle", "1e300"], ["--goal-angle must be an angle", "[-180, 180]", "1e+300"]),
    (["--oracle", "--goal-angle", "nan"], ["--goal-angle must be an angle"]),
    (["--oracle", "--goal-angle", "180.0000001"], ["within [-180, 180], got 180.0000001"]),  # it said "got 180"
    (["--oracle", "--goal-angle", "-inf"], ["within [-180, 180], got -inf"]),  # it said "expected one argument"
    (["--write-goal-image", "g.png", "--angle", "-400"], ["--angle must be an angle"]),
])
def test_control_refuses_meaningless_angles(argv: list[str], needles: list[str], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    refused("piga-control", argv, capsys, *needles)
    assert _listing(tmp_path) == []


def test_control_oracle_on_a_baseline_run_says_what_it_is(fake_planet_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused("piga-control", ["--oracle", "--model", str(fake_planet_run), "--episodes", "1"], capsys,
                   "is a piga-baseline planet run", "drop --oracle")
    assert "model_config" not in line


def test_holdable_range_is_one_value() -> None:
    """The README's holdable range and the goal-image warning's come from the same computed angle."""
    import re

    from envs.fields import upper_bound_text
    from piga.control.goal import HOLDABLE_ANGLE, holdable_angle

    assert HOLDABLE_ANGLE == holdable_angle(10.0, 1.0) == math.asin(0.4)
    root = Path(__file__).parents[1]
    pages = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    quoted = [value for page in pages if page.is_file()
              for value in re.findall(r"holdable\s+range \(±([\d.]+)°", page.read_text())]
    assert quoted and set(quoted) == {upper_bound_text(math.degrees(HOLDABLE_ANGLE), 4)}  # as the warning writes it


def test_video_on_a_full_disk_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from piga.evaluation.video import panels_video

    _full_disk(monkeypatch)

    def write(argv: object) -> int:
        panels_video([("real", np.zeros((5, 8, 8), np.uint8))], tmp_path / "v.mp4")
        return 0

    code, _, err = run_in_process("piga-control", write, capsys=capsys)
    assert_one_line(code, err, "the video v.mp4 needs about", "of disk")
    assert _listing(tmp_path) == []


def _writes_to_a_full_disk(monkeypatch: pytest.MonkeyPatch, folder: Path) -> list[object]:
    """Makes every atomic write in ``folder`` go through a link to ``/dev/full`` (the kernel's own ENOSPC, with no
    mount), and collects what Python could not raise (a finaliser's traceback): the list that is returned."""
    import sys

    import piga.io.atomic

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")

    def full(target: Path) -> Path:
        link = folder / f".{target.name}.partial-{os.getpid()}"
        if not os.path.lexists(link):
            link.symlink_to("/dev/full")
        return link

    unraisable: list[object] = []
    monkeypatch.setattr(piga.io.atomic, "partial_path", full)
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    return unraisable


@pytest.mark.parametrize("argv, needle", [
    (["--write-goal-image", "g.png", "--angle", "10"], "the disk is full"),
    (["--model", "RUN", "--video", "v.gif", "--episodes", "1", "--steps", "20", "--candidates", "8", "--iterations", "1",
      "--horizon", "2", "--quiet"], "its disk has"),
])
def test_an_image_on_a_disk_that_fills_is_one_line(argv: list[str], needle: str, tiny_piga_run: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """imageio's writer, failing as it closes the file, would print its finaliser's traceback when collected."""
    import gc

    argv = [str(tiny_piga_run) if word == "RUN" else word for word in argv]
    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.chdir(out)
    unraisable = _writes_to_a_full_disk(monkeypatch, out)
    code, _, err = run_in_process("piga-control", control.main, *argv, capsys=capsys)
    gc.collect()
    lines = [line for line in err.strip().splitlines() if "warning" not in line]  # the tiny run's "not converged"
    assert_one_line(code, "\n".join(lines), needle)
    assert unraisable == []
    assert _listing(out) == []


@pytest.mark.parametrize("argv, last", [
    (["--oracle", "--out", "res"], "md"),
    (["--model", "RUN", "--sweep", "1:1.2:0.2", "--workers", "1", "--out", "sw"], "png"),
])
def test_out_that_fills_the_disk_part_way_leaves_nothing_for_the_rerun(argv: list[str], last: str, tiny_piga_run: Path,
                                                                      tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """OUT.json, OUT.md (and OUT.png) are one set: the disk filling on the last leaves none, and the rerun works."""
    import errno

    from matplotlib.figure import Figure

    def full(self: object, path: object, *args: Any, **kwargs: Any) -> None:  # the .md or the .png only
        if f".{last}." in Path(str(path if last == "png" else self)).name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        write(self, path, *args, **kwargs)

    argv = [str(tiny_piga_run) if word == "RUN" else word for word in argv]
    argv += ["--episodes", "1", "--steps", "20", "--candidates", "8", "--iterations", "1", "--horizon", "2", "--quiet"]
    monkeypatch.chdir(tmp_path)
    owner, name = (Path, "write_text") if last == "md" else (Figure, "savefig")
    write = getattr(owner, name)
    with monkeypatch.context() as patch:
        patch.setattr(owner, name, full)
        code, _, err = run_in_process("piga-control", control.main, *argv, capsys=capsys)
    assert_one_line(code, "\n".join(line for line in err.splitlines() if "warning" not in line), "the disk is full")
    assert _listing(tmp_path) == []
    code, _, err = run_in_process("piga-control", control.main, *argv, capsys=capsys)
    assert code == 0, err
    assert len(_listing(tmp_path)) == (3 if last == "png" else 2)


def test_a_sweep_overwrite_interrupted_as_it_writes_keeps_the_earlier_set(tiny_piga_run: Path, tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str],
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C as --sweep --overwrite wrote its figure, the last of the set, deleted the earlier sw.json and sw.md and
    said "nothing was written"."""
    import hashlib

    from matplotlib.figure import Figure

    argv = ["--model", str(tiny_piga_run), "--sweep", "1:1.2:0.2", "--workers", "1", "--out", "sw", "--episodes", "1",
            "--steps", "20", "--candidates", "8", "--iterations", "1", "--horizon", "2", "--quiet"]
    monkeypatch.chdir(tmp_path)
    code, _, err = run_in_process("piga-control", control.main, *argv, capsys=capsys)
    assert code == 0, err

    def digests() -> dict[str, str]:
        return {p.name: hashlib.md5(p.read_bytes()).hexdigest() for p in tmp_path.iterdir()}

    before = digests()
    assert sorted(before) == ["sw.json", "sw.md", "sw.png"]

    def interrupted(self: object, path: object, *args: Any, **kwargs: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", interrupted)
    code, _, err = run_in_process("piga-control", control.main, *argv, "--seed", "1", "--overwrite", capsys=capsys)
    assert code == 130 and err.endswith("piga-control: interrupted; nothing was written\n"), err
    assert digests() == before


@pytest.mark.parametrize("stop", [OSError, KeyboardInterrupt])
def test_written_together_removes_what_it_wrote_and_puts_back_what_was_there(stop: type[BaseException],
                                                                             tmp_path: Path) -> None:
    """An --overwrite of a set stopped part-way (piga-control --sweep --overwrite, interrupted as it wrote) lost the
    earlier OUT.json, which it had replaced, and said "nothing was written"."""
    from piga.io.atomic import atomic_output, written_together

    kept, replaced, new = tmp_path / "kept.md", tmp_path / "replaced.json", tmp_path / "new.png"
    kept.write_text("old md")
    replaced.write_text("old json")
    with pytest.raises(stop), written_together([kept, replaced, new]):
        for path in (replaced, new):
            with atomic_output(path, overwrite=True) as tmp:
                tmp.write_text("new")
        raise stop("the disk filled on the last one")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.md", "replaced.json"]  # no hidden copy left
    assert kept.read_text() == "old md" and replaced.read_text() == "old json"
    with written_together([kept, replaced, new]):  # a set written whole replaces the earlier one
        for path in (kept, replaced, new):
            with atomic_output(path, overwrite=True) as tmp:
                tmp.write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.md", "new.png", "replaced.json"]
    assert {p.read_text() for p in tmp_path.iterdir()} == {"new"}


def test_a_set_inside_a_set_puts_back_what_was_there(tmp_path: Path) -> None:
    """piga-control writes --out's set inside the set with its --video: the inner set found the outer's kept copy."""
    from piga.io.atomic import atomic_output, written_together

    video, out = tmp_path / "v.mp4", tmp_path / "o.json"
    video.write_text("old video")
    out.write_text("old json")
    with pytest.raises(KeyboardInterrupt), written_together([video, out]):
        with atomic_output(video, overwrite=True) as tmp:
            tmp.write_text("new")
        with written_together([out]):
            with atomic_output(out, overwrite=True) as tmp:
                tmp.write_text("new")
            raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.json", "v.mp4"]
    assert video.read_text() == "old video" and out.read_text() == "old json"


def test_a_copy_kept_by_a_killed_set_is_removed_by_the_next_write(tmp_path: Path) -> None:
    from piga.io.atomic import atomic_output

    out = tmp_path / "out.json"
    out.write_text("earlier")
    stale = tmp_path / ".out.json.kept-999999999"  # (no such process)
    stale.write_text("kept by a killed command")
    with atomic_output(out, overwrite=True) as tmp:
        tmp.write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_a_gif_is_refused_before_the_episodes_where_an_mp4_fits(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A GIF takes about ten times an MP4's room: the check before the episodes knows."""
    from piga.evaluation.video import check_video_room
    from piga.io.resources import ResourceError

    class Usage:
        total, used, free = 10**9, 10**9 - 2 * 1024**2, 2 * 1024**2

    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage())
    check_video_room(tmp_path / "v.mp4", 200)
    with pytest.raises(ResourceError, match="the video v.gif needs about"):
        check_video_room(tmp_path / "v.gif", 200)


# ---------------------------------------------------------------------------------------------
# piga-diagnose and piga-train-model: data files are checked on open
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("data, needles", [
    ("blank", ["every frame is blank"]),
    ("still", ["nothing moves"]),
    ("nan_state", ["/states holds NaN"]),
])
def test_diagnose_refuses_data_before_the_diagnosis(data: str, needles: list[str], files: dict[str, Path],
                                                    tiny_piga_run: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-diagnose", ["--model", str(tiny_piga_run), "--data", str(files[data]), "--out", str(tmp_path / "report"),
                              "--quiet"], capsys, *needles)
    assert _listing(tmp_path) == []


def test_diagnose_refusing_an_unconverged_model_says_one_line(tiny_data: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A run that did not converge, refused by the diagnosis (as one whose autoencoder draws no
    pendulum is): the refusal alone, not the convergence warning first and then the refusal."""
    import types

    import piga.io.checkpoint
    import piga.diagnostics
    import piga.io.runs
    from piga.cli.common import PigaError

    def training_failed(*args: object, **kwargs: object) -> None:
        raise PigaError("the model's training failed: train it longer")

    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"converged": False, "convergence": {"reason": "too short"}}))
    pendulum = types.SimpleNamespace(config=types.SimpleNamespace(system="pendulum"))
    monkeypatch.setattr(piga.io.checkpoint, "require_piga_run", lambda *args: None)
    monkeypatch.setattr(piga.io.runs, "load_model", lambda path: (pendulum, {}))
    monkeypatch.setattr(piga.diagnostics, "diagnose", training_failed)
    refused("piga-diagnose", ["--model", str(run), "--data", str(tiny_data), "--out", str(tmp_path / "report"), "--quiet"],
            capsys, "training failed")
    assert _listing(tmp_path) == ["run", "run/metrics.json"]


def test_diagnose_on_a_baseline_run_says_what_it_is(files: dict[str, Path], fake_planet_run: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    line = refused("piga-diagnose", ["--model", str(fake_planet_run), "--data", str(files["tiny"]), "--out",
                                     str(tmp_path / "report")], capsys, "is a piga-baseline planet run", "piga-train-model")
    assert "model_config" not in line
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("data, needles", [
    ("blank", ["every frame is blank"]),
    ("nan_state", ["/states holds NaN"]),
    ("balls5", ["attribute 'n_objects' is 5 but 'scene_config' says 2"]),
    ("scene_gravity", ["attribute 'scene' is 'gravity', a gravity scene, but 'system' says 'spring'"]),
    # a pendulum file labelled 'spring' trained as a scene, and its refusal blamed a lost object
    ("labelled_spring", ["attribute 'system' says 'spring', whose model takes 0 action dimension(s), but /actions has 1"]),
    ("still", ["nothing moves"]),  # a model "learned" from a frozen camera, and the run exited as merely unconverged
])
def test_train_model_refuses_data_on_open(data: str, needles: list[str], files: dict[str, Path], tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-train-model", [str(files[data]), "--out", str(tmp_path / "run"), "--batch-size", "4", "--threads", "1",
                                 "--quiet"], capsys, *needles)
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("argv, needles, code", [
    (["--epochs", "9" * 20], ["epochs=99999999999999999999 plans", "more than 10,000,000", "lower --epochs"], 1),  # it trained for ever
    (["--budget-steps", "9" * 20], ["--budget-steps=99999999999999999999 plans", "more than 10,000,000"], 1),
    (["--model", "video-lstm", "--video-lstm-scale", "99999999"], ["--video-lstm-scale: expected an integer in [1, 32]"], 1),
    (["--data-file", "gravity", "--fixed-g", "1e308"], ["--fixed-g: expected a number from 1e-06 to 1e+06"], 1),  # NaN loss
    (["--data-file", "gravity", "--fixed-g", "1e-300"], ["--fixed-g: expected a number from 1e-06 to 1e+06", "got 1e-300"], 1),
    # the library's "(or 0: learn g)" was quoted, and 0 was then refused as not > 0
    (["--data-file", "gravity", "--fixed-g", "0"], ["--fixed-g: expected a number from 1e-06 to 1e+06, got 0"], 1),
    (["--epochs", "1", "--budget-steps", "50"], ["--epochs and --budget-steps both set the run's length"], 1),  # the budget
    (["--preset", "paper", "--budget-steps", "50"], ["the paper preset plans in epochs (1000)", "give --epochs"], 1),  # was ignored
])
def test_train_model_refuses_runs_it_could_never_finish(argv: list[str], needles: list[str], code: int, tiny_data: Path,
                                                        gravity_data: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """--video-lstm-scale 1e8 was an internal error (torch's size arithmetic overflowed)."""
    data = gravity_data if argv[:2] == ["--data-file", "gravity"] else tiny_data
    argv = argv[2:] if data == gravity_data else argv
    refused("piga-train-model", [str(data), "--out", str(tmp_path / "run"), "--batch-size", "4", "--threads", "1",
                                 "--quiet", *argv], capsys, *needles, code=code)
    assert _listing(tmp_path) == []


def test_a_model_too_large_to_count_is_a_resource_error() -> None:
    from piga.io.resources import ResourceError
    from piga.world.model import ModelConfig

    with pytest.raises(ValueError, match=r"video_lstm_scale must be in \[1, 32\]"):
        ModelConfig(architecture="video-lstm", video_lstm_scale=33)
    from agents.planet.config import RSSMConfig
    from agents.planet.rssm import parameter_count

    with pytest.raises(ResourceError, match="more weights than torch can index"):
        parameter_count(RSSMConfig(deter_size=10**11))


def test_train_model_refuses_frames_too_small_before_training(tiny_data: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """4x4 frames trained a whole run, then failed in the SSIM with scikit-image's message, leaving a run
    folder that made the rerun refuse."""
    rng = np.random.default_rng(0)
    def tiny_frames(f: h5py.File) -> None:
        _replace(f, "frames", rng.integers(0, 255, (*f["frames"].shape[:2], 4, 4)).astype(np.uint8))
        del f.attrs["env_config"]  # (its 64 px frames contradict these, which is refused on open)

    data = _variant(tiny_data, tmp_path / "d.h5", tiny_frames)
    refused("piga-train-model", [str(data), "--out", str(tmp_path / "run"), "--batch-size", "4", "--threads", "1", "--quiet"],
            capsys, "frames of 4x4 px are too small to learn from; at least 8x8")
    assert _listing(tmp_path) == ["d.h5"]


def test_n_objects_must_agree_with_the_states(files: dict[str, Path], tmp_path: Path) -> None:
    from piga.data.schema import DataFormatError, inspect_dataset

    def edit(f: h5py.File) -> None:
        f.attrs["n_objects"] = 5
        del f.attrs["scene_config"]
        del f.attrs["state_names"]

    path = _variant(files["balls5"], tmp_path / "b.h5", edit)
    with pytest.raises(DataFormatError, match="'n_objects' is 5, but /states holds 8 values per frame"):
        inspect_dataset(path)


def test_an_empty_split_reads_as_no_sequences(tiny_data: Path, tmp_path: Path) -> None:
    from piga.data.schema import load_states, read_sequences

    path = _variant(tiny_data, tmp_path / "all_train.h5", lambda f: f["split"].__setitem__(slice(None), 0))
    frames, actions = read_sequences(path, "test")
    assert frames.shape == (0, 16, 64, 64) and actions.shape == (0, 16, 1) and load_states(path, "valid").shape == (0, 16, 2)


# ---------------------------------------------------------------------------------------------
# piga-demo
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("argv, needles", [
    (["--goal-angle", "1e300"], ["--goal-angle must be an angle"]),
    (["--sequences", "1000000000"], ["needs about"]),
    (["--seed", "9" * 25], ["--seed: expected an integer in [0, 2^63 - 1]"]),
    (["--epochs", "1000000000"], ["--epochs: expected an integer in [1, 200]", "small default job"]),
    (["--episodes", "1000000000"], ["--episodes: expected an integer in [1, 100]"]),
    (["--control-steps", "1000000000"], ["--control-steps: expected an integer in [20, 5000]"]),
    # it ran, and a success meant the goal held for a step or two; then the range said [1, 5000] and a later line 20
    (["--control-steps", "19"], ["--control-steps: expected an integer in [20, 5000]", "held for the last 20 steps"]),
    (["--control-steps", "0"], ["--control-steps: expected an integer in [20, 5000]", "held for the last 20 steps"]),
])
def test_demo_refusals_leave_no_folder(argv: list[str], needles: list[str], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-demo", ["--out", str(tmp_path / "demo" / "out"), *argv], capsys, *needles)
    assert _listing(tmp_path) == []


def test_demo_interrupted_leaves_no_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "collect", interrupted)
    code, _, err = run_in_process("piga-demo", demo.main, "--out", str(tmp_path / "demo"), capsys=capsys)
    assert code == 130 and err.strip() == "piga-demo: interrupted; nothing was written", err
    assert _listing(tmp_path) == []


def test_demo_keeps_a_folder_that_existed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "demo").mkdir()
    refused("piga-demo", ["--out", str(tmp_path / "demo"), "--sequences", "1000000000"], capsys, "needs about")
    assert _listing(tmp_path) == ["demo"]
    assert os.listdir(tmp_path / "demo") == []


def test_demo_refuses_a_run_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A demo into a train-model run's folder locked it for minutes: other commands called that finished run "still
    being trained"."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"a run's")
    for extra in ([], ["--overwrite"]):
        refused("piga-demo", ["--out", str(run), *extra], capsys, "holds a run of its own (checkpoint.pt)",
                "give another --out")
    assert _listing(tmp_path) == ["run", "run/checkpoint.pt"]


def test_demo_refused_in_training_leaves_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Training refuses the collected data (too few sequences): the data and the strip go too, so that the
    rerun is refused for the same reason, not for files "from an earlier demo"."""
    from piga.cli.common import PigaError

    def fake_collect(config: Any, out: Path, **kwargs: Any) -> None:
        Path(out).write_bytes(b"data")

    def fake_show(argv: Sequence[str]) -> int:
        Path(argv[argv.index("--out") + 1]).write_bytes(b"png")
        return 0

    def refused_training(argv: Sequence[str], **_: Any) -> int:
        raise PigaError("27 training windows are fewer than one batch of 32")

    monkeypatch.setattr(demo, "collect", fake_collect)
    monkeypatch.setattr(demo.show, "main", fake_show)
    monkeypatch.setattr(demo.train, "main", refused_training)
    for _ in range(2):
        refused("piga-demo", ["--out", str(tmp_path / "demo"), "--sequences", "1"], capsys, "fewer than one batch")
        assert _listing(tmp_path) == []


def test_demo_failed_after_a_checkpoint_keeps_its_data_for_resume(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Training diverged after its first checkpoint: the data stays beside the model (it was deleted, the model kept)."""
    from piga.cli.common import PigaError

    def fake_collect(config: Any, out: Path, **kwargs: Any) -> None:
        Path(out).write_bytes(b"data")

    def diverged(argv: Sequence[str], prog: str, **_: Any) -> int:
        run = Path(argv[argv.index("--out") + 1])
        run.mkdir(parents=True, exist_ok=True)
        (run / "checkpoint.pt").write_bytes(b"ckpt")
        raise PigaError("the loss became NaN at epoch 3; model/checkpoint.pt holds epoch 2")

    monkeypatch.setattr(demo, "collect", fake_collect)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", diverged)
    refused("piga-demo", ["--out", str(tmp_path / "demo")], capsys, "the loss became NaN",
            "keeps this demo's data and model", "--resume")
    assert {"demo/pendulum.h5", "demo/model/checkpoint.pt"} <= set(_listing(tmp_path))


@pytest.mark.parametrize("learned", [True, False])
def test_a_resumed_demo_that_fails_in_training_removes_the_earlier_models_control_table(
        learned: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A resume that failed after its training's checkpoint left goal.png and control.md of the model it replaced;
    they are removed, and the refusal says so (it did not, where the run did not identify its parameters)."""
    from piga.cli.common import PigaError

    out = tmp_path / "demo"
    (out / "model").mkdir(parents=True)
    for name in ("pendulum.h5", "frames.png", "goal.png", "control.md", "model/checkpoint.pt"):
        (out / name).write_bytes(b"earlier")

    def failed(argv: Sequence[str], prog: str, **_: Any) -> int:
        (Path(argv[argv.index("--out") + 1]) / "checkpoint.pt").write_bytes(b"continued")
        if learned:
            raise PigaError("the loss became NaN at epoch 4; model/checkpoint.pt holds epoch 3")
        raise PigaError(f"the run did not identify its parameters; {_['longer'](260, 260, 'data', 26)}")

    monkeypatch.setattr(demo, "_check_kept_data", lambda data, config: None)
    monkeypatch.setattr(demo, "_check_not_the_users", lambda data: None)
    monkeypatch.setattr(demo, "_trained_on", lambda *args, **kwargs: True)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", failed)
    line = refused("piga-demo", ["--out", str(out), "--resume"], capsys,
                   "the loss became NaN" if learned else "did not identify", "--resume",
                   "(goal.png and control.md of the earlier demo, made with its model, were removed)")
    assert line.count("were removed") == 1 and line.count("keeps this demo's") == 1, line
    assert sorted(p.name for p in out.iterdir()) == ["frames.png", "model", "pendulum.h5"]


def test_a_demo_resumed_with_fewer_epochs_is_told_the_demos_option(tiny_data: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """piga-demo --resume --epochs 3, after 5, was told "--resume may raise --epochs or --budget-steps", and piga-demo
    has no --budget-steps."""
    from tests.helpers import train_tiny

    run = train_tiny(tiny_data, tmp_path / "run", epochs=2)
    code, _, err = run_in_process("piga-demo", lambda argv: train.main(argv, prog="piga-demo"), str(tiny_data),
                                  "--out", str(run), "--resume", "--epochs", "1", "--quiet", capsys=capsys)
    assert code == 1 and "--resume may raise --epochs, never lower them" in err and "--budget-steps" not in err, err
    code, _, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), "--resume",
                                  "--epochs", "1", "--quiet", capsys=capsys)
    assert code == 1 and "--resume may raise --epochs or --budget-steps, never lower them" in err, err


def test_demo_whose_model_did_not_learn_says_the_demos_way_to_train_longer(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The training's own fix (--max-minutes, --budget-steps: not the demo's options) gave way to the demo's, said once."""
    from piga.cli.common import PigaError

    def fake_collect(config: Any, out: Path, **kwargs: Any) -> None:
        Path(out).write_bytes(b"data")

    def not_learned(argv: Sequence[str], prog: str, longer: Any) -> int:
        run = Path(argv[argv.index("--out") + 1])
        run.mkdir(parents=True, exist_ok=True)
        (run / "checkpoint.pt").write_bytes(b"ckpt")
        raise PigaError(f"the run did not identify its parameters: it settled on nothing; {longer(260, 260, 'length', 26)}")

    monkeypatch.setattr(demo, "collect", fake_collect)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", not_learned)
    line = refused("piga-demo", ["--out", str(tmp_path / "demo")], capsys, "did not identify",
                   "run the demo again with --resume and a larger --epochs, up to 200 (its training took 260 of 260 planned "
                   f"steps), or with --overwrite and more --sequences; {tmp_path / 'demo'} keeps this demo's data and "
                   "model")
    assert line.count("keeps this demo's") == 1 and "--max-minutes" not in line and "--budget-steps" not in line


def test_the_demos_fix_for_a_run_that_did_not_learn_the_motion_reads_as_one_sentence() -> None:
    """It read "give it more or longer sequences, or dmx keeps this demo's data and model: run the demo again with
    --resume ...": the demo's words pasted into piga-train-model's, and the longer training first, where more data is
    what a run that did not learn the motion needs first."""
    from piga.cli.demo import _longer
    from piga.cli.train import _reason_for
    from piga.training.convergence import data_fix

    reason = "it did not learn the motion, so its parameters mean nothing; " + data_fix(240, 240)
    said, _ = _reason_for({"reason": reason, "planned_steps": 240, "steps": 240}, "piga-demo",
                          lambda planned, steps, need, epochs: _longer(Path("dmx"), planned, steps, need, epochs), "",
                          24)
    assert said == ("it did not learn the motion, so its parameters mean nothing; run the demo again with --overwrite and "
                    "more --sequences, or with --resume and a larger --epochs, up to 200 (its training took 240 of 240 "
                    "planned steps); dmx keeps this demo's data and model")


def test_the_demos_fix_for_a_file_without_a_test_split_is_more_sequences() -> None:
    """A 2-sequence demo ended "collect one with a test split to check them": the demo collects, with --sequences."""
    from piga.cli.demo import _longer
    from piga.cli.train import _reason_for
    from piga.training.convergence import SPLIT_FIX

    reason = "its parameters settled, but the file has no test sequences, so no frame it did not train on checks them; "
    said, whose = _reason_for({"reason": reason + SPLIT_FIX, "planned_steps": 2000, "steps": 2000}, "piga-demo",
                              lambda planned, steps, need, epochs: _longer(Path("dmx"), planned, steps, need, epochs),
                              " (options of piga-train-model)", 2000)
    assert (said, whose) == (reason + "run the demo again with --overwrite and --sequences 6 or more, which leave it a "
                             "test split", "")


def test_the_demos_fix_past_its_largest_epochs_is_piga_train_models() -> None:
    """A tiny demo's fast preset planned 300 epochs of a step each, and the demo said "--resume and a larger
    --epochs", which it refuses past 200."""
    from piga.cli.demo import _longer

    said = _longer(Path("dmx"), 300, 300, "data", 300)
    assert said == ("run the demo again with --overwrite and more --sequences (its training took 300 of 300 planned "
                    "steps in 300 epochs, and the demo's --epochs is at most 200), or train it longer with "
                    "piga-train-model dmx/pendulum.h5 --out dmx/model --resume --epochs 600 and then run the demo "
                    "again with --resume; dmx keeps this demo's data and model")


def test_demo_interrupted_in_training_says_what_it_kept(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from piga.cli.common import Interrupted
    from piga.data.collect import collect

    def small_collect(config: Any, path: Path, **kwargs: Any) -> None:  # (a real file: --resume reads it)
        collect(replace(config, steps=4, workers=1), path, **kwargs)

    def interrupted_training(argv: Sequence[str], prog: str, **_: Any) -> int:  # as piga-train-model after its first checkpoint
        raise Interrupted("model/checkpoint.pt holds epoch 1; continue with --resume")

    monkeypatch.setattr(demo, "collect", small_collect)
    monkeypatch.setattr(demo, "_check_enough_sequences", lambda config: None)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", interrupted_training)
    argv = ["--out", str(tmp_path / "demo"), "--sequences", "4", "--quiet"]
    code, _, err = run_in_process("piga-demo", demo.main, *argv, capsys=capsys)
    assert code == 130
    assert err.strip() == f"piga-demo: interrupted; {tmp_path / 'demo'} keeps pendulum.h5 from this demo; run the same " \
                          "command with --resume to continue it, or with --overwrite to start over", err
    assert _listing(tmp_path) == ["demo", "demo/pendulum.h5"]
    # interrupted again when resumed: the data file kept from the first run is named too (it was left out)
    code, _, err = run_in_process("piga-demo", demo.main, *argv, "--resume", capsys=capsys)
    assert code == 130 and "keeps pendulum.h5 from this demo" in err, err


def test_demo_resume_continues_from_what_it_kept(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """An interrupted demo blocked its plain rerun and had no way to continue: --resume keeps the data collected
    with the same --sequences and --seed, continues the training from its checkpoint, and redoes the rest."""
    from piga.cli.common import Interrupted
    from piga.data.collect import collect

    out = tmp_path / "demo"
    calls: list[tuple[str, list[str]]] = []

    def small_collect(config: Any, path: Path, **kwargs: Any) -> None:
        calls.append(("collect", []))
        collect(replace(config, steps=8, workers=1), path, **kwargs)

    def interrupted_training(argv: Sequence[str], prog: str, **_: Any) -> int:
        calls.append(("train", list(argv)))
        (out / "model").mkdir()
        (out / "model" / "checkpoint.pt").write_bytes(b"ckpt")
        raise Interrupted("model/checkpoint.pt holds epoch 1; continue with --resume")

    monkeypatch.setattr(demo, "collect", small_collect)
    monkeypatch.setattr(demo, "_check_enough_sequences", lambda config: None)
    monkeypatch.setattr(demo.show, "main", lambda argv: calls.append(("show", list(argv))) or 0)
    monkeypatch.setattr(demo.train, "main", interrupted_training)
    argv = ["--out", str(out), "--sequences", "4", "--quiet"]
    code, _, err = run_in_process("piga-demo", demo.main, *argv, capsys=capsys)
    assert code == 130 and "--resume to continue it" in err, err
    refused("piga-demo", argv, capsys, "pass --resume to continue that demo or --overwrite to replace it")
    refused("piga-demo", [*argv, "--resume", "--seed", "1"], capsys,
            "holds 4 pendulum sequences collected with seed 0, not this command's --sequences 4 --seed 1")
    refused("piga-demo", [*argv, "--resume", "--overwrite"], capsys, "give one of them")
    kept = (out / "pendulum.h5").read_bytes()
    (out / "pendulum.h5").write_bytes(kept[: len(kept) // 2])  # truncated: its line named no way out
    refused("piga-demo", [*argv, "--resume"], capsys, "pendulum.h5", "pass --overwrite (not --resume) to start the demo over")
    (out / "pendulum.h5").write_bytes(kept)
    calls.clear()

    def resumed_training(argv: Sequence[str], prog: str, **_: Any) -> int:
        calls.append(("train", list(argv)))
        raise Interrupted("again")

    monkeypatch.setattr(demo.train, "main", resumed_training)
    code, out_text, err = run_in_process("piga-demo", demo.main, *argv, "--resume", capsys=capsys)
    assert code == 130, err
    assert "[1/4] keeping the 4 sequences" in out_text and "[3/4] continuing the training" in out_text, out_text
    assert [name for name, _ in calls] == ["show", "train"]  # nothing collected again
    assert "--overwrite" in calls[0][1] and "--resume" in calls[1][1] and "--overwrite" not in calls[1][1]
    refused("piga-demo", ["--out", str(tmp_path / "empty"), "--resume"], capsys, "holds no earlier demo to continue")
    # a folder that kept only the pictures: --resume starts over (it said "no earlier demo", the plain rerun "pass
    # --resume", each sending the user to the other)
    shutil.rmtree(out / "model")
    (out / "pendulum.h5").unlink()
    (out / "frames.png").write_bytes(b"png")  # (the faked piga-show wrote none)
    calls.clear()
    code, out_text, err = run_in_process("piga-demo", demo.main, *argv, "--resume", capsys=capsys)
    assert code == 130 and "[1/4] collecting 4 sequences" in out_text, (out_text, err)
    assert [name for name, _ in calls] == ["collect", "show", "train"] and "--overwrite" in calls[2][1]


@pytest.mark.parametrize("prog, argv, needle", [
    ("piga-train-model", ["FILE", "--threads", "100000"], "--threads: expected an integer in [0, "),
    ("piga-baseline", ["planet", "FILE", "--out", "OUT", "--threads", "100000"], "--threads: expected an integer in [0, "),
    ("piga-baseline", ["ddpg", "--out", "OUT", "--threads", "100000"], "--threads: expected an integer in [0, "),
    ("piga-train-model", ["FILE", "--seed", "9" * 25], "--seed: expected an integer in [0, 2^63 - 1]"),
    ("piga-control", ["--oracle", "--seed", "9" * 25], "--seed: expected an integer in [0, 2^63 - 1]"),
])
def test_threads_and_seeds_are_refused_beyond_what_the_machine_and_the_generators_take(
        prog: str, argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A thread count above the CPUs crashes torch's pool; a seed above 2^63 - 1 overflows numpy's generator."""
    argv = [str(tmp_path / "x.h5") if a == "FILE" else str(tmp_path / "out") if a == "OUT" else a for a in argv]
    refused(prog, argv, capsys, needle)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--model", "RUN", "--oracle"], "not both"),
    (["--write-goal-image", "OUT.png", "--angle", "30", "--oracle"], "takes no --model or --oracle"),
    (["--write-goal-image", "OUT.png", "--angle", "30", "--episodes", "3"], "only writes a picture and exits; drop --episodes"),
    (["--oracle", "--workers", "3"], "--workers runs the jobs of --sweep"),
    (["--oracle", "--workers", "2"], "--workers runs the jobs of --sweep"),  # the default's value, given: still ignored
    (["--oracle", "--torque-arrow"], "the oracle plans on the true state and sees no frames: drop --torque-arrow"),
    (["--write-goal-image", "OUT.png", "--angle", "30", "--episodes=5"], "drop --episodes"),  # the default, as FLAG=VALUE
])
def test_control_refuses_options_it_would_ignore(argv: list[str], needle: str, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """--oracle beside a piga run, and --write-goal-image beside an agent, used to be silently ignored."""
    run = tmp_path / "run"  # a piga run folder, as far as its kind goes (refused before its checkpoint is read)
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"not read")
    argv = [str(run) if a == "RUN" else str(tmp_path / a) if a == "OUT.png" else a for a in argv]
    refused("piga-control", argv, capsys, needle)
    assert not (tmp_path / "OUT.png").exists()


@pytest.mark.parametrize("argv, needles", [
    (["--horizon", "7"], ["--horizon", "ddpg"]),
    (["--horizon", "20"], ["--horizon", "ddpg"]),  # the piga planner's own default: still not a DDPG option
    (["--no-warm-start"], ["--no-warm-start: a ddpg run plans", "a policy, no planner"]),  # the flag as written
    (["--not-told"], ["--not-told is for the piga agent", "ddpg run is never told"]),
])
def test_control_refuses_planner_options_for_a_baseline_run(argv: list[str], needles: list[str],
                                                            baseline_runs: dict[str, Path],
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A DDPG run has no planner and a PlaNet-style run plans with PlaNet's CEM: --horizon would be ignored, and
    so was --not-told (a baseline is never told)."""
    refused("piga-control", ["--model", str(baseline_runs["ddpg"]), *argv], capsys, *needles)


def test_a_folder_of_another_kind_is_not_offered_resume(baseline_runs: dict[str, Path], tiny_data: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A train-model run into a DDPG run's folder was told "already holds a run ... pass --resume", which then refused
    it as another kind's run; the same for the baselines into each other's folders."""
    line = refused("piga-train-model", [str(tiny_data), "--out", str(baseline_runs["ddpg"]), "--quiet"], capsys,
                   "already holds a piga-baseline ddpg run", "give another --out, or --overwrite")
    assert "--resume" not in line
    line = refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(baseline_runs["planet"])], capsys,
                   "already holds a piga-baseline planet run", "give another --out")
    assert "--resume" not in line


@pytest.mark.parametrize("argv, needles", [
    (["--not-told"], ["sac run is never told"]),
    (["--goal-angle", "30"], ["a sac run has no goal input"]),
    (["--horizon", "7"], ["a sac run plans with its own settings"]),
])
def test_control_names_a_ddpg_runs_algorithm(argv: list[str], needles: list[str], baseline_runs: dict[str, Path],
                                             tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A SAC run (a ``piga-baseline ddpg --algo sac`` run) was called "the ddpg agent" in control's refusals."""
    run = tmp_path / "sac"
    shutil.copytree(baseline_runs["ddpg"], run)
    record = json.loads((run / "config.json").read_text())
    record["ddpg"]["algo"] = "sac"  # the refusals come before the policy is loaded
    (run / "config.json").write_text(json.dumps(record))
    refused("piga-control", ["--model", str(run), *argv], capsys, *needles)


@pytest.mark.parametrize("argv, needles", [
    (["--model", "RUN"], ["trained on frames of piga/PixelPendulum-v0", "control it with --env piga/PixelPendulum-v0"]),
    (["--oracle", "--env-option", "mass2"], ["--env-option: expected KEY=VALUE"]),  # the flag was not named
])
def test_control_on_dmc_refuses_in_one_line(argv: list[str], needles: list[str], tiny_piga_run: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("dm_control")
    argv = [str(tiny_piga_run) if a == "RUN" else a for a in argv]
    refused("piga-control", ["--env", "piga/DMCPendulum-v0", "--episodes", "1", "--quiet", *argv], capsys, *needles)


@pytest.mark.parametrize("dt, data, needles", [
    (0.05, "pixel", ["trained on frames of piga/PixelPendulum-v0 (0.05 s apart)", "no action_repeat",
                     "control it with --env piga/PixelPendulum-v0", "piga-collect --env piga/DMCPendulum-v0"]),
    (0.05, None, ["frames 0.05 s apart (piga/PixelPendulum-v0's rate)", "control it with --env piga/PixelPendulum-v0"]),
    (0.03, None, ["trained on frames 0.03 s apart, and no action_repeat", "train one on frames of piga/DMCPendulum-v0"]),
    (0.06, None, ["the env steps 0.04 s; give --env-option action_repeat=3"]),
])
def test_a_piga_model_of_another_frame_rate_than_dmcs_is_told_what_matches(dt: float, data: str | None,
                                                                           needles: list[str], tiny_data: Path) -> None:
    """A model of the pixel pendulum's 0.05 s frames was told to set an action_repeat, which no integer makes."""
    from envs.dmc import DMCPendulumConfig
    from piga.cli.common import PigaError

    checkpoint = {"data": {"path": str(tiny_data)}} if data else {}
    with pytest.raises(PigaError) as info:
        control._check_dmc_rate("run", checkpoint, dt, DMCPendulumConfig())
    for needle in needles:
        assert needle in str(info.value), str(info.value)
    assert "control it with" not in str(info.value) or dt == 0.05


@pytest.fixture(scope="module")
def tiny_piga_run(tiny_run: Path) -> Path:
    """A one-epoch piga-train-model run on ``tiny_data``: the session's (tests/conftest.py)."""
    return tiny_run


@pytest.mark.parametrize("env_id, warned", [(None, True), ("piga/PixelPendulum-v0", False)])
def test_control_warns_of_a_model_that_learned_other_frames(env_id: str | None, warned: bool, tiny_piga_run: Path,
                                                            tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A model trained on an imported recording (its checkpoint names no env) controls Gymnasium's pendulum from
    the env's frames, another camera's picture: said in one warning line (it was said nowhere)."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    ckpt = torch.load(run / "checkpoint.pt", weights_only=False)
    assert ckpt["data"]["env_id"] == "piga/PixelPendulum-v0"  # what training records
    assert ckpt["data"]["env_config"]["image_size"] == 64  # the file's env settings too, kept where the file is gone
    ckpt["data"]["env_id"] = env_id
    torch.save(ckpt, run / "checkpoint.pt")
    _, _, err = run_in_process("piga-control", control.main, "--model", str(run), "--episodes", "1", "--steps", "20",
                               "--candidates", "8", "--iterations", "1", "--horizon", "2", "--quiet", capsys=capsys)
    assert ("not collected by piga-collect (an imported recording?)" in err) is warned, err


@pytest.mark.parametrize("extra, needles", [
    (["--seed", "7"], ["drop --seed"]),
    (["--preset", "paper"], ["drop --preset"]),
    (["--data-file", "balls"], ["continues on the file the run trained on", "without --resume"]),
])
def test_train_resume_refuses_what_it_would_ignore(extra: list[str], needles: list[str], tiny_piga_run: Path,
                                                   tiny_data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """--resume continues the run's recipe on its own file: another seed, preset or file used to be ignored."""
    run = _run_copy(tiny_piga_run, tmp_path / "run")
    data = tiny_data
    if extra[0] == "--data-file":  # another pendulum file of the same look, with other sequences
        from dataclasses import replace

        from piga.data.collect import CollectConfig, collect

        data, extra = tmp_path / "other.h5", []
        collect(replace(CollectConfig(), sequences=8, steps=16, workers=1, seed=3), data, command="t", progress=False)
    refused("piga-train-model", [str(data), "--out", str(run), "--resume", "--epochs", "2", "--quiet", *extra], capsys,
            *needles)


def _edit_checkpoint(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def edit(run: Path) -> None:
        import torch

        payload = torch.load(run / "checkpoint.pt", weights_only=False)
        change(payload)
        torch.save(payload, run / "checkpoint.pt")

    return edit


@pytest.mark.parametrize("change, needles", [
    (lambda c: c.pop("state"), ["it lacks the entry 'state'"]),  # an internal error (KeyError)
    (lambda c: c.pop("optimizer"), ["it lacks the entry 'optimizer'"]),
    (lambda c: c["state"].__setitem__("bogus", 1), ["not a readable piga checkpoint", "'bogus'"]),
    (lambda c: c["state"].__setitem__("step", -5), ["its step is -5, not a count"]),  # "trained 1 epoch (-5 steps)"
])
def test_train_resume_refuses_a_checkpoint_it_cannot_continue(change: Callable[[dict[str, Any]], None],
                                                              needles: list[str], tiny_piga_run: Path, tiny_data: Path,
                                                              tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(tiny_piga_run, tmp_path / "run", _edit_checkpoint(change))
    before = _listing(run)
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--epochs", "2", "--quiet"], capsys,
            *needles)
    assert _listing(run) == before


@pytest.mark.parametrize("kind, change, needles", [
    ("planet", lambda c: c.pop("optimizer"), ["it lacks the entry 'optimizer'"]),
    ("planet", lambda c: c["state"].__setitem__("step", "many"), ["its step is 'many', not a count"]),
    ("ddpg", lambda c: c.pop("episodes"), ["it lacks the entry 'episodes'"]),
])
def test_baseline_resume_refuses_a_checkpoint_it_cannot_continue(kind: str, change: Callable[[dict[str, Any]], None],
                                                                 needles: list[str], baseline_runs: dict[str, Path],
                                                                 tiny_data: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs[kind], tmp_path / "run", _edit_checkpoint(change))
    before = _listing(run)
    argv = (["planet", str(tiny_data), "--steps", "4"] if kind == "planet" else ["ddpg", "--obs", "state", "--steps", "400"])
    refused("piga-baseline", [*argv, "--out", str(run), "--resume", "--quiet"], capsys, *needles)
    assert _listing(run) == before


def test_a_zeroed_checkpoint_is_called_unreadable_not_lacking_an_entry(tiny_piga_run: Path, tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """torch's reader raises KeyError("filename 'storages' not found") for it, which read as a missing entry of that
    name ("it lacks the entry \"filename 'storages' not found\" that piga-train-model writes")."""
    run = _run_copy(tiny_piga_run, tmp_path / "run")
    size = (run / "checkpoint.pt").stat().st_size
    (run / "checkpoint.pt").write_bytes(bytes(size))
    line = refused("piga-control", ["--model", str(run), "--episodes", "1", "--steps", "20", "--quiet"], capsys,
                   "checkpoint.pt: not a readable piga checkpoint", "truncated")
    assert "lacks the entry" not in line


def test_a_checkpoint_whose_bytes_changed_is_refused(tiny_piga_run: Path, tmp_path: Path) -> None:
    """torch.load read a checkpoint with 64 bytes overwritten in the middle, and piga-control ran it (exit 0)."""
    from piga.io.checkpoint import RunKind, read_checkpoint

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    size = (run / "checkpoint.pt").stat().st_size
    with open(run / "checkpoint.pt", "r+b") as f:
        f.seek(size // 2)
        f.write(b"\xff" * 64)
    with pytest.raises(ValueError, match="fails its checksum"):
        read_checkpoint(run, RunKind.PIGA)


def test_a_baseline_run_whose_record_is_not_an_object_names_the_record(baseline_runs: dict[str, Path], tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A config.json of '[1, 2]' made the PlaNet-style checkpoint look like the wrong kind of run."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    (run / "config.json").write_text("[1, 2]")
    refused("piga-control", ["--model", str(run), "--episodes", "1", "--quiet"], capsys,
            "config.json, the run's record, is not a run record", "restore the file")


def test_train_resume_refuses_a_file_whose_dt_changed(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The fingerprint covers the arrays, not the attributes: a file whose 'dt' was edited was continued on, the
    physics stepping the run's own dt."""
    run, data = _run_copy(tiny_piga_run, tmp_path / "run"), tmp_path / "t.h5"
    shutil.copy(tiny_data, data)
    with h5py.File(data, "a") as f:
        f.attrs["dt"] = 0.1
        del f.attrs["env_id"]  # a file of no env (one of the pixel pendulum's is refused on open: it steps 0.05 s)
    refused("piga-train-model", [str(data), "--out", str(run), "--resume", "--epochs", "2", "--quiet"], capsys,
            "now says its frames are 0.1 s apart; the run trained on them as 0.05 s apart", "restore the file's 'dt'")


def test_train_resume_refuses_the_default_seed_written_for_a_run_of_another(tiny_piga_run: Path, tiny_data: Path,
                                                                            tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """--seed 0, the default, went through (and was ignored) on the resume of a run of seed 3."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["train_config"]["seed"] = 3
    torch.save(checkpoint, run / "checkpoint.pt")
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--epochs", "2", "--quiet", "--seed", "0"],
            capsys, "drop --seed")


@pytest.mark.parametrize("edit, needle", [
    (_edit_record(lambda r: r["train"].__setitem__("lr", 0.005)), "(lr 0.005 there, 0.001 in the checkpoint)"),
    (_edit_record(lambda r: r["model"].__setitem__("image_size", 16)), "(image_size 16 there, 64 in the checkpoint)"),
    (_edit_record(lambda r: r["train"].__setitem__("seed", 7)), "(seed 7 there, 0 in the checkpoint)"),
], ids=["lr", "image_size", "another-runs-checkpoint"])
def test_train_resume_names_a_record_that_does_not_describe_its_checkpoint(edit: Callable[[Path], None], needle: str,
                                                                           tiny_piga_run: Path, tiny_data: Path,
                                                                           tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """An edited record (or another run's checkpoint put beside it) was rewritten from the checkpoint without a word:
    the user's edit was lost. It is named, with both values, and nothing is written; without the record, the run
    resumes from the checkpoint's settings, as the line says."""
    from piga.cli import train as cli
    from piga.cli.common import NOT_CONVERGED

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    argv = [str(tiny_data), "--out", str(run), "--resume", "--epochs", "2", "--threads", "1", "--quiet"]
    code, _, err = run_in_process("piga-train-model", cli.main, *argv, capsys=capsys)  # writes the run's record
    assert code in (0, NOT_CONVERGED) and (run / "config.json").is_file(), err
    edit(run)
    before = {path: path.read_bytes() for path in run.rglob("*") if path.is_file()}
    argv[argv.index("2")] = "3"
    refused("piga-train-model", argv, capsys, f"{run / 'config.json'} does not describe the run its checkpoint holds "
            + needle, "restore the record's values, or delete it to resume from the checkpoint's")
    assert {path: path.read_bytes() for path in run.rglob("*") if path.is_file()} == before
    (run / "config.json").unlink()
    code, _, err = run_in_process("piga-train-model", cli.main, *argv, capsys=capsys)
    assert code in (0, NOT_CONVERGED) and "Traceback" not in err, err


def test_train_resume_without_its_record_takes_the_checkpoints_own_recipe(tiny_piga_run: Path, tiny_data: Path,
                                                                           tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A run without config.json has no starting command to read: its own batch size, written out on --resume, was
    refused ("drop --batch-size"); it is the checkpoint's, and another is still refused."""
    import torch

    from tests.helpers import run_in_process
    from piga.cli import train as cli
    from piga.cli.common import NOT_CONVERGED

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    own = torch.load(run / "checkpoint.pt", weights_only=False)["train_config"]["batch_size"]
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--epochs", "2", "--quiet",
                                 "--batch-size", str(own + 1)], capsys, "drop --batch-size")
    code, _, err = run_in_process("piga-train-model", cli.main, str(tiny_data), "--out", str(run), "--resume",
                                  "--epochs", "2", "--quiet", "--batch-size", str(own), capsys=capsys)
    assert code in (0, 1, NOT_CONVERGED) and "drop" not in err and "Traceback" not in err, err


def test_a_run_stopped_by_max_minutes_is_told_to_raise_it(tiny_data: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """--max-minutes is a budget over the run's whole life: the advice "--resume and a larger --epochs" trained no
    step and said the same again. The advice names --max-minutes, and a resume that could not train is refused."""
    from tests.helpers import run_in_process
    from piga.cli import train as cli

    run = tmp_path / "run"
    code, _, err = run_in_process("piga-train-model", cli.main, str(tiny_data), "--out", str(run), "--budget-steps",
                                  "60", "--batch-size", "8", "--threads", "1", "--quiet", "--max-minutes", "1e-6",
                                  capsys=capsys)
    assert code in (1, 3) and "continue this run with --resume and a larger --max-minutes" in err, err
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--epochs", "40", "--quiet"], capsys,
            "past its --max-minutes 1e-06 (a budget over the run's whole life", "give a larger --max-minutes")


def test_train_resume_refuses_a_baseline_run(baseline_runs: dict[str, Path], tiny_data: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run")
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--quiet"], capsys, "piga-baseline ddpg run")


@pytest.mark.parametrize("extra, needle", [
    (["--autoencoder-steps", "5"], "--autoencoder-steps is for --obs latent"),
    # at their defaults too: the docs say "with --obs latent", "with --algo drqv2", "with --env piga/DMCPendulum-v0"
    (["--autoencoder-steps", "2000"], "--autoencoder-steps is for --obs latent"),
    (["--encoder-precision", "float32"], "--encoder-precision is for --algo drqv2; SB3's ddpg trains its own networks"),
    (["--view", "face"], "--view chooses a view of piga/DMCPendulum-v0; piga/PixelPendulum-v0 is seen as it renders"),
    (["--torque-arrow"], "--obs state sees no frames"),  # the arrow was recorded for a policy that never saw it
    (["--steps", "200", "--eval-every", "400"], "never be evaluated"),
    (["--steps", "450", "--eval-every", "1000"], "--eval-every (1000) is more than --steps (450)"),  # "than steps (450)"
    (["--steps", "600", "--eval-every", "400"], "--steps must be a multiple of --eval-every, got 600 and 400"),  # its last 200 steps unscored
    (["--steps", "400", "--eval-every", "200", "--learning-starts", "5000"], "never learn"),
    (["--steps", "400", "--eval-every", "200", "--learning-starts", "100", "--batch-size", "500", "--buffer-size", "100"],
     "cannot be drawn from the replay buffer"),
])
def test_ddpg_refuses_settings_that_would_do_nothing(extra: list[str], needle: str, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Settings a run would ignore, or that leave it never evaluated or never learning, used to exit 0."""
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), "--quiet", *extra], capsys, needle)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--steps", "9" * 20], "steps must be in [1, 10,000,000]"),
    (["--eval-episodes", "99999999999"], "--eval-episodes must be at most 10,000"),
])
def test_ddpg_refuses_work_it_would_never_finish(argv: list[str], needle: str, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Both were taken, and the run went on for ever."""
    refused("piga-baseline", _once(["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG], argv), capsys,
            needle)
    assert _listing(tmp_path) == []


def test_ddpg_latent_bounds_the_autoencoder_and_says_its_plan(tiny_data: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """--autoencoder-steps 1e9 was taken and trained for ever, without a word under --quiet."""
    import agents.sb3.autoencoder as autoencoder
    from agents.sb3.autoencoder import MAX_STEPS, AutoencoderConfig
    from piga.training.train import MAX_TRAIN_STEPS

    assert MAX_STEPS == MAX_TRAIN_STEPS  # piga-train-model's bound
    base = ["ddpg", "--obs", "latent", "--data", str(tiny_data), "--out", str(tmp_path / "run"), *TINY_DDPG]
    refused("piga-baseline", [*base, "--autoencoder-steps", "1000000000"], capsys,
            "--autoencoder-steps: expected an integer in [1, 10000000]")
    with pytest.raises(ValueError, match="AutoencoderConfig.steps must be at most 10,000,000"):
        AutoencoderConfig(steps=10**9)

    def interrupted_autoencoder(*args: Any, **kwargs: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(autoencoder, "train_autoencoder", interrupted_autoencoder)
    code, stdout, _ = run_in_process("piga-baseline", baseline.main, *base, "--autoencoder-steps", "3000", capsys=capsys)
    assert code == 130 and f"training the autoencoder on {tiny_data}'s train frames for 3000 steps (batches of 64)" in stdout
    assert _listing(tmp_path) == []


def test_ddpg_resume_refuses_fewer_steps(baseline_runs: dict[str, Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run")
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(run), "--resume", "--steps", "100", "--quiet"], capsys,
            "never lower it")


def test_train_refuses_a_folder_with_another_runs_curves(tiny_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A folder that holds only a tensorboard/ (another run's curves) is not silently trained into: the new run's
    curves would join the old ones. --overwrite replaces them."""
    out = tmp_path / "run"
    (out / "tensorboard").mkdir(parents=True)
    (out / "tensorboard" / "events.old").write_text("old curves")
    refused("piga-train-model", [str(tiny_data), "--out", str(out), "--quiet"], capsys, "tensorboard", "--overwrite")
    assert (out / "tensorboard" / "events.old").exists()


@pytest.mark.slow
def test_train_resume_tells_a_moved_file_from_another_of_the_same_shape(tiny_piga_run: Path, tiny_data: Path,
                                                                        tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """The checkpoint keeps a fingerprint of the file's contents: a copy elsewhere resumes, another recording of
    the same shape (another seed) is refused (it used to pass as "a moved file")."""
    import shutil

    from piga.data.collect import CollectConfig, collect
    from tests.helpers import run_in_process
    from piga.cli import train as cli
    from piga.cli.common import NOT_CONVERGED

    other = tmp_path / "other.h5"
    collect(CollectConfig(sequences=12, steps=16, seed=4, workers=1, split=(8, 2, 2)), other, progress=False, command="t")
    refused("piga-train-model", [str(other), "--out", str(_run_copy(tiny_piga_run, tmp_path / "a")), "--resume",
                                 "--epochs", "2", "--quiet"], capsys, "continues on the file the run trained on")
    moved = tmp_path / "moved.h5"
    shutil.copy(tiny_data, moved)
    run = _run_copy(tiny_piga_run, tmp_path / "b")
    code, _, err = run_in_process("piga-train-model", cli.main, str(moved), "--out", str(run), "--resume", "--epochs", "2",
                                  "--quiet", capsys=capsys)
    assert code in (0, NOT_CONVERGED), err  # resumed and trained: a tiny run is too short to be judged converged


@pytest.mark.slow
def test_train_resume_names_the_trained_file_from_the_current_folder(tiny_piga_run: Path, tiny_data: Path,
                                                                    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A run resumed in elsewhere/deep on ../moved.h5 was refused another file from the folder above with "continues on
    the file the run trained on (../moved.h5)": a path relative to the folder it trained in, which from here is
    another (missing) file. The checkpoint records that folder, and the line names the file from here."""
    import torch

    from piga.cli import train as cli
    from piga.cli.common import NOT_CONVERGED
    from tests.helpers import run_in_process

    deep = tmp_path / "elsewhere" / "deep"
    run = _run_copy(tiny_piga_run, deep / "copy1")
    shutil.copy(tiny_data, tmp_path / "elsewhere" / "moved.h5")
    monkeypatch.chdir(deep)
    code, _, err = run_in_process("piga-train-model", cli.main, "../moved.h5", "--out", "copy1", "--resume", "--epochs",
                                  "2", "--quiet", capsys=capsys)
    assert code in (0, NOT_CONVERGED), err
    data = torch.load(run / "checkpoint.pt", weights_only=False)["data"]
    assert data["path"] == "../moved.h5" and data["folder"] == str(deep)
    monkeypatch.chdir(tmp_path)
    other = _variant(tiny_data, tmp_path / "other.h5", lambda f: f["frames"].__setitem__(0, 255 - f["frames"][0]))
    refused("piga-train-model", [str(other), "--out", "elsewhere/deep/copy1", "--resume", "--epochs", "3", "--quiet"],
            capsys, "continues on the file the run trained on (elsewhere/moved.h5), not ")
    monkeypatch.chdir(tmp_path / "elsewhere")  # below the run's folder: the file's path from here stays relative
    refused("piga-train-model", [str(other), "--out", "deep/copy1", "--resume", "--epochs", "3", "--quiet"],
            capsys, "continues on the file the run trained on (moved.h5), not ")
    monkeypatch.chdir(deep / "copy1")  # beside it: absolute
    refused("piga-train-model", [str(other), "--out", ".", "--resume", "--epochs", "3", "--quiet"],
            capsys, f"continues on the file the run trained on ({tmp_path / 'elsewhere' / 'moved.h5'}), not ")


def test_a_recorded_path_is_read_from_the_folder_it_was_recorded_in(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Paths in a run's records are as its command was given them: read against the folder that command ran in."""
    from piga.io.checkpoint import recorded_data_path, recorded_path

    monkeypatch.chdir(tmp_path)
    assert recorded_path("../moved.h5", str(tmp_path / "a" / "b")) == str(Path("a") / "moved.h5")
    assert recorded_path("../moved.h5", str(tmp_path)) == "../moved.h5"  # recorded here: as given
    assert recorded_path("x.h5", str(tmp_path / "a" / "b")) == str(Path("a") / "b" / "x.h5")
    assert recorded_path("x.h5", "/elsewhere") == "/elsewhere/x.h5"
    assert recorded_path("/data/x.h5", str(tmp_path / "a")) == "/data/x.h5"
    assert recorded_path("x.h5", None) == "x.h5"  # an older record: as it is
    assert recorded_data_path({"path": "x.h5"}) == "x.h5" and recorded_data_path({}) is None


def test_train_resume_says_the_file_has_changed(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """The run's own file, changed in place: it read "continues on the file the run trained on (X), not X"."""
    import torch

    data = _variant(tiny_data, tmp_path / "d.h5", lambda f: f["frames"].__setitem__(0, 255 - f["frames"][0]))
    run = _run_copy(tiny_piga_run, tmp_path / "run")
    ckpt = torch.load(run / "checkpoint.pt", weights_only=False)
    ckpt["data"]["path"] = str(data)
    torch.save(ckpt, run / "checkpoint.pt")
    refused("piga-train-model", [str(data), "--out", str(run), "--resume", "--epochs", "3", "--quiet"], capsys,
            f"--resume: {data} has changed since the run trained on it")


@pytest.mark.slow
def test_train_resume_without_its_record_says_it_rebuilds_it(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """The checkpoint holds the recipe and the model, so a lost config.json does not stop a resume; the rebuilt
    record says that the first command is unknown, and so does a note on stdout (stderr is kept for an error's one
    line, which may follow: a checkpoint that cannot continue)."""
    import json

    from tests.helpers import run_in_process
    from piga.cli import train as cli
    from piga.cli.common import NOT_CONVERGED

    run = _run_copy(tiny_piga_run, tmp_path / "a")
    assert not (run / "config.json").exists()  # a run trained through the library has none
    code, out, err = run_in_process("piga-train-model", cli.main, str(tiny_data), "--out", str(run), "--resume",
                                    "--epochs", "2", "--quiet", capsys=capsys)
    assert code in (0, NOT_CONVERGED), err
    assert "config.json is missing; the resumed run rewrites it from the checkpoint" in out
    record = json.loads((run / "config.json").read_text())
    assert record["command"] is None and len(record["resumed"]) == 1 and record["train"]["epochs"] == 2


# ---------------------------------------------------------------------------------------------
# Options a command would ignore, work it would never finish, and outputs it cannot make
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("prog, argv", [
    ("piga-train-model", ["DATA", "--out", "afile/run", "--quiet"]),
    ("piga-baseline", ["planet", "DATA", "--out", "afile/run", *TINY_PLANET]),
    ("piga-baseline", ["ddpg", "--obs", "state", "--out", "afile/run", *TINY_DDPG]),
    ("piga-demo", ["--out", "afile/demo", "--quiet"]),
])
def test_an_out_folder_below_a_file_names_the_file(prog: str, argv: list[str], tiny_data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """It used to start training and fail with "[Errno 20] Not a directory" at the first checkpoint."""
    (tmp_path / "afile").write_text("x")
    argv = [str(tiny_data) if a == "DATA" else str(tmp_path / a) if a.startswith("afile") else a for a in argv]
    line = refused(prog, argv, capsys, f"{tmp_path / 'afile'} is a file, not a folder")
    assert "Errno" not in line
    assert _listing(tmp_path) == ["afile"]


@pytest.mark.parametrize("prog, argv, run", [
    ("piga-train-model", ["DATA", "--out", "RUN", "--resume", "--overwrite", "--epochs", "2", "--quiet"], "piga"),
    ("piga-baseline", ["planet", "DATA", "--out", "RUN", "--resume", "--overwrite", "--steps", "4", "--quiet"], "planet"),
    ("piga-baseline", ["ddpg", "--obs", "state", "--out", "RUN", "--resume", "--overwrite", "--steps", "400", "--quiet"],
     "ddpg"),
])
def test_resume_with_overwrite_is_refused(prog: str, argv: list[str], run: str, tiny_piga_run: Path,
                                          baseline_runs: dict[str, Path], tiny_data: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """--overwrite beside --resume used to be ignored (the run was continued)."""
    copy = _run_copy(tiny_piga_run if run == "piga" else baseline_runs[run], tmp_path / "run")
    before = _listing(copy)
    argv = [str(tiny_data) if a == "DATA" else str(copy) if a == "RUN" else a for a in argv]
    refused(prog, argv, capsys, "--resume continues the run in --out and --overwrite replaces it")
    assert _listing(copy) == before


def test_train_refuses_a_stream_cache_for_a_file_read_whole(tiny_data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-train-model", [str(tiny_data), "--out", str(tmp_path / "run"), "--data-loading", "memory",
                                 "--stream-cache-mb", "10", "--quiet"], capsys, "--stream-cache-mb", "drop one")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("argv, needle, code", [
    (["--episodes", "1000000000"], "--episodes: expected an integer in [1, 10000]", 1),
    (["--steps", "1000000000"], "--steps: expected an integer in [20, 100000]", 1),
    (["--horizon", "100000000"], "candidates x horizon x iterations = 200 x 100000000 x 5", 1),
    (["--candidates", "1000000000"], "lower the candidates, the horizon or the iterations", 1),
    (["--iterations", "100000000"], "more than 1e+07", 1),
])
def test_control_refuses_work_it_would_never_finish(argv: list[str], needle: str, code: int, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """These used to plan or play for hours (or swap) without a word."""
    refused("piga-control", ["--oracle", "--out", str(tmp_path / "o"), "--quiet", *argv], capsys, needle, code=code)
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("mult", ["2", "1", "1.0"])
def test_control_sweep_refuses_a_gravity_multiplier(mult: str, tiny_piga_run: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """--gravity-mult beside --sweep used to be ignored, and still was at its default value, 1."""
    refused("piga-control", ["--model", str(tiny_piga_run), "--sweep", "0.5:1:0.5", "--gravity-mult", mult], capsys,
            "drop --gravity-mult")


@pytest.mark.parametrize("extra, needles", [
    (["--goal-image", "goal.png"], ["--sweep gives each job its goal as an angle: give --goal-angle DEG, not --goal-image"]),
    (["--video", "v.mp4"], ["--sweep plays its jobs in worker processes and films none of them: drop --video"]),
])
def test_control_sweep_refuses_a_goal_image_and_a_video_for_what_they_are(
        extra: list[str], needles: list[str], tiny_piga_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """It said "--sweep runs upright swing-ups", while a sweep takes --goal-angle and runs every job to that goal."""
    monkeypatch.chdir(tmp_path)
    line = refused("piga-control", ["--model", str(tiny_piga_run), "--sweep", "1:1.2:0.2", "--episodes", "1", "--steps",
                                    "20", "--workers", "1", "--quiet", *extra], capsys, *needles)
    assert "upright" not in line


def test_a_baseline_sweep_refuses_a_video_for_what_it_is(baseline_runs: dict[str, Path],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-control", ["--model", str(baseline_runs["planet"]), "--sweep", "1:1.2:0.2", "--episodes", "1", "--steps",
                             "20", "--workers", "1", "--quiet", "--video", "v.mp4"], capsys,
            "--sweep plays its jobs in worker processes and films none of them")


@pytest.mark.parametrize("log_g, needle", [
    (float("nan"), "checkpoint.pt: holds NaN or infinite weights (system.log_g)"),
    (800.0, "checkpoint.pt: its physical parameters are not finite numbers (g = inf)"),
])
@pytest.mark.parametrize("prog", ["piga-control", "piga-train-model"])
def test_a_checkpoint_with_nan_weights_is_named(prog: str, log_g: float, needle: str, tiny_piga_run: Path,
                                                tiny_data: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A checkpoint whose log g is NaN: control failed in the physics' own check without naming the file, and a
    resume trained to a NaN loss and called the damaged file the "last good checkpoint". A finite log g of 800 is
    g = inf: control planned with it and exited 0."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    ckpt = torch.load(run / "checkpoint.pt", weights_only=False)
    ckpt["model"]["system.log_g"].fill_(log_g)
    torch.save(ckpt, run / "checkpoint.pt")
    argv = (["--model", str(run), "--episodes", "1", "--quiet"] if prog == "piga-control"
            else [str(tiny_data), "--out", str(run), "--resume", "--epochs", "3", "--quiet"])
    refused(prog, argv, capsys, needle, "train the run again")


def test_control_refuses_two_goals_and_reads_a_goal_image_quietly(tiny_piga_run: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """--goal-angle beside --goal-image was ignored (exit 0); reading a goal image printed torch's
    requires_grad warning on stderr."""
    image = tmp_path / "g.png"
    assert run_in_process("piga-control", control.main, "--write-goal-image", str(image), "--angle", "10", capsys=capsys)[0] == 0
    for angle in ("10", "0"):  # 0, the default's value, written: still ignored
        refused("piga-control", ["--model", str(tiny_piga_run), "--goal-image", str(image), "--goal-angle", angle], capsys,
                "--goal-image sets the goal", "drop --goal-angle")
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, _, err = run_in_process("piga-control", control.main, "--model", str(tiny_piga_run), "--goal-image", str(image),
                                      "--episodes", "1", "--steps", "20", "--horizon", "2", "--candidates", "4",
                                      "--iterations", "1", "--quiet", capsys=capsys)
    assert code == 0, err
    assert not [w for w in caught if "requires_grad" in str(w.message)]


@pytest.mark.parametrize("sweep, needle", [
    ("1e308:1e308:1", "--sweep: the gravity it gives, 10 x 1e+308 = inf m/s², is out of range"),  # a job failed, after a warning
    ("1e-300:2e-300:1e-300", "gravity multipliers must be > 0 (at 10 decimals)"),  # it read "> 0, got 1e-300"
    ("0.00000001:1:0.5", "--sweep: the gravity it gives, 10 x 1e-08 = 1e-07 m/s², is out of range: at least 1e-06"),
])
def test_control_sweep_refuses_multipliers_up_front(sweep: str, needle: str, tiny_piga_run: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-control", ["--model", str(tiny_piga_run), "--sweep", sweep, "--episodes", "1", "--quiet"], capsys, needle)


def test_control_refuses_a_gravity_too_weak_to_show(capsys: pytest.CaptureFixture[str]) -> None:
    """--gravity-mult 1e-300 ran swing-ups of a pendulum that never falls, and exited 0."""
    refused("piga-control", ["--oracle", "--gravity-mult", "1e-300", "--episodes", "1", "--quiet"], capsys,
            "--gravity-mult 1e-300: the gravity it gives, 10 x 1e-300 = 1e-299 m/s², is out of range: at least 1e-06 m/s²")


def test_the_weakest_gravity_and_gain_move_the_pendulum_by_under_a_hundredth_of_a_pixel() -> None:
    """The floors' reason, as their errors give it: over a 200-step episode, the full torque at the weakest gain, or the
    weakest gravity, moves the tip of Gymnasium's pendulum (1 of the 2.2 half-widths of its 500-pixel picture, so
    14.5 px in a 64-pixel frame) by under 0.01 px against a pendulum without it; the floors themselves are accepted."""
    import gymnasium as gym
    import numpy as np

    from envs.pendulum import MIN_ACTUATION_GAIN, MIN_GRAVITY, PixelPendulumConfig

    PixelPendulumConfig(gravity=MIN_GRAVITY, actuation_gain=MIN_ACTUATION_GAIN)
    PixelPendulumConfig(gravity_mult=MIN_GRAVITY / PixelPendulumConfig.gravity)

    def angles(g: float, torque: float) -> np.ndarray:
        env = gym.make("Pendulum-v1", g=g).unwrapped
        env.reset(seed=0, options={"x_init": 0.0, "y_init": 0.0})
        env.state = np.array([np.pi / 2, 0.0])  # gravity's torque at its largest
        return np.array([env.step(np.array([torque], np.float32))[0] for _ in range(200)])[:, :2]  # (T, cos/sin)

    tip_px = 64 / 500 * 500 / (2 * 2.2)
    for g, torque in ((MIN_GRAVITY, 0.0), (0.0, 2 * MIN_ACTUATION_GAIN)):
        moved = np.abs(angles(g, torque) - angles(0.0, 0.0)).max()  # |Δ(cos θ, sin θ)| <= |Δθ|, and ~ it when small
        assert 0 < moved * tip_px < 0.01, (g, torque, moved * tip_px)


def test_control_sweep_warns_once_about_an_unconverged_run(tiny_piga_run: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The sweep's jobs warned a second time, without the command's name."""
    def unconverged(run: Path) -> None:
        metrics = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").exists() else {}
        (run / "metrics.json").write_text(json.dumps({**metrics, "converged": False, "convergence": {"reason": "too short"}}))

    run = _run_copy(tiny_piga_run, tmp_path / "run", unconverged)
    code, out, err = run_in_process("piga-control", control.main, "--model", str(run), "--sweep", "1:1:1",
                                    "--episodes", "1", "--steps", "20", "--horizon", "3", "--candidates", "4", "--iterations",
                                    "1", "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0, err
    assert err.count("did not converge") == 1 and err.startswith("piga-control: warning:"), err


def test_planet_names_its_chunk_length_flag_when_the_sequences_are_shorter(tiny_data: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """"shorter than chunk_length 7 x action repeat 2; lower it" named the config's field, not the flag."""
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"),
                              *_once(TINY_PLANET, ["--chunk-length", "9"])], capsys,
            "sequences of 16 frames are shorter than --chunk-length 9 x action repeat 2; lower it")
    assert _listing(tmp_path) == []


def test_planet_refuses_one_frame_sequences_as_no_video(tiny_data: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Sequences of one frame read "sequences of 1 frames are shorter than --chunk-length", which no length fixes."""
    def one_frame(f: h5py.File) -> None:
        for name in [k for k in ("frames", "actions", "states", "rewards") if k in f]:
            _replace(f, name, f[name][:, :1])

    data = _variant(tiny_data, tmp_path / "one.h5", one_frame)
    refused("piga-baseline", ["planet", str(data), "--out", str(tmp_path / "run"), *_once(TINY_PLANET, [])], capsys,
            "has 1 frame per sequence, and a video needs two")
    assert _listing(tmp_path) == ["one.h5"]


def test_planet_refuses_a_batch_that_cannot_fit(tiny_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--batch-size 1e6 used to swap for ever."""
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), *_once(TINY_PLANET, ["--batch-size", "1000000"])],
            capsys, "a batch of 1000000 x 8 frames", "of memory")
    assert _listing(tmp_path) == []


def test_planet_resume_refuses_fewer_steps(baseline_runs: dict[str, Path], tiny_data: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """It exited 0 having trained nothing, and recorded the lower count in config.json."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    before = (run / "config.json").read_text()
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(run), "--resume", "--steps", "1", "--quiet"], capsys,
            "never lower it")
    assert (run / "config.json").read_text() == before


def test_planet_resumes_on_its_file_named_from_elsewhere(baseline_runs: dict[str, Path], tiny_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """A run trained on a relative path, resumed from another folder (or on a copy of the file), was refused as
    "trained on another file"."""
    run = _run_copy(baseline_runs["planet"], tmp_path / "run", _edit_record(lambda r: r.__setitem__("data", "tiny.h5")))
    copy = tmp_path / "elsewhere" / "same.h5"
    copy.parent.mkdir()
    shutil.copyfile(tiny_data, copy)
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(copy), "--out", str(run), "--resume",
                                  "--steps", "3", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)


@pytest.mark.parametrize("obs", ["state", "latent"])
def test_sb3_on_dmc_names_the_obs_it_was_given(obs: str, tiny_data: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """The refusal spoke of the torque arrow, which the user had not asked for."""
    data = ["--data", str(tiny_data)] if obs == "latent" else []
    line = refused("piga-baseline", ["ddpg", "--env", "piga/DMCPendulum-v0", "--obs", obs, *data, "--out",
                                     str(tmp_path / "run"), "--quiet"], capsys, f"--obs {obs} is not available for piga/DMCPendulum-v0",
                   "--obs pixels")
    assert "arrow" not in line
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("algo", [("--algo", "ddpg", "--obs", "state"), ("--algo", "sac", "--obs", "state"),
                                  ("--algo", "drqv2", "--obs", "pixels")], ids=lambda a: a[1])
@pytest.mark.parametrize("rate", ["1e39", "1e300", "11"])
def test_sb3_refuses_a_learning_rate_out_of_range_up_front(algo: tuple[str, ...], rate: str, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Above float32's range, SB3's logs overflowed with an internal error."""
    refused("piga-baseline", ["ddpg", *algo, "--out", str(tmp_path / "run"), *TINY_DDPG, "--learning-rate", rate],
            capsys, "--learning-rate must be in (0, 10]")
    assert _listing(tmp_path) == []


def test_ddpg_refuses_noise_beyond_the_action_scale(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG, "--noise-std", "1e9"],
            capsys, "--noise-std must be at most 10")
    assert _listing(tmp_path) == []


def test_demo_refuses_too_few_sequences_before_collecting(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It collected and showed them, then relayed training's "lower the batch size", an option piga-demo lacks."""
    line = refused("piga-demo", ["--out", str(tmp_path / "demo"), "--sequences", "1"], capsys,
                   "fewer than one batch of 32", "give --sequences 2 or more")
    assert "batch size" not in line
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("argv, needle, code", [
    (["--bootstrap", "1000000000"], "--bootstrap: expected 0 (no intervals) or an integer in [10, 10000]", 1),
    (["--episodes", "3"], "--episodes sets the MPC episodes of --env", 1),
    (["--env", "damping=0.2", "--episodes", "1000000000"], "--episodes: expected an integer in [1, 10000]", 1),
])
def test_diagnose_refuses_before_any_work(argv: list[str], needle: str, code: int, fake_planet_run: Path, tiny_data: Path,
                                          tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A huge bootstrap ran for days; --episodes without --env was ignored; a huge --episodes was refused by the
    episodes' config only after the whole diagnosis."""
    refused("piga-diagnose", ["--model", str(fake_planet_run), "--data", str(tiny_data), "--out", str(tmp_path / "report"),
                              "--quiet", *argv], capsys, needle, code=code)
    assert _listing(tmp_path) == []


def test_control_warns_of_a_goal_angle_beyond_the_torque_limit(capsys: pytest.CaptureFixture[str]) -> None:
    """A goal image beyond the holdable range was warned of, the same goal given in degrees was not."""
    code, out, err = run_in_process("piga-control", control.main, "--oracle", "--goal-angle", "90", "--episodes", "1",
                                    "--steps", "20", "--horizon", "3", "--candidates", "4", "--iterations", "1", "--quiet",
                                    capsys=capsys)
    assert code == 0 and err.count("\n") == 1, err
    assert err.startswith("piga-control: warning: goal 90 deg needs torque") and "holdable goals are within" in err


def test_the_hold_warning_at_the_edge_does_not_contradict_itself() -> None:
    """23.6 deg read "needs torque -2.00 ..., beyond the limit of 2; holdable goals are within ±23.6 deg"."""
    from piga.control.goal import hold_warning

    line = hold_warning(math.radians(23.6)) or ""
    assert "goal 23.6 deg needs torque -2.002" in line and "within ±23.57 deg" in line, line
    assert hold_warning(math.radians(23.57)) is None and hold_warning(math.radians(-23.57)) is None


def test_a_sweep_names_the_multipliers_at_which_its_goal_cannot_be_held(tiny_piga_run: Path, monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A single run at x0.9 warned that 30 deg needs torque -2.25; a sweep over x0.9 and x1 to the same goal said
    nothing. Its one line names the multipliers, before any job is played."""
    from piga.control import jobs
    from piga.control.goal import hold_warning

    line = hold_warning(math.radians(30), [0.5, 0.9, 1.0]) or ""
    assert line.startswith("goal 30 deg needs torque -2.25 to -2.5 to hold in the env at gravity x0.9, x1 "), line
    assert "holdable goals there are within ±26.38 to ±23.57 deg" in line and "x0.5" not in line, line
    assert hold_warning(math.radians(30), [0.5, 0.8]) is None
    assert "at gravity x1 to x1.4 (5 of the sweep's 6)" in (hold_warning(math.radians(25), [0.9, 1, 1.1, 1.2, 1.3, 1.4]) or "")

    def played(*_: object, **__: object) -> None:
        raise RuntimeError("no job is played here")

    monkeypatch.setattr(jobs, "run_jobs", played)
    with pytest.raises(RuntimeError, match="no job is played here"):
        control.main(["--model", str(tiny_piga_run), "--sweep", "0.5:1:0.5", "--goal-angle", "25", "--episodes", "1",
                      "--steps", "20", "--workers", "1", "--quiet"])
    warnings = [w for w in capsys.readouterr().err.splitlines() if "holdable" in w]
    assert len(warnings) == 1 and "at gravity x1 (its own physics)" in warnings[0], warnings


def test_a_goal_is_judged_holdable_in_the_env_the_agent_was_not_told_of(tiny_piga_run: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """20 deg is holdable at gravity x1 (±23.6 deg), not at x1.4 (±16.6): --not-told judged it at x1, in silence."""
    _, _, err = run_in_process("piga-control", control.main, "--model", str(tiny_piga_run), "--goal-angle", "20",
                               "--gravity-mult", "1.4", "--not-told", "--episodes", "1", "--steps", "20", "--horizon",
                               "2", "--candidates", "8", "--iterations", "1", "--quiet", capsys=capsys)
    assert "goal 20 deg needs torque" in err and "within ±16.6 deg" in err, err


def test_a_dmc_frame_may_not_span_seconds() -> None:
    """action_repeat 1e8 collected for ever (and a DMC episode of 1000 physics steps would hold no frame)."""
    from envs.dmc import MAX_ACTION_REPEAT, DMCPendulumConfig

    with pytest.raises(ValueError, match=rf"action_repeat=100000000 is out of range \(action_repeat in \[1, {MAX_ACTION_REPEAT}\]\)$"):
        DMCPendulumConfig(action_repeat=10**8)


def test_planet_refuses_more_sequences_than_the_file_has(tiny_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """It trained on all 8 and recorded max_sequences 100."""
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), *TINY_PLANET, "--max-sequences",
                              "100"], capsys, "--max-sequences 100", "has 8 train sequences")
    assert _listing(tmp_path) == []


def test_import_passes_over_hidden_files(frame_folders: dict[str, Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """macOS's ``._f0.png`` metadata beside each frame copied to a foreign disk: it was read as a frame
    ("not a readable image")."""
    folder = tmp_path / "frames"
    shutil.copytree(frame_folders["moving"], folder)
    (folder / "._f0.png").write_bytes(b"\x00\x05\x16\x07 AppleDouble")
    csv = tmp_path / "u.csv"
    csv.write_text("0.5\n" * 12)
    code, _, err = run_in_process("piga-import", importer.main, str(folder), str(csv), "--dt", "0.05", "--steps", "4",
                                  "--image-size", "32", "--split", "1,1,1", "--out", str(tmp_path / "out.h5"), capsys=capsys)
    assert code == 0, err
    with h5py.File(tmp_path / "out.h5") as f:
        assert f["frames"].shape[:2] == (3, 4)


def test_import_refuses_a_ragged_row(frame_folders: dict[str, Path], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A row with a stray second column was read as its first, silently."""
    csv = tmp_path / "u.csv"
    csv.write_text("u\n" + "0.5\n" * 6 + "0.5,2\n" + "0.5\n" * 5)
    refused("piga-import", [str(frame_folders["moving"]), str(csv), "--dt", "0.05", "--steps", "4", "--image-size", "32",
                            "--split", "1,1,1", "--out", str(tmp_path / "out.h5")], capsys,
            "line 8: 2 column(s), but line 1 has 1")
    assert _listing(tmp_path) == ["u.csv"]


def test_an_invalid_dmc_physics_state_is_the_configs_error(capsys: pytest.CaptureFixture[str]) -> None:
    """A tip of 1e-12 kg made MuJoCo's state invalid: an internal error, after absl's warning line. The config now
    refuses such a mass; a state that still goes invalid is a ValueError naming the config, with no log line."""
    pytest.importorskip("dm_control")
    from envs.dmc import DMCPendulumConfig, DMCPendulumEnv

    with pytest.raises(ValueError, match="mass=1e-12 is out of range"):
        DMCPendulumConfig(mass=1e-12)
    config = DMCPendulumConfig()
    object.__setattr__(config, "mass", 1e-12)  # past the check, as a config that MuJoCo still cannot integrate
    env = DMCPendulumEnv(config)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="physics became invalid .* mass=1e-12"):
        for _ in range(5):
            env.step(np.ones(1))
    env.close()
    assert "QACC" not in capsys.readouterr().err


@pytest.mark.slow
def test_a_scene_with_forces_too_strong_names_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--g 1e6 flings every start into a wall; the message named only the sequences, the speed and the image."""
    refused("piga-collect", ["--out", str(tmp_path / "d.h5"), "--system", "gravity", "--g", "1e6", "--sequences", "2",
                             "--steps", "30", "--workers", "1", "--split", "1,1,0", "--quiet"], capsys,
            "stays clear of the walls", "weaker forces than g = 1e+06")
    assert _listing(tmp_path) == []


def test_a_spring_rest_length_is_refused_only_where_the_balls_overlap() -> None:
    """The rest length 2l must leave a pixel between the balls (their radius r); digits, whose glyphs do not fill
    their box, may overlap."""
    from envs.scenes import SceneError, scene_config

    for params, radius in (({"l": 3.4}, 3.0), ({}, 6.0)):
        with pytest.raises(SceneError, match=f"give l of at least {radius + 0.5:g} "):
            scene_config("spring", params=params, radius=radius, image_size=64)
    scene_config("spring", params={"l": 3.5})
    scene_config("digits-spring", radius=14.0)
    # images too small for the balls come first, and say the overlap too (a larger image alone would not do)
    with pytest.raises(SceneError, match=r"images are too small .*; and at l = 6 the balls rest .* at least 20\.5"):
        scene_config("spring", radius=20.0, image_size=32)
    # beyond the largest image: said so, not "2l = inf; need at least inf px" (l = 1e308)
    for params, radius, fix in (({"l": 1e308}, 3.0, "smaller l or radius"), ({}, 1e308, "smaller l or radius")):
        with pytest.raises(SceneError, match=f"need images larger than 1024 px, the largest piga-collect draws; give a "
                                             f"{fix}$") as error:
            scene_config("spring", params=params, radius=radius, image_size=32)
        assert "inf" not in str(error.value), error.value
    with pytest.raises(SceneError, match="bouncing: 2 objects of radius 1e\\+308 need images larger .* smaller radius$"):
        scene_config("bouncing", radius=1e308, image_size=32)


@pytest.mark.slow
def test_a_scene_with_forces_too_weak_to_show_says_so_before_the_walls(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """--k 1e-9 lets the balls fly into the walls: the refusal offered shorter sequences and a larger image, and a
    larger image was then refused for forces too weak to show, which no sequence length or image size helps."""
    line = refused("piga-collect", ["--out", str(tmp_path / "d.h5"), "--system", "spring", "--k", "1e-9", "--sequences",
                                    "6", "--steps", "12", "--workers", "1", "--quiet"], capsys,
                   "with k = 1e-09, l = 6 the forces move no ball by 0.01 px", "use stronger forces (the scene's own")
    assert "walls" not in line and "--image-size" not in line and "longer sequences" not in line
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("prog", ["piga-control", "piga-diagnose"])
def test_a_checkpoint_lacking_an_entry_says_which(prog: str, tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A foreign checkpoint (an empty dict) was reported as "(KeyError: 'model_config'); it may be truncated"."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    torch.save({}, run / "checkpoint.pt")
    argv = ["--model", str(run), "--episodes", "1", "--quiet"] if prog == "piga-control" else \
        ["--model", str(run), "--data", str(tiny_data), "--out", str(tmp_path / "report"), "--quiet"]
    line = refused(prog, argv, capsys, "not a piga checkpoint: it lacks the entry 'model_config'")
    assert "KeyError" not in line and "truncated" not in line
    assert not (tmp_path / "report").exists()


@pytest.mark.parametrize("name, needle", [("s.txt", "matplotlib writes no .txt files"), ("s.h5", "matplotlib writes no"),
                                          ("s", "an image needs the suffix of its format")])
def test_show_refuses_an_image_format_matplotlib_lacks(name: str, needle: str, tiny_data: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """It drew the strip, then relayed matplotlib's "Format 'txt' is not supported", naming no option; a name without
    a suffix was written as a PNG that its name did not call one."""
    refused("piga-show", [str(tiny_data), "--out", str(tmp_path / name)], capsys, f"--out {tmp_path / name}: {needle}",
            "use .png (or ", ".pdf", ".svg")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("count", ["1", "9"])
def test_diagnose_refuses_a_bootstrap_too_small_for_an_interval(count: str, capsys: pytest.CaptureFixture[str]) -> None:
    """One replicate gave the "95% interval" 1.29..1.29 to a gain estimated at 1.035, and turned a verdict of no
    significant gap into a named gain."""
    refused("piga-diagnose", ["--model", "m", "--data", "d.h5", "--out", "r", "--bootstrap", count], capsys,
            f"argument --bootstrap: expected 0 (no intervals) or an integer in [10, 10000], got {count}")


def test_show_refuses_pgf_without_its_tex_system(tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """matplotlib offers .pgf whether or not xelatex is installed, and its writer failed after the strip was drawn
    (an internal error); the refusal listed .pgf among the formats to use."""
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name, *args, **kwargs: None)
    refused("piga-show", [str(tiny_data), "--out", str(tmp_path / "s.pgf")], capsys,
            f"--out {tmp_path / 's.pgf'}: matplotlib writes .pgf through xelatex, which is not installed", "use .png (or ")
    assert ".pgf" not in refused("piga-show", [str(tiny_data), "--out", str(tmp_path / "s.txt")], capsys, "use .png (or ")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("prog, argv", [("piga-collect", ["--sequences", "2", "--steps", "3", "--workers", "1"]),
                                        ("piga-import", ["rec.mp4", "actions.csv", "--dt", "0.05"])])
@pytest.mark.parametrize("name", ["o.txt", "o"])
def test_an_hdf5_output_is_named_so(prog: str, argv: list[str], name: str, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    """piga-collect and piga-import wrote their HDF5 file as o.txt, or o, and exited 0."""
    out = tmp_path / name
    refused(prog, [*argv, "--out", str(out)], capsys, f"argument --out: expected an HDF5 file ending in .h5 or .hdf5, "
            f"got '{out}'")
    assert _listing(tmp_path) == []


def test_an_hdf5_output_may_end_in_h5_or_hdf5_in_any_case() -> None:
    import argparse

    from piga.cli.common import h5_path

    assert [h5_path(name) for name in ("d.h5", "d.hdf5", "d.H5", "runs/d.HDF5")] == ["d.h5", "d.hdf5", "d.H5", "runs/d.HDF5"]
    for bad in ("d.h5.txt", "d.h", ".h5x"):
        with pytest.raises(argparse.ArgumentTypeError, match="expected an HDF5 file ending in .h5 or .hdf5"):
            h5_path(bad)


@pytest.mark.parametrize("argv", [["--episodes", "1", "--steps", "20"], ["--sweep", "1:1:1", "--episodes", "1"]])
def test_control_refuses_a_model_of_another_frame_rate(argv: list[str], tiny_piga_run: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A model of frames 0.1 s apart (an imported recording) planned Gymnasium's 0.05 s steps with its own, silently."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["model_config"]["dt"] = 0.1
    torch.save(checkpoint, run / "checkpoint.pt")
    refused("piga-control", ["--model", str(run), "--quiet", *argv], capsys, "trained on frames 0.1 s apart",
            "steps 0.05 s")


@pytest.mark.parametrize("prog, argv, needle", [
    ("piga-control", ["--oracle", "--out", ""], "argument --out: expected a value, got ''"),
    ("piga-control", ["--write-goal-image", "", "--angle", "3"], "argument --write-goal-image: expected a value"),
    ("piga-collect", ["--out", " "], "argument --out: expected a value, got ' '"),
    ("piga-train-model", ["", "--out", "run"], "argument data: expected a value"),
    ("piga-baseline", ["ddpg", "--obs", "state", "--out", ""], "argument --out: expected a value"),
])
def test_empty_text_values_are_refused(prog: str, argv: list[str], needle: str, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """--out '' was taken for no --out (piga-control ran and wrote nothing, exit 0) or for the current folder
    ("'.' is a folder"); --write-goal-image '' was answered "--angle goes with --write-goal-image"."""
    monkeypatch.chdir(tmp_path)
    refused(prog, argv, capsys, needle)
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# options that apply to nothing in the run, counts beyond the file, data that cannot identify a
# ---------------------------------------------------------------------------------------------


def test_train_refuses_seed_retries_where_there_is_no_object_check(tiny_data: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The pendulum's model has no object slots: the retries were accepted, recorded, and could never happen."""
    refused("piga-train-model", [str(tiny_data), "--out", str(tmp_path / "run"), "--epochs", "1", "--seed-retries", "3",
                                 "--quiet"], capsys, "--seed-retries retries a run whose object check",
            "holds pendulum data, whose model has no object slots to check: drop --seed-retries")
    assert _listing(tmp_path) == []


def test_train_refuses_pendulum_data_whose_actions_are_all_zero(tiny_data: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """a multiplies the actions: it never left its start, and the run blamed the learning rate and its length."""
    zero = tmp_path / "zero.h5"
    shutil.copy(tiny_data, zero)
    with h5py.File(zero, "a") as f:
        f["actions"][...] = 0.0
    refused("piga-train-model", [str(zero), "--out", str(tmp_path / "run"), "--epochs", "1", "--quiet"], capsys,
            "every action of its train split is 0", "actuation gain a", "cannot be identified")
    assert _listing(tmp_path) == ["zero.h5"]


@pytest.mark.parametrize("argv, needle", [(["--frames", "1000"], "--frames 1000: {data} has 16 frames per sequence; "
                                                                 "give at most 16"),
                                          (["--sequences", "9"], "--sequences 9: {data} has 8 sequences in its train "
                                                                 "split; give at most 8")])
def test_show_refuses_more_than_the_file_holds(argv: list[str], needle: str, tiny_data: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """It drew 16 frames x 8 sequences and said nothing."""
    refused("piga-show", [str(tiny_data), "--out", str(tmp_path / "s.png"), *argv], capsys, needle.format(data=tiny_data))
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("prog", ["piga-show", "piga-train-model"])
def test_a_pipe_given_as_the_data_file_is_refused_not_waited_on(prog: str, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A FIFO named as the data file: opening it waited for a writer for ever."""
    import os

    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    refused(prog, [str(fifo), "--out", str(tmp_path / ("s.png" if prog == "piga-show" else "run"))], capsys,
            f"{fifo}: is not a regular file (a pipe, a socket or a device)")
    assert _listing(tmp_path) == ["pipe.h5"]


def test_overwrite_never_replaces_a_device_or_a_pipe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--overwrite replaced a FIFO (and, as root, /dev/null) named as the output with a regular file."""
    import os
    import stat

    from piga.io.atomic import atomic_output

    fifo = tmp_path / "out.h5"
    os.mkfifo(fifo)
    refused("piga-collect", ["--sequences", "4", "--steps", "5", "--workers", "1", "--quiet", "--out", str(fifo),
                             "--overwrite"], capsys, f"{fifo} is a device, a pipe or a socket, not a file")
    with pytest.raises(PermissionError, match="is a device, a pipe or a socket"), atomic_output(fifo, overwrite=True):
        pass
    assert stat.S_ISFIFO(fifo.stat().st_mode) and _listing(tmp_path) == ["out.h5"]


def test_a_baseline_run_killed_before_its_record_says_overwrite_both_ways(baseline_runs: dict[str, Path], tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Killed between its first checkpoint and its config.json, a run was told to --resume by the rerun and to
    --overwrite by --resume: each sent the user to the other. The rerun names both; --resume rebuilds the record from
    the checkpoint."""
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", lambda r: (r / "config.json").unlink())
    argv = ["ddpg", "--obs", "state", "--out", str(run), *TINY_DDPG]
    refused("piga-baseline", argv, capsys, "holds a checkpoint without the record of its settings",
            "continue it with --resume", "pass --overwrite")
    code, out, err = run_in_process("piga-baseline", baseline.main, *argv[:5], "--resume", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)
    assert "config.json is missing; the resumed run rewrites it from the checkpoint" in out and (run / "config.json").exists()


@pytest.mark.parametrize("kind", ["ddpg", "planet"])
def test_a_baseline_runs_record_is_written_before_its_first_checkpoint(kind: str, tiny_data: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str],
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """So that no kill leaves a checkpoint without the record that --resume needs."""
    import agents.planet.train as planet_train
    import agents.sb3.train as sb3_train

    module = sb3_train if kind == "ddpg" else planet_train
    save, seen = module._save, []

    def checked_save(*args: object, **kwargs: object) -> None:
        seen.append((tmp_path / "run" / "config.json").exists() and not (tmp_path / "run" / "checkpoint.pt").exists())
        save(*args, **kwargs)

    monkeypatch.setattr(module, "_save", checked_save)
    argv = ["ddpg", "--obs", "state", *TINY_DDPG] if kind == "ddpg" else ["planet", str(tiny_data), *TINY_PLANET]
    code, _, err = run_in_process("piga-baseline", baseline.main, *argv, "--out", str(tmp_path / "run"), capsys=capsys)
    assert code in (0, 1) and "Traceback" not in err and seen[:1] == [True], err


def test_a_run_killed_before_its_first_checkpoint_is_simply_run_again(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A SIGKILL before the first checkpoint left TensorBoard's folder and the record, and the rerun was refused
    ("pass --overwrite"). What such a run leaves is replaced; a file of value, or a config.json that is not such a
    run's record, is still the user's to keep."""
    run = tmp_path / "run"
    (run / "tensorboard" / "ddpg_0").mkdir(parents=True)
    (run / "tensorboard" / "ddpg_0" / "events.out").write_text("")
    (run / "config.json").write_text(json.dumps({"command": "piga-baseline ddpg --obs state", "kind": "ddpg"}))
    argv = ["ddpg", "--obs", "state", "--out", str(run), *TINY_DDPG]
    code, out, err = run_in_process("piga-baseline", baseline.main, *argv, capsys=capsys)
    assert code in (0, 1) and "removing what a run of" in out and (run / "checkpoint.pt").exists(), err
    other = tmp_path / "other"
    other.mkdir()
    (other / "config.json").write_text('{"another tool": true}')
    refused("piga-baseline", [*argv[:3], "--out", str(other), *TINY_DDPG], capsys,
            "holds outputs of an earlier run but no checkpoint (config.json)", "--overwrite")
    (run / "checkpoint.pt").unlink()
    (run / "autoencoder.pt").write_text("minutes of training")
    refused("piga-baseline", argv, capsys, "holds outputs of an earlier run but no checkpoint", "--overwrite")


def test_control_names_a_missing_model_folder_before_judging_workers(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """--model of a folder that does not exist, with --workers, was told "--workers runs the jobs of --sweep"."""
    refused("piga-control", ["--model", str(tmp_path / "none"), "--episodes", "1", "--workers", "1", "--quiet"], capsys,
            f"--model {tmp_path / 'none'} does not exist")


def test_import_names_a_pipe_or_a_device_as_such(frame_folders: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A FIFO or /dev/zero was "no such actions file" or "no such video file": they exist."""
    import os

    fifo = tmp_path / "acts.csv"
    os.mkfifo(fifo)
    refused("piga-import", [str(frame_folders["moving"]), str(fifo), "--dt", "0.05", "--out", str(tmp_path / "o.h5")],
            capsys, f"{fifo}: is not a regular file (a pipe, a socket or a device), not an actions CSV file")
    (tmp_path / "a.csv").write_text("0\n")
    refused("piga-import", ["/dev/zero", str(tmp_path / "a.csv"), "--dt", "0.05", "--out", str(tmp_path / "o.h5")],
            capsys, "/dev/zero: is not a regular file", "not a video file or frame folder")
    assert sorted(_listing(tmp_path)) == ["a.csv", "acts.csv"]


def test_import_names_a_folder_given_as_the_actions(frame_folders: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """It said "acts: no such actions file" of a folder that exists."""
    acts = tmp_path / "acts"
    acts.mkdir()
    refused("piga-import", [str(frame_folders["moving"]), str(acts), "--dt", "0.05", "--out", str(tmp_path / "o.h5")],
            capsys, f"{acts} is a folder, not an actions CSV file")
    assert _listing(tmp_path) == ["acts"]


def test_import_names_a_data_file_given_as_the_actions(frame_folders: dict[str, Path], tiny_data: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """It said "byte 0x89 is not UTF-8 text; save the file as UTF-8", which no re-save of an HDF5 file answers."""
    line = refused("piga-import", [str(frame_folders["moving"]), str(tiny_data), "--dt", "0.05", "--out",
                                   str(tmp_path / "o.h5")], capsys, f"{tiny_data} is an HDF5 file",
                   "not an actions CSV file; give the CSV of the recording's actions")
    assert "UTF-8" not in line and _listing(tmp_path) == []


def test_planet_iterative_refuses_another_envs_file(files: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-baseline", ["planet", str(files["labelled_dmc"]), "--out", str(tmp_path / "run"), *TINY_PLANET,
                              "--iterative", "1"], capsys, "the PlaNet-style agent is trained on and controls "
            "piga/PixelPendulum-v0", "this file is pendulum from piga/DMCPendulum-v0")
    assert _listing(tmp_path) == []


def test_control_refuses_a_planet_run_of_dmc_frames(baseline_runs: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A PlaNet-style run trained on dm_control's frames (0.04 s apart) was scored on Gymnasium's pendulum, exit 0.
    Training on such a file is refused now; a run made before is refused here (its checkpoint names the env)."""
    import torch

    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["data"] |= {"env_id": "piga/DMCPendulum-v0", "dt": 0.04}
    torch.save(checkpoint, run / "checkpoint.pt")
    refused("piga-control", ["--model", str(run), "--episodes", "1", "--steps", "20", "--workers", "1", "--quiet"], capsys,
            "trained on frames of piga/DMCPendulum-v0, 0.04 s apart", "not of Gymnasium's pixel pendulum")


@pytest.mark.parametrize("argv", [["--episodes", "1", "--steps", "20", "--workers", "1"], ["--sweep", "1:1:1", "--episodes", "1"]])
def test_control_refuses_a_planet_run_of_another_frame_rate(argv: list[str], baseline_runs: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A run whose checkpoint names no env (from before it was recorded) is judged by its frames' rate."""
    import torch

    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    assert checkpoint["data"]["env_id"] == "piga/PixelPendulum-v0"
    checkpoint["data"] = {k: v for k, v in checkpoint["data"].items() if k != "env_id"} | {"dt": 0.04}
    torch.save(checkpoint, run / "checkpoint.pt")
    refused("piga-control", ["--model", str(run), "--quiet", *argv], capsys, "trained on frames 0.04 s apart", "steps 0.05 s")


def test_control_on_a_state_run_says_nothing_of_the_torque_arrow(baseline_runs: dict[str, Path], tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A state policy sees no frames: "trained with the torque arrow shown; these episodes hide it" was noise."""
    import torch

    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", _edit_record(lambda r: r["ddpg"].__setitem__("torque_arrow", True)))
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["config"]["torque_arrow"] = True  # a run made before --obs state refused the arrow
    torch.save(checkpoint, run / "checkpoint.pt")
    code, _, err = run_in_process("piga-control", control.main, "--model", str(run), "--episodes", "1", "--steps", "20",
                                  "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0, err
    assert "torque arrow" not in err, err
    # and --torque-arrow, which shows the arrow only in frames it never sees, is refused (unless a --video shows them)
    refused("piga-control", ["--model", str(run), "--episodes", "1", "--steps", "20", "--torque-arrow", "--quiet"], capsys,
            "acts on the state (--obs state) and sees none, and no --video is written: drop --torque-arrow")


def test_a_parameter_beyond_float_range_is_named_not_an_internal_error(tiny_data: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """JSON integers are unbounded: g = 10**400 raised OverflowError (exit 70) in every reader."""
    data = tmp_path / "big.h5"
    shutil.copy(tiny_data, data)
    with h5py.File(data, "a") as f:
        params = json.loads(f.attrs["params"])
        f.attrs["params"] = json.dumps({**params, "g": 10**400})
    for prog, argv in (("piga-show", [str(data), "--out", str(tmp_path / "s.png")]),
                       ("piga-train-model", [str(data), "--out", str(tmp_path / "run"), "--quiet"])):
        line = refused(prog, argv, capsys, "attribute 'params' must give each parameter as a finite number, got g=1000")
        assert len(line) < 300, line  # the 401 digits are cut
    assert _listing(tmp_path) == ["big.h5"]


def _damage_chunk(path: Path, sequence: int) -> None:
    """Overwrites bytes inside the compressed chunk of ``sequence``'s frames, so that its filter fails to read it."""
    with h5py.File(path, "r") as f:
        info = f["frames"].id.get_chunk_info_by_coord((sequence,) + (0,) * (f["frames"].ndim - 1))
    with open(path, "r+b") as raw:
        raw.seek(info.byte_offset + info.size // 3)
        raw.write(b"\xff" * min(200, info.size // 3))


@pytest.mark.parametrize("prog", ["piga-show", "piga-train-model"])
def test_a_damaged_chunk_is_named_with_its_file_and_sequence(prog: str, tiny_data: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """HDF5's "Can't synchronously read data (filter returned failure during read)" named neither the file nor what
    in it; training failed after it had written its first checkpoint when the damage lay in a held-out sequence."""
    data = tmp_path / "bad.h5"
    shutil.copy(tiny_data, data)
    _damage_chunk(data, 0)
    argv = [str(data), "--out", str(tmp_path / ("s.png" if prog == "piga-show" else "run"))]
    refused(prog, [*argv, *([] if prog == "piga-show" else ["--epochs", "1", "--batch-size", "4", "--quiet"])], capsys,
            f"{data}: /frames of ", "cannot be read", "the file is damaged")
    assert _listing(tmp_path) == ["bad.h5"]


def test_a_damaged_chunk_past_the_first_sequence_is_named_before_training(tiny_data: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The background's sample of the training frames read the damaged chunk without naming it: a bare OSError. (The
    fingerprint of the file, which hashes every frame, reads it first, and names its sequence.)"""
    from piga.data.schema import split_indices

    data = tmp_path / "bad.h5"
    shutil.copy(tiny_data, data)
    damaged = int(split_indices(data, "train")[-1])
    _damage_chunk(data, damaged)
    refused("piga-train-model", [str(data), "--out", str(tmp_path / "run"), "--epochs", "1", "--batch-size", "4",
                                 "--quiet"], capsys, f"{data}: /frames of sequence {damaged} cannot be read",
            "the file is damaged")
    assert _listing(tmp_path) == ["bad.h5"]


@pytest.mark.parametrize("option", ["--max-speed", "--max-angle"])
def test_collect_reads_minus_zero_as_zero(option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """-0 made the reset range -0 to 0, which numpy refused as "high - low < 0" (an error naming no option)."""
    from piga.cli.collect import main as collect_main

    assert collect_main(["--out", str(tmp_path / "d.h5"), "--sequences", "4", "--steps", "6", "--split", "2,1,1",
                         "--workers", "1", "--quiet", option, "-0"]) == 0


def test_an_image_beyond_pillows_limit_is_called_too_large(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 40000 x 40000 goal image was "not a readable image (DecompressionBombError)"."""
    from PIL import Image

    from piga.data.scene import read_image

    Image.new("L", (64, 64)).save(tmp_path / "g.png")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)  # a 64 x 64 picture is then beyond twice the limit
    with pytest.raises(ValueError, match=r"g.png: the image is too large to read \(more than Pillow's limit of 2,000 "):
        read_image(tmp_path / "g.png")


def test_a_file_an_imageio_plugin_misreads_is_no_image_and_one_line(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A piga checkpoint given as the goal image: imageio's SPE plugin read it as 0 frames, with a UserWarning on
    stderr beside the error ("expected a 2-D gray or RGB image, got shape (0, 29043, 29808)")."""
    import warnings

    import imageio.v3 as iio

    from piga.data.scene import read_image

    def misread(path: object, **kwargs: object) -> np.ndarray:
        warnings.warn("The file header claims there are 7 frames, but there are actually 0 frames.")
        return np.zeros((0, 29043, 29808), np.uint8)

    (tmp_path / "checkpoint.pt").write_bytes(b"PK\x03\x04 not an image")
    monkeypatch.setattr(iio, "imread", misread)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning passed on would raise here
        with pytest.raises(ValueError, match=r"checkpoint.pt: not a readable image \(it has no pixels\)"):
            read_image(tmp_path / "checkpoint.pt")


@pytest.fixture(scope="module")
def foreign_frame_runs(files: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One-epoch piga runs on frames the pixel pendulum does not render: 63x63 gray ("cropped_63"), 64x64 colour ("colour"),
    each in a file of no env (a file of the pixel pendulum's with them is refused on open)."""
    from tests.helpers import train_tiny

    root = tmp_path_factory.mktemp("foreign")
    return {name: train_tiny(files[file], root / name) for name, file in (("cropped_63", "cropped_63"),
                                                                          ("colour", "colour_recording"))}


@pytest.mark.parametrize("run, needle", [("cropped_63", "takes 63x63 gray frames"), ("colour", "takes 64x64 3-channel frames")])
@pytest.mark.parametrize("argv", [[], ["--goal-image", "GOAL"], ["--video", "OUT/v.mp4"], ["--sweep", "1:1:1", "--workers", "1"]])
def test_control_refuses_a_model_of_frames_the_env_does_not_render(run: str, needle: str, argv: list[str],
                                                                   foreign_frame_runs: dict[str, Path], tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A model trained on 63 px or colour frames failed on the env's 64 px gray ones (exit 70: "The size of tensor a
    (64) must match ...", "frames must be (B, T, H, W) or (B, T, H, W, C=3)"), after the run's convergence warning."""
    goal = tmp_path / "goal.png"
    if "GOAL" in argv:
        assert run_in_process("piga-control", control.main, "--write-goal-image", str(goal), "--angle", "10", capsys=capsys)[0] == 0
    out = tmp_path / "out"
    out.mkdir()
    argv = [str(goal) if a == "GOAL" else str(out / "v.mp4") if a == "OUT/v.mp4" else a for a in argv]
    refused("piga-control", ["--model", str(foreign_frame_runs[run]), "--episodes", "1", "--steps", "20", "--quiet", *argv],
            capsys, needle, "Gymnasium's pixel pendulum renders 64x64 gray ones")
    assert _listing(out) == []


def _latent(ae: Callable[[Path], None], data: Path) -> Callable[[Path], None]:
    """An edit that turns a copy of the state DDPG run into a latent one of ``data`` (its record and checkpoint say so),
    then makes its autoencoder with ``ae``."""
    def edit(run: Path) -> None:
        import torch

        _edit_record(lambda r: r.update(data=str(data), ddpg={**r["ddpg"], "obs": "latent"}))(run)
        checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
        checkpoint["config"]["obs"] = "latent"
        torch.save(checkpoint, run / "checkpoint.pt")
        ae(run / "autoencoder.pt")

    return edit


def _truncated_torch_file(path: Path) -> None:
    import torch

    torch.save({"model": {"w": torch.zeros(1000)}, "config": {}}, path)
    with open(path, "r+b") as f:
        f.truncate(1000)


@pytest.mark.parametrize("ae, needles", [
    (_truncated_torch_file, ["autoencoder.pt: not a readable autoencoder of a latent DDPG run", "cut short or damaged",
                             "may be truncated", "--overwrite"]),
    (lambda path: None, ["autoencoder.pt is missing", "restore it, or train the run again with --overwrite"]),
])
@pytest.mark.parametrize("prog", ["piga-baseline", "piga-control"])
def test_a_latent_ddpg_run_with_a_damaged_autoencoder_is_named(ae: Callable[[Path], None], needles: list[str], prog: str,
                                                               baseline_runs: dict[str, Path], tiny_data: Path,
                                                               tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A truncated autoencoder.pt was an internal error ("PytorchStreamReader failed reading zip archive"), a missing
    one (in piga-control) a bare "[Errno 2] No such file or directory"."""
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "run", _latent(ae, tiny_data))
    before = _listing(run)
    argv = (["ddpg", "--obs", "latent", "--data", str(tiny_data), "--out", str(run), "--resume", "--steps", "400", "--quiet"]
            if prog == "piga-baseline" else ["--model", str(run), "--episodes", "1", "--steps", "20", "--quiet"])
    line = refused(prog, argv, capsys, str(run / "autoencoder.pt"), *needles)
    assert "Errno" not in line
    assert _listing(run) == before


@pytest.mark.parametrize("flags", [[], ["--workers", "1"], ["--workers", "2"], ["--ray", "127.0.0.1:1"],
                                   ["--candidates", "8"]], ids=lambda f: " ".join(f) or "none")
@pytest.mark.parametrize("kind, record", [("planet", None), ("planet", '{"kind": '), ("ddpg", None)])
def test_control_on_a_baseline_run_without_its_record_names_the_record(kind: str, record: str | None, flags: list[str],
                                                                       baseline_runs: dict[str, Path], tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Without config.json, control took the run for a piga one and said that its checkpoint "is a piga-baseline planet
    checkpoint, not a piga-train-model run", although it runs planet and ddpg runs; with --workers or --ray, it blamed
    the flag, which a baseline's run takes."""
    def damage(run: Path) -> None:
        (run / "config.json").unlink() if record is None else (run / "config.json").write_text(record)

    run = _run_copy(baseline_runs[kind], tmp_path / "run", damage)
    refused("piga-control", ["--model", str(run), "--episodes", "1", "--steps", "20", "--quiet", *flags], capsys,
            f"{run / 'config.json'}, the run's record, {'is missing' if record is None else 'cannot be read'}",
            f"piga-baseline {kind} checkpoint", "read a run's kind from its config.json")


@pytest.mark.parametrize("flags", [[], ["--candidates", "8"], ["--workers", "1"]], ids=lambda f: " ".join(f) or "none")
def test_control_on_a_record_of_another_kind_than_its_checkpoint_names_both(flags: list[str], tiny_piga_run: Path,
                                                                            tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A piga run whose config.json says planet was judged as a planet run: --candidates was blamed."""
    def planet(run: Path) -> None:
        record = run / "config.json"
        (run / "config.json").write_text(json.dumps({**(json.loads(record.read_text()) if record.exists() else {}),
                                                     "kind": "planet"}))

    run = _run_copy(tiny_piga_run, tmp_path / "run", planet)
    refused("piga-control", ["--model", str(run), "--episodes", "1", "--steps", "20", "--quiet", *flags], capsys,
            f"{run / 'config.json'} names a piga-baseline planet run", "is a piga-train-model checkpoint",
            "restore the run's own config.json")


def test_control_sweep_refuses_an_unreachable_ray_before_warning(tiny_piga_run: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The run's not-converged warning came first, so a refused --ray printed two lines."""
    def unconverged(run: Path) -> None:
        metrics = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").exists() else {}
        (run / "metrics.json").write_text(json.dumps({**metrics, "converged": False, "convergence": {"reason": "too short"}}))

    run = _run_copy(tiny_piga_run, tmp_path / "run", unconverged)
    line = refused("piga-control", ["--model", str(run), "--sweep", "1:1:1", "--ray", "nohost:1", "--episodes", "1",
                                    "--quiet"], capsys, "--ray nohost:1")
    assert "converge" not in line


def test_diagnose_refuses_sequences_too_short_for_its_fit_first(tiny_piga_run: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """It encoded every frame (half a minute) before its fit found no window in sequences of 12 frames. A missing
    model, a file or a baseline's run given as --model was reported as that data problem; it is named first."""
    from piga.data.collect import CollectConfig
    from piga.data.collect import collect as collect_data

    data = tmp_path / "short.h5"
    collect_data(CollectConfig(sequences=20, steps=12, seed=1, workers=1), data, progress=False, command="test")
    code, _, err = run_in_process("piga-diagnose", diagnose.main, "--data", str(data), "--model", str(tiny_piga_run),
                                  "--out", str(tmp_path / "report"), capsys=capsys)
    assert_one_line(code, err, f"{data}: sequences of 12 frames are too short to diagnose: the fit needs 13",
                    "piga-collect --steps 13")
    assert _listing(tmp_path) == ["short.h5"]
    imported = tmp_path / "imported.h5"  # a recording brought in has no env to collect again: import it longer
    shutil.copy(data, imported)
    with h5py.File(imported, "a") as f:
        for key in ("env_id", "env_config"):
            f.attrs.pop(key, None)
    code, _, err = run_in_process("piga-diagnose", diagnose.main, "--data", str(imported), "--model",
                                  str(tiny_piga_run), "--out", str(tmp_path / "report"), capsys=capsys)
    line = assert_one_line(code, err, "too short to diagnose", "piga-import --steps 13")
    # 240 frames make 18 sequences of 13: imported again that way, it was refused for their number
    assert line.endswith("; but its 240 frames make 18 such sequences, and the diagnosis needs 20 (260 frames): "
                         "record a longer video"), line
    imported.unlink()
    planet = tmp_path / "planet"
    planet.mkdir()
    (planet / "config.json").write_text(json.dumps({"kind": "planet"}))
    (planet / "checkpoint.pt").write_bytes(b"not read")
    for model, needle in ((tmp_path / "nowhere", f"--model {tmp_path / 'nowhere'} does not exist"),
                          (data, f"--model {data} is a file, not a run folder"),
                          (planet, "is a piga-baseline planet run")):
        line = refused("piga-diagnose", ["--data", str(data), "--model", str(model), "--out", str(tmp_path / "report")],
                       capsys, needle)
        assert "too short" not in line, line


def test_a_virtual_dataset_whose_source_is_missing_is_named(tiny_data: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """HDF5 reads a virtual dataset's missing source as its fill value: the frames were refused as "blank"."""
    source, data = tmp_path / "source.h5", tmp_path / "virtual.h5"
    shutil.copy(tiny_data, source)
    shutil.copy(tiny_data, data)
    with h5py.File(source) as f:
        shape, dtype = f["frames"].shape, f["frames"].dtype
    layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
    layout[:] = h5py.VirtualSource("source.h5", "frames", shape=shape)
    with h5py.File(data, "a") as f:
        del f["frames"]
        f.create_virtual_dataset("frames", layout)
    code, _, err = run_in_process("piga-show", show.main, str(data), "--out", str(tmp_path / "s.png"), capsys=capsys)
    assert code == 0, err  # the source beside it: read through
    source.unlink()
    code, _, err = run_in_process("piga-show", show.main, str(data), "--out", str(tmp_path / "t.png"), "--overwrite",
                                  capsys=capsys)
    assert_one_line(code, err, f"{data}: /frames is a virtual dataset whose source file source.h5 is missing")


def _config_cases() -> list[tuple[str, dict[str, object], str]]:
    nan, inf = float("nan"), float("inf")
    return [
        ("agents.reward_head:RewardHeadConfig", {"hidden": "64"}, "RewardHeadConfig.hidden must be an integer"),
        ("agents.reward_head:RewardHeadConfig", {"lr": inf}, "RewardHeadConfig.lr must be a finite number > 0"),
        ("piga.control.episodes:EpisodeConfig", {"goal_angle": nan}, "EpisodeConfig.goal_angle must be a finite number"),
        ("piga.control.episodes:EpisodeConfig", {"angle_tolerance": -1.0}, "EpisodeConfig.angle_tolerance must be"),
        ("piga.control.episodes:EpisodeConfig", {"frame_stack": 0}, "frame_stack must be >= 1"),
        ("agents.config:MPCConfig", {"cem": "abc"}, "MPCConfig.cem must be a CEMConfig"),
        ("agents.config:MPCConfig", {"velocity_weight": inf}, "MPCConfig.velocity_weight must be a finite number >= 0"),
        ("agents.config:MPCConfig", {"warm_init_std": -0.3}, "MPCConfig.warm_init_std must be a finite number > 0"),
        ("agents.config:CEMConfig", {"init_std": inf}, "CEMConfig.init_std must be a finite number > 0"),
        ("agents.planet.config:RSSMConfig", {"min_std": inf}, "RSSMConfig.min_std must be a finite number > 0"),
        ("agents.planet.config:PlanetTrainConfig", {"kl_scale": -1.0}, "kl_scale=-1.0"),
        ("agents.sb3.autoencoder:AutoencoderConfig", {"lr": inf}, "a finite lr > 0"),
        ("piga.world.model:ModelConfig", {"channels": 0}, "channels 1 or 3"),
        ("piga.world.model:ModelConfig", {"system": ["pendulum"]}, "unknown system ['pendulum']"),
        ("piga.world.model:ModelConfig", {"init_scale": nan}, "ModelConfig.init_scale must be a finite number > 0"),
        ("piga.evaluation.evaluate:EvalConfig", {"max_sequences": 0}, "EvalConfig.max_sequences must be >= 1"),
    ]


@pytest.mark.parametrize("target, values, needle", _config_cases())
def test_the_librarys_configs_refuse_nonsense_naming_the_field(target: str, values: dict[str, object], needle: str) -> None:
    """Values that were accepted (an infinite learning rate, a NaN goal, a weight below 0) or failed deep inside
    ("'<' not supported", "unhashable type"): one error naming the field."""
    import importlib

    module, name = target.split(":")
    cls = getattr(importlib.import_module(module), name)
    with pytest.raises((TypeError, ValueError)) as error:
        cls(**values)
    assert needle in str(error.value) and "\n" not in str(error.value), str(error.value)
    cls()  # the defaults stand


def test_a_disk_that_fills_while_a_figure_is_written_is_named_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """matplotlib's PDF writer broke on a full disk with an AttributeError ('Stream' object has no attribute 'pos'),
    an internal error; a PNG's OSError was printed raw ("OSError: [Errno 28] No space left on device")."""
    import errno
    import shutil
    from collections import namedtuple

    from piga.cli.common import run_cli
    from piga.evaluation import plots

    def broken(*args: object, **kwargs: object) -> None:
        raise AttributeError("'Stream' object has no attribute 'pos'")

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(plots.Figure, "savefig", broken)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(1 << 20, 1 << 20, 0))
    with pytest.raises(OSError) as full:
        plots.save_figure(plots.plt.figure(), tmp_path / "x.pdf")
    assert full.value.errno == errno.ENOSPC and full.value.filename == str(tmp_path / "x.pdf")
    assert list(tmp_path.iterdir()) == []  # the atomic write left no partial file
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(1 << 30, 0, 1 << 30))  # room left: the writer's own bug
    with pytest.raises(AttributeError):
        plots.save_figure(plots.plt.figure(), tmp_path / "x.pdf")

    def fills(argv: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device", "out/metrics.json")

    with pytest.raises(SystemExit) as exit_:
        run_cli("piga-x", fills, [])
    assert exit_.value.code == 1
    assert_one_line(1, capsys.readouterr().err, "piga-x: error: out/metrics.json: the disk is full", "free some space")


def test_an_interrupt_after_the_last_checkpoint_says_the_run_is_kept(tiny_data: Path, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C (or SIGTERM) while the finished run wrote its report said "nothing was written", and the rerun was then
    refused ("already holds a run"): the line names the checkpoint and --resume, which writes the report."""
    from piga.cli.common import NOT_CONVERGED
    from piga.training import report

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    run = tmp_path / "run"
    argv = [str(tiny_data), "--out", str(run), "--epochs", "1", "--batch-size", "4", "--threads", "1", "--quiet"]
    with monkeypatch.context() as patch:
        patch.setattr(report, "write_run_report", interrupted)
        code, _, err = run_in_process("piga-train-model", train.main, *argv, capsys=capsys)
    assert code == 130 and err.count("\n") == 1, err
    assert f"{run / 'checkpoint.pt'} holds the trained model (epoch 1)" in err and "--resume" in err
    code, _, err = run_in_process("piga-train-model", train.main, *argv, "--resume", capsys=capsys)
    assert code in (0, 1, NOT_CONVERGED) and "Traceback" not in err, err
    assert (run / "metrics.json").exists()


def test_an_interrupt_inside_a_garbage_collector_callback_is_raised_again(capsys: pytest.CaptureFixture[str]) -> None:
    """SIGTERM that landed in a weakref callback printed "Exception ignored in ... Traceback ... KeyboardInterrupt"
    (9 lines) and was lost: it is delivered again, and the command stops with its one line."""
    import gc
    import time
    import weakref

    from piga.cli.common import run_cli

    class Thing:
        pass

    def main(argv: object) -> int:
        thing = Thing()

        def callback(ref: object) -> None:
            raise KeyboardInterrupt  # what the SIGTERM handler does when the signal lands here

        ref = weakref.ref(thing, callback)  # kept alive until the thing goes
        assert ref() is thing
        del thing
        gc.collect()
        for _ in range(200):  # where the command's code runs next, the interrupt is raised (within 2 s here)
            time.sleep(0.01)
        return 0

    with pytest.raises(SystemExit) as exit_:
        run_cli("piga-x", main, [])
    err = capsys.readouterr().err
    assert exit_.value.code == 130 and err == "piga-x: interrupted; nothing was written\n", err


def test_an_unreadable_image_says_why_in_words(tmp_path: Path) -> None:
    """An empty or truncated goal image was "not a readable image (OSError)"; a file of no image format, imageio's
    "Could not find a backend to open ... with iomode `r`"."""
    from piga.data.scene import read_image

    empty, truncated, text = tmp_path / "empty.png", tmp_path / "cut.png", tmp_path / "notes.xyz"
    empty.write_bytes(b"")
    iio_png = tmp_path / "whole.png"
    import imageio.v3 as iio

    iio.imwrite(iio_png, np.zeros((64, 64), np.uint8))
    truncated.write_bytes(iio_png.read_bytes()[:40])
    text.write_text("hello")
    for path, why in ((empty, "the file is empty"), (truncated, "damaged, or not a picture in the format its suffix names"),
                      (text, "no reader knows its format")):
        with pytest.raises(ValueError, match="not a readable image") as bad:
            read_image(path)
        assert why in str(bad.value) and "\n" not in str(bad.value), str(bad.value)


def test_a_data_file_stops_before_hdf5_runs_out_of_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """HDF5 that runs out of disk mid-write left objects whose deallocation printed dozens of tracebacks, then the
    process segfaulted: the writer checks the room for each slice first, and the partial file goes. (The disk fills
    after the command's own check, which asks for the same room.)"""
    from piga.data import collect as collect_module, schema

    real = shutil.disk_usage
    monkeypatch.setattr(collect_module, "check_resources", lambda config, out: None)
    monkeypatch.setattr(schema.shutil, "disk_usage", lambda path: real(path)._replace(free=1000))
    out = tmp_path / "d.h5"
    refused("piga-collect", ["--out", str(out), "--sequences", "3", "--steps", "4", "--image-size", "16", "--workers", "1",
                             "--quiet"], capsys, "d.h5: its disk has 1000 B free, less than the", "free some space")
    assert _listing(tmp_path) == []


def test_a_checkpoint_onto_a_full_disk_is_enospc_not_torchs_runtime_error() -> None:
    """torch's zip writer reported a full disk as "RuntimeError: unexpected pos", which read as a bug (exit 70)."""
    import errno

    from piga.io.atomic import torch_save

    with pytest.raises(OSError) as info:
        torch_save({"weights": np.zeros(1000)}, "/dev/full")
    assert info.value.errno == errno.ENOSPC


@pytest.mark.parametrize("value, needle", [(np.nan, "frame 5 (counted from 0): 1 of its 1024 pixel values are not finite"),
                                           (np.inf, "frame 5 (counted from 0): 1 of its 1024 pixel values are not finite"),
                                           (-0.5, "frame 5 (counted from 0): its values go below 0 (down to -0.5)")])
def test_import_refuses_a_float_stack_of_nonsense_pixels_naming_them(value: float, needle: str, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A NaN pixel was cast to a black frame (and two numpy warnings), exit 0; negative frames were called blank."""
    import imageio.v3 as iio

    frames = np.zeros((12, 32, 32), np.float32)
    for i in range(12):
        frames[i, i : i + 6, 8:14] = 0.8
    frames[5, 0, 0] = value
    iio.imwrite(tmp_path / "v.tif", frames)
    (tmp_path / "u.csv").write_text("\n".join(["0.5"] * 12) + "\n")
    refused("piga-import", ["--dt", "0.05", "--steps", "4", "--image-size", "16", str(tmp_path / "v.tif"),
                            str(tmp_path / "u.csv"), "--out", str(tmp_path / "x.h5")], capsys, needle)
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("text, needle", [("0x1\n" + "0.5\n" * 11, "line 1: expected a finite number, got '0x1'"),
                                          ("caf\u00e9\n", "line 1: byte 0xe9 is not UTF-8 text")])
def test_import_reads_no_malformed_number_as_a_header_and_names_a_latin1_file(
        text: str, needle: str, frame_folders: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "u.csv"
    csv.write_bytes(text.encode("latin-1"))
    refused("piga-import", ["--dt", "0.05", "--steps", "4", str(frame_folders["moving"]), str(csv), "--out",
                            str(tmp_path / "x.h5")], capsys, needle)


def test_import_skips_comment_lines_only_where_no_action_follows(tmp_path: Path) -> None:
    """Every # line was dropped: a commented-out action between values shifted every later one by a frame."""
    from piga.data.importer import read_actions

    path = tmp_path / "u.csv"
    path.write_text("# recorded at 20 Hz\nu\n0.5\n-1\n  # the end\n")
    assert read_actions(path).tolist() == [0.5, -1.0]
    path.write_text("u\n0.5\n  # a gap\n-1\n")
    with pytest.raises(ValueError, match="line 3 is a comment"):
        read_actions(path)


@pytest.mark.parametrize("order", ["swapped", "csv twice"])
def test_import_names_swapped_arguments(order: str, frame_folders: dict[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A GIF given as the actions was "line 1: byte 0x85 is not UTF-8 text; save the file as UTF-8"; a CSV given as
    the recording, "no reader knows its format"."""
    import imageio.v3 as iio

    gif, csv = tmp_path / "v.gif", tmp_path / "a.csv"
    iio.imwrite(gif, np.stack([np.full((16, 16), 40 * i, np.uint8) for i in range(4)]), extension=".gif")
    csv.write_text("0.5\n" * 4)
    argv = [str(csv), str(gif)] if order == "swapped" else [str(csv), str(csv)]
    line = refused("piga-import", [*argv, "--dt", "0.05", "--steps", "2", "--out", str(tmp_path / "o.h5")], capsys,
                   "the recording comes first, then the actions: piga-import RECORDING ACTIONS.csv")
    assert (f"{gif} is a GIF, not an actions CSV file" if order == "swapped" else "it is a CSV file, such as the actions") \
        in line and "UTF-8" not in line, line
    acts = tmp_path / "frames"
    shutil.copytree(frame_folders["moving"], acts)
    refused("piga-import", [str(csv), str(acts), "--dt", "0.05", "--out", str(tmp_path / "o.h5")], capsys,
            f"{acts} is a folder, not an actions CSV file (a folder of frames: the recording comes first")


@pytest.mark.parametrize("prog, argv, needle", [
    ("piga-collect", ["--steps", "1"], "--steps must be >= 2"),
    ("piga-collect", ["--system", "spring", "--radius", "0.3"], "--radius must be at least 0.5 px"),
    ("piga-collect", ["--system", "bouncing", "--half"], "--half (the top-half data) is for the spring scene"),
    ("piga-train-model", ["DATA", "--video-lstm-scale", "2"], "--video-lstm-scale sizes the video-lstm baseline"),
    ("piga-train-model", ["DATA", "--broadcast-width", "8"], "--broadcast-width sizes the spatial-broadcast decoder"),
    # at their defaults too: the docs say "only with --model video-lstm", "not with --model video-lstm", "only with
    # --decoder broadcast" (each ran)
    ("piga-train-model", ["DATA", "--video-lstm-scale", "1"], "--video-lstm-scale sizes the video-lstm baseline; "
                                                                "architecture 'piga' has its own sizes: drop"),
    ("piga-train-model", ["DATA", "--model", "video-lstm", "--decoder", "st"], "--decoder does not apply to --model "
                                                                                "video-lstm"),
    ("piga-train-model", ["DATA", "--decoder", "mlp", "--broadcast-width", "16"], "decoder 'mlp' has its own sizes"),
])
def test_a_configs_refusal_names_the_flag_not_the_field(prog: str, argv: list[str], needle: str, tiny_data: Path,
                                                        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [str(tiny_data) if word == "DATA" else word for word in argv]
    refused(prog, [*argv, "--out", str(tmp_path / ("o.h5" if prog == "piga-collect" else "run")), "--quiet"], capsys, needle)
    assert _listing(tmp_path) == []


def test_collects_summary_never_rounds_an_effect_into_a_refused_value() -> None:
    from envs.effects import format_effects

    assert format_effects([("deadzone", 1.999999), ("gain", 1.0000000000000002), ("delay", 2.0)]) == \
        "deadzone=1.999999 gain=1.0000000000000002 delay=2"


def test_a_report_interrupted_while_written_leaves_no_folder_it_made(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An interrupted piga-diagnose said "nothing was written" and left the parents of its --out."""
    from piga.diagnostics import report

    def interrupted(*args: Any, **kwargs: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "_write_files", interrupted)
    with pytest.raises(KeyboardInterrupt):
        report.write_report(None, tmp_path / "new" / "sub" / "g", "model", "data", "cmd")  # type: ignore[arg-type]
    assert _listing(tmp_path) == []


def test_an_error_line_comes_after_the_progress_bar_it_ended(tmp_path: Path) -> None:
    """The interrupt's line landed inside collect's bar, which was redrawn after it when collected."""
    result = subprocess.run(["python", "-c", "import sys, tqdm; from piga.cli.common import run_cli\n"
                             "def main(argv):\n    bar = tqdm.tqdm(total=10, file=sys.stderr); bar.update(3)\n"
                             "    raise ValueError('bad input')\nrun_cli('prog', main)"],
                            capture_output=True, text=True, env=ENV, timeout=60)
    assert result.returncode == 1 and result.stderr.rstrip().endswith("prog: error: bad input"), result.stderr


@pytest.mark.slow
def test_diagnose_refuses_an_env_that_contradicts_the_files_effects(tmp_path: Path, tiny_piga_run: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """The MPC comparison of --env would have run on another system than the one the data came from. (Judged after
    the model's own checks: a DMC model was told "give --env 'none'", which its frame rate then refused.)"""
    data = tmp_path / "eff.h5"
    assert run_in_process("piga-collect", collect.main, "--out", str(data), "--sequences", "20", "--steps", "24",
                          "--image-size", "16", "--effect", "damping=0.2", "--workers", "1", "--quiet", capsys=capsys)[0] == 0
    for env in ("delay=2", "none", "damping=0.3"):
        refused("piga-diagnose", ["--model", str(tiny_piga_run), "--data", str(data), "--env", env, "--out",
                                  str(tmp_path / "rep"), "--quiet"], capsys, "was collected with effects damping=0.2",
                "give --env 'damping=0.2'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eff.h5"]


def test_a_split_counts_attribute_that_contradicts_the_split_is_named(tiny_data: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    def lie(f: h5py.File) -> None:
        f.attrs["split_counts"] = json.dumps({"train": 1, "valid": 1, "test": 10})

    data = _variant(tiny_data, tmp_path / "lie.h5", lie)
    refused("piga-train-model", [str(data), "--out", str(tmp_path / "run"), "--quiet"], capsys,
            "attribute 'split_counts' says", "but /split holds")


@pytest.mark.parametrize("kind", ["planet", "ddpg"])
def test_control_warns_that_a_baseline_run_did_not_learn(kind: str, baseline_runs: dict[str, Path], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """piga-baseline exits 1 on such a run, keeping it; piga-control scored it without a word, where a piga run that
    did not converge is warned of."""
    from piga.cli.control import baseline_did_not_learn
    from piga.io.checkpoint import RunKind

    run = baseline_runs[kind]
    why = baseline_did_not_learn(run, RunKind(kind))
    if why is None:
        pytest.skip("the tiny run learned")
    code, _, err = run_in_process("piga-control", control.main, "--model", str(run), "--episodes", "1", "--steps", "20",
                                  "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0 and err.strip().splitlines() == [f"piga-control: warning: the run {run} did not learn ({why}); "
                                                      "these episodes score it all the same"], err
    assert baseline_did_not_learn(tmp_path, RunKind(kind)) is None  # no record: nothing to say


@pytest.mark.parametrize("kind", ["planet", "ddpg"])
def test_control_warns_that_a_baseline_run_stopped_before_its_end(kind: str, baseline_runs: dict[str, Path],
                                                                  tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """An interrupted run (a checkpoint, no metrics.json) was scored without a word; a finished one that did not learn
    was warned of, and so was a piga run without metrics.json."""
    run = _run_copy(baseline_runs[kind], tmp_path / "run")
    (run / "metrics.json").unlink()
    code, _, err = run_in_process("piga-control", control.main, "--model", str(run), "--episodes", "1", "--steps", "20",
                                  "--workers", "1", "--quiet", capsys=capsys)
    assert code == 0 and err.strip().splitlines() == [
        f"piga-control: warning: the run {run} has no metrics.json: it stopped before its end (interrupted, or killed) "
        "and was never checked for learning; this used its last checkpoint (continue it with piga-baseline --resume)"], err


def test_a_stderr_open_only_for_reading_is_taken_as_closed(tmp_path: Path) -> None:
    """pyenv's shim, run with 2>&-, left its script open on descriptor 2, read-only: the first write failed the command."""
    script = tmp_path / "held.txt"
    script.write_text("a file a launcher left open\n")
    with script.open() as read_only:
        result = subprocess.run(["python", "-m", "piga.cli.collect", "--out", str(tmp_path / "d.h5"), "--sequences", "3",
                                 "--steps", "4", "--image-size", "16", "--workers", "1"], stderr=read_only,
                                stdout=subprocess.PIPE, text=True, env=ENV, timeout=120)
    assert result.returncode == 0 and (tmp_path / "d.h5").exists(), result.stdout


def test_a_report_folder_made_meanwhile_by_another_command_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two diagnoses given one --out: the second ended in "OSError: [Errno 39] Directory not empty"."""
    import errno

    from piga.diagnostics import report
    from piga.io.atomic import OutputExistsError

    def busy(src: object, dst: object) -> None:
        raise OSError(errno.ENOTEMPTY, "Directory not empty")

    monkeypatch.setattr(report, "_write_files", lambda *args, **kwargs: None)
    monkeypatch.setattr(report.os, "rename", busy)
    with pytest.raises(OutputExistsError, match="appeared while writing; pass --overwrite"):
        report.write_report(None, tmp_path / "g", "model", "data", "cmd")  # type: ignore[arg-type]
    assert _listing(tmp_path) == []


def test_a_strip_of_renders_that_overshoot_draws_without_matplotlibs_warnings(tmp_path: Path) -> None:
    import logging
    import warnings

    from piga.evaluation.plots import frame_strip

    frames = np.full((1, 2, 8, 8, 3), 0.5, np.float32)
    frames[0, 0, 0, 0] = (-0.01, 1.2, 0.5)  # a video-lstm render a little outside [0, 1]
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    logging.getLogger("matplotlib").addHandler(handler)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            frame_strip(frames)
    finally:
        logging.getLogger("matplotlib").removeHandler(handler)
    assert not [r for r in records if "Clipping" in r.getMessage()]


@pytest.mark.parametrize("kind", ["LA", "CMYK"])
def test_import_reads_gray_with_alpha_and_cmyk_frames(kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An opaque gray+alpha PNG was "expected a 2-D gray or RGB image"; a CMYK JPEG's K was read as an alpha."""
    from PIL import Image

    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(12):
        x = np.zeros((32, 32), np.uint8)
        x[i : i + 6, 8:14] = 220
        image = Image.fromarray(np.stack([x, np.full_like(x, 255)], -1), "LA") if kind == "LA" else \
            Image.fromarray(x).convert("CMYK")
        image.save(folder / f"f{i}.{'png' if kind == 'LA' else 'jpg'}")
    (tmp_path / "u.csv").write_text("0.5\n" * 12)
    code, _, err = run_in_process("piga-import", importer.main, str(folder), str(tmp_path / "u.csv"), "--dt", "0.05",
                                  "--steps", "4", "--image-size", "16", "--out", str(tmp_path / "x.h5"), capsys=capsys)
    assert code == 0, err
    with h5py.File(tmp_path / "x.h5") as f:
        assert f["frames"][0, 0].max() > 100  # the square, not a blank or a refusal


def test_a_frame_name_with_a_superscript_digit_sorts() -> None:
    from piga.data.importer import _natural_key

    names = [Path(n) for n in ("f10.png", "f3\u00b2.png", "f2.png")]
    assert [p.name for p in sorted(names, key=_natural_key)] == ["f2.png", "f3\u00b2.png", "f10.png"]


def test_a_path_too_long_for_its_temporary_name_is_refused_up_front(tmp_path: Path) -> None:
    """A path just under PATH_MAX failed at its write, through its longer temporary name: "[Errno 36] File name too
    long" with 4,000 characters of path (diagnose's, after its work)."""
    from piga.io.atomic import check_folder_target, check_writable_target

    parts, length = [], len(str(tmp_path))
    while length + 201 < 4080 - 100:
        parts.append("d" * 200)
        length += 201
    path = Path(tmp_path, *parts, "x" * (4080 - length - 1))  # 4080 bytes: a path the system takes
    assert len(os.fsencode(str(path))) == 4080
    with pytest.raises(ValueError, match="would pass the 4096 that the system takes for a path"):
        check_writable_target(path, overwrite=False)
    with pytest.raises(ValueError, match="and with the files in it"):
        check_folder_target(path)


def test_the_own_training_file_must_still_be_the_runs(tiny_data: Path, tmp_path: Path) -> None:
    """A run's data path is relative to where it trained; from another folder it named another file, whose effects
    a diagnosis then read as the run's own."""
    from piga.data.schema import fingerprint
    from piga.io.runs import training_data_path

    other = _variant(tiny_data, tmp_path / "other.h5", lambda f: f["actions"].__setitem__(..., -f["actions"][()]))
    own = {"data": {"path": str(tiny_data), "fingerprint": fingerprint(tiny_data)}}
    assert training_data_path(own) == str(tiny_data)
    assert training_data_path({"data": {**own["data"], "path": str(other)}}) is None
    assert training_data_path({"data": {"path": str(other)}}) == str(other)  # an old checkpoint keeps no fingerprint


def test_the_fingerprint_covers_every_frame_and_reads_a_kept_one_as_it_was_taken(tiny_data: Path,
                                                                                  tmp_path: Path) -> None:
    """Sequences after the first reversed in time kept the fingerprint (it hashed the actions, the split and the first
    sequence's frames), and a resumed training, a PlaNet-style resume and piga-diagnose --training-data took the
    edited file as the run's. A run of an earlier version kept such a fingerprint: it is compared by it still."""
    import shutil

    from piga.data.schema import FINGERPRINT_MARK, fingerprint, has_fingerprint
    from piga.io.runs import with_training_file

    edited = _variant(tiny_data, tmp_path / "edited.h5", lambda f: f["frames"].__setitem__(
        slice(5, None), f["frames"][5:][:, ::-1]))
    copy = shutil.copy(tiny_data, tmp_path / "copy.h5")
    kept = fingerprint(tiny_data)
    assert kept.startswith(FINGERPRINT_MARK) and fingerprint(copy) == kept and fingerprint(edited) != kept
    assert has_fingerprint(copy, kept) and not has_fingerprint(edited, kept) and not has_fingerprint(copy, None)
    earlier = fingerprint(tiny_data, legacy=True)  # as an earlier version kept it: 16 hex digits
    assert len(earlier) == 16 and not earlier.startswith(FINGERPRINT_MARK)
    assert has_fingerprint(copy, earlier) and has_fingerprint(edited, earlier)  # (what it could not tell apart)
    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(ValueError, match="is not the file .* was trained on"):
        with_training_file({"data": {"path": str(tiny_data), "fingerprint": kept}}, run, given=edited)
    assert with_training_file({"data": {"path": "gone.h5", "fingerprint": earlier}}, run, given=edited)["data"]["path"] \
        == str(edited)  # an earlier run's file, compared as it was


def test_train_resume_refuses_its_file_with_later_frames_edited(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The resume trained on, exit 3 (the fingerprint hashed the first sequence's frames only)."""
    edited = _variant(tiny_data, tmp_path / "edited.h5", lambda f: f["frames"].__setitem__(
        slice(5, None), f["frames"][5:][:, ::-1]))
    refused("piga-train-model", [str(edited), "--out", str(_run_copy(tiny_piga_run, tmp_path / "a")), "--resume",
                                 "--epochs", "2", "--quiet"], capsys, "continues on the file the run trained on")


def test_the_own_training_file_is_found_beside_a_moved_run_and_given_by_hand(tiny_data: Path, tmp_path: Path) -> None:
    """A run trained in another folder records its data path relative to that folder: from here the diagnosis found
    no own file and judged a gain against the nominal model's a (a dm_control model "gain 1.05" on its own system).
    The file is found through the folder the run recorded, or beside the run folder, or given by hand, each checked
    by content."""
    import shutil

    from piga.data.schema import fingerprint
    from piga.io.runs import training_data_path, with_training_file

    data = {"path": "elsewhere/tiny.h5", "fingerprint": fingerprint(tiny_data)}
    run = tmp_path / "runs" / "r"
    run.mkdir(parents=True)
    assert training_data_path(with_training_file({"data": data}, run)) is None  # nowhere to be found
    found = with_training_file({"data": {**data, "path": tiny_data.name, "folder": str(tiny_data.parent)}}, run)
    assert found["data"]["path"] == tiny_data.name and training_data_path(found) in (str(tiny_data), tiny_data.name)
    beside = shutil.copy(tiny_data, tmp_path / "runs" / "tiny.h5")
    assert training_data_path(with_training_file({"data": data}, run)) == str(beside)
    given = with_training_file({"data": {**data, "folder": "/elsewhere"}}, run, given=tiny_data)
    assert training_data_path(given) == str(tiny_data)
    other = _variant(tiny_data, tmp_path / "other.h5", lambda f: f["actions"].__setitem__(..., -f["actions"][()]))
    with pytest.raises(ValueError, match=r"other\.h5 is not the file .* was trained on \(its content differs"):
        with_training_file({"data": data}, run, given=other)
    with pytest.raises(ValueError, match="no such file"):
        with_training_file({"data": data}, run, given=tmp_path / "gone.h5")
    with pytest.raises(ValueError, match="is a folder: give the data file"):
        with_training_file({"data": data}, run, given=tmp_path)
    (tmp_path / "notes.txt").write_text("not data\n")
    with pytest.raises(ValueError, match=r"notes\.txt is not a piga data file \(HDF5"):
        with_training_file({"data": data}, run, given=tmp_path / "notes.txt")


@pytest.mark.parametrize("where", ["under-a-file", "/proc/piga-matplotlib"])
def test_a_folder_matplotlib_cannot_write_gets_a_temporary_one_quietly(where: str, tiny_data: Path,
                                                                      tmp_path: Path) -> None:
    """A read-only HOME (or MPLCONFIGDIR) gave two matplotlib warnings on stderr; so did a folder under /proc, which
    root may write as far as os.access says."""
    if where.startswith("/proc") and not Path("/proc/self").is_dir():
        pytest.skip("needs Linux's /proc")
    folder = str(tiny_data / "not-a-folder") if where == "under-a-file" else where  # never writable
    result = subprocess.run(["python", "-m", "piga.cli.show", str(tiny_data), "--out", str(tmp_path / "s.png")],
                            capture_output=True, text=True, env={**ENV, "MPLCONFIGDIR": folder}, timeout=120)
    assert result.returncode == 0 and result.stderr == "", result.stderr


def test_a_half_spring_too_short_for_its_test_sequences_says_longer(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """The advice was "use shorter sequences, a lower speed", which --half refuses and no flag sets, after "job sequence
    18 failed"; then "use longer sequences (--steps, now 20)", with no length that works (20 failed, 30 worked)."""
    import re

    real = collect.scene_config  # a --half scene draws up to 100,000 starts (7 s) before it gives up: 2,000 here
    monkeypatch.setattr(collect, "scene_config", lambda scene, **given: real(scene, **{"max_tries": 2000, **given}))
    line = refused("piga-collect", ["--system", "spring", "--half", "--sequences", "20", "--steps", "11", "--out",
                                    str(tmp_path / "h.h5"), "--quiet"], capsys,
                   "then reaches the bottom half within 11 frames", "use longer sequences (--steps, now 11; a start "
                   "drawn here reaches the bottom half with --steps ")
    # a larger image puts the bottom half further away: it was named too, and did not help
    assert "job" not in line and "--image-size" not in line and not (tmp_path / "h.h5").exists()
    steps = re.search(r"with --steps (\d+)\)", line)
    assert steps is not None and int(steps.group(1)) > 11, line


@pytest.mark.slow
@pytest.mark.parametrize("seed, steps", [(0, 11), (32045, 14), (32045, 20)])
def test_the_length_a_half_spring_is_told_works(seed: int, steps: int, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """With all its draws (100,000, about 9 s), the length that the refusal names collects the file (20 frames failed
    for seed 32045, and the refusal named no length)."""
    import re

    out = str(tmp_path / "h.h5")
    line = refused("piga-collect", ["--system", "spring", "--half", "--sequences", "20", "--steps", str(steps), "--out",
                                    out, "--seed", str(seed), "--quiet"], capsys, "a start drawn here reaches")
    named = re.search(r"with --steps (\d+)\)", line)
    assert named is not None, line
    assert collect.main(["--system", "spring", "--half", "--sequences", "20", "--steps", named.group(1), "--out", out,
                         "--seed", str(seed), "--quiet"]) == 0


@pytest.mark.parametrize("text, needle", [("1:1e308:1e-308", "gives more than 1000 values"),
                                          ("1:1.00000000001:1e-11", "its step repeats multipliers at the 10 decimals")])
def test_a_sweep_range_too_long_or_too_fine_is_refused(text: str, needle: str, tiny_piga_run: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """1:1e308:1e-308 was an internal error (OverflowError); a step below 1e-10 gave duplicate multipliers."""
    refused("piga-control", ["--model", str(tiny_piga_run), "--episodes", "1", "--steps", "20", "--sweep", text,
                             "--quiet"], capsys, needle)


@pytest.mark.parametrize("out", [".", ".."])
def test_control_refuses_a_folder_for_out(out: str, capsys: pytest.CaptureFixture[str]) -> None:
    """--out . was "PosixPath('.') has an empty name"; --out .. wrote the hidden files ./...json and ./...md."""
    refused("piga-control", ["--oracle", "--episodes", "1", "--steps", "20", "--out", out], capsys,
            "expected a file name, got the folder")


def test_the_table_gives_the_gravity_multiplier_as_the_command_line_does() -> None:
    from piga.evaluation.episodes import EpisodeSummary, summary_markdown

    fields = {f: 0.0 for f in EpisodeSummary.__dataclass_fields__ if f != "labels"}
    rows = [EpisodeSummary(**{**fields, "episodes": 1, "gravity_mult": m}) for m in (0.001, 1.001, 1.002)]
    cells = [line.split("|")[2].strip() for line in summary_markdown(rows).splitlines()[2:]]
    assert cells == ["0.001", "1.001", "1.002"]


def test_a_not_told_run_and_a_sac_run_are_named_so_in_their_outputs(tiny_piga_run: Path, baseline_runs: dict[str, Path],
                                                                     tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OUT.json of --not-told read as a told run's; a SAC or DrQ-v2 run was called "ddpg" (all are piga-baseline ddpg runs)."""
    from piga.control.jobs import agent_name

    out = tmp_path / "nt"
    code, stdout, err = run_in_process("piga-control", control.main, "--model", str(tiny_piga_run), "--episodes", "1",
                                       "--steps", "20", "--gravity-mult", "1.4", "--not-told", "--candidates", "8",
                                       "--iterations", "1", "--horizon", "2", "--quiet", "--out", str(out), capsys=capsys)
    assert code == 0, err
    assert json.loads(out.with_suffix(".json").read_text())["agent"] == f"piga (not told) ({tiny_piga_run})"
    assert f"piga (not told) ({tiny_piga_run}), gravity x1.4" in stdout
    run = _run_copy(baseline_runs["ddpg"], tmp_path / "sac", _edit_record(lambda r: r["ddpg"].__setitem__("algo", "sac")))
    assert agent_name("ddpg", str(run)) == "sac" and agent_name("ddpg", str(baseline_runs["ddpg"])) == "ddpg"
    assert agent_name("planet", str(baseline_runs["planet"])) == "planet"


@pytest.mark.parametrize("edit", [lambda m: m["open_loop"].__setitem__("context", float("inf")),
                                  lambda m: m["open_loop"].__setitem__("frame_mse", [])])
def test_an_edited_planet_metrics_record_tells_nothing_and_says_nothing(edit: Callable[[dict[str, Any]], None],
                                                                        baseline_runs: dict[str, Path], tmp_path: Path,
                                                                        recwarn: pytest.WarningsRecorder) -> None:
    """context: Infinity was an internal error (OverflowError); an empty list printed two numpy warnings."""
    from piga.cli.control import baseline_did_not_learn
    from piga.io.checkpoint import RunKind

    run = _run_copy(baseline_runs["planet"], tmp_path / "run")
    metrics = json.loads((run / "metrics.json").read_text())
    edit(metrics)
    (run / "metrics.json").write_text(json.dumps(metrics))
    assert baseline_did_not_learn(run, RunKind.PLANET) is None
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


@pytest.mark.slow
def test_resume_takes_a_default_the_run_was_started_at(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--resume --encoder-precision auto on a run started without it was "drop --encoder-precision" (the record holds
    the precision resolved); the run was started at auto all the same."""
    out = str(tmp_path / "drq")
    argv = ["ddpg", "--algo", "drqv2", "--obs", "pixels", "--out", out, "--steps", "200", "--eval-every", "200",
            "--eval-episodes", "1", "--learning-starts", "190", "--buffer-size", "1000", "--batch-size", "8", "--threads",
            "1", "--quiet"]  # (10 updates)
    assert_sb3_run_finished(*run_in_process("piga-baseline", baseline.main, *argv, capsys=capsys)[::2])
    code, _, err = run_in_process("piga-baseline", baseline.main, *argv, "--resume", "--encoder-precision", "auto",
                                  capsys=capsys)
    assert "recipe" not in err, err
    assert_sb3_run_finished(code, err)


def test_a_goal_image_of_another_shape_is_warned_of(tiny_piga_run: Path, tmp_path: Path) -> None:
    """A 33x47 copy of a 15° render was read as 10.66° without a word: only its centre square is read."""
    import cv2

    from piga.control.goal import goal_from_image, render_goal_image
    from piga.io.runs import load_model

    square = tmp_path / "g15.png"
    cv2.imwrite(str(square), render_goal_image(15.0)[..., ::-1])  # (RGB to cv2's BGR)
    squashed = tmp_path / "squashed.png"
    cv2.imwrite(str(squashed), cv2.resize(cv2.imread(str(square)), (33, 47), interpolation=cv2.INTER_AREA))
    model, checkpoint = load_model(tiny_piga_run)
    warned = [w for w in goal_from_image(model, checkpoint, squashed).warnings if "not square" in w]
    assert warned == [f"{squashed} is 33x47, not square: its centre 33x33 square is read, as the env's square frame "
                      "would show it; a picture resized to another shape reads another angle"]
    assert not any("not square" in w for w in goal_from_image(model, checkpoint, square).warnings)
    tiny = tmp_path / "tiny.png"  # a 16 px copy: "not a picture of the pendulum scene (mismatch 0.51 ...)", no why
    cv2.imwrite(str(tiny), cv2.resize(cv2.imread(str(square)), (8, 8), interpolation=cv2.INTER_AREA))
    from piga.control.goal import NotTheSceneError

    with pytest.raises(NotTheSceneError, match="at 8x8 it is enlarged to the model's 64x64 frames, which blurs it: "
                                               "give a picture of 64x64 or larger$"):
        goal_from_image(model, checkpoint, tiny)


@pytest.mark.slow
def test_train_model_resume_takes_auto_loading_the_run_was_started_at(tiny_data: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """--resume --data-loading auto on a run started without it was "drop --data-loading" (the checkpoint holds the
    loading that auto resolved to); another value than the run's is still refused."""
    from piga.cli import train as train_cli

    argv = [str(tiny_data), "--out", str(tmp_path / "run"), "--batch-size", "4", "--threads", "1", "--quiet"]
    code, _, err = run_in_process("piga-train-model", train_cli.main, *argv, "--epochs", "1", capsys=capsys)
    assert code in (0, 1, 3) and "Traceback" not in err, err
    code, _, err = run_in_process("piga-train-model", train_cli.main, *argv, "--epochs", "2", "--resume",
                                  "--data-loading", "auto", capsys=capsys)
    assert code in (0, 1, 3) and "recipe" not in err, err
    refused("piga-train-model", [*argv, "--epochs", "3", "--resume", "--data-loading", "stream"], capsys,
            "--resume keeps the run's recipe; drop --data-loading")


@pytest.mark.slow
def test_control_writes_its_outputs_for_a_non_ascii_model_under_a_c_locale(tiny_piga_run: Path, tmp_path: Path) -> None:
    """Under LC_ALL=C with PYTHONUTF8=0 the model's name held lone surrogates, and OUT.md failed to encode after the
    episodes ("surrogates not allowed")."""
    run = Path(shutil.copytree(tiny_piga_run, tmp_path / "d\u00e9 mo"))
    env = {**ENV, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"}
    result = subprocess.run(["python", "-m", "piga.cli.control", "--model", str(run), "--episodes", "1", "--steps", "20",
                             "--candidates", "8", "--iterations", "1", "--horizon", "2", "--quiet", "--out",
                             str(tmp_path / "o")], capture_output=True, env=env, timeout=180)
    assert result.returncode == 0, result.stderr
    assert "piga (d\u00e9 mo" in (tmp_path / "o.md").read_text(encoding="utf-8").replace(str(tmp_path) + "/", "")


@pytest.mark.parametrize("dt, told", [(0.04, True), (0.03, False)])
def test_a_model_of_a_rate_dmc_steps_is_pointed_at_dmc(dt: float, told: bool, tiny_piga_run: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A model of DMC's frames (0.04 s apart) given to the pixel pendulum was refused without naming the env it fits."""
    import torch

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["model_config"]["dt"] = dt
    torch.save(checkpoint, run / "checkpoint.pt")
    line = refused("piga-control", ["--model", str(run), "--quiet", "--episodes", "1", "--steps", "20"], capsys,
                   f"trained on frames {dt:g} s apart")
    assert ("--env piga/DMCPendulum-v0" in line) == told, line
    if told:  # a 32 px DMC model too: its rate names the env before its size (whose advice pointed at piga-collect)
        from types import SimpleNamespace

        from piga.cli.common import PigaError

        small = SimpleNamespace(config=SimpleNamespace(system="pendulum", image_size=32, channels=1, dt=dt))
        with pytest.raises(PigaError, match="--env piga/DMCPendulum-v0") as refusal:
            control.check_pendulum_model(small, str(run))
        assert "piga-collect --image-size" not in str(refusal.value)


# ---------------------------------------------------------------------------------------------
# Environment variables, seeds, goal images, data a baseline cannot use
# ---------------------------------------------------------------------------------------------


@needs_dmc
@pytest.mark.parametrize("renderer", ["glfw", "osmesa"])
@pytest.mark.slow
def test_a_renderer_that_cannot_start_here_is_one_line(renderer: str, tmp_path: Path) -> None:
    """MUJOCO_GL=glfw without a display was exit 70 after glfw's warnings and a half-made context's complaint
    (16 lines); osmesa without its library was exit 70 (PyOpenGL's AttributeError)."""
    result = subprocess.run(["python", "-m", "piga.cli.control", "--oracle", "--env", "piga/DMCPendulum-v0", "--episodes",
                             "1", "--quiet", "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=180,
                            env={**ENV, "MUJOCO_GL": renderer, "DISPLAY": "", "OMP_NUM_THREADS": "1"})
    assert result.returncode == 1, result.stderr
    line = assert_one_line(1, result.stderr, f"MUJOCO_GL='{renderer}'", "unset MUJOCO_GL")
    assert "Traceback" not in line and not list(tmp_path.iterdir())


@pytest.mark.parametrize("variables", [{"OMP_NUM_THREADS": "0", "MPLBACKEND": "bogus"}, {"OMP_NUM_THREADS": "abc"}])
@pytest.mark.slow
def test_a_variable_a_library_cannot_use_changes_nothing(variables: dict[str, str], tiny_data: Path,
                                                         tmp_path: Path) -> None:
    """OMP_NUM_THREADS=0 printed libgomp's "Invalid value" on stderr; MPLBACKEND=bogus failed at the first figure,
    after the work (a sweep's outputs lost, a PlaNet-style run without metrics that blocked its rerun). (Two variables
    in one run: either one's failure fails it.)"""
    for argv in (["piga.cli.show", str(tiny_data), "--out", str(tmp_path / "s.png")],  # a figure
                 ["piga.cli.control", "--write-goal-image", str(tmp_path / "g.png"), "--angle", "15"]):  # torch's threads
        result = subprocess.run(["python", "-m", *argv], capture_output=True, text=True, timeout=180,
                                env={**ENV, **variables})
        assert result.returncode == 0 and not result.stderr, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.png", "s.png"]


@pytest.mark.parametrize("seed", [str(2**32), str(2**63 - 1)])
@pytest.mark.slow
def test_every_seed_the_parser_takes_runs(seed: str, tiny_data: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Seeds from 2^32 to 2^63 - 1 passed the parser, then failed in numpy's global seeding ("Seed must be between 0
    and 2**32 - 1") after the plan was printed: piga-train-model, piga-baseline ddpg and piga-demo."""
    from piga.data.schema import legacy_seed

    assert legacy_seed(7) == 7 and 0 <= legacy_seed(int(seed)) < 2**32 and legacy_seed(int(seed)) == legacy_seed(int(seed))
    code, _, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(tmp_path / "t"), "--seed",
                                  seed, "--budget-steps", "4", "--batch-size", "4", "--threads", "1", "--quiet", capsys=capsys)
    assert code in (0, 3) and "Seed must be" not in err, err  # 3: too short to judge, said in its warning
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(tmp_path / "d"),
                                  "--seed", seed, *TINY_DDPG, capsys=capsys)
    assert_sb3_run_finished(code, err)


@pytest.fixture(scope="module")
def transparent_images(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Pictures whose transparency is a colour key or a palette entry (a PNG's tRNS, a GIF's), not an alpha channel."""
    from PIL import Image

    root = tmp_path_factory.mktemp("goals")
    gray = np.full((40, 40), 200, np.uint8)
    gray[10:30, 18:22] = 30  # a pole; the rest is the key colour
    made = {}
    for name, image, info in (("gray.png", Image.fromarray(gray), {"transparency": 200}),
                              ("rgb.png", Image.fromarray(np.repeat(gray[..., None], 3, -1)), {"transparency": (200, 200, 200)}),
                              ("palette.png", Image.fromarray(gray).convert("P"), {"transparency": 200}),
                              ("palette.gif", Image.fromarray(gray).convert("P"), {"transparency": 200})):
        image.save(root / name, **info)
        made[name] = root / name
    return made


@pytest.mark.parametrize("name", ["gray.png", "rgb.png", "palette.png", "palette.gif"])
def test_a_transparent_colour_is_transparency(name: str, transparent_images: dict[str, Path]) -> None:
    """The docs say a goal image with transparent pixels is refused; one whose transparency was a tRNS entry was read
    as opaque, and its hidden pixels taken as the scene."""
    from piga.data.scene import read_image, scene_to_gray

    with pytest.raises(ValueError, match="transparent"):
        scene_to_gray(read_image(transparent_images[name]), 32)


def test_a_huge_image_is_read_without_pillows_warning(tmp_path: Path, recwarn: pytest.WarningsRecorder,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """An image between Pillow's warning and error limits printed its DecompressionBombWarning (two more lines)."""
    from PIL import Image

    from piga.data.scene import read_image

    Image.fromarray(np.zeros((60, 60), np.uint8)).save(tmp_path / "big.png")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 3000)  # 3600 pixels: above the warning, below twice it
    assert read_image(tmp_path / "big.png").shape == (60, 60)
    assert not [w for w in recwarn if "DecompressionBomb" in w.category.__name__]


def test_a_device_is_not_called_missing(capsys: pytest.CaptureFixture[str]) -> None:
    """--goal-image /dev/zero said "no such image file"."""
    from piga.data.scene import read_image

    with pytest.raises(ValueError, match="not a regular file"):
        read_image("/dev/zero")


@pytest.mark.parametrize("variant", ["labelled_dmc", "labelled_spring"])
def test_planet_refuses_before_training_a_file_no_command_could_use_it_on(variant: str, files: dict[str, Path],
                                                                          tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """PlaNet-style training on dm_control's frames ran (1.8 h at the defaults) and piga-control refused the run after;
    a spring scene's file was said to lack the /rewards that piga-collect writes."""
    out = tmp_path / "p"
    refused("piga-baseline", ["planet", str(files[variant]), "--out", str(out), *TINY_PLANET], capsys,
            "the PlaNet-style agent is trained on and controls piga/PixelPendulum-v0")
    assert not out.exists()


def test_drqv2_exploration_never_rises(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """--algo drqv2 --noise-std 0.05 was a schedule that rose to 0.1 without a word."""
    refused("piga-baseline", ["ddpg", "--algo", "drqv2", "--obs", "pixels", "--noise-std", "0.05", "--out",
                              str(tmp_path / "d"), "--quiet"], capsys, "--noise-std (0.05) is below", "at least 0.1")


@needs_dmc
def test_dmc_control_runs_what_it_is_asked_for(capsys: pytest.CaptureFixture[str]) -> None:
    """--env piga/DMCPendulum-v0 with neither --model nor --oracle ran the oracle; the pixel env refuses that."""
    refused("piga-control", ["--env", "piga/DMCPendulum-v0", "--episodes", "1", "--quiet"], capsys, "give --model RUN_DIR")


def test_a_mass_below_the_range_is_not_explained_by_the_heavy_side() -> None:
    from envs.dmc import DMCPendulumConfig

    with pytest.raises(ValueError) as light:
        DMCPendulumConfig(mass=1e-4)
    with pytest.raises(ValueError) as heavy:
        DMCPendulumConfig(mass=1e7)
    assert "heavier" not in str(light.value) and "heavier" in str(heavy.value)


def test_a_parameter_the_file_gives_no_true_value_for_is_still_printed() -> None:
    """A file whose params named g only printed "learned: g=1.0539 (true 10, ...)", leaving out the learned a."""
    from piga.evaluation.evaluate import summary_line

    line = summary_line({"parameters": {"g": 1.0539, "a": 0.3037, "offset": 0.0}, "fixed_parameters": {},
                         "parameter_errors": {"g": {"learned": 1.0539, "true": 10.0, "relative_error": 0.8946}}})
    assert line == "g=1.0539 (true 10, error 89.46%), a=0.3037"


def test_a_huge_actuation_gain_draws_a_bounded_arrow() -> None:
    """--actuation-gain 1000 was exit 70: Gymnasium's arrow, scaled by the torque, ran pygame out of memory."""
    from envs.pendulum import ARROW_MAX_TORQUE, make_pixel_pendulum

    env = make_pixel_pendulum(image_size=16, actuation_gain=1000.0)
    env.reset(seed=0)
    frame, *_ = env.step(np.array([2.0], np.float32))
    assert frame.shape[-2:] == (16, 16) and abs(env.unwrapped.last_u) == 2000.0 > ARROW_MAX_TORQUE  # applied in full
    env.close()


def test_a_file_open_for_writing_elsewhere_is_said_to_be(tiny_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A file another process held open for writing was "not a readable HDF5 file (BlockingIOError)"."""
    locked = tmp_path / "locked.h5"
    shutil.copyfile(tiny_data, locked)
    holder = subprocess.Popen(["python", "-c", "import h5py, sys, time; f = h5py.File(sys.argv[1], 'a'); print('open', "
                               "flush=True); time.sleep(60)", str(locked)], stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "open"
        refused("piga-show", [str(locked), "--out", str(tmp_path / "s.png")], capsys, "another process has it open for "
                "writing", "wait for that process to end")
    finally:
        holder.kill()
        holder.wait()
    assert not (tmp_path / "s.png").exists()


def test_a_second_control_given_the_same_out_is_refused_before_its_episodes(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Two controls given one --out both ran their episodes; the second was refused only at its write, its work lost."""
    stem = tmp_path / "o"
    holder = subprocess.Popen(["python", "-c", "import sys, time; from piga.io.lock import lock_run_folder; "
                               "lock_run_folder(sys.argv[1]); print('held', flush=True); time.sleep(60)", str(stem)],
                              stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        refused("piga-control", ["--oracle", "--episodes", "1", "--steps", "20", "--quiet", "--out", str(stem)], capsys,
                f"--out {stem} is in use by another piga command (PID {holder.pid})")
    finally:
        holder.kill()
        holder.wait()
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("script, module, taken", [("piga-collect", "", "piga-collect"), ("notebook.py", "", ""),
                                                   ("-m", "piga.cli.importer", "piga-import"),
                                                   ("-m", "piga.cli.train", "piga-train-model")])
def test_ctrl_c_while_a_command_loads_is_one_line(script: str, module: str, taken: str) -> None:
    """Ctrl-C in a command's first ~0.25 s, inside its imports, printed Python's KeyboardInterrupt traceback (17 to
    37 lines). A program that only imports piga keeps its own Ctrl-C. ``python -m piga.cli.X`` is named as its
    command (it was "piga")."""
    code = (f"import os, signal, sys, time; sys.argv[0] = {script!r}; "
            f"sys.orig_argv = [sys.executable, '-m', {module!r}] if {module!r} else sys.orig_argv; import piga.cli; "
            "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler, flush=True); "
            "os.kill(os.getpid(), signal.SIGINT); time.sleep(30)")
    result = subprocess.run(["python", "-c", code], capture_output=True, text=True, timeout=60, env=ENV)
    if taken:
        assert result.stdout.strip() == "False" and result.returncode == 130, result.stderr
        assert result.stderr == f"{taken}: interrupted; nothing was written\n"
    else:
        assert result.stdout.strip() == "True" and "KeyboardInterrupt" in result.stderr


def test_ctrl_c_inside_an_import_waits_for_the_import(tmp_path: Path) -> None:
    """A Ctrl-C that landed inside a library's import (torch's runs Python code from C++) aborted the command
    ("terminate called after throwing an instance of 'pybind11::error_already_set'"), or ended it by SIGINT (exit -2)
    after its own line. It is raised once the import is over: the module below is imported whole."""
    (tmp_path / "slow_library.py").write_text(
        "import os, signal, time\nos.kill(os.getpid(), signal.SIGINT)\n"
        "exec('x = 1')\ntime.sleep(0.3)\nopen(os.environ['MARK'], 'w').close()\n", encoding="utf-8")
    code = ("import os, sys, time; sys.argv[0] = 'piga-x'; from piga.cli.common import run_cli\n"
            "def main(argv):\n    import slow_library\n    time.sleep(30)\n    open(os.environ['MARK'] + '.slept', 'w').close()\n"
            "run_cli('piga-x', main)")
    mark = tmp_path / "imported"
    result = subprocess.run(["python", "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                            env={**ENV, "MARK": str(mark), "PYTHONPATH": f"{tmp_path}{os.pathsep}{ENV.get('PYTHONPATH', '')}"})
    assert result.returncode == 130 and result.stderr == "piga-x: interrupted; nothing was written\n", result.stderr
    assert mark.exists() and not (tmp_path / "imported.slept").exists()  # raised after the import, not after the sleep


def test_a_signal_while_python_exits_keeps_the_commands_exit_code(tmp_path: Path) -> None:
    """Python sets the signals' handlers back to the default as it shuts down: a Ctrl-C then killed a command that
    had already printed its error (exit -2 for its 1). Here one lands as the script's globals are torn down."""
    script = tmp_path / "late.py"
    script.write_text("import os, signal, sys\nsys.argv[0] = 'piga-x'\nfrom piga.cli.common import PigaError, run_cli\n"
                      "class Late:\n    def __del__(self):\n        os.kill(os.getpid(), signal.SIGINT)\n"
                      "late = Late()\ndef main(argv):\n    raise PigaError('bad input')\nrun_cli('piga-x', main)\n",
                      encoding="utf-8")
    result = subprocess.run(["python", str(script)], capture_output=True, text=True, timeout=60, env=ENV)
    assert result.returncode == 1 and result.stderr == "piga-x: error: bad input\n", (result.returncode, result.stderr)


def test_a_signal_after_the_work_says_the_outputs_are_complete() -> None:
    """A SIGTERM after piga-diagnose's report was complete ended it with exit 143 and no word: the user took the run
    for lost, and the rerun was refused ("report.md exists")."""
    code = ("import os, signal, time; from piga.cli.common import _exit_quietly_on_late_signals as late; "
            "late('piga-x: interrupted after it finished its work; its outputs are complete'); "
            "os.kill(os.getpid(), signal.SIGTERM); time.sleep(30)")
    _ends_by_sigterm_saying_complete(code)


#: The line of a command interrupted once its outputs are complete.
COMPLETE = "piga-x: interrupted after it finished its work; its outputs are complete\n"


def _ends_by_sigterm_saying_complete(code: str) -> None:
    """Runs ``code`` (which sends itself SIGTERM) in its own interpreter: exit 143 and :data:`COMPLETE` alone."""
    result = subprocess.run(["python", "-c", code], capture_output=True, text=True, timeout=60, env=ENV)
    assert result.returncode == 143
    assert result.stderr == COMPLETE


def test_a_signal_between_the_last_write_and_the_return_says_the_outputs_are_complete(
        capsys: pytest.CaptureFixture[str]) -> None:
    """piga-control interrupted after it had written its --out set, before it returned, said "nothing was written"
    beside the complete set. A command calls work_finished() once its outputs are complete."""
    code = ("import os, signal, time; from piga.cli.common import run_cli, work_finished\n"
            "def main(argv):\n    work_finished(); os.kill(os.getpid(), signal.SIGTERM); time.sleep(30)\n"
            "run_cli('piga-x', main)\n")
    _ends_by_sigterm_saying_complete(code)

    def main(argv: Sequence[str] | None) -> int:  # in a caller's process (a test, a notebook): the same line
        from piga.cli.common import work_finished

        work_finished()
        raise KeyboardInterrupt

    code_, _, err = run_in_process("piga-x", main, capsys=capsys)
    assert code_ == 130 and err == COMPLETE
    code_, _, err = run_in_process("piga-x", lambda argv: (_ for _ in ()).throw(KeyboardInterrupt), capsys=capsys)
    assert err == "piga-x: interrupted; nothing was written\n"  # the next command starts unfinished


def test_the_readers_refuse_a_limit_or_window_that_is_no_count(tiny_data: Path) -> None:
    """load_states(path, "test", -1) sliced from the end (the other readers refused it); SequenceWindows(window="14")
    was "'<' not supported between instances of 'str' and 'int'", naming no argument."""
    import piga

    with pytest.raises(ValueError, match="limit must be None"):
        piga.load_states(tiny_data, "test", -1)
    for given in ({"window": "14"}, {"window": None}, {"window": 4, "stride": "2"}, {"window": 4, "stride": 1.0}):
        with pytest.raises(TypeError, match=f"{'stride' if 'stride' in given else 'window'} must be an integer"):
            piga.SequenceWindows(tiny_data, "train", **given)


@pytest.mark.parametrize("names", [("f7.png", "f07.png"), ("f7.png", "f7.jpg")])
def test_two_files_of_one_frame_number_are_refused(names: tuple[str, str], tmp_path: Path) -> None:
    """f7.png beside f07.png were both imported, one of them at a guessed place in the timeline."""
    from PIL import Image

    from piga.data.importer import frame_files

    for i, name in enumerate(("f1.png", "f2.png", *names)):
        Image.fromarray(np.full((8, 8), 40 * i, np.uint8)).save(tmp_path / name)
    with pytest.raises(ValueError, match="are the same frame in name order"):
        frame_files(tmp_path)


def test_overwrite_is_a_yes_or_no(tiny_data: Path, tmp_path: Path) -> None:
    """piga.collect(config, path, overwrite="no") replaced the existing file: a string is truthy."""
    import piga

    out = tmp_path / "x.h5"
    shutil.copyfile(tiny_data, out)
    with pytest.raises(TypeError, match="overwrite must be True or False"):
        piga.collect(piga.CollectConfig(sequences=4, steps=4), out, overwrite="no")
    assert out.read_bytes() == tiny_data.read_bytes()


@pytest.mark.parametrize("argv, needle", [
    (["--episodes", "10000", "--steps", "100000"], "--episodes 10000 x --steps 100000 = 1,000,000,000 control steps"),
    (["--episodes", "40", "--steps", "50000", "--candidates", "100000", "--horizon", "20", "--iterations", "5"],
     "2e+13 imagined model steps"),
    (["--sweep", "0.5:1.5:0.1", "--episodes", "10000", "--steps", "200"], "22 runs (--sweep's multipliers x 2 agents)"),
])
def test_control_that_would_plan_for_days_is_refused_up_front(argv: list[str], needle: str, tiny_piga_run: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Each option within its own cap, 10,000 episodes of 100,000 steps started without a word (two weeks)."""
    refused("piga-control", ["--model", str(tiny_piga_run), "--quiet", *argv], capsys, needle)


def test_a_folder_removed_while_a_command_writes_in_it_is_said_in_words(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A run folder removed mid-run ended in "[Errno 2] No such file or directory: b'run/tensorboard/...'"."""
    def main(argv: Sequence[str] | None) -> int:
        open(os.fsencode(tmp_path / "gone" / "events.out"), "wb")  # the folder is not there any more
        return 0

    code = _exit_code_of(main, capsys)
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err
    assert f"{tmp_path / 'gone' / 'events.out'}: no such file or folder (was a folder the command writes in removed" in err


def _exit_code_of(main: Callable[[Sequence[str] | None], int], capsys: pytest.CaptureFixture[str]) -> int:
    from piga.cli.common import run_cli

    with pytest.raises(SystemExit) as info:
        run_cli("piga-x", main, [])
    return int(info.value.code or 0)


def test_a_title_in_a_script_the_font_lacks_warns_nothing(tmp_path: Path) -> None:
    """piga-show on "ñ日本.h5" printed matplotlib's two-line "Glyph ... missing from font(s)" warning per glyph."""
    import warnings

    import matplotlib.pyplot as plt

    from piga.evaluation.plots import save_figure

    fig = plt.figure()
    fig.suptitle("ñ日本.h5")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        save_figure(fig, tmp_path / "strip.png")
    assert [str(w.message) for w in caught] == [] and (tmp_path / "strip.png").exists()


@pytest.mark.skipif(not Path("/proc/self").is_dir() or shutil.disk_usage("/proc").total != 0, reason="needs Linux's /proc")
def test_an_out_on_a_file_system_without_storage_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--out /proc/x.h5 was "needs about 128.4 KiB of disk, but /proc has 0 B free; ask for less", for 1 sequence."""
    refused("piga-collect", ["--out", "/proc/x.h5", "--sequences", "1", "--steps", "2", "--quiet", "--workers", "1"],
            capsys, "cannot be written under /proc: it is on a file system that stores no files")


@pytest.mark.parametrize("stems, gap", [
    (["f1", "f2", "f4", "f5"], "jump from 2 (f2.png) to 4 (f4.png), where the others step by 1"),
    (["cam2_0010", "cam2_0011", "cam2_0012", "cam2_0020"], "jump from 12 (cam2_0012.png) to 20"),
    (["f0", "f5", "f10", "f15"], None),  # every 5th frame: evenly spaced
    (["a1", "b2", "c4"], None),  # names that differ beside the number: no frame number to read
    (["f1", "f3"], None),  # two frames: no usual step
])
def test_a_gap_in_the_frame_numbers_is_refused(stems: list[str], gap: str | None, tmp_path: Path) -> None:
    """f1 f2 f4 was imported as three frames --dt apart: the missing frame made one step twice as long."""
    from PIL import Image

    from piga.data.importer import frame_files

    for i, stem in enumerate(stems):
        Image.fromarray(np.full((8, 8), 40 * i, np.uint8)).save(tmp_path / f"{stem}.png")
    if gap is None:
        assert [p.stem for p in frame_files(tmp_path)] == stems
    else:
        with pytest.raises(ValueError, match=re.escape(gap)):
            frame_files(tmp_path)


@needs_dmc
def test_a_scene_model_on_the_dmc_env_is_refused_for_its_system(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A spring model on --env piga/DMCPendulum-v0 was told to give --env-option action_repeat=15 (its frames' rate);
    doing so, it was then refused for its system."""
    from types import SimpleNamespace

    import piga.io.checkpoint
    import piga.io.runs
    from piga.io.checkpoint import RunKind

    monkeypatch.setattr(piga.io.checkpoint, "checked_run_kind", lambda run: RunKind.PIGA)
    monkeypatch.setattr(piga.io.runs, "load_model",
                        lambda run: (SimpleNamespace(config=SimpleNamespace(system="spring", dt=0.3)), {}))
    (tmp_path / "run").mkdir()
    refused("piga-control", ["--model", str(tmp_path / "run"), "--env", "piga/DMCPendulum-v0", "--episodes", "1"],
            capsys, "a spring model cannot control the pendulum")


def test_diagnose_names_a_scene_file_before_its_length(tiny_piga_run: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A 12-frame spring file was first "too short to diagnose ... piga-collect --steps 13"; recollected, it was then
    refused as spring data."""
    data = tmp_path / "spring.h5"
    assert collect.main(["--system", "spring", "--sequences", "4", "--steps", "12", "--split", "2,1,1", "--out", str(data), "--quiet"]) == 0
    refused("piga-diagnose", ["--model", str(tiny_piga_run), "--data", str(data), "--out", str(tmp_path / "rep")],
            capsys, "piga-diagnose is for pendulum data; this file holds spring data")


def test_a_digits_spring_file_is_named_by_its_scene(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A digits-spring file (system "spring", scene "digits-spring") was called "spring" by the commands that refuse
    it."""
    pytest.importorskip("sklearn", reason="the digits need the 'scenes' extra (scikit-learn)")
    data = tmp_path / "digits.h5"
    assert collect.main(["--system", "digits-spring", "--sequences", "4", "--steps", "12", "--split", "2,1,1", "--out",
                         str(data), "--seed", "1", "--quiet"]) == 0
    refused("piga-baseline", ["planet", str(data), "--out", str(tmp_path / "bp"), "--quiet"], capsys,
            "this file is digits-spring")


def test_diagnose_env_on_a_model_of_another_rate_says_drop_env(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A DMC model (frames 0.04 s apart) with --env was sent to "--env piga/DMCPendulum-v0", control's advice, which
    diagnose's --env (effects) refuses."""
    from dataclasses import replace as swap
    from types import SimpleNamespace

    import piga.io.runs

    real = piga.io.runs.load_model

    def dmc_rate(run: Any, **kwargs: Any) -> Any:
        model, checkpoint = real(run, **kwargs)
        return SimpleNamespace(config=swap(model.config, dt=0.04)), checkpoint

    monkeypatch.setattr(piga.io.runs, "load_model", dmc_rate)
    line = refused("piga-diagnose", ["--model", str(tiny_piga_run), "--data", str(tiny_data), "--out",
                                     str(tmp_path / "rep"), "--env", "none"], capsys,
                   "--env runs MPC episodes on Gymnasium's pixel pendulum", "drop --env")
    assert "DMCPendulum" not in line


def test_resume_takes_the_seed_a_retried_run_was_started_with(tiny_piga_run: Path, tiny_data: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A scene run started with the default seed 0 and retried up to seed 3: "--resume --seed 0" was refused ("drop
    --seed"), while "--seed 3", which the user never gave, was taken."""
    import torch

    def retried(run: Path) -> None:  # as three object-check retries leave it
        checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
        checkpoint["train_config"]["seed"] = 3
        torch.save(checkpoint, run / "checkpoint.pt")
        (run / "config.json").write_text(json.dumps({"command": f"piga-train-model {tiny_data} --out {run}",
                                                     "retried_seeds": [0, 1, 2]}))

    run = _run_copy(tiny_piga_run, tmp_path / "run", retried)
    refused("piga-train-model", [str(tiny_data), "--out", str(run), "--resume", "--seed", "5", "--quiet"], capsys,
            "--resume keeps the run's recipe; drop --seed")
    code, _, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), "--resume", "--seed",
                                  "0", "--quiet", capsys=capsys)
    assert "drop --seed" not in err and code in (0, 3), err


@pytest.mark.parametrize("option, needle", [
    ("image_size=32", "--env-option 'image_size=32': the frame side is piga-collect's own option: give --image-size"),
    ("episode_length=3", "give --steps"),
    ("frame_stack=2", "a file stores one frame per step"),
])
def test_an_env_option_that_collect_sets_itself_names_its_option(option: str, needle: str, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """--env-option image_size=32 was "--env-option --image-size: unknown for piga/DMCPendulum-v0", naming the key as
    a flag, and not saying that --image-size itself sets it."""
    refused("piga-collect", ["--env", "piga/DMCPendulum-v0", "--env-option", option, "--out", str(tmp_path / "x.h5")],
            capsys, needle)
    assert _listing(tmp_path) == []


def test_a_video_the_memory_cannot_hold_is_refused_before_its_episode(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """--steps 15000 --video under an 8 GB limit played its 2.4-minute episode, then failed "out of memory (an array
    of 640.0 KiB did not fit)": the frames are held whole until they are encoded."""
    import piga.io.resources
    from piga.evaluation.video import check_video_room
    from piga.io.resources import ResourceError

    monkeypatch.setattr(piga.io.resources, "available_memory", lambda: 2 * 1024**3)
    check_video_room(tmp_path / "v.mp4", 200)
    with pytest.raises(ResourceError, match=r"the video v.mp4 \(15,000 frames, held whole until encoded\) needs about "
                                            r".* give fewer --steps, or drop --video"):
        check_video_room(tmp_path / "v.mp4", 15000)


@pytest.mark.parametrize("argv, needle", [
    # "lower --eval-every or raise --steps", where --eval-every was at its least already
    (["--steps", "100", "--eval-every", "200"], "--steps (100) is less than one episode of 200 steps"),
    (["--steps", "200", "--eval-every", "200", "--learning-starts", "10000"],
     "--learning-starts (10000) is not below --steps (200)"),  # it said "raise steps"
])
def test_a_ddpg_budget_below_one_evaluation_names_what_to_give(argv: list[str], needle: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *argv], capsys, needle)
    assert _listing(tmp_path) == []


def test_a_disk_that_fills_after_the_first_checkpoint_names_the_resume(tiny_data: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str],
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The disk filling in the middle of training said "free some space ... and run the command again", and the same
    command was then refused: "already holds a run". The line names the checkpoint kept and --resume, which works."""
    import errno

    import piga.training.train

    real = piga.training.train.train

    def full_after_its_first_checkpoint(*args: Any, on_epoch: Any = None, **kwargs: Any) -> Any:
        def hook(state: Any, model: Any) -> None:
            on_epoch(state, model)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "run" / "events"))

        return real(*args, on_epoch=hook, **kwargs)

    argv = [str(tiny_data), "--out", str(tmp_path / "run"), "--epochs", "2", "--batch-size", "16", "--quiet"]
    with monkeypatch.context() as patch:
        patch.setattr(piga.training.train, "train", full_after_its_first_checkpoint)
        code, _, err = run_in_process("piga-train-model", train.main, *argv, capsys=capsys)
    assert_one_line(code, err, "the disk is full (no space left on device)", "checkpoint.pt holds epoch 1: free some "
                    "space and continue with --resume")
    code, _, err = run_in_process("piga-train-model", train.main, *argv, "--resume", capsys=capsys)
    assert code in (0, 3), err


@pytest.mark.parametrize("how, epoch", [(["--resume", "--epochs", "3"], 2), (["--overwrite", "--epochs", "2", "--batch-size", "16"], 1)])
def test_an_interrupted_resume_leaves_no_report_of_the_older_state(how: list[str], epoch: int, tiny_piga_run: Path,
                                                                    tiny_data: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str],
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A finished run resumed with more epochs and interrupted kept metrics.json and its figures (10 epochs, g 1.7, not
    converged) beside a checkpoint of epoch 24 (g 10.07): piga-diagnose judged the newer model by the older report.
    An interrupted --overwrite did the same (and piga-control trusted the replaced run's convergence)."""
    import piga.training.train

    real = piga.training.train.train

    def interrupted_after_its_first_checkpoint(*args: Any, on_epoch: Any = None, **kwargs: Any) -> Any:
        def hook(state: Any, model: Any) -> None:
            on_epoch(state, model)
            raise KeyboardInterrupt

        return real(*args, on_epoch=hook, **kwargs)

    run = _run_copy(tiny_piga_run, tmp_path / "run")
    assert (run / "metrics.json").exists()
    monkeypatch.setattr(piga.training.train, "train", interrupted_after_its_first_checkpoint)
    code, _, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(run), *how, "--quiet",
                                  capsys=capsys)
    assert code == 130 and f"holds epoch {epoch}; continue with --resume" in err, err
    # the same command with --resume was refused beside --overwrite ("give one of them"): the line says so
    assert ("in place of --overwrite" in err) == ("--overwrite" in how), err
    assert (run / "checkpoint.pt").exists() and not any((run / name).exists() for name in
                                                        ("metrics.json", "rollout.png", "curves.png"))


def test_frames_in_external_raw_storage_not_found_are_named(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """HDF5 looks for a dataset's external raw file from the current folder: run from another, the file was "damaged;
    collect, import or copy it again", with HDF5's own words."""
    frames = np.random.default_rng(0).integers(0, 255, (12, 20, 32, 32), dtype=np.uint8)
    frames.tofile(tmp_path / "raw.bin")
    with h5py.File(tmp_path / "ext.h5", "w") as f:
        f.create_dataset("frames", shape=frames.shape, dtype=np.uint8, external=[("raw.bin", 0, frames.nbytes)])
        f["actions"] = np.zeros((12, 20, 1), np.float32)
        f["split"] = np.array([0] * 10 + [1, 2], np.int8)
        f.attrs.update(system="pendulum", dt=0.05, params=json.dumps({}))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    refused("piga-show", [str(tmp_path / "ext.h5"), "--out", "x.png"], capsys,
            "/frames keeps its data in the external file raw.bin, which is not found from the current folder")
    monkeypatch.chdir(tmp_path)
    code, _, err = run_in_process("piga-show", show.main, "ext.h5", "--out", "x.png", capsys=capsys)
    assert code == 0, err


def test_a_stream_cache_that_auto_does_not_use_is_said(tiny_data: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """--data-loading auto --stream-cache-mb 5 on a file that fits in memory recorded the cache and read the file whole,
    without a word (an explicit --data-loading memory with it is refused)."""
    code, out, err = run_in_process("piga-train-model", train.main, str(tiny_data), "--out", str(tmp_path / "run"),
                                    "--stream-cache-mb", "5", "--epochs", "1", "--batch-size", "8", "--quiet",
                                    "--threads", "1", capsys=capsys)
    assert code in (0, 1, 3), err
    assert f"note: --data-loading auto reads {tiny_data} whole (it fits in memory), so --stream-cache-mb 5 is not " \
           "used" in out, out


def test_a_data_file_removed_while_the_run_trained_says_the_checkpoint_is_kept(tiny_data: Path, tmp_path: Path,
                                                                              capsys: pytest.CaptureFixture[str],
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """The file removed or truncated while the run trained ended in "w.h5: no such file" or "not a readable HDF5 file
    (OSError)", without saying that the run keeps its checkpoint and how to go on."""
    import piga.data.schema
    from piga.data.schema import DataFormatError

    real = piga.data.schema.fingerprint

    def gone_after_the_start(path: Any) -> str:  # read again once the run has its checkpoint: gone by then
        if (tmp_path / "run" / "checkpoint.pt").exists():
            raise DataFormatError(f"{path}: no such file")
        return real(path)

    monkeypatch.setattr(piga.data.schema, "fingerprint", gone_after_the_start)
    line = refused("piga-train-model", [str(tiny_data), "--out", str(tmp_path / "run"), "--epochs", "1", "--batch-size",
                                        "8", "--quiet", "--threads", "1"], capsys,
                   f"{tiny_data}: no such file now, after the run trained on it: the run in {tmp_path / 'run'} keeps its "
                   "checkpoint", "run the same command with --resume")
    assert (tmp_path / "run" / "checkpoint.pt").exists(), line


def test_frames_whose_chunks_were_never_written_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Sequences 6 to 11 of a chunked /frames never written read as 0: the file trained and scored a blank test split
    ("SSIM 0.000, encoder angle error 109.54 deg") without a word. A chunk written with zeros counts as written."""
    for written, name in ((6, "cut.h5"), (12, "zeros.h5")):
        with h5py.File(tmp_path / name, "w") as f:
            frames = f.create_dataset("frames", (12, 20, 32, 32), np.uint8, chunks=(1, 20, 32, 32))
            frames[:written] = np.random.default_rng(0).integers(0, 255, (written, 20, 32, 32), dtype=np.uint8) \
                if name == "cut.h5" else 0
            f["actions"] = np.zeros((12, 20, 1), np.float32)
            f["split"] = np.array([0] * 10 + [1, 2], np.int8)
            f.attrs.update(system="pendulum", dt=0.05, params=json.dumps({}))
    refused("piga-show", [str(tmp_path / "cut.h5"), "--out", str(tmp_path / "x.png")], capsys,
            "/frames holds 6 of its 12 chunks; the rest were never written")
    from piga.data.schema import inspect_dataset

    assert inspect_dataset(tmp_path / "zeros.h5").n_sequences == 12  # (blank, which the commands refuse for that)


@pytest.mark.parametrize("argv, needle", [
    (["--oracle", "--episodes", "1", "--steps", "20", "--out", "/proc/o8"], "/proc/o8.json cannot be written under /proc"),
    (["--write-goal-image", "/proc/g.png", "--angle", "30"], "/proc/g.png cannot be written under /proc"),
    (["--write-goal-image", "GOAL/.png", "--angle", "30"], "the name is only a suffix; give a name before it, such as goal.png"),
    (["--write-goal-image", ".", "--angle", "30"], "names a folder, not a file"),
    (["--oracle", "--out", "GOAL/.json"], "the name is only a suffix; give a name before it, such as results.json"),
    (["--model", "RUN", "--video", "GOAL/.mp4"], "the name is only a suffix; give a name before it, such as episode.mp4"),
])
def test_control_outputs_that_cannot_be_written_are_refused_before_the_episodes(
        argv: list[str], needle: str, tiny_piga_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """/proc's --out failed after the episodes, "removed or moved while it ran?"; ".png" was told to "use a .png path"."""
    if argv[1].startswith("/proc") and not os.path.isdir("/proc"):
        pytest.skip("no /proc here")
    argv = [str(tiny_piga_run) if a == "RUN" else a.replace("GOAL", str(tmp_path)) for a in argv]
    refused("piga-control", argv, capsys, needle)
    assert _listing(tmp_path) == []


def test_a_video_goes_with_the_out_set_that_failed(tiny_piga_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The --out set failing after the video was written left the video, and the rerun was refused for it."""
    import errno

    def full(*args: Any, **kwargs: Any) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(control, "_write_outputs", full)
    code, _, err = run_in_process("piga-control", control.main, "--model", str(tiny_piga_run), "--video",
                                  str(tmp_path / "v.gif"), "--out", str(tmp_path / "res"), "--episodes", "1", "--steps",
                                  "20", "--candidates", "8", "--iterations", "1", "--horizon", "2", "--quiet", capsys=capsys)
    assert code == 1 and "the disk is full" in err
    assert _listing(tmp_path) == []


def test_an_earlier_sweeps_figure_goes_when_its_set_is_overwritten(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OUT.png of a sweep stayed beside OUT.json and OUT.md that now described one oracle run."""
    (tmp_path / "sw.png").write_bytes(b"an earlier sweep's figure")
    for name in ("sw.json", "sw.md"):
        (tmp_path / name).write_text("{}")
    code, _, err = run_in_process("piga-control", control.main, "--oracle", "--episodes", "1", "--steps", "20",
                                  "--horizon", "3", "--candidates", "4", "--iterations", "1", "--quiet", "--out",
                                  str(tmp_path / "sw"), "--overwrite", capsys=capsys)
    assert code == 0, err
    assert _listing(tmp_path) == ["sw.json", "sw.md"]


@pytest.fixture(scope="module")
def long_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One pendulum sequence of 1000 frames."""
    from piga.data.collect import CollectConfig, collect as collect_data

    return collect_data(CollectConfig(sequences=1, steps=1000, split=(1, 0, 0), workers=1),
                        tmp_path_factory.mktemp("long") / "long.h5", progress=False, command="t")


@pytest.mark.parametrize("suffix, needle", [
    (".webp", "beyond .webp's limit of 16383 px a side; give at most --frames 227, or write .png"),
    (".jpg", "beyond .jpg's limit of 65500 px a side; give at most --frames 909, or write .png"),
])
def test_a_strip_too_wide_for_its_format_is_refused_before_it_is_drawn(suffix: str, needle: str, long_data: Path,
                                                                       tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    data = long_data
    refused("piga-show", [str(data), "--out", str(tmp_path / f"s{suffix}"), "--frames", "1000"], capsys, needle)
    refused("piga-show", [str(data), "--out", str(tmp_path / ".png")], capsys, "the name is only a suffix")


def test_an_lzw_tiff_goal_image_is_read(tmp_path: Path) -> None:
    """cv2 writes TIFF with LZW, which imageio's tifffile reads only with imagecodecs: it was "not a readable image"."""
    import cv2

    from piga.data.scene import read_image

    picture = np.zeros((40, 30, 3), np.uint8)
    picture[10:20, 5:15] = (10, 200, 30)
    assert cv2.imwrite(str(tmp_path / "g.tiff"), picture)
    assert np.array_equal(read_image(tmp_path / "g.tiff"), picture[..., ::-1])


def test_a_collection_worker_killed_under_a_step_is_one_line(tmp_path: Path) -> None:
    """A worker of AsyncVectorEnv that died (SIGKILL here; a process-group SIGTERM once raced the parent's own handler)
    left the parent reading its closed pipe: an internal error (EOFError) with 24 lines of Gymnasium's traceback."""
    out = tmp_path / "x.h5"
    proc = subprocess.Popen([sys.executable, "-m", "piga.cli.collect", "--out", str(out), "--sequences", "4000",
                             "--steps", "20", "--workers", "2", "--quiet"], env=ENV, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 60
        workers: list[str] = []
        while time.time() < deadline and len(workers) < 2:  # AsyncVectorEnv's two workers (forks), once started
            time.sleep(0.5)
            workers = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout.split()
        assert len(workers) == 2, "the workers did not start"
        time.sleep(1.0)
        os.kill(int(workers[0]), signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, err
    assert_one_line(proc.returncode, err, "a collection worker process ended in the middle of a step")
    assert _listing(tmp_path) == []


def test_a_path_beyond_path_max_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Folder names each under 255 bytes but 4 KB in all made is_dir() raise: "OSError: [Errno 36]" and the whole path."""
    deep = tmp_path / (("b" * 200 + "/") * 21) / "x.h5"
    refused("piga-collect", ["--out", str(deep), "--sequences", "4", "--steps", "4", "--workers", "1", "--quiet"], capsys,
            "the path is", "bytes", "give a shorter one")


def test_control_out_may_not_replace_its_models_own_files(tiny_piga_run: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """--out RUN/metrics --overwrite replaced the run's metrics.json with a control summary (its "did not converge"
    warning gone with it)."""
    run = _run_copy(tiny_piga_run, tmp_path / "run")
    before = (run / "metrics.json").read_bytes()
    refused("piga-control", ["--model", str(run), "--out", str(run / "metrics"), "--overwrite", "--episodes", "1"], capsys,
            "is the --model run's metrics.json", "write to another path")
    assert (run / "metrics.json").read_bytes() == before


def test_demo_out_on_a_file_system_that_stores_no_files(capsys: pytest.CaptureFixture[str]) -> None:
    """/proc/d was "removed or moved while it ran?; run the command again" (and /sys/d an errno line)."""
    if not os.path.isdir("/proc/self"):
        pytest.skip("no /proc here")
    refused("piga-demo", ["--out", "/proc/piga-demo-test", "--sequences", "6"], capsys, "cannot be written under /proc")


def test_objects_for_a_model_without_slots_is_refused(gravity_data: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """video-lstm with --objects 5: accepted, recorded, then enforced on --resume ("continues the run's own objects")."""
    refused("piga-train-model", [str(gravity_data), "--out", str(tmp_path / "run"), "--model", "video-lstm", "--objects",
                                 "5", "--quiet"], capsys, "--model video-lstm has none: drop --objects")
    assert _listing(tmp_path) == []


def test_a_scene_run_cut_short_is_continued_not_retried(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--max-minutes stopped each try after a step or two; its objects, barely trained, were "not found", and three
    more seeds were tried, then "train again with another --seed ... --overwrite"."""
    from envs.scenes import scene_config
    from piga.data.collect_scenes import SceneCollectConfig, collect_scene

    data = collect_scene(SceneCollectConfig(scene=scene_config("gravity"), sequences=8, steps=20, workers=1,
                                            split=(6, 1, 1)), tmp_path / "g.h5", progress=False, command="t")
    code, stdout, err = run_in_process("piga-train-model", train.main, str(data), "--out", str(tmp_path / "run"),
                                       "--max-minutes", "0.0001", "--preset", "paper", "--batch-size", "2", "--quiet",
                                       capsys=capsys)
    assert code in (1, 3) and "training again" not in stdout, (stdout, err)  # (1: g had not moved yet, said too)
    assert "another --seed" not in err and "--resume and a larger --max-minutes" in err


def test_a_planet_run_cut_short_by_its_budget_says_so(tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """It said "use a larger --steps", which --max-minutes stopped again (a stand-in stops the run at step 2 of 500,
    as --max-minutes would at a checkpoint)."""
    import agents.planet.train as planet_training

    real = planet_training.train_planet
    monkeypatch.setattr(planet_training, "train_planet",
                        lambda data, run_dir, config, *args, **kwargs: real(data, run_dir, replace(config, steps=2), *args,
                                                                             **kwargs))
    argv = ["planet", str(tiny_data), "--out", str(tmp_path / "pl"), "--steps", "500", "--max-minutes", "1",
            *TINY_PLANET[2:]]  # (TINY_PLANET without its --steps 2)
    code, _, err = run_in_process("piga-baseline", baseline.main, *argv, capsys=capsys)
    assert code in (1, 3) and "--max-minutes stopped" in err and "of 500" in err, err


def test_demo_resume_trains_anew_a_run_of_an_earlier_demos_data(tmp_path: Path, tiny_run: Path,
                                                                 capsys: pytest.CaptureFixture[str],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """An --overwrite with another --seed stopped after its collection left the earlier demo's run (put back as it was)
    beside the new data; --resume sent it to piga-train-model --resume, which refused the other file."""
    from piga.cli.common import Interrupted
    from piga.data.collect import collect

    out = tmp_path / "demo"
    calls: list[list[str]] = []

    def small_collect(config: Any, path: Path, **kwargs: Any) -> None:
        collect(replace(config, steps=8, workers=1), path, **kwargs)

    def interrupted_training(argv: Sequence[str], prog: str, **_: Any) -> int:
        calls.append(list(argv))
        raise Interrupted("stopped")

    monkeypatch.setattr(demo, "collect", small_collect)
    monkeypatch.setattr(demo, "_check_enough_sequences", lambda config: None)
    monkeypatch.setattr(demo.show, "main", lambda argv: 0)
    monkeypatch.setattr(demo.train, "main", interrupted_training)
    argv = ["--out", str(out), "--sequences", "4", "--quiet"]
    run_in_process("piga-demo", demo.main, *argv, capsys=capsys)  # keeps its pendulum.h5, no run yet
    shutil.copytree(tiny_run, out / "model")  # a run of other data (the earlier demo's, put back)
    calls.clear()
    code, text, err = run_in_process("piga-demo", demo.main, *argv, "--resume", capsys=capsys)
    assert code == 130, err
    assert "anew" in text and "--overwrite" in calls[0] and "--resume" not in calls[0], (text, calls)


def test_a_piga_run_that_diverged_after_a_checkpoint_is_warned_of_as_diverged(tiny_run: Path, tmp_path: Path) -> None:
    """Its readers called it interrupted ("continue it with --resume"), which repeats the divergence exactly."""
    from piga.io.checkpoint import record_divergence
    from piga.io.runs import convergence_warning

    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / "metrics.json").unlink(missing_ok=True)
    (run / "config.json").write_text(json.dumps({"command": f"piga-train-model tiny.h5 --out {run}"}))
    assert "interrupted" in (convergence_warning(run) or "")
    record_divergence(run, "training diverged: loss became nan at step 9 (epoch 2); last good checkpoint: run/x")
    warning = convergence_warning(run) or ""
    assert warning.startswith(f"warning: the run {run} diverged (training diverged: loss became nan at step 9") and \
        "--overwrite and a lower learning rate" in warning, warning


def test_a_float32_dt_is_read_as_the_decimal_written(tiny_data: Path, tmp_path: Path) -> None:
    """float32's 0.05 (0.0500000007) was refused: "says the frames are 0.05 s apart, but piga/PixelPendulum-v0 steps
    0.05 s; set 'dt' to 0.05"."""
    from piga.data.schema import inspect_dataset

    data = _variant(tiny_data, tmp_path / "d.h5", lambda f: f.attrs.__setitem__("dt", np.float32(0.05)))
    assert inspect_dataset(data).dt == 0.05
