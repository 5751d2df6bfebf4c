"""``--device``: the choice and its errors, checkpoints saved on a GPU read and resumed on the CPU, and
(on a machine with a GPU only) training there."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any
from unittest import mock

import pytest
import torch

from piga.cli import baseline
from piga.cli import train as train_cli
from piga.io import device as device_module
from piga.io.checkpoint import CHECKPOINT
from piga.io.device import cuda_available, resolve_device
from tests.helpers import assert_one_line, assert_planet_run_finished, assert_sb3_run_finished, run_in_process, train_tiny

TINY_PLANET = ("--steps", "2", "--batch-size", "2", "--chunk-length", "8", "--deter-size", "8", "--stoch-size", "4",
               "--threads", "1", "--quiet")
TINY_DDPG = ("--steps", "200", "--eval-every", "200", "--eval-episodes", "1", "--learning-starts", "100", "--quiet",
             "--batch-size", "16", "--buffer-size", "300")
NO_GPU = "no CUDA device is available (torch.cuda.is_available() is False); use --device cpu or auto"
needs_gpu = pytest.mark.skipif(not cuda_available(), reason="needs a CUDA GPU (torch.cuda.is_available() is False)")


@pytest.fixture
def no_gpu(monkeypatch: pytest.MonkeyPatch) -> None:
    """A machine where torch sees no CUDA device, whatever this one has."""
    monkeypatch.setattr(device_module, "cuda_available", lambda: False)


def test_the_choices_resolve(no_gpu: None) -> None:
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto") == torch.device("cpu")
    with pytest.raises(ValueError, match=r"^--device cuda: no CUDA device is available"):
        resolve_device("cuda")
    with pytest.raises(ValueError, match="--device must be one of auto, cpu, cuda; got 'tpu'"):
        resolve_device("tpu")


def test_auto_says_nothing_where_torch_warns_about_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    def warning_check() -> bool:  # a CUDA build of torch on a machine without a driver
        warnings.warn("CUDA initialization: Found no NVIDIA driver on your system", UserWarning, stacklevel=2)
        return False

    monkeypatch.setattr(torch.cuda, "is_available", warning_check)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert resolve_device("auto") == torch.device("cpu")
    assert not caught, [str(w.message) for w in caught]


def test_the_configs_refuse_an_unknown_device() -> None:
    from agents.planet.config import PlanetTrainConfig
    from agents.sb3.config import SB3Config
    from piga.training.train import TrainConfig

    for config in (TrainConfig, PlanetTrainConfig, SB3Config):
        with pytest.raises(ValueError, match=r"\.device must be one of 'auto', 'cpu', 'cuda'; got 'gpu'"):
            config(device="gpu")  # type: ignore[arg-type]


@pytest.mark.parametrize("prog, main, argv", [
    ("piga-train-model", train_cli.main, ("{data}", "--out", "{out}")),
    ("piga-baseline", baseline.main, ("planet", "{data}", "--out", "{out}")),
    ("piga-baseline", baseline.main, ("ddpg", "--obs", "state", "--out", "{out}")),
])
def test_device_errors_get_one_line(prog: str, main: Any, argv: tuple[str, ...], tiny_data: Path, tmp_path: Path,
                                    no_gpu: None, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    args = [a.format(data=tiny_data, out=out) for a in argv]
    code, _, err = run_in_process(prog, main, *args, "--device", "cuda", capsys=capsys)
    assert code == 1
    assert_one_line(code, err, f"{prog}: error: --device cuda: {NO_GPU}")
    code, _, err = run_in_process(prog, main, *args, "--device", "tpu", capsys=capsys)
    assert code == 1
    assert_one_line(code, err, "--device: invalid choice: 'tpu'")
    assert not out.exists()


def as_if_saved_on_a_gpu(run_dir: Path, **changes: dict[str, Any]) -> None:
    """Saves ``run_dir``'s checkpoint again as a GPU run would: every tensor's storage tagged "cuda:0", so that
    torch.load without a map_location fails on a machine without a GPU. ``changes``: entries to update."""
    path = run_dir / CHECKPOINT
    payload = torch.load(path, map_location="cpu", weights_only=False)
    for key, values in changes.items():
        payload[key].update(values)
    with mock.patch.object(torch.serialization, "location_tag", lambda storage: "cuda:0"):
        torch.save(payload, path)
    if not cuda_available():  # the tag is real: read as it is, the file needs a GPU
        with pytest.raises(RuntimeError, match="CUDA"):
            torch.load(path, weights_only=False)


@pytest.mark.slow
def test_a_model_trained_on_a_gpu_loads_and_resumes_on_the_cpu(tiny_data: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    from piga.io.runs import load_model

    run_dir = train_tiny(tiny_data, tmp_path / "run", device="cpu")
    saved = load_model(run_dir)[0].state_dict()
    as_if_saved_on_a_gpu(run_dir, train_config={"device": "cuda"}, state={"device": "cuda:0"})
    model, ckpt = load_model(run_dir)
    assert all(t.device.type == "cpu" and torch.equal(t, saved[k]) for k, t in model.state_dict().items())
    code, out, err = run_in_process("piga-train-model", train_cli.main, str(tiny_data), "--out", str(run_dir),
                                    "--resume", "--epochs", "2", "--device", "cpu", "--quiet", capsys=capsys)
    assert code in (0, 3), err  # 3: too short to be judged converged
    assert "(device cpu)" in out and "epoch 2:" in out
    assert json.loads((run_dir / "metrics.json").read_text())["training"]["device"] == "cpu"
    assert load_model(run_dir)[1]["train_config"]["device"] == "cpu"


def test_a_planet_run_trained_on_a_gpu_resumes_on_the_cpu(tiny_data: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    from agents.planet.run import load_planet

    run_dir = tmp_path / "planet"
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run_dir),
                                  *TINY_PLANET, "--device", "cpu", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((run_dir / "metrics.json").read_text())["device"] == "cpu"
    as_if_saved_on_a_gpu(run_dir)
    record = json.loads((run_dir / "config.json").read_text())
    (run_dir / "config.json").write_text(json.dumps({**record, "train": {**record["train"], "device": "cuda"}}))
    assert next(load_planet(run_dir)[0].parameters()).device.type == "cpu"
    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out", str(run_dir),
                                  "--resume", "--steps", "3", "--device", "cpu", "--quiet", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((run_dir / "config.json").read_text())["train"]["device"] == "cpu"
    assert json.loads((run_dir / "metrics.json").read_text())["steps"] == 3


@pytest.mark.slow
def test_a_baseline_run_from_before_the_device_option_resumes(tiny_data: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    run_dir = tmp_path / "ddpg"
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(run_dir),
                                  *TINY_DDPG, capsys=capsys)
    assert_sb3_run_finished(code, err)
    record = json.loads((run_dir / "config.json").read_text())
    assert record["ddpg"].pop("device") == "auto"
    (run_dir / "config.json").write_text(json.dumps(record))  # as a run recorded before --device
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "state", "--out", str(run_dir),
                                  "--resume", "--steps", "400", "--device", "cpu", "--quiet", capsys=capsys)
    assert_sb3_run_finished(code, err)  # a run that did not learn resumes; it says again whether it learned
    if code:
        assert "never reached -200 in 400 env steps" in err
    assert json.loads((run_dir / "metrics.json").read_text())["steps"] == 400
    assert json.loads((run_dir / "config.json").read_text())["ddpg"]["device"] == "cpu"


@needs_gpu
def test_training_on_the_gpu_loads_and_resumes_on_the_cpu(tiny_data: Path, tmp_path: Path) -> None:
    from piga.io.runs import load_model
    from piga.training.train import TrainConfig, train
    from piga.world.model import ModelConfig

    run_dir = train_tiny(tiny_data, tmp_path / "gpu", device="cuda")
    model, ckpt = load_model(run_dir)
    assert ckpt["state"]["device"].startswith("cuda") and next(model.parameters()).device.type == "cpu"
    assert all(torch.isfinite(t).all() for t in model.state_dict().values())
    config = TrainConfig.from_dict({**ckpt["train_config"], "epochs": 2, "device": "cpu"})
    resumed, state = train(tiny_data, run_dir, config, ModelConfig(), resume=True, progress=False)
    assert state.epoch == 2 and state.device == "cpu"
    # the same run on the CPU starts from the same weights and draws the same batches: its first epoch's loss
    # differs by the kernels' rounding only (cuDNN may convolve in TF32 by default)
    cpu = train_tiny(tiny_data, tmp_path / "cpu", device="cpu")
    gpu_loss = load_model(run_dir)[1]["state"]["history"][0]["loss"]
    cpu_loss = load_model(cpu)[1]["state"]["history"][0]["loss"]
    assert abs(gpu_loss - cpu_loss) < 1e-2 * cpu_loss, (gpu_loss, cpu_loss)


@needs_gpu
def test_the_baselines_train_on_the_gpu_and_load_on_the_cpu(tiny_data: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    from agents.planet.run import load_planet
    from agents.sb3.run import load_sb3

    code, _, err = run_in_process("piga-baseline", baseline.main, "planet", str(tiny_data), "--out",
                                  str(tmp_path / "p"), *TINY_PLANET, "--device", "cuda", capsys=capsys)
    assert_planet_run_finished(code, err)
    assert json.loads((tmp_path / "p" / "metrics.json").read_text())["device"].startswith("cuda")
    assert next(load_planet(tmp_path / "p")[0].parameters()).device.type == "cpu"
    code, _, err = run_in_process("piga-baseline", baseline.main, "ddpg", "--obs", "latent", "--data", str(tiny_data),
                                  "--autoencoder-steps", "5", "--out", str(tmp_path / "d"), *TINY_DDPG,
                                  "--device", "cuda", capsys=capsys)
    assert_sb3_run_finished(code, err)
    model, _, encoder = load_sb3(tmp_path / "d")
    assert model.device.type == "cpu" and next(encoder.parameters()).device.type == "cpu"
    assert json.loads((tmp_path / "d" / "metrics.json").read_text())["device"].startswith("cuda")
