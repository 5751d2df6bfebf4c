"""The systems: each physical system defined once, as the acceleration of its generalised coordinates.

A :class:`System` holds one family's equations of motion q̈ = F(q, q̇, u) and its unknown physical
parameters (positive ones learned in log space, each with its unit). The integrators
(:mod:`piga.world.physics.integrators`) step any system; the pendulum's equation and its effect
terms are :mod:`piga.world.effects`, shared with the diagnosis, the planners and the effect wrappers.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from piga.io.choices import check_types, check_ranges
from piga.world.effects import DAMPING, pendulum_acceleration
from piga.world.encoder import ENCODER_RANGES, pivot_gate_pair

__all__ = ["System", "Pendulum", "Spring", "Gravity", "Bouncing", "SYSTEMS", "make_system", "SystemOptions",
           "PendulumOptions", "SpringOptions", "GravityOptions", "BouncingOptions"]


def _pairwise_differences(p: Tensor) -> Tensor:
    """d[b, i, j] = p[b, i] - p[b, j] for positions p of shape (B, N, D); returns (B, N, N, D)."""
    return p.unsqueeze(2) - p.unsqueeze(1)  # (B, N, N, D)


def _guarded_norm(d: Tensor, min_norm: float) -> Tensor:
    """Euclidean norm over the last axis, clamped below at ``min_norm``; returns (..., 1).

    The clamp is applied to the squared norm, before the square root, so coincident points give a
    finite value and zero (not NaN) gradient.
    """
    return d.square().sum(dim=-1, keepdim=True).clamp_min(min_norm**2).sqrt()


@dataclass(frozen=True)
class SystemOptions:
    """A world model's options for one system (:attr:`piga.world.model.ModelConfig.system_options`): what
    only a model of that system may set. Each :class:`System` names its own in :attr:`System.Options`."""

    LEGACY: ClassVar[dict[str, Any]] = {}
    """Values of options that a checkpoint saved before they existed lacks: the model it holds was trained
    without them (:meth:`piga.world.model.ModelConfig.from_dict`)."""

    def encoder_fields(self) -> dict[str, Any]:
        """The :class:`piga.world.encoder.EncoderConfig` fields these options set (none by default)."""
        return {}

    def check_physics_init(self, physics_init: Mapping[str, float]) -> None:
        """Refuses initial values (:attr:`piga.world.model.ModelConfig.physics_init`) that contradict the options."""


class System(nn.Module):
    """Base class of a physical system: q̈ = F(q, q̇, u) over generalised coordinates q, and its parameters.

    Subclasses set the four shape attributes, register their positive parameters with
    :meth:`_add_positive_parameter`, give their units in :attr:`units`, and implement
    :meth:`acceleration`. Systems with hard constraints (walls) also override :meth:`constrain`.
    An articulated system (a cart-pole, a double pendulum) fits the same interface: its
    :meth:`acceleration` solves its configuration-dependent mass matrix, M(q)·q̈ = f(q, q̇, u).

    Attributes:
        n_objects: N, the number of objects.
        coord_dim: D, generalised coordinates per object (1 for an angle, 2 for cartesian x, y).
        action_dim: A, the size of the action vector (0 if unactuated).
        dt: Seconds between two frames.
        reference_values: The physical parameters of the paper's data sets (for oracles and
            error reports); a learnable system never starts from them by default.
        units: Each physical parameter's unit.
    """

    reference_values: ClassVar[dict[str, float]] = {}
    units: ClassVar[dict[str, str]] = {}
    Options: ClassVar[type[SystemOptions]] = SystemOptions
    """The world model's options for this system."""

    @classmethod
    def for_model(cls, options: SystemOptions, dt: float, n_objects: int, image_size: int,
                  physics_init: Mapping[str, float]) -> System:
        """The system a world model learns: constructor arguments ``physics_init`` (the initial values)
        with what ``options`` (an instance of :attr:`Options`) make of them, N objects in frames of
        ``image_size`` pixels, ``dt`` seconds apart."""
        return cls(**{"dt": dt, **physics_init, "n_objects": n_objects})

    def __init__(self, n_objects: int, coord_dim: int, action_dim: int, dt: float) -> None:
        super().__init__()
        if n_objects < 1:
            raise ValueError(f"n_objects must be >= 1, got {n_objects}")
        if coord_dim < 1:
            raise ValueError(f"coord_dim must be >= 1 (an angle: 1, a position x, y: 2), got {coord_dim}")
        if action_dim < 0:
            raise ValueError(f"action_dim must be >= 0, got {action_dim}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.n_objects = int(n_objects)
        self.coord_dim = int(coord_dim)
        self.action_dim = int(action_dim)
        self.dt = float(dt)
        self._physical_names: list[str] = []

    # ----------------------------------------------------------------- parameters
    def _add_positive_parameter(self, name: str, value: float, learnable: bool) -> None:
        """Register ``log_<name>`` = log(value) as an ``nn.Parameter``; frozen if not learnable."""
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{type(self).__name__}: {name} must be a number, got {value!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{type(self).__name__}: {name} must be finite and > 0, got {value!r}")
        log_value = torch.tensor(math.log(value), dtype=torch.get_default_dtype())
        self.register_parameter(f"log_{name}", nn.Parameter(log_value, requires_grad=learnable))
        self._physical_names.append(name)

    @staticmethod
    def _resolve_learnable(
        cls_name: str, names: tuple[str, ...], learnable: bool | Collection[str]
    ) -> dict[str, bool]:
        """Map each parameter name to whether it is learned, validating a collection of names."""
        if isinstance(learnable, bool):
            return {name: learnable for name in names}
        if isinstance(learnable, str):
            learnable = (learnable,)
        unknown = sorted(set(learnable) - set(names))
        if unknown:
            raise ValueError(
                f"{cls_name}: unknown parameter name(s) {unknown} in learnable; "
                f"known: {list(names)}"
            )
        return {name: name in learnable for name in names}

    @torch.no_grad()
    def set_parameters(self, **values: float) -> None:
        """Overwrite physical parameters in place, e.g. ``set_parameters(g=14.0)``.

        For oracles, counterfactuals (a changed gravity) and float64 checks: the log is computed in
        float64 and then stored in the parameter's own dtype. ``requires_grad`` is unchanged.
        """
        for name, value in values.items():
            if name not in self._physical_names:
                raise ValueError(
                    f"{type(self).__name__} has no parameter {name!r}; known: {self._physical_names}"
                )
            value = float(value)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{type(self).__name__}: {name} must be finite and > 0, got {value!r}")
            getattr(self, f"log_{name}").fill_(math.log(value))

    def parameters_dict(self) -> dict[str, float]:
        """The current physical parameter values (positive values, not logs), for logging."""
        return {
            name: float(getattr(self, f"log_{name}").detach().exp()) for name in self._physical_names
        }

    # ------------------------------------------------------------------- dynamics
    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        """F(p, v, u): the acceleration of every object.

        Args:
            p: Positions, (B, N, D).
            v: Velocities, (B, N, D).
            u: Actions, (B, A), or None (no actuation).

        Returns:
            Accelerations, (B, N, D).
        """
        raise NotImplementedError

    def forward(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        """:meth:`acceleration` (so that ``torch.func.functional_call`` can evaluate it with other parameters)."""
        return self.acceleration(p, v, u)

    def constrain(self, p: Tensor, v: Tensor) -> tuple[Tensor, Tensor]:
        """Apply hard constraints after each substep; the identity unless a subclass has walls."""
        return p, v

    def extra_repr(self) -> str:
        values = ", ".join(f"{k}={v:.4g}" for k, v in self.parameters_dict().items())
        return f"N={self.n_objects}, D={self.coord_dim}, A={self.action_dim}, dt={self.dt}" + (
            f", {values}" if values else ""
        )


#: The largest initial damping b: 1e3 damps a pendulum of Gymnasium's size within one 0.05 s step already.
DAMPING_INIT_MAX = 1e3


@dataclass(frozen=True)
class PendulumOptions(SystemOptions):
    """A pendulum model's options."""

    LEGACY: ClassVar[dict[str, Any]] = {"pivot_gate": (0.0, 0.0)}

    learn_offset: bool = False
    """Learn the angle offset φ between the model's angle and upright. Needed
    when the encoder's angle convention is arbitrary (the "regress" readout; the paper preset
    learns it). The centroid readout is anchored by geometry (θ = 0: the object straight above the
    pivot, i.e. the camera is upright), and a learnable φ there only adds a flat direction (encoder
    convention, template orientation and φ drifting together) that drags g and a around; so it is
    frozen by default."""
    learn_damping: bool = False
    """Add a learnable viscous damping b to the engine (θ̈ = ... − 3·b·θ̇), starting
    at ``damping_init``. A real hinge has friction; Gymnasium's pendulum has none."""
    damping_init: float = 0.01
    """Initial b when ``learn_damping`` (far from any real hinge's value)."""
    signed_actuation: bool = False
    """Learn a in linear space, sign included (:class:`Pendulum`), for a camera on the other side or a
    motor wired the other way; a then starts at +0.3 and may cross 0."""
    angle_reference: float = 0.0
    """Centroid readout of the angle: the direction read as θ = 0 (the learned offset φ absorbs it)."""
    pivot_gate: tuple[float, float] = (0.125, 0.16)
    """Centroid readout of the angle: radii (fractions of the image side) within which pixels do not
    vote, so Gymnasium's torque arrow at the pivot cannot move the reading
    (:class:`piga.world.encoder.EncoderConfig`)."""

    def __post_init__(self) -> None:
        check_types(self)
        check_ranges(self, {"damping_init": (0, DAMPING_INIT_MAX), "angle_reference": ENCODER_RANGES["angle_reference"]},
                     above=("damping_init",))
        object.__setattr__(self, "pivot_gate", pivot_gate_pair(self.pivot_gate, "PendulumOptions"))  # JSON gives a list

    def encoder_fields(self) -> dict[str, Any]:
        return {"angle_reference": self.angle_reference, "pivot_gate": self.pivot_gate}


class Pendulum(System):
    """Gymnasium's ``Pendulum-v1`` with a learnable gravity g and actuation gain a.

    | quantity | value |
    |---|---|
    | state | θ (rad, 0 upright, positive counter-clockwise as displayed), θ̇ (rad/s) |
    | action | torque u, (B, 1) |
    | dynamics | θ̈ = (3 / 2l)·g·sin(θ + φ) + (3 / m l²)·(a·u − b·θ̇), i.e. 1.5·g·sin(θ + φ) + 3·a·u − 3·b·θ̇ for m = l = 1 |
    | step | dt = 0.05 |
    | truth | g = 10, a = 1 |

    Gymnasium clips θ̇ to ±8 after each step; that clip is intentionally not modelled.

    φ (``offset``, radians, not positive so not in log space) is where upright lies in the
    model's angle: Gymnasium's θ = model θ + φ. An encoder/decoder pair learned without labels
    may settle on any template orientation; a learnable φ lets the physics absorb it smoothly
    instead of forcing the templates to re-orient (a local minimum). φ = 0 (fixed) is the paper's
    engine; ``learnable`` may name "offset" or leave it out.

    Args:
        g: Initial gravity (default 1, far from the true 10).
        a: Initial actuation gain (default 0.3, far from the true 1).
        length: Rod length l, fixed (not learned).
        mass: Rod mass m, fixed (not learned).
        dt: Seconds per frame.
        offset: Initial angle offset φ (default 0).
        damping: Initial viscous damping b, or None for the paper's engine without damping (the
            default). A real hinge has friction; Gymnasium's pendulum has none.
        signed_actuation: Learn a as a plain number (``a_signed``) instead of in log space, so that
            it can turn negative: a camera on the other side of the hinge, or a motor wired the
            other way, flips the sign of the actuation that the frames show. In log space a can
            only shrink toward 0 on such data.
        learnable: True (all), False (none, e.g. an oracle), or the names to learn among
            "g", "a", "offset" and (with ``damping``) "b".
    """

    reference_values: ClassVar[dict[str, float]] = {"g": 10.0, "a": 1.0}
    units: ClassVar[dict[str, str]] = {"g": "m/s²", "a": "factor on the torque", "offset": "rad", "b": DAMPING.unit}
    Options: ClassVar[type[SystemOptions]] = PendulumOptions

    @classmethod
    def for_model(cls, options: SystemOptions, dt: float, n_objects: int, image_size: int,
                  physics_init: Mapping[str, float]) -> System:
        """g, a (and the options' φ, b) learned; one object whatever ``n_objects`` says."""
        assert isinstance(options, PendulumOptions)
        kwargs: dict[str, Any] = {"dt": dt, **physics_init}
        kwargs["learnable"] = ("g", "a", "offset") if options.learn_offset else ("g", "a")
        if options.learn_damping:
            kwargs["damping"] = kwargs.get("damping", options.damping_init)
            kwargs["learnable"] += ("b",)
        if options.signed_actuation:
            kwargs["signed_actuation"] = True
        return cls(**kwargs)

    def __init__(
        self,
        g: float = 1.0,
        a: float = 0.3,
        length: float = 1.0,
        mass: float = 1.0,
        dt: float = 0.05,
        offset: float = 0.0,
        learnable: bool | Collection[str] = True,
        damping: float | None = None,
        signed_actuation: bool = False,
    ) -> None:
        super().__init__(n_objects=1, coord_dim=1, action_dim=1, dt=dt)
        if not length > 0:
            raise ValueError(f"Pendulum: length must be > 0, got {length}")
        if not mass > 0:
            raise ValueError(f"Pendulum: mass must be > 0, got {mass}")
        self.length = float(length)
        self.mass = float(mass)
        names = ("g", "a", "offset") + (("b",) if damping is not None else ())
        flags = self._resolve_learnable("Pendulum", names, learnable)
        self._add_positive_parameter("g", g, flags["g"])
        self.signed_actuation = bool(signed_actuation)
        if self.signed_actuation:
            if not (math.isfinite(float(a)) and a != 0):
                raise ValueError(f"Pendulum: a must be finite and nonzero, got {a!r}")
            self.a_signed = nn.Parameter(torch.tensor(float(a)), requires_grad=flags["a"])
        else:
            self._add_positive_parameter("a", a, flags["a"])
        self.offset = nn.Parameter(torch.tensor(float(offset)), requires_grad=flags["offset"])
        self.has_damping = damping is not None
        if damping is not None:
            self._add_positive_parameter("b", damping, flags["b"])

    @property
    def g(self) -> Tensor:
        """Gravity, exp(log_g)."""
        return self.log_g.exp()

    @property
    def a(self) -> Tensor:
        """Actuation gain, exp(log_a) (or ``a_signed`` with ``signed_actuation``)."""
        return self.a_signed if self.signed_actuation else self.log_a.exp()

    def parameters_dict(self) -> dict[str, float]:
        values = super().parameters_dict()
        if self.signed_actuation:
            values = {"g": values.pop("g"), "a": float(self.a_signed.detach()), **values}
        return values

    @torch.no_grad()
    def set_parameters(self, **values: float) -> None:
        if self.signed_actuation and "a" in values:
            a = float(values.pop("a"))
            if not (math.isfinite(a) and a != 0):
                raise ValueError(f"Pendulum: a must be finite and nonzero, got {a!r}")
            self.a_signed.fill_(a)
        super().set_parameters(**values)

    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        actuation = None if u is None else (self.a, u.unsqueeze(-1))  # u: (B, 1) -> (B, 1, 1)
        passive = [(DAMPING, self.log_b.exp())] if self.has_damping else []
        return pendulum_acceleration(p, v, self.g, self.offset, self.length, self.mass, actuation=actuation,
                                     passive=passive)  # (B, 1, 1)


@dataclass(frozen=True)
class SpringOptions(SystemOptions):
    """A spring model's options: none."""


class Spring(System):
    """N objects of unit mass joined pairwise by identical springs (the paper's 2-balls spring).

    The force on object i from object j, with d = p_i - p_j, is -k·(abs(d) - 2l)·d / abs(d): l is half
    the rest length (the published code's convention). True values: (k, l) = (4, 6) for the balls
    data set, (2, 12) for the digits.

    Args:
        n_objects: N.
        k: Initial spring constant (default 1, far from the truth).
        l: Initial half rest length in pixels (default 1, far from the truth).
        dt: Seconds per frame.
        min_distance: abs(d) is clamped below at this many pixels so that coincident objects give
            a finite force and gradient.
        learnable: True (all), False (none), or the names to learn.
    """

    reference_values: ClassVar[dict[str, float]] = {"k": 4.0, "l": 6.0}
    units: ClassVar[dict[str, str]] = {"k": "1/s² (per unit mass)", "l": "px"}
    Options: ClassVar[type[SystemOptions]] = SpringOptions

    def __init__(
        self,
        n_objects: int = 2,
        k: float = 1.0,
        l: float = 1.0,  # noqa: E741 - the paper's name
        dt: float = 0.3,
        min_distance: float = 1e-4,
        learnable: bool | Collection[str] = True,
    ) -> None:
        super().__init__(n_objects=n_objects, coord_dim=2, action_dim=0, dt=dt)
        if not min_distance > 0:
            raise ValueError(f"Spring: min_distance must be > 0, got {min_distance}")
        self.min_distance = float(min_distance)
        flags = self._resolve_learnable("Spring", ("k", "l"), learnable)
        self._add_positive_parameter("k", k, flags["k"])
        self._add_positive_parameter("l", l, flags["l"])

    @property
    def k(self) -> Tensor:
        """Spring constant, exp(log_k)."""
        return self.log_k.exp()

    @property
    def l(self) -> Tensor:  # noqa: E743 - the paper's name
        """Half the rest length, exp(log_l)."""
        return self.log_l.exp()

    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        d = _pairwise_differences(p)  # (B, N, N, 2)
        dist = _guarded_norm(d, self.min_distance)  # (B, N, N, 1)
        force = -self.k * (dist - 2.0 * self.l) * d / dist  # (B, N, N, 2); zero on the diagonal
        return force.sum(dim=2)  # (B, N, 2)


#: The values ``GravityOptions.fixed_g`` may take besides 0: --fixed-g 1e308 and 1e-300 made the loss NaN at the
#: first step (the mass 1/fixed_g is 0 or inf in float32).
FIXED_G_RANGE = (1e-6, 1e6)


@dataclass(frozen=True)
class GravityOptions(SystemOptions):
    """A gravity model's options."""

    fixed_g: float = 0.0
    """The paper's m run. Hold g at this value (the user's; training never reads the
    file's parameters) and learn the bodies' shared mass m instead; 0 (the default): learn g with
    unit masses. The motion depends on g·m only, so m starts at 1/``fixed_g``: the force starts as
    weak as in the g run (g = 1, m = 1), far from any true g·m."""

    def __post_init__(self) -> None:
        check_types(self)
        if not (self.fixed_g == 0 or FIXED_G_RANGE[0] <= self.fixed_g <= FIXED_G_RANGE[1]):
            from envs.fields import number_text  # here: the model is built without gymnasium's import

            raise ValueError(f"fixed_g must be in [{FIXED_G_RANGE[0]:g}, {FIXED_G_RANGE[1]:g}] (or 0: learn g), got "
                             f"{number_text(self.fixed_g)}: the mass starts at 1/fixed_g, which float32 must hold with room to learn")

    def check_physics_init(self, physics_init: Mapping[str, float]) -> None:
        if self.fixed_g and "g" in physics_init:
            raise ValueError("fixed_g holds g at its value; physics_init must not set g as well")


class Gravity(System):
    """N bodies of one shared mass m under Newtonian gravity (the paper's 3-balls gravity).

    The force between bodies i and j is g·m_i·m_j / abs(d)², so the acceleration of body i is
    Σ_{j≠i} -g·m_j·d / abs(d)³ with d = p_i - p_j. True values g = 60, m = 1.

    The paper learns either g with the masses fixed (m = 1, the default here: m is then a constant,
    not a parameter) or m with g fixed (``mass`` given, ``learnable=("m",)``). With one shared mass
    the motion depends on g·m only, so learning both is a flat direction and is refused.

    Args:
        n_objects: N.
        g: Initial gravitational constant (default 1, far from the truth), or its fixed value.
        dt: Seconds per frame.
        softening: abs(d) is clamped below at this many pixels (the published code clips at 1):
            exact for bodies further apart, a bounded force and finite gradient for closer ones.
        mass: None for unit masses (a constant, the paper's g run), or the initial shared mass m,
            registered as the parameter ``log_m``.
        learnable: True (all), False (none), or the names to learn among "g" and (with ``mass``)
            "m"; not both.
    """

    reference_values: ClassVar[dict[str, float]] = {"g": 60.0}
    units: ClassVar[dict[str, str]] = {"g": "px³/s² per unit mass", "m": "mass units"}
    Options: ClassVar[type[SystemOptions]] = GravityOptions

    @classmethod
    def for_model(cls, options: SystemOptions, dt: float, n_objects: int, image_size: int,
                  physics_init: Mapping[str, float]) -> System:
        """g learned with unit masses, or (``fixed_g``) g held and the shared mass m learned from 1/g."""
        assert isinstance(options, GravityOptions)
        kwargs: dict[str, Any] = {"dt": dt, **physics_init, "n_objects": n_objects}
        if options.fixed_g:
            kwargs.update(g=options.fixed_g, learnable=("m",))
            kwargs.setdefault("mass", 1.0 / options.fixed_g)
        return cls(**kwargs)

    def __init__(
        self,
        n_objects: int = 3,
        g: float = 1.0,
        dt: float = 0.5,
        softening: float = 1.0,
        learnable: bool | Collection[str] = True,
        mass: float | None = None,
    ) -> None:
        super().__init__(n_objects=n_objects, coord_dim=2, action_dim=0, dt=dt)
        if not softening > 0:
            raise ValueError(f"Gravity: softening must be > 0, got {softening}")
        self.softening = float(softening)
        names = ("g", "m") if mass is not None else ("g",)
        flags = self._resolve_learnable("Gravity", names, learnable)
        if flags["g"] and flags.get("m", False):
            raise ValueError("Gravity: g and m enter the motion only as g·m, so they cannot both be learned; "
                             "learn one and fix the other")
        self._add_positive_parameter("g", g, flags["g"])
        self.has_mass = mass is not None
        if mass is not None:
            self._add_positive_parameter("m", mass, flags["m"])

    @property
    def g(self) -> Tensor:
        """Gravitational constant, exp(log_g)."""
        return self.log_g.exp()

    @property
    def m(self) -> Tensor:
        """The shared mass, exp(log_m), or 1 (a constant) without ``mass``."""
        return self.log_m.exp() if self.has_mass else self.log_g.new_ones(())

    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        d = _pairwise_differences(p)  # (B, N, N, 2)
        dist = _guarded_norm(d, self.softening)  # (B, N, N, 1)
        acc = -self.g * self.m * d / dist**3  # (B, N, N, 2); zero on the diagonal
        return acc.sum(dim=2)  # (B, N, 2)


@dataclass(frozen=True)
class BouncingOptions(SystemOptions):
    """A bouncing-balls model's options."""

    wall_radius: float = 2.0
    """How far from the image edge a centre bounces, pixels (the published engine's 2)."""


class Bouncing(System):
    """N balls moving freely in a square box with elastic walls; no force, no parameters.

    A ball's centre stays in [radius, size - radius] in each coordinate. :meth:`constrain`
    reflects a centre that left that interval back inside and flips that velocity component.

    Args:
        n_objects: N.
        size: Side of the box in pixels (the image size).
        radius: Ball radius in pixels.
        dt: Seconds per frame.
    """

    Options: ClassVar[type[SystemOptions]] = BouncingOptions

    @classmethod
    def for_model(cls, options: SystemOptions, dt: float, n_objects: int, image_size: int,
                  physics_init: Mapping[str, float]) -> System:
        """The box is the image; the walls ``wall_radius`` from its edges (unless ``physics_init`` says otherwise)."""
        assert isinstance(options, BouncingOptions)
        kwargs: dict[str, Any] = {"dt": dt, **physics_init, "n_objects": n_objects}
        kwargs.setdefault("size", float(image_size))
        kwargs.setdefault("radius", options.wall_radius)
        return cls(**kwargs)

    def __init__(
        self, n_objects: int = 2, size: float = 32.0, radius: float = 2.0, dt: float = 0.3
    ) -> None:
        super().__init__(n_objects=n_objects, coord_dim=2, action_dim=0, dt=dt)
        if not radius >= 0:
            raise ValueError(f"Bouncing: radius must be >= 0, got {radius}")
        if not size > 2 * radius:
            raise ValueError(f"Bouncing: size must be > 2 * radius = {2 * radius}, got {size}")
        self.size = float(size)
        self.radius = float(radius)

    def acceleration(self, p: Tensor, v: Tensor, u: Tensor | None = None) -> Tensor:
        return torch.zeros_like(p)

    def constrain(self, p: Tensor, v: Tensor) -> tuple[Tensor, Tensor]:
        """Reflect off the walls once: p -> 2·wall - p and v -> -v where p crossed a wall.

        A single reflection per call, so a substep must move a ball less than the box width.
        """
        low, high = self.radius, self.size - self.radius
        below, above = p < low, p > high  # (B, N, 2)
        p = torch.where(below, 2 * low - p, torch.where(above, 2 * high - p, p))
        v = torch.where(below | above, -v, v)
        return p, v


SYSTEMS: dict[str, type[System]] = {
    "pendulum": Pendulum,
    "spring": Spring,
    "gravity": Gravity,
    "bouncing": Bouncing,
}
"""Name -> system class, for :func:`make_system`, the world model (:meth:`System.for_model`, with the
class's :attr:`System.Options`) and the command line: a new system is its class and one line here."""


def make_system(name: str, **kwargs: object) -> System:
    """Build the system registered as ``name`` with constructor keyword arguments ``kwargs``."""
    try:
        cls = SYSTEMS[name]
    except KeyError:
        raise ValueError(f"unknown system {name!r}; known: {', '.join(sorted(SYSTEMS))}") from None
    return cls(**kwargs)  # type: ignore[arg-type]
