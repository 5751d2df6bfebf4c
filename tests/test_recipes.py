"""The typed recipes of piga-train-model and piga-collect are the recipes they replaced.

``OLD_*`` are the presets as they were written before they were typed (overrides of the dataclass
defaults, applied with ``replace``); each typed recipe must resolve to exactly the same configs.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import pytest

from envs.pendulum import PixelPendulumConfig
from piga.data.collect import PRESETS as COLLECT_PRESETS
from piga.data.collect import CollectConfig
from piga.data.collect_scenes import SCENE_PRESETS as COLLECT_SCENE_PRESETS
from piga.data.collect_scenes import SceneCollectConfig
from piga.data.schema import DatasetInfo
from piga.training.train import PRESETS, SCENE_PRESETS, TrainConfig, model_config_for, preset_for
from piga.world.model import ModelConfig

_PAPER_TRAIN = {"epochs": 1000, "lr": 3e-4, "lr_physics": 3e-4, "optimizer": "rmsprop", "schedule": "step", "lr_decay_epoch": 500,
                "warmup_fraction": 0.0, "curriculum_fraction": 0.0, "grad_clip": 0.0, "average_fraction": 0.0, "physics_grad_clip": 0.0}
OLD_PRESETS = {
    "fast": {},
    "paper": {"train": _PAPER_TRAIN,
              "model": {"substeps": 5, "learn_offset": True, "readout": "regress", "rec_frames": "all", "pred_trim": 0.0,
                        "velocity_correction": True}},
    "continuous": {"model": {"integrator": "rk4", "substeps": 2, "velocity_hold": True, "learn_damping": True}},
}
_SCENE_MODEL = {"input_frames": 4, "pred_frames": 6, "pred_trim": 0.0, "velocity_correction": True, "velocity_shoot": True,
                "substeps": 5, "mask_pixelwise": True, "alpha": 2.0, "init_background": True}
_SCENE_FAST_TRAIN = {"budget_steps": 1650, "warmup_fraction": 0.18, "curriculum_fraction": 0.36, "average_fraction": 1 / 6,
                     "window_stride": 2}
_SCENE_PAPER = {"train": {**_PAPER_TRAIN, "epochs": 500, "lr_decay_epoch": 375, "batch_size": 100},
                "model": {**_SCENE_MODEL, "readout": "regress", "rec_frames": "all"}}
OLD_SCENE_PRESETS = {
    "bouncing": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0, "wall_radius": 3.0}},
                 "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "wall_radius": 3.0}}},
    "spring": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0}}, "paper": _SCENE_PAPER},
    "gravity": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 1.0, "pred_frames": 12,
                                                               "extrapolate_frames": 24}},
                "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "pred_frames": 12,
                                                                    "extrapolate_frames": 24}}},
    "digits-spring": {"fast": {"train": _SCENE_FAST_TRAIN, "model": {**_SCENE_MODEL, "init_scale": 2.0}},
                      "paper": {"train": _SCENE_PAPER["train"], "model": {**_SCENE_PAPER["model"], "init_scale": 2.0}}},
}
#: (system, scene attr, image shape) of a file of each scene.
FILES = {"pendulum": ("pendulum", (64, 64)), "bouncing": ("bouncing", (32, 32, 3)), "spring": ("spring", (32, 32, 3)),
         "gravity": ("gravity", (36, 36, 3)), "digits-spring": ("spring", (64, 64, 3))}


def _info(scene: str) -> DatasetInfo:
    system, shape = FILES[scene]
    n_objects = {"pendulum": 1, "gravity": 3}.get(system, 2)
    return DatasetInfo(path=Path(f"{scene}.h5"), n_sequences=10, steps=40, image_shape=shape, action_dim=0 if system != "pendulum" else 1,
                       has_states=False, system=system, dt=0.05 if system == "pendulum" else 0.3, params={},
                       split_counts={"train": 8, "valid": 1, "test": 1},
                       attrs={"scene": scene, "n_objects": n_objects} if system != "pendulum" else {})


def _old(scene: str, name: str) -> tuple[TrainConfig, ModelConfig]:
    """What the old code resolved: the file's model with the preset's overrides, the defaults' training with its."""
    info = _info(scene)
    recipe = OLD_PRESETS[name] if scene == "pendulum" else OLD_SCENE_PRESETS[scene][name]
    model = dict(recipe.get("model", {}))
    if scene != "pendulum":
        model["template_size"] = max(info.image_shape[0] // 2, 1)
    file_model = model_config_for(info)
    train = dict(recipe.get("train", {}))
    if name == "paper":  # since: one window per sequence, as the paper's epochs (a stride of the file's length)
        train["window_stride"] = info.steps
    return TrainConfig(**train), ModelConfig.from_dict({**file_model.to_dict(), **model})  # flat overrides


@pytest.mark.parametrize("scene,name", [("pendulum", name) for name in OLD_PRESETS]
                         + [(scene, name) for scene in OLD_SCENE_PRESETS for name in ("fast", "paper")])
def test_each_recipe_resolves_to_the_configs_of_the_old_overrides(scene: str, name: str) -> None:
    info = _info(scene)
    recipe = preset_for(name, info)
    train, model = _old(scene, name)
    assert asdict(recipe.train) == asdict(train)
    assert model_config_for(info, recipe.model).to_dict() == model.to_dict()


@pytest.mark.parametrize("scene", ["pendulum", "spring", "gravity"])
def test_the_paper_preset_passes_once_over_the_sequences_per_epoch(scene: str) -> None:
    """The paper's epoch: every training sequence once (500 epochs of 5000 sequences at batch 100 are 25,000 steps),
    not every window of it (21 per 30-frame sequence)."""
    info = _info(scene)

    def starts(name: str) -> int:  # training windows per sequence, as the run's plan counts them
        recipe = preset_for(name, info)
        window = model_config_for(info, recipe.model).window
        return len(range(0, info.steps - window + 1, recipe.train.window_stride))

    assert starts("paper") == 1 and starts("fast") > 1


def test_the_recipe_tables_hold_every_preset() -> None:
    assert sorted(PRESETS) == sorted(OLD_PRESETS) and sorted(SCENE_PRESETS) == sorted(OLD_SCENE_PRESETS)
    assert all(sorted(recipes) == ["fast", "paper"] for recipes in SCENE_PRESETS.values())


def test_a_pendulum_only_preset_on_a_scene_is_one_clear_error() -> None:
    with pytest.raises(ValueError, match="preset 'continuous' is the pendulum's; a spring file has fast, paper"):
        preset_for("continuous", _info("spring"))
    with pytest.raises(ValueError, match="unknown preset 'slow'"):
        preset_for("slow", _info("pendulum"))


def test_the_collection_presets_are_the_old_overrides() -> None:
    old = {"default": {}, "paper": {"sequences": 6000, "steps": 14, "split": (5000, 500, 500), "max_speed": 6.0}}
    for name, values in old.items():
        values = dict(values)
        env = PixelPendulumConfig(max_speed=values.pop("max_speed", PixelPendulumConfig.max_speed))
        assert COLLECT_PRESETS[name] == replace(CollectConfig(env=env), **values)
    old_scenes = {"default": {"sequences": 1000}, "paper": {"sequences": 6000, "split": (5000, 500, 500)}}
    assert {name: replace(SceneCollectConfig(), **values) for name, values in old_scenes.items()} == COLLECT_SCENE_PRESETS
