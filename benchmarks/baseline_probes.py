"""Probes of what a DDPG or SAC baseline was given and what it learned (the numbers in results/ddpg_tuning.md).

- ``autoencoder RUN DATA.h5``: the autoencoder of a ``piga-baseline ddpg --obs latent`` run, on DATA's
  test split: reconstruction MSE against the pixel variance (drawing the mean frame scores about the
  variance), the codes' spread per dimension, and how well (cos θ, sin θ) can be read off a code by
  its 5 nearest neighbours (fitted on half the test frames, scored on the other half). States are
  read for this evaluation only.
- ``actor RUN DATA.h5``: the policy of a ``--obs pixels`` run on stacks of 4 consecutive frames of
  DATA's first 50 sequences: its actions, the actor's pre-tanh output (DDPG's; SAC's Gaussian mean
  before the squash; saturated when far beyond ±3), the spread of the actor's CNN features over frames, and the critic's Q.

    python benchmarks/baseline_probes.py autoencoder results/baselines_runs/ddpg-latent-s0 results/baselines_runs/data-n2000.h5
    python benchmarks/baseline_probes.py actor results/baselines_runs/ddpg-pixels-s0 results/baselines_runs/data-n500.h5
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch
from piga.cli.common import ArgumentParser, PigaError


def knn_rmse(train_x: torch.Tensor, train_y: torch.Tensor, test_x: torch.Tensor, test_y: torch.Tensor, k: int = 5) -> list[float]:
    """RMSE per target column of a k-nearest-neighbour mean regression. (A cdist and a topk: scikit-learn
    is only an optional extra of piga, and this is all of it that the probe needs.)"""
    nearest = torch.cdist(test_x, train_x).topk(k, largest=False).indices  # (M, k)
    predicted = train_y[nearest].mean(1)  # (M, C)
    return ((predicted - test_y) ** 2).mean(0).sqrt().tolist()


def probe_autoencoder(run: Path, data: Path) -> dict[str, object]:
    from agents.sb3.autoencoder import load_autoencoder
    from piga.data.schema import load_states, read_sequences

    model = load_autoencoder(run / "autoencoder.pt")
    frames, _ = read_sequences(data, "test")  # (N, T, 64, 64) uint8
    states = load_states(data, "test")  # (N, T, 2): (θ, θ̇), for this evaluation only
    x = torch.from_numpy(frames.reshape(-1, 1, 64, 64)).float() / 255.0
    with torch.inference_mode():
        codes = torch.cat([model.encode(b) for b in x.split(1000)])  # (N·T, Z)
        mse = float(sum(((model(b) - b) ** 2).sum() for b in x.split(1000)) / x.numel())
    theta = torch.from_numpy(states.reshape(-1, states.shape[-1])[:, 0]).float()
    target = torch.stack([theta.cos(), theta.sin()], 1)  # (N·T, 2)
    half = len(codes) // 2
    return {"frames": len(codes), "reconstruction_mse": mse, "pixel_variance": float(x.var()),
            "code_std": codes.std(0).tolist(), "code_saturated_fraction": float((codes.abs() > 0.99).float().mean()),
            "knn5_rmse_cos_sin": knn_rmse(codes[:half], target[:half], codes[half:], target[half:])}


def probe_actor(run: Path, data: Path) -> dict[str, object]:
    import h5py

    from agents.sb3.run import load_sb3

    model, config, _ = load_sb3(run)
    if config.obs != "pixels":
        raise PigaError(f"{run}: a --obs {config.obs} run; the actor probe is for pixel runs")
    with h5py.File(data, "r") as f:
        obs = f["frames"][:50, 4:4 + config.frame_stack]  # (50, K, 64, 64) uint8
    actions, _ = model.predict(obs, deterministic=True)
    with torch.no_grad():
        o = torch.as_tensor(obs).float()
        features = model.actor.extract_features(o, model.actor.features_extractor)  # (50, F), SB3 scales the pixels
        if isinstance(model.actor.mu, torch.nn.Sequential):  # DDPG (TD3's actor): its layers, then a tanh
            pre_tanh = model.actor.mu[:-1](features)[:, 0]
        else:  # SAC: the squashed Gaussian's mean, before its tanh, as SB3's actor computes it
            pre_tanh = model.actor.get_action_dist_params(o)[0][:, 0]
        q = model.critic(o, torch.as_tensor(actions).float())[0][:, 0]
    return {"actions": np.asarray(actions)[:, 0].tolist(), "pre_tanh_min": float(pre_tanh.min()),
            "pre_tanh_max": float(pre_tanh.max()), "feature_std_over_frames": float(features.std(0).mean()),
            "feature_mean_abs": float(features.abs().mean()), "q_std_over_frames": float(q.std())}


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=("autoencoder", "actor"))
    p.add_argument("run", type=Path, help="a piga-baseline ddpg run folder")
    p.add_argument("data", type=Path, help="a piga-collect file")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    result = (probe_autoencoder if args.what == "autoencoder" else probe_actor)(args.run, args.data)
    json.dump(result, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
