"""The physics-as-inverse-graphics world model: encoder, velocity estimator, physics and decoder.

```
frames x_1..x_L ─► Encoder ─► p_1..p_L ─► VelocityEstimator ─► (p_L, v_L)
                                   │                                  │ actions u_L..
                                   ▼                                  ▼
                               Decoder ─► x̃ᵃᵉ (all frames)       Physics (Euler) ─► p_{L+1..L+T}
                                                                      │
                                                              Decoder ─► x̃ᵖʳᵉᵈ
loss = Σ_{t>L} MSE(x̃ᵖʳᵉᵈ_t, x_t) + α Σ_t MSE(x̃ᵃᵉ_t, x_t)
```

Frames enter as uint8 [B, T, H, W] (gray) or [B, T, H, W, C], as a data file stores them. The
actions are float [B, T, A], where ``actions[:, t]`` is applied after frame t.

Every model that ``piga-train-model`` trains is a :class:`FrameModel`: frames and actions in, predicted
frames and the parts of the loss out, so one training loop and one evaluation serve them all
(``ModelConfig.architecture``, built by :func:`piga.world.variants.build_model`). :class:`ObjectModel` is
the encoder, velocity estimator and decoder that piga's model and the Interaction-Network baseline
(:mod:`piga.world.interaction`) share; they differ only in what rolls the object states forward.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any, ClassVar, Literal, NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from piga.io.choices import check_choices, check_ranges, check_types
from piga.world.decoder import Decoder, DecoderConfig
from piga.world.encoder import Encoder, EncoderConfig
from piga.world.conv_decoders import BroadcastDecoder, DeconvDecoder
from piga.world.mlp_decoder import MLPDecoder
from piga.world.physics import SYSTEMS, System, SystemOptions, hold_velocity, make_integrator, rollout
from piga.world.velocity import VelocityConfig, VelocityEstimator

#: System name -> (N, D, A) of its state and actions.
SYSTEM_SHAPES: dict[str, tuple[int, int, int]] = {
    "pendulum": (1, 1, 1),
    "spring": (2, 2, 0),
    "gravity": (3, 2, 0),
    "bouncing": (2, 2, 0),
}


#: The largest :attr:`ModelConfig.video_lstm_scale`: its weights grow with the square of the scale, and at 32 they,
#: their gradients and Adam's moments take tens of gigabytes (a scale of 1e8 overflowed torch's size arithmetic).
MAX_VIDEO_LSTM_SCALE = 32


@dataclass(frozen=True)
class ModelConfig:
    """Everything needed to rebuild a model (stored in checkpoints).

    The defaults are the 'fast' recipe that every benchmark uses; the 'paper' preset
    (:data:`piga.training.train.PRESETS`) overrides what the paper's appendix does differently.
    """

    system: Literal["pendulum", "spring", "gravity", "bouncing"] = "pendulum"
    """Physics family: one of :data:`SYSTEM_SHAPES`."""
    architecture: Literal["piga", "video-lstm", "in-ig"] = "piga"
    """Which model (:mod:`piga.world.variants`): "piga" (encoder, velocity estimator, the system's physics,
    decoder); "video-lstm", a black-box frame predictor (:mod:`piga.world.video_lstm`); "in-ig", piga's
    encoder, velocity estimator and decoder with an Interaction Network in place of the physics
    (:mod:`piga.world.interaction`). The two baselines have no physical parameters."""
    loss: Literal["joint", "pred-only", "separate"] = "joint"
    """Training scheme (the paper's Table 2 ablation): "joint", L_pred + α·L_rec into every part; "pred-only",
    L_pred alone (L_rec is still measured, never trained on, and there is no autoencoder warm-up);
    "separate", L_pred + α·L_rec with the gradients split: the encoder and decoder learn from L_rec only,
    the velocity estimator and what rolls the states forward (the physics) from L_pred only
    (:meth:`ObjectModel.forward` says where the gradient is stopped). Not for video-lstm, which has no such parts."""
    decoder: Literal["st", "mlp", "deconv", "broadcast"] = "st"
    """Decoder of object coordinates to frames: "st", the coordinate-consistent spatial-transformer decoder
    (:mod:`piga.world.decoder`); "mlp", the paper's black-box decoder ablation (:mod:`piga.world.mlp_decoder`),
    an MLP from the objects' coordinates to the frame; "deconv" and "broadcast", the black-box decoders of its
    unseen-region ablation (:mod:`piga.world.conv_decoders`): an MLP to a small feature map then transposed
    convolutions, and a spatial-broadcast decoder (each object's coordinates tiled over the grid with fixed x, y
    channels, stride-1 convolutions, objects composed by masks). Not for video-lstm, which has its own decoder."""
    video_lstm_scale: int = 1
    """VideoLSTM's size: its convolution channels (32 and 64), frame latent (128) and LSTM units (256) times this
    (2: more parameters than piga's on every scene of the prediction benchmark). Only for video-lstm."""
    broadcast_width: int = 16
    """The spatial-broadcast decoder's convolution channels (16: the per-pixel work of every object's maps at full
    resolution that a CPU affords; wider, a capacity check). Only with decoder "broadcast"."""
    physics_init: dict[str, float] = field(default_factory=dict)
    """Initial physical parameters (empty: the system's far-from-truth defaults)."""
    system_options: SystemOptions | None = None
    """The options of ``system`` only, an instance of its ``Options`` (e.g.
    :class:`piga.world.physics.PendulumOptions` of :class:`piga.world.physics.Pendulum`); None: their defaults."""
    dt: float = 0.05
    """Seconds per frame (from the data file)."""
    image_size: int = 64
    """H = W."""
    channels: int = 1
    """C."""
    n_objects: int = 1
    """N, the object slots of the encoder, decoder and physics (balls, digits); the data file's count unless
    chosen (``piga-train-model --objects``: the paper's Appendix E gives 3-body gravity 2 and 4). A slot count
    other than the scene's leaves an object unmodelled or a slot empty; the pendulum has one."""
    input_frames: int = 4
    """L, frames given to the encoder and velocity estimator."""
    pred_frames: int = 10
    """T_pred, frames predicted by the physics during training."""
    extrapolate_frames: int = 20
    """T_ext, frames predicted beyond T_pred when evaluating (capped by the sequence length); training
    never uses it. The paper's (L, T_pred, T_ext) give 20, and 24 for gravity."""
    alpha: float = 3.0
    """Weight α of the reconstruction loss."""
    pred_trim: float = 0.1
    """Fraction of each batch's windows with the largest prediction loss left out of L_pred (a
    least-trimmed-squares loss). Rare events the physics does not model, such as Gymnasium's ±8
    speed clip, then cannot bias g and a. Fitting true pendulum states shows that 5-10% removes
    the clip's -1% bias on a. 0 is the paper's plain mean (the paper preset)."""
    rec_frames: Literal["all", "input"] = "input"
    """Frames in the reconstruction loss: "all" L + T_pred (the paper preset), or "input" (the L input
    frames only: the encoder then runs on L frames per item instead of L + T_pred, 3.5x less
    work for the pendulum, and with overlapping windows every frame is still reconstructed)."""
    velocity_correction: bool = False
    """Velocity estimator: backward difference plus the paper's MLP (True, the paper preset), or the difference alone
    (exact for one Euler substep; see :class:`piga.world.velocity.VelocityConfig`)."""
    substeps: int = 1
    """Integrator substeps M per frame (the paper preset: 5 Euler; 1 Euler matches Gymnasium's pendulum exactly)."""
    integrator: Literal["euler", "rk4"] = "euler"
    """"euler" (semi-implicit, the paper's) or "rk4" (a continuous system under a held action; the
    'continuous' preset), see :mod:`piga.world.physics`."""
    velocity_hold: bool = False
    """Read the velocity at frame L through the integrator (:func:`piga.world.physics.hold_velocity`,
    using the action over the last input frame) instead of taking the backward difference as it.
    Needed when the system moves within a frame (substeps, RK4): there the difference lags the
    velocity at the frame by about dt·F/2. The 'continuous' preset sets it."""
    readout: Literal["centroid", "regress"] = "centroid"
    """Encoder readout: "centroid" (soft centroid of each mask) or "regress" (the paper's location network, the paper preset)."""
    mask_width: int = 16
    """Encoder mask-network channels."""
    loc_width: int = 32
    """Encoder location-network channels."""
    template_hidden: int = 200
    """Hidden units of the template generators (the paper: 200)."""
    template_size: int = 0
    """Side of each object template in template pixels (0: the image side). The scenes use H/2, as the
    published decoder does."""
    init_scale: float = 1.0
    """Initial spatial-transformer scale s, image pixels per template pixel; learned. With templates of
    H/2, the paper's s = 2 (balls: a template covering half the image) is 1 here, and its s = 1
    (digits: the whole image) is 2."""
    mask_pixelwise: bool = False
    """Encoder: add a full-resolution colour term to the mask logits (:class:`piga.world.encoder.EncoderConfig`)."""
    velocity_physics: bool = False
    """Add the engine's own velocity change dt·(2·a(p_L) + a(p_{L-1}))/6 to the estimator's velocity. The
    backward difference is the mean velocity over the last frame interval; this makes it v_L, exactly
    for a cubic path, with the current physics (the MLP, if on, corrects the rest). No gradient flows
    from this term into the physical parameters."""
    velocity_shoot: bool = False
    """Unactuated systems: the velocity at frame L is the one the engine ends the last input interval
    with when it starts at p_{L-1} and reaches p_L (shooting, :func:`piga.world.physics.hold_velocity`, from
    the estimator's velocity), with the current physical parameters detached as in ``velocity_physics``,
    which it replaces. Exact for noiseless positions when the engine is the data's. The cubic term of
    ``velocity_physics`` is not the engine's own (staggered, semi-implicit) velocity at dt = 0.3, and
    biases k and g low (``benchmarks/velocity_bias.py``)."""
    init_background: bool = False
    """Start the decoder's background content at the encoder's label-free median background
    (:meth:`piga.world.decoder.Decoder.init_background`). On the balls' black background the sigmoid
    content otherwise stalls a few levels above 0, and SSIM, whose luminance term compares means
    near 0, punishes that hard (a uniform 0.003 alone caps it near 0.92)."""

    def __post_init__(self) -> None:
        check_types(self)  # a number given as text fails here, naming the field, not at a comparison below
        if not isinstance(self.system, str) or self.system not in SYSTEM_SHAPES:
            raise ValueError(f"unknown system {self.system!r}; known: {', '.join(sorted(SYSTEM_SHAPES))}")
        check_choices(self)  # architecture, loss, decoder, rec_frames, integrator, readout
        if self.image_size < 8 or self.channels not in (1, 3) or self.substeps < 1:
            raise ValueError(f"ModelConfig needs image_size >= 8, channels 1 or 3 and substeps >= 1, got image_size="
                             f"{self.image_size}, channels={self.channels}, substeps={self.substeps}")
        check_ranges(self, {"init_scale": (0, math.inf)}, above=("init_scale",))
        if self.architecture == "video-lstm" and self.loss == "separate":
            raise ValueError("video-lstm has no separate encoder/decoder and dynamics to train apart: it takes loss "
                             f"'joint' or 'pred-only', not {self.loss!r}")
        if self.architecture == "video-lstm" and self.decoder != "st":
            raise ValueError(f"video-lstm draws its frames with its own network, not an object decoder: decoder "
                             f"{self.decoder!r} does not apply to it (leave the decoder out)")
        if not 1 <= self.video_lstm_scale <= MAX_VIDEO_LSTM_SCALE:
            raise ValueError(f"video_lstm_scale must be in [1, {MAX_VIDEO_LSTM_SCALE}] (its weights grow with its square), "
                             f"got {self.video_lstm_scale}")
        if self.video_lstm_scale != 1 and self.architecture != "video-lstm":
            raise ValueError(f"video_lstm_scale sizes the video-lstm baseline; architecture {self.architecture!r} has "
                             "its own sizes")
        if self.broadcast_width < 1:
            raise ValueError(f"broadcast_width must be >= 1, got {self.broadcast_width}")
        if self.broadcast_width != ModelConfig.broadcast_width and self.decoder != "broadcast":
            raise ValueError(f"broadcast_width sizes the spatial-broadcast decoder; decoder {self.decoder!r} has its "
                             "own sizes")
        if self.n_objects < 1:
            raise ValueError(f"n_objects must be >= 1, got {self.n_objects}")
        if self.system == "pendulum" and self.n_objects != 1:
            raise ValueError(f"a pendulum model has one object (its angle), not n_objects={self.n_objects}")
        if self.extrapolate_frames < 0:
            raise ValueError(f"extrapolate_frames must be >= 0, got {self.extrapolate_frames}")
        if self.input_frames < 2 or self.pred_frames < 1:
            raise ValueError(f"need input_frames >= 2 and pred_frames >= 1, got {self.input_frames}, {self.pred_frames}")
        options = SYSTEMS[self.system].Options
        if self.system_options is None:
            object.__setattr__(self, "system_options", options())
        elif type(self.system_options) is not options:
            raise ValueError(f"a {self.system} model takes {options.__name__}, not {type(self.system_options).__name__}")
        if not 0 <= self.pred_trim < 1:
            raise ValueError(f"pred_trim must be in [0, 1), got {self.pred_trim}")
        if not (math.isfinite(self.alpha) and self.alpha >= 0):  # nan passed "< 0", and the first loss was nan
            raise ValueError(f"ModelConfig.alpha must be a finite number >= 0, got {self.alpha}")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"ModelConfig.dt must be the seconds between frames, a finite number > 0, got {self.dt}")
        init = self.physics_init
        if not isinstance(init, Mapping) or not all(
                isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for k, v in init.items()):
            raise ValueError(f"ModelConfig.physics_init must map parameter names to finite numbers, got {init!r}"[:200])
        self.system_options.check_physics_init(init)
        if init:  # its names and values as the system takes them (they failed deep inside training before)
            try:
                SYSTEMS[self.system].for_model(self.system_options, self.dt, self.n_objects, self.image_size, dict(init))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"ModelConfig.physics_init {dict(init)!r} does not fit a {self.system} model: "
                                 f"{' '.join(str(exc).split())}"[:300]) from None

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> ModelConfig:
        """The config of a checkpoint (:meth:`to_dict`), or of one saved when every system's options were
        fields of their own (the flat form: the other systems' ones at their defaults, which are dropped).
        Option fields given flat override ``system_options``. A flat config lacking an option that came
        later (``SystemOptions.LEGACY``, e.g. the pendulum's ``pivot_gate``) was trained without it."""
        values = dict(values)
        system = values.get("system", cls.system)
        if system not in SYSTEMS:
            raise ValueError(f"unknown system {system!r}; known: {', '.join(sorted(SYSTEMS))}")
        options = SYSTEMS[system].Options
        nested = values.pop("system_options", None)
        shared = {f.name for f in fields(cls)}
        flat = {k: values.pop(k) for k in list(values) if k not in shared}
        given = nested if nested is not None else {**options.LEGACY}
        if isinstance(given, SystemOptions):
            given = asdict(given)
        return cls(**values, system_options=_options(system, {**given, **flat}))

    @property
    def coord_dim(self) -> int:
        """D."""
        return SYSTEM_SHAPES[self.system][1]

    @property
    def action_dim(self) -> int:
        """A."""
        return SYSTEM_SHAPES[self.system][2]

    @property
    def window(self) -> int:
        """Frames per training item: L + T_pred."""
        return self.input_frames + self.pred_frames

    def to_dict(self) -> dict[str, Any]:
        """JSON-able fields (``system_options`` as a dict of its own)."""
        return asdict(self)

    def with_options(self, **changes: Any) -> ModelConfig:
        """This config with some of its system's options changed, e.g. ``with_options(learn_damping=True)``."""
        return replace(self, system_options=_options(self.system, {**asdict(self.system_options), **changes}))


def _options(system: str, values: Mapping[str, Any]) -> SystemOptions:
    """The options of a ``system`` model from field values; another system's option at its default (a
    flat config holds every system's) is dropped, one set otherwise is refused in one line."""
    options = SYSTEMS[system].Options
    own = {f.name for f in fields(options)}
    others = {f.name: (name, f.default) for name, cls in SYSTEMS.items() if cls.Options is not options
              for f in fields(cls.Options)}  # option -> (its system, its default)
    for key, value in values.items():
        if key in own:
            continue
        if key not in others:
            raise ValueError(f"ModelConfig has no field or system option {key!r}")
        owner, default = others[key]
        if _plain(value) != _plain(default):
            raise ValueError(f"{key} is an option for {owner} models, not for a {system} model "
                             f"(its options: {', '.join(sorted(own)) or 'none'})")
    return options(**{k: v for k, v in values.items() if k in own})


def _plain(value: Any) -> Any:
    """A value as JSON stores it (a tuple as a list), for comparing a stored field with its default."""
    return list(value) if isinstance(value, tuple) else value


class ModelOutput(NamedTuple):
    """One forward pass on a training window."""

    loss: Tensor
    """Scalar, L_pred + α·L_rec."""
    loss_pred: Tensor
    """Scalar, Σ over predicted frames of the per-frame MSE (batch mean; trimmed in training if ``pred_trim``)."""
    loss_rec: Tensor
    """Scalar, Σ over all frames of the autoencoder's per-frame MSE (batch mean)."""
    target: Tensor
    """(B, L+T, C, H, W) the frames in [0, 1]."""
    pred: Tensor
    """(B, T_pred, C, H, W) frames rendered from the physics."""
    rec: Tensor
    """(B, L+T or L, C, H, W) frames rendered from the encoder's coordinates (see ``rec_frames``)."""
    coords: Tensor | None
    """(B, L+T or L, N, D) encoder coordinates (None: a model without object coordinates, video-lstm)."""
    coords_pred: Tensor | None
    """(B, T_pred, N, D) predicted coordinates (None as ``coords``)."""


def prediction_losses(config: ModelConfig, x: Tensor, pred: Tensor, rec: Tensor, training: bool) -> tuple[Tensor, Tensor, Tensor]:
    """(loss, loss_pred, loss_rec) of a window, the same for every model: L_pred the per-frame MSE of
    the predicted frames summed over them (trimmed in training by ``pred_trim``), L_rec the same of the
    reconstructed ones, and loss = L_pred + α·L_rec, or L_pred alone when ``config.loss`` is "pred-only"
    (L_rec is then reported, not trained on).

    Args:
        x: (B, L+T, C, H, W) the window's frames in [0, 1].
        pred: (B, T, C, H, W) the predicted frames L+1 .. L+T.
        rec: (B, R, C, H, W) the reconstructions of the first R frames.
    """
    ell = config.input_frames
    loss_rec = F.mse_loss(rec, x[:, : rec.shape[1]], reduction="none").mean(dim=(2, 3, 4)).sum(1).mean()
    per_window = F.mse_loss(pred, x[:, ell:], reduction="none").mean(dim=(2, 3, 4)).sum(1)  # (B,)
    drop = int(round(config.pred_trim * per_window.shape[0])) if training else 0
    loss_pred = per_window.sort().values[: per_window.shape[0] - drop].mean() if drop else per_window.mean()
    if config.loss == "pred-only":
        return loss_pred, loss_pred, loss_rec.detach()
    return loss_pred + config.alpha * loss_rec, loss_pred, loss_rec


def window_inputs(config: ModelConfig, frames: Tensor, actions: Tensor,
                  pred_frames: int | None) -> tuple[Tensor, int, Tensor | None]:
    """A training window made ready for a model's forward pass.

    Returns:
        The frames x (B, L+T, C, H, W) in [0, 1], T, and the actions after frames 1 .. L-1+T (B, L-1+T, A),
        the ones a prediction of T frames may use (None if unactuated).
    """
    ell = config.input_frames
    t_pred = config.pred_frames if pred_frames is None else pred_frames
    x = frames_to_float(frames, config.channels)[:, : ell + t_pred]  # (B, L+T, C, H, W)
    if x.shape[1] < ell + t_pred:
        raise ValueError(f"need {ell + t_pred} frames per item, got {x.shape[1]}")
    acts = actions[:, : ell - 1 + t_pred].float() if config.action_dim else None  # (B, L-1+T, A)
    return x, t_pred, acts


def frames_to_float(frames: Tensor, channels: int) -> Tensor:
    """uint8 (B, T, H, W) or (B, T, H, W, C) -> float (B, T, C, H, W) in [0, 1]; a tensor or a numpy array."""
    frames = torch.as_tensor(frames)  # read_sequences' numpy arrays too
    x = frames.float() / 255.0 if frames.dtype == torch.uint8 else frames.float()
    if x.dim() == 4:
        x = x.unsqueeze(2)  # (B, T, 1, H, W)
    elif x.dim() == 5 and x.shape[-1] == channels and x.shape[2] != channels:
        x = x.permute(0, 1, 4, 2, 3)  # (B, T, C, H, W)
    if x.dim() != 5 or x.shape[2] != channels:
        raise ValueError(f"frames must be (B, T, H, W) or (B, T, H, W, C={channels}), got {tuple(frames.shape)}")
    return x


class _Forces:
    """A system's constraints and constants with another force function (the physics, detached) for the integrator."""

    def __init__(self, system: System, acceleration: Any) -> None:
        self.system, self.acceleration = system, acceleration
        self.dt = system.dt

    def constrain(self, p: Tensor, v: Tensor) -> tuple[Tensor, Tensor]:
        return self.system.constrain(p, v)


class FrameModel(nn.Module):
    """What the training loop and the evaluation ask of a model: frames and actions in, predicted frames and
    the loss parts out. A model without physical parameters (a black-box baseline) keeps the defaults
    of the physics methods: no parameters, none learned."""

    #: Whether the model has physical parameters (a physics engine) that control and diagnosis can use.
    has_physics: ClassVar[bool] = False
    #: Whether the model encodes frames to object coordinates and renders them (``encode``, ``decoder``).
    has_objects: ClassVar[bool] = False
    #: Whether its decoder draws learned object templates (templates.png): the spatial-transformer decoder.
    has_templates: bool = False
    config: ModelConfig

    def physics_parameters(self) -> list[nn.Parameter]:
        """The tensors of the physical parameters (trained with ``lr_physics``; frozen ones included)."""
        return []

    def physical_parameters(self) -> dict[str, float]:
        """Current physical parameter values by name (none for a black-box model)."""
        return {}

    def learned_parameter_names(self) -> list[str]:
        """The physical parameters that training changes."""
        return []

    def set_background(self, background: Tensor) -> None:
        """Starts the model from the label-free background (C, H, W) of the training frames."""
        raise NotImplementedError

    def background_image(self) -> Tensor:
        """The label-free background (C, H, W) it was started from: the prediction of a model that learned nothing."""
        raise NotImplementedError

    def predict_frames(self, frames: Tensor, actions: Tensor | None, steps: int) -> tuple[Tensor, Tensor | None]:
        """Predicts ``steps`` frames after L input frames.

        Args:
            frames: (B, L, C, H, W) float input frames in [0, 1].
            actions: (B, L-1+steps, A), the actions after frames 1 .. L-1+steps (the last one moves the
                system into the last predicted frame); None if unactuated.

        Returns:
            The frames (B, steps, C, H, W) and, for a model of objects, their coordinates (B, steps, N, D), else None.
        """
        raise NotImplementedError

    def forward(self, frames: Tensor, actions: Tensor, pred_frames: int | None = None) -> ModelOutput:
        """Loss and renders on a window of L + T frames (uint8 or float; see module docstring).

        ``pred_frames`` (default: the config's T_pred) may be smaller, for a rollout curriculum;
        frames after L + pred_frames are then ignored.
        """
        raise NotImplementedError


def _split_actions(config: ModelConfig, actions: Tensor | None) -> tuple[Tensor | None, Tensor | None]:
    """The actions after frames 1 .. L-1+T (B, L-1+T, A) -> the ones after input frame L, L+1, ... (B, T, A)
    and the one after frame L-1 (B, A), as :meth:`ObjectModel.predict` takes them (None, None if unactuated)."""
    if actions is None:
        return None, None
    ell = config.input_frames
    return actions[:, ell - 1 :], actions[:, ell - 2]


class ObjectModel(FrameModel):
    """Encoder + velocity estimator + coordinate-consistent decoder, around what rolls the states forward
    (:meth:`predict`: the physics, or a learned dynamics)."""

    has_objects: ClassVar[bool] = True

    def __init__(self, config: ModelConfig, n_objects: int, coord_dim: int):
        super().__init__()
        self.config = config
        n, d = n_objects, coord_dim
        self.encoder = Encoder(EncoderConfig(config.image_size, config.channels, n, d, config.readout,
                                             config.mask_width, config.loc_width, pixelwise=config.mask_pixelwise,
                                             **config.system_options.encoder_fields()))
        self.velocity = VelocityEstimator(VelocityConfig(config.input_frames, n, d, config.dt, config.image_size,
                                                         correction=config.velocity_correction))

    def _add_decoder(self, n: int, d: int) -> None:
        """The decoder of ``config.decoder``, registered after the dynamics (the order of a piga checkpoint's parameters)."""
        cfg = self.config
        self.has_templates = cfg.decoder == "st"
        self.decoder: Decoder | MLPDecoder | DeconvDecoder | BroadcastDecoder
        if cfg.decoder == "mlp":
            self.decoder = MLPDecoder(cfg.image_size, cfg.channels, n, d, hidden=cfg.template_hidden)
        elif cfg.decoder == "deconv":
            self.decoder = DeconvDecoder(cfg.image_size, cfg.channels, n, d, hidden=cfg.template_hidden)
        elif cfg.decoder == "broadcast":
            self.decoder = BroadcastDecoder(cfg.image_size, cfg.channels, n, d, width=cfg.broadcast_width)
        else:
            self.decoder = Decoder(DecoderConfig(cfg.image_size, cfg.channels, n, d, hidden=cfg.template_hidden,
                                                 template_size=cfg.template_size or None, init_scale=cfg.init_scale))

    def background_image(self) -> Tensor:
        return self.encoder.background

    def set_background(self, background: Tensor) -> None:
        with torch.no_grad():
            self.encoder.background.copy_(background)
        if self.config.init_background:
            self.decoder.init_background(self.encoder.background)

    def encode(self, frames: Tensor) -> Tensor:
        """Float frames (B, T, C, H, W) -> coordinates (B, T, N, D)."""
        if not isinstance(frames, Tensor) or frames.dim() != 5:
            raise TypeError(f"encode takes float frames as a tensor (B, T, C, H, W), got {type(frames).__name__} "
                            f"{tuple(getattr(frames, 'shape', ()))}: convert them with piga.frames_to_float")
        expected = (self.config.channels, self.config.image_size, self.config.image_size)
        if tuple(frames.shape[2:]) != expected:  # (torch said "The size of tensor a (32) must match ... (64)")
            raise ValueError(f"encode takes frames of (C, H, W) = {expected}, the model's, got {tuple(frames.shape[2:])}")
        weight = next(self.encoder.parameters(), None)
        if not frames.is_floating_point() or (weight is not None and frames.dtype != weight.dtype):
            raise TypeError(f"encode takes {weight.dtype if weight is not None else 'float'} frames, got {frames.dtype}: "
                            "convert them with piga.frames_to_float")
        b, t = frames.shape[:2]
        coords = self.encoder(frames.flatten(0, 1).contiguous(memory_format=torch.channels_last))
        return coords.view(b, t, *coords.shape[1:])

    def predict(self, coords: Tensor, actions: Tensor | None, steps: int,
                last_action: Tensor | None = None) -> Tensor:
        """Rolls the states on from L encoded frames.

        Args:
            coords: (B, L, N, D), the encoder's coordinates of the input frames.
            actions: (B, steps, A), the actions after input frame L, L+1, ...; None if unactuated.
            steps: frames to predict.
            last_action: (B, A), the action after input frame L-1 (for ``velocity_hold``).

        Returns:
            (B, steps, N, D) coordinates of frames L+1 .. L+steps.
        """
        raise NotImplementedError

    def predict_frames(self, frames: Tensor, actions: Tensor | None, steps: int) -> tuple[Tensor, Tensor | None]:
        acts, last = _split_actions(self.config, actions)
        coords = self.predict(self.encode(frames), acts, steps, last)  # (B, steps, N, D)
        return self.decoder(coords), coords

    def forward(self, frames: Tensor, actions: Tensor, pred_frames: int | None = None) -> ModelOutput:
        """See :meth:`FrameModel.forward`. With ``config.loss == "separate"`` the gradient of L_pred is stopped
        at two places, so that it reaches the velocity estimator and the dynamics only:

        1. the input coordinates of the prediction are detached from the encoder (``coords[:, :L].detach()``):
           L_pred does not move the encoder, while the velocity estimator and the physics that follow get it;
        2. the predicted frames are drawn by the decoder with its parameters detached
           (``torch.func.functional_call`` with ``p.detach()`` for each): the gradient still flows through the
           rendering into the predicted coordinates, hence into the physics, but not into the decoder's parameters.

        L_rec reaches the encoder and decoder as in "joint"; it never reaches the velocity estimator or the
        physics, which it does not use.
        """
        cfg = self.config
        ell = cfg.input_frames
        separate = cfg.loss == "separate"
        x, t_pred, acts = window_inputs(cfg, frames, actions, pred_frames)  # x (B, L+T, C, H, W)
        coords = self.encode(x if cfg.rec_frames == "all" else x[:, :ell])  # (B, L+T or L, N, D)
        after, last = _split_actions(cfg, acts)  # (B, T, A), (B, A)
        given = coords[:, :ell].detach() if separate else coords[:, :ell]  # (B, L, N, D); stop 1
        coords_pred = self.predict(given, after, t_pred, last)  # (B, T, N, D)
        rec = self.decoder(coords)  # (B, L+T or L, C, H, W)
        if separate:  # stop 2: the decoder's parameters as constants, its input still differentiable
            frozen = {name: p.detach() for name, p in self.decoder.named_parameters()}
            pred = torch.func.functional_call(self.decoder, frozen, (coords_pred,))  # (B, T, C, H, W)
        else:
            pred = self.decoder(coords_pred)  # (B, T, C, H, W)
        loss, loss_pred, loss_rec = prediction_losses(cfg, x, pred, rec, self.training)
        return ModelOutput(loss, loss_pred, loss_rec, x, pred, rec, coords, coords_pred)


class PhysicsModel(ObjectModel):
    """Encoder + velocity estimator + differentiable physics + coordinate-consistent decoder."""

    has_physics: ClassVar[bool] = True

    def __init__(self, config: ModelConfig):
        # the system first: it knows its N and D (a pendulum is one angle whatever n_objects says)
        system = SYSTEMS[config.system].for_model(config.system_options, config.dt, config.n_objects, config.image_size,
                                                   config.physics_init)
        n, d = system.n_objects, system.coord_dim
        super().__init__(config, n, d)
        self.system: System = system
        self.integrator = make_integrator(config.integrator, config.substeps)
        self._add_decoder(n, d)

    def physics_parameters(self) -> list[nn.Parameter]:
        return list(self.system.parameters())

    def learned_parameter_names(self) -> list[str]:
        """The physical parameters that training changes, e.g. ``["k", "l"]``; a fixed one (gravity's g
        in the m run) is left out."""
        names = []
        for name in self.physical_parameters():
            param = getattr(self.system, f"log_{name}", None)
            if name == "a" and param is None:
                param = getattr(self.system, "a_signed", None)
            if name == "offset":
                param = self.system.offset
            if param is not None and param.requires_grad:
                names.append(name)
        return names

    def physical_parameters(self) -> dict[str, float]:
        """Current physical parameter values, e.g. ``{"g": 9.98, "a": 1.002}`` (plus ``offset``)."""
        values = self.system.parameters_dict()
        if hasattr(self.system, "offset"):
            values["offset"] = float(self.system.offset.detach())
        return values

    def initial_state(self, coords: Tensor, last_action: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Coordinates of L frames (B, L, N, D) -> (p_L, v_L), each (B, N, D).

        ``last_action`` (B, A) is the action over the last input frame (after frame L-1); it is
        needed, and used, only with ``velocity_hold``.
        """
        v = self.velocity(coords)  # (B, N, D)
        if self.config.velocity_hold and self.config.action_dim:
            if last_action is None:
                raise ValueError("this model reads velocities through its integrator (velocity_hold): "
                                 "initial_state needs the action over the last input frame")
            v = hold_velocity(self.system, self.integrator, coords[:, -2], v, last_action)
        elif self.config.velocity_shoot:
            frozen = {name: p.detach() for name, p in self.system.named_parameters()}

            def engine(p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:  # the system, parameters detached
                return torch.func.functional_call(self.system, frozen, (p, v, u))

            v = hold_velocity(_Forces(self.system, engine), self.integrator, coords[:, -2], v, None)
        elif self.config.velocity_physics:
            # The backward difference D is exact for a cubic path once corrected by dt·(2·a_L + a_{L-1})/6
            # (Taylor: D = v_L - a_L·dt/2 + ȧ·dt²/6). The physical parameters are detached here: they must
            # be identified by the rollout, not by the shortcut of bending the initial velocity.
            frozen = {name: p.detach() for name, p in self.system.named_parameters()}
            a_last = torch.func.functional_call(self.system, frozen, (coords[:, -1], v))  # (B, N, D)
            a_prev = torch.func.functional_call(self.system, frozen, (coords[:, -2], v))
            v = v + self.config.dt * (2 * a_last + a_prev) / 6
        return coords[:, -1], v

    def predict(self, coords: Tensor, actions: Tensor | None, steps: int,
                last_action: Tensor | None = None) -> Tensor:
        """Rolls the physics on from L encoded frames (see :meth:`ObjectModel.predict`)."""
        p0, v0 = self.initial_state(coords, last_action)
        positions, _ = rollout(self.system, self.integrator, p0, v0, actions, steps)
        return positions
