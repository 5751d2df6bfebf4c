"""A full disk, for real: every command that writes refuses up front with one line, and leaves nothing behind.

The disk is a tmpfs of 1 MiB mounted for the test, which needs root (or CAP_SYS_ADMIN); elsewhere the
tests skip. Opt-in (``-m slow``): each case runs a command in a fresh process.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.helpers import assert_one_line_error, run, train_tiny

pytestmark = pytest.mark.slow


@pytest.fixture
def full_disk(tmp_path: Path):  # noqa: ANN201
    """A 1 MiB tmpfs, unmounted after the test."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)], capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {done.stderr.strip() or 'mount failed'}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], capture_output=True)


#: (command, options with {data}, {run} and {disk}); each needs more than 1 MiB.
CASES = {
    "collect": ("piga-collect", "--out {disk}/x.h5 --sequences 200 --workers 1 --quiet"),
    "train-model": ("piga-train-model", "{data} --out {disk}/run --epochs 1 --batch-size 4 --threads 1 --quiet"),
    "planet": ("piga-baseline", "planet {data} --out {disk}/planet --steps 2 --chunk-length 8 --threads 1 --quiet"),
    "ddpg": ("piga-baseline", "ddpg --obs state --out {disk}/ddpg --steps 400 --eval-every 200 --learning-starts 100 "
                              "--threads 1 --quiet"),
    "control video": ("piga-control", "--model {run} --video {disk}/v.mp4 --episodes 1 --quiet"),
    "control gif": ("piga-control", "--model {run} --video {disk}/v.gif --episodes 1 --steps 20 --quiet"),  # ~0.9 MB
    "demo": ("piga-demo", "--out {disk}/demo --threads 1 --quiet"),
    "show": ("piga-show", "{data} --out {disk}/strip.pdf"),
    "diagnose": ("piga-diagnose", "--model {run} --data {data} --out {disk}/diagnosis --threads 1 --quiet"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_full_disk_is_refused_up_front_and_leaves_nothing(case: str, full_disk: Path, tiny_data: Path,
                                                            tmp_path: Path) -> None:
    prog, options = CASES[case]
    model = train_tiny(tiny_data, tmp_path / "model") if "{run}" in options else None
    args = options.format(data=tiny_data, run=model, disk=full_disk).split()
    result = run(prog, *args)
    assert_one_line_error(result, "disk", "free")
    assert result.returncode == 1
    assert sorted(p.name for p in full_disk.iterdir()) == [], "a refused run left files behind"
