"""Candidate physics for a sim-to-real gap, fitted to encoded trajectories.

Each candidate is the nominal engine plus one or more unmodelled effects. Both are written once, in
:mod:`piga.world.effects` (the pendulum's equation and each effect's typed term: its parameter, unit,
starting grid, lower bound and stage), and shared with the model's engine
(:class:`piga.world.physics.Pendulum`), its integrators' step functions
(:func:`piga.world.physics.euler_step`, :func:`~piga.world.physics.rk4_step`) and the effect wrappers of
:mod:`envs.effects` (model convention: Gymnasium's θ = θ + φ):

| effect | parameter | where it acts |
|---|---|---|
| ``delay`` | integer k (steps) | ũ_t = u_{t-k} |
| ``deadzone`` | d (action units) | ũ = sign(u)·max(abs(u) - d, 0) |
| ``saturation`` | s (action units) | ũ = clip(u, -s, s) |
| ``damping`` | b (1/s) | torque -b·θ̇ |
| ``friction`` | c (rad/s²) | torque -c·tanh(θ̇ / 0.1) |
| ``bias`` | τ0 (rad/s²) | torque +τ0 |
| ``speed_clip`` | v (rad/s) | θ̇ clipped to ±v after each step |
| ``within_frame`` | integer M (substeps) | the system moves within the frame: M semi-implicit Euler steps of dt / M per frame, the action held |

θ̈ = 1.5·g·sin(θ + φ) + 3·a·ũ + 3·(passive torques); semi-implicit Euler with the nominal model's
substeps (or its RK4, and its own learned damping, when the nominal model has them: :class:`Nominal`).
A gain error (ũ = m·u) is not a separate term: it is the refitted a over the nominal a. A negative a
is a flipped actuation (a camera on the other side of the hinge, or a motor wired the other way):
its size is fitted in log space, its sign is held.

Units. The engine is a rod's θ̈ = (3 / m·l²)·τ + (3 / 2l)·g·sin θ with m = l = 1, so its "torques"
are torques per m·l² (per kg·m²): a term 3·b·θ̇ in rad/s² with θ̇ in rad/s makes b a rate, in 1/s;
c and τ0 are in rad/s². For a rod of mass m and length l, b·m·l² is the hinge's damping in
N·m·s/rad and c·m·l², τ0·m·l² are torques in N·m (equal numbers on Gymnasium's pendulum, where
m·l² = 1 kg·m²; on dm_control's, piga's b is its hinge damping d over 3·I, :mod:`envs.dmc`).

``within_frame``: a real system (or a simulator with fine physics steps, such as MuJoCo's) keeps
moving under the held action between two frames. Then the second difference of the frames sees
about (M + 1) / 2M of u_t and (M − 1) / 2M of u_{t−1}, and the backward difference lags the velocity
at the frame by about dt·F·(M − 1) / 2M, which one Euler step per frame reads as a lower a and g (and
a residual correlated with the action at lag 1 that no integer delay fits). The candidate simulates
M substeps per frame and reads the start velocity through them (the velocity whose frame step
reproduces the observed difference, :func:`piga.world.physics.shoot_velocity`, as the model's
:func:`~piga.world.physics.hold_velocity` does); M = 16 stands for a continuous system. M is searched over
the term's grid (:data:`piga.world.effects.WITHIN_FRAME`), as k is for a delay.

The substeps take the damping implicitly, as MuJoCo's Euler integrator does: q̇ <- (q̇ + h·f) / (1 + h·r)
with r = 3·b and f every other acceleration (:func:`piga.world.physics.euler_step`). Frames cannot tell
this from explicit damping with g, a and b scaled by 1 / (1 + h·r) (the two differ by (h·r)²), so the
convention fixes what they mean: MuJoCo's, the simulator whose coarse physics steps make the
difference matter (measured on the blind dm_control benchmark, where explicit substeps read g low by
0.95·h·r across 19 cases: 2.8% at h·r = 3.1%). At M = 16, the stand-in for a continuous system, h·r
is small and either reading is the continuous one. The report says how large the factor is.

The fits run on the encoded angles alone (no images, no labels), so they take seconds: L-BFGS in
float64 on the mean squared multi-step angle error over windows of the fit split.

Why :func:`simulate` is not the model's :func:`piga.world.physics.rollout`: the model's engine is an
``nn.Module`` whose learnable parameters train with the networks, on (B, N, D) float32 tensors, and its
equations are the *identified* physics (the effects are by design not in it: the diagnosis must find
them as a gap). The candidates' parameters are a plain dict of float64 scalars that L-BFGS and the
bootstrap refit thousands of times, and a delay needs the actions before the window. So
:func:`simulate` composes the same equation, terms and step functions over (B,) tensors itself.
"""

from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass, field
from dataclasses import replace as dataclass_replace

import numpy as np
import torch
from torch import Tensor

from envs.constants import MAX_ACTION
from piga.diagnostics.repeats import repeat_sources
from piga.io.runs import Nominal
from piga.world.effects import (
    CANDIDATES,
    DAMPING,
    DELAY,
    EFFECTS,
    WITHIN_FRAME,
    CommandTerm,
    Effect,
    TorqueTerm,
    VelocityTerm,
    acceleration_of,
    pendulum_coefficients,
    pendulum_gains,
)
from piga.world.physics import euler_step, rk4_step, shoot_velocity

MAX_DELAY = int(max(DELAY.grid))
"""Largest delay tried (steps)."""
HOLD_ITERATIONS = 3
"""Newton steps that read the start velocity through the frame step (``within_frame``)."""
START_ITERATIONS = 2
"""Gauss-Newton steps that fit a window's two start angles (:attr:`Windows.fit_starts`): the
errors are nearly linear in them (moves of a few mrad), and 2 from the read angles settle them."""


def nominal_damping(nominal: Nominal) -> float:
    """The nominal model's own damping b."""
    return float(nominal.b)


def implicit_rate(passive: list[tuple[TorqueTerm, Tensor | float]]) -> Tensor:
    """r = k_τ·Σb (1/s) of the damping terms in ``passive``: what :func:`euler_step` takes implicitly."""
    return pendulum_gains()[1] * sum((torch.as_tensor(v, dtype=torch.float64) for t, v in passive if t is DAMPING),
                                     torch.zeros((), dtype=torch.float64))


def nominal_integrator(nominal: Nominal) -> str:
    """The nominal model's integrator."""
    return str(nominal.integrator)


@dataclass(frozen=True)
class Windows:
    """Multi-step prediction problems cut from encoded sequences. B windows of H steps."""

    theta0: Tensor
    """(B,) angle at the start frame s."""
    v0: Tensor
    """(B,) velocity (θ_s - θ_{s-1}) / dt."""
    actions: Tensor
    """(B, MAX_DELAY + H) commanded actions u_{s - MAX_DELAY} .. u_{s + H - 1}."""
    target: Tensor
    """(B, H) encoded angles θ_{s+1} .. θ_{s+H}."""
    mask: Tensor
    """(B, H) 1 where the target exists (inside the sequence)."""
    sequence: Tensor
    """(B,) index of the window's sequence."""
    source: Tensor | None = None
    """(B, H) long or None. With repeated (stale) frames: which prediction each target repeats,
    0 for the start θ_s and j for the j-th predicted step. A camera that dropped frame t shows
    frame t - 1 again, so a model that knows it predicts the repeat (see :func:`squared_errors`)."""
    fit_starts: bool = False
    """Fit the two read angles that start each window (θ_s and θ_{s-1}, so its velocity) with the
    physics, as data like the targets, instead of taking them as read (:func:`loss`); only for
    windows of 2 or more steps."""
    substeps: int = 0
    """The recorded system's physics steps per frame, where its file says (dm_control: its ``action_repeat``, see
    :func:`piga.diagnostics.observe.system_substeps`): ``within_frame`` is fitted at that M, not searched over its
    grid; 0: not known. (Searched, M is a fit of its own that moves with the other effects: dm_control at 2 physics
    steps per frame with a hinge damping of 1.0 was named "within_frame, 3 substeps" beside the right damping, and
    with dampings of 0.07 to 1.5 sometimes 2 substeps, mostly none.)"""


def min_frames(horizon: int) -> int:
    """The fewest frames a sequence needs for one window of ``horizon`` steps (:func:`make_windows`): the first start
    is frame MAX_DELAY, so that every delay fitted has its actions."""
    return max(1, MAX_DELAY) + horizon + 1


def make_windows(theta: np.ndarray, actions: np.ndarray, rows: np.ndarray, horizon: int | None, stride: int,
                 dt: float, stale: np.ndarray | None = None, repeat: bool = False) -> Windows:
    """Windows from sequences ``rows`` of (N, T) angles and actions.

    Starts run from s = MAX_DELAY (so every delay up to MAX_DELAY has its actions) every ``stride``
    frames. ``horizon`` None rolls every window to the end of its sequence (free run), masked.

    ``stale`` (N, T) bool marks repeated frames (dropped or delayed by the camera). Then a window
    starts only where frames s - 1 and s are fresh (its velocity is a real difference), and a stale
    target is masked out, or with ``repeat`` kept and mapped to the prediction it repeats
    (:attr:`Windows.source`).
    """
    t = theta.shape[1]
    s_min = max(1, MAX_DELAY)
    h = t - 1 - s_min if horizon is None else horizon
    starts = np.arange(s_min, t - 1 if horizon is None else t - horizon, stride)
    if len(starts) == 0 or h < 1:
        raise ValueError(f"sequences of {t} frames are too short for windows of {h} steps after {s_min} frames")
    th0, v0, acts, target, mask, seq, src = [], [], [], [], [], [], []
    pad_t = np.pad(theta, ((0, 0), (0, h)), mode="edge")
    pad_u = np.pad(np.clip(actions, -MAX_ACTION, MAX_ACTION), ((0, 0), (0, h)))
    if stale is not None:
        pad_stale = np.pad(stale, ((0, 0), (0, h)), mode="edge")
        pad_src = np.pad(repeat_sources(stale), ((0, 0), (0, h)), mode="edge")
    for s in starts:
        r = rows if stale is None else rows[~stale[rows, s] & ~stale[rows, s - 1]]
        inside = np.broadcast_to(np.arange(s + 1, s + 1 + h) < t, (len(r), h))
        th0.append(theta[r, s])
        v0.append((theta[r, s] - theta[r, s - 1]) / dt)
        acts.append(pad_u[r, s - MAX_DELAY : s + h])
        target.append(pad_t[r, s + 1 : s + 1 + h])
        seq.append(r)
        if stale is not None and repeat:
            src.append(pad_src[r, s + 1 : s + 1 + h] - s)
        elif stale is not None:
            inside = inside & ~pad_stale[r, s + 1 : s + 1 + h]
        mask.append(inside)
    f = lambda x: torch.as_tensor(np.concatenate(x), dtype=torch.float64)  # noqa: E731
    source = torch.as_tensor(np.concatenate(src), dtype=torch.long) if src else None
    return Windows(f(th0), f(v0), f(acts), f(target), f(mask), torch.as_tensor(np.concatenate(seq)), source)


@dataclass
class Model:
    """A candidate: the nominal engine plus ``effects``, with its parameters."""

    effects: tuple[str, ...] = ()
    """Effects added (names of :data:`piga.world.effects.CANDIDATES`)."""
    delay: int = 0
    """k for the delay effect (0 without it)."""
    values: dict[str, float] = field(default_factory=dict)
    """Parameter values: g, a and each effect's parameter."""
    substeps: int = 0
    """M for the within_frame effect (0 without it: the nominal model's substeps)."""

    def __post_init__(self) -> None:
        unknown = [e for e in self.effects if e not in CANDIDATES]
        if unknown:
            raise ValueError(f"unknown effect(s) {unknown} in a candidate physics; known: {', '.join(CANDIDATES)}")
        # the delay and M a fit can use: those of the terms' grids (a longer delay has no actions in the windows)
        if not (isinstance(self.delay, numbers.Integral) and 0 <= self.delay <= MAX_DELAY):
            raise ValueError(f"Model.delay must be an integer from 0 to {MAX_DELAY} (frames); got {self.delay!r}")
        if not (isinstance(self.substeps, numbers.Integral) and 0 <= self.substeps <= max(WITHIN_FRAME.grid)):
            raise ValueError(f"Model.substeps must be an integer from 0 to {max(WITHIN_FRAME.grid)}; got {self.substeps!r}")

    @property
    def name(self) -> str:
        """"none", or the effects joined by "+"."""
        return "+".join(self.effects) if self.effects else "none"

    @property
    def terms(self) -> tuple[Effect, ...]:
        """The effects' typed terms, in the order of :data:`piga.world.effects.EFFECTS` (the order they apply in)."""
        return tuple(e for name, e in EFFECTS.items() if name in self.effects)

    def has(self, effect: Effect) -> bool:
        """Whether ``effect`` is among the effects."""
        return effect.name in self.effects

    @property
    def n_parameters(self) -> int:
        """Free parameters: g, a and one per effect (the delay and M count as one each)."""
        return 2 + len(self.effects)

    def with_values(self, values: dict[str, float]) -> Model:
        """The same effects, delay and M with other ``values``."""
        return Model(self.effects, self.delay, values, self.substeps)


def _value(term: Effect, params: dict[str, Tensor]) -> Tensor:
    """A term's parameter as the physics uses it: stopped at its lower bound."""
    value = params[term.parameter]
    return value if term.lower_bound is None else value.clamp_min(term.lower_bound)


def simulate(model: Model, params: dict[str, Tensor], nominal: Nominal, w: Windows, with_velocity: bool = False) -> Tensor:
    """Predicted angles (B, H) of windows ``w`` under ``model`` with (differentiable) ``params``.

    With ``with_velocity``, returns angles and velocities stacked: (B, H, 2). Only ``theta0``,
    ``v0``, ``actions`` and the horizon of ``w.target`` are used.
    """
    u = w.actions  # (B, MAX_DELAY + H)
    h_steps = w.target.shape[1]
    k = model.delay if model.has(DELAY) else 0
    within = model.has(WITHIN_FRAME)
    terms = model.terms
    # ũ over the frame before the start (for within_frame's start velocity) and the H frames after it
    padded = torch.cat([u.new_zeros(u.shape[0], 1), u], 1)  # (B, 1 + MAX_DELAY + H); u_{-MAX_DELAY-1} = 0
    cmd = padded[:, MAX_DELAY - k : MAX_DELAY - k + h_steps + 1]  # (B, H + 1)
    for term in terms:
        if isinstance(term, CommandTerm):
            cmd = term.transform(cmd, _value(term, params))
    g, a = params["log_g"].exp(), params["log_a"].exp() * params.get("a_sign", 1.0)
    substeps = model.substeps if within else nominal.substeps
    h = nominal.dt / substeps
    b_nominal = nominal_damping(nominal)
    torques = [(term, _value(term, params)) for term in terms if isinstance(term, TorqueTerm)]
    limits = [term for term in terms if isinstance(term, VelocityTerm)]

    def limit(v: Tensor) -> Tensor:
        for term in limits:
            v = term.limit(v, _value(term, params))
        return v

    passive = ([(DAMPING, b_nominal)] if b_nominal else []) + torques
    if within:  # the substeps take the damping implicitly, as MuJoCo's Euler does (see the module's text)
        step = functools.partial(euler_step, implicit_damping=implicit_rate(passive))
        passive = [(term, value) for term, value in passive if term is not DAMPING]
    else:
        step = rk4_step if nominal_integrator(nominal) == "rk4" else euler_step

    coefficients = pendulum_coefficients(g, gain=a, passive=passive)  # taken once, not at every step

    def frame(theta: Tensor, v: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
        def acceleration(q: Tensor, dq: Tensor) -> Tensor:
            return acceleration_of(coefficients, q, dq, nominal.offset, c)

        for _ in range(substeps):
            theta, v = step(acceleration, theta, v, h, limit if limits else None)
        return theta, v

    theta, v = w.theta0, w.v0
    if within or getattr(nominal, "velocity_hold", False):
        # v0 is the difference over the last frame: read the velocity at the start through the frame step
        v = shoot_velocity(lambda q, dq: frame(q, dq, cmd[:, 0]), theta - nominal.dt * v, v, nominal.dt,
                           HOLD_ITERATIONS)
    out, speeds = [], []
    for j in range(h_steps):
        theta, v = frame(theta, v, cmd[:, j + 1])
        out.append(theta)
        speeds.append(v)
    if with_velocity:
        return torch.stack([torch.stack(out, 1), torch.stack(speeds, 1)], -1)  # (B, H, 2)
    return torch.stack(out, 1)  # (B, H)


def as_observed(w: Windows, pred: Tensor) -> Tensor:
    """(B, H) predicted angles -> what the camera shows: at a repeated frame, the prediction (or the
    start angle) it repeats (:attr:`Windows.source`); unchanged without repeats."""
    if w.source is None:
        return pred
    return torch.cat([w.theta0[:, None].to(pred), pred], 1).gather(1, w.source)


def collapsed(model: Model, nominal: Nominal, factor: float = 1e3) -> bool:
    """A fit that ran off: a value that is not finite, g more than ``factor`` times away from the
    nominal's, |a| more than ``factor`` times above it or exactly 0 (their logs are fitted, and ran
    toward 0 or infinity: measured, g = 1e-10 on angles that a model read from frames under camera
    noise it did not take out). A small |a| is no run-off: a of the wrong sign shrinks toward 0,
    which is how a flipped actuation shows."""
    if not all(math.isfinite(v) for v in model.values.values()):
        return True
    g, a = model.values.get("g", nominal.g), abs(model.values.get("a", nominal.a))
    return not (nominal.g / factor < g < nominal.g * factor and 0 < a < abs(nominal.a) * factor)


def parameters_of(model: Model, nominal: Nominal) -> dict[str, Tensor]:
    """The tensors :func:`simulate` takes, from a model's values (defaults: nominal g, a; grid starts).

    a is fitted in log space; a negative a (a flipped actuation) keeps its sign in ``a_sign``, which
    is held, not fitted."""
    a, g = model.values.get("a", nominal.a), model.values.get("g", nominal.g)
    if not (g > 0 and a != 0 and math.isfinite(g) and math.isfinite(a)):  # (it was "math domain error", one line)
        from piga.diagnostics.observe import DiagnosisInputError

        raise DiagnosisInputError(f"a fit to this recording's angles ran off (g = {g:.3g}, a = {a:.3g}): the angles read "
                                  "from it are no pendulum motion that the model's physics can follow: a camera the "
                                  "model does not read (blurred, moved or cut off), or an effect far beyond the "
                                  "nominal physics")
    values = {"log_g": math.log(g), "log_a": math.log(abs(a))}
    for term in model.terms:
        if term.parameter is not None:
            values[term.parameter] = model.values.get(term.parameter, term.grid[0])
    params = {k: torch.tensor(float(v), dtype=torch.float64, requires_grad=True) for k, v in values.items()}
    if a < 0:
        params["a_sign"] = torch.tensor(-1.0, dtype=torch.float64)
    return params


def squared_errors(model: Model, nominal: Nominal, w: Windows, params: dict[str, Tensor] | None = None) -> Tensor:
    """(B, H) squared angle errors (masked to 0 outside the sequences)."""
    p = parameters_of(model, nominal) if params is None else params
    return (as_observed(w, simulate(model, p, nominal, w)) - w.target) ** 2 * w.mask


def with_starts(w: Windows, d: Tensor, dt: float) -> Windows:
    """``w`` with its read start angles θ_s and θ_{s-1} moved by ``d`` (B, 2) rad."""
    theta0 = w.theta0 + d[:, 0]
    before = w.theta0 - dt * w.v0 + d[:, 1]
    return dataclass_replace(w, theta0=theta0, v0=(theta0 - before) / dt, fit_starts=False)


def fitted_starts(model: Model, nominal: Nominal, w: Windows, params: dict[str, Tensor],
                  iterations: int = START_ITERATIONS, eps: float = 1e-6) -> Tensor:
    """(B, 2) the moves of each window's two start angles that minimise its squared errors, the
    targets' and the start angles' own (each read with the same error): Gauss-Newton from the read
    angles, each window a 2x2 problem, the Jacobian by forward differences (float64)."""
    d = torch.zeros(len(w.theta0), 2, dtype=torch.float64)
    eye = torch.eye(2, dtype=torch.float64)
    with torch.no_grad():
        for _ in range(iterations):
            def residuals(moves: Tensor) -> Tensor:  # (B, H)
                moved = with_starts(w, moves, nominal.dt)
                return (as_observed(moved, simulate(model, params, nominal, moved)) - w.target) * w.mask

            r = residuals(d)
            columns = []
            for k in range(2):
                step = torch.zeros_like(d)
                step[:, k] = eps
                columns.append((residuals(d + step) - r) / eps)
            jac = torch.stack(columns, -1)  # (B, H, 2)
            grad = (jac.transpose(1, 2) @ r[..., None])[..., 0] + d  # (B, 2)
            system = jac.transpose(1, 2) @ jac + eye  # (B, 2, 2)
            d = d - gauss_newton_step(system, grad)
    return d


def gauss_newton_step(system: Tensor, grad: Tensor) -> Tensor:
    """(B, 2) the solutions of the (B, 2, 2) ``system`` for the (B, 2) ``grad``, 0 for a window whose system cannot be
    solved: one whose simulation overflowed (a damping of 100 on nearly still frames) is not finite, and one whose
    Jacobian is finite but so large that adding the identity leaves it singular in float64 (dm_control's camera 0 on
    a model of the face-on camera); either made the solve fail ("the input matrix is singular"), an internal error.
    Such a window keeps its read starts."""
    finite = torch.isfinite(system).all(dim=(1, 2)) & torch.isfinite(grad).all(dim=1)
    eye = torch.eye(system.shape[-1], dtype=system.dtype).expand_as(system)
    step, info = torch.linalg.solve_ex(torch.where(finite[:, None, None], system, eye),
                                       torch.where(finite[:, None], grad, 0.0)[..., None])
    step = step[..., 0]
    ok = finite & (info == 0) & torch.isfinite(step).all(dim=1)
    return torch.where(ok[:, None], step, 0.0)


def loss(model: Model, nominal: Nominal, w: Windows, weights: Tensor | None = None,
         params: dict[str, Tensor] | None = None) -> Tensor:
    """Mean squared multi-step angle error (rad²), optionally weighted per window (B,).

    With ``w.fit_starts`` (and 2 or more steps) the start angles are fitted too (:func:`fitted_starts`),
    and count with the targets: the loss is profiled over them (variable projection). Its gradient
    in the parameters is the partial one at the fitted starts, which are therefore held fixed in the
    backward pass (the envelope theorem)."""
    if w.fit_starts and w.target.shape[1] > 1:
        p = parameters_of(model, nominal) if params is None else params
        d = fitted_starts(model, nominal, w, p)
        se = (squared_errors(model, nominal, with_starts(w, d, nominal.dt), p).sum(1) + (d**2).sum(1)) \
            / (w.mask.sum(1) + 2)  # (B,)
    else:
        se = squared_errors(model, nominal, w, params).sum(1) / w.mask.sum(1).clamp_min(1)  # (B,)
    if weights is None:
        return se.mean()
    return (se * weights).sum() / weights.sum()


def fit(model: Model, nominal: Nominal, w: Windows, weights: Tensor | None = None, max_iter: int = 60,
        fit_ga: bool = True) -> Model:
    """Fits g, a (unless ``fit_ga`` is False) and the effects' parameters; returns a new :class:`Model`.

    A continuous effect parameter starts from the best point of its term's grid (the loss is not
    convex in a deadzone or a clip level); L-BFGS then refines all parameters.
    """
    start = model.with_values(dict(model.values))
    for term in model.terms:
        name = term.parameter
        if name is None or name in model.values:
            continue
        best = None
        for value in term.grid:
            trial = start.with_values({**start.values, name: value})
            with torch.no_grad():
                score = float(loss(trial, nominal, w, weights))
            if best is None or score < best[0]:
                best = (score, value)
        start.values[name] = best[1]
    params = parameters_of(start, nominal)
    free = [p for k, p in params.items() if p.requires_grad and (fit_ga or not k.startswith("log_"))]
    if not free:
        return start
    opt = torch.optim.LBFGS(free, lr=1.0, max_iter=max_iter, line_search_fn="strong_wolfe", tolerance_grad=1e-12,
                            tolerance_change=1e-14)

    best: list = [math.inf, None]  # the lowest finite loss met, and its parameters

    def closure() -> Tensor:
        opt.zero_grad()
        value = loss(start, nominal, w, weights, params)
        value.backward()
        if float(value.detach()) < best[0]:  # (False for a NaN)
            best[:] = [float(value.detach()), {k: p.detach().clone() for k, p in params.items()}]
        return value

    opt.step(closure)

    def ga(params: dict[str, Tensor]) -> dict[str, float]:
        sign = float(params["a_sign"]) if "a_sign" in params else 1.0
        return {"g": float(params["log_g"].detach().exp()), "a": sign * float(params["log_a"].detach().exp())}

    values = ga(params)
    if best[1] is not None and not (all(math.isfinite(float(p.detach())) for p in params.values())
                                    and 0 < values["g"] < math.inf and 0 < abs(values["a"]) < math.inf):
        # a line search that stepped where the simulation overflows leaves the parameters NaN or g and a out of
        # float range (measured: saturation with the motion within the frame on 21 sequences of 14 frames with an
        # actuator delay of 2): the fit is the best finite point it met
        params = best[1]
        values = ga(params)
    bounds = {t.parameter: t.lower_bound for t in model.terms if t.lower_bound is not None}
    values.update({k: max(float(v.detach()), bounds.get(k, -math.inf)) for k, v in params.items()
                   if not k.startswith("log_") and k != "a_sign"})
    return model.with_values(values)


def fit_best_delay(effects: tuple[str, ...], base: dict[str, float], nominal: Nominal, w: Windows,
                   substeps: int = 0) -> Model:
    """Fits ``effects`` (which include "delay") for each k in 1..MAX_DELAY; returns the best."""
    best = None
    for k in DELAY.grid:
        m = fit(Model(effects, k, dict(base), substeps), nominal, w)
        score = fitted_loss(m, nominal, w)
        if best is None or score < best[0]:
            best = (score, m)
    return best[1]


def fitted_loss(model: Model, nominal: Nominal, w: Windows) -> float:
    """:func:`loss` of a fitted ``model``, the score by which a search over k or M picks one; inf for a fit that
    ran off (:func:`collapsed`), which scores last rather than stopping the search."""
    if collapsed(model, nominal):
        return math.inf
    with torch.no_grad():
        score = float(loss(model, nominal, w))
    return score if math.isfinite(score) else math.inf


def fit_candidate(effects: tuple[str, ...], base: dict[str, float], nominal: Nominal, w: Windows,
                  delay: int | None = None, substeps: int | None = None) -> Model:
    """Fits a candidate with ``effects``, starting from the values in ``base`` (g, a, ...).

    With a "delay" among the effects, ``delay`` holds k fixed; None searches k = 1..MAX_DELAY.
    With "within_frame", ``substeps`` holds M fixed; None takes the recorded system's (:attr:`Windows.substeps`), or
    where that is not known searches the effect's grid.
    """
    substeps = substeps if substeps is not None else (w.substeps or None)
    if WITHIN_FRAME.name in effects and substeps is None:
        best = None
        for m_sub in WITHIN_FRAME.grid:
            m = fit_candidate(effects, base, nominal, w, delay, m_sub)
            score = fitted_loss(m, nominal, w)
            if best is None or score < best[0]:
                best = (score, m)
        return best[1]
    m_sub = substeps if WITHIN_FRAME.name in effects else 0
    if DELAY.name in effects and delay is None:
        return fit_best_delay(effects, base, nominal, w, m_sub)
    return fit(Model(effects, delay if DELAY.name in effects else 0, dict(base), m_sub or 0), nominal, w)


def one_step_bic(model: Model, nominal: Nominal, w1: Windows) -> tuple[float, float]:
    """(BIC, RSS) of the one-step angle residuals on windows ``w1`` (horizon 1).

    BIC = n·ln(RSS / n) + p·ln(n), p = free parameters. One-step residuals are close to
    independent, unlike multi-step ones, so they are the ones counted.
    """
    with torch.no_grad():
        se = squared_errors(model, nominal, w1)[:, 0]
    n = se.numel()
    if n == 0:
        raise ValueError("no one-step window to score: every frame of the recording repeats the previous one or "
                         "the sequences are too short (a still or frozen video?)")
    rss = float(se.sum())
    return n * math.log(max(rss, 1e-300) / n) + model.n_parameters * math.log(n), rss


def horizon_errors(model: Model, nominal: Nominal, w: Windows) -> np.ndarray:
    """(H,) mean squared angle error (rad²) at each horizon 1..H over windows ``w`` (masked)."""
    with torch.no_grad():
        se = squared_errors(model, nominal, w)
    return (se.sum(0) / w.mask.sum(0).clamp_min(1)).numpy()


def window_errors(model: Model, nominal: Nominal, w: Windows) -> np.ndarray:
    """(B,) each window's mean squared angle error (rad²) over its steps (masked)."""
    with torch.no_grad():
        se = squared_errors(model, nominal, w)
    return (se.sum(1) / w.mask.sum(1).clamp_min(1)).numpy()


def bootstrap(model: Model, nominal: Nominal, w: Windows, replicates: int, seed: int) -> dict[str, list[float]]:
    """Refits ``model`` on ``replicates`` resamplings of the fit sequences; returns each parameter's values.

    The delay k is held at its estimate; the other parameters start from the estimates.
    """
    rng = np.random.default_rng(seed)
    seqs = torch.unique(w.sequence)
    draws: dict[str, list[float]] = {k: [] for k in model.values}
    for _ in range(replicates):
        pick = rng.integers(0, len(seqs), len(seqs))
        counts = torch.bincount(torch.as_tensor(pick), minlength=len(seqs)).double()
        lookup = torch.zeros(int(seqs.max()) + 1, dtype=torch.float64)
        lookup[seqs] = counts
        m = fit(model, nominal, w, weights=lookup[w.sequence], max_iter=30)
        for k, v in m.values.items():
            draws[k].append(v)
    return draws

