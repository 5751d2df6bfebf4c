"""The paper's unactuated scenes: ground-truth simulation and anti-aliased rendering, in NumPy.

| scene | image | objects | force on object i (d = p_i - p_j) | start | dt | truth |
|---|---|---|---|---|---|---|
| ``bouncing`` | 32x32 RGB | 2 balls, r = 3 | none; elastic reflection at the image edges | p ~ U[r, H - r], speed ``speed`` in a random direction | 0.3 | (none) |
| ``spring`` | 32x32 RGB | 2 balls, r = 3 | -k·(abs(d) - 2l)·d/abs(d) | centre of mass uniform, separation 2l·U[0.5, 1.5] at a random angle, each ball ``speed`` in a random direction | 0.3 | k = 4, l = 6 |
| ``gravity`` | 36x36 RGB | 3 balls, r = 3 | -g·m_i·m_j·d/abs(d)³ | a near-equilateral triangle around the centre, radius H/4·U[0.75, 1.25], tangential speed ``speed`` plus a shared U(-0.5, 0.5) drift | 0.5 | g = 60, m = 1 |
| ``digits-spring`` | 64x64 RGB | 2 digits, 22 px | the spring above | as the spring | 0.3 | k = 2, l = 12 |

The starts follow the published generators (github.com/seuqaj114/paig, ``nn/datasets/generators.py``):
a start whose trajectory touches a wall (or, for gravity, brings two balls within r + 1 of each other)
within the sequence is redrawn, so the force-only systems never meet a wall. Bouncing balls do not
collide with each other (as in the published engine); they pass through each other.

Conventions (those of :mod:`piga.world.physics` and the decoder): positions are in pixels, x to the right,
y down, the origin at the top-left corner of the image, and pixel i covers [i, i + 1]. Every object
has unit mass. The simulation takes ``substeps`` semi-implicit Euler steps per frame (10, as the
generators), each ``v <- v + h·a(p)``, ``p <- p + h·v``.

Rendering draws each frame ``supersample`` times larger, then averages each block of
``supersample`` x ``supersample`` pixels (:func:`skimage.transform.downscale_local_mean`): the
exact area average of the high-resolution picture, i.e. anti-aliased. Balls are colour channel
2 - j (blue, green, red), digits channel j (red, green), as in the generators; ``colors``,
``radius`` and (balls) ``background`` change the look, for data rendered unlike the training data. The digits are
scikit-learn's ``load_digits`` images (8x8, upscaled), over a darkened scikit-image texture
(``skimage.data.brick``): the paper's MNIST digits and CIFAR background cannot be downloaded here.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from typing import Any, Literal, get_args

import numpy as np

from envs.constants import MAX_IMAGE_SIZE
from envs.fields import number_text

__all__ = ["SCENES", "SceneConfig", "scene_config", "accelerations", "simulate", "draw_start", "render",
           "generate_sequence", "state_names", "SceneError", "MIN_FORCE_SHIFT", "force_shift", "check_forces_visible",
           "fastest_frequency", "aliasing_warning"]


#: Smallest ball radius (or half digit side) accepted, in pixels: smaller objects leave no trace in the frames.
MIN_RADIUS = 0.5
#: Smallest difference, in some RGB channel (0 to 1), between an object's colour and the background's.
MIN_CONTRAST = 0.1


#: The scenes (the keys of :data:`SCENES`).
Scene = Literal["bouncing", "spring", "gravity", "digits-spring"]
#: The force families, :mod:`piga.world.physics` system names.
Physics = Literal["bouncing", "spring", "gravity"]


class SceneError(ValueError):
    """A scene's settings cannot work (for example images too small for its objects)."""


@dataclass(frozen=True)
class SceneConfig:
    """One scene: physics, picture and how starts are drawn. Defaults per scene: :data:`SCENES`."""

    scene: Scene
    """One of :data:`SCENES`."""
    physics: Physics
    """The force family, a :mod:`piga.world.physics` system name: "bouncing", "spring" or "gravity"."""
    image_size: int
    """H = W, pixels."""
    n_objects: int
    """N."""
    dt: float
    """Seconds per frame."""
    params: dict[str, float] = field(default_factory=dict)
    """True physical parameters: k, l (spring) or g, m (gravity); empty for bouncing."""
    radius: float = 3.0
    """Ball radius in pixels; for digits, half the digit's side (11: 22 px digits)."""
    speed: float = 8.0
    """Initial speed of each object, pixels per second (the published data sets' "vx8", "vx2")."""
    substeps: int = 10
    """Semi-implicit Euler substeps per frame of the ground truth."""
    supersample: int = 8
    """Drawing resolution / image resolution."""
    wall_margin: float | None = None
    """A start is redrawn when a centre comes within this many pixels of an edge (None: ``radius``)."""
    colors: tuple[tuple[float, float, float], ...] = ()
    """RGB in [0, 1] per object; empty for the generators' colours."""
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """RGB in [0, 1] of the balls' uniform background (the generators' black); the digits have their texture."""
    max_tries: int = 10_000
    """Redraws allowed per sequence before giving up with :class:`SceneError`."""
    half: bool = False
    """The paper's unseen-region data (its Appendix D; ball spring only): every ball stays wholly in the top half of
    the image in every frame of a training or validation sequence, and in the first ``half_frames`` frames of a test
    sequence, after which a ball lies wholly in the bottom half in some frame. Starts are drawn as usual and
    rejected until they comply (``scene_config`` then sets the speed to :data:`HALF_SPEED` unless given)."""
    half_frames: int = 10
    """With ``half``: the frames of a test sequence kept in the top half, the input and prediction frames L + T_pred
    (10 for the balls, as the paper's 3 + 7 and the scene recipe's 4 + 6)."""

    def __post_init__(self) -> None:
        if self.scene not in SCENES:
            raise SceneError(f"unknown scene {self.scene!r}; known: {', '.join(sorted(SCENES))}")
        if self.physics not in get_args(Physics):
            raise SceneError(f"SceneConfig.physics must be one of {', '.join(map(repr, get_args(Physics)))}; got {self.physics!r}")
        if self.n_objects < 1:
            raise SceneError(f"n_objects must be >= 1, got {self.n_objects}")
        if not (self.dt > 0 and self.radius > 0 and self.speed >= 0):
            raise SceneError(f"need dt > 0, radius > 0 and speed >= 0, got {self.dt}, {self.radius}, {self.speed}")
        if self.substeps < 1 or self.supersample < 1:
            raise SceneError(f"substeps and supersample must be >= 1, got {self.substeps}, {self.supersample}")
        if self.colors and len(self.colors) < self.n_objects:
            raise SceneError(f"{len(self.colors)} colours for {self.n_objects} objects")
        object.__setattr__(self, "colors", tuple(tuple(float(c) for c in rgb) for rgb in self.colors))
        object.__setattr__(self, "background", tuple(float(c) for c in self.background))
        for rgb in (*self.colors, self.background):
            if len(rgb) != 3 or not all(0.0 <= c <= 1.0 for c in rgb):
                raise SceneError(f"a colour must be 3 values (R, G, B) in [0, 1], got {rgb}")
        if self.scene == "digits-spring" and any(self.background):
            raise SceneError("digits-spring draws its digits over a texture; a background colour is for the balls")
        if self.radius < MIN_RADIUS:
            raise SceneError(f"{type(self).__name__}.radius must be at least {MIN_RADIUS:g} px (a smaller object leaves no trace in the frames), "
                             f"got {number_text(self.radius)}")
        if self.scene != "digits-spring":
            hidden = [j for j, rgb in enumerate(self.colors[: self.n_objects])
                      if max(abs(a - b) for a, b in zip(rgb, self.background)) < MIN_CONTRAST]
            if hidden:
                same = "is" if self.colors[hidden[0]] == self.background else f"is within {MIN_CONTRAST:g} of"
                raise SceneError(f"object {hidden[0]}'s colour {self.colors[hidden[0]]} {same} the background's: it would be "
                                 "invisible; choose colours that differ from the background")
        for name, value in self.params.items():
            if not (math.isfinite(float(value)) and float(value) > 0):
                raise SceneError(f"{self.scene}: parameter {name} must be finite and > 0, got {value}")
        if self.physics == "spring":
            stiffest = max_stable_k(self.dt, self.substeps, self.n_objects)
            if self.params.get("k", 0.0) >= stiffest:
                raise SceneError(f"{self.scene}: k = {number_text(self.params['k'])} is too stiff for {self.substeps} substeps of "
                                 f"{self.dt:g} s: the simulation would blow up; k must be below {stiffest:.8g} "
                                 "((2·substeps/dt)²/objects)")
        overlap = None  # the spring's balls at rest closer than their diameter (checked after the image's size)
        if self.scene == "spring" and 2 * self.params.get("l", math.inf) < 2 * self.radius + BALL_GAP:
            # (digits-spring's "radius" is half a digit's box, which its glyph does not fill: its digits may overlap)
            overlap = (f"at l = {number_text(self.params['l'])} the balls rest with their centres 2l = "
                       f"{number_text(2 * self.params['l'])} px apart, under their diameter 2r = "
                       f"{number_text(2 * self.radius)} px plus {BALL_GAP:g} px: they would touch or overlap (one "
                       f"hiding the other) in most frames; give l of at least "
                       f"{number_text(self.radius + BALL_GAP / 2)} (r + {BALL_GAP / 2:g}), or a smaller radius")
        if self.half and self.scene != "spring":
            raise SceneError(f"{type(self).__name__}.half (the top-half data) is for the spring scene, not {self.scene}")
        if self.half_frames < 1:
            raise SceneError(f"{type(self).__name__}.half_frames must be >= 1, got {self.half_frames}")
        if self.image_size > MAX_IMAGE_SIZE:  # as the pendulum's: 2000 px spring frames were collected, then untrainable
            raise SceneError(f"{type(self).__name__}.image_size must be at most {MAX_IMAGE_SIZE} px (the largest frames "
                             f"piga-collect draws), got {self.image_size}")
        needed = _minimum_size(self)
        if needed > MAX_IMAGE_SIZE:  # (l = 1e308: "2l = inf; need at least inf px")
            raise SceneError(f"{self.scene}: {self.n_objects} objects of radius {number_text(self.radius)}"
                             + (f" and rest length 2l at l = {number_text(self.params['l'])}" if "l" in self.params else "")
                             + f" need images larger than {MAX_IMAGE_SIZE} px, the largest piga-collect draws; give a "
                             + ("smaller l or radius" if "l" in self.params else "smaller radius"))
        if self.image_size < needed:
            raise SceneError(f"{self.scene}: {self.image_size}x{self.image_size} images are too small for "
                             f"{self.n_objects} objects of radius {self.radius:g}"
                             + (f" and rest length 2l = {2 * self.params['l']:g}" if "l" in self.params else "")
                             + f"; need at least {needed:.6g} px (a lower bound: moving objects may need more room)"
                             + (f"; and {overlap}" if overlap else ""))
        if overlap:
            raise SceneError(f"{self.scene}: {overlap}")

    @property
    def margin(self) -> float:
        """Distance from an edge that a centre must keep (``wall_margin`` or ``radius``)."""
        return self.radius if self.wall_margin is None else self.wall_margin

    def to_dict(self) -> dict[str, Any]:
        """JSON-able fields."""
        return asdict(self)


#: Pixels that the spring scene's rest length 2l must leave between its balls (the gravity scene redraws starts that
#: bring two balls' centres within r + 1): at a shorter l the balls overlap at rest, one hiding the other.
BALL_GAP = 1.0


def max_stable_k(dt: float, substeps: int, n_objects: int) -> float:
    """The stiffest spring constant that semi-implicit Euler with ``substeps`` steps per frame of
    ``dt`` integrates stably: the fastest mode of ``n_objects`` balls joined pairwise by springs has
    ω² = n·k, and the method is stable for ω·h < 2 (h = dt / substeps)."""
    h = dt / substeps
    return (2 / h) ** 2 / n_objects


def _minimum_size(config: SceneConfig) -> float:
    """The smallest image side on which starts can be drawn at all (a float: inf for a radius such as 1e308)."""
    r, n = config.radius, config.n_objects
    if config.physics == "spring":
        size = 2 * (r + config.params.get("l", 0.0)) + 1  # the centre of mass needs room
    elif config.physics == "gravity":
        # the triangle's radius is H/4·[0.75, 1.25]; its balls must fit inside and apart from each other
        size = max(2 * r * n + 2, 8 * r)
    else:
        size = 2 * r * n + 2  # bouncing: the balls must fit side by side
    return float(math.ceil(size)) if math.isfinite(size) else size


#: Each scene's defaults (the paper's).
SCENES: dict[str, dict[str, Any]] = {
    "bouncing": {"physics": "bouncing", "image_size": 32, "n_objects": 2, "dt": 0.3, "params": {}, "radius": 3.0,
                 "speed": 8.0},
    "spring": {"physics": "spring", "image_size": 32, "n_objects": 2, "dt": 0.3, "params": {"k": 4.0, "l": 6.0},
               "radius": 3.0, "speed": 8.0},
    "gravity": {"physics": "gravity", "image_size": 36, "n_objects": 3, "dt": 0.5, "params": {"g": 60.0, "m": 1.0},
                "radius": 3.0, "speed": 2.0},
    "digits-spring": {"physics": "spring", "image_size": 64, "n_objects": 2, "dt": 0.3,
                      "params": {"k": 2.0, "l": 12.0}, "radius": 11.0, "speed": 8.0, "wall_margin": 2.0,
                      "supersample": 4},
}


#: The start speed of ``half`` data (pixels per second; the published data sets' "vx2"): at the scene's 8, about
#: one start in 20,000 keeps both balls in the top half for 30 frames; at 2, one in 1,000 (measured).
HALF_SPEED = 2.0


def scene_config(scene: str, **overrides: Any) -> SceneConfig:
    """The scene's defaults with ``overrides``; ``params`` entries are merged, not replaced. With ``half=True`` the
    speed is :data:`HALF_SPEED` and ``max_tries`` 100,000 unless given."""
    if scene not in SCENES:
        raise SceneError(f"unknown scene {scene!r}; known: {', '.join(sorted(SCENES))}")
    values = dict(SCENES[scene])
    params = dict(values["params"])
    unknown = set(overrides.get("params", {})) - set(params)
    if unknown:
        raise SceneError(f"{scene} has no parameter(s) {sorted(unknown)}; it has {sorted(params) or 'none'}")
    params.update(overrides.pop("params", {}))
    if overrides.get("half"):
        overrides = {"speed": HALF_SPEED, "max_tries": 100_000, **overrides}
    return SceneConfig(scene=scene, **{**values, **overrides, "params": params})


def state_names(n_objects: int) -> list[str]:
    """Names of the /states columns: x0, y0, x1, y1, ..., then vx0, vy0, ..."""
    return [f"{a}{i}" for i in range(n_objects) for a in ("x", "y")] + [
        f"v{a}{i}" for i in range(n_objects) for a in ("x", "y")]


# ------------------------------------------------------------------------------------------ physics
def accelerations(config: SceneConfig, p: np.ndarray) -> np.ndarray:
    """Acceleration of every object, (..., N, 2), at positions p (..., N, 2), unit masses."""
    if config.physics == "bouncing":
        return np.zeros_like(p)
    d = p[..., :, None, :] - p[..., None, :, :]  # (..., N, N, 2), d[i, j] = p_i - p_j
    dist = np.sqrt((d**2).sum(-1, keepdims=True))  # (..., N, N, 1)
    dist = np.where(dist > 0, dist, 1.0)  # the diagonal's d is 0: avoid 0/0 (its term is 0 anyway)
    if config.physics == "spring":
        k, ell = config.params["k"], config.params["l"]
        return (-k * (dist - 2 * ell) * d / dist).sum(-2)
    g, m = config.params["g"], config.params.get("m", 1.0)
    return (-g * m * m * d / dist**3).sum(-2) / m  # force g·m_i·m_j/|d|², divided by m_i


def _reflect(config: SceneConfig, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Elastic walls: a centre beyond [r, H - r] is mirrored back inside and that velocity flips."""
    low, high = config.radius, config.image_size - config.radius
    below, above = p < low, p > high
    p = np.where(below, 2 * low - p, np.where(above, 2 * high - p, p))
    return p, np.where(below | above, -v, v)


def simulate(config: SceneConfig, p0: np.ndarray, v0: np.ndarray, steps: int,
             substeps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of ``steps`` frames, each (T, ..., N, 2), from p0, v0 (..., N, 2); frame 0 is (p0, v0).

    Each frame is ``substeps`` (default ``config.substeps``) semi-implicit Euler steps of dt/substeps.
    """
    m = config.substeps if substeps is None else substeps
    h = config.dt / m
    p, v = np.array(p0, dtype=np.float64), np.array(v0, dtype=np.float64)
    ps, vs = np.empty((steps, *p.shape)), np.empty((steps, *p.shape))
    # a candidate start that blows up (balls of the gravity scene passing through each other)
    # turns inf or NaN quietly: _acceptable rejects it, and numpy's warnings would only be noise
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for t in range(steps):
            ps[t], vs[t] = p, v
            for _ in range(m):
                v = v + h * accelerations(config, p)
                p = p + h * v
                if config.physics == "bouncing":
                    p, v = _reflect(config, p, v)
    return ps, vs


def _random_direction(rng: np.random.Generator, n: int) -> np.ndarray:
    angle = rng.uniform(0, 2 * np.pi, size=n)
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (n, 2)


def _start(config: SceneConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One candidate start (p0, v0), each (N, 2), drawn as the published generators draw it."""
    size, n, r = float(config.image_size), config.n_objects, config.radius
    if config.physics == "bouncing":
        p = rng.uniform(r, size - r, size=(n, 2))
        return p, config.speed * _random_direction(rng, n)
    if config.physics == "spring":
        ell = config.params["l"]
        reach = r + ell
        centre = reach + (size - 2 * reach) * rng.uniform(size=2)
        angles = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n) / n
        spread = ell * rng.uniform(0.5, 1.5)
        p = centre + spread * np.stack([np.cos(angles), np.sin(angles)], -1)
        return p, config.speed * _random_direction(rng, n)
    # gravity: a near-regular polygon around the centre, tangential speeds in one sense, a shared drift
    base = rng.uniform(0, 2 * np.pi)
    jitter = np.concatenate([[0.0], rng.uniform(-0.25, 0.25, size=n - 1)])
    angles = base + 2 * np.pi * np.arange(n) / n + jitter
    radius = rng.uniform(0.75, 1.25) * size / 4
    p = size / 2 + radius * np.stack([np.cos(angles), np.sin(angles)], -1)
    sense = rng.choice([-1.0, 1.0])
    tangent = angles + sense * np.pi / 2
    v = config.speed * np.stack([np.cos(tangent), np.sin(tangent)], -1) + rng.uniform(-0.5, 0.5, size=2)
    return p, v


def _acceptable(config: SceneConfig, ps: np.ndarray, test: bool = False, reach: bool = True) -> np.ndarray:
    """Which candidates (ps: (T, B, N, 2), ``config.substeps`` rows per frame) keep every centre off the walls
    (force-only scenes), for gravity no two balls within r + 1 of each other, and with ``half`` the balls in the top
    half as :attr:`SceneConfig.half` says (``test``: a test sequence, which must then reach the bottom half, unless
    ``reach`` is False); (B,) bool."""
    if config.physics == "bouncing":
        return np.ones(ps.shape[1], bool)
    low, high = config.margin, config.image_size - config.margin
    ok = ((ps > low) & (ps < high)).all(axis=(0, 2, 3))
    if config.half:
        middle, y = config.image_size / 2, ps[..., 1]  # (T, B, N)
        kept = (config.half_frames - 1) * config.substeps + 1 if test else len(ps)  # rows that stay on top
        ok &= (y[:kept] + config.radius <= middle).all(axis=(0, 2))  # no pixel of a ball in the bottom half
        if test and reach:  # a ball wholly in the bottom half in some later frame
            ok &= (y[kept - 1 :: config.substeps] - config.radius >= middle).any(axis=(0, 2))
    if config.physics == "gravity":
        d = np.sqrt(((ps[..., :, None, :] - ps[..., None, :, :]) ** 2).sum(-1))  # (T, B, N, N)
        eye = np.eye(config.n_objects, dtype=bool)
        ok &= np.where(eye, np.inf, d).min(axis=(0, 2, 3)) > config.radius + 1
    return ok


#: Candidate starts simulated together while looking for an acceptable one.
_CANDIDATES = 64
#: The starts of --half test sequences that kept to the top half but did not reach the bottom, kept to find the
#: length that one of them needs (:func:`_half_test_steps`): the more, the shorter the least of those lengths.
_STAYED = 1024


def draw_start(config: SceneConfig, rng: np.random.Generator, steps: int,
               test: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A start whose ``steps`` frames are acceptable, and its trajectory: positions, velocities (T, N, 2).
    ``test``: the sequence is in the test split (it matters only with :attr:`SceneConfig.half`).

    Candidates are drawn in batches of 64 (bouncing: 1) and simulated together; the first acceptable one is kept,
    which is what drawing them one at a time until one passes gives. The check runs on every
    substep (as the generators do), so no wall is touched between frames either.

    Raises:
        SceneError: no acceptable start in ``config.max_tries`` draws.
    """
    fine = replace(config, dt=config.dt / config.substeps, substeps=1)
    batch = 1 if config.physics == "bouncing" else _CANDIDATES  # every bouncing start is acceptable
    stayed: list[tuple[np.ndarray, np.ndarray]] = []  # (a --half test sequence) starts (p0, v0) that kept to the top
    # half and failed only to reach the bottom: a few, to find the length they need
    for _ in range(0, config.max_tries, batch):
        starts = [_start(config, rng) for _ in range(batch)]
        p0 = np.stack([p for p, _ in starts])  # (B, N, 2)
        v0 = np.stack([v for _, v in starts])
        # forces such as --g 1e308 overflow to inf and NaN: those candidates fail the check, without a warning
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            fine_p, fine_v = simulate(fine, p0, v0, (steps - 1) * config.substeps + 1)  # (T·M, B, N, 2)
            good = np.flatnonzero(_acceptable(config, fine_p, test))
            if config.half and test and not len(good) and len(stayed) < _STAYED:
                stayed += [(p0[i], v0[i]) for i in np.flatnonzero(_acceptable(config, fine_p, test, reach=False))]
        if len(good):
            return simulate(config, p0[good[0]], v0[good[0]], steps)
    # forces too weak to show are refused first: no wall, sequence length or image size would make them learnable
    frames = [a[:: config.substeps].transpose(1, 0, 2, 3).reshape(batch, steps, -1) for a in (fine_p, fine_v)]
    check_forces_visible(config, np.concatenate(frames, -1), walls=True)  # (B, T, 4N), as generate_sequence writes
    if config.half and test:  # a test sequence must leave the top half: short ones cannot
        # a larger image keeps a start in the top half longer, and puts the bottom half further away: it helps only
        # where no start stayed on top, and longer sequences only where some did
        if stayed:
            needed = _half_test_steps(config, stayed, steps)
            fix = ("use longer sequences (--steps, now " + str(steps)
                   + (f"; a start drawn here reaches the bottom half with --steps {needed}" if needed else "")
                   + f"){_force_advice(config)}")
        else:
            fix = f"use a larger image (--image-size, now {config.image_size}){_force_advice(config)}"
        raise SceneError(f"{config.scene}: no start in {config.max_tries} draws stays clear of the walls and in the top "
                         f"half for its first {config.half_frames} frames, then reaches the bottom half within {steps} "
                         f"frames (a --half test sequence); {fix}")
    raise SceneError(f"{config.scene}: no start in {config.max_tries} draws stays clear of the walls"
                     f"{' and in the top half' if config.half else ''} for {steps} frames; use shorter sequences "
                     f"(--steps){_force_advice(config)} or a larger image (--image-size)")


#: How many of the starts :func:`_half_test_steps` tries must pass at the length it names: the least length at which
#: one passes was one that 100,000 new draws missed (seed 32045: 20 named, 20 refused again).
_HALF_SEARCH_PASSING = 3
#: The most candidate substeps (starts x simulated substeps) :func:`_half_test_steps` simulates: about 64 MiB of
#: positions and velocities for two balls, and a second or two of checks.
_HALF_SEARCH_SUBSTEPS = 1_000_000


def _half_test_steps(config: SceneConfig, starts: list[tuple[np.ndarray, np.ndarray]], steps: int) -> int | None:
    """The fewest frames, past ``steps`` and up to 10 times as many (at most 200 more), with which one of ``starts``
    (p0, v0) makes an acceptable --half test sequence (:func:`_acceptable`: clear of the walls throughout, on top for
    its first frames, then wholly in the bottom half); None where none does. As many starts are tried as
    :data:`_HALF_SEARCH_SUBSTEPS` allows."""
    fine = replace(config, dt=config.dt / config.substeps, substeps=1)
    longest = min(10 * steps, steps + 200)
    starts = starts[: max(1, _HALF_SEARCH_SUBSTEPS // (longest * config.substeps))]
    p0, v0 = np.stack([p for p, _ in starts]), np.stack([v for _, v in starts])  # (B, N, 2)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        fine_p, _ = simulate(fine, p0, v0, (longest - 1) * config.substeps + 1)  # (T·M, B, N, 2)
        first = None
        for length in range(steps + 1, longest + 1):
            count = int(_acceptable(config, fine_p[: (length - 1) * config.substeps + 1], test=True).sum())
            first = first or (length if count else None)
            if count >= _HALF_SEARCH_PASSING:  # (the first length that one start passes at, few draws reach again)
                return length
    return first


#: Least displacement, in pixels, by which a scene's forces must move some ball away from its force-free path (a straight
#: line at its start velocity) over a collection's first batch of sequences: less, and no frame shows the forces, so
#: their parameters cannot be learned (the pendulum's floors use the same hundredth of a pixel).
MIN_FORCE_SHIFT = 0.01


def _params_text(params: dict[str, float]) -> str:
    """``g = 60, m = 1``: a scene's physical values as its errors name them."""
    return ", ".join(f"{name} = {value:g}" for name, value in params.items())


def force_shift(config: SceneConfig, states: np.ndarray) -> float:
    """The largest distance, in pixels, between a ball's path and its force-free path (the straight line of its
    start velocity), over the sequences of ``states`` (float [B, T, 4N]: positions, then velocities, as
    :func:`generate_sequence` writes them); 0 for a scene without forces. The forces' scenes touch no wall, so
    without forces their paths would be exactly these lines (semi-implicit Euler moves a free ball uniformly)."""
    if config.physics == "bouncing":
        return 0.0
    n, t = config.n_objects, states.shape[1]
    p = states[..., : 2 * n].astype(np.float64)  # (B, T, 2N)
    v0 = states[:, :1, 2 * n :].astype(np.float64)  # (B, 1, 2N)
    free = p[:, :1] + v0 * (config.dt * np.arange(t))[None, :, None]  # (B, T, 2N)
    return float(np.abs(p - free).max()) if states.size else 0.0


def check_forces_visible(config: SceneConfig, states: np.ndarray, walls: bool = False) -> None:
    """Refuses forces too weak to show in the frames (:data:`MIN_FORCE_SHIFT`; ``states`` as :func:`force_shift`):
    ``--g 1e-300`` leaves the gravity scene's balls on straight lines, and g could not be learned from them.
    ``walls``: the starts all hit a wall, so longer sequences are not offered.

    Raises:
        SceneError: naming the parameters, the displacement and the scene's own values.
    """
    if not config.params:
        return
    shift = force_shift(config, states)
    if shift < MIN_FORCE_SHIFT:
        values, own = _params_text(config.params), _params_text(SCENES[config.scene]["params"])
        raise SceneError(f"{config.scene}: with {values} the forces move no ball by {MIN_FORCE_SHIFT:g} px from a straight "
                         f"line in {states.shape[1]} frames (at most {shift:.3g} px), so the frames cannot show them and "
                         f"their parameters cannot be learned; use stronger forces (the scene's own: {own})"
                         + ("" if walls else " or longer sequences"))


def fastest_frequency(config: SceneConfig, states: np.ndarray) -> float:
    """The fastest angular frequency of a scene's motion, rad/s (``states`` as :func:`force_shift`): the spring's
    fastest mode, √(n·k) for n balls joined pairwise (:func:`max_stable_k`); gravity's fastest orbit, √(2·g·m/d³) for
    two balls at the closest distance d of any two in ``states``; 0 for the bouncing balls, which do not oscillate."""
    if config.n_objects < 2:
        return 0.0
    if config.physics == "spring":
        return math.sqrt(config.n_objects * config.params["k"])
    if config.physics != "gravity" or not states.size:
        return 0.0
    n = config.n_objects
    p = states[..., : 2 * n].astype(np.float64).reshape(*states.shape[:-1], n, 2)  # (B, T, N, 2)
    d = np.sqrt(((p[..., :, None, :] - p[..., None, :, :]) ** 2).sum(-1))  # (B, T, N, N)
    closest = float(np.where(np.eye(n, dtype=bool), np.inf, d).min())
    if closest == 0:  # two balls in one place: no start the scene draws
        return math.inf
    return math.sqrt(2 * config.params["g"] * config.params.get("m", 1.0) / closest**3)


def aliasing_warning(config: SceneConfig, states: np.ndarray) -> str | None:
    """A warning where a scene moves faster than its frames sample it: more than π rad of its fastest oscillation or
    orbit (:func:`fastest_frequency`; ``states`` as :func:`force_shift`) per frame, beyond which the frames show a fast
    motion as a slower one (they alias it) and its parameters cannot be learned from them; else None. A warning, not a
    refusal: the simulation is right (up to :func:`max_stable_k`), the frames are too far apart. The spring at dt =
    0.3 s passes π rad a frame from k = 54.8 (the scene's own k = 4: 0.85 rad)."""
    omega = fastest_frequency(config, states)
    per_frame = omega * config.dt
    if per_frame <= math.pi:
        return None
    name = "k" if config.physics == "spring" else "g"
    motion = "oscillate at" if config.physics == "spring" else "orbit each other at up to"
    below = config.params[name] * (math.pi / per_frame) ** 2  # ω grows as the square root of k (of g)
    objects = "digits" if config.scene == "digits-spring" else "balls"
    return (f"{config.scene}: with {_params_text(config.params)} the {objects} {motion} {omega:.3g} rad/s, "
            f"{per_frame:.3g} rad per frame of {config.dt:g} s, beyond the π rad per frame that the frames can sample: "
            f"they alias the motion, and {name} cannot be learned from them; give {name} below {below:.4g} (the scene's "
            f"own: {_params_text(SCENES[config.scene]['params'])})")


def _force_advice(config: SceneConfig) -> str:
    """What to change in the forces of a scene whose starts all hit a wall: weaker forces where they exceed the
    scene's own (--g 1e6 flings every start into a wall), stronger ones where they fall short of them (--k 1e-300 lets
    the balls fly apart), other ones where both; nothing for a scene without forces, or with the scene's own."""
    if not config.params:
        return ""
    values = _params_text(config.params)
    own = SCENES[config.scene]["params"]
    above = any(value > own.get(name, value) for name, value in config.params.items())
    below = any(value < own.get(name, value) for name, value in config.params.items())
    if not (above or below):  # the scene's own forces: the sequences, the speed or the image are the ones to change
        return ""
    kind = "other" if above and below else "weaker" if above else "stronger"
    scene = _params_text(own)
    return f", {kind} forces than {values} (the scene's own: {scene})"


# ---------------------------------------------------------------------------------------- rendering
_BALL_COLORS = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))  # channel 2 - j, as the generators
_DIGIT_COLORS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))  # channel j


def _colors(config: SceneConfig) -> np.ndarray:
    if config.colors:
        return np.asarray(config.colors[: config.n_objects])
    table = _DIGIT_COLORS if config.scene == "digits-spring" else _BALL_COLORS
    return np.asarray([table[j % 3] for j in range(config.n_objects)])


@lru_cache(maxsize=8)
def _digit_images(side: int, n: int) -> tuple[np.ndarray, ...]:
    """The first ``n`` distinct-class digits of scikit-learn's ``load_digits``, (side, side) in [0, 1]."""
    try:
        from sklearn.datasets import load_digits
    except ImportError:  # pragma: no cover - depends on the install
        raise SceneError("the digits scene needs scikit-learn: pip install 'piga[scenes]'") from None
    from skimage.transform import resize

    data = load_digits()
    picked: list[np.ndarray] = []
    seen: set[int] = set()
    for image, label in zip(data.images, data.target):
        if int(label) not in seen:
            seen.add(int(label))
            picked.append(resize(image / 16.0, (side, side), order=3, anti_aliasing=False).clip(0, 1))
        if len(picked) == n:
            break
    return tuple(picked)


@lru_cache(maxsize=8)
def _texture(side: int) -> np.ndarray:
    """The background of the digits: a darkened crop of ``skimage.data.brick``, (side, side) in [0, 1]."""
    from skimage import data
    from skimage.transform import resize

    crop = data.brick()[:160, :160] / 255.0
    return np.clip(resize(crop, (side, side), anti_aliasing=True) - 0.2, 0.0, 1.0)


def render(config: SceneConfig, positions: np.ndarray) -> np.ndarray:
    """Frames of positions (T, N, 2) -> uint8 (T, H, W, 3), drawn ``supersample`` x larger and block-averaged.

    Balls: each ball's coverage of every pixel is the share of its s x s sample points (at the
    high-resolution pixel centres) inside the disk, and balls are layered in order (a later one on
    top): the block average of the high-resolution drawing wherever balls do not overlap within a
    pixel. Digits: pasted into the high-resolution picture, which is then block-averaged.
    """
    s, size = config.supersample, config.image_size
    colors = _colors(config)
    positions = np.asarray(positions, dtype=np.float64)
    steps = len(positions)
    if config.scene == "digits-spring":
        return _render_digits(config, positions, colors)
    box = int(math.ceil(2 * config.radius)) + 2  # pixels around a ball that it can cover
    offsets = (np.arange(box * s) + 0.5) / s  # high-resolution pixel centres in the box, box pixels
    canvas = np.empty((steps, size + 2 * box, size + 2 * box, 3))  # padded: boxes may leave the image
    canvas[:] = config.background
    rows = np.arange(steps)[:, None, None]
    for j in range(config.n_objects):
        corner = np.floor(positions[:, j] - config.radius).astype(int)  # (T, 2), the box's top-left pixel
        dx = corner[:, 0, None] + offsets[None] - positions[:, j, 0, None]  # (T, box·s)
        dy = corner[:, 1, None] + offsets[None] - positions[:, j, 1, None]
        inside = dy[:, :, None] ** 2 + dx[:, None, :] ** 2 < config.radius**2  # (T, box·s, box·s)
        cover = inside.reshape(steps, box, s, box, s).mean(axis=(2, 4))[..., None]  # (T, box, box, 1)
        top = np.clip(corner[:, 1], -box, size) + box  # (T,) padded rows
        left = np.clip(corner[:, 0], -box, size) + box
        ys = top[:, None, None] + np.arange(box)[None, :, None]  # (T, box, 1)
        xs = left[:, None, None] + np.arange(box)[None, None, :]  # (T, 1, box)
        canvas[rows, ys, xs] = canvas[rows, ys, xs] * (1 - cover) + cover * colors[j]
    canvas = canvas[:, box : box + size, box : box + size]
    return np.round(canvas * 255).clip(0, 255).astype(np.uint8)


def _render_digits(config: SceneConfig, positions: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """Digits pasted over the texture at high resolution and block-averaged.

    Only the pixels a digit can touch are redrawn at high resolution (each digit's box, or the union
    of the boxes where they meet); elsewhere the block average of the texture is the same in every frame.
    """
    s, size = config.supersample, config.image_size
    side = int(round(2 * config.radius * s))
    box = int(math.ceil(2 * config.radius)) + 2  # image pixels a digit can touch
    glyphs = _digit_images(side, config.n_objects)
    background = np.repeat(_texture(size * s)[..., None], 3, axis=-1)  # (H·s, W·s, 3)
    low = background.reshape(size, s, size, s, 3).mean(axis=(1, 3))  # (H, W, 3)
    frames = np.empty((len(positions), size, size, 3), np.uint8)
    for t, pos in enumerate(positions):
        frame = low.copy()
        corners = [np.clip(np.floor(p - config.radius).astype(int) - 1, 0, size) for p in pos]
        merged: list[list[int]] = []  # boxes x0, y0, x1, y1; the union of those that meet
        for c in corners:
            r = [int(c[0]), int(c[1]), min(int(c[0]) + box, size), min(int(c[1]) + box, size)]
            for m in merged:
                if r[0] < m[2] and m[0] < r[2] and r[1] < m[3] and m[1] < r[3]:
                    m[:] = [min(m[0], r[0]), min(m[1], r[1]), max(m[2], r[2]), max(m[3], r[3])]
                    break
            else:
                merged.append(r)
        for x0, y0, x1, y1 in merged:
            if x1 <= x0 or y1 <= y0:
                continue
            crop = background[y0 * s : y1 * s, x0 * s : x1 * s].copy()
            for j, (x, y) in enumerate(pos):
                _paste(crop, glyphs[j], colors[j], x * s - side / 2 - x0 * s, y * s - side / 2 - y0 * s)
            frame[y0:y1, x0:x1] = crop.reshape(y1 - y0, s, x1 - x0, s, 3).mean(axis=(1, 3))
        frames[t] = np.round(frame * 255).clip(0, 255).astype(np.uint8)
    return frames


def _paste(canvas: np.ndarray, glyph: np.ndarray, color: np.ndarray, left: float, top: float) -> None:
    """Alpha-composites ``glyph`` (alpha = intensity) of ``color`` with its top-left corner at (left, top), clipped."""
    side, height, width = glyph.shape[0], canvas.shape[0], canvas.shape[1]
    x0, y0 = int(round(left)), int(round(top))
    gx0, gy0 = max(0, -x0), max(0, -y0)
    cx0, cy0 = max(0, x0), max(0, y0)
    cx1, cy1 = min(width, x0 + side), min(height, y0 + side)
    if cx1 <= cx0 or cy1 <= cy0:
        return
    alpha = glyph[gy0 : gy0 + cy1 - cy0, gx0 : gx0 + cx1 - cx0, None]
    region = canvas[cy0:cy1, cx0:cx1]
    canvas[cy0:cy1, cx0:cx1] = alpha * color + (1 - alpha) * region


def generate_sequence(config: SceneConfig, rng: np.random.Generator, steps: int,
                      test: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """One sequence: frames uint8 (T, H, W, 3) and states float32 (T, 4N) (positions, then velocities); ``test``:
    a test-split sequence (:attr:`SceneConfig.half`)."""
    ps, vs = draw_start(config, rng, steps, test)
    states = np.concatenate([ps.reshape(steps, -1), vs.reshape(steps, -1)], axis=1).astype(np.float32)
    return render(config, ps), states
