"""Candidate physics for a sim-to-real gap, fitted to encoded trajectories.

Each candidate is the nominal engine plus one or more unmodelled effects, with the same equations
as the effect wrappers of :mod:`envs.effects` (model convention: Gymnasium's θ = θ + φ):

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
reproduces the observed difference, as :func:`piga.world.physics.hold_velocity` does); M = 16 stands for
a continuous system. M is searched over :data:`WITHIN_FRAME_SUBSTEPS`, as k is for a delay.

The fits run on the encoded angles alone (no images, no labels), so they take seconds: L-BFGS in
float64 on the mean squared multi-step angle error over windows of the fit split.

Why a second pendulum engine (:func:`simulate`) next to the model's
(:class:`piga.world.physics.Pendulum` with :class:`piga.world.physics.Euler`)? Without effects the two are the
same equations and the same semi-implicit Euler step, and they agree to rounding (a test checks
it). They stay apart because they serve different needs:

- The model's engine is one of several :class:`piga.world.physics.System` force functions, an
  ``nn.Module`` whose learnable parameters train with the networks, on (B, N, D) tensors in
  float32. Its equations are the *identified* physics; the effects are by design not in it
  (the diagnosis must find them as a gap).
- The diagnosis' engine adds the candidate effects, each with its own parameter, as optional
  terms, and acts on delayed and transformed commands (a delay needs the actions before the
  window). Its parameters are a plain dict of float64 scalars that L-BFGS and the bootstrap refit
  thousands of times; a module with ten optional parameters would only hide which are free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from envs.constants import MAX_ACTION
from envs.effects import FRICTION_SMOOTHING
from piga.diagnostics.repeats import repeat_sources
from piga.io.runs import Nominal, nominal_of  # noqa: F401 (nominal_of: re-exported for the diagnosis)

if TYPE_CHECKING:
    from piga.world.model import PhysicsModel

#: Effects that the fit can add to the physics, in the order of the report.
CANDIDATES: tuple[str, ...] = ("damping", "friction", "bias", "delay", "deadzone", "saturation", "speed_clip",
                               "within_frame")
#: Continuous parameter of each effect (delay is discrete).
PARAMETER: dict[str, str] = {"damping": "b", "friction": "c", "bias": "tau0", "deadzone": "d", "saturation": "s",
                             "speed_clip": "v"}
#: Starting grids for the continuous parameters (the best grid point starts L-BFGS).
GRIDS: dict[str, tuple[float, ...]] = {
    "damping": (0.0, 0.05, 0.1, 0.2, 0.4),
    "friction": (0.0, 0.05, 0.1, 0.2, 0.4),
    "bias": (-0.3, -0.1, 0.0, 0.1, 0.3),
    "deadzone": (0.05, 0.2, 0.4, 0.7, 1.0),
    "saturation": (0.5, 0.8, 1.1, 1.4, 1.8),
    "speed_clip": (2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
}
MAX_DELAY = 4
"""Largest delay tried (steps)."""
WITHIN_FRAME_SUBSTEPS: tuple[int, ...] = (2, 3, 4, 8, 16)
"""Substeps M tried for ``within_frame`` (16: close to a continuous system)."""
HOLD_ITERATIONS = 3
"""Newton steps that read the start velocity through the frame step (``within_frame``)."""
#: Smallest value that :func:`simulate` uses for a limit (a saturation level, a speed clip): the
#: fit may move the free parameter below it, but the physics, and so the reported value, stop there.
LOWER_BOUNDS: dict[str, float] = {"s": 1e-3, "v": 0.1}


def nominal_damping(nominal: Nominal) -> float:
    """The nominal model's own damping b."""
    return float(nominal.b)


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
    """Effects added (a subset of :data:`CANDIDATES`)."""
    delay: int = 0
    """k for the delay effect (0 without it)."""
    values: dict[str, float] = field(default_factory=dict)
    """Parameter values: g, a and each effect's parameter."""
    substeps: int = 0
    """M for the within_frame effect (0 without it: the nominal model's substeps)."""

    @property
    def name(self) -> str:
        """"none", or the effects joined by "+"."""
        return "+".join(self.effects) if self.effects else "none"

    @property
    def n_parameters(self) -> int:
        """Free parameters: g, a and one per effect (the delay and M count as one each)."""
        return 2 + len(self.effects)

    def with_values(self, values: dict[str, float]) -> Model:
        """The same effects, delay and M with other ``values``."""
        return Model(self.effects, self.delay, values, self.substeps)


def simulate(model: Model, params: dict[str, Tensor], nominal: Nominal, w: Windows, with_velocity: bool = False) -> Tensor:
    """Predicted angles (B, H) of windows ``w`` under ``model`` with (differentiable) ``params``.

    With ``with_velocity``, returns angles and velocities stacked: (B, H, 2). Only ``theta0``,
    ``v0``, ``actions`` and the horizon of ``w.target`` are used.
    """
    u = w.actions  # (B, MAX_DELAY + H)
    h_steps = w.target.shape[1]
    k = model.delay if "delay" in model.effects else 0
    within = "within_frame" in model.effects
    # ũ over the frame before the start (for within_frame's start velocity) and the H frames after it
    padded = torch.cat([u.new_zeros(u.shape[0], 1), u], 1)  # (B, 1 + MAX_DELAY + H); u_{-MAX_DELAY-1} = 0
    cmd = padded[:, MAX_DELAY - k : MAX_DELAY - k + h_steps + 1]  # (B, H + 1)
    if "deadzone" in model.effects:
        cmd = torch.sign(cmd) * torch.relu(cmd.abs() - params["d"])
    if "saturation" in model.effects:
        s = params["s"].clamp_min(LOWER_BOUNDS["s"])
        cmd = torch.minimum(torch.maximum(cmd, -s), s)
    g, a = params["log_g"].exp(), params["log_a"].exp() * params.get("a_sign", 1.0)
    substeps = model.substeps if within else nominal.substeps
    h = nominal.dt / substeps
    b_nominal = nominal_damping(nominal)
    rk4 = nominal_integrator(nominal) == "rk4" and not within

    def acceleration(theta: Tensor, v: Tensor, c: Tensor) -> Tensor:
        tau = a * c
        if b_nominal:
            tau = tau - b_nominal * v
        if "damping" in model.effects:
            tau = tau - params["b"] * v
        if "friction" in model.effects:
            tau = tau - params["c"] * torch.tanh(v / FRICTION_SMOOTHING)
        if "bias" in model.effects:
            tau = tau + params["tau0"]
        return 1.5 * g * torch.sin(theta + nominal.offset) + 3.0 * tau

    def clip(v: Tensor) -> Tensor:
        if "speed_clip" in model.effects:
            vmax = params["v"].clamp_min(LOWER_BOUNDS["v"])
            v = torch.minimum(torch.maximum(v, -vmax), vmax)
        return v

    def frame(theta: Tensor, v: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
        for _ in range(substeps):
            if rk4:  # the nominal model's classical Runge-Kutta (piga.world.physics.RK4), the action held
                a1 = acceleration(theta, v, c)
                v2 = v + 0.5 * h * a1
                a2 = acceleration(theta + 0.5 * h * v, v2, c)
                v3 = v + 0.5 * h * a2
                a3 = acceleration(theta + 0.5 * h * v2, v3, c)
                v4 = v + h * a3
                a4 = acceleration(theta + h * v3, v4, c)
                theta = theta + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
                v = clip(v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4))
            else:
                v = clip(v + h * acceleration(theta, v, c))
                theta = theta + h * v
        return theta, v

    theta, v = w.theta0, w.v0
    if within or getattr(nominal, "velocity_hold", False):
        # v0 is the difference over the last frame: read the velocity at the start through the frame step
        previous = theta - nominal.dt * v
        start = v
        for _ in range(HOLD_ITERATIONS):
            reached, _ = frame(previous, start, cmd[:, 0])
            start = start + (theta - reached) / nominal.dt
        _, v = frame(previous, start, cmd[:, 0])
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


def parameters_of(model: Model, nominal: Nominal) -> dict[str, Tensor]:
    """The tensors :func:`simulate` takes, from a model's values (defaults: nominal g, a; grid starts).

    a is fitted in log space; a negative a (a flipped actuation) keeps its sign in ``a_sign``, which
    is held, not fitted."""
    a = model.values.get("a", nominal.a)
    values = {"log_g": math.log(model.values.get("g", nominal.g)), "log_a": math.log(abs(a))}
    for e in model.effects:
        if e in PARAMETER:
            values[PARAMETER[e]] = model.values.get(PARAMETER[e], GRIDS[e][0])
    params = {k: torch.tensor(float(v), dtype=torch.float64, requires_grad=True) for k, v in values.items()}
    if a < 0:
        params["a_sign"] = torch.tensor(-1.0, dtype=torch.float64)
    return params


def squared_errors(model: Model, nominal: Nominal, w: Windows, params: dict[str, Tensor] | None = None) -> Tensor:
    """(B, H) squared angle errors (masked to 0 outside the sequences)."""
    p = parameters_of(model, nominal) if params is None else params
    return (as_observed(w, simulate(model, p, nominal, w)) - w.target) ** 2 * w.mask


def loss(model: Model, nominal: Nominal, w: Windows, weights: Tensor | None = None,
         params: dict[str, Tensor] | None = None) -> Tensor:
    """Mean squared multi-step angle error (rad²), optionally weighted per window (B,)."""
    se = squared_errors(model, nominal, w, params).sum(1) / w.mask.sum(1).clamp_min(1)  # (B,)
    if weights is None:
        return se.mean()
    return (se * weights).sum() / weights.sum()


def fit(model: Model, nominal: Nominal, w: Windows, weights: Tensor | None = None, max_iter: int = 60,
        fit_ga: bool = True) -> Model:
    """Fits g, a (unless ``fit_ga`` is False) and the effects' parameters; returns a new :class:`Model`.

    A continuous effect parameter starts from the best point of its grid in :data:`GRIDS` (the
    loss is not convex in a deadzone or a clip level); L-BFGS then refines all parameters.
    """
    start = model.with_values(dict(model.values))
    for e in model.effects:
        name = PARAMETER.get(e)
        if name is None or name in model.values:
            continue
        best = None
        for value in GRIDS[e]:
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

    def closure() -> Tensor:
        opt.zero_grad()
        value = loss(start, nominal, w, weights, params)
        value.backward()
        return value

    opt.step(closure)
    sign = float(params["a_sign"]) if "a_sign" in params else 1.0
    values = {"g": float(params["log_g"].detach().exp()), "a": sign * float(params["log_a"].detach().exp())}
    values.update({k: max(float(v.detach()), LOWER_BOUNDS.get(k, -math.inf)) for k, v in params.items()
                   if not k.startswith("log_") and k != "a_sign"})
    return model.with_values(values)


def fit_best_delay(effects: tuple[str, ...], base: dict[str, float], nominal: Nominal, w: Windows,
                   substeps: int = 0) -> Model:
    """Fits ``effects`` (which include "delay") for each k in 1..MAX_DELAY; returns the best."""
    best = None
    for k in range(1, MAX_DELAY + 1):
        m = fit(Model(effects, k, dict(base), substeps), nominal, w)
        with torch.no_grad():
            score = float(loss(m, nominal, w))
        if best is None or score < best[0]:
            best = (score, m)
    return best[1]


def fit_candidate(effects: tuple[str, ...], base: dict[str, float], nominal: Nominal, w: Windows,
                  delay: int | None = None, substeps: int | None = None) -> Model:
    """Fits a candidate with ``effects``, starting from the values in ``base`` (g, a, ...).

    With a "delay" among the effects, ``delay`` holds k fixed; None searches k = 1..MAX_DELAY.
    With "within_frame", ``substeps`` holds M fixed; None searches :data:`WITHIN_FRAME_SUBSTEPS`.
    """
    if "within_frame" in effects and substeps is None:
        best = None
        for m_sub in WITHIN_FRAME_SUBSTEPS:
            m = fit_candidate(effects, base, nominal, w, delay, m_sub)
            with torch.no_grad():
                score = float(loss(m, nominal, w))
            if best is None or score < best[0]:
                best = (score, m)
        return best[1]
    m_sub = substeps if "within_frame" in effects else 0
    if "delay" in effects and delay is None:
        return fit_best_delay(effects, base, nominal, w, m_sub)
    return fit(Model(effects, delay if "delay" in effects else 0, dict(base), m_sub or 0), nominal, w)


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

