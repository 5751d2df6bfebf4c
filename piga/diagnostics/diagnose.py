"""The sim-to-real gap diagnosis: how big the gap is, where it lies, which effect causes it, how far it shrinks.

Steps (no state labels, no effect labels; only frames and actions of the "real" system):

1. :func:`~piga.diagnostics.observe.observe`: encode and re-render every frame with the identified
   model. The re-rendering error against the model's own training error says how much of the gap
   is vision.
2. Cut the encoded angles into windows: multi-step (8 steps) on the fit split (the file's train
   split) for fitting, one-step for the information criterion, free-run on the held-out split.
3. Fit "none" (g and a refitted) and each candidate effect with g and a
   (:mod:`piga.diagnostics.fit`); rank by the one-step BIC on the fit split; report the held-out
   multi-step errors.
4. Forward selection: candidates are tried in BIC order, and the first that lowers the BIC by
   more than ``bic_margin`` *and* the held-out free-run error by more than ``min_gain`` is
   accepted (a delay alone can win the one-step BIC while an unmodelled speed clip ruins its free
   run); a second effect is then tried on top of the first in the same way.
5. A gain error is the refitted a over the nominal a, beyond ``gain_tolerance``. A fitted speed
   clip within ``gym_clip_tolerance`` of 8 rad/s is Gymnasium's own clip, present in the nominal
   environment too, so it is reported but is not a gap.
6. "Not explained by the candidates": a flexible basis of the state and action
   (:func:`~piga.diagnostics.residuals.generic_features`) fitted to the remaining one-step
   residuals still lowers the held-out residual by more than ``unexplained_gain`` with a BIC gain.
7. Bootstrap the chosen model over fit sequences for uncertainties; closure per horizon, raw
   (1 - error_corrected / error_nominal) and against the noise floor, the free-run error that an
   exactly right model still has with the encoder's noise (:func:`~piga.diagnostics.fit.noise_floor`):
   (error_nominal - error_corrected) / (error_nominal - floor).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

from piga.diagnostics import fit as F
from piga.diagnostics.observe import Observations, observe
from piga.diagnostics.residuals import (action_correlation, autocorrelation, binned, generic_features, heatmap,
                                        one_step_residuals)
from piga.model import PhysicsModel
from piga.train import training_reconstruction_mse

#: Gymnasium Pendulum-v1's own speed clip (rad/s).
GYM_SPEED_CLIP = 8.0


@dataclass(frozen=True)
class DiagnoseConfig:
    """How the diagnosis decides."""

    fit_horizon: int = 8
    """Steps of the multi-step fitting loss."""
    stride: int = 2
    """Frames between window starts."""
    bic_margin: float = 10.0
    """BIC drop (one-step, fit split) an effect needs to be accepted ("very strong" on Kass & Raftery's scale)."""
    min_gain: float = 0.1
    """Relative drop of the held-out free-run error an effect needs to be accepted."""
    unexplained_gain: float = 0.02
    """Relative drop of the held-out one-step residual that the flexible basis needs to call the gap
    "not explained" (measured: 0.0-0.2% when a candidate explains the data, 8% for a cogging torque
    of 0.3 N·m)."""
    gain_tolerance: float = 0.03
    """|a / a_nominal - 1| above this is reported as an actuator gain error."""
    gym_clip_tolerance: float = 0.3
    """A fitted speed clip within this of 8 rad/s is Gymnasium's own."""
    max_effects: int = 2
    """Effects the forward selection may combine."""
    bootstrap: int = 20
    """Bootstrap replicates for the uncertainties (0: none)."""
    seed: int = 0
    """Seed of the bootstrap."""
    vision_ratio: float = 2.0
    """Re-rendering error above this multiple of the model's training error counts as a vision gap."""

    def __post_init__(self) -> None:
        if self.fit_horizon < 1 or self.stride < 1 or self.max_effects < 0 or self.bootstrap < 0:
            raise ValueError(f"need fit_horizon, stride >= 1 and max_effects, bootstrap >= 0, got {self}")


@dataclass
class Diagnosis:
    """Everything the report shows (JSON-ready through :meth:`to_dict`)."""

    verdict: str
    """One line: the named effect(s), "no significant gap", or "not explained by the candidates"."""
    verdict_class: str
    """"none", "unexplained", or the names of the effects joined by "+" (for scoring)."""
    effects: list[dict[str, Any]]
    """Named effects with coefficient, 95% interval and unit."""
    nominal: dict[str, float]
    """The identified model's g, a, φ."""
    corrected: dict[str, float]
    """g, a and the effect parameters of the chosen model."""
    corrected_effects: list[str]
    """The effects in the chosen model's physics (including Gymnasium's own clip when found)."""
    candidates: list[dict[str, Any]]
    """Ranked table of the single-effect fits (and the selection steps)."""
    gap: dict[str, Any]
    """Errors per horizon: state (rad²) and pixels, nominal vs chosen, and the closure."""
    vision: dict[str, float]
    """Re-rendering error on the real frames vs the model's training error."""
    residuals: dict[str, Any]
    """Heatmap, bins, autocorrelation, action cross-correlation of the nominal model."""
    notes: list[str] = field(default_factory=list)
    """Other findings (Gymnasium's own clip, vision gap, ...)."""

    control: dict[str, Any] | None = None
    """With ``--env``: MPC on the simulated real system with the nominal vs the corrected physics."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def corrected_model(self) -> F.Model:
        """The chosen physics as a :class:`piga.diagnostics.fit.Model` (for a planner)."""
        values = {k: float(v) for k, v in self.corrected.items() if k != "delay"}
        return F.Model(tuple(self.corrected_effects), int(self.corrected.get("delay", 0)), values)


def nominal_of(model: PhysicsModel) -> F.Nominal:
    """The identified model's physics: g, a, φ, dt and substeps."""
    p = model.physical_parameters()
    return F.Nominal(p["g"], p["a"], p.get("offset", 0.0), model.config.dt, model.config.substeps)


def _score(m: F.Model, nom: F.Nominal, w_fit1: F.Windows, w_free: F.Windows) -> dict[str, Any]:
    bic, _ = F.one_step_bic(m, nom, w_fit1)
    h = F.horizon_errors(m, nom, w_free)
    return {"model": m, "name": m.name, "bic": bic, "free_run": float(h.mean()), "horizon": h}


def diagnose(model: PhysicsModel, data: str | os.PathLike[str], config: DiagnoseConfig = DiagnoseConfig(),
             checkpoint: dict | None = None, progress: bool = False) -> Diagnosis:
    """Diagnoses the gap between ``model`` and the recording ``data`` (frames and actions only).

    Args:
        model: the identified pendulum model (from :func:`piga.train.load_model`).
        data: a piga HDF5 file of the "real" system.
        config: see :class:`DiagnoseConfig`.
        checkpoint: the model's checkpoint, for its training reconstruction error (vision check).
    """
    obs = observe(model, data, progress=progress)
    return analyse(obs, nominal_of(model), config, model=model, rec_training=training_reconstruction_mse(model, checkpoint),
                   progress=progress)


def analyse(obs: Observations, nom: F.Nominal, config: DiagnoseConfig = DiagnoseConfig(), model: PhysicsModel | None = None,
            rec_training: float = 0.0, progress: bool = False) -> Diagnosis:
    """The diagnosis of observations ``obs`` against the nominal physics ``nom``.

    ``model`` (its decoder) renders the pixel errors of ``obs.frames``; without it they are left
    out. ``rec_training`` is the model's own re-rendering MSE (0: unknown, no vision check).
    """
    from tqdm.auto import tqdm

    fit_rows, held_rows = np.flatnonzero(obs.fit), np.flatnonzero(~obs.fit)
    w_fit = F.make_windows(obs.theta, obs.actions, fit_rows, config.fit_horizon, config.stride, obs.dt)
    w_fit1 = F.make_windows(obs.theta, obs.actions, fit_rows, 1, 1, obs.dt)
    w_free = F.make_windows(obs.theta, obs.actions, held_rows, None, config.stride, obs.dt)
    w_held1 = F.make_windows(obs.theta, obs.actions, held_rows, 1, 1, obs.dt)

    nominal_model = F.Model((), 0, {"g": nom.g, "a": nom.a})
    nominal_score = _score(nominal_model, nom, w_fit1, w_free)
    bar = tqdm(total=1 + len(F.CANDIDATES), desc="fitting candidates", disable=not progress)
    refit = _score(F.fit_candidate((), {}, nom, w_fit), nom, w_fit1, w_free)
    bar.update()
    singles = []
    for name in F.CANDIDATES:
        singles.append(_score(F.fit_candidate((name,), refit["model"].values, nom, w_fit), nom, w_fit1, w_free))
        bar.update()
    bar.close()
    singles.sort(key=lambda s: s["bic"])

    # forward selection
    chosen, steps = refit, []
    pool = singles
    for _round in range(config.max_effects):
        best = None
        for cand in pool:  # in BIC order: the first that passes both tests is accepted
            bic_drop = chosen["bic"] - cand["bic"]
            if bic_drop <= config.bic_margin:
                break  # the rest have even smaller BIC drops
            free_drop = 1 - cand["free_run"] / chosen["free_run"] if chosen["free_run"] > 0 else 0.0
            accepted = free_drop > config.min_gain
            steps.append({"tried": cand["name"], "bic_drop": bic_drop, "free_run_drop": free_drop, "accepted": bool(accepted)})
            if accepted:
                best = cand
                break
        if best is None:
            break
        chosen = best
        if _round + 1 == config.max_effects:
            break
        base = chosen["model"]
        rest = [c for c in F.CANDIDATES if c not in base.effects]
        pool = []
        for name in tqdm(rest, desc=f"adding to {base.name}", disable=not progress):
            effects = tuple(e for e in F.CANDIDATES if e in (*base.effects, name))
            m = F.fit_candidate(effects, base.values, nom, w_fit, delay=base.delay or None)
            pool.append(_score(m, nom, w_fit1, w_free))
        pool.sort(key=lambda s: s["bic"])

    final: F.Model = chosen["model"]
    notes: list[str] = []
    # Gymnasium's own speed clip is no gap
    named = list(final.effects)
    if "speed_clip" in named and abs(final.values["v"] - GYM_SPEED_CLIP) <= config.gym_clip_tolerance:
        named.remove("speed_clip")
        notes.append(f"a speed clip at {final.values['v']:.2f} rad/s was found: Gymnasium's own ±8 rad/s clip, which the "
                     "nominal environment has too (the model's engine does not); it is not counted as a gap")
    gain = final.values["a"] / nom.a
    gain_error = abs(gain - 1) > config.gain_tolerance

    # not explained by the candidates? a flexible basis on what is left
    res_fit = one_step_residuals(final, nom, obs.theta, obs.actions, fit_rows)
    res_held = one_step_residuals(final, nom, obs.theta, obs.actions, held_rows)
    x_fit, x_held = generic_features(res_fit), generic_features(res_held)
    coef, *_ = np.linalg.lstsq(x_fit, res_fit.rho, rcond=None)
    n = len(res_fit.rho)
    rss0, rss1 = float((res_fit.rho**2).sum()), float(((res_fit.rho - x_fit @ coef) ** 2).sum())
    bic_drop = n * math.log(rss0 / n) - (n * math.log(rss1 / n) + x_fit.shape[1] * math.log(n))
    held0, held1 = float((res_held.rho**2).mean()), float(((res_held.rho - x_held @ coef) ** 2).mean())
    unexplained = bic_drop > config.bic_margin and held1 < (1 - config.unexplained_gain) * held0
    generic = {"bic_drop": bic_drop, "held_out_drop": 1 - held1 / held0 if held0 > 0 else 0.0, "significant": bool(unexplained)}

    # uncertainties
    draws = F.bootstrap(final, nom, w_fit, config.bootstrap, config.seed) if config.bootstrap else {}

    def interval(key: str) -> list[float] | None:
        d = draws.get(key)
        return [float(np.percentile(d, 2.5)), float(np.percentile(d, 97.5))] if d else None

    effects: list[dict[str, Any]] = []
    units = {"b": "N·m·s/rad", "c": "N·m", "tau0": "N·m", "d": "action units", "s": "action units", "v": "rad/s"}
    for e in named:
        if e == "delay":
            effects.append({"effect": "delay", "value": final.delay, "interval": None, "unit": "steps"})
        else:
            key = F.PARAMETER[e]
            effects.append({"effect": e, "value": final.values[key], "interval": interval(key), "unit": units[key]})
    if gain_error:
        a_int = interval("a")
        effects.append({"effect": "gain", "value": gain, "unit": "factor on the nominal a",
                        "interval": [x / nom.a for x in a_int] if a_int else None})
    g_ratio = final.values["g"] / nom.g
    if abs(g_ratio - 1) > config.gain_tolerance:
        notes.append(f"g refits to {final.values['g']:.3f} (x{g_ratio:.3f} the nominal {nom.g:.3f}): gravity, or the "
                     "pendulum's length, differs from the identified model")

    names = [x["effect"] for x in effects]
    if unexplained:
        verdict_class = "unexplained"
        verdict = ("not explained by the candidates: a flexible state-action basis still explains "
                   f"{100 * generic['held_out_drop']:.0f}% of the held-out residual"
                   + (f" after adding {'+'.join(names)}" if names else ""))
    elif names:
        verdict_class = "+".join(sorted(names))
        verdict = "; ".join(_describe(x) for x in effects)
    else:
        verdict_class = "none"
        verdict = "no significant gap"

    # vision
    rec_real = float(np.mean(obs.rec_mse))
    vision = {"rec_mse_real": rec_real, "rec_mse_training": rec_training,
              "ratio": rec_real / rec_training if rec_training else float("nan")}
    if rec_training and vision["ratio"] > config.vision_ratio:
        notes.append(f"vision gap: the autoencoder re-renders the real frames {vision['ratio']:.1f}x worse than its "
                     "training frames (blur, noise, a shifted camera or a different scene?)")

    # gap per horizon, state and pixels
    h_nom, h_fin = nominal_score["horizon"], chosen["horizon"]
    closure = [float(1 - b / a) if a > 0 else 0.0 for a, b in zip(h_nom, h_fin)]
    one_step = F.horizon_errors(final, nom, w_held1)[0]
    sigma = math.sqrt(one_step / 6)  # r = n_{t+1} - 2 n_t + n_{t-1} for white angle noise n
    h_floor = F.noise_floor(final, nom, w_free, sigma, seed=config.seed)
    reducible = float(h_nom.mean() - h_floor.mean())
    gap_closure = float((h_nom.mean() - h_fin.mean()) / reducible) if reducible > 0 else None
    pixels = _pixel_errors(model, obs, nom, nominal_model, final) if model is not None else \
        {"pixel_mse_nominal": [], "pixel_mse_corrected": []}
    res_nom = one_step_residuals(nominal_model, nom, obs.theta, obs.actions, np.arange(len(obs.theta)))
    gap = {
        "horizon": list(range(1, len(h_nom) + 1)),
        "state_mse_nominal": h_nom.tolist(), "state_mse_corrected": h_fin.tolist(), "closure": closure,
        "free_run_mse_nominal": float(h_nom.mean()), "free_run_mse_corrected": float(h_fin.mean()),
        "free_run_closure": float(1 - h_fin.mean() / h_nom.mean()) if h_nom.mean() > 0 else 0.0,
        "state_mse_noise_floor": h_floor.tolist(), "free_run_mse_noise_floor": float(h_floor.mean()),
        "encoder_noise_rad": sigma,
        "free_run_gap_closure": gap_closure,
        "one_step_rms_nominal_rad": math.sqrt(float(F.horizon_errors(nominal_model, nom, w_held1)[0])),
        "one_step_rms_corrected_rad": math.sqrt(float(one_step)),
        **pixels,
    }
    table = [{"candidate": "nominal (no refit)", "bic": nominal_score["bic"], "held_out_free_run_mse": nominal_score["free_run"],
              "values": nominal_model.values}]
    for s in [refit, *singles]:
        m = s["model"]
        table.append({"candidate": "none (g, a refitted)" if not m.effects else m.name, "bic": s["bic"],
                      "delta_bic": s["bic"] - refit["bic"], "held_out_free_run_mse": s["free_run"],
                      "values": m.values, "delay": m.delay or None})
    return Diagnosis(
        verdict=verdict, verdict_class=verdict_class, effects=effects,
        nominal={"g": nom.g, "a": nom.a, "offset": nom.offset},
        corrected={**final.values, **({"delay": final.delay} if "delay" in final.effects else {})},
        corrected_effects=list(final.effects),
        candidates=table + [{"selection": steps, "generic_basis": generic}],
        gap=gap, vision=vision,
        residuals={"heatmap": heatmap(res_nom), "bins": binned(res_nom), "autocorrelation": autocorrelation(res_nom),
                   "action_correlation": action_correlation(res_nom)},
        notes=notes,
    )


def _describe(e: dict[str, Any]) -> str:
    if e["effect"] == "delay":
        return f"actuator delay of {e['value']} steps"
    ci = f" (95% interval {e['interval'][0]:.3g}..{e['interval'][1]:.3g})" if e.get("interval") else ""
    return f"{e['effect']} {e['value']:.3g} {e['unit']}{ci}"


@torch.no_grad()
def _pixel_errors(model: PhysicsModel, obs: Observations, nom: F.Nominal, nominal_model: F.Model,
                  final: F.Model) -> dict[str, list[float]]:
    """Per-horizon pixel MSE of free runs rendered by the decoder, on the kept held-out sequences."""
    from piga.model import frames_to_float

    if len(obs.frames_index) == 0:
        return {"pixel_mse_nominal": [], "pixel_mse_corrected": []}
    t = obs.theta.shape[1]
    w = F.make_windows(obs.theta, obs.actions, obs.frames_index, None, t, obs.dt)  # one free run per sequence
    x = frames_to_float(torch.from_numpy(obs.frames[:, F.MAX_DELAY + 1 :]), model.config.channels)  # (n, H, C, H, W)
    out = {}
    for key, m in (("pixel_mse_nominal", nominal_model), ("pixel_mse_corrected", final)):
        theta = F.simulate(m, F.parameters_of(m, nom), nom, w).float()  # (n, H)
        frames = model.decoder(theta[..., None, None])  # (n, H, C, H, W)
        out[key] = ((frames - x) ** 2).mean(dim=(0, 2, 3, 4)).tolist()
    return out
