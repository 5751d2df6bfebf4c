"""Fixed-choice config fields are typed ``Literal`` and refuse any other value with one line naming the field and the choices."""

from __future__ import annotations

from dataclasses import replace
from typing import Any, get_args

import pytest

from envs.dmc import FLIPS, DMCPendulumConfig
from envs.effects import EFFECTS, EffectKind
from envs.scenes import SCENES, Physics, Scene, SceneError, scene_config
from piga.control.episodes import EpisodeConfig
from piga.control.jobs import ControlJob
from piga.evaluation.evaluate import EvalConfig
from piga.io.choices import check_choices, literal_fields
from piga.io.runs import Nominal
from piga.training.train import TrainConfig
from piga.world.encoder import EncoderConfig

CASES = [
    (TrainConfig(), "optimizer", ("adam", "rmsprop")),
    (TrainConfig(), "schedule", ("cosine", "step")),
    (EvalConfig(), "split", ("train", "valid", "test")),
    (Nominal(g=10.0, a=1.0, offset=0.0, dt=0.05), "integrator", ("euler", "rk4")),
    (EncoderConfig(), "readout", ("centroid", "regress")),
    (ControlJob("oracle", EpisodeConfig()), "agent", ("piga", "oracle", "planet", "ddpg")),
]


@pytest.mark.parametrize("config,name,choices", CASES, ids=[f"{type(c).__name__}.{n}" for c, n, _ in CASES])
def test_a_value_outside_the_literal_is_one_line_naming_the_field_and_choices(config: object, name: str,
                                                                              choices: tuple[str, ...]) -> None:
    assert dict(literal_fields(type(config)))[name] == choices
    with pytest.raises(ValueError) as info:
        replace(config, **{name: "bogus"})  # type: ignore[type-var]
    message = str(info.value)
    assert "\n" not in message and f"{type(config).__name__}.{name}" in message and "'bogus'" in message
    assert all(repr(choice) in message for choice in choices), message


def test_check_choices_accepts_each_choice() -> None:
    for config, name, choices in CASES:
        for choice in choices:
            check_choices(replace(config, **{name: choice}) if name != "agent" else config)  # type: ignore[type-var]


def test_the_env_configs_take_their_literals() -> None:
    assert set(SCENES) == set(get_args(Scene)) and {s["physics"] for s in SCENES.values()} == set(get_args(Physics))
    with pytest.raises(SceneError, match="SceneConfig.physics must be one of 'bouncing', 'spring', 'gravity'; got 'magnet'"):
        replace(scene_config("spring"), physics="magnet")  # type: ignore[arg-type]
    assert FLIPS == ("none", "camera", "motor")
    with pytest.raises(ValueError, match="flip"):
        DMCPendulumConfig(flip="upside")  # type: ignore[arg-type]
    assert {spec.kind for spec in EFFECTS.values()} <= set(get_args(EffectKind))
    with pytest.raises(ValueError, match="EffectSpec.kind must be one of 'actuator', 'passive', 'clip', 'vision'; got 'x'"):
        replace(next(iter(EFFECTS.values())), kind="x")  # type: ignore[arg-type]


@pytest.mark.parametrize("make, needle", [
    (lambda: __import__("piga").CollectConfig(sequences="10"), "CollectConfig.sequences must be an integer; got '10' (str)"),
    (lambda: __import__("piga").CollectConfig(sequences=2.5), "CollectConfig.sequences must be an integer; got 2.5"),
    (lambda: __import__("piga").TrainConfig(lr=None), "TrainConfig.lr must be a number; got None"),
    (lambda: __import__("piga").TrainConfig(batch_size=[32]), "TrainConfig.batch_size must be an integer; got [32]"),
    (lambda: __import__("piga").ModelConfig(image_size="64"), "ModelConfig.image_size must be an integer"),
    (lambda: __import__("piga").TrainConfig(epochs=True), "TrainConfig.epochs must be an integer; got True (bool)"),
    # the planners', the episodes', the diagnosis', the baselines' and the envs' configs check their fields' kinds too
    (lambda: __import__("envs.dmc").dmc.DMCPendulumConfig(shadows="no"), "DMCPendulumConfig.shadows must be true or false"),
    (lambda: __import__("envs.dmc").dmc.DMCPendulumConfig(image_size=float("inf")), "image_size must be an integer"),
    (lambda: __import__("agents.planet.config").planet.config.PlanetTrainConfig(steps="5"),
     "PlanetTrainConfig.steps must be an integer; got '5'"),
    (lambda: __import__("agents.config").config.CEMConfig(horizon="20"), "CEMConfig.horizon must be an integer"),
    (lambda: __import__("piga.control.episodes").control.episodes.EpisodeConfig(episodes=None),
     "EpisodeConfig.episodes must be an integer"),
    (lambda: __import__("agents.sb3.autoencoder").sb3.autoencoder.AutoencoderConfig(lr="fast"),
     "AutoencoderConfig.lr must be a number"),
])
def test_a_field_of_another_kind_is_named(make: Any, needle: str) -> None:
    """A library caller without a type checker got "'<' not supported between instances of 'str' and 'int'"."""
    with pytest.raises(TypeError) as error:
        make()
    assert needle in str(error.value)


def test_numpy_numbers_and_lists_for_tuples_are_taken() -> None:
    import numpy as np

    import piga

    config = piga.TrainConfig(epochs=np.int64(3), lr=np.float32(1e-3))
    assert config.epochs == 3
    assert piga.CollectConfig(sequences=np.int64(20), split=[16, 2, 2]).sequences == 20


def test_the_library_entry_points_name_an_argument_of_another_kind(tmp_path: Any, tiny_data: Any) -> None:
    import piga
    from piga.data.schema import read_sequences
    from piga.data.windows import SequenceWindows

    with pytest.raises(TypeError, match="CollectConfig.env must be a PixelPendulumConfig or a DMCPendulumConfig"):
        piga.CollectConfig(env=None)
    with pytest.raises(TypeError, match="config must be a CollectConfig, got dict"):
        piga.collect({"sequences": 4}, tmp_path / "x.h5")
    with pytest.raises(TypeError, match="train_config must be a TrainConfig, got NoneType"):
        piga.train(tiny_data, tmp_path / "r", None)
    with pytest.raises(ValueError, match="limit must be None .* got -1"):
        read_sequences(tiny_data, "test", limit=-1)  # it read all but the last
    with pytest.raises(ValueError, match=r"window must be >= 1 \(frames per item\), got 0"):
        SequenceWindows(tiny_data, "train", window=0)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("make, needle", [
    (lambda: __import__("piga").ModelConfig(alpha=float("nan")), "ModelConfig.alpha must be a finite number >= 0"),
    (lambda: __import__("piga").ModelConfig(dt=float("nan")), "ModelConfig.dt must be the seconds between frames"),
    (lambda: __import__("piga").ModelConfig(physics_init=[1]), "ModelConfig.physics_init must map parameter names"),
    (lambda: __import__("piga").ModelConfig(physics_init={"bogus": 1.0}), "unexpected keyword argument 'bogus'"),
    (lambda: __import__("piga").ModelConfig(physics_init={"g": -1.0}), "does not fit a pendulum model"),
    (lambda: __import__("agents.sb3.config").sb3.config.SB3Config(net_arch=[-5]), "net_arch must be hidden layer widths"),
    # torch's generator failed on them: "Overflow when unpacking long long"
    (lambda: __import__("piga").TrainConfig(seed=2**70), "TrainConfig.seed must be <= 9223372036854775807"),
    (lambda: __import__("agents.planet.config").planet.config.PlanetTrainConfig(seed=2**63), "PlanetTrainConfig.seed must be <="),
    (lambda: __import__("agents.sb3.config").sb3.config.SB3Config(seed=2**63), "SB3Config.seed must be <="),
])
def test_a_value_no_run_can_use_is_named_at_construction(make: Any, needle: str) -> None:
    """Each was taken, and failed inside training: a nan loss at step 0 naming no field, or a keyword error."""
    with pytest.raises(ValueError) as error:
        make()
    assert needle in str(error.value)


def _pendulum_options(**kw: Any) -> Any:
    from piga.world.physics.systems import PendulumOptions

    return PendulumOptions(**kw)


def _diagnose(**kw: Any) -> Any:
    from piga.diagnostics.diagnose import DiagnoseConfig

    return DiagnoseConfig(**kw)


def _camera(**kw: Any) -> Any:
    from piga.diagnostics.vision import CameraConfig

    return CameraConfig(**kw)


def _fit_model(**kw: Any) -> Any:
    from piga.diagnostics.fit import Model

    return Model(**kw)


@pytest.mark.parametrize("make, error, needle", [
    (lambda: _pendulum_options(pivot_gate=1), TypeError, "PendulumOptions.pivot_gate must be a tuple"),
    (lambda: _pendulum_options(pivot_gate=("a", "b")), ValueError, "PendulumOptions.pivot_gate must be two numbers"),
    (lambda: _pendulum_options(pivot_gate=(0.3, 0.1)), ValueError, "0 <= inner <= outer < 0.5"),
    (lambda: _pendulum_options(damping_init=0.0), ValueError, "PendulumOptions.damping_init must be a finite number > 0"),
    (lambda: _pendulum_options(damping_init=float("nan")), ValueError, "damping_init must be a finite number"),
    (lambda: _pendulum_options(angle_reference=1e9), ValueError, "PendulumOptions.angle_reference must be"),
    (lambda: _pendulum_options(learn_offset="yes"), TypeError, "PendulumOptions.learn_offset must be True or False"),
    (lambda: EncoderConfig(mask_width=0), ValueError, "EncoderConfig.mask_width must be a finite number >= 1"),
    (lambda: EncoderConfig(image_size=10**9), ValueError, "EncoderConfig.image_size must be"),
    (lambda: EncoderConfig(pivot_gate=(0.1,)), ValueError, "EncoderConfig.pivot_gate must be two numbers"),
    (lambda: __import__("piga.world.physics.systems").world.physics.systems.GravityOptions(fixed_g="3"), TypeError,
     "GravityOptions.fixed_g must be a number"),
    (lambda: __import__("piga.data.collect_scenes").data.collect_scenes.SceneCollectConfig(scene=None), TypeError,
     "SceneCollectConfig.scene must be an envs.scenes.SceneConfig"),
    (lambda: _diagnose(min_gain=float("nan")), ValueError, "DiagnoseConfig.min_gain must be a finite number >= 0 and <= 1"),
    (lambda: _diagnose(vision_ratio=0.0), ValueError, "DiagnoseConfig.vision_ratio must be a finite number > 0"),
    (lambda: _diagnose(fit_horizon=10**9), ValueError, "DiagnoseConfig.fit_horizon must be"),
    (lambda: _diagnose(camera=None), TypeError, "DiagnoseConfig.camera must be a CameraConfig"),
    (lambda: _camera(min_noise=-1.0), ValueError, "CameraConfig.min_noise must be a finite number >= 0"),
    (lambda: _camera(repeats=3), TypeError, "CameraConfig.repeats must be a RepeatConfig"),
    (lambda: _fit_model(delay=-1), ValueError, "Model.delay must be an integer from 0 to"),
    (lambda: _fit_model(substeps=10**6), ValueError, "Model.substeps must be an integer from 0 to"),
])
def test_the_library_configs_name_a_bad_field(make: Any, error: type, needle: str) -> None:
    """Each was taken at construction and failed later in another's words (an iteration over an int, a NaN
    comparison that passed), or ran: a damping start of 0 is log(0) in the physics."""
    with pytest.raises(error) as raised:
        make()
    assert needle in str(raised.value) and "\n" not in str(raised.value)


def test_more_threads_than_cpus_is_named_before_torch_takes_them(tiny_data: Any, tmp_path: Any) -> None:
    """100000 threads segfaulted torch's thread pool (exit 139, nothing on stderr), where --threads refused them."""
    import os

    import piga

    with pytest.raises(ValueError, match=r"TrainConfig.threads must be at most this machine's \d+ CPUs"):
        piga.train(tiny_data, tmp_path / "run", piga.TrainConfig(epochs=1, threads=(os.cpu_count() or 1) + 1),
                   progress=False)
    assert not (tmp_path / "run").exists()


def test_the_api_names_an_argument_of_the_wrong_kind(tiny_data: Any, tmp_path: Any) -> None:
    """Each failed deep inside dataclasses, functools or torch, naming nothing of the call."""
    import torch

    import piga

    with pytest.raises(TypeError, match="config must be a PixelPendulumConfig or None, got dict"):
        piga.make_pixel_pendulum(config={"gravity": 3})
    with pytest.raises(TypeError, match="make_env must be a function"):
        piga.collect(piga.CollectConfig(sequences=2, steps=4, workers=1), tmp_path / "x.h5", make_env=5)
    model = piga.PhysicsModel(piga.ModelConfig())
    x = torch.zeros(1, 2, 1, 64, 64)
    assert model.encode(x).shape == (1, 2, 1, 1)
    with pytest.raises(ValueError, match=r"encode takes frames of \(C, H, W\) = \(1, 64, 64\), the model's, got \(1, 32, 32\)"):
        model.encode(x[..., :32, :32])
    with pytest.raises(TypeError, match="encode takes torch.float32 frames, got torch.float64"):
        model.encode(x.double())
