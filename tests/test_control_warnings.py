"""piga-control's warnings about the model it is given, on Gymnasium's pixel pendulum."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("trained, mult, told, said", [
    ({"gravity": 5.0, "gravity_mult": 1.0, "actuation_gain": 2.0, "effects": []}, 1.0, 1.0,
     "the env runs g = 10 m/s², actuation gain 1, the model's training file was collected at g = 5 m/s², actuation "
     "gain 2: its planner plans with the physics it identified there, so the success below measures that mismatch "
     "too (--gravity-mult 0.5 --not-told runs the env at the trained gravity)"),
    ({"gravity": 10.0, "gravity_mult": 1.2, "actuation_gain": 1.0, "effects": []}, 1.0, 1.0,
     "the env runs g = 10 m/s², the model's training file was collected at g = 12 m/s²: its planner plans with the "
     "physics it identified there, so the success below measures that mismatch too (--gravity-mult 1.2 --not-told "
     "runs the env at the trained gravity)"),
    ({"gravity": 14.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, 1.4, 1.0, None),  # as it hints
    ({"gravity": 14.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, 1.4, 1.4,  # read "14 ... at g = 14"
     "the env runs g = 14 m/s², the model's training file was collected at g = 14 m/s² (told x1.4, the agent plans "
     "with g = 19.6 m/s²): its planner plans with the physics it identified there, so the success below measures that "
     "mismatch too (--gravity-mult 1.4 --not-told runs the env at the trained gravity)"),
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, 1.4, 1.4, None),  # zero-shot, told
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, 1.4, 1.0, None),  # not told
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 0.6, "effects": [["damping", 0.3]]}, 1.0, 1.0,
     "the env runs actuation gain 1, no effect, the model's training file was collected at actuation gain 0.6, the "
     "effects damping=0.3: its planner plans with the physics it identified there, so the success below measures that "
     "mismatch too"),
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": [["blur", 1.5]]}, 1.0, 1.0,
     "the env runs no effect, the model's training file was collected at the effects blur=1.5: its encoder learned to "
     "read frames made with them, so the success below measures that mismatch too"),  # a blur is no "physics"
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": [["blur", 1.5], ["damping", 0.2]]},
     1.0, 1.0, "the env runs no effect, the model's training file was collected at the effects damping=0.2, blur=1.5: "
     "its planner plans with the physics it identified there, so the success below measures that mismatch too"),
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, 1.0, 1.0, None),
    ({}, 1.0, 1.0, None),
])
def test_a_model_of_other_physics_than_the_env_is_run_with_a_warning(trained, mult, told, said, capsys):
    """A model identified at g = 5 and gain 2 (to within 1%) swung up 0 of 2 episodes of the default env without a
    word, and 2 of 2 at its own gravity: one line says that the env is not the physics it learned; none where the env
    runs the gravity that the agent believes, or the model was trained at the env's base gravity (zero-shot, told or
    not)."""
    from piga.cli.control import _warn_if_other_pixel_physics

    _warn_if_other_pixel_physics({"data": {"env_config": trained}}, (mult,), told=told == mult)
    err = capsys.readouterr().err
    assert err == ("" if said is None else f"piga-control: warning: {said}\n")


@pytest.mark.parametrize("trained, sweep, told, said", [
    ({"gravity": 14.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, (1.0, 1.4), False,
     "at x1 of the sweep the env runs other physics than the model's training file (g = 14 m/s²): its planner plans "
     "with the physics it identified there, so the success there measures that mismatch too (x1.4 runs the env at "
     "the trained gravity that the agent plans with)"),
    ({"gravity": 14.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, (1.0, 1.4), True,  # told: 19.6
     "at x1, x1.4 of the sweep the env runs other physics than the model's training file (g = 14 m/s²): its planner "
     "plans with the physics it identified there, so the success there measures that mismatch too (with --not-told, "
     "x1.4 runs the env at the trained gravity that the agent plans with)"),
    ({"gravity": 14.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, (1.4,), False, None),
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": []}, (0.8, 1.2), True, None),  # zero-shot
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 0.6, "effects": []}, (0.9, 1.0), True,
     "at x0.9, x1 of the sweep the env runs other physics than the model's training file (actuation gain 0.6): its "
     "planner plans with the physics it identified there, so the success there measures that mismatch too"),
    ({"gravity": 10.0, "gravity_mult": 1.0, "actuation_gain": 1.0, "effects": [["noise", 5]]}, (1.0, 1.4), True,
     "at x1, x1.4 of the sweep the env runs another camera than the model's training file (the effects noise=5): its "
     "encoder learned to read frames made with them, so the success there measures that mismatch too"),
])
def test_a_sweep_names_the_multipliers_that_run_other_physics(trained, sweep, told, said, capsys):
    """A sweep's warning suggested ``--gravity-mult 1.4 --not-told``, which a sweep refuses, and ran x1.4 itself: it
    names the multipliers at which the env differs from the training file instead."""
    from piga.cli.control import _warn_if_other_pixel_physics

    _warn_if_other_pixel_physics({"data": {"env_config": trained}}, sweep, told=told, sweep=True)
    err = capsys.readouterr().err
    assert err == ("" if said is None else f"piga-control: warning: {said}\n")
