"""Goals given as images: read the goal angle with the encoder, check it, and write goal images.

An image is converted the way the environment converts its render (:mod:`piga.data.scene`): a centre
crop to a square, ``cv2.resize(..., INTER_AREA)`` to the model's size, then Gymnasium's gray
weights (0.2125, 0.7154, 0.0721), truncated to uint8.

Before the model reads it, an image is checked against the environment's own renders, which
does not depend on how well the model was trained (:func:`scene_mismatch`): a picture that no
render of the pendulum, at any angle, comes close to is refused.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import torch

from envs.constants import MAX_ACTION
from envs.fields import number_text, upper_bound_text
from envs.pendulum import PixelPendulumConfig
from piga.world.effects import scaled_gravity
from piga.world.model import PhysicsModel, frames_to_float
from piga.data.scene import GRAY_WEIGHTS, load_scene_image, read_image, scene_to_gray

__all__ = ["GOAL_IMAGE_FORMATS", "GRAY_WEIGHTS", "HOLDABLE_ANGLE", "GoalEstimate", "NotTheSceneError", "goal_from_image",
           "holdable_angle", "load_scene_image", "read_goal",
           "render_goal_image", "scene_mismatch", "scene_to_gray"]

SCENE_ANGLES = 120
"""Angles (every 3°) at which the environment's renders are compared with a goal image."""
MAX_SCENE_MISMATCH = 0.5
"""Largest :func:`scene_mismatch` of a goal image. A render at an angle between two of the
compared ones scores below 0.05; an empty background scores 1; random noise far above 1."""


def holdable_angle(g: float, a: float = 1.0, max_action: float = MAX_ACTION) -> float:
    """Largest |θ| from upright (rad) at which the pendulum can be held at rest with |u| <= ``max_action``.

    At rest, 1.5·g·sin θ + 3·a·u = 0, so holding θ needs u = -g·sin θ / (2a): |sin θ| <= 2·a·max_action / g.
    """
    return math.asin(min(1.0, 2 * a * max_action / g))


HOLDABLE_ANGLE = holdable_angle(PixelPendulumConfig.gravity, PixelPendulumConfig.actuation_gain)
"""The pixel pendulum's holdable range around upright (rad), at its own gravity: asin(0.4), ±23.578°.
The README quotes it; the goal-image warning prints the same value (for gravity x1)."""


class NotTheSceneError(ValueError):
    """A goal image that does not show the pendulum scene."""


@functools.lru_cache(maxsize=4)
def scene_renders(size: int, count: int = SCENE_ANGLES) -> np.ndarray:
    """The environment's frames of the pendulum at rest at ``count`` angles over the circle, no arrow:
    float (count, size, size) in [0, 1]; the last row is the empty background (no pendulum)."""
    from envs.pendulum import make_pixel_pendulum

    env = make_pixel_pendulum(draw_torque_arrow=False, frame_stack=1, image_size=size)
    frames = []
    for k in range(count):
        obs, _ = env.reset(seed=0, options={"state": [2 * math.pi * k / count - math.pi, 0.0]})
        frames.append(obs[-1])
    env.close()
    frames = np.asarray(frames, np.float64) / 255  # (K, size, size)
    background = np.median(frames, axis=0)  # the pendulum covers each pixel in few of the angles
    return np.concatenate([frames, background[None]])


def scene_mismatch(image: np.ndarray) -> float:
    """How unlike the environment's scene a gray uint8 (H, W) picture is, independent of any model.

    The smallest mean squared difference to the environment's renders at :data:`SCENE_ANGLES`
    angles, divided by that of the empty background (the pendulum's own share of a frame): 0 for
    a render, 1 for a picture of the background without the pendulum.
    """
    renders = scene_renders(image.shape[0])
    x = np.asarray(image, np.float64) / 255
    mse = ((renders[:-1] - x) ** 2).mean(axis=(1, 2))  # (K,)
    pendulum = ((renders[:-1] - renders[-1]) ** 2).mean(axis=(1, 2))  # (K,) the pendulum's share at each angle
    return float(mse.min() / pendulum.mean())


@dataclass(frozen=True)
class GoalEstimate:
    """What the model reads from a goal image."""

    angle: float
    """Goal angle θ in Gymnasium's convention (rad, 0 upright)."""
    reconstruction_mse: float
    """MSE of the model's re-rendering of the image (how well the image looks like the scene)."""
    hold_torque: float
    """Torque u needed to hold θ at rest under the agent's physics."""
    feasible_max_angle: float
    """Largest |θ| around upright that the env's pendulum can be held at with |u| <= 2 (rad; :func:`holdable_angle`)."""
    warnings: list[str] = field(default_factory=list)
    """Human-readable warnings (infeasible goal, image not of the scene)."""


@torch.no_grad()
def env_holdable_angle(gravity_mult: float = 1.0) -> float:
    """:func:`holdable_angle` of the env's own physics at ``gravity_mult`` (rad)."""
    return holdable_angle(PixelPendulumConfig(gravity_mult=gravity_mult).effective_gravity, PixelPendulumConfig.actuation_gain)


def hold_warning(angle: float, gravity_mult: float | Sequence[float] = 1.0) -> str | None:
    """One line when the goal ``angle`` (rad) cannot be held within the torque limit in the env at ``gravity_mult``
    (judged with the env's own physics), else None.

    Given a sweep's multipliers (a sequence), the one line names those at which the goal cannot be held, with the
    range of torques it needs and of goals that can be held there; a single run's line names none."""
    sweep = not isinstance(gravity_mult, (int, float))
    multipliers = list(gravity_mult) if sweep else [gravity_mult]  # type: ignore[arg-type]
    beyond = [m for m in multipliers if abs(math.sin(angle)) > math.sin(env_holdable_angle(m))]
    if not beyond:
        return None
    gain = PixelPendulumConfig.actuation_gain
    needed = sorted({f"{-PixelPendulumConfig(gravity_mult=m).effective_gravity * math.sin(angle) / (2 * gain):+.4g}"
                     for m in beyond}, key=lambda t: abs(float(t)))  # (the torque grows with the gravity)
    bounds = [f"±{upper_bound_text(math.degrees(env_holdable_angle(m)), 4)}" for m in (beyond[0], beyond[-1])]
    where, there = "", ""
    if sweep:
        named = ", ".join(f"x{number_text(m)}" for m in beyond) if len(beyond) <= 4 else \
            f"x{number_text(beyond[0])} to x{number_text(beyond[-1])} ({len(beyond)} of the sweep's {len(multipliers)})"
        where, there = f" at gravity {named}", " there"
    # the goal as given and the bound rounded down, the torque to 4 digits: at the edge, "goal 23.6 deg needs torque
    # -2.00 ... within ±23.6 deg" contradicted itself (the bound is 23.578)
    return (f"goal {math.degrees(angle):.6g} deg needs torque {' to '.join(dict.fromkeys((needed[0], needed[-1])))} "
            f"to hold in the env{where} (its own physics), beyond the limit of {MAX_ACTION:g}; holdable goals{there} are "
            f"within {' to '.join(dict.fromkeys(bounds))} deg of upright (or of hanging down); the controller will do "
            "its best")


def read_goal(model: PhysicsModel, image: np.ndarray, g: float, a: float, mse_limit: float,
              gravity_mult: float = 1.0) -> GoalEstimate:
    """Encodes a goal image (uint8 (H, W)) and checks it.

    Args:
        model: the trained pendulum model.
        image: uint8 (H, W) from :func:`load_scene_image`.
        g, a: the agent's physics (learned g times any gravity multiplier, learned a): the hold torque.
        mse_limit: reconstruction MSE above which the image is reported as not of the scene.
        gravity_mult: the env's gravity multiplier. Whether the goal can be held is the env's
            property: it is judged, and its range named, with the env's own physics
            (:func:`holdable_angle`; :data:`HOLDABLE_ANGLE` at x1), not with the learned one.
    """
    x = frames_to_float(torch.from_numpy(image)[None, None], model.config.channels)  # (1, 1, C, H, W)
    with torch.no_grad():  # a reading, not a training step (a float of a graph's tensor warned on stderr)
        coords = model.encode(x)  # (1, 1, 1, 1)
        rec = model.decoder(coords)
    mse = float(((rec - x) ** 2).mean())
    offset = model.physical_parameters().get("offset", 0.0)
    angle = math.remainder(float(coords[0, 0, 0, 0]) + offset, 2 * math.pi)
    hold = -g * math.sin(angle) / (2 * a)  # 1.5 g sin θ + 3 a u = 0
    feasible = env_holdable_angle(gravity_mult)
    warnings = [w for w in (hold_warning(angle, gravity_mult),) if w is not None]
    if mse > mse_limit:
        warnings.append(
            f"the goal image does not look like the scene: the model re-renders it with MSE {mse:.4f} "
            f"(typical {mse_limit / 4:.4f}); the goal angle {math.degrees(angle):.1f} deg may be meaningless"
        )
    return GoalEstimate(angle, mse, hold, feasible, warnings)


def goal_from_image(model: PhysicsModel, checkpoint: dict, path: str | os.PathLike[str],
                    gravity_mult: float = 1.0, told: float | None = None) -> GoalEstimate:
    """Reads the goal from an image file for a model loaded by :func:`piga.io.runs.load_model`.

    ``gravity_mult`` is the env's (whether the goal can be held), ``told`` the multiplier the agent
    believes (its hold torque; by default the env's).

    The image is first compared with the environment's renders (:func:`scene_mismatch`). The
    model's "not the scene" warning limit is 4x its own final reconstruction MSE per frame.

    Raises:
        NotTheSceneError: the image does not show the pendulum scene (mismatch above
            :data:`MAX_SCENE_MISMATCH`).
    """
    learned = model.physical_parameters()
    from piga.io.runs import training_reconstruction_mse

    image = load_scene_image(path, model.config.image_size)
    height, width = read_image(path).shape[:2]  # (the image as given: load_scene_image returns it converted)
    mismatch = scene_mismatch(image)
    if mismatch > MAX_SCENE_MISMATCH:
        side = model.config.image_size
        small = (f"; at {width}x{height} it is enlarged to the model's {side}x{side} frames, which blurs it: give a "
                 f"picture of {side}x{side} or larger") if min(width, height) < side else ""
        raise NotTheSceneError(
            f"{path}: not a picture of the pendulum scene: no render of the pendulum at any angle comes close to it "
            f"(mismatch {mismatch:.2f}; a render scores 0, the empty background 1, the limit is {MAX_SCENE_MISMATCH})"
            + small)
    typical = training_reconstruction_mse(model, checkpoint) or 0.001
    believed = gravity_mult if told is None else told
    goal = read_goal(model, image, g=scaled_gravity(learned["g"], believed), a=learned["a"], mse_limit=4 * typical,
                     gravity_mult=gravity_mult)
    if abs(width - height) > 0.01 * max(width, height):  # a 33x47 copy of a 15° render read 10.66°, in silence
        side = min(width, height)
        goal.warnings.append(f"{path} is {width}x{height}, not square: its centre {side}x{side} square is read, as "
                             "the env's square frame would show it; a picture resized to another shape reads another "
                             "angle")
    return goal


#: The suffixes that ``--write-goal-image`` writes, each with imageio's options for it: every one lossless but JPEG's,
#: whose error the goal's reading absorbs; each reads back through :func:`load_scene_image` to the angle written
#: (tests/test_cli_wording.py). Pillow writes WebP lossy unless told.
GOAL_IMAGE_FORMATS: dict[str, dict[str, Any]] = {".png": {}, ".jpg": {}, ".jpeg": {}, ".webp": {"lossless": True},
                                                 ".bmp": {}, ".tif": {}, ".tiff": {}}


def render_goal_image(angle_deg: float) -> np.ndarray:
    """Gymnasium's own full-size render (RGB uint8) of the pendulum at rest at ``angle_deg`` (0 = upright), no arrow."""
    from envs.pendulum import make_pixel_pendulum

    env = make_pixel_pendulum(draw_torque_arrow=False)
    env.reset(seed=0, options={"state": [math.radians(angle_deg), 0.0]})
    picture = env.render()
    env.close()
    return np.asarray(picture)
