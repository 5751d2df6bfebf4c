"""Values at their bounds: error lines that print the value as checked, floors that keep effects visible, bounds named
by their options."""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from envs.effects import EFFECTS, MIN_EFFECT, parse_effect
from envs.fields import number_text, upper_bound_text
from envs.pendulum import MAX_BLUR_FRACTION, MAX_IMAGE_SIZE
from piga.cli import collect, importer, train
from piga.cli.common import PigaError
from tests.helpers import moving_png_folder
from tests.test_faults import TINY_DDPG, refused

ROOT = Path(__file__).parents[1]
COLLECT = ("--sequences", "3", "--steps", "6", "--workers", "1", "--split", "1,1,1", "--quiet")
ORACLE = ("--oracle", "--episodes", "1", "--steps", "20", "--horizon", "3", "--candidates", "4", "--iterations", "1",
          "--quiet")


def _listing(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*"))


# ---------------------------------------------------------------------------------------------
# The value as checked: no rounding that puts it on the accepted side of its bound
# ---------------------------------------------------------------------------------------------


def test_number_text_is_short_unless_that_rounds() -> None:
    assert [number_text(v) for v in (1e6, 0.5, 900.0, 10.0000001, 1000000.1, 1e-320, 2)] == \
        ["1e+06", "0.5", "900", "10.0000001", "1000000.1", "1e-320", "2"]
    assert upper_bound_text(math.pi / 0.02, 7) == "157.0796" and upper_bound_text(math.pi / 0.02, 4) == "157"


@pytest.mark.parametrize("argv, needles", [
    (["--gravity-mult", "9.9999999e-08"], ["--gravity-mult 9.9999999e-08: the gravity it gives, 10 x 9.9999999e-08 = "
                                           "9.999999900000001e-07 m/s², is out of range: at least 1e-06"]),
    (["--gravity-mult", "106.61"], ["--gravity-mult 106.61:", "10 x 106.61 = 1066.1 m/s²", "at most 1066"]),
])
def test_control_prints_the_gravity_as_checked(argv: list[str], needles: list[str], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """It read "10 x 1e-07 = 1e-06 m/s², is out of range: at least 1e-06"."""
    refused("piga-control", [*ORACLE, *argv], capsys, *needles)


@pytest.mark.parametrize("argv, needles", [
    (["--system", "spring", "--k", "2222.2223"], ["k = 2222.2223 is too stiff", "below 2222.2222 "]),  # "k = 2222.22"
    (["--effect", "blur=8.0000001"], ["blur=8.0000001 px would blur the pendulum away", "at most 8 px"]),
    (["--effect", "exposure=100"], ["every frame is blank (one flat level, 255)", "--effect exposure=100 turns the "
                                    "pendulum as white as the background: give a factor nearer 1"]),  # "their size"
    (["--effect", "exposure=0.001"], ["one flat level, 0)", "exposure=0.001 turns the whole picture black"]),
])
def test_collect_prints_the_value_as_checked(argv: list[str], needles: list[str], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-collect", ["--out", str(tmp_path / "d.h5"), *COLLECT, *argv], capsys, *needles)
    assert _listing(tmp_path) == []


def test_planet_prints_the_reward_scale_as_checked(tiny_data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """It read "--reward-scale must be at most 1e+06, got 1e+06"."""
    refused("piga-baseline", ["planet", str(tiny_data), "--out", str(tmp_path / "run"), "--reward-scale", "1000000.1",
                              "--quiet"], capsys, "--reward-scale must be at most 1e+06, got 1000000.1:")
    assert _listing(tmp_path) == []


def test_ddpg_prints_the_learning_rate_as_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It read "--learning-rate must be in (0, 10], got 10"."""
    refused("piga-baseline", ["ddpg", "--obs", "state", "--out", str(tmp_path / "run"), *TINY_DDPG, "--learning-rate",
                              "10.0000001"], capsys, "--learning-rate must be in (0, 10], got 10.0000001")
    assert _listing(tmp_path) == []


def test_the_config_checks_print_the_value_as_checked() -> None:
    from agents.planet.config import PlanetTrainConfig
    from agents.sb3.config import SB3Config
    from piga.world.physics.systems import FIXED_G_RANGE, GravityOptions

    with pytest.raises(ValueError, match=r"at most 1000 nats per frame \(PlaNet uses 3\), got 1000.0000001$"):
        PlanetTrainConfig(free_nats=1000.0000001)
    with pytest.raises(ValueError, match=r"noise_std must be at most 10 .*, got 10.0000001$"):
        SB3Config(noise_std=10.0000001)
    with pytest.raises(ValueError, match=r"noise_std \(0.1\) is below .* falls to \(0.10000001\)"):
        SB3Config(algo="drqv2", obs="pixels", noise_std=0.1, noise_final_std=0.10000001)
    high = FIXED_G_RANGE[1] * (1 + 1e-9)
    with pytest.raises(ValueError, match=f"got {number_text(high)}:"):
        GravityOptions(fixed_g=high)
    assert number_text(high) != f"{FIXED_G_RANGE[1]:g}"


# ---------------------------------------------------------------------------------------------
# Effects: a floor on every continuous one, so that a recorded effect changes the data
# ---------------------------------------------------------------------------------------------

#: The continuous effects with a floor of MIN_EFFECT (speed_clip has its own; delays are whole steps).
FLOORED = [name for name, spec in EFFECTS.items() if not spec.integer and name != "speed_clip"]


@pytest.mark.parametrize("name", FLOORED)
def test_a_continuous_effect_below_its_floor_is_refused(name: str) -> None:
    """``--effect shift=1e-320`` wrote frames byte-identical to the nominal file's, and an attr that said shift 1e-320."""
    for value in (1e-320, MIN_EFFECT / 2):
        with pytest.raises(ValueError, match=f"{name} must be .*{MIN_EFFECT:g}"):
            parse_effect(f"{name}={value!r}")
    assert parse_effect(f"{name}={MIN_EFFECT!r}") == (name, MIN_EFFECT)
    if name in ("bias", "shift"):
        assert parse_effect(f"{name}={-MIN_EFFECT!r}") == (name, -MIN_EFFECT)


def test_a_gain_error_must_differ_from_one_by_the_floor() -> None:
    with pytest.raises(ValueError, match="at least 1e-06 from 1"):
        parse_effect("gain=1.0000000001")
    assert parse_effect(f"gain={1 + 2 * MIN_EFFECT!r}")[1] == 1 + 2 * MIN_EFFECT


def test_collect_refuses_a_subnormal_effect(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-collect", ["--out", str(tmp_path / "e.h5"), *COLLECT, "--effect", "damping=1e-320"], capsys,
            "effect damping=1e-320 is out of range: damping must be in [1e-06, 100]")
    assert _listing(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# Bounds named by the user's options, and given in --help
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("speed", ["1000", "157.08"])
def test_a_dmc_reset_speed_is_refused_as_max_speed(speed: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It read "--env-option --max-speed=1000.0 is out of range (--max-speed in [0, 157.1])": the user gave --max-speed,
    and 157.08 is not within 157.1's bound (π/0.02 = 157.0796...)."""
    line = refused("piga-collect", ["--out", str(tmp_path / "d.h5"), *COLLECT, "--env", "piga/DMCPendulum-v0",
                                    "--max-speed", speed], capsys,
                   f"--max-speed={number_text(float(speed))} is out of range (--max-speed in [0, π/0.02 ≈ 157.0796])")
    assert "--env-option" not in line


def test_max_speed_help_gives_each_envs_range() -> None:
    text = " ".join(collect.build_parser().format_help().split())
    assert "s in [0, 8] on piga/PixelPendulum-v0" in text and "[0, π/0.02 ≈ 157.0796] on piga/DMCPendulum-v0" in text


@pytest.mark.parametrize("argv, needle", [
    (["--objects", "1000"], "argument --objects: expected an integer in [1, 64]"),  # it said EncoderConfig.n_objects
    (["--objects", "65"], "argument --objects: expected an integer in [1, 64]"),
    (["--seed-retries", "1000000"], "argument --seed-retries: expected an integer in [0, 10]"),  # it trained without end
])
def test_train_bounds_objects_and_seed_retries(argv: list[str], needle: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    refused("piga-train-model", [str(tmp_path / "gr.h5"), "--out", str(tmp_path / "run"), "--quiet", *argv], capsys,
            needle)
    assert _listing(tmp_path) == []


def test_train_help_and_config_share_the_bounds() -> None:
    from piga.training.train import MAX_SEED_RETRIES, TrainConfig
    from piga.world.encoder import ENCODER_RANGES, MAX_OBJECTS

    assert ENCODER_RANGES["n_objects"] == (1, MAX_OBJECTS)
    text = " ".join(train.build_parser().format_help().split())
    assert f"ModelConfig.n_objects, at most {MAX_OBJECTS}:" in text
    assert f"up to N times (at most {MAX_SEED_RETRIES}: each retry can cost a whole run)" in text
    with pytest.raises(ValueError, match=f"seed_retries must be <= {MAX_SEED_RETRIES}"):
        TrainConfig(seed_retries=MAX_SEED_RETRIES + 1)


@pytest.mark.parametrize("size", ["1025", "4096"])
def test_import_bounds_the_image_size_as_collect_does(size: str, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """piga-import upscaled to 4096 px frames, which piga-collect refuses above 1024."""
    refused("piga-import", [str(tmp_path / "rec"), str(tmp_path / "u.csv"), "--dt", "0.05", "--out",
                            str(tmp_path / "o.h5"), "--image-size", size], capsys,
            f"argument --image-size: expected an integer in [8, {MAX_IMAGE_SIZE}]")
    assert f"8 to {MAX_IMAGE_SIZE}" in " ".join(importer.build_parser().format_help().split())
    from piga.data.importer import ImportConfig

    with pytest.raises(ValueError, match=f"image_size must be in \\[8, {MAX_IMAGE_SIZE}\\], got {size}"):
        ImportConfig(dt=0.05, image_size=int(size))


# ---------------------------------------------------------------------------------------------
# Messages and docs that state the true bound
# ---------------------------------------------------------------------------------------------


def test_a_frame_delay_is_refused_with_the_bound_it_breaks(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It read "frame_delay=7 steps is not shorter than a sequence's 8 frames" (7 < 8)."""
    refused("piga-collect", ["--out", str(tmp_path / "x.h5"), "--quiet", "--workers", "1", "--sequences", "5", "--steps",
                             "8", "--image-size", "16", "--effect", "frame_delay=7"], capsys,
            "frame_delay=7 steps is not shorter than a sequence's 7 steps (between its 8 frames)")
    assert _listing(tmp_path) == []


def test_a_delay_and_a_frame_delay_that_add_up_to_a_sequence_are_refused(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """delay=6 with frame_delay=6 in 12 frames passed each check alone and wrote frames that no action reached (the
    same bytes with gain=50)."""
    refused("piga-collect", ["--out", str(tmp_path / "x.h5"), "--quiet", "--workers", "1", "--sequences", "3", "--steps",
                             "12", "--split", "1,1,1", "--image-size", "16", "--effect", "delay=6", "--effect",
                             "frame_delay=5"], capsys,
            "delay=6 and frame_delay=5 add up to 11 steps, not shorter than a sequence's 11 steps", "lower one of them")
    assert _listing(tmp_path) == []
    text = " ".join((ROOT / "docs" / "commands" / "collect.md").read_text().split())
    assert "A `delay` or `frame_delay`, and the two together, must be shorter than a sequence" in text


def test_frames_stilled_by_frame_drop_name_the_effect(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """frame_drop=0.999999 (in its range) was told "a frozen camera ... actions too weak to move it"."""
    line = refused("piga-collect", ["--out", str(tmp_path / "x.h5"), "--quiet", "--workers", "1", "--sequences", "3",
                                    "--steps", "6", "--split", "1,1,1", "--image-size", "16", "--effect",
                                    "frame_drop=0.999999"], capsys,
                   "nothing moves: --effect frame_drop=0.999999 dropped every frame", "lower --effect frame_drop")
    assert "too weak" not in line
    assert _listing(tmp_path) == []


def test_fractional_counts_that_sum_to_the_sequences_are_told_to_be_whole(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """--split 8.5,1,0.5 of 10 sequences was told to be "counts summing to 10", which it is."""
    refused("piga-collect", ["--out", str(tmp_path / "x.h5"), "--quiet", "--sequences", "10", "--steps", "4",
                             "--split", "8.5,1,0.5"], capsys,
            "split (8.5, 1, 0.5) sums to 10 as counts must, but the counts must be whole numbers")
    assert _listing(tmp_path) == []


@pytest.mark.parametrize("argv", [["--effect", "frame_drop=0.999999"],  # refused as the file closes
                                  ["--system", "spring", "--k", "1e-6"]])  # refused after the first batch
def test_a_refusal_clears_the_progress_bar(argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without --quiet, the bar stayed on the line above the error ("collect: 100%| 3/3"): two lines for one error."""
    from tests.helpers import run_in_process

    code, _, err = run_in_process("piga-collect", collect.main, "--out", str(tmp_path / "x.h5"), "--workers", "1",
                                  "--sequences", "3", "--steps", "6", "--split", "1,1,1", *argv, capsys=capsys)
    assert code == 1 and err.count("\n") == 1, repr(err)
    shown = err.split("\r")[-1]  # what a terminal shows: the bar's line cleared, then overwritten by the error
    assert shown.startswith("piga-collect: error: ") and "%|" not in shown, repr(err)


def test_the_collect_page_gives_the_blur_bound_of_the_code() -> None:
    text = " ".join((ROOT / "docs" / "commands" / "collect.md").read_text().split())
    assert MAX_BLUR_FRACTION == 8 and "sigma at most an eighth of the frame's side (8 px in 64 px frames)" in text
    assert "`blur` at most half" not in text


def test_a_model_of_other_frames_is_told_to_collect_at_the_envs_size() -> None:
    """It said "train it on frames the env renders (piga-collect)" of data that piga-collect made at 32 px."""
    from piga.cli.control import check_pendulum_model

    model = SimpleNamespace(config=SimpleNamespace(system="pendulum", image_size=32, channels=1, dt=0.05))
    with pytest.raises(PigaError, match=r"renders 64x64 gray ones; collect frames of that size \(piga-collect "
                                        r"--image-size 64, its default\) and train a model on them"):
        check_pendulum_model(model, "run")  # type: ignore[arg-type]


@pytest.mark.parametrize("value", ["1e-300", "-1e-40"])
def test_import_refuses_an_action_float32_cannot_hold(value: str, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Actions of 1e-300 were stored as 0 without a word (float32 underflow)."""
    folder = moving_png_folder(tmp_path / "rec")
    (tmp_path / "u.csv").write_text("\n".join(["0.5"] * 3 + [value] + ["0"] * 8) + "\n")
    refused("piga-import", [str(folder), str(tmp_path / "u.csv"), "--dt", "0.05", "--steps", "4", "--image-size", "32",
                            "--split", "1,1,1", "--out", str(tmp_path / "o.h5")], capsys,
            f"line 4: the action {value} is nonzero and below 1.1754944e-38 in magnitude",
            "scale the actions to the env's units")
    assert not (tmp_path / "o.h5").exists()


def test_a_file_that_is_no_hdf5_is_named_in_words(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """"rec.csv: not a readable HDF5 file (OSError)": the line gave an exception's name, not what the file is."""
    cases = {"rec.csv": (b"a,b\n1,2\n", "another kind of file: an HDF5 file (.h5) from piga-collect or piga-import"),
             "cut.h5": (b"\x89HDF\r\n\x1a\n" + b"\0" * 100, "damaged or cut short: it starts as an HDF5 file"),
             "empty.h5": (b"", "it is empty")}
    for name, (content, said) in cases.items():
        (tmp_path / name).write_bytes(content)
        line = refused("piga-show", [str(tmp_path / name), "--out", str(tmp_path / "s.png")], capsys,
                       f"{name}: not a readable HDF5 file ({said}")
        assert "Error" not in line, line


@pytest.mark.parametrize("length, bound", [(0.5, "0.8572"), (0.2, "0.4286")])
def test_the_camera_distance_bound_is_a_number_at_the_length(length: float, bound: str) -> None:
    """It read "camera_distance in [(length + 0.1) / 0.7, 3]": a formula in a default the user may not know."""
    from envs.dmc import DMCPendulumConfig
    from envs.fields import lower_bound_text

    with pytest.raises(ValueError, match=re.escape(f"(camera_distance in [{bound}, 3] at length {length:g}; nearer, "
                                                   "the camera crops the pendulum)")):
        DMCPendulumConfig(length=length, camera_distance=0.01)
    assert lower_bound_text(0.6 / 0.7, 4) == "0.8572" and lower_bound_text(0.5, 4) == "0.5"
    DMCPendulumConfig(length=length, camera_distance=float(bound))  # the bound written is inside the range


@pytest.mark.parametrize("distance", [3.01, 10.0, 1e9])
def test_a_camera_too_far_is_refused_for_the_far_side(distance: float) -> None:
    """A distance of 10 was refused with the near side's reason ("nearer, the camera crops the pendulum")."""
    from envs.dmc import DMCPendulumConfig

    with pytest.raises(ValueError, match=re.escape("[0.8572, 3] at length 0.5; farther, the pendulum is too small to "
                                                   "read: its tip is 1.5 pixels wide in a 64-pixel frame)")) as caught:
        DMCPendulumConfig(camera_distance=distance)
    assert "nearer" not in str(caught.value)
    DMCPendulumConfig(camera_distance=3.0)


# ---------------------------------------------------------------------------------------------
# Passive torques that Pendulum-v1's explicit step cannot integrate
# ---------------------------------------------------------------------------------------------


def _speeds(effects: tuple[tuple[str, float], ...], steps: int) -> np.ndarray:
    """θ̇ after each of ``steps`` steps of no action from 8 starts, through the env's own torque wrappers (no frames)."""
    import gymnasium as gym

    from envs.effects import wrap_effects
    from envs.pendulum import ActuationGain, ResetRange

    env = ActuationGain(wrap_effects(ResetRange(gym.make("Pendulum-v1", g=10.0, max_episode_steps=10**6), math.pi, 1.0),
                                     effects, "torque"), 1.0)
    out = []
    for seed in range(8):
        env.reset(seed=seed)
        out.append([env.step(np.zeros(1, np.float32))[0][2] for _ in range(steps)])
    return np.abs(np.asarray(out))  # (8, steps)


@pytest.mark.parametrize("argv, needles", [
    (["--effect", "damping=14"], ["damping=14 N·m·s/rad is unstable in Pendulum-v1's explicit step (dt = 0.05 s",
                                  "grows to the speed clip; use damping below 13.2"]),
    (["--effect", "damping=100"], ["use damping below 13.2"]),
    (["--effect", "friction=100"], ["friction=100 N·m makes Pendulum-v1's explicit step", "by up to 7.57 rad/s",
                                    "use friction of at most 13.2"]),
    (["--effect", "damping=10", "--effect", "friction=5"], ["friction=5 N·m", "at most 3.208",
                                                             "with damping=10, or lower damping"]),
    (["--effect", "damping=10", "--effect", "cogging=100"], ["use damping below 3.208 with cogging=100"]),
])
def test_collect_refuses_a_passive_torque_the_step_cannot_integrate(argv: list[str], needles: list[str], tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """damping=14 (in its range, [1e-6, 100]) wrote a file whose speed flipped sign each step up to the ±8 clip, and
    friction=100 one that shook between two angles at ±8 rad/s; piga-diagnose then said the actions barely move it."""
    refused("piga-collect", ["--out", str(tmp_path / "d.h5"), *COLLECT, *argv], capsys, *needles)
    assert _listing(tmp_path) == []


def test_the_passive_bounds_are_where_the_env_stops_making_sense() -> None:
    """The bounds the refusal states are the env's: damping just past it grows to the clip, just inside it does not,
    and friction at its bound chatters by under 1 rad/s, at 100 by about 7.5."""
    from envs.effects import MAX_FRICTION_CHATTER, explicit_step_problem

    assert explicit_step_problem({"damping": 13.2}, 10.0, 0.05) is None
    assert "below 13.2" in (explicit_step_problem({"damping": 13.21}, 10.0, 0.05) or "")
    assert _speeds((("damping", 13.2),), 400)[:, -100:].max() < 0.5  # the reset's ±1 rad/s dies out, slowly
    past = _speeds((("damping", 13.25),), 400)  # (8, 400): grows, slowly this near the bound
    assert past[:, -100:].max() > 2 * past[:, 100:200].max()
    assert _speeds((("damping", 14.0),), 100)[:, -50:].max() == 8.0
    late = _speeds((("friction", 13.2),), 60)[:, 30:]  # (8, 30): settled where gravity cannot move it
    chatter = _speeds((("friction", 100.0),), 60)[:, 30:]
    assert np.median(late) <= MAX_FRICTION_CHATTER < np.median(chatter) and np.median(chatter) > 7.0


def test_the_benchmarks_passive_effects_stay_accepted() -> None:
    from envs.pendulum import PixelPendulumConfig

    for effects in ({"damping": 0.3, "friction": 0.5, "cogging": 0.6}, {"damping": 13.2}, {"friction": 13.2},
                    {"cogging": 100.0}, {"damping": 0.4, "friction": 0.3}):
        PixelPendulumConfig(effects=tuple(effects.items()))


def test_the_collect_page_gives_the_passive_bounds_of_the_code() -> None:
    from envs.effects import explicit_step_problem

    text = " ".join((ROOT / "docs" / "commands" / "collect.md").read_text().split())
    assert "`damping` must be below 13.2 N·m·s/rad" in text and "A `friction` must be at most 13.2 N·m" in text
    assert "below 13.2" in (explicit_step_problem({"damping": 13.3}, 10.0, 0.05) or "")
    assert "at most 13.2 " in (explicit_step_problem({"friction": 13.3}, 10.0, 0.05) or "")
