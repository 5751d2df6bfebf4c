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


def activation_bytes(config: ModelConfig) -> int | None:
    """The activations that one training window of ``build_model(config)`` keeps for its backward pass, in bytes:
    the tensors autograd saves (each once; views of the parameters left out), measured by running the forward pass on
    torch's meta device (no memory taken, well under a second). None where an operation has no meta kernel.

    What a training run needs beyond its parameters: :mod:`piga.training.memory`.
    """
    import torch

    saved: dict[int, torch.Tensor] = {}
    try:
        with torch.device("meta"):
            model = build_model(config)
            own = {id(p) for p in model.parameters()}
            shape = (1, config.window, config.image_size, config.image_size) + ((config.channels,) if config.channels > 1 else ())
            frames = torch.zeros(shape, dtype=torch.uint8)  # (1, L+T, H, W[, C])
            actions = torch.zeros(1, config.window, config.action_dim)  # (1, L+T, A)
            with torch.autograd.graph.saved_tensors_hooks(lambda x: saved.setdefault(id(x), x), lambda x: x):
                model(frames, actions)
    except (RuntimeError, NotImplementedError, TypeError):
        return None
    return sum(x.numel() * x.element_size() for key, x in saved.items()
               if key not in own and not (x._base is not None and id(x._base) in own))
