"""benchmarks/camera_stage_time.py: a real (tiny) run and file; the stage itself is a stand-in (the diagnosis's tests
test it), so what is tested is what the script gives it and prints."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import h5py
import pytest

from tests.helpers import benchmark_module


def test_it_gives_the_stage_the_fit_split_and_prints_its_time_and_camera(
        tiny_data: Path, tiny_run: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import piga.diagnostics.vision as vision

    calls = []

    def stage(model, path, theta, fit, stale):  # noqa: ANN001, ANN202
        calls.append((path, theta.shape, fit.tolist(), stale))
        return SimpleNamespace(camera=vision.Camera(blur=0.5))

    monkeypatch.setattr(vision, "camera_stage", stage)
    run = tiny_run  # read, not written
    capsys.readouterr()
    with benchmark_module("camera_stage_time") as bench:
        assert bench.main([str(run), str(tiny_data)]) == 0
    with h5py.File(tiny_data) as f:
        n, t = f["frames"].shape[:2]
    (path, shape, fit, stale), = calls
    assert path == str(tiny_data) and shape == (n, t) and stale is None
    assert fit == [i < int(0.75 * n) for i in range(n)]
    out = capsys.readouterr().out
    assert out.startswith("camera stage: ")
    assert out.rstrip().endswith("camera Camera(blur=0.5, dx=0.0, dy=0.0, exposure=1.0, zoom=1.0)")
