"""The public API of ``import piga``: cheap to import, every name resolves, and the examples run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import piga

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "SDL_VIDEODRIVER": "dummy",
       "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}


def test_import_piga_loads_neither_torch_nor_the_modules() -> None:
    code = "import sys, piga; print(' '.join(m for m in sys.modules if m.split('.')[0] in ('torch', 'piga', 'envs', 'h5py')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120, env=ENV)
    assert out.stdout.split() == ["piga"], out.stdout


@pytest.mark.parametrize("name", sorted(set(piga.__all__) - {"__version__"}))
def test_every_public_name_resolves(name: str) -> None:
    value = getattr(piga, name)
    assert getattr(value, "__name__", name) == name and name in dir(piga)


def test_submodules_are_attributes_and_a_wrong_name_is_an_attribute_error() -> None:
    import piga.data.schema

    assert piga.data.schema.inspect_dataset is piga.inspect_dataset
    assert piga.data.collect.collect is not None  # a submodule, imported on first use
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        piga.no_such_name  # noqa: B018


def test_the_version_is_the_package_version() -> None:
    import tomllib

    assert piga.__version__ == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_the_example_and_the_readme_snippet_run(tmp_path: Path) -> None:
    """examples/identify_pendulum.py on tiny settings, then the README's snippet on its outputs."""
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "identify_pendulum.py"), "--out", str(tmp_path),
                          "--sequences", "12", "--epochs", "1"], capture_output=True, text=True, timeout=300, env=ENV)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "learned:" in out.stdout and "true:" in out.stdout
    snippet = re.search(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.DOTALL).group(1)
    snippet = snippet.replace('"demo/model"', repr(str(tmp_path / "run"))).replace('"demo/pendulum.h5"', repr(str(tmp_path / "pendulum.h5")))
    out = subprocess.run([sys.executable, "-c", snippet], capture_output=True, text=True, timeout=300, env=ENV)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "'g':" in out.stdout


def test_the_data_pages_example_writes_a_valid_file(tmp_path: Path) -> None:
    """docs/data.md's h5py example: a file written by hand is a valid piga file."""
    block = re.search(r"```python\n(.*?)```", (ROOT / "docs" / "data.md").read_text(), re.DOTALL).group(1)
    out = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, timeout=120, env=ENV, cwd=tmp_path)
    assert out.returncode == 0 and "n_sequences=3" in out.stdout, out.stderr[-2000:]


def test_a_run_trained_through_the_library_is_not_called_interrupted(tmp_path: Path) -> None:
    """piga.train writes no metrics.json: every such run was "stopped before its end ... continue it with --resume"."""
    from piga.io.runs import convergence_warning

    (tmp_path / "checkpoint.pt").write_bytes(b"")
    assert "piga.write_run_report" in convergence_warning(tmp_path) and "--resume" not in convergence_warning(tmp_path)
    (tmp_path / "config.json").write_text("{}")  # piga-train-model's record: a CLI run cut before its report
    assert "stopped before its end" in convergence_warning(tmp_path)
