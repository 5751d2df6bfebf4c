"""Did a training run identify its physical parameters? The check that every run ends with.

A run can end without having learned anything and still look like one that did: a small file
whose epochs end inside the autoencoder warm-up never runs the physics, a physics learning rate
that is too small leaves g where it started, and a run cut short by ``--max-minutes`` stops while
its parameters still move. The check reads the run's own record (its plan and the parameters'
trajectory, :class:`piga.training.train.TrainState`), never the truth, and gives one of three outcomes:

| outcome | meaning | ``piga-train-model`` |
|---|---|---|
| ``untrained`` | the physics never trained, a learned parameter never left its start, one collapsed to a float limit, the actuation gain faded toward 0, (for a scene) an object was not found or a slot draws nothing (:mod:`piga.evaluation.objects`), or its held-out predictions are no better than the background alone, or (with physical parameters) not clearly better than the last input frame held still | exits 1 with a line that names the fix |
| ``unsettled`` | it trained, but stopped before its plan ended, a parameter still drifts at the end or still moves about as fast as its decayed learning rate lets it, one stopped short of the value its training frames want (:mod:`piga.evaluation.profile`), or (with physical parameters) the file has no test sequences to check them on | exits 3 with a warning line |
| ``converged`` | none of the above | exits 0 |

A parameter *drifts* when its change over the last ``tail`` of the planned steps (a straight-line
fit of its log through the recorded trajectory) exceeds ``drift_tolerance``, or twice its spread
about that line, whichever is larger: at the end of the cosine schedule the learning rate is a few
percent of its peak, so a parameter that still moves by more than 1% there has not found its value
(a settled run of the default file moves g and a by under 0.5%).

A short run's learning rate is so small over its tail that a parameter still on its way moves by less than that,
so each parameter's change over the tail is also measured against the most its learning rate lets it move there
(Adam moves a log-parameter by about its learning rate a step when the gradient keeps its sign; the sum over
those steps): a parameter that moved ``speed_tolerance`` of that or more was still on its way when the schedule
ended it.

Every model's held-out predictions must beat drawing its label-free background alone (``blank_ratio``),
and a model with physical parameters must clearly beat holding the last input frame still (``hold_ratio``),
both read from frames only. A baseline without physical parameters (``piga-train-model --model video-lstm`` or
``in-ig``) has no trajectory to judge; that check and the plan's end are its whole check.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

if TYPE_CHECKING:  # the check itself needs torch and OpenCV; this module only reads its verdict
    from piga.evaluation.objects import ObjectCheck
    from piga.evaluation.profile import ParameterProfile

Outcome = Literal["converged", "unsettled", "untrained"]


@dataclass(frozen=True)
class ConvergenceConfig:
    """Thresholds of the check."""

    tail: float = 0.1
    """Fraction of the planned steps, at the end, over which drift is measured."""
    drift_tolerance: float = 0.01
    """Largest relative change over the tail of a settled parameter."""
    speed_tolerance: float = 0.75
    """Largest change over the tail of a settled parameter, as a fraction of the sum of its learning rate over those
    steps (about the most Adam can move a log-parameter there). Measured: 300 steps on 2 spring sequences
    settled with k 71% and l 43% off, l moving 0.53% (0.83 of its learning rate's sum); 300 steps on 60 spring
    sequences of 12 frames with k 20% off, k moving 0.81% (1.28). Identified runs moved 0.01 (spring, 1650
    steps) to 0.13 (the default pendulum, 2022 steps), 0.05 and 0.06 (pendulums of 20 sequences, 432 and
    406 steps); two with a still 8% short of its value moved it 0.53 (dm_control, 20 sequences, 432 steps)
    and 0.63 (a 32-pixel pendulum, 400 steps)."""
    moved_tolerance: float = 1e-3
    """Smallest relative change from its start of a parameter that was learned."""
    collapse_factor: float = 1e4
    """A parameter that ends this factor or more away from its start has collapsed (log-space runaway)."""
    actuation_fade: float = 50.0
    """An actuation gain ``a`` that ends this factor or more below its start has faded: in the frames the actions
    barely move the system, or move it the other way (a model learning a > 0 in log space can only shrink a).
    Measured on dm_control pendulums filmed from the other side (fast preset, a from 0.3): the runs settle at
    a = 0.0032 and 0.0034, 88x and 93x below the start, with g learned (the factor was 100 before them); a
    weak actuator 30x below the start is still learned as such."""
    blank_ratio: float = 0.9
    """A model whose held-out prediction MSE is above this fraction of the background's (the prediction of a
    model that learned nothing) is untrained."""
    hold_ratio: float = 0.3
    """A model with physical parameters whose held-out prediction MSE is above this fraction of that of the last
    input frame held still (a system that does not move) learned nothing of the motion, whatever its parameters
    did: it is untrained. Chosen from ``results/convergence_calibration.md``."""
    profile_tolerance: float = 0.02
    """A learned parameter whose training frames are predicted this much better (relative MSE) with it scaled by
    1.65 or 1/1.65 (:mod:`piga.evaluation.profile`) stopped short of its value: the run is unsettled."""
    flat_tolerance: float = 0.02
    """A learned parameter whose training frames are predicted within this (relative MSE) with it scaled by 1.65
    and by 1/1.65 is not determined by them: the run is judged on the others, and its summary says so. Identified
    parameters in ``results/convergence_calibration.md`` change the MSE by 18% or more one way; the damping b
    learned on Gymnasium's pendulum (truth 0) by 0.1%, and an actuation gain of a file whose actions barely move
    the system by 1.3%."""


@dataclass(frozen=True)
class ParameterCheck:
    """One learned parameter's trajectory, summarised."""

    start: float
    end: float
    change_from_start: float
    """Relative change (end - start) / |start| (absolute for a parameter that starts at 0)."""
    tail_change: float | None
    """Relative change over the tail by the straight-line fit (None: too few recorded points)."""
    tail_spread: float | None
    """Standard deviation (relative) about that line."""
    tail_speed: float | None = None
    """``tail_change`` over the sum of the physics learning rate over the same steps (None: not known)."""


@dataclass(frozen=True)
class Convergence:
    """The verdict on one run."""

    outcome: Outcome
    reason: str
    """One sentence; for ``untrained`` and ``unsettled`` it names the fix."""
    physics_steps: int
    """Steps in which the physics was part of the loss (after the warm-up)."""
    planned_steps: int
    steps: int
    parameters: dict[str, ParameterCheck] = field(default_factory=dict)
    undetermined: list[str] = field(default_factory=list)
    """Learned parameters the training frames do not determine: their profile is flat (``flat_tolerance``)."""

    @property
    def converged(self) -> bool:
        return self.outcome == "converged"

    def to_dict(self) -> dict[str, Any]:
        """What metrics.json keeps under ``convergence``."""
        return asdict(self)


def length_fix(planned: int, steps: int) -> str:
    """The fix for a run too short to judge or to learn: train longer, with this command's options (a command that
    trains through piga-train-model, piga-demo, puts its own in place of this text)."""
    if steps < planned:  # stopped by --max-minutes (a budget over the run's whole life): a larger one continues it
        return ("train longer: continue this run with --resume and a larger --max-minutes (it took "
                f"{steps} of {planned} planned steps), or give it more data")
    return ("train longer (--epochs or a larger --max-minutes, or more data), or continue this run with --resume "
            f"and a larger --epochs or --budget-steps, whichever it was started with (it took {steps} of {planned} "
            "planned steps)")


def data_fix(planned: int, steps: int) -> str:
    """The fix for a run that did not learn the motion: more data first, then :func:`length_fix`."""
    return "give it more or longer sequences, or " + length_fix(planned, steps)


#: What a run that did not converge needs first, as :func:`piga.cli.train.main`'s ``longer`` is told: to train longer
#: (:func:`length_fix`), more data and then longer training (:func:`data_fix`), or a test split (:data:`SPLIT_FIX`).
Need = Literal["length", "data", "split"]

#: The fix for a run checked on its training frames alone (a file without test sequences): this command's words (a
#: command that trains through piga-train-model, piga-demo, puts its own in their place).
SPLIT_FIX = "collect one with a test split to check them"


#: A background MSE below one gray level squared: the held-out frames hardly differ from the background.
FAINT_BACKGROUND_MSE = (1 / 255) ** 2


def _blank_fix(background: float, planned: int, steps: int) -> str:
    """The fix for predictions no better than the background: the data's, when the frames are the background."""
    if background < FAINT_BACKGROUND_MSE:
        return ("the held-out frames differ from the background by under one gray level (the system hardly shows in "
                "them, or hardly moves): check the data, not the training")
    return length_fix(planned, steps)


def check_convergence(state: Any, config: ConvergenceConfig = ConvergenceConfig(),
                      objects: ObjectCheck | None = None, blank: tuple[float, float] | None = None,
                      hold: float | None = None, profile: dict[str, ParameterProfile] | None = None,
                      held_out: bool = True, physics_lr: Callable[[int], float] | None = None) -> Convergence:
    """Judges a finished (or stopped) run from its :class:`~piga.training.train.TrainState`, and for a scene
    from ``objects`` (:func:`piga.evaluation.objects.check_objects`): a lost object leaves the physics to fit
    the others, and a slot that draws nothing is still moved by the physics (its pull, its springs), so in
    either case the parameters mean nothing.

    ``state.plan`` is the run's :class:`~piga.training.train.TrainPlan` (as a dict), ``state.start`` the
    learned parameters before the first step, ``state.trace`` their values every few steps, and
    ``state.history[-1]`` the values the run ended with.

    ``blank``: the model's held-out prediction MSE and that of its background alone (metrics.json's
    ``frame_mse_mean["prediction"]`` and ``frame_mse_background``). Predictions no better than the background
    mean nothing was learned, with physical parameters or without; a run with parameters is judged so once
    they have settled: a 45-step pendulum run whose g and a had moved and then stood still as its schedule
    decayed passed as converged, g 88% off, predicting worse than drawing no pendulum (2.8x the background's
    MSE; converged runs measured 0.37x at most).

    ``hold``: the held-out MSE of the last input frame held still (metrics.json's ``frame_mse_hold``). A model
    with parameters must beat it by ``config.hold_ratio``: pendulum runs on 20 sequences of 10 frames settled with
    g 67% off, predicting 0.85x the background's MSE and 0.5x the held frame's (identified runs: 0.12x at most).

    ``physics_lr``: the physical parameters' learning rate at a step (:func:`piga.training.train.physics_lr`). A
    parameter whose change over the tail is ``config.speed_tolerance`` or more of that rate's sum over the tail's
    steps was still moving when the schedule decayed, however little: a 300-step spring run on 2 sequences
    passed as converged with k 71% and l 43% off, l moving 0.53% (0.83 of that sum; identified runs 0.13 at
    most, and 0.63 for one with a still 8% short).

    ``held_out``: whether ``blank`` and ``hold`` were measured on a held-out split; a file without a test split is
    measured on its training split, and the reasons say so rather than "held-out".

    ``profile``: each learned parameter's profile on the training frames (:mod:`piga.evaluation.profile`). A
    parameter whose frames are predicted clearly better with it 1.65x larger or smaller stopped short of its
    value, however still it stands: the run is unsettled.
    One whose frames are predicted alike 1.65x larger and smaller is not determined by them: the verdict lists it
    under ``undetermined`` (a file whose actions had a gain of 1e-6 gave a = 0.09, 10^5x off, converged
    beside a learned g; its profile was flat within 1.3%).
    """
    plan = state.plan
    steps = int(state.step)
    planned = int(plan["epochs"]) * int(plan["steps_per_epoch"])
    physics_steps = max(0, steps - int(plan["warmup_steps"]))
    end_values = {k: float(state.history[-1][k]) for k in state.start} if state.history else dict(state.start)
    # the most the learning rate lets a parameter move over the tail's recorded steps, the same for each of them
    tail = [int(row[0]) for row in state.trace or () if row[0] > planned * (1 - config.tail)]
    allowed = sum(physics_lr(step) for step in range(tail[0], tail[-1])) if physics_lr and tail else 0.0
    checks = {name: _parameter(name, float(start), end_values[name], state.trace, list(state.start), planned, config,
                               allowed) for name, start in state.start.items()}

    flat = [name for name, p in (profile or {}).items()
            if name in checks and max(p.lower, p.upper) < 1 + config.flat_tolerance
            and min(p.lower, p.upper) >= 1 - config.profile_tolerance]

    def verdict(outcome: Outcome, reason: str) -> Convergence:
        if not held_out:  # the file has no test split: the report was measured on the training frames
            reason = reason.replace("check the data (its test split)", "check the data").replace("held-out", "training-split")
        return Convergence(outcome, reason, physics_steps, planned, steps, checks, flat)

    if physics_steps == 0:
        return verdict("untrained", f"the physics never trained: all {steps} steps were the autoencoder warm-up "
                                    f"({plan['warmup_steps']} steps); " + length_fix(planned, steps))
    # A parameter that starts at 0 (the pendulum's angle offset) has no scale of its own: it is judged
    # in absolute terms, and only for drift, since its truth may well be 0.
    scaled = {name: c for name, c in checks.items() if c.start != 0}
    for name, c in checks.items():
        if not math.isfinite(c.end):
            return verdict("untrained", f"{name} became {c.end}: lower --lr-physics")
    for name, c in scaled.items():
        if abs(c.end) >= config.collapse_factor * abs(c.start) or abs(c.end) <= abs(c.start) / config.collapse_factor:
            return verdict("untrained", f"{name} collapsed from {c.start:.4g} to {c.end:.4g}: the physics learning "
                                        "rate is too large for this file; lower --lr-physics")
    fade = scaled.get("a")
    if fade is not None and abs(fade.end) <= abs(fade.start) / config.actuation_fade:
        return verdict("untrained", f"a shrank from {fade.start:.4g} to {fade.end:.4g} (x{abs(fade.start / fade.end):.0f}): in "
                                    "these frames the actions barely move the system, or move it the other way (a camera "
                                    "filming from the other side, a motor wired in reverse); retrain with "
                                    "--signed-actuation, or check the file's actions")
    if objects is not None and objects.lost and objects.too_few_slots:  # no rate or length moves a spring of one body
        return verdict("untrained", objects.reason())
    stuck = [name for name, c in scaled.items() if abs(c.change_from_start) < config.moved_tolerance]
    if stuck:
        never = (f"{', '.join(stuck)} never left {'its' if len(stuck) == 1 else 'their'} initial value in "
                 f"{physics_steps} physics steps")
        if blank is not None and not blank[0] < config.blank_ratio * blank[1] and blank[1] >= FAINT_BACKGROUND_MSE:
            # a physics rate too small leaves the predictions poor too, so the two causes are named: --lr 10, whose
            # network never learned the frames (encoder angles 143° off), was told to raise --lr-physics alone
            return verdict("untrained", f"{never}, and its held-out predictions (MSE {blank[0]:.4g}) are not clearly "
                                        f"better than drawing the background alone (MSE {blank[1]:.4g}): raise "
                                        "--lr-physics, or, where --lr was raised, lower it (a network rate too large "
                                        "learns no frames, and leaves the physics nothing to fit); or "
                                        + length_fix(planned, steps))
        return verdict("untrained", f"{never}; raise --lr-physics or " + length_fix(planned, steps))
    if objects is not None and (objects.lost or (objects.empty_slots and checks)) and steps < planned:
        # cut short (--max-minutes): untrained objects are those of a run that barely trained, which --resume
        # continues; another seed was asked for, and the run thrown away
        return verdict("unsettled", f"the run stopped at step {steps} of {planned} planned, before its objects were "
                                    "learned; " + length_fix(planned, steps))
    if objects is not None and objects.lost:
        return verdict("untrained", objects.reason())
    if objects is not None and objects.empty_slots and checks:  # (a baseline has no parameters to bend)
        return verdict("untrained", objects.empty_reason())
    if blank is not None and not checks and not blank[0] < config.blank_ratio * blank[1]:
        return verdict("untrained", f"its held-out predictions (MSE {blank[0]:.4g}) are not clearly better than drawing "
                                    f"the background alone (MSE {blank[1]:.4g}; the bar is "
                                    f"{config.blank_ratio:g}x it, {config.blank_ratio * blank[1]:.4g}); "
                                    + _blank_fix(blank[1], planned, steps))
    if steps < planned:
        return verdict("unsettled", f"the run stopped at step {steps} of {planned} planned, before its learning rate "
                                    "decayed; " + length_fix(planned, steps))
    short = [name for name, c in checks.items() if c.tail_change is None]
    if short:
        from envs.fields import counted  # here: training runs without gymnasium's import

        return verdict("unsettled", f"the run is too short to judge whether {', '.join(short)} settled "
                                    f"({counted(steps, 'step')}, fewer than 5 recorded over its last tenth); "
                                    + length_fix(planned, steps))
    drifting = []
    for name, c in checks.items():
        if c.tail_change is not None and abs(c.tail_change) > max(config.drift_tolerance, 2 * (c.tail_spread or 0.0)):
            drifting.append(f"{name} moved {100 * c.tail_change:+.2f}% over the last {100 * config.tail:.0f}% of steps")
    if drifting:
        return verdict("unsettled", "still drifting at the end: " + "; ".join(drifting) + "; " + length_fix(planned, steps))
    if not checks:
        return verdict("converged", f"the {'physics' if blank is None else 'prediction'} trained for {physics_steps} "
                                    f"steps (no parameter to learn)" + ("" if blank is None else
                                    f"; its held-out MSE {blank[0]:.4g} is below the background's {blank[1]:.4g}"))
    if blank is not None and not blank[0] < config.blank_ratio * blank[1]:  # settled, but on what?
        return verdict("untrained", f"its parameters settled, but its held-out predictions (MSE {blank[0]:.4g}) are not "
                                    f"clearly better than drawing the background alone (MSE {blank[1]:.4g}; the bar is "
                                    f"{config.blank_ratio:g}x it, {config.blank_ratio * blank[1]:.4g}); "
                                    + _blank_fix(blank[1], planned, steps))
    if blank is not None and hold is not None and hold < FAINT_BACKGROUND_MSE:  # the held-out split does not move
        return verdict("untrained", f"its held-out frames differ from their last input frame by under one gray level "
                                    f"(MSE {hold:.4g} of holding it still): nothing moves in the held-out sequences, so "
                                    "they cannot tell whether it learned the motion; check the data (its test split), "
                                    "not the training")
    if blank is not None and hold is not None and not blank[0] < config.hold_ratio * hold:
        return verdict("untrained", f"its parameters settled, but its held-out predictions (MSE {blank[0]:.4g}) are not "
                                    f"{1 / config.hold_ratio:.3g}x better than holding the last input frame still (MSE "
                                    f"{hold:.4g}): it did not learn the motion, so its parameters mean nothing; "
                                    + data_fix(planned, steps))
    moving = [f"{name} moved {100 * c.tail_change:+.2f}% over the last {100 * config.tail:.0f}% of steps, "
              f"{abs(c.tail_speed):.2f}x the sum of its learning rate there (the bar is {config.speed_tolerance:g}x)"
              for name, c in checks.items() if c.tail_speed is not None and c.tail_change is not None
              and abs(c.tail_speed) >= config.speed_tolerance]
    if moving:
        return verdict("unsettled", "a parameter was still on its way when the learning rate decayed: " + "; ".join(moving)
                       + "; " + length_fix(planned, steps))
    short_of = [(name, p) for name, p in (profile or {}).items()
                if name in checks and min(p.lower, p.upper) < 1 - config.profile_tolerance]
    if short_of:
        return verdict("unsettled", "a parameter stopped short of its value: " + "; ".join(
            f"{name} = {p.value:.4g} settled, but the training frames are predicted {100 * (1 - min(p.lower, p.upper)):.0f}% "
            f"better with {name} = {p.better:.4g}" for name, p in short_of) + "; " + length_fix(planned, steps))
    if not held_out:  # a file of 1 spring sequence x 12 frames settled here with k 53% and l 56% off, its own frames
        # predicted at 0.03x the background's MSE: frames it trained on cannot tell such a fit from a right one
        return verdict("unsettled", "its parameters settled, but the file has no test sequences, so no frame it did "
                                    "not train on checks them (a file this small can be fitted with wrong values); "
                                    + SPLIT_FIX)
    return verdict("converged", f"every learned parameter left its start and settled over the last "
                                f"{100 * config.tail:.0f}% of {planned} steps")


def _parameter(name: str, start: float, end: float, trace: list[list[float]], names: list[str], planned: int,
               config: ConvergenceConfig, allowed: float = 0.0) -> ParameterCheck:
    """``allowed``: the sum of the physics learning rate over the tail's recorded steps (0: not known)."""
    scale = abs(start) or 1.0
    tail_change = tail_spread = tail_speed = None
    if trace and math.isfinite(end):
        rows = np.asarray(trace, dtype=np.float64)  # (K, 1 + P): step, then the parameters
        rows = rows[rows[:, 0] > planned * (1 - config.tail)]
        values = rows[:, 1 + names.index(name)] if len(rows) else rows
        if len(values) >= 5 and np.all(np.isfinite(values)) and np.all(values != 0):
            # Relative change: the log for a positive parameter; a signed one (a learned with its sign) linearly.
            y = np.log(np.abs(values)) if np.all(values > 0) or np.all(values < 0) else values / scale
            slope, intercept = np.polyfit(rows[:, 0], y, 1)
            tail_change = float(slope * (rows[-1, 0] - rows[0, 0]))
            tail_spread = float(np.std(y - (slope * rows[:, 0] + intercept)))
            if allowed > 0:
                tail_speed = tail_change / allowed
    return ParameterCheck(start, end, (end - start) / scale, tail_change, tail_spread, tail_speed)
