"""The diagnosis report: ``report.md``, ``report.json`` and its plots, written atomically into one folder."""

from __future__ import annotations

import errno
import math
import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from piga.io.atomic import (OutputExistsError, atomic_output, check_folder_target, check_writable_target,
                            missing_folders, partial_path, remove_empty_folders, write_json, written_together)
from piga.diagnostics.results import Diagnosis, VisionSummary, interval_text, value_text
from piga.diagnostics.vision import Camera
from piga.diagnostics.twin import MEASURABLE_GAP
from piga.evaluation.episodes import EpisodeSummary, summary_markdown
from piga.evaluation.plots import plt, save_figure

#: Files the report writes into its folder.
REPORT_FILES = ("report.md", "report.json", "gap.png", "residual_heatmap.png", "correlations.png", "frames.png")


def gap_figure(d: Diagnosis):  # noqa: ANN201
    """Held-out error against horizon, angles and pixels, nominal vs corrected, and the closure (none where nothing was
    named to correct: the refit is drawn for reference, and no closure)."""
    g = d.gap
    fig, axes = plt.subplots(1, 3, figsize=(11, 3))
    h = g.horizon
    other = "refitted" if g.no_gap else "corrected"
    axes[0].semilogy(h, np.degrees(np.sqrt(g.state_mse_nominal)), label="nominal")
    axes[0].semilogy(h, np.degrees(np.sqrt(g.state_mse_corrected)), label=other)
    if g.state_mse_floor is not None:
        axes[0].semilogy(h, np.degrees(np.sqrt(g.state_mse_floor)), ls=":", color="gray", label="floor (twin)")
    axes[0].set_title("angle RMSE (deg)" + (": nominal on the encoder's, corrected on matched angles"
                                            if g.closure_basis == "pixels" else ""), fontsize=8)
    closure = 100 * np.array(g.closure)
    title = "closure 1 - err_corr / err_nom (%), angles"
    if g.pixel_mse_nominal:
        pn, pc = np.array(g.pixel_mse_nominal), np.array(g.pixel_mse_corrected)
        hp = range(1, len(pn) + 1)
        axes[1].plot(hp, pn, label="nominal")
        axes[1].plot(hp, pc, label=other)
        if g.pixel_mse_floor is not None:
            axes[1].axhline(g.pixel_mse_floor, ls=":", color="gray", label="matched floor")
        if g.closure_basis == "pixels":
            closure = 100 * (pn - pc) / np.maximum(pn - g.pixel_mse_floor, 1e-12)
            title = "closure of the pixel gap above the floor (%)"
    axes[1].set_title("pixel MSE of the rendered prediction", fontsize=9)
    if g.no_gap:  # a ratio against a refit that corrects nothing: a curve of it read as a closure
        axes[2].text(0.5, 0.5, "no closure:\nnothing named to correct", ha="center", va="center",
                     transform=axes[2].transAxes)
    else:
        axes[2].plot(range(1, len(closure) + 1), closure)
        axes[2].set_ylim(min(0, float(np.min(closure)) if len(closure) else 0) - 5, 105)
    axes[2].set_title(title, fontsize=9)
    for ax in axes:
        ax.set_xlabel("horizon (steps)")
    axes[0].legend(fontsize=7)
    if g.pixel_mse_nominal:
        axes[1].legend(fontsize=7)
    else:  # no held-out sequence has two fresh frames where the free runs start (a camera 3+ frames late)
        axes[1].text(0.5, 0.5, "no free run to render", ha="center", va="center", transform=axes[1].transAxes)
    fig.tight_layout()
    return fig


def frames_figure(d: Diagnosis):  # noqa: ANN201
    """A held-out frame as recorded, re-rendered by the nominal and the corrected model, and the differences."""
    p = d.pictures
    fig, axes = plt.subplots(1, 5, figsize=(11, 2.6))
    gray = {"cmap": "gray", "vmin": 0, "vmax": 1}
    panels = [(p["real"], "recorded frame", gray), (p["nominal"], "nominal re-render", gray),
              (p["corrected"], "corrected re-render", gray),
              (np.abs(p["nominal"] - p["real"]), "|nominal - recorded|", {"cmap": "magma", "vmin": 0, "vmax": 0.5}),
              (np.abs(p["corrected"] - p["real"]), "|corrected - recorded|", {"cmap": "magma", "vmin": 0, "vmax": 0.5})]
    for ax, (img, title, kw) in zip(axes, panels):
        ax.imshow(img if img.ndim == 2 else img.clip(0, 1), **kw)
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    return fig


def heatmap_figure(d: Diagnosis):  # noqa: ANN201
    """Mean one-step acceleration residual of the nominal model over (θ, θ̇)."""
    hm = d.residuals["heatmap"]
    mean = np.array(hm["mean"], dtype=float)
    lim = np.nanmax(np.abs(mean)) if np.isfinite(mean).any() else 1.0
    fig, ax = plt.subplots(figsize=(5, 4))
    te, ve = np.degrees(hm["theta_edges"]), hm["speed_edges"]
    im = ax.pcolormesh(te, ve, mean.T, cmap="RdBu_r", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=ax, label="mean residual θ̈ (rad/s²)")
    ax.set_xlabel("θ (deg, 0 upright)")
    ax.set_ylabel("θ̇ (rad/s)")
    ax.set_title("nominal model: where the one-step residual lies", fontsize=9)
    fig.tight_layout()
    return fig


def correlation_figure(d: Diagnosis):  # noqa: ANN201
    """Residual autocorrelation and residual-action cross-correlation with the white-noise bands."""
    ac, cc = d.residuals["autocorrelation"], d.residuals["action_correlation"]
    fig, axes = plt.subplots(1, 2, figsize=(8, 3))
    for ax, lags, vals, band, title in ((axes[0], ac["lags"], ac["acf"], ac["band"], "residual autocorrelation"),
                                        (axes[1], cc["lags"], cc["ccf"], cc["band"], "corr(residual_t, u_{t-k})")):
        ax.bar(lags, vals, width=0.5)
        ax.axhspan(-band, band, color="gray", alpha=0.3, label="95% band (white)")
        ax.set_xlabel("lag k (steps)")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _pct(x: float | None) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{100 * x:.1f}%"


def _fmt(x: Any) -> str:
    """A value for a table: "–" for a missing or non-finite number (never "nan")."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def number(x: float | None, spec: str = ".3g") -> str:
    """``x`` formatted with ``spec``, or "–" when it is missing or not finite (a report never shows "nan")."""
    return "–" if x is None or not math.isfinite(x) else format(x, spec)


def _interval(ci: list[float] | None) -> str:
    return "–" if not ci or not all(math.isfinite(x) for x in ci) else interval_text(*ci, digits=4).replace("..", " .. ")


def _camera_lines(v: VisionSummary) -> list[str]:
    """The camera stage: candidate table, noise, repeated frames."""
    c = v.camera
    if c is None:
        return []
    noise = (f"sensor noise {c.noise:.2f} gray levels on the pixels the pendulum never reaches"
             if math.isfinite(c.noise) else "sensor noise not measured (the pendulum reaches every pixel)")
    if math.isfinite(c.noise_correlation):
        noise += f" (their correlation between successive frames is {c.noise_correlation:.2f}; sensor noise's is 0)"
    calm = any("calm_drop" in row for row in c.camera_candidates)
    lines = [
        f"- **Camera**: {noise}; "
        f"{c.repeated_frames} frames repeat the previous one (within 2 gray levels) ({c.dropped_frames} while the pendulum moves: "
        f"rate {100 * c.drop_rate:.2f}%)"
        + (f", and the first {c.leading_repeats} frame{'s' if c.leading_repeats != 1 else ''} of nearly every sequence "
           "repeat the first" if c.leading_repeats else "; no sequence starts with repeated frames")
        + ". The dynamics are fitted on "
        + ("angles matched to the decoder's renders" + (" through the fitted camera." if c.camera != Camera() else ".")
           if c.angles == "matched"
           else "the encoder's angles."), "",
        "  Camera candidates, fitted by matching frames to the decoder's renders over the whole circle "
        "(fit split), scored on held-out frames" + (": every one, and those after the smallest fifth of the actions "
                                                    "(calm; a candidate needs a drop over 10% in either; one that only "
                                                    "the calm frames show is fitted on those):" if calm else ":"), "",
        "  | candidate | blur σ (px) | dx (px) | dy (px) | exposure | zoom | held-out matched MSE | drop |"
        + (" calm drop |" if calm else "") + " accepted |",
        "  |---|---|---|---|---|---|---|---|" + ("---|" if calm else "") + "---|",
    ]
    for row in c.camera_candidates:
        cam = row["camera"]
        lines.append(f"  | {row['candidate']} | {cam['blur']:.3f} | {cam['dx']:.3f} | {cam['dy']:.3f} | "
                     f"{cam.get('exposure', 1.0):.3f} | {cam.get('zoom', 1.0):.3f} | "
                     f"{row['held_out_matched_mse']:.3e} | {100 * row['drop']:.1f}% | "
                     + (f"{100 * row['calm_drop']:.1f}% | " if calm and "calm_drop" in row else "– | " if calm else "")
                     + f"{'yes' if row['accepted'] else 'no (in part of the recording only)' if row.get('partial') else 'no'} |")
    lines.append("")
    return lines


def ambiguity_lines(d: Diagnosis) -> list[str]:
    """The report's paragraph on two candidates the data cannot tell apart (none when the choice is clear)."""
    a = d.ambiguity
    if a is None:
        return []
    # (a rival of "none" may have the lower BIC, by less than an effect needs: the free run made it a rival)
    why = "the lower BIC" if a.bic[0] <= a.bic[1] else \
        f"the choice: {a.candidates[1]}'s BIC is lower, by less than an effect needs to be named"
    overlap = ("were not compared (no bootstrap)" if a.intervals_overlap is None else
               "overlap" if a.intervals_overlap else "do not overlap")
    return [f"**Ambiguous between {a.between[0]} and {a.between[1]}**: the candidates {a.candidates[0]} and "
            f"{a.candidates[1]} have one-step BICs {a.bic[0]:.1f} and {a.bic[1]:.1f} and typical held-out free-run "
            f"errors {a.typical_free_run_mse[0]:.3g} and {a.typical_free_run_mse[1]:.3g} rad²; the 95% intervals of the "
            f"values they both fit {overlap}. Neither is named. {a.separate_by[0].upper()}{a.separate_by[1:]} would "
            f"separate them. The gap below is measured with {a.candidates[0]} ({why}).", ""]


#: How the physics refitted to the recording is labelled where nothing was named to correct (no closure): its values
#: are shown for reference, and are no correction ("no gap to close ...; corrected g = 12.52" read as one).
REFITTED = "refitted for reference, not a correction"


def values_text(values: dict[str, float], unread: Sequence[str] = ()) -> str:
    """"g = 12.52, a = 1.002" of a physics' values; those ``unread`` marked as held at their start, not read."""
    return ", ".join(f"{k} = {number(v, '.4g')}" + (" (held, not read)" if k in unread else "")
                     for k, v in values.items())


def convention_text(d: Diagnosis) -> str:
    """" (the damping taken explicitly; taken implicitly, the same frames read g = 13.18, a = 0.6666, b = 0.06977)"
    after the corrected values where they have a damping (:func:`~piga.diagnostics.diagnose.damping_convention`): the
    frames cannot tell the two conventions apart, and the verdict gives the damping as the recorded system takes it,
    so its b may be the other convention's (dm_control at mass 2 named b = 0.0698, and printed "corrected ... b =
    0.06933" beside it)."""
    c = d.damping_convention
    if not c or not c.get("values"):
        return ""
    return (f" (the damping taken {c['taken']}ly; taken {c['other']}ly, the same frames read "
            f"{values_text(c['values'])})")


def closure_line(d: Diagnosis) -> str:
    """The command's one line on the closure, each number with its basis: the headline in pixels or angles, and the
    mean over all windows, which is always in angles (a blur's "free-run closure 97.6% (pixel MSE ...; mean over all
    windows -654.9%)" read as if both were pixels; the -654.9% was the angles', which that corrected model reads
    through its camera, unlike the nominal one)."""
    g = d.gap
    pixels = g.closure_basis == "pixels"
    headline = "–" if g.free_run_gap_closure is None else f"{number(100 * g.free_run_gap_closure, '.1f')}%"
    if not g.floor_subtracted and g.free_run_gap_closure is not None:
        headline += " raw"
    if pixels:
        detail = (f"typical held-out window, pixel MSE {number(g.typical_pixel_mse_nominal)} -> "
                  f"{number(g.typical_pixel_mse_corrected)}"
                  + (f", of the gap above the matched floor {number(g.pixel_mse_floor)}" if g.floor_subtracted else ""))
    else:
        floor = g.typical_free_run_mse_floor
        detail = (f"typical held-out window, angle MSE {number(g.typical_free_run_mse_nominal)} -> "
                  f"{number(g.typical_free_run_mse_corrected)} rad²"
                  + (f", of the gap above the twin's floor {number(floor)}" if floor is not None and g.floor_subtracted
                     else ""))
    corrected = "corrected " + values_text(d.corrected, d.unread) + convention_text(d)
    basis = "in pixels" if pixels else "in angles"
    if g.no_gap and d.verdict_class in ("unexplained", "ambiguous"):  # a gap, but nothing named that would close it
        why = "the gap is not explained" if d.verdict_class == "unexplained" else "neither of the two is named"
        return (f"free-run closure: none measured ({why}, so nothing was corrected; {detail}); "
                f"{REFITTED}: {values_text(d.corrected, d.unread)}")
    if g.no_gap:
        return (f"free-run closure: no gap to close (nothing named to correct; {detail}); {REFITTED}: "
                f"{values_text(d.corrected, d.unread)}")
    mean = (f"mean over all windows in angles: MSE {number(g.free_run_mse_nominal)} -> {number(g.free_run_mse_corrected)} "
            f"rad², raw closure {number(100 * g.free_run_closure, '.1f')}%")
    if pixels:
        mean += ", not comparable: the corrected model reads its angles by matching the frames to the decoder's renders"
    if not g.gap_above_floor:  # the closure is a ratio of noise: no percentage leads the line
        nominal, fixed, floor = ((g.typical_pixel_mse_nominal, g.typical_pixel_mse_corrected, g.pixel_mse_floor) if pixels
                                 else (g.typical_free_run_mse_nominal, g.typical_free_run_mse_corrected,
                                       g.typical_free_run_mse_floor))
        kind, unit, floor_name = ("pixel", "", "matched floor") if pixels else ("angle", " rad²", "twin's floor")
        return (f"free-run closure {basis}: no gap above the floor to close (typical held-out window, {kind} MSE "
                f"{number(nominal)} -> {number(fixed)}{unit} beside the {floor_name} {number(floor)}: the nominal is "
                f"within {MEASURABLE_GAP:g}x the floor, so the closure ({headline}) is a ratio of noise; {mean}); {corrected}")
    return f"free-run closure {basis} {headline} ({detail}; {mean}); {corrected}"


def headline_text(d: Diagnosis) -> str:
    """The headline closure, labelled as what it is: above a floor, raw, or no gap to close."""
    g = d.gap
    if g.no_gap:
        lead = ("**No closure measured**: the gap is not explained by the candidates, so nothing was corrected."
                if d.verdict_class == "unexplained" else
                "**No closure measured**: neither of the two that explain the data about as well is named, so nothing "
                "was corrected." if d.verdict_class == "ambiguous" else
                "**No gap to close**: nothing was named to correct, so a closure would be a ratio of noise.")
        return (lead + " For "
                "reference, the typical held-out window's free-run angle MSE (the median over windows of each window's "
                f"mean squared error) is {number(g.typical_free_run_mse_nominal, '.3g')} rad² for the nominal model and "
                f"{number(g.typical_free_run_mse_corrected, '.3g')} rad² with the physics {REFITTED} "
                f"({values_text(d.corrected, d.unread)})"
                + (", the nominal model on the encoder's angles, the refit on those found by matching the frames to "
                   "the decoder's renders: not comparable." if g.closure_basis == "pixels" else "."))
    note = f" {g.floor_note[0].upper()}{g.floor_note[1:]}." if g.floor_note else ""
    bold = "**" if g.gap_above_floor else ""  # (a ratio of noise leads with no bold percentage)
    if g.closure_basis == "pixels":
        kind = "of the gap above the matched floor, in pixels" if g.floor_subtracted else "raw, in pixels"
        headline = (f"{bold}Free-run closure {_pct(g.free_run_gap_closure)}, {kind}{bold}: the corrected model reads its angles "
                    "by matching the frames to the decoder's renders, not with the encoder, and angle errors of the two "
                    "would not be comparable. On the typical held-out window (the median over windows of each window's "
                    f"mean pixel MSE of the rendered free run), the nominal model is at {number(g.typical_pixel_mse_nominal, '.3g')}, "
                    f"the corrected one at {number(g.typical_pixel_mse_corrected, '.3g')}, and "
                    + (f"no prediction can beat {number(g.pixel_mse_floor, '.3g')}, the error of the best-matching "
                       "render of each frame" if g.floor_subtracted else
                       f"the best-matching render of each frame errs {number(g.pixel_mse_floor, '.3g')}")
                    + ("; the closure is the share of the gap above that floor that the correction removes."
                       if g.floor_subtracted else "; the closure is 1 − corrected / nominal.") + note)
    elif g.floor_subtracted:
        headline = (f"{bold}Free-run closure {_pct(g.free_run_gap_closure)}{bold} of the gap above the floor, on the typical "
                    "held-out window (the median over windows of each window's mean squared free-run angle error): "
                    f"{number(g.typical_free_run_mse_nominal, '.3g')} rad² nominal, {number(g.typical_free_run_mse_corrected, '.3g')} rad² "
                    f"corrected, and a floor of {number(g.typical_free_run_mse_floor, '.3g')} rad², the corrected model's own error "
                    "on a simulated twin of the held-out data that it describes exactly (re-simulated with the corrected "
                    + ("physics, rendered by the simulator, " if g.floor_source != "decoder" else
                       "physics, drawn by the model's own decoder, whose picture is this recording's camera as it re-renders "
                       "the recording about as well as its training frames, ")
                    + (f"filmed through H.264 at crf {g.floor_crf:.0f}, the quality at which its median one-step "
                       "residual is this recording's (whose frames come from a lossy video), " if g.floor_crf is not None
                       else "")
                    + ("read by the encoder)" if g.floor_source != "decoder" else
                       "read by the encoder, and scaled down to this recording's own vision noise by the ratio of the "
                       "one-step errors, recording over twin)")
                    + ". Raw, with no floor subtracted (1 − corrected / nominal of the same two numbers): "
                    f"{_pct(g.typical_free_run_closure)}." + note)
    else:
        headline = (f"{bold}Free-run closure {_pct(g.free_run_gap_closure)}, raw{bold}: 1 − err_corrected / err_nominal on the "
                    "typical held-out window (the median over windows of each window's mean squared free-run angle "
                    f"error: {number(g.typical_free_run_mse_nominal, '.3g')} rad² nominal, "
                    f"{number(g.typical_free_run_mse_corrected, '.3g')} rad² corrected). No floor is subtracted." + note)
    if not g.gap_above_floor:
        headline = ("**No gap above the floor to close** on the typical held-out window: the nominal model's error there "
                    f"is within {MEASURABLE_GAP:g}x the floor, so the closure ({_pct(g.free_run_gap_closure)}) is a ratio "
                    "of noise. " + headline)
    return headline


def markdown(d: Diagnosis, model: str, data: str, command: str, model_warning: str | None = None) -> str:
    """The report as Markdown; ``model_warning``: what the model's own records say against it (a run that did not
    converge), said above the verdict, which measures the recording against that model."""
    g = d.gap
    lines = [
        "# piga-diagnose report", "",
        f"Command: `{command}`", "", f"Model: `{model}`. Data: `{data}` (frames and actions only).", "",
        *([f"**Warning: {model_warning}.** The effects below are the recording measured against this model, so they "
           "may be the model's own error.", ""] if model_warning else []),
        f"## Verdict: {d.verdict}", "",
    ]
    if d.effects:
        lines += ["| effect | value | 95% interval | unit |", "|---|---|---|---|"]
        for e in d.effects:
            rows = [(e.effect, e.value, e.interval, e.unit + (f", {e.where}" if e.where else "")
                     + (f", in the recording ({number(e.training, '.3g')} in the model's own training file)"
                        if e.training is not None else ""))]
            if e.effect == "shift":  # its length, and each component with its own interval
                rows += [("shift right (dx)", e.dx, e.dx_interval, "px"), ("shift down (dy)", e.dy, e.dy_interval, "px")]
            for name, value, ci, unit in rows:
                shown = value_text(value, ci if ci and all(math.isfinite(x) for x in ci) else None, digits=4) \
                    if isinstance(value, float) else _fmt(value)
                lines.append(f"| {name} | {shown} | {_interval(ci)} | {unit} |")
        lines.append("")
    lines += [f"- {n}" for n in d.exclusions + d.notes] + ([""] if d.notes or d.exclusions else [])
    lines += ambiguity_lines(d)
    headline = headline_text(d)
    other = "refitted" if g.no_gap else "corrected"  # a refit that corrects nothing has no closure (a ratio of noise)

    def closure(i: int) -> str:
        return "–" if g.no_gap else f"{100 * g.closure[i]:.1f}%"

    floor = "" if g.free_run_mse_floor is None else (
        f" On the twin, an exactly right model has {number(g.free_run_mse_floor, '.3g')} rad²" + (
            f": {_pct(g.mean_free_run_gap_closure)} of the gap above that floor is closed."
            if g.mean_free_run_gap_closure is not None else " (nothing to close)." if g.no_gap else
            f", so no closure above it is given for the means (the nominal error is not {MEASURABLE_GAP:g} times that "
            "floor: a ratio of noise)."))
    lines += [
        "## Size of the gap, and how far it shrinks", "", headline, "",
        f"Mean over all held-out windows and horizons 1..{g.horizon[-1]}: angle MSE {number(g.free_run_mse_nominal, '.3g')} rad² "
        f"nominal, {number(g.free_run_mse_corrected, '.3g')} rad² {other}"
        + (" (nothing to close)" if g.no_gap else f": raw closure {100 * g.free_run_closure:.1f}%")
        + (", in angles, which the corrected model reads by matching the frames to the decoder's renders and the "
           "nominal one with the encoder: not comparable, unlike the headline in pixels" if g.closure_basis == "pixels" else "") + ". That mean "
        "is dominated by the few windows that pass near upright, where any error grows fast, even in an exactly right "
        "model." + floor + " One step: RMSE "
        f"{math.degrees(g.one_step_rms_nominal_rad):.3f}° nominal, {math.degrees(g.one_step_rms_corrected_rad):.3f}° {other}"
        + (f" ({math.degrees(g.one_step_rms_nominal_matched_rad):.3f}° nominal on the corrected model's matched angles)"
           if g.one_step_rms_nominal_matched_rad is not None else "") + ".", "",
        f"Nominal g = {number(d.nominal['g'], '.4f')}, a = {number(d.nominal['a'], '.4f')}; "
        + (f"{REFITTED}: " if g.no_gap else "corrected: ")
        + ", ".join(f"{k} = {_fmt(v)}" for k, v in d.corrected.items()) + convention_text(d), "",
        "![gap](gap.png)", "",
        f"| horizon | angle RMSE nominal (deg) | {other} (deg) | closure | pixel MSE nominal | {other} |",
        "|---|---|---|---|---|---|",
    ]
    pn, pc = g.pixel_mse_nominal, g.pixel_mse_corrected
    for i in sorted({0, 1, 4, 9, 19, len(g.horizon) - 1} & set(range(len(g.horizon)))):
        pix = (f"{pn[i]:.2e} | {pc[i]:.2e}" if i < len(pn) else "– | –")
        lines.append(f"| {g.horizon[i]} | {math.degrees(math.sqrt(g.state_mse_nominal[i])):.3f} | "
                     f"{math.degrees(math.sqrt(g.state_mse_corrected[i])):.3f} | {closure(i)} | {pix} |")
    if d.control:
        env = ", ".join(f"{k}={v}" for k, v in d.control["effects"].items()) or "none"
        reader = ("reads angles through the fitted camera (matching) instead of the encoder"
                  if d.corrected_camera() is not None else "reads angles with the same encoder")
        lines += ["", f"MPC on the simulated real system ({env}), same frames and planner; the corrected agent plans with the "
                  f"corrected physics and {reader}:", "",
                  summary_markdown([EpisodeSummary.from_dict(r) for r in d.control["rows"]], extra=[("physics", "physics")]).rstrip()]
    v = d.vision
    ratio = "" if v.ratio is None else f" (x{number(v.ratio, '.2f')})"
    training = "an unknown error" if not v.rec_mse_training else f"{number(v.rec_mse_training, '.2e')}"
    lines += [
        "", "## Where it lies", "",
        f"- **Vision**: the autoencoder re-renders the real frames with MSE {number(v.rec_mse_real, '.2e')}, against "
        f"{training} on its training frames{ratio}.",
        *_camera_lines(v),
        f"- **Dynamics**: on the encoded angles, the nominal physics' held-out free-run angle RMSE is "
        f"{math.degrees(math.sqrt(g.free_run_mse_nominal)):.2f}°.", "",
        "![residual heatmap](residual_heatmap.png) ![correlations](correlations.png)", "",
        *(["A held-out frame, as recorded and as each model re-renders it:", "", "![frames](frames.png)", ""]
          if d.pictures is not None else []),
        "| bin | n | mean residual (rad/s²) | RMS |", "|---|---|---|---|",
    ]
    for group in d.residuals["bins"].values():
        for b in group:
            lines.append(f"| {b['bin']} | {b['n']} | {_fmt(b['mean'])} | {_fmt(b['rms'])} |")
    cc = d.residuals["action_correlation"]
    peak = (f"Residual–action cross-correlation peak: lag {cc['peak_lag']} (band ±{cc['band']:.3f}; a peak at lag k "
            "points to a delay of k steps)." if cc["peak_lag"] is not None else
            f"Residual–action cross-correlation: no positive peak outside the band ±{cc['band']:.3f} (a peak at lag k "
            "would point to a delay of k steps).")
    lines += ["", peak, "", "## Candidates", "",
              "Each fitted with g and a on the fit split; BIC of one-step residuals on the fit split (lower is better); "
              "error on the held-out split.", "",
              "| candidate | BIC | ΔBIC vs none | held-out free-run MSE, typical window (rad²) | mean (rad²) | fitted values |",
              "|---|---|---|---|---|---|"]
    for c in d.candidates:
        vals = ", ".join(f"{k} = {_fmt(float(val))}" for k, val in c.values.items()) + (f", k = {c.delay}" if c.delay else "")
        lines.append(f"| {c.candidate} | {c.bic:.0f} | {_fmt(c.delta_bic)} | {c.typical_free_run_mse:.3g} | "
                     f"{c.held_out_free_run_mse:.3g} | {vals} |")
    lines += ["", "Selection (every set of effects, against none; a set is accepted when each of its effects earns its place "
              "against the same set without it, and the accepted set of lowest BIC is chosen):", ""]
    for s in d.selection:
        lines.append(f"- {s.tried}: BIC drop {s.bic_drop:.1f}, typical held-out free-run drop {100 * s.free_run_drop:.1f}% "
                     f"-> {'accepted' if s.accepted else 'rejected'}{' (ambiguous with the chosen set)' if s.ambiguous else ''}")
    gb = d.generic_basis
    lines.append(f"- flexible basis on what is left: BIC drop {gb.bic_drop:.1f}, held-out residual drop "
                 f"{100 * gb.held_out_drop:.1f}% -> {'significant: not explained' if gb.significant else 'nothing left to explain'}")
    return "\n".join(lines) + "\n"


def check_report_target(out: str | os.PathLike[str], overwrite: bool) -> Path:
    """Fails early, before any work, if the report cannot or may not be written into the folder ``out``.

    The folder need not exist (it is created at the end, with any missing parents); if it exists,
    none of :data:`REPORT_FILES` may be in it without ``overwrite``.
    """
    from piga.io.resources import check_figure_disk

    folder = Path(out)
    check_folder_target(folder, logs=False)  # a report, no TensorBoard logs: any name the filesystem takes
    if folder.is_dir():
        for name in REPORT_FILES:
            check_writable_target(folder / name, overwrite)
    else:
        parent = folder.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
            raise PermissionError(f"cannot create --out {folder}: {parent} is not a writable folder")
    check_figure_disk(folder / REPORT_FILES[0], "the diagnosis (its report and figures)")
    return folder


def _write_files(d: Diagnosis, folder: Path, model: str, data: str, command: str, overwrite: bool,
                 model_warning: str | None = None) -> None:
    save_figure(gap_figure(d), folder / "gap.png", overwrite=overwrite)
    save_figure(heatmap_figure(d), folder / "residual_heatmap.png", overwrite=overwrite)
    save_figure(correlation_figure(d), folder / "correlations.png", overwrite=overwrite)
    if d.pictures is not None:
        save_figure(frames_figure(d), folder / "frames.png", overwrite=overwrite)
    write_json(folder / "report.json", {"command": command, "model": model, "data": data, "model_warning": model_warning,
                                        **d.to_dict()}, overwrite=overwrite)
    with atomic_output(folder / "report.md", overwrite=overwrite) as tmp:
        tmp.write_text(markdown(d, model, data, command, model_warning), encoding="utf-8")


def write_report(d: Diagnosis, out: str | os.PathLike[str], model: str, data: str, command: str,
                 overwrite: bool = False, model_warning: str | None = None) -> Path:
    """Writes :data:`REPORT_FILES` into the folder ``out``; returns the path of ``report.md``. ``model_warning``: what
    the model's records say against it (:func:`piga.io.runs.convergence_warning`), said in the report too.

    A new folder appears whole: the files are written into a hidden sibling, which is then renamed
    to ``out``. Into an existing folder, each file is written atomically.
    """
    folder = check_report_target(out, overwrite)
    if folder.is_dir():  # all or none of them, so that a failure part-way leaves nothing to refuse the rerun
        with written_together(folder / name for name in REPORT_FILES):
            _write_files(d, folder, model, data, command, overwrite, model_warning)
        return folder / "report.md"
    made = missing_folders(folder.parent)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = partial_path(folder)
    try:
        tmp.mkdir()
        _write_files(d, tmp, model, data, command, overwrite=True, model_warning=model_warning)
        try:
            os.rename(tmp, folder)
        except OSError as exc:  # another command made it meanwhile (a rename never replaces a folder with files)
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
            raise OutputExistsError(f"{folder} appeared while writing; pass --overwrite to replace it") from None
    except BaseException:  # refused or interrupted: the parents made for it go too, while empty
        shutil.rmtree(tmp, ignore_errors=True)
        remove_empty_folders(made)
        raise
    return folder / "report.md"
