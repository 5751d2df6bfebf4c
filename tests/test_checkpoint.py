"""A run folder's kind and its one checkpoint: the payloads keep the keys they had (so runs written before
still load), and reading names what it found."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint, require_piga_run, run_kind, write_checkpoint
from tests.helpers import train_tiny

#: The keys of each kind's checkpoint as runs wrote them before the checkpoint module (recorded from such runs),
#: plus the keys added since, which readers take as optional (PlaNet-style: ``best_model``, the weights of the
#: lowest valid loss).
PAYLOAD_KEYS = {
    RunKind.PIGA: ["data", "model", "model_config", "optimizer", "plan", "rng", "state", "train_config"],
    RunKind.PLANET: ["best_model", "data", "kind", "model", "optimizer", "rng", "rssm_config", "state", "train_config"],
    # (the replay buffer's bytes were in it, "replay_buffer", until they moved to a file of their own: such
    # checkpoints still resume, tests/test_ddpg.py)
    RunKind.DDPG: ["config", "elapsed", "episodes", "history", "kind", "model_zip", "replay_buffer_file", "rng"],
}


@pytest.fixture(scope="module")
def runs(tiny_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[RunKind, Path]:
    from agents.planet.config import PlanetTrainConfig, RSSMConfig
    from agents.planet.train import train_planet
    from agents.sb3.config import SB3Config
    from agents.sb3.train import train_sb3

    folder = tmp_path_factory.mktemp("kinds")
    train_tiny(tiny_data, folder / "piga")
    train_planet(tiny_data, folder / "planet", PlanetTrainConfig(steps=2, batch_size=2, chunk_length=4, checkpoint_every=2, threads=1),
                 RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16), progress=False)
    train_sb3(SB3Config(steps=200, learning_starts=100, eval_every=200, eval_episodes=1, batch_size=16, net_arch=(8,), buffer_size=300),
              folder / "ddpg", progress=False)
    for kind in (RunKind.PLANET, RunKind.DDPG):  # as piga-baseline records it
        (folder / kind.value / "config.json").write_text(json.dumps({"kind": kind.value}))
    return {RunKind.PIGA: folder / "piga", RunKind.PLANET: folder / "planet", RunKind.DDPG: folder / "ddpg"}


@pytest.mark.parametrize("kind", list(RunKind))
def test_each_kind_writes_the_payload_it_wrote_before(kind: RunKind, runs: dict[RunKind, Path]) -> None:
    payload = read_checkpoint(runs[kind], kind)
    assert sorted(payload) == PAYLOAD_KEYS[kind]
    assert run_kind(runs[kind]) is kind


def test_reading_names_what_it_found(runs: dict[RunKind, Path], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=f"{runs[RunKind.DDPG] / CHECKPOINT} is a piga-baseline ddpg checkpoint, not a "
                                         "piga-baseline planet run"):
        read_checkpoint(runs[RunKind.DDPG], RunKind.PLANET)
    with pytest.raises(ValueError, match="is a piga-train-model checkpoint, not a piga-baseline ddpg run"):
        read_checkpoint(runs[RunKind.PIGA], RunKind.DDPG)
    with pytest.raises(FileNotFoundError, match=r"no checkpoint \(is .* a piga-baseline planet run folder\?\)"):
        read_checkpoint(tmp_path, RunKind.PLANET)
    (tmp_path / CHECKPOINT).write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="not a readable PlaNet-style checkpoint .* truncated"):
        read_checkpoint(tmp_path, RunKind.PLANET)
    with pytest.raises(ValueError, match="is a piga-baseline planet run; piga-diagnose diagnoses"):
        require_piga_run(runs[RunKind.PLANET], "piga-diagnose diagnoses the identified physics")


def test_a_write_is_atomic_and_reads_back(tmp_path: Path) -> None:
    path = write_checkpoint(tmp_path, {"kind": "planet", "x": torch.arange(3)})
    assert path == tmp_path / CHECKPOINT and [p.name for p in tmp_path.iterdir()] == [CHECKPOINT]
    assert torch.equal(read_checkpoint(tmp_path, RunKind.PLANET)["x"], torch.arange(3))


def test_an_unknown_kind_is_named(tmp_path: Path) -> None:
    (tmp_path / "config.json").write_text(json.dumps({"kind": "dreamer"}))
    with pytest.raises(ValueError, match="config.json: unknown run kind 'dreamer'; known: piga, planet, ddpg"):
        run_kind(tmp_path)
    assert run_kind(tmp_path / "missing") is RunKind.PIGA  # loading the piga model then says what is missing
