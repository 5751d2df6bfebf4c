"""The damping's convention: a system that takes it implicitly (MuJoCo's Euler, dm_control) read by the one-step
explicit fit gives g, a and b all low by 1 / (1 + h·3b); two files whose dampings differ are compared, and the damping
is given, in the convention that the file says its system takes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from piga.diagnostics import fit
from piga.diagnostics.diagnose import convention_note, cut_windows, damping_convention, in_convention, name_effects
from piga.diagnostics.observe import Observations, damping_taken
from tests.test_diagnose_weak_evidence import FAST, NOTHING_LEFT, simulated
from tests.test_diagnostics import NOMINAL


def implicitly_damped(b: float, n: int = 60, t: int = 20, seed: int = 0) -> Observations:
    """Encoded-angle-like observations of a pendulum whose damping b is taken implicitly, as MuJoCo's Euler takes it
    (q̇ <- (q̇ + h·f) / (1 + h·3b); :func:`simulated`)."""
    return simulated(lambda v, x, u: (v + 0.05 * (15 * np.sin(x) + 3 * u)) / (1 + 0.05 * 3 * b), n, t, seed,
                     from_gymnasium=False)


def test_the_convention_is_read_from_the_files_provenance() -> None:
    assert damping_taken({"env_id": "piga/DMCPendulum-v0"}) == "implicit"
    assert damping_taken({"env_config": '{"action_repeat": 1}'}) == "implicit"  # files before env_id
    assert damping_taken({"env_id": "piga/PixelPendulum-v0"}) == "explicit"
    assert damping_taken({"env_config": '{"draw_torque_arrow": true}'}) == "explicit"
    assert damping_taken({"system": "pendulum", "source": "video.mp4"}) is None  # piga-import


def test_an_explicit_reading_is_turned_implicit_by_its_factor() -> None:
    m = fit.Model(("damping",), 0, {"g": 10.0, "a": 1.0, "b": 0.5})
    factor = 1 / (1 - 0.05 * 3 * 0.5)
    implicit = in_convention(m, NOMINAL, "implicit").values
    assert implicit == pytest.approx({"g": 10.0 * factor, "a": factor, "b": 0.5 * factor})
    assert in_convention(m, NOMINAL, "explicit") is m and in_convention(m, NOMINAL, None) is m
    assert in_convention(fit.Model((), 0, {"g": 10.0, "a": 1.0}), NOMINAL, "implicit").values == {"g": 10.0, "a": 1.0}


def test_an_explicit_reading_is_turned_implicit_over_the_systems_physics_steps() -> None:
    """dm_control takes its hinge damping at each 0.02 s physics step, two per 0.04 s frame: converted over one step of
    the frame, a damping of 1.594 read 1.67 with a "gain 1.06" and a "gravity 1.05"."""
    nom = replace(NOMINAL, dt=0.04)
    b_true, h = 1.594, 0.02
    d = 1 / (1 + h * 3 * b_true)  # each implicit step's factor on the speed
    b_explicit = (1 - d**2) / (0.04 * 3)  # the one explicit step per frame with the same decay over the frame
    m = fit.Model(("damping",), 0, {"g": 10.0, "a": 1.0, "b": b_explicit})
    two = in_convention(m, nom, "implicit", system_step=h).values
    assert two["b"] == pytest.approx(b_true, rel=1e-9)
    assert two["g"] == pytest.approx(10.0 * 2 / (d + d**2)) and two["a"] == pytest.approx(2 / (d + d**2))
    one = in_convention(m, nom, "implicit").values  # one step of the frame: b 5% high, g and a 5% high
    assert one["b"] / b_true > 1.04 and one["g"] / two["g"] > 1.04
    assert in_convention(m, nom, "implicit", system_step=0.04).values == pytest.approx(one)
    convention = damping_convention(m, nom, h)
    said = convention_note(convention, "implicit", said_by="training")
    assert "physics steps of 0.02 s" in said and "the model's training file says it comes from dm_control" in said
    assert f"the recording's: g = {two['g']:.3f}" in said


def test_a_damping_that_differs_between_implicitly_damped_files_names_no_gravity_error() -> None:
    """dm_control's hinge damping at 0.4 against the training file's 0.1, read one Euler step per frame, was named
    "gravity 0.967" with g unchanged; compared implicitly, as MuJoCo takes it, only the damping differs."""
    recording, training = implicitly_damped(0.5), implicitly_damped(0.13, seed=1)
    w = cut_windows(recording, recording.theta, None, FAST)
    final = fit.fit_candidate(("damping",), {"g": NOMINAL.g, "a": NOMINAL.a}, NOMINAL, w.fit)
    kwargs = dict(w=w, camera=None, generic=NOTHING_LEFT, config=FAST, from_gymnasium=False, own=training)
    implicit = name_effects(final, NOMINAL, damping_taken="implicit", **kwargs)
    assert [e.effect for e in implicit.effects] == ["damping"], implicit.verdict
    damping = implicit.effects[0]
    assert damping.value == pytest.approx(0.5, rel=0.02) and damping.training == pytest.approx(0.13, rel=0.05)
    assert any("takes the damping implicitly" in n for n in implicit.notes), implicit.notes
    # read in the fit's explicit convention, the two files' factors differ by 5%, which reads as gravity
    explicit = name_effects(final, NOMINAL, **kwargs)
    assert "gravity" in {e.effect for e in explicit.effects}, explicit.verdict
    assert explicit.effects[0].value == pytest.approx(final.values["b"])
