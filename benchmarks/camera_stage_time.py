"""Benchmark: the wall time of the diagnosis's camera stage (:func:`piga.diagnostics.vision.camera_stage`) on one run
and one recording, in this process, on one torch thread. Meant to be timed as a whole process by ``farm-bench``
against another checkout of piga (on ``PYTHONPATH``)::

    farm-bench -n 5 --vs "env PYTHONPATH=OLD_CHECKOUT python benchmarks/camera_stage_time.py RUN DATA" -- \\
        python benchmarks/camera_stage_time.py RUN DATA

Prints the stage's seconds and the camera it found; writes nothing.
"""

from __future__ import annotations

import time
from piga.cli.common import ArgumentParser


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="a piga-train-model run folder of the pendulum")
    p.add_argument("data", help="an HDF5 recording (piga-collect)")
    args = p.parse_args(argv)
    import numpy as np
    import torch

    from piga.data.schema import inspect_dataset
    from piga.diagnostics.vision import camera_stage
    from piga.io.runs import load_model

    torch.set_num_threads(1)
    info = inspect_dataset(args.data)  # a missing or foreign file in one line (it was h5py's text)
    model, _ = load_model(args.run)
    n, t = info.n_sequences, info.steps
    fit = np.arange(n) < int(0.75 * n)  # the diagnosis's fit split
    started = time.perf_counter()
    found = camera_stage(model, args.data, np.zeros((n, t)), fit, None)
    print(f"camera stage: {time.perf_counter() - started:.2f} s; camera {found.camera}")
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
