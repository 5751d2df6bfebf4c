"""What a diagnosis finds, as typed records: the effects, the candidate table, the gap, the vision check.

:func:`piga.diagnostics.diagnose.analyse` builds them step by step; :mod:`piga.diagnostics.report`
reads them. :meth:`Diagnosis.to_dict` gives the JSON of ``report.json``. Each record can also be
read by key, like that JSON (``diagnosis.gap["free_run_closure"]``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from piga.diagnostics import fit
from piga.diagnostics.vision import Camera


class _ByKey:
    """Read a record's fields by name too, as in ``report.json``: ``record["name"]``, ``record.get("name")``."""

    def __getitem__(self, key: str) -> Any:
        if key not in {f.name for f in fields(self)}:  # type: ignore[arg-type]
            raise KeyError(key)
        return getattr(self, key)

    def __contains__(self, key: str) -> bool:
        return key in {f.name for f in fields(self)}  # type: ignore[arg-type]

    def get(self, key: str, default: Any = None) -> Any:
        return getattr(self, key) if key in self else default


#: The most that rounding may move a bound of a printed interval, as a fraction of the interval's width: a gain's
#: interval of 1.2047..1.2151 printed "1.2..1.22", which reads as holding 1.2; it prints "1.205..1.215".
ROUNDING_OF_WIDTH = 0.25


def _interval_digits(low: float, high: float, digits: int) -> int:
    """``digits``, or as many more (up to 8) as keep two different bounds apart and move neither by more than
    :data:`ROUNDING_OF_WIDTH` of the width."""
    for digits in range(digits, max(digits, 8) + 1):
        if low == high:
            break
        lo, hi = f"{low:.{digits}g}", f"{high:.{digits}g}"
        if lo != hi and max(abs(float(lo) - low), abs(float(hi) - high)) <= ROUNDING_OF_WIDTH * abs(high - low):
            break
    return digits


def interval_text(low: float, high: float, digits: int = 3) -> str:
    """``low..high`` to ``digits`` significant digits, or as many more (up to 8) as keep two different bounds apart:
    an interval of 1.9973..2.0010 read "2..2", as if it had no width."""
    digits = _interval_digits(low, high, digits)
    return f"{low:.{digits}g}..{high:.{digits}g}"


def value_text(value: float, interval: list[float] | None, digits: int = 3) -> str:
    """``value`` to as many significant digits as its 95% ``interval`` is printed with (:func:`interval_text`), so that
    a value within its interval reads within it too (rounding to a fixed number of significant digits keeps the order):
    "mean 1 (95% interval 1.001..1.002)" printed 1.0015 to 3 digits and its bounds to 4."""
    if value is None or not math.isfinite(value):
        return "–"
    if interval is not None and all(math.isfinite(x) for x in interval):
        digits = _interval_digits(*interval, digits)
    return f"{value:.{digits}g}"


def _with_interval(value: float | None, interval: list[float] | None, unit: str) -> str:
    """"value unit (95% interval low..high)", the value to the interval's digits; without a finite interval, none."""
    known = interval is not None and all(math.isfinite(x) for x in interval)
    ci = f" (95% interval {interval_text(*interval)})" if known else ""
    return f"{value_text(value, interval if known else None)} {unit}{ci}"


def _toward(value: float | None, interval: list[float] | None, positive: str, negative: str) -> str:
    """:func:`_with_interval` of a shift's component in px toward ``positive`` ("right"), or, where it is negative, of
    its size toward ``negative`` ("left") with the interval turned with it."""
    if value is None or value >= 0:
        return _with_interval(value, interval, f"px {positive}")
    return _with_interval(-value, None if interval is None else [-interval[1], -interval[0]], f"px {negative}")


@dataclass(frozen=True)
class Effect(_ByKey):
    """A named effect with its coefficient."""

    effect: str
    """Its name: a dynamics candidate, "gain", "frame_delay", or a camera effect (blur, shift, zoom, exposure, noise,
    frame_drop)."""
    value: float
    """Its coefficient (steps for a delay)."""
    unit: str
    """The coefficient's unit."""
    interval: list[float] | None = None
    """95% interval (None: none, e.g. a discrete delay or no bootstrap)."""
    dx: float | None = None
    """Shift only: px to the right."""
    dy: float | None = None
    """Shift only: px down."""
    dx_interval: list[float] | None = None
    """Shift only: 95% interval of dx."""
    dy_interval: list[float] | None = None
    """Shift only: 95% interval of dy."""
    where: str | None = None
    """A camera effect in part of the recording only: where it shows ("in 25 of 50 sequences (the even ones; in the
    others, none)", "from frame 12 on (in the frames before it, none)"; :mod:`piga.diagnostics.partial`); None: in
    all of it."""
    training: float | None = None
    """A damping only: the same parameter as the model's own training file reads it, where the two files differ in it
    (``value`` is then the recording's reading, both on top of the nominal model's own damping; see
    :func:`piga.diagnostics.diagnose.damping_differs`); None: no such comparison."""
    stated: bool = False
    """``within_frame`` only: its substeps are the recorded system's physics steps per frame as its file states them
    (:attr:`piga.diagnostics.fit.Windows.substeps`), not a fit."""

    def describe(self) -> str:
        """One phrase for the verdict line."""
        steps = lambda k: f"{k} step" + ("s" if k != 1 else "")  # noqa: E731
        if self.effect == "delay":
            return f"actuator delay of {steps(self.value)}"
        if self.effect == "frame_delay":
            return f"camera delay (frame_delay) of {steps(self.value)}"
        if self.effect == "flip":
            return ("flipped actuation (the frames show the torque reversed: a camera on the other side of the hinge, "
                    "or a motor wired the other way)")
        if self.effect == "within_frame":
            return ("the system integrates within the frame (moves under the held action between frames; "
                    + (f"{self.value:g} physics steps per frame, as its file states)" if self.stated else
                       f"fits best as {self.value:g} substeps per frame)"))
        where = f" {self.where}" if self.where else ""
        if self.effect == "zoom":
            return (f"zoom {_with_interval(self.value, self.interval, 'x the drawn size')}{where}: a camera nearer or "
                    "farther, or a pendulum of another length, draws it so")
        if self.effect == "shift":  # each component with its own interval, toward the side it moves ("-1.5 px right")
            return (f"shift {_toward(self.dx, self.dx_interval, 'right', 'left')}, "
                    f"{_toward(self.dy, self.dy_interval, 'down', 'up')}{where}")
        if self.training is not None:
            known = self.interval is not None and all(math.isfinite(x) for x in self.interval)
            none = self.value <= 0 or (known and self.interval[0] <= 0)
            recording = (f"none (b = {_with_interval(self.value, self.interval, self.unit)})" if none else
                         _with_interval(self.value, self.interval, self.unit))
            return (f"{self.effect} {self.training:.3g} {self.unit} in the model's own training file, {recording} in "
                    "the recording")
        return f"{self.effect} {_with_interval(self.value, self.interval, self.unit)}{where}"

    def to_dict(self) -> dict[str, Any]:
        shift_only = ("dx", "dy", "dx_interval", "dy_interval")
        return {k: v for k, v in asdict(self).items()
                if (k not in shift_only or self.effect == "shift") and (k not in ("where", "training") or v is not None)
                and (k != "stated" or v)}


@dataclass(frozen=True)
class Score:
    """A candidate physics and how well it predicts."""

    model: fit.Model
    """The fitted candidate."""
    bic: float
    """BIC of its one-step residuals on the fit split."""
    free_run: float
    """Mean held-out free-run angle MSE (rad²) over windows and horizons."""
    horizon: np.ndarray
    """(H,) held-out free-run angle MSE (rad²) per horizon."""
    typical: float
    """Held-out free-run angle MSE (rad²) of the typical (median) window."""

    @property
    def name(self) -> str:
        return self.model.name


@dataclass(frozen=True)
class CandidateRow(_ByKey):
    """A row of the candidate table."""

    candidate: str
    """"nominal (no refit)" (with "; the encoder's angles, not comparable" where the others are read on other angles),
    "none (g, a refitted)" or the effect's name."""
    bic: float
    """One-step BIC on the fit split."""
    held_out_free_run_mse: float
    """Mean held-out free-run angle MSE (rad²)."""
    typical_free_run_mse: float
    """The typical held-out window's free-run angle MSE (rad²)."""
    values: dict[str, float]
    """Fitted g, a and the effect's parameter."""
    delta_bic: float | None = None
    """BIC against "none (g, a refitted)" (None for the nominal row)."""
    delay: int | None = None
    """k of a delay (None: no delay)."""

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        if self.delta_bic is None:  # the nominal row has neither
            out.pop("delta_bic")
            out.pop("delay")
        return out


@dataclass(frozen=True)
class SelectionStep(_ByKey):
    """One set of effects that the selection fitted (:func:`piga.diagnostics.diagnose.select`)."""

    tried: str
    """The effects, joined by "+"."""
    bic_drop: float
    """Its BIC drop against "none" (g and a refitted)."""
    free_run_drop: float
    """Relative drop of the typical held-out free-run error against "none"."""
    accepted: bool
    """Each of its effects earns its place against the same set without it (BIC and free-run drops)."""
    ambiguous: bool = False
    """Accepted too, and explains the data about as well as the chosen set; or, where no set is accepted, favoured by
    the held-out free run at a BIC close to "none"'s."""


@dataclass(frozen=True)
class Ambiguity(_ByKey):
    """Two candidates that explain the residual about equally: by BIC, by the typical held-out free-run
    error, and (with the bootstrap) by overlapping 95% intervals of the values they both fit."""

    between: list[str]
    """The effects that differ, one entry per candidate ("within_frame", "speed_clip", ...)."""
    candidates: list[str]
    """The two whole candidates (e.g. "damping+within_frame", "damping+speed_clip"); the first is the
    physics the gap is measured with (the lower BIC, or "none" where a single or a pair that the free run favours
    lowers the BIC by less than an effect needs)."""
    bic: list[float]
    """Their one-step BICs on the fit split."""
    typical_free_run_mse: list[float]
    """Their typical held-out free-run angle MSE (rad²)."""
    intervals_overlap: bool | None
    """The 95% intervals of their shared values overlap (None: not checked, no bootstrap)."""
    separate_by: str
    """What data would tell them apart."""

    def describe(self) -> str:
        """The verdict's phrase."""
        a, b = self.between
        first, second = self.typical_free_run_mse
        from piga.diagnostics.diagnose import DiagnoseConfig  # (diagnose imports this module)

        # a rival of "none" is one that the held-out free runs favour where the one-step fit cannot choose: say so
        lower = 1 - DiagnoseConfig.min_gain  # the free-run drop that makes a rival
        favoured = b if second < lower * first else a if first < lower * second else None
        # (a set the one-step fit favours as a whole but not each of its effects beside the others: bias+saturation
        # lowered the BIC by 22.7, the bias by 5.2 beside the saturation alone, and "cannot tell them apart" was said)
        lowest = b if self.bic[1] < self.bic[0] else a  # (said: "ΔBIC 22.7" and "ΔBIC 3.7" were read as one side)
        whole = abs(self.bic[1] - self.bic[0]) > DiagnoseConfig.ambiguous_bic and "+" in lowest
        one_step = (f"the one-step fit favours {lowest} as a whole, but not each of its effects beside the others" if whole
                    else "the one-step fit cannot tell them apart")
        why = (f"{one_step}, and the free runs of a few held-out sequences, which favour {favoured}, are too few to "
               "decide" if favoured else "the data cannot tell them apart")
        return (f"ambiguous between {a} and {b} (ΔBIC {abs(self.bic[1] - self.bic[0]):.1f}, lower for {lowest}; typical "
                f"held-out free-run errors {first:.3g} and {second:.3g} rad²): {why}; {self.separate_by} would separate "
                "them")


@dataclass(frozen=True)
class GenericBasis(_ByKey):
    """The "not explained by the candidates" test: a flexible basis fitted to what is left."""

    bic_drop: float
    """BIC drop of the basis on the fit split's one-step residuals."""
    held_out_drop: float
    """Relative drop of the held-out one-step residual."""
    significant: bool
    """Both large enough: the gap is not explained by the candidates."""
    reading_drop: float = 0.0
    """Relative drop of the held-out one-step residual by a periodic error in the encoder's angles alone
    (:func:`piga.diagnostics.residuals.reading_features`); where both explain it, ``bic_drop`` and
    ``held_out_drop`` are the state-action basis's on top of it."""
    reading_rms: float = 0.0
    """The rms over the recording's angles (rad) of the angle-reading error that the fit of
    ``reading_drop`` implies."""
    reading_significant: bool = False
    """A periodic reading error in the encoder's angles explains the residual (BIC and held-out drop)."""
    reading_decides: bool = False
    """The state-action basis explains the residual alone but not on top of the reading error: the gap
    left is the encoder's, not the physics'."""


@dataclass(frozen=True)
class Naming(_ByKey):
    """The effects named from the chosen physics and the camera stage, and the verdict."""

    effects: list[Effect]
    """Named effects, camera ones first."""
    notes: list[str]
    """Findings that are not effects (Gymnasium's own clip, a gain within its interval, ...)."""
    verdict: str
    """One line."""
    verdict_class: str
    """"none", "unexplained", "ambiguous", or the effects' names joined by "+" in alphabetical order."""
    physics: fit.Model | None = None
    """The recording's physics that the named effects describe, where it is not the chosen candidate's: a damping
    that the two files show differently, read on the recording with g and a (:func:`~piga.diagnostics.diagnose.
    damped_reference`). The corrected model, and its closure, are this physics then."""


@dataclass(frozen=True)
class CameraSummary(_ByKey):
    """The camera stage's findings, for the report."""

    camera: Camera
    """The accepted camera (all zero: none)."""
    camera_candidates: list[dict[str, Any]]
    """The camera stage's candidate table."""
    noise: float
    """Sensor noise (gray levels)."""
    repeated_frames: int
    """Frames that repeat the previous one."""
    dropped_frames: int
    """... while the pendulum moves."""
    drop_rate: float
    """Their rate."""
    leading_repeats: int
    """Frames 1..k repeat frame 0 in nearly every sequence."""
    matched_mse_nominal: float
    """Held-out matched residual with no camera effect."""
    matched_mse_corrected: float
    """... with the accepted camera."""
    angles: str
    """"matched" (the dynamics use angles matched through the camera) or "encoder"."""
    noise_correlation: float = float("nan")
    """Correlation of the still pixels between successive frames: sensor noise has none (NaN: not measured)."""
    drawn_scale: float | None = None
    """The pendulum's drawn size over the decoder's renders', through the accepted camera (None: not measured)."""


@dataclass(frozen=True)
class VisionSummary(_ByKey):
    """How well the autoencoder explains the recording, and the camera stage."""

    rec_mse_real: float
    """Mean re-rendering MSE of the recording's frames."""
    rec_mse_training: float
    """The model's own per-frame reconstruction MSE in training (0: unknown)."""
    ratio: float | None
    """rec_mse_real / rec_mse_training (None: the training error is unknown)."""
    camera: CameraSummary | None = None
    """The camera stage (None: not run)."""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rec_mse_real": self.rec_mse_real, "rec_mse_training": self.rec_mse_training,
                               "ratio": self.ratio}
        if self.camera is not None:
            out.update(asdict(self.camera))
        return out


@dataclass(frozen=True)
class PixelErrors(_ByKey):
    """Free-run pixel errors of the rendered predictions on the kept held-out sequences."""

    pixel_mse_nominal: list[float] = field(default_factory=list)
    """Per horizon, the nominal model (empty: no frames kept)."""
    pixel_mse_corrected: list[float] = field(default_factory=list)
    """Per horizon, the corrected model."""
    pixel_mse_floor: float | None = None
    """The matched residual of the same frames: no prediction beats it."""
    typical_pixel_mse_nominal: float | None = None
    """The typical sequence's mean pixel MSE, nominal."""
    typical_pixel_mse_corrected: float | None = None
    """... corrected."""
    typical_pixel_mse_floor: float | None = None
    """... the matched residual (the same sequences' median of their mean)."""


@dataclass(frozen=True)
class Gap(_ByKey):
    """The size of the gap per horizon, nominal vs corrected, and how far it closes."""

    horizon: list[int]
    """1..H."""
    state_mse_nominal: list[float]
    """(H,) held-out free-run angle MSE (rad²) of the nominal model."""
    state_mse_corrected: list[float]
    """(H,) ... of the corrected model."""
    closure: list[float]
    """(H,) 1 - corrected / nominal."""
    free_run_mse_nominal: float
    """Mean over windows and horizons, nominal."""
    free_run_mse_corrected: float
    """... corrected."""
    free_run_closure: float
    """1 - corrected / nominal of those means."""
    state_mse_floor: list[float] | None
    """(H,) the twin's floor (None: not measured)."""
    free_run_mse_floor: float | None
    """Its mean."""
    free_run_gap_closure: float | None
    """The headline: the typical window's closure above the floor, in angles or (``closure_basis``) pixels."""
    typical_free_run_mse_nominal: float
    """The typical held-out window's free-run angle MSE, nominal."""
    typical_free_run_mse_corrected: float
    """... corrected."""
    typical_free_run_mse_floor: float | None
    """... on the twin."""
    typical_free_run_closure: float | None
    """Raw closure on the typical window (no floor)."""
    floor_source: str | None
    """What drew the twin that measured the floor: "simulator" (Gymnasium's picture, for a recording
    from Gymnasium), "decoder" (the model's own picture of the recording's camera) or None (no twin)."""
    floor_crf: float | None
    """The H.264 quality (constant rate factor) the twin was filmed through, matched to the recording's median one-step
    residual, for frames read from a lossy video (:func:`piga.diagnostics.twin.codec_floor`); None: no codec."""
    typical_free_run_gap_closure: float | None
    """Closure above the floor on the typical window (raw when no floor)."""
    mean_free_run_gap_closure: float | None
    """Closure above the floor of the means over all windows; None where the means give no measurable
    gap above the floor, 1 where the corrected mean is at or below it (:func:`piga.diagnostics.twin.mean_gap_closure`)."""
    closure_basis: str
    """"state" (angles) or "pixels" (a camera effect changed the angles)."""
    pixel_free_run_gap_closure: float | None
    """Closure of the typical pixel gap above the matched floor; raw (1 − corrected / nominal) where
    ``pixel_closure_raw``: the floor lay above the corrected model's pixel error, so it is no floor."""
    gap_above_floor: bool
    """The nominal error exceeds the floor enough for a closure to mean something."""
    one_step_rms_nominal_rad: float
    """Held-out one-step angle RMSE, nominal (on the encoder's angles)."""
    one_step_rms_corrected_rad: float
    """... corrected."""
    pixel_mse_nominal: list[float]
    """See :class:`PixelErrors`."""
    pixel_mse_corrected: list[float]
    pixel_mse_floor: float | None
    typical_pixel_mse_nominal: float | None
    typical_pixel_mse_corrected: float | None
    floor_note: str | None = None
    """Why the headline closure has no floor subtracted (None: it has one, or none was tried): the
    recording was not filmed by the simulator's camera, or the floor lay above the corrected model's
    own error beyond its 95% interval (then it is no floor, and a closure against it would exceed
    100%); or why it is 100%: the corrected model's error lay at the floor, within that interval."""
    floor_subtracted: bool = False
    """The headline ``free_run_gap_closure`` is above a floor (the twin's, or the matched pixels');
    False: it is raw, 1 − err_corrected / err_nominal of the numbers next to it."""
    no_gap: bool = False
    """Nothing was named to correct (no effect): there is no gap to close, and no headline closure
    (``free_run_gap_closure`` None; the raw numbers stay for reference)."""
    pixel_closure_raw: bool = False
    """``pixel_free_run_gap_closure`` is raw, with no floor subtracted (it held the raw value unsaid)."""
    typical_free_run_mse_floor_interval: list[float] | None = None
    """95% bootstrap interval of ``typical_free_run_mse_floor``, a median over the held-out windows (None: no floor);
    wide on a recording of few held-out sequences."""
    held_out_windows: int | None = None
    """The held-out windows that the floor is a median over."""
    matched_floor: float | None = None
    """Where the dynamics are on angles matched through a fitted camera in a recording from Gymnasium (the closure is
    then in pixels, with no twin in angles): the typical held-out window's free-run angle MSE of the corrected physics
    on its twin, filmed through the same camera, with its named sensor noise, and matched as the recording's frames
    were (:func:`piga.diagnostics.twin.twin_floor` with ``camera``): the floor of ``typical_free_run_mse_corrected``
    in those angles. None otherwise."""
    matched_floor_interval: list[float] | None = None
    """95% bootstrap interval of ``matched_floor`` (a median over the held-out windows)."""
    one_step_rms_nominal_matched_rad: float | None = None
    """Where the corrected model's angles were matched through a fitted camera: the nominal model's held-out one-step
    angle RMSE on those same angles, the one that compares with ``one_step_rms_corrected_rad`` (None otherwise)."""


@dataclass
class Diagnosis(_ByKey):
    """Everything the report shows (JSON-ready through :meth:`to_dict`)."""

    verdict: str
    """One line: the named effect(s), "no significant gap", or "not explained by the candidates"."""
    verdict_class: str
    """"none", "unexplained", "ambiguous" (see ``ambiguity``), or the names of the effects joined by "+" (for scoring)."""
    effects: list[Effect]
    """Named effects with coefficient, 95% interval and unit."""
    nominal: dict[str, float]
    """The identified model's g, a, φ."""
    corrected: dict[str, float]
    """g, a and the effect parameters of the chosen model."""
    corrected_effects: list[str]
    """The effects in the chosen model's physics (including Gymnasium's own clip when found)."""
    candidates: list[CandidateRow]
    """Ranked table of the single-effect fits."""
    selection: list[SelectionStep]
    """Every set of effects that the selection fitted, in BIC order."""
    generic_basis: GenericBasis
    """The "not explained" test."""
    gap: Gap
    """Errors per horizon: state (rad²) and pixels, nominal vs chosen, and the closure."""
    vision: VisionSummary
    """Re-rendering error on the real frames vs the model's training error, and the camera stage."""
    residuals: dict[str, Any]
    """Heatmap, bins, autocorrelation, action cross-correlation of the nominal model."""
    notes: list[str] = field(default_factory=list)
    """Other findings (Gymnasium's own clip, vision gap, ...)."""

    control: dict[str, Any] | None = None
    """With ``--env``: MPC on the simulated real system with the nominal vs the corrected physics."""

    ambiguity: Ambiguity | None = None
    """Two candidates the data cannot tell apart (None: the choice is clear); then ``verdict_class``
    is "ambiguous" and neither's own effects are in ``effects``."""
    excluded: dict[str, str] = field(default_factory=dict)
    """Candidates left out before fitting, and why: the file's provenance (a dm_control file has no
    speed clip), or the nominal model already has them (an RK4 model moves within the frame)."""
    exclusions: list[str] = field(default_factory=list)
    """The report's sentences on ``excluded``: "excluded by the file's provenance: speed_clip (dm_control
    has no speed clip)", or "not tried: ..." (kept apart from ``notes``, which speak of the data)."""

    unread: list[str] = field(default_factory=list)
    """Parameters of ``corrected`` that the recording cannot show, left at their start: ``a`` where its actions are all
    0 (read "refitted for reference: g = 10.28, a = 1.003", an a no frame of it measured)."""

    damping_convention: dict[str, Any] | None = None
    """How ``corrected`` takes the damping ("explicit": a torque added before each Euler step, Gymnasium's
    way; "implicit": MuJoCo's), and the same frames' g, a and b under the other convention ("values",
    ``factor`` x the corrected ones): frames cannot tell the two apart. None: no damping (or RK4)."""

    pictures: dict[str, np.ndarray] | None = field(default=None, repr=False)
    """A held-out frame as recorded ("real", (H, W[, C]) in [0, 1]), re-rendered by the nominal model
    ("nominal": decoder at the encoder's angle) and by the corrected one ("corrected": through the
    fitted camera at the matched angle). For the report's picture; not in :meth:`to_dict`."""

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``report.json`` (the candidate table ends with the selection and the generic basis)."""
        return {
            "verdict": self.verdict, "verdict_class": self.verdict_class,
            "effects": [e.to_dict() for e in self.effects],
            "nominal": dict(self.nominal), "corrected": dict(self.corrected),
            "corrected_effects": list(self.corrected_effects),
            "candidates": [r.to_dict() for r in self.candidates]
            + [{"selection": [asdict(s) for s in self.selection], "generic_basis": asdict(self.generic_basis)}],
            "gap": asdict(self.gap), "vision": self.vision.to_dict(), "residuals": self.residuals,
            "notes": list(self.notes), "control": self.control,
            "ambiguity": None if self.ambiguity is None else asdict(self.ambiguity),
            "excluded": dict(self.excluded), "exclusions": list(self.exclusions),
            "damping_convention": None if self.damping_convention is None else dict(self.damping_convention),
        }

    def corrected_camera(self) -> Camera | None:
        """The camera to read angles through, when the diagnosis re-matched them (else None: the encoder)."""
        cam = self.vision.camera
        return cam.camera if cam is not None and cam.angles == "matched" else None

    def corrected_model(self) -> fit.Model:
        """The chosen physics as a :class:`piga.diagnostics.fit.Model` (for a planner)."""
        values = {k: float(v) for k, v in self.corrected.items() if k not in ("delay", "substeps")}
        return fit.Model(tuple(self.corrected_effects), int(self.corrected.get("delay", 0)), values,
                         int(self.corrected.get("substeps", 0)))
