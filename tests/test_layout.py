"""Dependencies point one way: reading a run or diagnosing never loads training code, and no cycle remains."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest


def _loaded_after(module: str) -> set[str]:
    """The piga/envs/agents modules that importing ``module`` in a fresh interpreter loads."""
    code = f"import sys, {module}; print(' '.join(m for m in sys.modules if m.split('.')[0] in ('piga', 'envs', 'agents')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    return set(out.stdout.split())


@pytest.mark.parametrize("module, never", [
    ("piga.io.runs", {"piga.training.train", "piga.diagnostics"}),
    ("piga.diagnostics.diagnose", {"piga.training.train", "agents"}),
    ("piga.diagnostics.report", {"piga.training.train", "agents"}),
    ("piga.data.schema", {"piga.data.windows"}),
    ("agents.planet.planner", {"piga.training.train", "piga.diagnostics", "piga.baselines"}),
    ("piga.baselines.agents", {"piga.training.train", "piga.diagnostics"}),
    ("piga.baselines.kinds", {"agents", "piga.world.model"}),
])
def test_a_module_does_not_load(module: str, never: set[str]) -> None:
    loaded = _loaded_after(module)
    assert not {m for m in loaded for n in never if m == n or m.startswith(n + ".")}, loaded


@pytest.mark.parametrize("path, never", [
    ("envs/constants.py", {"envs"}),
    ("envs/effects.py", {"envs.pendulum"}),
])
def test_the_env_modules_import_one_way(path: str, never: set[str]) -> None:
    """envs.pendulum imports envs.effects, which takes Pendulum-v1's constants from envs.constants (no cycle)."""
    tree = ast.parse((Path(__file__).parents[1] / path).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in imported for n in never if m == n or m.startswith(n + ".")}, imported


def test_envs_import_only_the_torch_free_effect_terms_of_piga() -> None:
    """envs builds its effect wrappers from piga.world.effects, the one module of piga it may import: it is
    torch-free, so making an environment never loads the model."""
    root = Path(__file__).parents[1]
    for path in sorted((root / "envs").glob("*.py")):
        tree = ast.parse(path.read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        piga = {m for m in imported if m == "piga" or m.startswith("piga.")}
        assert piga <= {"piga.world.effects"}, (path.name, piga)
    code = "import sys, envs.effects, envs.pendulum; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    loaded = set(out.stdout.split())
    assert "torch" not in loaded and {m for m in loaded if m.startswith("piga.")} == {"piga.world", "piga.world.effects"}


def _console_scripts() -> dict[str, str]:
    """pyproject.toml's console scripts: name -> module."""
    import tomllib

    scripts = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["scripts"]
    return {name: target.split(":")[0] for name, target in scripts.items()}


@pytest.mark.parametrize("name", sorted(_console_scripts()))
def test_every_command_runs_as_a_module(name: str) -> None:
    """``python -m piga.cli.X`` is the same command as its console script (for a checkout without the scripts)."""
    out = subprocess.run([sys.executable, "-m", _console_scripts()[name], "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith(f"usage: {name}"), out.stderr[-500:]
