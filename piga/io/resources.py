"""Memory and disk that a command will need, checked before it allocates or writes anything.

A size that cannot fit (``piga-collect --steps 1000000000``, ``--image-size 100000``) is refused
with one line naming the need and what is available, instead of a MemoryError traceback or a
disk that fills up hours later. Estimates are upper bounds of the large arrays only.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from piga.io.atomic import stores_no_files
from piga.io.checkpoint import CHECKPOINT, REPLACED_ASIDE

#: gzip (level 4) shrinks piga-collect's pendulum frames about 25x (measured on its default data);
#: the disk check of generated data assumes 20x.
RENDERED_FRAME_COMPRESSION = 20.0
#: Recorded video is noisier; the disk check of imported data assumes 2x.
RECORDED_FRAME_COMPRESSION = 2.0
#: dm_control's shaded frames shrink about 16x (40 sequences x 40 frames); the disk check assumes 10x.
SHADED_FRAME_COMPRESSION = 10.0
#: A scene's RGB frames shrink 24-28x for balls (20 sequences of each ball scene, and of bouncing balls of radius 12
#: at 64x64) and 4.5-4.8x for digits; the check assumes 12x and 4x.
SCENE_FRAME_COMPRESSION: dict[str, float] = {"balls": 12.0, "digits": 4.0}
#: An HDF5 file's own bytes beyond its data, as piga writes it: its metadata, and the chunk index of /frames (one
#: sequence a chunk), whose first node holds 64 entries. Measured on pendulum files (gzip-4): 11.1 KiB up to 64
#: sequences of any size, 25.7 KiB for 200 and 51.3 KiB for 600 (``os.path.getsize`` less each dataset's
#: ``get_storage_size``); :func:`hdf5_file_overhead` stays a little above them.
HDF5_FILE_BYTES = 12 * 1024
HDF5_BYTES_PER_SEQUENCE = 80
#: The room beyond a small file's data that a :class:`~piga.data.schema.DatasetWriter` keeps free as it writes, for
#: HDF5's metadata and caches: well above :func:`hdf5_file_overhead`, as running out mid-write is what must not happen.
HDF5_WRITE_HEADROOM = 128 * 1024


def hdf5_file_overhead(sequences: int) -> float:
    """An HDF5 file's own bytes beyond its data, for a file of ``sequences`` sequences (see :data:`HDF5_FILE_BYTES`)."""
    return HDF5_FILE_BYTES + HDF5_BYTES_PER_SEQUENCE * sequences


class ResourceError(ValueError):
    """A job needs more memory or disk than the machine has; the message says how much of each."""


def format_bytes(n: float) -> str:
    """1536 -> '1.5 KiB'."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def format_apart(need: float, have: float) -> tuple[str, str]:
    """:func:`format_bytes` of a need and what is there, in whole bytes where the two would read the same ("needs up to
    1.3 MiB ..., but it has 1.3 MiB free" read as if it fitted)."""
    if format_bytes(need) != format_bytes(have):
        return format_bytes(need), format_bytes(have)
    return f"{need:,.0f} B", f"{have:,.0f} B"


def _machine_available() -> int | None:
    """The machine's available memory (Linux: MemAvailable), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_folders() -> list[Path]:
    """This process's memory cgroup folders, its own first, then each parent up to the mount's root
    (cgroup v1's memory controller, or v2's unified hierarchy). Empty where there is none or it cannot be read."""
    try:
        own = Path("/proc/self/cgroup").read_text().splitlines()
        mounts = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return []
    for line in own:  # "ID:CONTROLLERS:PATH"; v2's is "0::PATH"
        _, controllers, path = line.split(":", 2)
        v2 = controllers == ""
        if not v2 and "memory" not in controllers.split(","):
            continue
        for mount in mounts:  # "... ROOT MOUNTPOINT OPTIONS ... - FSTYPE SOURCE SUPER_OPTIONS"
            fields, _, tail = mount.partition(" - ")
            fstype, _, super_options = (tail.split() + ["", "", ""])[:3]
            if (fstype == "cgroup2") if v2 else (fstype == "cgroup" and "memory" in super_options.split(",")):
                root, point = fields.split()[3:5]
                relative = os.path.relpath(path, root)
                if relative.startswith(".."):
                    continue
                folder = (Path(point) / relative).resolve()
                return [folder, *[p for p in folder.parents if p.is_relative_to(point)]]
    return []


def _read_number(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None  # v2's "max": no limit


def _cgroup_available() -> int | None:
    """Memory left under this process's memory cgroup limits (the tightest of its own and its parents'),
    counting reclaimable page cache (inactive files) as available; None without a limit."""
    left: int | None = None
    for folder in _cgroup_folders():
        v1 = (folder / "memory.limit_in_bytes").exists()
        limit = _read_number(folder / ("memory.limit_in_bytes" if v1 else "memory.max"))
        usage = _read_number(folder / ("memory.usage_in_bytes" if v1 else "memory.current"))
        if limit is None or usage is None or limit >= 1 << 60:  # v1 writes "no limit" as about 2**63
            continue
        inactive = 0
        try:
            for line in (folder / "memory.stat").read_text().splitlines():
                key, _, value = line.partition(" ")
                if key == ("total_inactive_file" if v1 else "inactive_file"):
                    inactive = int(value)
        except (OSError, ValueError):
            pass
        free = max(0, limit - usage + inactive)
        left = free if left is None else min(left, free)
    return left


def _address_space_available() -> int | None:
    """What the process's address-space limit (``ulimit -v``, RLIMIT_AS) leaves beyond its present size, or None
    where there is no such limit."""
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit == resource.RLIM_INFINITY:
            return None
        with open("/proc/self/status", encoding="ascii") as f:
            size = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    except (ImportError, OSError, StopIteration, ValueError):
        return None
    return max(0, limit - size)


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation, or None if unknown: the machine's (Linux:
    MemAvailable), or less where a memory cgroup (a container's or a job's limit) or the process's address-space
    limit (``ulimit -v``) leaves less."""
    known = [n for n in (_machine_available(), _cgroup_available(), _address_space_available()) if n is not None]
    return min(known) if known else None


def check_memory(needed: float, what: str, advice: str = "ask for less") -> None:
    """Raises :class:`ResourceError` if ``needed`` bytes exceed the available memory; ``advice`` ends the message."""
    available = available_memory()
    if available is not None and needed > available:
        shown_need, shown_available = format_apart(needed, available)
        raise ResourceError(f"{what} needs about {shown_need} of memory, but {shown_available} is available; {advice}")


#: Bytes per parameter of float32 training with Adam: the weights, their gradients and Adam's two moments.
TRAINING_BYTES_PER_PARAMETER = 16


def meta_parameter_count(build: Callable[[], Any], trainable_only: bool = False) -> int:
    """The parameters of the torch module that ``build()`` makes, built on torch's meta device (no memory taken);
    ``trainable_only``: those that require a gradient.

    Raises:
        ResourceError: sizes so large that torch's own size arithmetic overflows (a --deter-size of 1e11), which
            no machine could hold.
    """
    import torch

    try:
        with torch.device("meta"):
            return sum(p.numel() for p in build().parameters() if p.requires_grad or not trainable_only)
    except (RuntimeError, TypeError) as exc:  # TypeError: a size beyond int64 ("Overflow when unpacking long long")
        if "overflow" not in str(exc).lower():
            raise
        raise ResourceError("a model of these sizes has more weights than torch can index, far more than any "
                            "machine's memory; ask for less") from None


def check_training_memory(parameters: int, what: str) -> None:
    """Refuses, before anything is allocated, a model of ``parameters`` whose training state does not fit in memory
    (:data:`TRAINING_BYTES_PER_PARAMETER` each); ``what`` names the model in the message.

    Raises:
        ResourceError: as :func:`check_memory`.
    """
    check_memory(float(TRAINING_BYTES_PER_PARAMETER * parameters), what)


def check_disk(target: str | os.PathLike[str], needed: float, what: str, advice: str = "ask for less", *,
               bound: str = "about", detail: str = "", headroom: str = "") -> None:
    """Raises :class:`ResourceError` if ``needed`` bytes exceed the free space where ``target`` goes.

    ``target``'s folder need not exist yet (a run folder made at its first checkpoint): the space
    is measured at its nearest existing ancestor, the filesystem it will be made on. The message says "``what`` needs
    ``bound`` (about, up to) N of disk``detail``"; or, given ``headroom`` (what is written, in words), that ``needed``
    is a fixed room kept free: "``what`` keeps at least N of disk free (``headroom``)". ``advice`` ends the message:
    what the user can do.
    """
    folder = Path(target).parent if str(Path(target).parent) else Path(".")
    while not folder.is_dir() and folder != folder.parent:
        folder = folder.parent
    usage = shutil.disk_usage(folder)
    free = usage.free
    if usage.total == 0:  # /proc, /sys: "0 B free; ask for less" asked for what no size can meet
        raise ResourceError(stores_no_files(what, folder))
    if needed > free:
        shown_need, shown_free = format_apart(needed, free)
        need = (f"keeps at least {shown_need} of disk free ({headroom})" if headroom
                else f"needs {bound} {shown_need} of disk{detail}")
        raise ResourceError(f"{what} {need}, but {folder} has {shown_free} free; {advice}")


#: Room left on top of a training run's checkpoints, for its metrics, plots and TensorBoard.
RUN_DISK_MARGIN = 64 * 1024**2
#: Room a command that writes figures and a report only (``piga-show``, ``piga-diagnose``, ``piga-control --out``)
#: keeps free before its work: a diagnosis folder (report, JSON and four figures) or a strip of 30 sequences x 40
#: frames is under 2 MiB, a control summary or a goal image some KiB.
FIGURE_DISK_BYTES = 4 * 1024**2
#: What :func:`check_figure_disk`'s message says its outputs take.
FIGURE_DISK_WORDS = "what it writes takes under 2 MiB"


def check_figure_disk(target: str | os.PathLike[str], what: str, advice: str = "free some space, or give another --out") -> None:
    """Refuses figures, pictures or a report (``what``) where ``target`` goes with less than :data:`FIGURE_DISK_BYTES`
    free: a fixed room, and the message says so (the files themselves take far less).

    Raises:
        ResourceError: as :func:`check_disk`.
    """
    check_disk(target, FIGURE_DISK_BYTES, what, advice, headroom=FIGURE_DISK_WORDS)


def held_bytes(folder: str | os.PathLike[str], names: Sequence[str]) -> int:
    """The bytes that the files (or folders, all their files) ``names`` in ``folder`` take; 0 for those absent."""
    total = 0
    for name in names:
        path = Path(folder) / name
        files = [path] if path.is_file() else path.rglob("*") if path.is_dir() else []
        total += sum(f.stat().st_size for f in files if f.is_file())
    return total


def adam_checkpoint_bytes(module: Any) -> int:
    """The size of a float32 torch module's checkpoint with Adam's state: the weights and two moments."""
    return 3 * 4 * sum(p.numel() for p in module.parameters())


def run_disk_need(run_dir: str | os.PathLike[str], checkpoint_bytes: float, extra: float = 0.0,
                  resume: bool = False, rewritten: Sequence[str] = (CHECKPOINT,), overwrite: bool = False
                  ) -> tuple[float, int]:
    """The free disk a training run needs, and the bytes of ``run_dir`` counted as reused: each checkpoint is written
    beside the previous one (atomically), so twice ``checkpoint_bytes``, plus ``extra`` and :data:`RUN_DISK_MARGIN`;
    a resumed run (``resume``) or one that replaces the run there (``overwrite``) less what the files it replaces
    (``rewritten``, in ``run_dir``) already take there, but at least one checkpoint: the first is written beside them.
    (Counted as taken, the files that ``--overwrite`` replaces refused it on the disk where the same run had fit.)"""
    # (a baseline's --overwrite has set the replaced run aside by now)
    held = (held_bytes(run_dir, rewritten) + held_bytes(Path(run_dir) / REPLACED_ASIDE, rewritten)
            if resume or overwrite else 0)
    return max(checkpoint_bytes if held else 0.0, 2 * checkpoint_bytes + extra - held) + RUN_DISK_MARGIN, held


def check_run_disk(run_dir: str | os.PathLike[str], checkpoint_bytes: float, what: str, extra: float = 0.0,
                   checkpoint: str = CHECKPOINT, resume: bool = False, rewritten: Sequence[str] = (),
                   overwrite: bool = False) -> None:
    """Refuses, before a training run starts, a run folder whose disk cannot hold its checkpoints
    (:func:`run_disk_need`; ``rewritten``: files a resumed or overwriting run replaces besides ``checkpoint``).
    ``run_dir`` need not exist yet. A resumed run is told to free space only: another --out would not continue it.

    Raises:
        ResourceError: as :func:`check_disk`.
    """
    needed, held = run_disk_need(run_dir, checkpoint_bytes, extra, resume, (checkpoint, *rewritten), overwrite)
    check_disk(Path(run_dir) / checkpoint, needed, what,
               advice="free some space" if resume else "free some space, or give another --out",
               detail=f" beyond the {format_bytes(held)} of {run_dir} that it replaces" if held else "")


__all__ = ["FIGURE_DISK_BYTES", "FIGURE_DISK_WORDS", "HDF5_BYTES_PER_SEQUENCE", "HDF5_FILE_BYTES", "HDF5_WRITE_HEADROOM",
           "RECORDED_FRAME_COMPRESSION", "RENDERED_FRAME_COMPRESSION",
           "RUN_DISK_MARGIN", "SCENE_FRAME_COMPRESSION", "SHADED_FRAME_COMPRESSION", "ResourceError",
           "adam_checkpoint_bytes", "available_memory", "check_disk", "check_figure_disk", "check_memory", "check_training_memory",
           "check_run_disk", "format_apart", "format_bytes", "hdf5_file_overhead", "held_bytes", "run_disk_need"]
