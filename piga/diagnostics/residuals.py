"""Residual analysis of a model on encoded trajectories, as in classical system identification.

The one-step residual is an angular acceleration. With semi-implicit Euler (one substep per frame,
the fast preset) the observed acceleration is exactly (θ_{t+1} - 2θ_t + θ_{t-1}) / dt², so

    ρ_t = (θ_{t+1} - θ̂_{t+1}) / dt²,

where θ̂_{t+1} is the model's one-step prediction from θ_t and θ̇_t = (θ_t - θ_{t-1}) / dt. The
analysis bins ρ over the state and the action, and computes its autocorrelation and its
cross-correlation with the actions, with the ±1.96/√n band of a white residual. A cross-correlation
peak at lag k (ρ_t against u_{t-k}) points to an actuator delay of k steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from piga.diagnostics.fit import MAX_DELAY, Model, Nominal, make_windows, parameters_of, simulate


@dataclass(frozen=True)
class Residuals:
    """One-step residuals of a model, flattened over sequences and steps (n samples)."""

    rho: np.ndarray
    """(n,) acceleration residual (rad/s²)."""
    theta: np.ndarray
    """(n,) θ_t in Gymnasium's convention, wrapped to [-π, π) (0 upright)."""
    theta_dot: np.ndarray
    """(n,) θ̇_t = (θ_t - θ_{t-1}) / dt."""
    action: np.ndarray
    """(n,) u_t."""
    grid: np.ndarray
    """(N, T - 1 - MAX_DELAY) ρ per sequence and step, for correlations."""
    actions_grid: np.ndarray
    """(N, T) the actions, aligned with ``grid`` from step MAX_DELAY."""
    valid: np.ndarray
    """(n,) bool: False where frame s - 1, s or s + 1 is a repeated (stale) frame."""


def one_step_residuals(model: Model, nominal: Nominal, theta: np.ndarray, actions: np.ndarray, rows: np.ndarray,
                       stale: np.ndarray | None = None) -> Residuals:
    """One-step acceleration residuals of ``model`` on sequences ``rows`` of (N, T) encoded angles.

    ``stale`` (N, T) bool marks repeated frames; the residuals that touch one are flagged in ``valid``.
    """
    w = make_windows(theta, actions, rows, 1, 1, nominal.dt)  # every start s = MAX_DELAY..T-2, start-major
    with torch.no_grad():
        pred = simulate(model, parameters_of(model, nominal), nominal, w)[:, 0]
    rho = ((w.target[:, 0] - pred) / nominal.dt**2).numpy()  # (S * n,)
    gym_theta = np.remainder(w.theta0.numpy() + nominal.offset + math.pi, 2 * math.pi) - math.pi
    grid = rho.reshape(-1, len(rows)).T  # (n, S)
    valid = np.ones(len(rho), bool)
    if stale is not None:
        s = np.arange(MAX_DELAY, theta.shape[1] - 1)  # the starts, as in make_windows
        seen = stale[rows]
        valid = ~(seen[:, s - 1] | seen[:, s] | seen[:, s + 1]).T.reshape(-1)  # start-major, like rho
    return Residuals(rho, gym_theta, w.v0.numpy(), w.actions[:, -1].numpy(), grid, actions[rows], valid)


def heatmap(res: Residuals, bins: int = 12, speed_limit: float | None = None) -> dict[str, list]:
    """Mean residual and count over a (θ, θ̇) grid: ``{"theta_edges", "speed_edges", "mean", "count"}``."""
    vmax = speed_limit or float(np.percentile(np.abs(res.theta_dot), 99)) or 1.0
    te = np.linspace(-math.pi, math.pi, bins + 1)
    ve = np.linspace(-vmax, vmax, bins + 1)
    count, _, _ = np.histogram2d(res.theta, res.theta_dot, bins=(te, ve))
    total, _, _ = np.histogram2d(res.theta, res.theta_dot, bins=(te, ve), weights=res.rho)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count >= 5, total / np.maximum(count, 1), np.nan)
    return {"theta_edges": te.tolist(), "speed_edges": ve.tolist(), "mean": mean.tolist(), "count": count.tolist()}


def binned(res: Residuals) -> dict[str, list[dict]]:
    """Mean and RMS residual by sign of θ̇ and by |u| (where it lies)."""
    def stats(mask: np.ndarray, label: str) -> dict:
        r = res.rho[mask]
        return {"bin": label, "n": int(mask.sum()), "mean": float(r.mean()) if len(r) else None,
                "rms": float(np.sqrt((r**2).mean())) if len(r) else None}

    au = np.abs(res.action)
    return {
        "sign_theta_dot": [stats(res.theta_dot < 0, "θ̇ < 0"), stats(res.theta_dot >= 0, "θ̇ ≥ 0")],
        "abs_action": [stats((au >= lo) & (au < hi), f"{lo:g} ≤ |u| < {hi:g}") for lo, hi in
                       ((0, 0.5), (0.5, 1.0), (1.0, 1.5), (1.5, 2.01))],
    }


def autocorrelation(res: Residuals, max_lag: int = 10) -> dict[str, list[float] | float]:
    """Pooled within-sequence autocorrelation of ρ at lags 0..max_lag (at most the residual's length - 1: short
    sequences have no longer lags), with the white-noise band."""
    r = res.grid - res.grid.mean()
    var = float((r**2).mean())
    max_lag = min(max_lag, r.shape[1] - 1)
    acf = [float((r[:, : r.shape[1] - k] * r[:, k:]).mean() / var) if var > 0 else 0.0 for k in range(max_lag + 1)]
    return {"lags": list(range(max_lag + 1)), "acf": acf, "band": 1.96 / math.sqrt(r.size)}


def action_correlation(res: Residuals, max_lag: int = 8) -> dict[str, list[float] | float | int]:
    """Correlation of ρ_t with u_{t-k} for k = 0..max_lag (k ≤ MAX_DELAY), with the white band.

    ``peak_lag`` is the lag of the largest positive correlation outside the band (None if none):
    a residual that follows the action k steps late means an actuator delay of k.
    """
    n_seq, n_steps = res.grid.shape
    r = res.grid - res.grid.mean()
    out = []
    lags = list(range(0, min(max_lag, MAX_DELAY) + 1))
    for k in lags:
        u = res.actions_grid[:, MAX_DELAY - k : MAX_DELAY - k + n_steps]
        u = u - u.mean()
        den = math.sqrt(float((r**2).mean()) * float((u**2).mean()))
        out.append(float((r * u).mean() / den) if den > 0 else 0.0)
    band = 1.96 / math.sqrt(r.size)
    positive = [(c, k) for k, c in zip(lags, out) if c > band]
    return {"lags": lags, "ccf": out, "band": band, "peak_lag": max(positive)[1] if positive else None}


#: The names of :func:`generic_features`' columns (its default order 6).
GENERIC_COLUMNS = tuple([f"sin{k}" for k in range(1, 7)] + [f"cos{k}" for k in range(1, 7)]
                        + ["v", "tanh", "v|v|", "1", "u", "u3"])


def generic_features(res: Residuals, order: int = 6) -> np.ndarray:
    """(n, F) a flexible basis of the state and action, for the "not explained" test:
    sin and cos of kθ (k = 1..order), θ̇, tanh(θ̇/0.1), θ̇·|θ̇|, 1, u, u³."""
    th, v, u = res.theta, res.theta_dot, res.action
    cols = [np.sin(k * th) for k in range(1, order + 1)] + [np.cos(k * th) for k in range(1, order + 1)]
    cols += [v, np.tanh(v / 0.1), v * np.abs(v), np.ones_like(v), u, u**3]
    return np.stack(cols, 1)


def reading_features(model: Model, nominal: Nominal, theta: np.ndarray, actions: np.ndarray, rows: np.ndarray,
                     base: Residuals, harmonics: int = 12, step: float = 1e-4) -> np.ndarray:
    """(n, 2·(harmonics − 1)) how ``base`` (``model``'s one-step residuals on ``rows``) answers a periodic
    error in the angles that the encoder reads: column j is ∂ρ/∂ε for angles read as
    θ + ε·φ_j(θ), φ_j = sin kθ, cos kθ (k = 2..harmonics, θ the physical angle), by a forward
    difference of ``step`` rad. Not k = 1: to the physics, angles read off by sin θ or cos θ look
    mostly like another g and φ, which are fitted, and the fit of that column is ill-posed (on a
    planted error of 10 mrad rms with k = 1 the reading error's fitted size was 22 mrad whatever the
    planted size; from k = 2, 10.4 mrad).

    An encoder that reads the angle with an error δ(θ) (a perspective or a render it was not
    trained on) gives one-step residuals ≈ (δ_{t+1} − 2δ_t + δ_{t−1}) / dt² plus the physics'
    answer to the misread state: periodic in θ and scaled by the speed, unlike a torque that
    depends on θ (a cogging torque). Measured on a dm_control pendulum (its own camera, action
    repeat 4): the encoder's error against the true angle was 8.2 mrad rms, and 12 harmonics
    leave 1.4 mrad; on its one-step residual they explained 89% held out, where the state-action
    basis of :func:`generic_features` explained 33% alone and 1.1% on top of them.
    """
    phase = theta + nominal.offset  # (N, T) the physical angle
    cols = []
    for k in range(2, harmonics + 1):
        for f in (np.sin, np.cos):
            moved = one_step_residuals(model, nominal, theta + step * f(k * phase), actions, rows)
            cols.append((moved.rho - base.rho) / step)
    return np.stack(cols, 1)


def ridge(x: np.ndarray, y: np.ndarray, strength: float = 1e-3) -> np.ndarray:
    """(F,) ridge regression of (n,) ``y`` on (n, F) ``x``, on standardised columns (a constant column
    is left as it is): minimises |y - x·c|² + strength·n·|s ⊙ c|², s the columns' standard deviations.
    A small ``strength`` barely changes a well-posed fit (the flexible basis's held-out drop on the
    blind check's cogging data stays within 1%) but keeps an ill-posed one from extrapolating wildly."""
    s = x.std(0)
    s[s == 0] = 1.0
    xs = x / s
    a = xs.T @ xs + strength * len(y) * np.eye(x.shape[1])
    return np.linalg.solve(a, xs.T @ y) / s
