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


_environment_for_the_libraries()
