"""Command-line entry points. Each one only parses its arguments, calls one library function and saves."""

import os as _os


def _environment_for_the_libraries() -> None:
    """Two environment variables that would break a command from inside a library, put right before any loads it:

    - ``OMP_NUM_THREADS`` that is not a positive count (``0``, ``abc``): libgomp prints "Invalid value" on stderr as
      torch loads, and ignores it; it is dropped here (each command sets its threads itself, ``--threads``);
    - ``MPLBACKEND``: piga writes its figures to files only, with matplotlib's Agg, whatever the variable names (a
      backend that does not exist failed only at the first figure, after the work).
    """
    threads = _os.environ.get("OMP_NUM_THREADS")
    if threads is not None and not all(part.strip().isdigit() and int(part) > 0 for part in threads.split(",")):
        del _os.environ["OMP_NUM_THREADS"]
    if "MPLBACKEND" in _os.environ:
        _os.environ["MPLBACKEND"] = "Agg"


#: Each command's module and the script that runs it, as pyproject's [project.scripts] pairs them (a test checks
#: that the two agree): the early interrupt's line names the command from here, with no lookup that can fail mid-import.
SCRIPTS = {
    "piga.cli.collect": "piga-collect",
    "piga.cli.show": "piga-show",
    "piga.cli.demo": "piga-demo",
    "piga.cli.train": "piga-train-model",
    "piga.cli.control": "piga-control",
    "piga.cli.diagnose": "piga-diagnose",
    "piga.cli.importer": "piga-import",
    "piga.cli.baseline": "piga-baseline",
}


def _early_interrupt(number: int, frame: object) -> None:
    """SIGINT while a command still loads its libraries, before :func:`piga.cli.common.run_cli` takes the signal: the
    one line it would print then (Python's KeyboardInterrupt, raised inside an import, printed 17 to 37 lines)."""
    import sys

    name = _os.path.basename(sys.argv[0]) if sys.argv else ""
    if not name.startswith("piga-"):  # python -m piga.cli.X: sys.argv[0] is "-m" while X loads
        given = getattr(sys, "orig_argv", [])
        module = given[given.index("-m") + 1] if "-m" in given[:-1] else ""
        name = SCRIPTS.get(module, "piga")
    _os.write(2, f"{name}: interrupted; nothing was written\n".encode("utf-8", "replace"))
    _os._exit(128 + number)


def _take_early_interrupts() -> None:
    """Installs :func:`_early_interrupt` for a command's own process only (a piga-* script, ``python -m piga.cli.X``),
    never in a program that imports piga (a notebook's Ctrl-C stays its own), and only over Python's default."""
    import signal
    import sys
    import threading

    script = _os.path.basename(sys.argv[0]) if sys.argv else ""
    if (script.startswith("piga-") or script == "-m") and threading.current_thread() is threading.main_thread() \
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _early_interrupt)


_environment_for_the_libraries()
_take_early_interrupts()
