"""dm_control's MuJoCo pendulum (``suite.load("pendulum", "swingup")``) seen through a face-on camera.

A pendulum that piga did not simulate: MuJoCo integrates it in physics steps of 0.02 s while an
action is held over the frame (``action_repeat`` steps per frame), its hinge has damping, and the
picture is MuJoCo's shaded 3D pole over a textured floor and sky. The task, its reward and its
physics step are dm_control's own; piga only adds a camera on the hinge axis (an edit of the
model XML) and the Gymnasium interface.

Needs the optional extra ``dmc`` (``pip install -e '.[dmc]'``): without it, making the env raises
:class:`MissingExtraError` ("install piga[dmc]"). Rendering is headless. ``MUJOCO_GL`` defaults to
``egl`` here, which works on a CPU-only machine through Mesa's software rasteriser (llvmpipe); a
user's own ``MUJOCO_GL`` (``osmesa``, ``glfw``) is respected.

## Spaces

| space | shape | dtype | range |
|---|---|---|---|
| observation | (frame_stack × C, image_size, image_size) | uint8 | 0..255, oldest frame first; C = 1 (gray) or 3 (``color="rgb"``: R, G, B of each frame) |
| action | (1,) | float32 | u in [-1, 1] (DMC's control range; clipped) |

## Dynamics (MuJoCo, dm_control's pendulum.xml with the config's edits)

| quantity | value |
|---|---|
| angle θ | the hinge angle: 0 upright, positive counter-clockwise as displayed (camera on the +y side) |
| equation | I·θ̈ = m·g·l·sin θ + gear·u − d·θ̇, with I = m·(l² + 0.4·r²) (a sphere of radius r = 0.05 at the tip; the pole is massless) |
| piga's form | θ̈ = 1.5·g'·sin θ + 3·a·u − 3·b·θ̇ with g' = m·g·l / (1.5·I), a = gear / (3·I), b = d / (3·I) |
| integration | MuJoCo's semi-implicit Euler (damping implicit), 0.02 s per physics step, ``action_repeat`` steps per frame |
| frame dt | ``action_repeat × 0.02`` (0.04 by default) |
| reward | dm_control's: 1 while the pole is within 8° of upright (a tolerance on cos θ), summed over the frame's physics steps |
| reset | θ ~ U(-max_angle, max_angle), θ̇ ~ U(-max_speed, max_speed) (DMC's: U(-π, π) at rest); ``options={"state": [θ, θ̇]}`` sets it |
| truncation | after ``episode_length`` frames (DMC's episode: 1000 physics steps) |

``info["state"]`` is the true ``[θ, θ̇]`` (float64, θ unwrapped as MuJoCo keeps it), for evaluation
only, and ``info["dmc_reward"]`` the reward. DMC's score of an episode is the sum of its rewards
over 1000 physics steps (at most 1000).

``flip="camera"`` films from the other side (the picture is mirrored), ``flip="motor"`` wires the
motor the other way (gear -1): either flips the sign of the actuation as the frames show it.

``camera="fixed"`` renders through dm_control's own camera 0 instead (1.5 m in front, 2 m up, looking down at
45°: the swing is foreshortened), the view that DrQ-v2 and PlaNet learn DMC's tasks from (84x84 RGB there:
``image_size=84, color="rgb"``). piga's models assume the face-on view; this one is for the baselines.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, replace
from typing import Any, Callable, Literal, SupportsFloat, get_args

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import FrameStackObservation, GrayscaleObservation, ReshapeObservation, TransformObservation

from envs.fields import check_field_kinds, lower_bound_text, number_text, upper_bound_text
from envs.pendulum import MAX_IMAGE_SIZE, MIN_ACTUATION_GAIN

__all__ = ["CAMERAS", "COLORS", "DMC_PHYSICS_DT", "DMC_EPISODE_STEPS", "DMCPendulumConfig", "MissingExtraError", "make_dmc_pendulum",
           "DMCPendulumEnv"]

#: dm_control's pendulum physics step (pendulum.xml's ``timestep``), seconds.
DMC_PHYSICS_DT = 0.02
#: Physics steps of one DMC episode (20 s).
DMC_EPISODE_STEPS = 1000
#: Most physics steps per frame: 1 s between frames, half the pendulum's swing period; sparser frames would not show
#: its motion (and a DMC episode must keep many frames: 1000 physics steps).
MAX_ACTION_REPEAT = 50
#: Lightest tip (kg): MuJoCo's accelerations overflow below about 1e-10 kg (its state becomes invalid); far above that
#: already, one unit of torque swings the pendulum round in a frame.
MIN_MASS = 1e-3
#: Fastest reset speed θ̇ (rad/s): half a turn per physics step; faster, MuJoCo's steps and the frames alias the motion.
MAX_SPEED = math.pi / DMC_PHYSICS_DT
#: :data:`MAX_SPEED` as ranges write it (help and errors).
MAX_SPEED_TEXT = f"π/{DMC_PHYSICS_DT:g} ≈ {upper_bound_text(MAX_SPEED, 7)}"
#: Strongest hinge damping (N·m·s/rad), as the pixel pendulum's damping effect (:data:`envs.effects.MAX_PASSIVE`):
#: far beyond it the pendulum stands still in every frame (1e308 was taken, and its data showed no motion).
MAX_DAMPING = 100.0
#: Radius of the sphere at the pole's tip in pendulum.xml (its only mass).
TIP_RADIUS = 0.05
#: The shortest pole (m): the tip's radius. A shorter one hides under its tip (at 64 pixels it is 2 pixels
#: long), and 1e-300 failed in MuJoCo's words ("fromto points too close").
MIN_LENGTH = TIP_RADIUS
#: Earth's gravity as MuJoCo's default ``option/gravity``.
EARTH_GRAVITY = 9.81
#: The camera sees a square of this half-side (metres) around the pivot: a pole up to 0.6 m fits.
VIEW_HALF_SIDE = 0.7
#: Farthest ``camera_distance``: the view's side is then 4.2 m, and the tip sphere (0.1 m) about 1.5 pixels of a
#: 64-pixel frame; farther, the pendulum is too small for the frames to show its angle.
MAX_CAMERA_DISTANCE = 3.0
#: The tip sphere's width in a 64-pixel frame at :data:`MAX_CAMERA_DISTANCE` (the far bound's reason in words).
FARTHEST_TIP_PIXELS = 64 * 2 * TIP_RADIUS / (2 * VIEW_HALF_SIDE * MAX_CAMERA_DISTANCE)
#: Most frames in one observation.
MAX_FRAME_STACK = 64
#: Longest episode in frames (a million: 11 hours of the pendulum's time at the default action repeat).
MAX_EPISODE_LENGTH = 1_000_000
#: Vertical field of view of the face-on camera, degrees.
CAMERA_FOVY = 45.0
Flip = Literal["none", "camera", "motor"]
#: What a flip turns over: nothing, the camera (filmed from the other side) or the motor (gear -1).
FLIPS: tuple[Flip, ...] = get_args(Flip)
Camera = Literal["face", "fixed"]
#: The cameras: piga's face-on one on the hinge axis, or dm_control's own camera 0 (named "fixed" in pendulum.xml).
CAMERAS: tuple[Camera, ...] = get_args(Camera)
Color = Literal["gray", "rgb"]
#: The frames' colour: one gray channel, or MuJoCo's three.
COLORS: tuple[Color, ...] = get_args(Color)


class MissingExtraError(ImportError):
    """dm_control or MuJoCo is not installed (or the pair does not match)."""


@dataclass(frozen=True)
class DMCPendulumConfig:
    """Settings of the DMC pendulum env. The defaults are dm_control's pendulum-swingup."""

    image_size: int = 64
    """Side of the square gray frame in pixels."""
    frame_stack: int = 1
    """Number of most recent frames in one observation (oldest first)."""
    action_repeat: int = 2
    """Physics steps of 0.02 s per frame, the action held over them (the frame dt is their total)."""
    episode_length: int = 0
    """Frames before truncation; 0 means DMC's episode, 1000 physics steps (1000 // action_repeat frames)."""
    mass: float = 1.0
    """Mass of the tip sphere (kg; pendulum.xml: 1)."""
    length: float = 0.5
    """Distance from the hinge to the tip sphere's centre (m; pendulum.xml: 0.5)."""
    damping: float = 0.1
    """Hinge damping d (N·m·s/rad; pendulum.xml: 0.1)."""
    flip: Flip = "none"
    """"none", "camera" (filmed from the other side: mirrored) or "motor" (gear -1)."""
    max_angle: float = math.pi
    """Reset draws θ ~ U(-max_angle, max_angle) (DMC: π)."""
    max_speed: float = 0.0
    """Reset draws θ̇ ~ U(-max_speed, max_speed) (DMC: 0, at rest)."""
    camera_distance: float = 1.0
    """The face-on camera's distance from the hinge, as a multiple of the default (which frames
    ±0.7 m around the pivot): above 1 the pendulum looks smaller (at most 3, where its tip is 1.5 pixels of a 64-pixel
    frame); below, it must still fit in view."""
    camera: Camera = "face"
    """"face" (piga's camera on the hinge axis) or "fixed" (dm_control's camera 0, looking down at 45°: the view
    DrQ-v2 and PlaNet learn from; ``flip="camera"`` and ``camera_distance`` are for the face-on camera)."""
    color: Color = "gray"
    """"gray" (one channel per frame) or "rgb" (three: R, G, B, channel-first)."""
    shadows: bool = False
    """Render shadows (dm_control's 2048-pixel shadow map). Off by default: on a software
    rasteriser (llvmpipe) they make a frame ~4x slower, and seen face-on the shadow only darkens
    a sliver of the floor."""

    def __post_init__(self) -> None:
        check_field_kinds(self)  # a value of the wrong kind named here, not met deep inside (shadows="no" was on)
        # written into the MJCF model, whose reader takes no subnormal number (the length has a floor of its own)
        if self.damping != 0 and abs(self.damping) < sys.float_info.min:
            raise ValueError(f"DMCPendulumConfig.damping={self.damping!r} is below the smallest normal number "
                             f"({sys.float_info.min:g}), which MuJoCo's model reader refuses; give 0 or a larger value")
        longest = VIEW_HALF_SIDE - 2 * TIP_RADIUS
        if not MIN_LENGTH <= self.length <= longest:  # first: the mass's bound and the camera's follow from it
            why = ("shorter, the pole is hidden under its tip" if self.length < MIN_LENGTH
                   else "longer, the tip leaves the camera's view")  # the reason of the bound it breaks
            raise ValueError(f"DMCPendulumConfig.length={number_text(self.length)} is out of range (length in "
                             f"[{MIN_LENGTH:g}, {longest:g}] m; {why})")
        checks = {  # each field: whether it is in range, and its range in words
            "image_size": (8 <= self.image_size <= MAX_IMAGE_SIZE, f"image_size in [8, {MAX_IMAGE_SIZE}]"),
            "frame_stack": (1 <= self.frame_stack <= MAX_FRAME_STACK, f"frame_stack in [1, {MAX_FRAME_STACK}]"),
            "action_repeat": (1 <= self.action_repeat <= MAX_ACTION_REPEAT, f"action_repeat in [1, {MAX_ACTION_REPEAT}]"),
            "episode_length": (0 <= self.episode_length <= MAX_EPISODE_LENGTH, f"episode_length in [0, {MAX_EPISODE_LENGTH:,}]"),
            "mass": (MIN_MASS <= self.mass <= self.max_mass, f"mass in [{MIN_MASS:g}, {upper_bound_text(self.max_mass, 4)}]" + (
                     f"; heavier, the torque's effect 1 / (3 I) is below {MIN_ACTUATION_GAIN:g}, too weak for a frame "
                     "to show" if self.mass > self.max_mass else "")),
            "damping": (0 <= self.damping <= MAX_DAMPING, f"damping in [0, {MAX_DAMPING:g}]"),
            "flip": (self.flip in FLIPS, f"flip in {FLIPS}"),
            "max_angle": (0 <= self.max_angle <= math.pi, "max_angle in [0, pi]"),
            "max_speed": (0 <= self.max_speed <= MAX_SPEED, f"max_speed in [0, {MAX_SPEED_TEXT}]"),
            "camera": (self.camera in CAMERAS, f"camera in {CAMERAS}"),
            "color": (self.color in COLORS, f"color in {COLORS}"),
            "camera_distance": (self.camera_near <= self.camera_distance <= MAX_CAMERA_DISTANCE,
                                f"camera_distance in [{lower_bound_text(self.camera_near, 4)}, {MAX_CAMERA_DISTANCE:g}] "
                                f"at length {number_text(self.length)}" + (
                                    f"; farther, the pendulum is too small to read: its tip is {FARTHEST_TIP_PIXELS:.1f} "
                                    "pixels wide in a 64-pixel frame" if self.camera_distance > MAX_CAMERA_DISTANCE
                                    else "; nearer, the camera crops the pendulum" if self.camera_distance < self.camera_near
                                    else "")),  # NaN: no side
        }
        for name, (ok, allowed) in checks.items():
            if not ok:
                raise ValueError(f"DMCPendulumConfig.{name}={number_text(getattr(self, name))} is out of range ({allowed})")
        clash = [name for name, given in (("flip=camera", self.flip == "camera"),
                                          (f"camera_distance={number_text(self.camera_distance)}",
                                           self.camera_distance != 1.0)) if given]
        if self.camera == "fixed" and clash:  # they move the face-on camera only
            raise ValueError(f"DMCPendulumConfig.camera=fixed is dm_control's own camera, which {' and '.join(clash)} "
                             f"cannot move: drop {'it' if len(clash) == 1 else 'them'} or camera=fixed")

    @property
    def camera_near(self) -> float:
        """The nearest ``camera_distance`` at which the pole and its tip, (length + 0.1) m, stay in the view, whose half
        side is 0.7 m at distance 1."""
        return (self.length + 2 * TIP_RADIUS) / VIEW_HALF_SIDE

    @property
    def max_mass(self) -> float:
        """The heaviest tip whose torque the frames still show (actuation gain at least :data:`MIN_ACTUATION_GAIN`)."""
        return 1.0 / (3.0 * MIN_ACTUATION_GAIN * (self.length**2 + 0.4 * TIP_RADIUS**2))

    @property
    def channels(self) -> int:
        """Channels of one frame: 1 gray, 3 RGB."""
        return 3 if self.color == "rgb" else 1

    @property
    def dt(self) -> float:
        """Seconds per frame: ``action_repeat × 0.02``."""
        return self.action_repeat * DMC_PHYSICS_DT

    @property
    def frames_per_episode(self) -> int:
        """Frames before truncation."""
        return self.episode_length or DMC_EPISODE_STEPS // self.action_repeat

    @property
    def inertia(self) -> float:
        """Moment of inertia about the hinge, I = m·(l² + 0.4·r²)."""
        return self.mass * (self.length**2 + 0.4 * TIP_RADIUS**2)

    @property
    def gear(self) -> float:
        """The motor's gear: -1 when wired the other way."""
        return -1.0 if self.flip == "motor" else 1.0

    def piga_params(self) -> dict[str, float]:
        """The true parameters in piga's form (θ̈ = 1.5·g·sin θ + 3·a·u − 3·b·θ̇), as the frames show them.

        ``actuation_sign`` is -1 when a flipped camera or motor makes positive u turn the pole
        clockwise as displayed; ``actuation_gain`` is the magnitude.
        """
        inertia = self.inertia
        return {
            "g": self.mass * EARTH_GRAVITY * self.length / (1.5 * inertia),
            "actuation_gain": 1.0 / (3.0 * inertia),
            "damping": self.damping / (3.0 * inertia),
            "actuation_sign": -1.0 if self.flip != "none" else 1.0,
        }

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy of the fields."""
        return asdict(self)


def _renderer_error(cause: BaseException) -> ValueError:
    """The one error for a renderer that ``MUJOCO_GL`` names but that cannot start on this machine."""
    return ValueError(f"MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}: dm_control could not start that renderer here "
                      f"({type(cause).__name__}: {str(cause).splitlines()[0] if str(cause) else '-'}); unset "
                      "MUJOCO_GL (piga then renders with egl, which needs no display)")


def _quiet_half_made_context(hook: Callable[[Any], None]) -> Callable[[Any], None]:
    """``sys.unraisablehook`` that drops the complaint of a rendering context that failed half made (its
    ``__del__`` finds no pointer as it is collected), after the one error line has said why."""
    def quiet(unraisable: Any) -> None:
        if "Context" not in repr(unraisable.object):  # (MjrContext.__del__, GLContext's)
            hook(unraisable)
    return quiet


def _import_dm_control() -> tuple[Any, Any]:
    """dm_control's pendulum module and its ``control`` module, or one clear error."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        from dm_control.rl import control
        from dm_control.suite import pendulum
    except AttributeError as exc:  # PyOpenGL without the library MUJOCO_GL names ('NoneType' has no glGetError)
        raise _renderer_error(exc) from None
    except ImportError as exc:
        raise MissingExtraError(f"the DMC pendulum needs dm_control and MuJoCo: install piga[dmc] "
                                f"(pip install -e '.[dmc]'); import failed: {exc}") from None
    except RuntimeError as exc:  # dm_control checks the variable as it imports its renderer
        if "MUJOCO_GL" not in str(exc):
            raise
        raise ValueError(f"MUJOCO_GL={os.environ['MUJOCO_GL']!r} names no renderer dm_control knows; unset it (piga "
                         "then renders with egl) or set egl, osmesa or glfw") from None
    import logging

    # dm_control logs MuJoCo's instability warnings through absl before raising PhysicsError, which step() turns
    # into one ValueError: the log line would be a second line on stderr
    logging.getLogger("absl").setLevel(logging.ERROR)
    return pendulum, control


def model_xml(config: DMCPendulumConfig, base_xml: str) -> str:
    """pendulum.xml with the config's mass, length, damping, motor and shadows, and the face-on camera ``face``.

    The camera sits on the hinge axis (y), level with the pivot, at the distance where the view
    spans ±``VIEW_HALF_SIDE`` around it, looking along −y (image right = −x, image up = +z), so that
    θ > 0 turns counter-clockwise as displayed; ``flip="camera"`` puts it on the −y side.
    """
    root = ET.fromstring(base_xml)
    body = root.find("./worldbody/body[@name='pole']")
    if body is None:
        raise ValueError("pendulum.xml has no body 'pole': an unknown dm_control version")
    pivot = [float(x) for x in body.get("pos", "0 0 0").split()]
    body.find("./joint[@name='hinge']").set("damping", repr(config.damping))
    body.find("./geom[@name='pole']").set("fromto", f"0 0 0 0 0 {config.length!r}")
    mass = body.find("./geom[@name='mass']")
    mass.set("pos", f"0 0 {config.length!r}")
    mass.set("mass", repr(config.mass))
    root.find("./actuator/motor[@name='torque']").set("gear", repr(config.gear))
    visual = ET.SubElement(root, "visual")  # merged with common/visual.xml's
    ET.SubElement(visual, "quality", {"shadowsize": "2048" if config.shadows else "0"})
    size = str(max(config.image_size, 64))
    ET.SubElement(visual, "global", {"offwidth": size, "offheight": size})  # the off-screen buffer: one frame
    distance = config.camera_distance * VIEW_HALF_SIDE / math.tan(math.radians(CAMERA_FOVY / 2))
    side = -1.0 if config.flip == "camera" else 1.0
    ET.SubElement(root.find("./worldbody"), "camera", {
        "name": "face", "fovy": repr(CAMERA_FOVY),
        "pos": f"{pivot[0]!r} {side * distance!r} {pivot[2]!r}",
        "xyaxes": f"{-side!r} 0 0 0 0 1",
    })
    return ET.tostring(root, encoding="unicode")


class DMCPendulumEnv(gym.Env):
    """dm_control's pendulum-swingup as a Gymnasium env with RGB frames from the face-on camera.

    The observation is the (image_size, image_size, 3) uint8 frame; :func:`make_dmc_pendulum` adds
    the gray conversion and the frame stack. See the module docstring for the spaces and dynamics.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(self, config: DMCPendulumConfig | None = None, render_mode: str | None = "rgb_array"):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"the DMC pendulum renders only as 'rgb_array', got render_mode={render_mode!r}")
        self.config = config or DMCPendulumConfig()
        self.render_mode = "rgb_array"
        with warnings.catch_warnings():  # glfw warns (a second line) before it fails without a display
            warnings.filterwarnings("ignore", module="glfw")
            pendulum, control = _import_dm_control()
            self._make(pendulum, control)

    def _make(self, pendulum: Any, control: Any) -> None:
        """The MuJoCo model, the task and one frame rendered: a renderer that cannot start here fails now, in one line."""
        self._physics_error = control.PhysicsError
        xml, assets = pendulum.get_model_and_assets()
        xml = model_xml(self.config, xml.decode() if isinstance(xml, bytes) else xml)
        try:
            physics = pendulum.Physics.from_xml_string(xml, assets)
        except AttributeError as exc:  # e.g. 'MjModel' object has no attribute 'flex_vertedge'
            raise MissingExtraError(f"dm_control and MuJoCo do not match ({exc}): install piga[dmc], "
                                    "which pins a matching pair") from None
        self._task = pendulum.SwingUp(random=np.random.RandomState(0))
        # The time limit is this env's (truncation in frames), not dm_control's.
        self._env = control.Environment(physics, self._task, time_limit=float("inf"), n_sub_steps=1)
        self.physics = physics
        self.hinge_torque: Callable[[float, float], float] | None = None
        """A torque on the hinge (N·m) from the state (θ, θ̇) before each *physics step*, applied as MuJoCo's
        ``qfrc_applied``: how an effect added from outside dm_control (friction) acts within the frame,
        as a real one would, rather than held over the frame's physics steps. None: no torque."""
        size = self.config.image_size
        self.observation_space = gym.spaces.Box(0, 255, (size, size, 3), np.uint8)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._frames = 0
        try:
            self.render()
        except Exception as exc:  # mujoco.FatalError (glfw without a display), PyOpenGL's errors, ...
            error = _renderer_error(exc)
            del exc  # its traceback holds the half-made context
            sys.unraisablehook = _quiet_half_made_context(sys.unraisablehook)
            glfw = sys.modules.get("glfw")
            if glfw is not None:  # and glfw's own warning at exit, as it terminates uninitialised
                glfw.ERROR_REPORTING = "ignore"
            raise error from None

    def _state(self) -> np.ndarray:
        return np.array([self.physics.data.qpos[0], self.physics.data.qvel[0]], dtype=np.float64)

    def render(self) -> np.ndarray:
        size = self.config.image_size
        return self.physics.render(size, size, camera_id=self.config.camera)  # (H, W, 3) uint8

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        cfg = self.config
        self._env.reset()  # the task's own draw of θ is replaced below, from this env's np_random
        state = options.pop("state", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; known: ['state']")
        if state is None:
            state = [self.np_random.uniform(-cfg.max_angle, cfg.max_angle),
                     self.np_random.uniform(-cfg.max_speed, cfg.max_speed)]
        state = np.asarray(state, dtype=np.float64)
        if state.shape != (2,) or not np.isfinite(state).all():
            raise ValueError(f"reset option 'state' must be a finite [theta, theta_dot], got {state!r}")
        with self.physics.reset_context():
            self.physics.data.qpos[0] = state[0]
            self.physics.data.qvel[0] = state[1]
        self._frames = 0
        return self.render(), {"state": self._state(), "dmc_reward": 0.0}

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        u = np.clip(np.asarray(action, dtype=np.float64).reshape(1), -1.0, 1.0)
        reward = 0.0
        for _ in range(self.config.action_repeat):
            if self.hinge_torque is not None:
                data = self.physics.data
                data.qfrc_applied[0] = self.hinge_torque(float(data.qpos[0]), float(data.qvel[0]))
            try:
                reward += float(self._env.step(u).reward)
            except self._physics_error as exc:  # a config that MuJoCo cannot integrate: the user's to change
                raise ValueError(f"the DMC pendulum's physics became invalid ({exc}) with mass={self.config.mass:g}, "
                                 f"length={self.config.length:g}, damping={self.config.damping:g}; choose values nearer "
                                 "pendulum.xml's (1, 0.5, 0.1)") from None
        self._frames += 1
        truncated = self._frames >= self.config.frames_per_episode
        return self.render(), reward, False, truncated, {"state": self._state(), "dmc_reward": reward}

    def close(self) -> None:
        self.physics.free()
        super().close()


def make_dmc_pendulum(config: DMCPendulumConfig | None = None, render_mode: str | None = "rgb_array",
                      **overrides: Any) -> gym.Env:
    """The DMC pendulum with gray frames: ``DMCPendulumEnv -> GrayscaleObservation -> FrameStackObservation``, or
    with ``color="rgb"`` channel-first RGB ones: ``DMCPendulumEnv -> TransformObservation (HWC to CHW) ->
    FrameStackObservation -> ReshapeObservation`` (the K frames' channels in one axis, as DrQ-v2 stacks them).

    Args:
        config: the settings; None means the defaults.
        render_mode: only "rgb_array" (or None, which means the same).
        **overrides: fields of :class:`DMCPendulumConfig` that replace those of ``config``
            (``gym.make("piga/DMCPendulum-v0", mass=1.2)`` passes its keywords here).

    Returns:
        An env whose observation is uint8 (frame_stack × channels, image_size, image_size).

    Raises:
        MissingExtraError: dm_control or MuJoCo is missing ("install piga[dmc]").
    """
    if config is not None and not isinstance(config, DMCPendulumConfig):
        raise TypeError(f"config must be a DMCPendulumConfig or None, got {type(config).__name__}; give fields as "
                        "keywords or build the config")
    config = replace(config or DMCPendulumConfig(), **overrides)
    env: gym.Env = DMCPendulumEnv(config, render_mode)
    if config.color == "gray":
        env = GrayscaleObservation(env, keep_dim=False)  # (H, W)
        return FrameStackObservation(env, config.frame_stack)  # (K, H, W)
    size = config.image_size
    env = TransformObservation(env, lambda frame: np.ascontiguousarray(frame.transpose(2, 0, 1)),
                               gym.spaces.Box(0, 255, (3, size, size), np.uint8))  # (3, H, W)
    env = FrameStackObservation(env, config.frame_stack)  # (K, 3, H, W)
    return ReshapeObservation(env, (3 * config.frame_stack, size, size))  # (3K, H, W)
