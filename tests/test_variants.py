"""The baselines of ``piga-train-model --model``: video-lstm and in-ig, trained and judged as piga is."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from piga.cli import train as cli
from piga.training.convergence import check_convergence
from piga.training.train import TrainState
from piga.world.interaction import InteractionNetwork
from piga.world.model import ModelConfig
from piga.world.variants import MODELS, build_model
from tests.helpers import assert_one_line, run_in_process, stateless_pendulum

PROG = "piga-train-model"
#: A run of seconds on ``small_data`` (2 steps): too short to learn, so it ends "untrained" (exit 1) with its files.
SMALL = ("--epochs", "1", "--batch-size", "8", "--warmup-fraction", "0.5", "--quiet", "--threads", "1")


@pytest.fixture(scope="module")
def small_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 pendulum sequences x 15 frames, split 8/1/1, without /states."""
    return stateless_pendulum(tmp_path_factory.mktemp("small") / "small.h5", 10, 15, seed=7, split=(8, 1, 1))


@pytest.mark.parametrize("architecture", ["video-lstm", "in-ig"])
@pytest.mark.slow
def test_a_baseline_trains_is_evaluated_as_piga_and_says_it_has_no_physics(
        architecture: str, small_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code, stdout, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--model", architecture, *SMALL,
                                       capsys=capsys)
    # two steps learn nothing: the check against the background says so, and the files stay
    assert_one_line(code, err, "did not learn to predict", "background alone")
    assert "no physical parameters" in stdout and "epoch 1:" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["model"] == architecture and metrics["converged"] is False
    assert metrics["parameters"] is None and metrics["physical_parameters"] is None
    assert architecture in metrics["physical_parameters_reason"] and "no physical parameters" in metrics["physical_parameters_reason"]
    assert len(metrics["frame_ssim_per_step"]) == len(metrics["frame_mse_per_step"]) == 15 - 4
    assert all(0 < s <= 1 for s in metrics["frame_ssim_per_step"]) and metrics["frame_mse_background"] > 0
    assert json.loads((out / "config.json").read_text())["model"]["architecture"] == architecture
    assert torch.load(out / "checkpoint.pt", weights_only=False)["model_config"]["architecture"] == architecture
    assert (out / "rollout.png").exists() and (out / "curves.png").exists()
    assert (out / "templates.png").exists() == (architecture == "in-ig")  # video-lstm has no objects to draw

    # --resume keeps the run's model, and continues it without --model
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--model", "piga",
                                  "--epochs", "2", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume", f"({architecture})", "drop --model piga")
    code, stdout, _ = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--epochs", "2",
                                     "--quiet", capsys=capsys)
    assert "epoch 2:" in stdout and json.loads((out / "metrics.json").read_text())["training"]["steps"] == 4

    # what needs g and a refuses the run in one line
    from piga.cli.control import main as control_main
    from piga.cli.diagnose import main as diagnose_main

    code, _, err = run_in_process("piga-control", control_main, "--model", str(out), "--episodes", "1", capsys=capsys)
    assert_one_line(code, err, f"--model {architecture} run", "without the physical parameters")
    code, _, err = run_in_process("piga-diagnose", diagnose_main, "--data", str(small_data), "--model", str(out), "--out",
                                  str(tmp_path / "report"), capsys=capsys)
    assert_one_line(code, err, f"--model {architecture} run")
    assert not (tmp_path / "report").exists()


def test_options_of_the_physics_are_refused_for_a_baseline(small_data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(tmp_path / "run"), "--model", "video-lstm",
                                  "--signed-actuation", *SMALL, capsys=capsys)
    assert_one_line(code, err, "--signed-actuation", "video-lstm")
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(tmp_path / "run"), "--model", "lstm",
                                  capsys=capsys)
    assert code == 1 and "invalid choice" in err
    assert not (tmp_path / "run").exists()


def test_a_baseline_is_judged_by_its_predictions_against_the_background() -> None:
    state = TrainState(epoch=2, step=100, history=[{"loss": 1.0, "loss_pred": 1.0, "loss_rec": 0.1}],
                       plan={"epochs": 2, "steps_per_epoch": 50, "warmup_steps": 5})
    good = check_convergence(state, blank=(0.001, 0.003))
    assert good.outcome == "converged" and "below the background" in good.reason
    assert check_convergence(state, blank=(0.0029, 0.003)).outcome == "untrained"
    short = TrainState(**{**state.__dict__, "step": 60})
    assert check_convergence(short, blank=(0.001, 0.003)).outcome == "unsettled"


@pytest.mark.parametrize("architecture", sorted(MODELS))
@pytest.mark.parametrize("system", ["pendulum", "spring"])
def test_training_and_evaluation_see_the_same_predictions(architecture: str, system: str) -> None:
    """forward (training) and predict_frames (evaluation) predict the same frames, from the input frames only."""
    torch.manual_seed(0)
    scene = system != "pendulum"
    config = ModelConfig(system=system, architecture=architecture, image_size=32, channels=3 if scene else 1,
                         n_objects=2 if scene else 1, dt=0.3 if scene else 0.05, input_frames=4, pred_frames=3,
                         init_background=True)
    model = build_model(config).eval()
    model.set_background(torch.rand(config.channels, 32, 32) * 0.2)
    frames = torch.randint(0, 255, (2, 7, 32, 32, 3) if scene else (2, 7, 32, 32), dtype=torch.uint8)
    actions = torch.randn(2, 7, config.action_dim)
    with torch.no_grad():
        out = model(frames, actions)
        x = out.target[:, :4]  # (B, L, C, H, W)
        pred, coords = model.predict_frames(x, actions[:, : 4 - 1 + 3] if config.action_dim else None, 3)
        future = frames.clone()
        future[:, 4:] = 255 - future[:, 4:]
        changed = model(future, actions)
    assert pred.shape == out.pred.shape == (2, 3, config.channels, 32, 32)
    assert torch.allclose(pred, out.pred, atol=1e-6) and torch.allclose(changed.pred, out.pred, atol=1e-6)
    assert (coords is None) == (architecture == "video-lstm")
    assert torch.isfinite(out.loss) and out.loss_pred > 0


def test_the_video_lstm_is_conditioned_on_the_actions() -> None:
    torch.manual_seed(0)
    model = build_model(ModelConfig(architecture="video-lstm", image_size=32, input_frames=4, pred_frames=3)).eval()
    x = torch.rand(2, 4, 1, 32, 32)
    actions = torch.zeros(2, 6, 1)
    with torch.no_grad():
        still = model.predict_frames(x, actions, 3)[0]
        pushed = model.predict_frames(x, actions + 2.0, 3)[0]
    assert not torch.allclose(still, pushed)


def test_the_interaction_network_is_relational() -> None:
    """Objects are interchangeable (swapping them swaps the prediction), an object does not act on itself, and
    the untrained network moves every object at constant velocity."""
    torch.manual_seed(0)
    net = InteractionNetwork(n_objects=3, coord_dim=2, action_dim=0, dt=0.3, image_size=32)
    p, v = torch.rand(4, 3, 2) * 32, torch.randn(4, 3, 2)
    p1, v1 = net(p, v, None)
    assert torch.allclose(p1, p + 0.3 * v) and torch.allclose(v1, v)  # the update's last layer starts at zero
    for layer in (net.update[-1],):
        torch.nn.init.normal_(layer.weight, std=0.1)
    p1, v1 = net(p, v, None)
    order = torch.tensor([2, 0, 1])
    p2, v2 = net(p[:, order], v[:, order], None)
    assert torch.allclose(p2, p1[:, order], atol=1e-5) and torch.allclose(v2, v1[:, order], atol=1e-5)
    # each object's effects are the sum over the others only: object 0 of two feels object 1, not itself
    pair = InteractionNetwork(n_objects=2, coord_dim=2, action_dim=0, dt=0.3, image_size=32)
    seen: list[torch.Tensor] = []
    pair.update.register_forward_hook(lambda module, inputs, output: seen.append(inputs[0]))
    p, v = torch.rand(1, 2, 2) * 32, torch.randn(1, 2, 2)
    pair(p, v, None)
    s = pair._features(p, v)  # (1, 2, F)
    expected = pair.relation(torch.cat([s[:, 0], s[:, 1], (p[:, 0] - p[:, 1]) / 16], dim=-1))  # (1, E)
    assert torch.allclose(seen[0][:, 0, s.shape[-1]:], expected, atol=1e-6)


def test_the_broadcast_width_sizes_that_decoder_and_only_it(small_data: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    def count(**config: object) -> int:
        model = build_model(ModelConfig(system="spring", n_objects=2, image_size=32, channels=3, decoder="broadcast",
                                        **config))
        return sum(p.numel() for p in model.decoder.convs.parameters())  # the background is per pixel

    assert count(broadcast_width=32) > 3 * count()  # the convolutions between widths grow with its square
    with pytest.raises(ValueError, match="broadcast_width sizes the spatial-broadcast decoder"):
        ModelConfig(decoder="st", broadcast_width=32)
    with pytest.raises(ValueError, match=">= 1"):
        ModelConfig(decoder="broadcast", broadcast_width=0)
    assert " ".join(_field_docs()["broadcast_width"].split()).startswith(cli.BROADCAST_WIDTH_HELP)
    out = tmp_path / "run"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--broadcast-width", "32", *SMALL,
                                  capsys=capsys)
    assert_one_line(code, err, "--broadcast-width sizes", "'st'")
    assert not out.exists()
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--decoder", "broadcast",
                                  "--broadcast-width", str(cli.MAX_BROADCAST_WIDTH + 1), *SMALL, capsys=capsys)
    assert code == 1 and "gigabytes per batch" in err and not out.exists()


def test_a_model_larger_than_the_memory_is_refused_before_it_is_built(small_data: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    from piga.io import resources

    monkeypatch.setattr(resources, "available_memory", lambda: 10**6)  # 1 MB: less than any model's weights
    out = tmp_path / "run"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--model", "video-lstm", *SMALL,
                                  capsys=capsys)
    assert_one_line(code, err, "training on frames of 64x64 needs about", "976.6 KiB is available",
                    "smaller --image-size")
    assert not out.exists()


def _field_docs() -> dict[str, str]:
    """ModelConfig's field docstrings by field name, which the command line's help texts begin with."""
    import ast
    import inspect

    tree = ast.parse(Path(inspect.getsourcefile(ModelConfig)).read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "ModelConfig")
    return {a.target.id: b.value.value for a, b in zip(cls.body, cls.body[1:])
            if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant)}


@pytest.mark.slow
def test_the_video_lstm_scale_sizes_it_and_only_it(small_data: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    def count(**config: object) -> int:
        model = build_model(ModelConfig(architecture="video-lstm", image_size=32, channels=3, **config))
        return sum(p.numel() for p in model.parameters())

    assert count(video_lstm_scale=2) > 3.5 * count()  # wider convolutions, latent and LSTM: about 4x
    with pytest.raises(ValueError, match="video_lstm_scale sizes the video-lstm baseline"):
        ModelConfig(architecture="in-ig", video_lstm_scale=2)
    for bad in (0, 33):
        with pytest.raises(ValueError, match=r"must be in \[1, 32\]"):
            ModelConfig(architecture="video-lstm", video_lstm_scale=bad)
    assert " ".join(_field_docs()["video_lstm_scale"].split()).startswith(cli.VIDEO_LSTM_SCALE_HELP)  # the doc is the help

    out = tmp_path / "run"
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--video-lstm-scale", "2", *SMALL,
                                  capsys=capsys)
    assert_one_line(code, err, "--video-lstm-scale sizes", "'piga'")  # piga has its own sizes
    assert not out.exists()
    code, _, _ = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--model", "video-lstm",
                                "--video-lstm-scale", "2", *SMALL, capsys=capsys)
    assert code == 1 and json.loads((out / "config.json").read_text())["model"]["video_lstm_scale"] == 2  # (2 steps: untrained)
    code, _, err = run_in_process(PROG, cli.main, str(small_data), "--out", str(out), "--resume", "--video-lstm-scale", "1",
                                  "--epochs", "2", "--quiet", capsys=capsys)
    assert_one_line(code, err, "--resume", "drop --video-lstm-scale 1")
