"""Identify the pixel pendulum with piga's Python API: collect, train, read states, roll the physics.

    python examples/identify_pendulum.py --out runs/example

The defaults (40 sequences, 2 epochs) take under a minute and learn little: g and a move, but
do not converge. With ``--sequences 500 --epochs 16`` (piga-collect's and the fast preset's defaults,
about 10 minutes on 2 cores) they converge.
"""

import argparse
from pathlib import Path

import torch

import piga

parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
parser.add_argument("--out", default="runs/example", help="folder for the data file and the run")
parser.add_argument("--sequences", type=int, default=40, help="sequences to collect")
parser.add_argument("--epochs", type=int, default=2, help="training epochs")
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)

data = piga.collect(piga.CollectConfig(sequences=args.sequences, workers=1), out / "pendulum.h5",
                            overwrite=True, progress=False)
model, state = piga.train(data, out / "run", piga.TrainConfig(epochs=args.epochs), progress=False)  # run/checkpoint.pt
metrics = piga.write_run_report(model, state, data, out / "run")  # run/metrics.json: held-out errors, convergence
print("converged:", metrics["converged"], (metrics.get("convergence") or {}).get("reason", ""))

model, _ = piga.load_model(out / "run")  # the trained model, in eval mode
frames, actions = piga.read_sequences(data, "test")  # uint8 (N, T, 64, 64), float32 (N, T, 1)
x = piga.frames_to_float(torch.from_numpy(frames[:, :4]), channels=1)  # (N, 4, 1, 64, 64)
u = torch.from_numpy(actions)
with torch.no_grad():
    theta = model.encode(x)  # (N, 4, 1, 1): the angle read from each of the first 4 frames
    future = model.predict(theta, u[:, 3:13], steps=10, last_action=u[:, 2])  # (N, 10, 1, 1): frames 5..14
print("learned:", {k: round(v, 3) for k, v in model.physical_parameters().items()})
print("true:", piga.inspect_dataset(data).params)
print("angles of sequence 0, read and predicted:", theta[0].flatten().tolist(), future[0].flatten().tolist())
