"""The composed model: shapes, loss, gradients into the physics."""

from __future__ import annotations

import json
from dataclasses import fields
from typing import Any

import pytest
import torch

from piga.world.model import ModelConfig, PhysicsModel, frames_to_float
from piga.world.physics import BouncingOptions, GravityOptions, PendulumOptions


@pytest.mark.parametrize("rec_frames", ["all", "input"])
def test_forward_shapes_and_gradients_reach_physics(rec_frames: str) -> None:
    torch.manual_seed(0)
    model = PhysicsModel(ModelConfig(rec_frames=rec_frames))
    frames = torch.randint(0, 256, (2, 14, 64, 64), dtype=torch.uint8)
    actions = torch.rand(2, 14, 1) * 4 - 2
    out = model(frames, actions)
    n_rec = 14 if rec_frames == "all" else 4
    assert out.pred.shape == (2, 10, 1, 64, 64) and out.rec.shape == (2, n_rec, 1, 64, 64)
    assert out.coords_pred.shape == (2, 10, 1, 1) and torch.isfinite(out.loss)
    out.loss.backward()
    assert model.system.log_g.grad is not None and model.system.log_g.grad.abs() > 0
    assert model.system.log_a.grad is not None and model.system.log_a.grad.abs() > 0


def test_starts_far_from_truth() -> None:
    params = PhysicsModel(ModelConfig()).physical_parameters()
    assert params["g"] == pytest.approx(1.0) and params["a"] == pytest.approx(0.3)


def test_shorter_horizon_and_actions_alignment() -> None:
    model = PhysicsModel(ModelConfig())
    frames = torch.zeros(1, 14, 64, 64, dtype=torch.uint8)
    actions = torch.zeros(1, 14, 1)
    assert model(frames, actions, pred_frames=3).pred.shape[1] == 3
    # the action after input frame L (index L-1) drives the first predicted frame
    coords = torch.zeros(1, 4, 1, 1)
    a1 = model.predict(coords, torch.ones(1, 2, 1), 2)
    a0 = model.predict(coords, torch.zeros(1, 2, 1), 2)
    assert (a1 - a0)[0, 0].item() == pytest.approx(3 * 0.3 * 0.05 * 0.05, rel=1e-4)


def test_frames_to_float_layouts() -> None:
    gray = torch.full((2, 3, 8, 8), 255, dtype=torch.uint8)
    assert frames_to_float(gray, 1).shape == (2, 3, 1, 8, 8) and frames_to_float(gray, 1).max() == 1.0
    colour = torch.zeros(2, 3, 8, 8, 3, dtype=torch.uint8)
    assert frames_to_float(colour, 3).shape == (2, 3, 3, 8, 8)
    with pytest.raises(ValueError, match="frames must be"):
        frames_to_float(colour, 1)
    assert torch.equal(frames_to_float(gray.numpy(), 1), frames_to_float(gray, 1))  # read_sequences' arrays as they are
    with pytest.raises(TypeError, match="convert them with piga.frames_to_float"):
        PhysicsModel(ModelConfig()).encode(gray.numpy())  # uint8 frames not converted


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="unknown system"):
        ModelConfig(system="rocket")
    with pytest.raises(ValueError, match="rec_frames"):
        ModelConfig(rec_frames="some")


def test_trimmed_prediction_loss_ignores_the_worst_windows() -> None:
    torch.manual_seed(0)
    model = PhysicsModel(ModelConfig(pred_trim=0.25))
    frames = torch.randint(0, 256, (4, 14, 64, 64), dtype=torch.uint8)
    actions = torch.zeros(4, 14, 1)
    model.train()
    trimmed = model(frames, actions).loss_pred
    model.eval()  # evaluation reports the plain mean
    plain = model(frames, actions).loss_pred
    assert trimmed < plain
    with pytest.raises(ValueError, match="pred_trim"):
        ModelConfig(pred_trim=1.0)


def test_checkpoint_config_without_pivot_gate_reads_as_trained() -> None:
    """A checkpoint from before the gate existed was trained without it: it loads with the gate off."""
    legacy = {k: v for k, v in _flat(ModelConfig()).items() if k != "pivot_gate"}
    assert ModelConfig.from_dict(legacy).system_options.pivot_gate == (0.0, 0.0)
    assert ModelConfig.from_dict(ModelConfig().to_dict()) == ModelConfig()


#: The flat form every checkpoint stored before the systems' options moved to their systems: each system's
#: options as fields of the config, at these defaults.
FLAT_OPTIONS = {"learn_offset": False, "learn_damping": False, "damping_init": 0.01, "signed_actuation": False,
                "angle_reference": 0.0, "pivot_gate": [0.125, 0.16], "wall_radius": 2.0, "fixed_g": 0.0}


def _flat(config: ModelConfig) -> dict[str, Any]:
    """``config`` as a checkpoint of the flat form stored it (JSON values: a tuple is a list)."""
    values = json.loads(json.dumps(config.to_dict()))
    return {**FLAT_OPTIONS, **values.pop("system_options"), **values}


@pytest.mark.parametrize("config", [
    ModelConfig(system_options=PendulumOptions(learn_offset=True, learn_damping=True, damping_init=0.07, signed_actuation=True,
                                               angle_reference=0.3, pivot_gate=(0.1, 0.2)), substeps=5),
    ModelConfig(system="spring", n_objects=2, dt=0.3),
    ModelConfig(system="gravity", n_objects=3, system_options=GravityOptions(fixed_g=60.0)),
    ModelConfig(system="bouncing", system_options=BouncingOptions(wall_radius=3.0), image_size=32)])
def test_a_flat_checkpoint_config_loads_and_a_new_one_round_trips(config: ModelConfig) -> None:
    assert ModelConfig.from_dict(_flat(config)) == config
    stored = json.loads(json.dumps(config.to_dict()))  # as config.json holds it
    assert set(stored["system_options"]) == {f.name for f in fields(type(config.system_options))}
    assert ModelConfig.from_dict(stored) == config and ModelConfig.from_dict(config.to_dict()) == config


def test_an_option_of_another_system_is_one_line_naming_both() -> None:
    with pytest.raises(ValueError, match=r"^learn_damping is an option for pendulum models, not for a spring model "
                                         r"\(its options: none\)$"):
        ModelConfig.from_dict({**_flat(ModelConfig(system="spring")), "learn_damping": True})
    with pytest.raises(ValueError, match="^wall_radius is an option for bouncing models, not for a gravity model "
                                         r"\(its options: fixed_g\)$"):
        ModelConfig(system="gravity").with_options(wall_radius=3.0)
    with pytest.raises(ValueError, match="^a spring model takes SpringOptions, not PendulumOptions$"):
        ModelConfig(system="spring", system_options=PendulumOptions())
    with pytest.raises(ValueError, match="has no field or system option 'wall'"):
        ModelConfig.from_dict({"system": "bouncing", "wall": 3.0})


@pytest.mark.parametrize("side", [16, 36, 50, 64])
def test_the_location_network_reads_any_side_from_16(side: int) -> None:
    """The paper's preset on the 3-body gravity scene (36x36 frames, the paper's size) was refused: "image_size must
    be a multiple of 16 for the location network"; its four halvings leave 2x2 of 36 as of 32."""
    from piga.world.encoder import _LocationNet

    assert _LocationNet(3, 8, side, 4)(torch.zeros(2, 3, side, side)).shape == (2, 4)
    with pytest.raises(ValueError, match="at least 16"):
        _LocationNet(3, 8, 15, 4)
