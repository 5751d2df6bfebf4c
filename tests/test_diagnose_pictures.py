"""What the diagnosis says about the picture: sensor noise against a change of the picture, and a picture darker or
brighter than the model's, which its encoder cannot read."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import torch

from piga.diagnostics import vision as V
from piga.diagnostics.diagnose import DiagnoseConfig, summarise_vision
from piga.diagnostics.results import Effect
from tests.test_vision import SIZE, _renders, rod_model

N, T = 24, 16


@pytest.fixture(scope="module")
def model():
    return rod_model(SIZE)


def _recording(path: Path, model, change: str, exposure: float = 1.0, noise: float = 3.0) -> Path:
    """A file of N swinging sequences of T frames from the rod model's decoder, with sensor noise or a shadow drawn on
    (or neither: ``change`` "none"), seen with an ``exposure``."""
    rng = np.random.default_rng(3)
    t = np.arange(T)
    theta = rng.uniform(-math.pi, math.pi, (N, 1)) + 0.3 * np.sin(0.5 * t + rng.uniform(0, 6, (N, 1)))  # (N, T)
    frames = _renders(model, torch.from_numpy(theta.ravel())).astype(np.float64).reshape(N, T, SIZE, SIZE)
    frames = np.minimum(frames * exposure, 255)
    if change == "none":
        pass
    elif change == "noise":
        frames += noise * rng.normal(size=frames.shape)
    else:  # a soft dark blob that drifts across the picture, as a moving shadow does
        ys, xs = np.mgrid[0:SIZE, 0:SIZE]
        cx = rng.uniform(0, SIZE, (N, 1)) + 1.5 * t  # (N, T)
        blob = np.exp(-((xs - cx[..., None, None] % SIZE) ** 2 + (ys - SIZE / 4) ** 2) / (2 * 3.0**2))
        frames -= 40 * blob
    with h5py.File(path, "w") as f:
        f["frames"] = np.clip(np.rint(frames), 0, 255).astype(np.uint8)
    return path


@pytest.mark.parametrize("change", ["noise", "shadow"])
def test_a_moving_shadow_is_not_named_sensor_noise(model, tmp_path: Path, change: str) -> None:
    """The still pixels' spread is named noise only where it does not persist from frame to frame: dm_control with
    shadows on read "noise 2.5 gray levels", from a shadow that crosses the pixels the pendulum never reaches."""
    path = _recording(tmp_path / "rec.h5", model, change)
    fit = np.arange(N) < 16
    found = V.camera_stage(model, str(path), np.zeros((N, T)), fit, None)
    assert found.noise > V.CameraConfig().min_noise  # both spread the still pixels
    named = {e["effect"] for e in found.effects}
    config = DiagnoseConfig()
    _, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None,
                                [SimpleNamespace(effect=e) for e in named], config)
    persist = [n for n in notes if "persist from frame to frame" in n]
    if change == "noise":
        assert abs(found.noise_correlation) < 0.1 and found.noise == pytest.approx(3.0, rel=0.1)
        assert named == {"noise"} and found.rematched and not persist
    else:
        assert found.noise_correlation > config.camera.max_noise_correlation
        assert "noise" not in named and not found.rematched
        assert len(persist) == 1 and "not sensor noise" in persist[0] and f"{found.noise:.2f} gray levels" in persist[0]


def _zoomed(path: Path, zoom: float) -> Path:
    """The file's frames zoomed by ``zoom`` about the image centre (the rod's hinge), as cv2 warps them."""
    import cv2

    with h5py.File(path, "a") as f:
        c = SIZE / 2 - 0.5  # the hinge, in the pixel centres' coordinates
        warp = np.array([[zoom, 0.0, (1 - zoom) * c], [0.0, zoom, (1 - zoom) * c]])
        frames = f["frames"][...].reshape(-1, SIZE, SIZE)
        f["frames"][...] = np.stack([cv2.warpAffine(x, warp, (SIZE, SIZE), flags=cv2.INTER_LINEAR,
                                                    borderMode=cv2.BORDER_REPLICATE) for x in frames]).reshape(N, T, SIZE, SIZE)
    return path


@pytest.mark.parametrize("zoom", [1.0, 0.8])
def test_a_zoomed_picture_is_named_a_zoom_and_not_a_shift(model, tmp_path: Path, zoom: float) -> None:
    """dm_control filmed from 1.1 times farther (the pendulum drawn x0.91, the physics nominal) was named "shift -0.492
    px down": the zoom is a camera candidate, named with its factor, the angles read through it, and no shift."""
    path = _zoomed(_recording(tmp_path / "rec.h5", model, "none"), zoom)
    config = DiagnoseConfig(camera=V.CameraConfig(fit_frames=120, held_frames=60))  # fewer frames: a faster fit
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None, config.camera)
    vision, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None, [], config)
    assert vision.to_dict()["drawn_scale"] == found.scale  # in report.json's vision
    assert not found.rescaled(config.camera) and found.scale == pytest.approx(1.0, abs=0.06)  # through the zoom
    said = [n for n in notes if "drawn x" in n]
    named = {e["effect"]: e for e in found.effects}
    assert found.camera.dx == found.camera.dy == found.camera.blur == 0
    assert not {"shift", "blur", "exposure"} & set(named)
    if zoom == 1.0:
        assert found.camera == V.Camera() and not said and not found.rematched
    else:
        assert found.camera.zoom == pytest.approx(zoom, abs=0.02) and found.rematched
        lo, hi = named["zoom"]["interval"]
        assert lo <= found.camera.zoom <= hi and hi - lo < 0.05
        assert len(said) == 1 and f"drawn x{found.camera.zoom:.3g} the size" in said[0] and "another length" in said[0]
        assert "zoom" in Effect(**named["zoom"]).describe() and "another length" in Effect(**named["zoom"]).describe()


def test_no_size_is_claimed_through_heavy_noise(model, tmp_path: Path) -> None:
    """Noise of 60 gray levels lit pixels far from the hinge, and a recording named "noise 59.5" got a note of a
    pendulum drawn x2.76: beyond ``CameraConfig.max_scale_noise`` the stage measures no size, and tries no zoom."""
    import h5py

    path = _recording(tmp_path / "rec.h5", model, "none")
    with h5py.File(path, "r+") as f:
        frames = f["frames"][()].astype(float)
        f["frames"][...] = np.clip(frames + np.random.default_rng(0).normal(0, 40, frames.shape), 0, 255)
    config = V.CameraConfig(fit_frames=120, held_frames=60)
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None, config)
    assert found.noise > config.max_scale_noise and found.scale is None and not found.rescaled(config)
    assert not any("zoom" in r["candidate"] for r in found.table)


def test_a_size_that_no_zoom_takes_up_accepts_no_shift(model, tmp_path: Path) -> None:
    """Where the zoom is not tried (or does not take the size difference up), no blur or shift fitted to renders of
    another size is accepted, and the report says the size."""
    path = _zoomed(_recording(tmp_path / "rec.h5", model, "none"), 0.8)
    config = V.CameraConfig(zoom_scale=10.0)  # the zoom never tried
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None, config)
    assert found.scale == pytest.approx(0.8, abs=0.06) and found.rescaled(config)
    _, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None, [],
                                DiagnoseConfig(camera=config))
    said = [n for n in notes if "does not describe" in n]
    assert len(said) == 1 and f"x{found.scale:.2f} the size" in said[0]
    assert not any(r["accepted"] for r in found.table if "shift" in r["candidate"] or "blur" in r["candidate"])
    assert found.camera == V.Camera() and not found.effects


def test_a_verdict_not_explained_on_a_zoomed_picture_names_the_zoom_first() -> None:
    """dm_control filmed from 0.9 times as far read "not explained ...: the actions barely move the system", its
    actuation unchanged: the size difference that no candidate describes comes first, and an undetermined gain is the
    angles' (it listed a motor wired in reverse and actions of other units as causes, for a true a x1.56)."""
    from piga.diagnostics.diagnose import ACTIONS_BARELY_MOVE, ACTUATOR_CAUSES, THROUGH_VISION, _zoom_first
    from piga.diagnostics.results import Naming

    config = V.CameraConfig()
    unexplained = Naming([], [], f"not explained by the candidates: {ACTIONS_BARELY_MOVE}: a refits to 2.9e-08; "
                                 + ACTUATOR_CAUSES, "unexplained")
    zoomed = SimpleNamespace(scale=1.12, rescaled=lambda c: True)
    said = _zoom_first(unexplained, zoomed, config).verdict
    assert said.startswith("not explained: the pendulum is drawn x1.12 the size of the model's renders")
    assert f"What the fits read through it: not explained by the candidates: {THROUGH_VISION[0]}: a refits" in said
    assert "motor wired in reverse" not in said and said.endswith("through a picture of another size, which says "
                                                                  "nothing of the actuator: angles that the vision "
                                                                  "misreads do not follow the actions either")
    named = Naming([], [], "damping 0.128 1/s", "damping")  # a named effect stays as it is (the note says the size)
    assert _zoom_first(named, zoomed, config) is named
    assert _zoom_first(unexplained, SimpleNamespace(scale=1.0, rescaled=lambda c: False), config) is unexplained


def test_a_camera_change_under_the_naming_size_is_said_in_a_note() -> None:
    """dm_control filmed from 1.05 times as far: a zoom of 0.972 lowered the matched residual by 40%, under the 3%
    named, and nothing said the picture differs."""
    config = DiagnoseConfig()
    none = {"candidate": "none", "camera": V.Camera().__dict__, "drop": 0.0, "accepted": False}
    zoom = {"candidate": "zoom", "camera": {**V.Camera().__dict__, "zoom": 0.972}, "drop": 0.40, "accepted": False}
    shift = {"candidate": "shift", "camera": {**V.Camera().__dict__, "dy": -0.27}, "drop": 0.17, "accepted": False}
    found = V.CameraFindings(V.Camera(), 0.0, 0.0, 0, 0, [none, shift, zoom], 1e-3, 1e-3, [])
    _, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None, [], config)
    said = [n for n in notes if n.startswith("a camera a little different")]
    assert len(said) == 1 and "the zoom candidate (zoom 0.972)" in said[0] and "by 40%" in said[0], notes
    for quiet in (replace(found, table=[none, {**zoom, "drop": 0.05}]),  # a drop under min_drop
                  replace(found, table=[none, {**zoom, "rescaled": True}]),  # refused for the size: its own note
                  replace(found, camera=V.Camera(blur=1.0))):  # a camera named
        assert quiet.below_naming(config.camera) is None


def test_a_camera_candidate_that_takes_up_what_is_drawn_with_the_action_is_not_called_a_camera() -> None:
    """Gymnasium recordings at actuation gains of 0.3 to 0.5 (a smaller torque arrow) read "a camera a little different
    from the model's: the exposure candidate (exposure 1.04) lowers the held-out matched residual by 31-45%": where
    the re-rendering error follows the action unlike on the training file, the note puts it on the action's drawing;
    a recording whose error follows the action as the training file's does keeps the camera note."""
    from piga.diagnostics.diagnose import action_linked

    config = DiagnoseConfig()
    rng = np.random.default_rng(0)
    actions, own_actions = rng.uniform(-2, 2, (30, 12)), rng.uniform(-2, 2, (40, 12))

    def error(u: np.ndarray, arrow: float) -> np.ndarray:  # (N, T) frame t + 1 after u_t, an arrow's share growing
        return np.concatenate([np.full((len(u), 1), 1e-4), 1e-4 + arrow * np.abs(u[:, :-1]) ** 2], 1)

    none = {"candidate": "none", "camera": V.Camera().__dict__, "drop": 0.0, "accepted": False}
    lit = {"candidate": "exposure", "camera": {**V.Camera().__dict__, "exposure": 1.04}, "drop": 0.41,
           "accepted": False, "core_brightening": 1.0}
    found = V.CameraFindings(V.Camera(), 0.0, 0.0, 0, 0, [none, lit], 1e-3, 1e-3, [])
    own = SimpleNamespace(rec_mse=error(own_actions, 2e-4), actions=own_actions, stale=None)  # after large actions ~8x the calm
    small_arrow = SimpleNamespace(rec_mse=error(actions, 5e-6), actions=actions, stale=None)
    _, notes = summarise_vision(small_arrow, 1.0, found, None, [], config, lambda: own)
    assert action_linked(small_arrow.rec_mse, actions, own.rec_mse, own_actions) is not None
    said = [n for n in notes if "exposure 1.04" in n]
    assert len(said) == 1 and said[0].startswith("the re-rendering error follows the action less than"), notes
    assert "drawn smaller or not at all" in said[0], said  # it read "follows the action as it does not" beside x1, x8.1
    large_arrow = SimpleNamespace(rec_mse=error(actions, 5e-3), actions=actions, stale=None)
    _, notes = summarise_vision(large_arrow, 1.0, found, None, [], config, lambda: own)
    assert any(n.startswith("the re-rendering error follows the action more than") and "drawn larger" in n
               for n in notes), notes
    assert "the pendulum itself does not brighten" in said[0] and "under the size" not in said[0], said
    alike = SimpleNamespace(rec_mse=error(actions, 1.6e-4), actions=actions, stale=None)  # the same share: a camera's change
    assert action_linked(alike.rec_mse, actions, own.rec_mse, own_actions) is None
    _, notes = summarise_vision(alike, 1.0, found, None, [], config, lambda: own)
    assert any(n.startswith("a camera a little different") for n in notes), notes
    _, notes = summarise_vision(small_arrow, 1.0, found, None, [], config)  # no training file: nothing to compare
    assert any(n.startswith("a camera a little different") for n in notes), notes


def test_a_camera_accepted_under_the_named_size_is_said_where_the_angles_are_matched_through_it() -> None:
    """An actuation gain of 0.8 drew the torque arrow smaller, and an exposure of 1.015 was accepted for the matching
    but read on the pendulum under the size that is named: "the dynamics are fitted ... through the fitted camera"
    named no camera."""
    from piga.diagnostics.results import Effect

    actions = np.random.default_rng(0).uniform(-2, 2, (4, 6))
    obs = SimpleNamespace(rec_mse=np.full((4, 6), 1e-4), actions=actions, stale=None)
    found = V.CameraFindings(V.Camera(exposure=1.015), 0.0, 0.0, 0, 0, [], 1e-4, 1e-4, [], theta=np.zeros((4, 6)))
    _, notes = summarise_vision(obs, 1e-4, found, None, [], DiagnoseConfig())
    said = [n for n in notes if "through the fitted camera" in n]
    assert len(said) == 1 and "(exposure 1.015, under the sizes that are named, so no camera is named)" in said[0], notes
    blurred = V.CameraFindings(V.Camera(blur=1.2), 0.0, 0.0, 0, 0, [], 1e-4, 1e-4, [], theta=np.zeros((4, 6)))
    _, notes = summarise_vision(obs, 1e-4, blurred, None, [Effect("blur", 1.2, "px (Gaussian σ)")], DiagnoseConfig())
    assert any("through the fitted camera (analysis by synthesis)" in n for n in notes), notes  # named: not said again
    read = replace(blurred, effects=[{"effect": "blur", "value": 1.2, "unit": "px (Gaussian σ)"}])
    _, notes = summarise_vision(obs, 1e-4, read, None, [], DiagnoseConfig())  # read, under a verdict listing none
    assert any("through the fitted camera (analysis by synthesis)" in n for n in notes), notes
    # a camera the stage read, under a verdict of "not explained" that lists no effect: no "a shifted camera?" asked
    # (a cogging torque under a shift of 1 px, 3.3x)
    shifted = V.CameraFindings(V.Camera(dx=1.0, dy=1.0), 0.0, 0.0, 0, 0, [], 1e-4, 1e-4,
                               [{"effect": "shift", "value": 1.41, "unit": "px"}], theta=np.zeros((4, 6)))
    seen = SimpleNamespace(rec_mse=np.full((4, 6), 3.3e-4), actions=actions, stale=None)
    _, notes = summarise_vision(seen, 1e-4, shifted, None, [], DiagnoseConfig())
    assert not any(n.startswith("vision gap") for n in notes), notes
    _, notes = summarise_vision(seen, 1e-4, replace(shifted, effects=[]), None, [], DiagnoseConfig())
    assert any("a shifted camera or a different scene?" in n for n in notes), notes


def test_a_vision_gap_in_what_is_drawn_with_the_action_puts_every_step_on_the_matched_angles(monkeypatch) -> None:
    """Gymnasium at an actuation gain of 1.6 (its torque arrow drawn larger than any in the training frames) read "not
    explained ... a camera moved far?" with a = 2e-09 on the encoder's angles, which read through the arrow; the
    angles matched to the decoder's renders read the gain."""
    from piga.diagnostics import analyse
    from piga.diagnostics.diagnose import drawn_with_the_action
    from tests.test_diagnostics import NOMINAL, planted

    obs = planted({"gain": 1.6}, n=80, t=24)
    rng = np.random.default_rng(1)
    u = np.abs(obs.actions[:, :-1])  # (N, T - 1)
    arrow = np.concatenate([np.full((len(u), 1), 1e-4), 1e-4 + 5e-4 * u ** 2], 1)  # (N, T) after u_t, frame t + 1
    read_through = obs.theta + 0.3 * np.concatenate([np.zeros((len(u), 1)), obs.actions[:, :-1]], 1) \
        + rng.normal(0, 0.05, obs.theta.shape)  # the encoder pulled toward the arrow
    seen = replace(obs, theta=read_through, rec_mse=arrow)
    config = replace(DiagnoseConfig(), bootstrap=10)
    assert drawn_with_the_action(seen, 2e-4, config)
    assert not drawn_with_the_action(replace(seen, rec_mse=np.full_like(arrow, 1e-3)), 2e-4, config)  # every frame
    assert not drawn_with_the_action(seen, 2e-3, config)  # within the vision ratio: no gap
    # an arrow a little larger than the training file's (an actuation gain of 1.2 beside friction, 1.6-1.7x): the
    # encoder's one-step errors were 3-4x the matched angles', which read the friction that the encoder's missed
    mean = float(arrow.mean())
    assert drawn_with_the_action(seen, mean / 1.5, config)
    assert not drawn_with_the_action(seen, mean / 1.1, config)  # clean recordings: 0.98x
    camera = V.CameraFindings(V.Camera(), 0.0, 0.0, 0, 0, [], 1e-3, 1e-3, [])
    fast = replace(config, bootstrap=0)
    d = analyse(seen, NOMINAL, fast, rec_training=2e-4, camera=camera, matched=lambda: obs.theta)
    assert d.verdict_class == "gain" and abs(d.effects[0].value - 1.6) < 0.05, d.verdict
    assert any(n.startswith("the encoder reads its angles through what is drawn with the action") for n in d.notes)
    # without the matched angles, every step stays on the encoder's (stopped where the windows are cut: a whole
    # diagnosis of the encoder's angles here takes 6x the one above)
    import importlib

    class Cut(Exception):
        pass

    def cut(_, theta, *args):
        raise Cut(theta)

    monkeypatch.setattr(importlib.import_module("piga.diagnostics.diagnose"), "cut_windows", cut)
    with pytest.raises(Cut) as on_encoder:
        analyse(seen, NOMINAL, replace(fast, matched_angles=False), rec_training=2e-4, camera=camera,
                matched=lambda: obs.theta)
    assert on_encoder.value.args[0] is seen.theta
    with pytest.raises(Cut) as on_matched:
        analyse(seen, NOMINAL, fast, rec_training=2e-4, camera=camera, matched=lambda: obs.theta)
    assert on_matched.value.args[0] is obs.theta


def _through_a_codec(obs, rng: np.random.Generator):
    """``obs`` whose angles the encoder reads as it read H.264 at crf 26: mostly within a few tenths of a degree, a
    fifth of the frames off by about 2 degrees (the codec's blocks), where matching read every frame within 0.2."""
    blocks = rng.random(obs.theta.shape) < 0.2
    return replace(obs, theta=obs.theta + np.where(blocks, rng.normal(0, 0.035, obs.theta.shape),
                                                   rng.normal(0, 0.006, obs.theta.shape)), lossy_source="clip.mp4")


def test_a_lossy_videos_codec_read_by_the_encoder_puts_every_step_on_the_matched_angles(monkeypatch) -> None:
    """A friction of 0.3 filmed to H.264 at crf 26 and imported read "damping 0.0654" and "damping 0.0706" (two seeds)
    on the encoder's angles, which erred 1.49 deg (RMS) against the states, the angles matched to the decoder's renders
    0.22 deg; on those, "friction 0.3" (both). A recording that the encoder reads no worse than matching (uncompressed
    frames: 0.80-0.86x), or one from no lossy video, stays on the encoder's angles."""
    import importlib

    from piga.diagnostics import analyse
    from piga.diagnostics.diagnose import codec_reading_ratio
    from tests.test_diagnostics import NOMINAL, planted

    obs = planted({"friction": 0.3}, n=60, t=24)
    seen = _through_a_codec(obs, np.random.default_rng(2))
    assert codec_reading_ratio(seen, obs.theta, NOMINAL) > 2.0
    assert codec_reading_ratio(obs, seen.theta, NOMINAL) < 0.5
    config = replace(DiagnoseConfig(), bootstrap=0)
    camera = V.CameraFindings(V.Camera(), 0.0, 0.0, 0, 0, [], 1e-3, 1e-3, [])

    class Cut(Exception):
        pass

    def cut(_, theta, *args):
        raise Cut(theta)

    monkeypatch.setattr(importlib.import_module("piga.diagnostics.diagnose"), "cut_windows", cut)

    def angles(o, c=config, matched=obs.theta):
        with pytest.raises(Cut) as read:
            analyse(o, NOMINAL, c, rec_training=1e-3, camera=camera, matched=lambda: matched)
        return read.value.args[0]

    assert angles(seen) is obs.theta
    assert angles(replace(seen, lossy_source=None)) is seen.theta  # (no lossy video: the encoder's)
    assert angles(seen, matched=seen.theta + 0.0) is seen.theta  # (matching reads no better: the encoder's)
    assert angles(seen, replace(config, codec_reading_ratio=100.0)) is seen.theta
    assert angles(seen, replace(config, matched_angles=False)) is seen.theta
    # the report says why
    found = replace(camera, theta=obs.theta, matched_for_codec=4.2)
    _, notes = summarise_vision(seen, 1e-3, found, None, [], config)
    assert any(n.startswith("the frames come from clip.mp4, a lossy video, whose codec's errors the encoder reads: the "
                            "nominal physics' typical one-step angle error is 4.2x as large") for n in notes), notes


@pytest.mark.slow
def test_a_friction_through_a_codec_is_read_as_a_friction_on_the_matched_angles() -> None:
    """The whole diagnosis of the recording above runs on the matched angles, reads the friction within 10%, says
    where it was read, and claims no stand-in (these independent reading errors do not bend the friction on the
    encoder's angles either, 0.318 there: the codec's, which did, are measured in ``codec_reading_ratio``'s text)."""
    from piga.diagnostics import analyse
    from tests.test_diagnostics import NOMINAL, planted

    obs = planted({"friction": 0.3}, n=60, t=24)
    seen = _through_a_codec(obs, np.random.default_rng(2))
    camera = V.CameraFindings(V.Camera(), 0.0, 0.0, 0, 0, [], 1e-3, 1e-3, [])
    d = analyse(seen, NOMINAL, replace(DiagnoseConfig(), bootstrap=0), rec_training=1e-3, camera=camera,
                matched=lambda: obs.theta)
    assert d.verdict_class == "friction" and abs(d.effects[0].value - 0.3) < 0.03, d.verdict
    assert any("a lossy video, whose codec's errors the encoder reads" in n for n in d.notes), d.notes
    assert not any("may stand in for another" in n for n in d.notes), d.notes


def test_noise_only_after_large_actions_is_not_sensor_noise() -> None:
    """Gymnasium at an actuation gain of 3 drew its torque arrow onto pixels that no training frame's reaches, and read
    "noise 41.8 gray levels" on a file with none: the frames after the smallest fifth of the actions show none. At a
    gain of 4, a real noise of 3 read 44.7 (44.6..44.7) over every frame: these frames read it alone."""
    rng = np.random.default_rng(0)
    n, t = 20, 12
    actions = rng.uniform(-2, 2, (n, t)).astype(np.float32)  # (N, T)
    seqs, times = np.repeat(np.arange(n), t), np.tile(np.arange(t), n)  # (M,) every frame
    big = np.zeros(len(seqs), bool)
    big[times >= 1] = np.abs(actions[seqs[times >= 1], times[times >= 1] - 1]) > 1.0
    still = np.ones((8, 8), bool)
    arrow = np.full((len(seqs), 8, 8), 255, np.uint8)
    arrow[big] = rng.integers(100, 255, (int(big.sum()), 8, 8), dtype=np.uint8)  # changed only after large actions
    assert V.noise_level(arrow, still) > 3  # read as noise over all frames
    assert V.calm_noise(arrow, seqs, times, actions, still) == (0.0, None)
    noisy = np.clip(128 + rng.normal(0, 10, (len(seqs), 8, 8)), 0, 255).astype(np.uint8)  # sensor noise: every frame
    value, interval = V.calm_noise(noisy, seqs, times, actions, still)
    assert interval is not None and interval[0] < 10 < interval[1] and abs(value - 10) < 1
    stale = np.zeros((n, t), bool)  # dropped frames among the calm ones repeat the frame before, arrow and all
    calm = np.flatnonzero(V._calm(actions, seqs, times))
    stale[seqs[calm[::2]], times[calm[::2]]] = True
    repeated = arrow.copy()
    repeated[stale[seqs, times]] = rng.integers(100, 255, (int(stale.sum()), 8, 8), dtype=np.uint8)
    assert V.calm_noise(repeated, seqs, times, actions, still)[0] > 3
    assert V.calm_noise(repeated, seqs, times, actions, still, stale) == (0.0, None)
    both = noisy.copy()  # the noise, and the arrow on top of it after the large actions
    both[big] = arrow[big]
    assert V.noise_level(both, still) > 20
    value, interval = V.calm_noise(both, seqs, times, actions, still)
    assert interval is not None and interval[0] < 10 < interval[1]


def test_repeated_frames_do_not_hide_sensor_noise(model, tmp_path: Path) -> None:
    """A repeated frame (a dropped frame) repeats its noise: the repeats are left out of the correlation."""
    path = _recording(tmp_path / "rec.h5", model, "noise")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...]
        stale = (np.arange(T) % 3 != 0)[None].repeat(N, 0)  # (N, T) two frames in three repeat the one before
        for t in range(1, T):
            frames[stale[:, t], t] = frames[stale[:, t], t - 1]
        f["frames"][...] = frames
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, stale)
    assert abs(found.noise_correlation) < 0.1 and "noise" in {e["effect"] for e in found.effects}


@pytest.mark.parametrize("exposure, change, noise", [(0.85, "none", 0), (0.7, "noise", 3), (1.3, "none", 0),
                                                    (1.0, "none", 0), (1.0, "noise", 3), (1.0, "noise", 20)])
def test_another_exposure_is_named_and_read_through(model, tmp_path: Path, exposure: float, change: str,
                                                    noise: float) -> None:
    """A picture 15% darker than the model's was read by the encoder 110° off, and the diagnosis blamed the dynamics;
    it is an exposure, fitted with the camera and matched through. A clean or merely noisy picture has none (noise of
    20 gray levels, clipped at white, was read as a darker picture by a least-squares fit)."""
    path = _recording(tmp_path / "rec.h5", model, change, exposure, noise)
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    named = {e["effect"]: e for e in found.effects}
    if exposure == 1.0:
        assert "exposure" not in named and abs(found.camera.exposure - 1) * 255 <= V.CameraConfig().min_exposure
        return
    assert set(named) == ({"exposure", "noise"} if change == "noise" else {"exposure"})
    lo, hi = named["exposure"]["interval"]
    # a brighter picture shows only on the rod, whose edges are anti-aliased: within 3%
    k = named["exposure"]["value"]
    assert k == pytest.approx(exposure, abs=0.01 if exposure < 1 else 0.03) and lo <= k <= hi
    assert found.rematched and found.camera.blur == 0 and found.camera.dx == found.camera.dy == 0
    assert found.matched_error < (0.2 if exposure < 1 else 0.6) * found.matched_error_nominal


def test_the_diagnose_page_gives_the_camera_stage_s_thresholds() -> None:
    """The page's numbers are CameraConfig's."""
    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "commands" / "diagnose.md").read_text().split())
    c = V.CameraConfig()
    assert f"changes white by more than {c.min_exposure:g} gray levels" in text
    assert f"lowers the held-out residual by more than {100 * c.min_drop:g}%" in text
    assert f"lower it by more than {100 * c.min_drop:g}%" in text
    assert f"named above {c.min_noise:g} gray level" in text
    assert f"successive frames of at most {c.max_noise_correlation:g}" in text
    assert f"more than {100 * c.max_missing:g}% of such held-out frames is refused" in text
    assert f"{'half' if c.min_core_share == 0.5 else c.min_core_share} of its brightening" in text
    assert f"through the accepted camera by {c.repeats.visible:g} gray levels or more" in text
    assert f"renders by more than {100 * c.zoom_scale:g}% (`CameraConfig.zoom_scale`)" in text
    assert f"|z − 1| exceeds {c.min_zoom:g} (`CameraConfig.min_zoom`)" in text
    assert f"differs by more than {100 * c.max_scale_change:g}% (`CameraConfig.max_scale_change`)" in text


def test_another_scene_is_refused_unless_a_camera_explains_it() -> None:
    """A picture 30% darker re-rendered 237x worse than the training frames and was refused as another scene; through
    its exposure it matches at 0.5x, and is diagnosed. Without an accepted camera, or one that still matches badly,
    the refusal stands."""
    from piga.diagnostics.diagnose import check_scene_through_camera
    from piga.diagnostics.observe import NotTheSceneError

    unlike = NotTheSceneError("this is not the scene the model knows")
    check_scene_through_camera(None, V.Camera(), 1.0, 1e-4, 100)  # the scene passed: nothing to decide
    check_scene_through_camera(unlike, V.Camera(exposure=0.7), 1.8e-4, 3.9e-4, 100)
    for camera, matched in ((V.Camera(), 1e-4), (V.Camera(exposure=0.7), 0.05), (V.Camera(exposure=0.7), math.nan)):
        with pytest.raises(NotTheSceneError):
            check_scene_through_camera(unlike, camera, matched, 3.9e-4, 100)


def test_a_recording_too_noisy_to_read_is_refused_as_noise() -> None:
    """Sensor noise of 80 gray levels was refused as "not the scene the model knows" (137x); the named noise explains
    that error, and the line says so, with the noise this model reads. Frames whose error noise does not explain
    (uniform random frames: their spread reads as noise of about 74) keep the refusal as another scene."""
    from piga.diagnostics.diagnose import check_scene_through_camera
    from piga.diagnostics.observe import NotTheSceneError

    unlike = NotTheSceneError("this is not the scene the model knows")
    with pytest.raises(NotTheSceneError, match=r"^these frames are too noisy to read: sensor noise of about 79.5 gray "
                       r"levels \(σ\) has the model re-render them with MSE 0.0535, 137x its training error 0.000391 "
                       r"\(the limit is 100x\); it reads noise up to about 67 gray levels: record with less"):
        check_scene_through_camera(unlike, V.Camera(), 1.0, 3.91e-4, 100, rec_real=0.0535, noise=79.5)
    for rec_real, noise in ((0.0535, 0.0), (0.27, 74.0)):
        with pytest.raises(NotTheSceneError, match="^this is not the scene the model knows$"):
            check_scene_through_camera(unlike, V.Camera(), 1.0, 3.91e-4, 100, rec_real=rec_real, noise=noise)


@pytest.mark.parametrize("blank", [0, T // 2])
def test_frames_without_the_pendulum_are_counted(model, tmp_path: Path, blank: int) -> None:
    """A file whose second half of every sequence was blank read "blur 1.68 px"; its empty frames are now counted, and
    piga-diagnose refuses it beyond CameraConfig.max_missing."""
    path = _recording(tmp_path / "rec.h5", model, "noise")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...]
        empty = 255 + 3.0 * np.random.default_rng(4).normal(size=frames[:, T - blank :].shape)  # white, and noise
        frames[:, T - blank :] = np.clip(np.rint(empty), 0, 255)
        f["frames"][...] = frames
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    if blank:
        assert found.missing == pytest.approx(blank / T, abs=0.1) and found.missing > V.CameraConfig().max_missing
    else:
        assert found.missing == 0


def test_a_blur_is_not_read_as_a_brighter_picture(model, tmp_path: Path) -> None:
    """A blur lightens the rod's core as a brighter exposure does: fitted first, k = 1.48 took a blur of 1.85 px's place
    (named "blur 0.62 px, exposure 1.48"); now a brighter picture competes with the blur, and the blur wins."""
    import cv2

    path = _recording(tmp_path / "rec.h5", model, "none")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...].reshape(-1, SIZE, SIZE)
        f["frames"][...] = np.stack([cv2.GaussianBlur(x, (0, 0), 1.85) for x in frames]).reshape(N, T, SIZE, SIZE)
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    assert [e["effect"] for e in found.effects] == ["blur"] and found.camera.blur == pytest.approx(1.85, abs=0.1)


def _patched_model():
    """The rod model with a faint gray patch in its background, as a decoder draws the mean of a torque arrow that
    the training frames showed and a recording may lack."""
    from tests.test_vision import rod_model as plain

    m = plain(SIZE)
    with torch.no_grad():
        background = torch.ones(1, SIZE, SIZE)
        background[:, SIZE // 2 - 6 : SIZE // 2 + 6, 2:12] = 0.9
        ys, xs = torch.meshgrid(torch.arange(SIZE) + 0.5, torch.arange(SIZE) + 0.5, indexing="ij")
        rod = ((xs - SIZE / 2).abs() < 1.6) & (ys > 4) & (ys < SIZE / 2 + 1)
        m.decoder.load_templates(torch.full((1, 1, SIZE, SIZE), 0.2), torch.where(rod, 8.0, -8.0)[None, None],
                                 background=background, background_mask_logit=torch.zeros(1, SIZE, SIZE))
    return m.eval()


def test_a_picture_without_the_arrow_is_not_a_brighter_exposure(tmp_path: Path) -> None:
    """A recording without the torque arrow of the training frames read "exposure 1.05": brightening the renders
    whitened the decoder's faint arrow. A real exposure brightens the pendulum itself, which here stays as drawn."""
    model = _patched_model()
    path = _recording(tmp_path / "rec.h5", model, "none")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...]
        frames[..., SIZE // 2 - 6 : SIZE // 2 + 6, 2:12] = np.maximum(frames[..., SIZE // 2 - 6 : SIZE // 2 + 6, 2:12],
                                                                       np.where(frames[..., SIZE // 2 - 6 : SIZE // 2 + 6, 2:12] > 200, 255, 0).astype(np.uint8))
        f["frames"][...] = frames
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    lit = next(row for row in found.table if row["candidate"] == "exposure")
    assert lit["drop"] > V.CameraConfig().min_drop and lit["camera"]["exposure"] > 1  # it lowers the residual ...
    assert lit["core_brightening"] == pytest.approx(1.0, abs=0.01) and not lit["accepted"]  # ... not on the rod
    assert "exposure" not in {e["effect"] for e in found.effects}
    brighter = _recording(tmp_path / "bright.h5", _patched_model(), "none", exposure=1.3)
    assert V.core_brightening(model, V._flat(h5py.File(brighter)["frames"][:4].reshape(-1, SIZE, SIZE)),
                              V.decoder_renders(model, V.TABLE_SIZE // 2)) == pytest.approx(1.3, abs=0.03)


@pytest.mark.slow
def test_a_brighter_picture_on_white_is_read_on_the_rod_against_the_training_file(tmp_path: Path) -> None:
    """On Gymnasium's frames the matched residual read a picture brightened by 1.07 as 1.037 (interval 1.03..1.04),
    and its rod's dark pixels read it right: the value is now read there, against the training file's."""
    model = _patched_model()
    # the training frames' rod 2% brighter than the decoder draws it (the default model's: 0.9%), their white the same
    training = _recording(tmp_path / "train.h5", model, "noise", exposure=1.02)
    for k in (1.07, 1.1):  # (with sensor noise, which dithers the rod's whole gray levels, as real frames' edges do)
        path = _recording(tmp_path / f"rec{k}.h5", model, "noise", exposure=k)
        found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None, reference=str(training))
        named = {e["effect"]: e for e in found.effects}
        lo, hi = named["exposure"]["interval"]
        value = named["exposure"]["value"]
        assert abs(value - k / 1.02) < 0.003 and lo < value < hi and hi - lo < 0.01, named["exposure"]
        assert not next(r for r in found.table if r["candidate"] == "exposure").get("core_brightening", 2) < 1.03


def test_a_brighter_picture_on_white_beside_a_blur_is_read_with_it(tmp_path: Path) -> None:
    """Gymnasium blurred 0.9 px and brightened by 1.1 read "blur 0.86" alone: the blur lowered the residual more than
    the exposure did, and the exposure was never fitted with it (the dynamics, matched through that camera, read "not
    explained ... is the recording the scene the model knows?"). Here a mid-gray rod, as Gymnasium's is, on white."""
    import cv2

    model = rod_model(SIZE, gray=0.45)
    path = _recording(tmp_path / "rec.h5", model, "none")
    with h5py.File(path, "a") as f:  # blurred, then brightened (as the camera candidates model it), with sensor noise
        frames = f["frames"][...].reshape(-1, SIZE, SIZE).astype(np.float64)
        seen = np.minimum(np.stack([cv2.GaussianBlur(x, (0, 0), 0.9) for x in frames]) * 1.1, 255)
        seen = seen.reshape(N, T, SIZE, SIZE) + 3 * np.random.default_rng(4).normal(size=(N, T, SIZE, SIZE))
        f["frames"][...] = np.clip(np.rint(seen), 0, 255).astype(np.uint8)
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    named = {e["effect"]: e["value"] for e in found.effects}
    assert {"blur", "exposure"} <= set(named), found.table
    assert abs(named["blur"] - 0.9) < 0.03 and abs(named["exposure"] - 1.1) < 0.01, named


def test_a_camera_is_scored_on_the_frames_that_carry_nothing_drawn_with_the_action(model, tmp_path: Path) -> None:
    """Gymnasium at an actuation gain of 5 draws its torque arrow so large that a blur of 1.5 px lowered the residual
    of every frame by 7.5% alone, under the 10% named: the gain was read 4.28 (4.03..4.77) for 5, and no blur. The
    frames after the smallest fifth of the actions carry no arrow: the candidates are scored, and then fitted, there."""
    import cv2

    path = _recording(tmp_path / "rec.h5", model, "none")
    rng = np.random.default_rng(5)
    actions = rng.uniform(-2, 2, (N, T)).astype(np.float32)  # (N, T)
    large = np.zeros((N, T), bool)  # the frames after the larger half of the actions: an "arrow" at the hinge
    large[:, 1:] = np.abs(actions[:, :-1]) >= np.median(np.abs(actions[:, :-1]))
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    with h5py.File(path, "a") as f:
        frames = f["frames"][...].reshape(-1, SIZE, SIZE).astype(np.float64)
        frames = np.stack([cv2.GaussianBlur(x, (0, 0), 1.5) for x in frames]).reshape(N, T, SIZE, SIZE)
        for n, t in zip(*np.nonzero(large)):
            cx, cy = SIZE / 2 + rng.uniform(-2, 2, 2)
            frames[n, t] -= 255 * np.exp(-((xs - cx) ** 2 + (ys - cy) ** 2) / (2 * 10.0**2))
        f["frames"][...] = np.clip(np.rint(frames), 0, 255).astype(np.uint8)
    fit = np.arange(N) < 16
    unknown = V.camera_stage(model, str(path), np.zeros((N, T)), fit, None)  # the actions unknown: every frame
    assert unknown.camera == V.Camera() and "blur" not in {e["effect"] for e in unknown.effects}
    found = V.camera_stage(model, str(path), np.zeros((N, T)), fit, None, actions=actions)
    blur = next(r for r in found.table if r["candidate"] == "blur")
    assert blur["drop"] < V.CameraConfig().min_drop < blur["calm_drop"] and blur["fitted_on"] == "calm"
    assert found.camera.blur == pytest.approx(1.5, abs=0.05) and not found.camera.dx and not found.camera.dy


def test_the_report_shows_the_calm_frames_drop_that_accepted_a_candidate() -> None:
    """An exposure accepted at a held-out drop of 5.9%, under the 10% named, read as a broken rule: the drop on the
    frames after the smallest fifth of the actions, which accepted it, was in report.json alone."""
    from piga.diagnostics.report import _camera_lines
    from piga.diagnostics.results import CameraSummary, VisionSummary

    cam = V.Camera().__dict__
    rows = [{"candidate": "none", "camera": cam, "held_out_matched_mse": 1e-3, "drop": 0.0, "calm_drop": 0.0,
             "accepted": False},
            {"candidate": "exposure", "camera": {**cam, "exposure": 1.1}, "held_out_matched_mse": 9.41e-4, "drop": 0.059,
             "calm_drop": 0.31, "accepted": True}]
    summary = CameraSummary(V.Camera(exposure=1.1), rows, 0.0, 0, 0, 0.0, 0, 1e-3, 9.41e-4, "matched", float("nan"), None)
    text = "\n".join(_camera_lines(VisionSummary(1e-3, 1e-3, 1.0, summary)))
    assert "| held-out matched MSE | drop | calm drop | accepted |" in text
    assert "| 9.410e-04 | 5.9% | 31.0% | yes |" in text and "a drop over 10% in either" in text
    rows = [{k: v for k, v in row.items() if k != "calm_drop"} for row in rows]  # actions unknown: no such column
    summary = CameraSummary(V.Camera(), rows, 0.0, 0, 0, 0.0, 0, 1e-3, 1e-3, "encoder", float("nan"), None)
    assert "calm" not in "\n".join(_camera_lines(VisionSummary(1e-3, 1e-3, 1.0, summary)))


@pytest.mark.slow
def test_a_large_shift_moves_the_pendulum_onto_pixels_not_read_as_noise(model, tmp_path: Path) -> None:
    """A shift of 4.9 px, beyond the still pixels' margin of 4, read "noise 8.34": the still pixels are now those the
    pendulum never reaches through the accepted camera."""
    import cv2

    path = _recording(tmp_path / "rec.h5", model, "none")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...].reshape(-1, SIZE, SIZE)
        warp = np.array([[1.0, 0.0, 4.9], [0.0, 1.0, 4.9]])
        f["frames"][...] = np.stack([cv2.warpAffine(x, warp, (SIZE, SIZE), flags=cv2.INTER_LINEAR,
                                                    borderMode=cv2.BORDER_REPLICATE) for x in frames]).reshape(N, T, SIZE, SIZE)
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, None)
    assert [e["effect"] for e in found.effects] == ["shift"] and found.camera.dx == pytest.approx(4.9, abs=0.1)
    (shift,) = found.effects  # its length, each component, and each with an interval that holds it
    assert shift["value"] == pytest.approx(math.hypot(found.camera.dx, found.camera.dy))
    for key in ("", "dx_", "dy_"):
        low, high = shift[key + "interval"]
        assert low <= shift[key[:-1] or "value"] <= high, shift
    assert found.noise < V.CameraConfig().min_noise  # clean frames: the still pixels never change


def test_a_blurred_pendulum_moving_slowly_does_not_drop_frames(model, tmp_path: Path) -> None:
    """Through a 3.9 px blur, steps of 0.02-0.028 rad changed the frames by at most 2 gray levels and read "frame_drop
    0.0118": a repeat counts as a drop only across a step that shows through the accepted camera."""
    import cv2

    from piga.diagnostics.repeats import stale_frames

    theta = np.linspace(0, 0.025 * (T - 1), T)[None] + np.linspace(-3, 3, N)[:, None]  # (N, T) 0.025 rad per step
    frames = _renders(model, torch.from_numpy(theta.ravel())).reshape(-1, SIZE, SIZE)
    frames = np.stack([cv2.GaussianBlur(x, (0, 0), 3.9) for x in frames]).reshape(N, T, SIZE, SIZE)
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as f:
        f["frames"] = frames
    stale = stale_frames(frames)
    assert stale.sum() >= 5  # the blur leaves moving frames within a repeat's tolerance
    found = V.camera_stage(model, str(path), theta, np.arange(N) < 16, stale)
    assert found.camera.blur == pytest.approx(3.9, abs=0.2) and "frame_drop" not in {e["effect"] for e in found.effects}


@pytest.mark.slow
def test_an_exposure_is_named_relative_to_the_models_own_frames(model, tmp_path: Path) -> None:
    """A model trained on g = 3 frames drew the whole scene 1.6% darker than they were, and its own training file read
    "exposure 1.02": the exposure is the recording's over the own file's, where that file is there."""
    own = _recording(tmp_path / "own.h5", model, "none", exposure=0.984)  # the decoder draws 1 / 0.984 of these
    same = _recording(tmp_path / "same.h5", model, "none", exposure=0.984)
    darker = _recording(tmp_path / "darker.h5", model, "none", exposure=0.984 * 0.8)
    fit = np.arange(N) < 16
    alone = V.camera_stage(model, str(same), np.zeros((N, T)), fit, None)
    assert "exposure" in {e["effect"] for e in alone.effects}  # against the decoder alone: its own bias
    found = V.camera_stage(model, str(same), np.zeros((N, T)), fit, None, reference=str(own))
    assert "exposure" not in {e["effect"] for e in found.effects}
    named = {e["effect"]: e for e in V.camera_stage(model, str(darker), np.zeros((N, T)), fit, None,
                                                   reference=str(own)).effects}
    assert named["exposure"]["value"] == pytest.approx(0.8, abs=0.01)
    lo, hi = named["exposure"]["interval"]
    assert lo <= named["exposure"]["value"] <= hi
    gone = V.camera_stage(model, str(same), np.zeros((N, T)), fit, None, reference=str(tmp_path / "gone.h5"))
    assert "exposure" in {e["effect"] for e in gone.effects}  # no own file: the decoder is the reference


def test_a_vision_gap_only_in_the_frames_of_large_actions_is_put_on_what_is_drawn_with_them() -> None:
    """A recording at an actuation gain of 1.5 (Gymnasium's torque arrow drawn larger than any in the training frames)
    read "vision gap ... (blur, noise, a shifted camera or a different scene?)": where the frames after the smallest
    actions re-render no worse than the training frames, the note says the gap lies in what is drawn with the action;
    a gap in every frame keeps the general note."""
    from piga.diagnostics.diagnose import calm_frames_error

    rng = np.random.default_rng(0)
    actions = rng.uniform(-2, 2, (30, 12))
    arrow = np.concatenate([np.zeros((30, 1)), 1e-4 + 1e-3 * np.abs(actions[:, :-1]) ** 2], 1)  # frame t + 1 after u_t
    config = DiagnoseConfig()
    _, notes = summarise_vision(SimpleNamespace(rec_mse=arrow, actions=actions, stale=None), 2e-4, None, None, [],
                                config)
    assert len(notes) == 1 and "the gap lies in what is drawn with the action" in notes[0], notes
    assert calm_frames_error(arrow, actions) < 2e-4
    everywhere = np.full((30, 12), 1e-3)
    _, notes = summarise_vision(SimpleNamespace(rec_mse=everywhere, actions=actions, stale=None), 2e-4, None, None, [],
                                config)
    assert len(notes) == 1 and "(blur, noise, a shifted camera or a different scene?)" in notes[0], notes
    assert calm_frames_error(everywhere, np.ones((30, 12))) is None  # actions that never vary tell nothing


def test_a_brighter_picture_is_named_only_where_the_rod_shows_its_share() -> None:
    """A recording without the torque arrow, blurred 0.8 px, fitted an exposure of 1.032 with the blur (on the arrow's
    faint pixels) and named "exposure 1.012", read on its rod: under half of the fit's brightening, which a real
    exposure shows in full (1.3 read 1.31)."""
    from piga.diagnostics.vision import CameraConfig, rod_shows_exposure

    config = CameraConfig()
    assert not rod_shows_exposure(1.012, 1.032, config)
    assert rod_shows_exposure(1.31, 1.3, config) and rod_shows_exposure(1.05, 1.08, config)
    assert not rod_shows_exposure(1.011, 1.011, config)  # under min_exposure gray levels, as before
    assert not rod_shows_exposure(1.05, 1.12, replace(config, min_core_share=0.5))


@pytest.mark.parametrize("matched_angles", [True, False])
def test_no_matched_angles_set_aside_by_an_accepted_camera_is_said(matched_angles: bool) -> None:
    """--no-matched-angles on a recording whose camera stage accepted an exposure of 1.013, under the size that is
    named: the dynamics were fitted on the matched angles, and nothing said that the flag was set aside."""
    found = V.CameraFindings(V.Camera(exposure=1.013), 0.0, 0.0, 0, 0, [], 1e-3, 1e-3, [], theta=np.zeros((2, 3)))
    config = DiagnoseConfig(matched_angles=matched_angles)
    _, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None, [], config)
    said = [n for n in notes if n.startswith("--no-matched-angles is set aside")]
    assert len(said) == (not matched_angles), notes
    if said:
        assert said[0] == ("--no-matched-angles is set aside: the camera stage accepted a camera under the sizes that "
                           "are named, so every step reads the angles matched to the decoder's renders")
