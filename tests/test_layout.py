"""Dependencies point one way: envs <- piga's core <- agents <- piga.control and piga.cli; reading a run or
diagnosing never loads training code, and no cycle remains.

The rules, checked on every file by its imports (its syntax tree, function-level imports included):

- piga's core (piga.world, piga.data, piga.training, piga.evaluation, piga.diagnostics, piga.io) imports
  neither ``agents`` nor ``piga.control`` nor ``piga.cli``;
- ``agents`` imports neither ``piga.control`` nor ``piga.cli``, and ``piga.training`` only from an agent's
  own trainer (``agents/<agent>/train.py``), which needs the core's training interfaces (``TrainingDiverged``);
  an agent's model, planner and run loader never load training code.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest


_OURS = "('piga', 'envs', 'agents', 'torch')"

#: One interpreter that has loaded torch forks a child per module, which imports it and prints what it loaded: the
#: modules that may load torch, whose import took most of a fresh interpreter's 2-3 s.
_FORKED = f"""
import json, os, sys
import torch  # noqa: F401
for module in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        try:
            __import__(module)
            print(json.dumps([module, [m for m in sys.modules if m.split('.')[0] in {_OURS}]]), flush=True)
        finally:
            os._exit(0)
    os.waitpid(pid, 0)
"""

NEVER = [
    ("piga.io.runs", {"piga.training.train", "piga.diagnostics"}),
    ("piga.diagnostics.diagnose", {"piga.training.train", "agents"}),
    ("piga.diagnostics.report", {"piga.training.train", "agents", "piga.control", "piga.cli"}),
    ("piga.data.schema", {"piga.data.windows"}),
    ("piga.evaluation.episodes", {"agents", "piga.control", "torch"}),
    ("agents.planet.planner", {"piga.training.train", "piga.diagnostics", "piga.control"}),
    ("agents.planet.run", {"piga.training.train", "piga.control"}),
    ("agents.sb3.run", {"piga.training.train", "piga.control"}),
    ("piga.control.registry", {"piga.training.train", "piga.diagnostics"}),
    ("piga.io.checkpoint", {"agents", "piga.world.model", "torch"}),
    ("piga.io.device", {"torch"}),
    ("agents.planet.config", {"torch"}),
]


def _loaded_after(module: str) -> set[str]:
    """The piga/envs/agents (and torch) modules that importing ``module`` in a fresh interpreter loads."""
    code = f"import sys, {module}; print(' '.join(m for m in sys.modules if m.split('.')[0] in {_OURS}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    return set(out.stdout.split())


@pytest.fixture(scope="module")
def loaded_with_torch() -> dict[str, set[str]]:
    """What importing each module that may load torch loads, beside torch (:data:`_FORKED`)."""
    import json

    modules = [module for module, never in NEVER if "torch" not in never]
    out = subprocess.run([sys.executable, "-c", _FORKED, *modules], capture_output=True, text=True, check=True,
                         timeout=300)
    return {module: set(loaded) for module, loaded in map(json.loads, out.stdout.splitlines())}


@pytest.mark.parametrize("module, never", NEVER)
def test_a_module_does_not_load(module: str, never: set[str], request: pytest.FixtureRequest) -> None:
    loaded = _loaded_after(module) if "torch" in never else \
        request.getfixturevalue("loaded_with_torch")[module]  # (a failed import: KeyError)
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


ROOT = Path(__file__).parents[1]
CORE = ("piga/world", "piga/data", "piga/training", "piga/evaluation", "piga/diagnostics", "piga/io")


def _imports(path: Path, root: Path = ROOT) -> set[str]:
    """The modules a file imports, at its top or inside functions (relative imports resolved against its package)."""
    tree = ast.parse(path.read_text())
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    found = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom):
            base = ".".join(package.split(".")[: len(package.split(".")) - n.level + 1]) if n.level else ""
            module = ".".join(p for p in (base, n.module or "") if p)
            found.add(module)
            found |= {f"{module}.{a.name}" for a in n.names}  # ``from piga import control`` imports piga.control
    return found


def _offending(folders: tuple[str, ...], never: tuple[str, ...], allowed: tuple[str, ...] = (),
               root: Path = ROOT) -> dict[str, list[str]]:
    """File -> the imports of ``never`` (or their submodules) in each .py file under ``folders``, but for ``allowed`` files."""
    bad = {}
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            if path.relative_to(root).as_posix() in allowed:
                continue
            hits = sorted(m for m in _imports(path, root) for n in never if m == n or m.startswith(n + "."))
            if hits:
                bad[path.relative_to(root).as_posix()] = hits
    return bad


def test_the_core_imports_neither_agents_nor_the_composition_layer() -> None:
    assert not _offending(CORE, ("agents", "piga.control", "piga.cli"))


def test_agents_import_only_the_core() -> None:
    """agents never reaches up into piga.control or piga.cli; only an agent's own trainer uses piga.training."""
    assert not _offending(("agents",), ("piga.control", "piga.cli"))
    trainers = tuple(p.relative_to(ROOT).as_posix() for p in (ROOT / "agents").glob("*/train.py"))
    assert not _offending(("agents",), ("piga.training",), allowed=trainers)


def test_the_import_rules_catch_a_violation(tmp_path: Path) -> None:
    """The checker sees function-level and ``from package import module`` imports."""
    (tmp_path / "piga" / "io").mkdir(parents=True)
    (tmp_path / "piga" / "io" / "probe.py").write_text("def f():\n    from piga import control\n    import agents.mpc\n")
    (tmp_path / "piga" / "io" / "fine.py").write_text("from piga.io.atomic import write_json\nfrom . import runs\n")
    assert _offending(("piga/io",), ("agents", "piga.control"), root=tmp_path) == {"piga/io/probe.py": ["agents.mpc", "piga.control"]}


def _console_scripts() -> dict[str, str]:
    """pyproject.toml's console scripts: name -> module."""
    import tomllib

    scripts = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["scripts"]
    return {name: target.split(":")[0] for name, target in scripts.items()}


#: Runs each module given as ``python -m`` runs it (``runpy``, as ``__main__``) with ``--help``, in one interpreter
#: (one torch import for all the commands), and prints each one's exit status and first line of help as JSON.
_AS_MAIN = """
import contextlib, io, json, runpy, sys
for module in sys.argv[1:]:
    sys.argv = [module, "--help"]
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            runpy.run_module(module, run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as stop:
        code = stop.code or 0
    print(json.dumps([module, code, out.getvalue().splitlines()[:1]]))
"""


def test_every_command_runs_as_a_module() -> None:
    """``python -m piga.cli.X`` is the same command as its console script (for a checkout without the scripts)."""
    import json

    scripts = _console_scripts()
    out = subprocess.run([sys.executable, "-c", _AS_MAIN, *scripts.values()], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-500:]
    ran = {module: (code, first) for module, code, first in map(json.loads, out.stdout.splitlines())}
    for name, module in scripts.items():
        code, first = ran[module]
        assert code == 0 and first and first[0].startswith(f"usage: {name}"), (name, code, first)
