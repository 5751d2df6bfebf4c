"""Benchmark: the job runner's two backends, local processes and Ray, give the same results for the same seeds.

It runs two farms with the commands themselves, each twice: once on local processes (two at a time)
and once with ``--ray`` (default ``auto``: the Ray instance of this machine, started if none runs):

1. a control sweep, ``piga-control --model MODEL --sweep SWEEP --episodes E --workers 2 --out ...`` (the
   piga agent and the oracle at each gravity multiplier: one job each);
2. the blind diagnosis benchmark, ``python benchmarks/diagnose_blind.py --model MODEL --cases N
   --sequences Q --jobs 2 ...`` (one job per case; each case collects, strips, diagnoses in a fresh
   ``piga-diagnose`` process and scores).

Then it compares the two runs of each farm, byte for byte as canonical JSON, with the timings left out:
the sweep's ``plan_ms_*`` fields (plan times per step, measured while the jobs share the machine) and
the blind benchmark's per-case ``seconds`` (wall time); everything else, every score, verdict and
coefficient, must be equal. ``--cluster HOST:PORT`` adds a third run of the sweep on that cluster, and a
farm of short tasks that report the Ray node, host and process each ran on, to show that every node took
work. Writes OUT.json and OUT.md.

    python benchmarks/backends.py --model runs/bench/default-seed0 --work runs/backends --out results/ray

A farm whose outputs are in ``--work`` is not run again (the blind benchmark also continues a stopped
run case by case), so a stopped benchmark continues where it stopped.
"""

from __future__ import annotations

import argparse
import json
import shlex
import statistics
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

from common import farm_main, machine, machine_words, out_prefix, work_folder, write_page
from piga.cli.common import ArgumentParser, positive_int, ray_address
from piga.io.atomic import write_json

#: The blind benchmark's own sequences per case (``diagnose_blind.py --sequences``), for the page.
BLIND_SEQUENCES = 200
#: Fields left out of the comparison, as (farm, field name, why).
EXCLUDED = (("sweep", "plan_ms_median, plan_ms_p95 (per episode and per summary)", "plan times per step: timings"),
            ("blind", "seconds (per case)", "wall time of the case"),
            ("blind, each case's report.json", "command, data, model", "the paths it names: the model as given, the case's own files"))
#: Top-level fields of a piga-diagnose report.json that name paths (left out of the comparison).
REPORT_PATHS = ("command", "data", "model")


def without(value: Any, drop: tuple[str, ...]) -> Any:
    """``value`` (JSON) without the dict keys that start with any of ``drop``, at any depth."""
    if isinstance(value, dict):
        return {k: without(v, drop) for k, v in value.items() if not k.startswith(drop)}
    if isinstance(value, list):
        return [without(v, drop) for v in value]
    return value


def canonical(value: Any) -> bytes:
    """The bytes compared: sorted keys, floats as Python writes them (repr: every bit)."""
    return json.dumps(value, sort_keys=True).encode()


def run_step(command: list[str], log: Path, timing: Path) -> float:
    """Runs a command once (its output to ``log``), keeping its wall seconds in ``timing``; a rerun reads them."""
    if timing.exists():
        return float(json.loads(timing.read_text())["seconds"])
    print("$ " + shlex.join(command), flush=True)
    started = time.monotonic()
    with log.open("w") as f:
        code = subprocess.run(command, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
    seconds = time.monotonic() - started
    if code:
        sys.exit(f"backends benchmark: {shlex.join(command[:3])} ... failed (exit {code}); see {log}")
    write_json(timing, {"command": shlex.join(command), "seconds": seconds}, overwrite=True)
    return seconds


def sweep_command(args: argparse.Namespace, out: Path, ray: str | None) -> list[str]:
    return ["piga-control", "--model", args.model, "--sweep", args.sweep, "--episodes", str(args.episodes), "--workers", "2",
            "--quiet", "--out", str(out), "--overwrite", *(["--ray", ray] if ray else [])]


def blind_command(args: argparse.Namespace, out: Path, cases: Path, ray: str | None) -> list[str]:
    return [sys.executable, str(Path(__file__).with_name("diagnose_blind.py")), "--model", args.model, "--out", str(out),
            "--work", str(cases), "--cases", str(args.cases), "--sequences", str(args.sequences), "--seed", "0",
            "--jobs", "2", *(["--ray", ray] if ray else [])]


def shown(command: list[str]) -> str:
    """A command as the page shows it: ``python benchmarks/...`` for this interpreter and folder."""
    here = Path(__file__).parent
    return shlex.join(["python" if c == sys.executable else f"benchmarks/{Path(c).name}" if Path(c).parent == here else c
                       for c in command])


def compare_sweeps(a: Path, b: Path) -> dict[str, Any]:
    """Two sweep outputs (OUT.json) compared without their plan times."""
    x, y = (without(json.loads(p.read_text()), ("plan_ms",)) for p in (a, b))
    return {"identical": canonical(x) == canonical(y), "jobs": len(x["results"]),
            "episodes": sum(len(r["episodes"]) for r in x["results"])}


def report_bytes(path: Path) -> bytes:
    """A diagnosis report as compared: canonical JSON without the paths it names (:data:`REPORT_PATHS`)."""
    return canonical({k: v for k, v in json.loads(path.read_text()).items() if k not in REPORT_PATHS})


def compare_files(a: Path, b: Path) -> dict[str, Any]:
    """The cases' own files in two blind-benchmark work folders: each data file byte for byte, each diagnosis
    report as canonical JSON without the paths it names."""
    data = sorted(p.name for p in a.glob("case*.h5"))
    reports = sorted(p.parent.name for p in a.glob("case*/report.json"))
    same_data = [n for n in data if (b / n).exists() and (a / n).read_bytes() == (b / n).read_bytes()]
    same_reports = [n for n in reports if (b / n / "report.json").exists()
                    and report_bytes(a / n / "report.json") == report_bytes(b / n / "report.json")]
    return {"data_files": len(data), "data_files_identical": len(same_data), "reports": len(reports),
            "reports_identical": len(same_reports)}


def compare_blind(a: Path, b: Path) -> dict[str, Any]:
    """Two blind-benchmark outputs compared case by case without their wall times; the median seconds per case."""
    x, y = (json.loads(p.read_text()) for p in (a, b))
    cases = {r["case"]: r for r in x["runs"]}, {r["case"]: r for r in y["runs"]}
    differ = sorted(c for c in cases[0].keys() | cases[1].keys()
                    if c not in cases[0] or c not in cases[1]
                    or canonical(without(cases[0][c], ("seconds",))) != canonical(without(cases[1][c], ("seconds",))))
    return {"identical": not differ and canonical(x["summary"]) == canonical(y["summary"]), "cases": len(cases[0]),
            "differing_cases": differ, "summary_identical": canonical(x["summary"]) == canonical(y["summary"]),
            "top1": [x["summary"]["top1_accuracy"], y["summary"]["top1_accuracy"]],
            "median_case_seconds": [statistics.median(r["seconds"] for r in x["runs"]),
                                    statistics.median(r["seconds"] for r in y["runs"])]}


def _where(i: int) -> dict[str, Any]:
    """A task that reports where it ran (after a second's work, so that the tasks spread over the nodes)."""
    import os
    import socket

    import ray

    time.sleep(1.0)
    return {"task": i, "node": ray.get_runtime_context().get_node_id()[:12], "host": socket.gethostname(), "pid": os.getpid()}


def where_farm(address: str, tasks: int) -> dict[str, Any]:
    """``tasks`` short tasks on the cluster at ``address``: which node, host and process ran each."""
    from piga.io.pool import Backend, run_pool

    backend = Backend("ray", address)
    backend.connect()
    import ray

    nodes = [n for n in ray.nodes() if n.get("Alive")]
    ran = run_pool(_where, list(range(tasks)), progress=False, backend=backend)
    return {"address": address, "nodes": [{"node": n["NodeID"][:12], "cpus": n["Resources"].get("CPU", 0),
                                           "address": n["NodeManagerAddress"]} for n in nodes],
            "tasks_per_node": dict(Counter(r["node"] for r in ran)), "tasks": ran}


def code(text: str) -> str:
    """``text`` as inline code in Markdown, also when it holds backticks."""
    return f"`` {text} ``" if "`" in text else f"`{text}`"


def node_words(node: dict[str, Any]) -> str:
    return f"{node['node']} with {node['cpus']:g} CPU"


def markdown(record: dict[str, Any]) -> str:
    yes = {True: "**identical**", False: "**differ**"}
    sweep, blind, files, cmd = record["sweep"], record["blind"], record["blind_files"], record["commands"]
    t = record["seconds"]
    lines = [
        "# The job runner's backends: local processes and Ray", "",
        f"Command: {code(record['command'])}", "",
        f"Machine: {machine_words(record['machine'])}; no GPU. The machine was shared with other work while this ran, "
        "so the times are indicative only.", "",
        "Each farm ran twice with the same seeds, once on local processes (two at a time) and once on Ray "
        f"(`--ray {record['ray']}`: a local Ray instance of the machine's CPUs, one job per CPU, one torch thread each). "
        "The records are compared byte for byte as canonical JSON, with the timings left out:", "",
        "| farm | left out of the comparison | why |", "|---|---|---|",
        *[f"| {farm} | {fields} | {why} |" for farm, fields, why in EXCLUDED], "",
        "| farm | jobs | local processes | Ray | records |", "|---|---|---|---|---|",
        f"| control sweep: piga and the oracle at {record['multipliers']} multipliers, {record['episodes']} episodes each "
        f"| {sweep['jobs']} | {t['sweep_local']:.0f} s | {t['sweep_ray']:.0f} s | {yes[sweep['identical']]} |",
        f"| blind diagnosis, {blind['cases']} cases of {record['sequences']} sequences{record['sequences_note']} (top-1: {blind['top1'][0]:.0%}, "
        f"{blind['top1'][1]:.0%}) | {blind['cases']} | median {blind['median_case_seconds'][0]:.0f} s per case | median "
        f"{blind['median_case_seconds'][1]:.0f} s per case | {yes[blind['identical']]} |",
        f"| the blind cases' own files: data files (byte for byte), diagnosis reports | {files['data_files']}, "
        f"{files['reports']} | | | {files['data_files_identical']} and {files['reports_identical']} "
        f"{yes[files['data_files_identical'] == files['data_files'] and files['reports_identical'] == files['reports']]} |",
        "",
        "The commands it ran:", "",
        *[f"- {name}: `{c}`" for name, c in cmd.items()], "",
    ]
    if (cluster := record.get("cluster")) is not None:
        farm = cluster["where"]
        lines += [
            "## Two Ray nodes", "",
            f"The cluster at `{farm['address']}`: {len(farm['nodes'])} nodes "
            f"({', '.join(node_words(n) for n in farm['nodes'])}). {cluster['note']}", "",
            f"- {len(farm['tasks'])} short tasks, by node: "
            + ", ".join(f"{node} ran {n}" for node, n in sorted(farm["tasks_per_node"].items())) + ".",
            f"- The control sweep on the cluster (`{cluster['command']}`, {t['sweep_cluster']:.0f} s): records "
            f"{yes[cluster['sweep']['identical']]} to the local run's.", "",
        ]
    return "\n".join(lines)


@farm_main
def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (the sweep's agent, the diagnosis' model)")
    p.add_argument("--work", type=work_folder, required=True, help="folder for the farms' outputs (kept; a rerun skips finished farms)")
    p.add_argument("--out", type=out_prefix, required=True, help="OUT.json and OUT.md are written")
    p.add_argument("--ray", type=ray_address, default="auto", help="the Ray backend to compare with (default %(default)s)")
    p.add_argument("--sweep", default="0.6:1.4:0.2", help="gravity multipliers of the sweep (default %(default)s)")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes per sweep job (default %(default)s)")
    p.add_argument("--cases", type=positive_int, default=20, help="blind-benchmark cases (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=100, help="sequences per blind case (default %(default)s)")
    p.add_argument("--cluster", type=ray_address, metavar="HOST:PORT",
                   help="also run the sweep, and a farm that reports where each of its tasks ran, on this Ray cluster")
    p.add_argument("--cluster-note", help="what the cluster is, for the page (default none)")
    args = p.parse_args()
    from piga.cli.common import connect_backend
    from piga.io.ray_backend import disconnect

    for address in (args.ray, args.cluster):  # refused in seconds, before the local farms (it came after them)
        if address is not None:
            connect_backend(address)
            disconnect()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    from piga.control.episodes import parse_range

    commands = {"sweep, local": sweep_command(args, work / "sweep-local", None),
                "sweep, Ray": sweep_command(args, work / "sweep-ray", args.ray),
                "blind, local": blind_command(args, work / "blind-local", work / "blind-local-cases", None),
                "blind, Ray": blind_command(args, work / "blind-ray", work / "blind-ray-cases", args.ray)}
    seconds = {}  # the sweeps' wall times (a blind run that continued a stopped one has no meaningful wall time)
    for key, name in (("sweep_local", "sweep, local"), ("sweep_ray", "sweep, Ray"), ("blind_local", "blind, local"),
                      ("blind_ray", "blind, Ray")):
        slug = key.replace("_", "-")
        took = run_step(commands[name], work / f"{slug}.log", work / f"{slug}.time.json")
        if key.startswith("sweep"):
            seconds[key] = took
    record: dict[str, Any] = {
        "command": shlex.join(["python", "benchmarks/backends.py", *sys.argv[1:]]), "machine": machine(), "ray": args.ray,
        "multipliers": len(parse_range(args.sweep)), "episodes": args.episodes, "sequences": args.sequences,
        "sequences_note": "" if args.sequences == BLIND_SEQUENCES else f" (the benchmark's default: {BLIND_SEQUENCES})",
        "excluded": [{"farm": f, "fields": x, "why": w} for f, x, w in EXCLUDED],
        "commands": {k: shown(c) for k, c in commands.items()}, "seconds": seconds,
        "sweep": compare_sweeps(work / "sweep-local.json", work / "sweep-ray.json"),
        "blind": compare_blind(work / "blind-local.json", work / "blind-ray.json"),
        "blind_files": compare_files(work / "blind-local-cases", work / "blind-ray-cases"),
    }
    if args.cluster:
        command = sweep_command(args, work / "sweep-cluster", args.cluster)
        seconds["sweep_cluster"] = run_step(command, work / "sweep-cluster.log", work / "sweep-cluster.time.json")
        where = work / "cluster-where.json"
        if not where.exists():
            write_json(where, where_farm(args.cluster, 8))
        record["cluster"] = {"where": json.loads(where.read_text()), "command": shown(command), "note": args.cluster_note or "",
                             "sweep": compare_sweeps(work / "sweep-local.json", work / "sweep-cluster.json")}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    page = markdown(record)
    write_page(out, record, page)
    print(page)
    files = record["blind_files"]
    identical = record["sweep"]["identical"] and record["blind"]["identical"] and \
        files["data_files_identical"] == files["data_files"] and files["reports_identical"] == files["reports"] and \
        record.get("cluster", {}).get("sweep", {}).get("identical", True)
    return 0 if identical else 1


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
