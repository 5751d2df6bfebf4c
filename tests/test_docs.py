"""The command reference (docs/commands/) against the parsers: every option documented, every documented default the code's."""

from __future__ import annotations

import argparse
import importlib
import math
import re
from pathlib import Path
from typing import Any

import pytest

from piga.cli.common import documented_default

DOCS = Path(__file__).resolve().parents[1] / "docs"

#: Command -> its CLI module (each has ``build_parser()``).
COMMANDS = {
    "piga-collect": "piga.cli.collect",
    "piga-show": "piga.cli.show",
    "piga-train-model": "piga.cli.train",
    "piga-control": "piga.cli.control",
    "piga-demo": "piga.cli.demo",
    "piga-diagnose": "piga.cli.diagnose",
    "piga-import": "piga.cli.importer",
    "piga-baseline planet": "piga.cli.baseline:planet",
    "piga-baseline ddpg": "piga.cli.baseline:ddpg",
}

#: Command -> its page in docs/commands/.
PAGES = {
    "piga-collect": "collect.md",
    "piga-show": "show.md",
    "piga-train-model": "train-model.md",
    "piga-control": "control.md",
    "piga-demo": "demo.md",
    "piga-diagnose": "diagnose.md",
    "piga-import": "import.md",
    "piga-baseline planet": "baseline.md",
    "piga-baseline ddpg": "baseline.md",
}


def build_parser(command: str) -> argparse.ArgumentParser:
    """The parser of a command, or of its subcommand ("module:subcommand")."""
    module, _, sub = COMMANDS[command].partition(":")
    parser = importlib.import_module(module).build_parser()
    if not sub:
        return parser
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return subparsers.choices[sub]

#: Words the reference uses for a default, and the values they stand for.
WORDS: dict[str, tuple[Any, ...]] = {
    "off": (False, None),
    "on": (True,),
    "none": (None, 0, 0.0),
    "torch's": (0,),
    "from the data": (0,),
    "π": (math.pi,),
}


def option_rows(text: str) -> dict[str, list[tuple[list[str], list[str], str]]]:
    """Command -> rows (options, documented defaults, the row) of the option tables in its section of ``text``.

    A section starts at a heading that names the command in backticks (``# `piga-collect ...` ``).

    A table with a ``default`` column gives its cell, split at ", " into one default per option.
    In a table without one, a row whose text holds "(default A, B, ...)" with one value per
    option gives those; other rows document no default.
    """
    rows: dict[str, list[tuple[list[str], list[str], str]]] = {}
    command = None
    header: list[str] = []
    for line in text.splitlines():
        heading = re.match(r"#+ .*`(piga-[a-z-]+)( [a-z]+)?", line)
        if heading:
            named = "".join(g or "" for g in heading.groups())
            command = named if named in COMMANDS else heading.group(1) if heading.group(1) in COMMANDS else None
            header = []
            continue
        if command is None or not line.startswith("|"):
            header = [] if not line.startswith("|") else header
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not header:
            header = [c.lower() for c in cells]
            continue
        if set(line) <= set("|-: ") or "option" not in header[0]:
            continue
        options = re.findall(r"`(--[a-z][a-z0-9-]*)", cells[0])
        if not options:
            continue
        if "default" in header:
            cell = cells[header.index("default")]
            defaults = [] if not cell else [cell] if len(options) == 1 else [d.strip() for d in cell.split(", ")]
        else:
            found = re.search(r"\(default ([^;)]*)", " ".join(cells[1:]))
            defaults = [d.strip() for d in found.group(1).split(", ")] if found else []
            if len(defaults) != len(options):
                continue
        if defaults:
            rows.setdefault(command, []).append((options, defaults, line))
    return rows


def help_default(action: argparse.Action) -> str | None:
    """The default that an option's help text names, "(default X)" or "(default X; ...)", if any."""
    found = re.search(r"\(default:? ([^;)]*)", (action.help or "").replace("\n", " "))
    if not found:
        return None
    return found.group(1).replace("%(default)s", str(action.default)).strip()


def code_default(action: argparse.Action) -> Any:
    """The parser's default; for an option whose default is decided later (None), the one its help names."""
    value = documented_default(action)
    return help_default(action) if value is None and help_default(action) is not None else value


def matches(documented: str, action: argparse.Action) -> bool:
    """Whether the reference's text for a default is the parser's default."""
    value = code_default(action)
    text = documented.strip("`")
    if isinstance(value, str) and action.choices is None:  # a default known only from the help text
        try:
            return math.isclose(float(text), float(value))
        except ValueError:
            return text == value
    if text.lower() in WORDS:
        return any(value == w and type(value) is not bool or value is w for w in WORDS[text.lower()])
    if action.choices is not None and text in action.choices:
        return text == value
    try:
        numbers = [float(x) for x in text.split(",")]
    except ValueError:
        return text == str(value)
    if isinstance(value, (tuple, list)):
        return len(numbers) == len(value) and all(math.isclose(a, float(b)) for a, b in zip(numbers, value))
    return len(numbers) == 1 and value is not None and not isinstance(value, bool) and math.isclose(numbers[0], float(value))


def reference_text() -> str:
    """The command pages, each starting with its command's heading."""
    return "\n\n".join((DOCS / "commands" / page).read_text() for page in sorted(set(PAGES.values())))


ROWS = option_rows(reference_text())


def test_the_reference_documents_defaults_of_the_main_commands() -> None:
    # guards the parser of the tables: it must find the rows it is meant to check
    assert {"piga-collect", "piga-train-model"} <= set(ROWS)
    assert sum(len(r) for r in ROWS.values()) >= 15


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_reference_defaults_match_the_parser(command: str) -> None:
    parser = build_parser(command)
    actions = {flag: a for a in parser._actions for flag in a.option_strings}
    wrong = []
    for options, defaults, line in ROWS.get(command, []):
        assert len(options) == len(defaults), f"docs/commands/{PAGES[command]}: a row lists {len(options)} options but {len(defaults)} defaults: {line}"
        for option, documented in zip(options, defaults):
            assert option in actions, f"docs/commands/{PAGES[command]} documents {option}, which {command} does not have: {line}"
            if not matches(documented, actions[option]):
                wrong.append(f"{option}: docs/commands/{PAGES[command]} says {documented!r}, the code {code_default(actions[option])!r}")
    assert not wrong, f"{command}: " + "; ".join(wrong)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_option_is_on_its_commands_page(command: str) -> None:
    """Each option of the parser is named on the command's page (in a table or in the text)."""
    page = (DOCS / "commands" / PAGES[command]).read_text()
    missing = [a.option_strings[-1] for a in build_parser(command)._actions
               if a.option_strings and "--help" not in a.option_strings
               and not any(re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", page) for o in a.option_strings)]
    assert not missing, f"docs/commands/{PAGES[command]} does not mention {command}'s {', '.join(missing)}"


def test_every_command_has_a_page_in_the_site() -> None:
    """pyproject's console scripts all have a page, and mkdocs.yml's navigation lists every command page."""
    import tomllib

    root = DOCS.parent
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    documented = {c.split()[0] for c in COMMANDS}
    assert set(scripts) == documented, f"commands without a reference page: {set(scripts) - documented}"
    nav = (root / "mkdocs.yml").read_text()
    pages = {p.name for p in (DOCS / "commands").glob("*.md")}
    assert all(f"commands/{p}" in nav for p in pages), f"mkdocs.yml's nav misses some of {sorted(pages)}"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_text_names_the_parsers_default(command: str) -> None:
    """A help text that retypes a default ("(default 2e-2)") must say what argparse really uses."""
    parser = build_parser(command)
    wrong = []
    for action in parser._actions:
        shown, value = help_default(action), documented_default(action)
        if shown is None or value is None or not action.option_strings or "%(default)" in (action.help or ""):
            continue
        first = shown.split(",")[0].split()[0] if isinstance(value, (int, float)) and not isinstance(value, bool) else None
        if first is not None:
            try:
                ok = math.isclose(float(first), float(value))
            except ValueError:
                ok = True  # words, such as "no limit"
            if not ok:
                wrong.append(f"{action.option_strings[0]}: help says {shown!r}, the default is {value!r}")
    assert not wrong, f"{command}: " + "; ".join(wrong)


def test_the_table_reader_catches_a_wrong_default() -> None:
    text = ("### `piga-train-model FILE.h5`\n\n| option | default | meaning |\n|---|---|---|\n"
            "| `--batch-size`, `--lr` | 32, 2e-3 | knobs |\n")
    (options, defaults, _), = option_rows(text)["piga-train-model"]
    parser = importlib.import_module(COMMANDS["piga-train-model"]).build_parser()
    actions = {flag: a for a in parser._actions for flag in a.option_strings}
    assert matches(defaults[0], actions[options[0]]) and not matches(defaults[1], actions[options[1]])


def test_the_short_file_rule_quotes_the_code() -> None:
    """The train-model page's rule for sequences shorter than the window names the code's floor and window."""
    from piga.training.train import MIN_PRED_FRAMES, PRESETS

    model = PRESETS["fast"].model
    text = (DOCS / "commands" / "train-model.md").read_text()
    assert f"L + T_pred ({model.input_frames} + {model.pred_frames} for the pendulum)" in text
    assert f"down to {MIN_PRED_FRAMES} (`MIN_PRED_FRAMES`)" in text


def test_the_convergence_rules_quote_the_check() -> None:
    """The train-model page's end-of-run rules name the thresholds of ``ConvergenceConfig`` and the profile's."""
    from piga.evaluation.profile import PROFILE_FACTOR, PROFILE_SEQUENCES
    from piga.training.convergence import ConvergenceConfig

    config = ConvergenceConfig()
    text = " ".join((DOCS / "commands" / "train-model.md").read_text().split())
    assert f"MSE not below {config.blank_ratio:g} of `frame_mse_background`" in text
    assert f"MSE not below {config.hold_ratio:g} of `frame_mse_hold`" in text
    assert f"{config.speed_tolerance:g} or more of the sum of its learning rate" in text
    planet = " ".join((DOCS / "commands" / "baseline.md").read_text().split())
    assert f"filtered frames are not below {config.blank_ratio:g} of the mean frame's MSE (`ConvergenceConfig.blank_ratio`" in planet
    assert f"scaled by {PROFILE_FACTOR:.2f} or 1/{PROFILE_FACTOR:.2f}" in text
    assert f"first windows of {PROFILE_SEQUENCES} training sequences are predicted more than " \
           f"{100 * config.profile_tolerance:g}% better" in text
    assert f"predicted within {100 * config.flat_tolerance:g}% with it scaled by {PROFILE_FACTOR:.2f} and by " \
           f"1/{PROFILE_FACTOR:.2f}) is not determined" in text


def test_the_diagnose_page_gives_the_fewest_frames_the_fit_takes() -> None:
    """The page said 12 frames, and 12 were refused ("the fit needs 13")."""
    from piga.diagnostics.diagnose import DiagnoseConfig
    from piga.diagnostics.fit import MAX_DELAY, min_frames

    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "commands" / "diagnose.md").read_text().split())
    horizon = DiagnoseConfig().fit_horizon
    assert (f"or {min_frames(horizon)} frames (the fit's windows of {horizon} steps after {MAX_DELAY} frames)" in text)


def test_the_collect_page_names_every_env_option() -> None:
    """The page listed 6 of the 9 keys that --env-option takes (help derives its list from DMCPendulumConfig)."""
    from piga.cli.collect import env_option_keys

    row = next(line for line in (DOCS / "commands" / "collect.md").read_text(encoding="utf-8").splitlines()
               if line.startswith("| `--env-option"))
    assert [key for key in env_option_keys() if f"`{key}`" not in row] == []


def test_the_gravity_range_on_the_pages_is_the_envs() -> None:
    """The collect and control pages gave [1e-6, 1e6] m/s² after the bound moved to where the explicit step is stable."""
    from envs.pendulum import MAX_GRAVITY, MIN_GRAVITY

    low = f"{MIN_GRAVITY:.0e}".replace("e-0", "e-")  # as the pages write it: 1e-6
    for page in ("collect.md", "control.md"):
        assert f"[{low}, {MAX_GRAVITY:g}] m/s²" in (DOCS / "commands" / page).read_text(encoding="utf-8"), page


def test_the_control_page_names_what_write_goal_image_takes() -> None:
    """The page said that --write-goal-image takes only --overwrite besides; --quiet and --env are taken too."""
    from piga.cli.control import GOAL_IMAGE_OPTIONS

    row = next(line for line in (DOCS / "commands" / "control.md").read_text(encoding="utf-8").splitlines()
               if line.startswith("| `--write-goal-image"))
    assert [name for name in GOAL_IMAGE_OPTIONS if f"`--{name.replace('_', '-')}" not in row] == []


def test_collect_help_names_the_reset_speed_default_of_each_env() -> None:
    """--help said "(default 1, Gymnasium's ...)", while on the DMC pendulum the default recorded is 0 (at rest)."""
    from envs import DMC_PENDULUM, PIXEL_PENDULUM
    from envs.dmc import DMCPendulumConfig
    from envs.pendulum import PixelPendulumConfig

    action = next(a for a in build_parser("piga-collect")._actions if "--max-speed" in a.option_strings)
    text = " ".join((action.help or "").split())
    assert f"default {PixelPendulumConfig.max_speed:g} on {PIXEL_PENDULUM}" in text, text
    assert f"{DMCPendulumConfig.max_speed:g} on {DMC_PENDULUM}" in text, text
