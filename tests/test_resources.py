"""Sizes in messages: a need and what is there never read the same."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from piga.io.resources import ResourceError, check_disk, format_apart


def test_a_need_and_a_free_space_that_round_alike_are_given_in_bytes() -> None:
    assert format_apart(1.33 * 2**20, 1.0 * 2**20) == ("1.3 MiB", "1.0 MiB")
    assert format_apart(1_364_000, 1_331_200) == ("1,364,000 B", "1,331,200 B")


def test_a_disk_refusal_does_not_read_as_if_it_fitted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 1300 KiB disk: "needs up to 1.3 MiB ... but tfs has 1.3 MiB free"."""
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real(path)._replace(free=1_331_200))
    with pytest.raises(ResourceError, match=r"needs up to 1,364,000 B of disk, but .* has 1,331,200 B free; ask"):
        check_disk(tmp_path / "a.h5", 1_364_000, "the file", bound="up to")
