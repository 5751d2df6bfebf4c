"""What the benchmark scripts share: a record of the machine the numbers were measured on."""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import torch


def machine() -> dict[str, object]:
    """Where the numbers were measured."""
    cpu, family, model = "unknown", "?", "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            key, value = key.strip(), value.strip()
            if key == "model name" and cpu == "unknown":
                cpu = value
            elif key == "cpu family" and family == "?":
                family = value
            elif key == "model" and model == "?":
                model = value
    except OSError:
        pass
    # "AMD EPYC" names several generations, of different speeds (family 23 model 1 is Zen 1); family/model tells them apart
    return {"cpu": cpu, "cpu_family_model": f"{family}/{model}", "cores": os.cpu_count(), "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
            "python": platform.python_version(), "platform": platform.platform()}


def machine_words(m: dict[str, object]) -> str:
    """A :func:`machine` record in words, for a results page: "AMD EPYC (family/model 25/17), 2 cores; ..."."""
    threads = m.get("torch_threads")
    plural = "" if threads == 1 else "s"
    return (f"{m.get('cpu', 'unknown')} (family/model {m.get('cpu_family_model', '?')}), {m.get('cores', '?')} cores; "
            f"torch {m.get('torch', '?')} on {threads} thread{plural}, Python {m.get('python', '?')}")


#: The diagnosis' opt-in readings that the benchmarks running ``piga-diagnose`` pass through: (flag, help).
DIAGNOSE_OPTIONS = (("--fit-starts", "diagnose with piga-diagnose --fit-starts"),
                    ("--matched-angles", "diagnose with piga-diagnose --matched-angles"))


def add_diagnose_options(parser: argparse.ArgumentParser) -> None:
    """Adds :data:`DIAGNOSE_OPTIONS` to a benchmark's parser."""
    for flag, text in DIAGNOSE_OPTIONS:
        parser.add_argument(flag, action="store_true", help=text)


def diagnose_options(args: object) -> tuple[str, ...]:
    """The ``piga-diagnose`` flags of :data:`DIAGNOSE_OPTIONS` that ``args`` turned on."""
    return tuple(flag for flag, _ in DIAGNOSE_OPTIONS if getattr(args, flag[2:].replace("-", "_")))
