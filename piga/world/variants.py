"""The models ``piga-train-model --model`` trains, by :attr:`piga.world.model.ModelConfig.architecture`.

| architecture | model | physical parameters |
|---|---|---|
| ``piga`` | :class:`piga.world.model.PhysicsModel`: encoder, velocity estimator, the system's physics, decoder | the system's (g, a; k, l; ...) |
| ``video-lstm`` | :class:`piga.world.video_lstm.VideoLSTM`: conv encoder, LSTM, deconv decoder | none |
| ``in-ig`` | :class:`piga.world.interaction.InteractionModel`: piga's encoder, velocity estimator and decoder around an Interaction Network | none |

Each is a :class:`piga.world.model.FrameModel`, so one training loop and one evaluation serve them all.
"""

from __future__ import annotations

from piga.io.resources import meta_parameter_count
from piga.world.interaction import InteractionModel
from piga.world.model import FrameModel, ModelConfig, PhysicsModel
from piga.world.video_lstm import VideoLSTM

#: architecture -> its model class.
MODELS: dict[str, type[FrameModel]] = {"piga": PhysicsModel, "video-lstm": VideoLSTM, "in-ig": InteractionModel}

#: Why a model of an architecture has no physical parameters (metrics.json's ``physical_parameters_reason``).
NO_PHYSICS: dict[str, str] = {
    "video-lstm": "video-lstm is a black-box frame predictor (conv encoder, LSTM, deconv decoder): it has no physical "
                  "parameters",
    "in-ig": "in-ig predicts the objects' states with a learned Interaction Network in place of the physics: it has no "
             "physical parameters",
}


def build_model(config: ModelConfig) -> FrameModel:
    """A new (untrained) model of ``config.architecture``."""
    return MODELS[config.architecture](config)


def parameter_count(config: ModelConfig) -> int:
    """The trainable parameters of ``build_model(config)``, counted on torch's meta device (no memory taken)."""
    return meta_parameter_count(lambda: build_model(config), trainable_only=True)
