"""The paper's Table 2 ablations: ``--loss {joint,pred-only,separate}`` and ``--decoder {st,mlp}``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from piga.cli import train as cli
from piga.world.mlp_decoder import MLPDecoder
from piga.world.model import ModelConfig, PhysicsModel
from piga.world.variants import build_model
from tests.helpers import assert_one_line, run_in_process, stateless_pendulum

PROG = "piga-train-model"
SMALL = ("--epochs", "1", "--batch-size", "8", "--warmup-fraction", "0.5", "--quiet", "--threads", "1")


@pytest.fixture(scope="module")
def small_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 pendulum sequences x 15 frames, split 8/1/1, without /states."""
    return stateless_pendulum(tmp_path_factory.mktemp("small") / "small.h5", 10, 15, seed=7, split=(8, 1, 1))


def _window(config: ModelConfig, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Random uint8 frames (2, L+T, H, W) and actions (2, L+T, 1)."""
    gen = torch.Generator().manual_seed(seed)
    frames = torch.randint(0, 256, (2, config.window, config.image_size, config.image_size), generator=gen, dtype=torch.uint8)
    return frames, torch.randn(2, config.window, 1, generator=gen)


def _grads(model: PhysicsModel, loss: torch.Tensor) -> dict[str, torch.Tensor | None]:
    """d loss / d each named parameter (None where the loss does not reach it)."""
    names, params = zip(*((n, p) for n, p in model.named_parameters() if p.requires_grad))
    grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return dict(zip(names, grads))


def _reached(grads: dict[str, torch.Tensor | None], prefix: str) -> bool:
    """Whether any parameter under ``prefix`` has a nonzero gradient."""
    return any(g is not None and bool(g.abs().sum() > 0) for name, g in grads.items() if name.startswith(prefix))


@pytest.mark.parametrize("decoder", ["st", "mlp"])
def test_separate_stops_the_prediction_gradient_at_the_encoder_and_decoder(decoder: str) -> None:
    parts = ("encoder.", "decoder.", "velocity.", "system.")
    reached = {}
    for scheme in ("joint", "separate"):
        torch.manual_seed(0)
        config = ModelConfig(image_size=32, pred_frames=3, velocity_correction=True, loss=scheme, decoder=decoder)
        model = build_model(config)
        assert isinstance(model, PhysicsModel)
        out = model(*_window(config))
        reached[scheme] = {"pred": {p: _reached(_grads(model, out.loss_pred), p) for p in parts},
                           "rec": {p: _reached(_grads(model, out.loss_rec), p) for p in parts}}
        if scheme == "separate":  # the whole loss's gradient is that of α·L_rec on the encoder and decoder
            total, rec = _grads(model, out.loss), _grads(model, config.alpha * out.loss_rec)
            for name, g in total.items():
                if name.startswith(("encoder.", "decoder.")) and g is not None:
                    assert rec[name] is not None and torch.allclose(g, rec[name], atol=1e-7, rtol=1e-5), name
    # joint: L_pred reaches every part (so the check below can fail)
    assert reached["joint"]["pred"] == dict.fromkeys(parts, True)
    # separate: L_pred reaches only the velocity estimator and the physics; L_rec only the encoder and decoder
    assert reached["separate"]["pred"] == {"encoder.": False, "decoder.": False, "velocity.": True, "system.": True}
    assert reached["separate"]["rec"] == {"encoder.": True, "decoder.": True, "velocity.": False, "system.": False}


def test_separate_one_optimiser_step_leaves_the_encoder_where_l_rec_alone_moves_it() -> None:
    """One SGD step on the whole loss with ``separate`` moves the encoder exactly as one on α·L_rec alone."""
    after = {}
    for which in ("loss", "rec"):
        torch.manual_seed(0)
        config = ModelConfig(image_size=32, pred_frames=3, loss="separate")
        model = build_model(config)
        out = model(*_window(config))
        loss = out.loss if which == "loss" else config.alpha * out.loss_rec
        loss.backward()
        with torch.no_grad():
            for p in model.parameters():
                if p.grad is not None:
                    p -= 0.1 * p.grad
        after[which] = {k: v.clone() for k, v in model.state_dict().items() if k.startswith("encoder.")}
    assert all(torch.equal(after["loss"][k], after["rec"][k]) for k in after["rec"])


def test_pred_only_trains_on_l_pred_alone() -> None:
    torch.manual_seed(0)
    config = ModelConfig(image_size=32, pred_frames=3, loss="pred-only")
    model = build_model(config)
    out = model(*_window(config))
    assert torch.equal(out.loss, out.loss_pred) and out.loss_rec > 0  # L_rec measured, not in the loss
    assert not out.loss_rec.requires_grad
    torch.manual_seed(0)
    joint = build_model(ModelConfig(image_size=32, pred_frames=3))
    out_joint = joint(*_window(config))
    assert torch.equal(out.loss_pred, out_joint.loss_pred) and torch.equal(out.loss_rec, out_joint.loss_rec)
    assert torch.allclose(out_joint.loss, out.loss + config.alpha * out.loss_rec)


def test_mlp_decoder_draws_frames_from_coordinates_of_any_leading_shape() -> None:
    decoder = MLPDecoder(image_size=16, channels=3, n_objects=2, coord_dim=2, hidden=8)
    coords = torch.rand(4, 5, 2, 2) * 16  # (B, T, N, D)
    frames = decoder(coords)
    assert frames.shape == (4, 5, 3, 16, 16) and 0 <= float(frames.min().detach()) and float(frames.max().detach()) <= 1
    assert not torch.equal(frames[0, 0], frames[0, 1])  # the drawing depends on the coordinates
    background = torch.rand(3, 16, 16) * 0.8 + 0.1
    decoder.init_background(background)
    torch.nn.init.zeros_(decoder.net[-1].weight)
    assert torch.allclose(decoder(coords)[2, 3], background, atol=1e-5)


def test_old_configs_are_joint_with_the_st_decoder_and_video_lstm_refuses_what_it_lacks() -> None:
    saved = ModelConfig().to_dict()
    del saved["loss"], saved["decoder"]  # a checkpoint from before the options
    config = ModelConfig.from_dict(saved)
    assert (config.loss, config.decoder) == ("joint", "st")
    assert isinstance(build_model(config).decoder, torch.nn.Module) and build_model(config).has_templates
    with pytest.raises(ValueError, match="video-lstm .* train apart: it takes loss 'joint' or 'pred-only', not 'separate'"):
        ModelConfig(architecture="video-lstm", loss="separate")
    # each refusal names what to leave out: the decoder's did not mention decoders plainly
    with pytest.raises(ValueError, match="decoder 'mlp' does not apply to it"):
        ModelConfig(architecture="video-lstm", decoder="mlp")
    with pytest.raises(ValueError, match="loss"):
        ModelConfig(loss="rec-only")  # type: ignore[arg-type]


@pytest.mark.parametrize(("flag", "value", "other"), [("--loss", "pred-only", "joint"), ("--loss", "separate", "pred-only"),
                                                      ("--decoder", "mlp", "st")])
@pytest.mark.slow
def test_each_option_trains_is_recorded_and_kept_by_resume(flag: str, value: str, other: str, small_data: Path,
                                                           tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    field = flag[2:]
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), flag, value, *SMALL, capsys=capsys)
    assert code in (0, 1, 3) and "epoch 1:" in stdout, err  # two steps: trained, whatever the verdict
    assert ("no autoencoder warm-up" in stdout) == (value == "pred-only")
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics[field] == value and metrics["training"]["steps"] == 2
    assert json.loads((out / "config.json").read_text())["model"][field] == value
    assert torch.load(out / "checkpoint.pt", weights_only=False)["model_config"][field] == value
    assert (out / "templates.png").exists() == (value != "mlp")  # the MLP decoder has no templates to draw

    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", flag, other,
                                  "--epochs", "2", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume", f"({value})", f"drop {flag} {other}")
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", flag, value,
                                  "--batch-size", "16", "--epochs", "2", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume keeps the run's recipe; drop --batch-size")
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--preset", "continuous",
                                  "--epochs", "2", "--quiet", capsys=capsys)  # it was taken, and ignored
    assert_one_line(code, err, "--resume keeps the run's recipe; drop --preset")
    # the starting command's own values may be repeated: that command plus --resume (and more epochs) continues the
    # run, and so may the run's own preset (the default's) be named
    code, stdout, _ = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", flag, value,
                                     "--batch-size", "8", "--warmup-fraction", "0.5", "--epochs", "2", "--quiet",
                                     "--preset", "fast", capsys=capsys)
    assert "epoch 2:" in stdout and json.loads((out / "metrics.json").read_text())["training"]["steps"] == 4


@pytest.mark.slow
def test_resume_refuses_another_preset_and_takes_the_runs_own(small_data: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A run of --preset continuous resumed with --preset fast: the preset was taken and ignored."""
    out = tmp_path / "run"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--preset", "continuous",
                                  "--budget-steps", "2", *SMALL[2:], capsys=capsys)
    assert code in (0, 1, 3), err
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--preset", "fast",
                                  "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume keeps the run's recipe; drop --preset")
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--preset", "continuous",
                                  "--quiet", capsys=capsys)
    assert code in (0, 1, 3) and "Traceback" not in err, err


def test_video_lstm_with_separate_is_refused_in_one_line(small_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(tmp_path / "run"), "--model", "video-lstm",
                                  "--loss", "separate", *SMALL, capsys=capsys)
    assert_one_line(code, err, "video-lstm", "separate")
    assert not (tmp_path / "run" / "checkpoint.pt").exists()
