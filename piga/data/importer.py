"""Importing a user's own recording (a video or a folder of frames, plus a CSV of actions).

The output is a file of piga's one schema (:mod:`piga.data.schema`), like the files that ``piga-collect``
writes. It has no ``/states``, because a real recording has no ground truth.

| input | what is accepted |
|---|---|
| recording | a video file that imageio reads (``.mp4``, ``.gif``, ...), an image stack (a multi-page TIFF: gray ``(T, H, W)`` or colour ``(T, H, W, 3 or 4)``), or a folder of ``.png`` / ``.jpg`` / ``.jpeg`` frames in natural name order (``f2`` before ``f10``) |
| actions | a CSV with one row per frame: the action u_t applied after frame t. Either one column, with or without a header row naming it ``u`` or ``action``, or a header row with a column named ``u`` or ``action`` |
| dt | the frame interval in seconds |

Each frame is converted as the env converts its render (:func:`piga.data.scene.scene_to_gray`): a
centre crop to a square, ``cv2.resize(..., INTER_AREA)`` to ``image_size``, then Gymnasium's gray
weights. The recording is cut into consecutive sequences of ``steps`` frames. The frames left over
at the end, fewer than one sequence, are dropped. The sequences are split train/valid/test in
recording order, like ``piga-collect`` (:func:`piga.data.collect.split_counts`), so that the test
sequences are the end of the recording. The converted frames are held in memory before writing
(4 KiB per 64x64 frame), because their count must match the CSV's before anything is written.

File attrs: ``system`` = "pendulum", ``dt``, ``params`` = {} (unknown), ``seed`` = -1,
``command``, ``source`` (the recording's path), ``source_actions`` (the CSV's path),
``source_frames`` (frames in the recording), ``dropped_frames``, and ``split_counts``.
"""

from __future__ import annotations

import csv
import math
import re
import shlex
import sys
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from envs.fields import counted
from envs.pendulum import MAX_IMAGE_SIZE
from piga.io.atomic import check_not_an_input, check_writable_target
from piga.data.collect import split_counts
from piga.data.schema import (MAX_ABS_ACTION, MAX_DT, MIN_DT, MIN_IMAGE_SIZE, SPLITS, DatasetWriter, blank_error,
                              check_data_disk, frames_have_signal, frames_move, still_error)
from piga.data.scene import DAMAGED_READ, read_image, reader_log, scene_to_gray

#: float32's smallest normal number: a nonzero action below it would be stored as 0 or rounded.
FLOAT32_TINY = np.finfo(np.float32).tiny

#: File name endings read from a folder of frames (case-insensitive).
FRAME_EXTENSIONS = (".png", ".jpg", ".jpeg")
#: Header names that mark the action column of a CSV with several columns (case-insensitive).
ACTION_COLUMNS = ("u", "action")


@dataclass(frozen=True)
class ImportConfig:
    """How ``piga-import`` turns a recording into piga's schema."""

    dt: float
    """Seconds between consecutive frames of the recording."""
    steps: int = 40
    """T, frames per sequence; the recording is cut into sequences of T frames."""
    image_size: int = 64
    """Side of the square gray frame in pixels (the pixel pendulum's default)."""
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)
    """Train/valid/test, as fractions summing to 1 or as counts summing to the number of sequences."""

    def __post_init__(self) -> None:
        number = isinstance(self.dt, (int, float, np.floating))
        if not (number and MIN_DT <= self.dt <= MAX_DT):
            shown = format(self.dt, "g") if number else repr(self.dt)
            if number and float(shown) != self.dt:  # 10.000001 is not "10", which is in range
                shown = repr(float(self.dt))
            raise ValueError(f"{type(self).__name__}.dt must be the seconds between frames, {MIN_DT:g} to {MAX_DT:g}, got {shown}")
        if self.steps < 2:
            raise ValueError(f"{type(self).__name__}.steps must be >= 2 (a video needs two frames), got {self.steps}")
        if not MIN_IMAGE_SIZE <= self.image_size <= MAX_IMAGE_SIZE:  # the largest piga-collect draws
            raise ValueError(f"image_size must be in [{MIN_IMAGE_SIZE}, {MAX_IMAGE_SIZE}], got {self.image_size}")


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_recording` wrote."""

    path: Path
    """The file written."""
    sequences: int
    """N, sequences written."""
    source_frames: int
    """Frames in the recording."""
    dropped_frames: int
    """Frames left over at the end (fewer than one sequence), not written."""
    split_counts: dict[str, int]
    """Sequences per split name."""
    source_shape: tuple[int, int]
    """(height, width) of the recording's frames, before the centre crop to a square and the resize to ``image_size``."""

    @property
    def source_side(self) -> int:
        """The side of the square cropped from the recording's frames, before resizing to ``image_size``."""
        return min(self.source_shape)


def recording_frame_seconds(path: str | Path) -> float | None:
    """The seconds between frames that a video file says (an MP4's fps, a GIF's frame duration), or None where it
    says none (a folder of frames, an image stack) or cannot be read for it."""
    p = Path(path)
    if not p.is_file():
        return None
    import imageio.v3 as iio

    try:
        meta = iio.immeta(p)
    except Exception:  # noqa: BLE001 (a reader's own errors: the frames were read; only the rate is unknown)
        return None
    fps, duration = meta.get("fps"), meta.get("duration")
    if isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0:
        return 1.0 / fps
    if p.suffix.lower() == ".gif" and isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0:
        return duration / 1000.0  # Pillow's GIF duration: milliseconds per frame
    return None


def _natural_key(path: Path) -> list[int | str]:
    return [int(part) if part.isdecimal() else part.lower() for part in re.split(r"(\d+)", path.name)]


def frame_files(folder: str | Path) -> list[Path]:
    """The frame files of a folder, in natural name order (``f2.png`` before ``f10.png``). Hidden files are
    not frames (macOS leaves ``._f2.png`` metadata beside each file it copies to a foreign disk).

    Raises:
        ValueError: the folder holds no PNG or JPEG file.
    """
    folder = Path(folder)
    named = [p for p in folder.iterdir() if not p.name.startswith(".") and p.suffix.lower() in FRAME_EXTENSIONS]
    odd = next((p for p in named if p.exists() and not p.is_file() and not p.is_dir()), None)
    if odd is not None:  # a pipe named as a frame was skipped, and the recording lost a frame without a word
        raise ValueError(f"{odd}: is not a regular file (a pipe, a socket or a device), though named as a frame; "
                         "remove it or replace it with the frame")
    files = sorted((p for p in named if p.is_file()), key=_natural_key)
    if not files:
        raise ValueError(f"{folder}: no frames in this folder (expected {', '.join(FRAME_EXTENSIONS)} files)")
    seen: dict[tuple[int | str, ...], Path] = {}
    for p in files:  # f7.png and f07.png (or f7.jpg) are one place in the order: which comes first is a guess
        key = tuple(_natural_key(Path(p.stem)))
        if key in seen:
            raise ValueError(f"{folder}: {seen[key].name} and {p.name} are the same frame in name order; keep one")
        seen[key] = p
    _check_no_frame_missing(folder, files)
    return files


def _check_no_frame_missing(folder: Path, files: list[Path]) -> None:
    """Refuses frames numbered with a gap (``f1 f2 f4``): the step across it would last twice as long as the others,
    and the physics would be learned from it as one step. The number is the last one in each name; names that differ
    elsewhere, or fewer than three frames, are taken as they are. A constant stride (every 5th frame) is kept."""
    parts = [re.fullmatch(r"(.*?)(\d+)(\D*)", p.stem) for p in files]
    if len(files) < 3 or any(m is None for m in parts) or len({(m.group(1), m.group(3)) for m in parts if m}) > 1:
        return
    numbers = [int(m.group(2)) for m in parts if m]
    steps = [b - a for a, b in zip(numbers, numbers[1:])]
    usual = Counter(steps).most_common(1)[0][0]
    for i, step in enumerate(steps):
        if step != usual:
            raise ValueError(f"{folder}: the frame numbers jump from {numbers[i]} ({files[i].name}) to {numbers[i + 1]} "
                             f"({files[i + 1].name}), where the others step by {usual}: the frames there are not evenly "
                             "spaced in time, yet each step counts as --dt; put the missing frames back, or import the "
                             "frames before the gap and those after it as two recordings")


def read_recording(path: str | Path, size: int) -> np.ndarray:
    """All frames of a video file or a folder of frames, converted: uint8 (F, size, size).

    Raises:
        FileNotFoundError: no such file or folder.
        ValueError: an unreadable video or frame (the message names it), or no frames at all.
    """
    return _read_recording(path, size)[0]


def _read_recording(path: str | Path, size: int) -> tuple[np.ndarray, tuple[int, int]]:
    """:func:`read_recording`'s frames (F, size, size), and the first frame's (height, width), before the centre crop
    to a square and the resize (a short side below ``size`` means the frames were enlarged). A recording whose reader
    warned of damage it read past is refused: a TIFF stack cut short gave the pages before the cut, and the actions
    were blamed for the count ("a.csv has 48 actions but cut.tif has 24 frames"), or half the recording was written."""
    with reader_log() as caught:
        frames, shape = _decode_recording(path, size)
    if caught:
        raise ValueError(f"{path}: not a readable video or image stack ({DAMAGED_READ}); piga-import takes "
                         f"{RECORDINGS}")
    return frames, shape


def _decode_recording(path: str | Path, size: int) -> tuple[np.ndarray, tuple[int, int]]:
    """:func:`_read_recording`'s frames and first frame's (height, width)."""
    p = Path(path)
    if p.is_dir():
        frames = []
        first: tuple[Path, tuple[int, ...]] | None = None
        for file in frame_files(p):
            image = read_image(file)  # its errors name the file
            first = first or (file, image.shape[:2])
            if image.shape[:2] != first[1]:
                raise ValueError(f"{file}: {image.shape[1]}x{image.shape[0]} px (width x height), but {first[0].name} "
                                 f"is {first[1][1]}x{first[1][0]}: the frames of one recording share one size")
            try:
                frames.append(scene_to_gray(image, size))
            except ValueError as exc:
                raise ValueError(f"{file}: {exc}") from None
        shape = (int(first[1][0]), int(first[1][1])) if first else (size, size)
        return np.stack(frames), shape  # (F, size, size); frame_files found some
    if not p.is_file():
        if p.exists():  # a FIFO, a socket, a device: exists, but no video to decode
            raise ValueError(f"{p}: is not a regular file (a pipe, a socket or a device), not a video file or frame folder")
        raise FileNotFoundError(f"{p}: no such video file or frame folder")
    frames = []
    shape = (size, size)
    for image in _read_images(p):
        for frame in _frames_of(image, p):
            here = (int(frame.shape[0]), int(frame.shape[1]))
            shape = here if not frames else shape
            if here != shape:  # a stack's page of another size was enlarged to the rest without a word
                raise ValueError(f"{p}: frame {len(frames)} (counted from 0) is {here[1]}x{here[0]} px (width x "
                                 f"height), but frame 0 is {shape[1]}x{shape[0]}: the frames of one recording share "
                                 "one size")
            try:
                frames.append(scene_to_gray(frame, size))
            except ValueError as exc:
                raise ValueError(f"{p}: frame {len(frames)} (counted from 0): {exc}") from None
    if not frames:
        raise ValueError(f"{p}: the video has no frames")
    return np.stack(frames), shape  # (F, size, size)


def _mixed_pages(path: Path) -> str:
    """Why a multi-page TIFF whose pages differ in size cannot be read (tifffile: "incompatible keyframe"), naming the
    first page of another size than page 0 (it was called "damaged")."""
    import tifffile  # (imageio's TIFF reader)

    with tifffile.TiffFile(path) as tif:
        sizes = [tuple(int(x) for x in page.shape[:2]) for page in tif.pages]
    other = next((i for i, size in enumerate(sizes) if size != sizes[0]), None)
    if other is None:
        return "damaged, or of a format its reader does not take"
    (h0, w0), (h, w) = sizes[0], sizes[other]
    return (f"its page 0 is {w0}x{h0} px (width x height), but page {other} is {w}x{h}: the frames of one recording "
            "share one size")


#: What a recording may be, as the errors say it.
RECORDINGS = "a video file, an image stack such as a multi-page TIFF, or a folder of .png/.jpg frames"


def _read_images(path: Path) -> Iterator[np.ndarray]:
    """The images imageio reads from a file, one at a time: a video's frames, or one array (an image stack)."""
    import imageio.v3 as iio

    try:
        for image in iio.imiter(path):
            yield np.asarray(image)
    except Exception as exc:  # imageio and its plugins raise many types for foreign or corrupt files
        first = (str(exc).strip().splitlines() or [""])[0][:120]
        why = (f"it is a {path.suffix[1:].upper()} file, such as the actions; {ORDER}"
               if path.suffix.lower() in (".csv", ".tsv", ".txt") else  # the arguments swapped
               "no reader knows its format" if "Could not find a backend" in first else  # imageio's words for it
               "it is empty" if path.stat().st_size == 0 else
               "it is an HDF5 file, such as piga's data files, which need no import" if _is_hdf5(path) else
               _mixed_pages(path) if "incompatible keyframe" in first else  # tifffile's words for pages of two sizes
               # not the reader's own words after it ("Could not load meta information")
               "damaged, or of a format its reader does not take")
        raise ValueError(f"{path}: not a readable video or image stack ({why}); piga-import takes {RECORDINGS}") from None


def _is_hdf5(path: Path) -> bool:
    """Whether ``path`` starts as an HDF5 file (a data file, not a recording); False where it cannot be read."""
    import h5py

    try:
        return bool(h5py.is_hdf5(path))
    except OSError:
        return False


def _frames_of(image: np.ndarray, path: Path) -> Sequence[np.ndarray]:
    """The frames in one array imageio read: an image, gray (H, W) or with channels (H, W, 1, 3 or 4), is one frame; a
    stack of them (T, H, W) or (T, H, W, 1, 3 or 4), as a multi-page TIFF is read, is T frames."""
    channels = (1, 3, 4)
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] in channels):
        return (image,)
    if image.ndim == 3 or (image.ndim == 4 and image.shape[3] in channels):
        return image  # type: ignore[return-value]
    raise ValueError(f"{path}: holds an array of shape {image.shape}, not frames; piga-import takes {RECORDINGS}")


#: A number as a CSV writes one: ASCII digits, an optional sign, point and exponent; or Python's words for NaN and the
#: infinities (read, then refused as not finite). Python's float() takes more (``1_0``, Arabic-Indic or fullwidth
#: digits), which no CSV writer means as a number.
_CSV_NUMBER = re.compile(r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)", re.IGNORECASE)


def _number(text: str) -> float | None:
    """The number a CSV cell writes (:data:`_CSV_NUMBER`), or None."""
    return float(text) if _CSV_NUMBER.fullmatch(text) else None


#: A cell that starts as a number does (a sign, a point, a digit): never a column's name.
_LOOKS_NUMERIC = re.compile(r"[+-]?\.?\d")


def _is_header(row: list[str]) -> bool:
    """Whether a CSV row is a header: a cell that is a name, neither empty nor a number in any spelling Python reads,
    nor a malformed one (a first row ``1_0`` or ``0x1`` starts as a number does: a value to refuse, not a header to
    skip)."""
    for cell in row:
        try:
            float(cell)
        except ValueError:
            if cell and not _LOOKS_NUMERIC.match(cell):
                return True
    return False


#: The arguments' order, for a recording given as the actions or a CSV given as the recording.
ORDER = "the recording comes first, then the actions: piga-import RECORDING ACTIONS.csv"

#: The first bytes of the image and video formats a recording comes in, and what they are called.
_MEDIA_MAGIC = ((b"GIF8", "a GIF"), (b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
                (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"), (b"\x1aE\xdf\xa3", "a Matroska or WebM video"),
                (b"BM", "a BMP image"))


def _media_kind(path: Path) -> str | None:
    """What image or video format ``path`` is, by its first bytes (the container's signature, which no text file
    written as actions starts with), or None."""
    try:
        with open(path, "rb") as file:
            head = file.read(12)
    except OSError:
        return None
    if head[4:8] == b"ftyp":  # the ISO base media files: MP4, MOV, M4V
        return "an MP4 or MOV video"
    if head[:4] == b"RIFF" and head[8:12] in (b"AVI ", b"WEBP"):
        return "an AVI video" if head[8:12] == b"AVI " else "a WebP image"
    return next((kind for magic, kind in _MEDIA_MAGIC if head.startswith(magic)), None)


def read_actions(path: str | Path) -> np.ndarray:
    """The actions of a CSV, one row per frame: float32 (F,).

    The CSV has one column, with an optional header row that names it ``u`` or ``action``, or several columns under
    a header row that names the action column ``u`` or ``action``. Commas, semicolons or tabs separate the columns, lines that start with ``#`` and blank
    lines before the header or after the last value are skipped, and a separator that ends every row (``0.26,``) is not
    a column. Values are written in ASCII decimal (:data:`_CSV_NUMBER`).

    Raises:
        FileNotFoundError: no such file.
        ValueError: a folder, an image or a video (the arguments swapped), the file is empty, a blank or ``#`` line
            comes before a value (a value missing or commented out there would shift every later action by a frame), a value is not a finite number or beyond
            ±:data:`piga.data.schema.MAX_ABS_ACTION` (the message gives the line), the action column cannot be told,
            or a row has another number of columns than the first.
    """
    p = Path(path)
    if p.is_dir():
        frames = any(f.suffix.lower() in FRAME_EXTENSIONS for f in p.iterdir())
        raise ValueError(f"{p} is a folder, not an actions CSV file" + (f" (a folder of frames: {ORDER})" if frames else ""))
    if not p.is_file():
        if p.exists():
            raise ValueError(f"{p}: is not a regular file (a pipe, a socket or a device), not an actions CSV file")
        raise FileNotFoundError(f"{p}: no such actions file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        if (kind := _media_kind(p)) is not None:  # the arguments swapped: "re-save it as UTF-8" would be no help
            raise ValueError(f"{p} is {kind}, not an actions CSV file; {ORDER}") from None
        if _is_hdf5(p):  # a data file, which no re-save makes a CSV
            raise ValueError(f"{p} is an HDF5 file (a data file of piga's?), not an actions CSV file; give the CSV of "
                             f"the recording's actions ({ORDER})") from None
        line = p.read_bytes()[:exc.start].count(b"\n") + 1
        raise ValueError(f"{p}: line {line}: byte 0x{exc.object[exc.start]:02x} is not UTF-8 text; save the file as "
                         "UTF-8 (or plain ASCII)") from None
    # blank lines and comment lines (``#``, as numpy's loadtxt skips them) are not rows; where actions follow them,
    # both are refused below
    lines = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{p}: the actions file is empty")
    delimiter = next((d for d in (",", ";", "\t") if d in lines[0][1]), ",")
    rows = [(number, [cell.strip() for cell in next(csv.reader([line], delimiter=delimiter))]) for number, line in lines]
    if all(len(row) > 1 and row[-1] == "" for _, row in rows):  # every row ends in a separator (``0.26,``): no column
        rows = [(number, row[:-1]) for number, row in rows]
    first_number, first = rows[0]
    column = 0
    header = _is_header(first)
    values = lines[1:] if header else lines
    if delimiter == "," and not (header and len(first) > 1) and values \
            and all(re.fullmatch(r"[-+]?\d+,\d+", line.strip()) for _, line in values):
        # "-0,5123" on every row: a decimal comma (a European locale's), or two columns of integers: either way one line
        raise ValueError(f"{p}: line {values[0][0]}: {values[0][1].strip()!r}, as every row, is one number with a decimal "
                         "comma or two columns of integers; write numbers with a decimal point, or, for two columns, "
                         "add a header that names the action column 'u' or 'action'")
    if header:
        names = [cell.lower() for cell in first]
        if len(first) == 1 and names[0] not in ACTION_COLUMNS:  # a word in place of the first value, or another name
            raise ValueError(f"{p}: line {first_number}: expected a finite number or a header naming the column 'u' or "
                             f"'action', got {first[0]!r}")
        if len(first) > 1:
            matches = [names.index(name) for name in ACTION_COLUMNS if name in names]
            if not matches:
                raise ValueError(f"{p}: line {first_number}: the header {first} names no column 'u' or 'action'")
            if len(matches) > 1:  # which of the two holds the actions is unknown
                raise ValueError(f"{p}: line {first_number}: the header {first} names both 'u' and 'action'; name one "
                                 "action column")
            column = matches[0]
            if names.count(names[column]) > 1:  # which of the two columns holds the actions is unknown
                raise ValueError(f"{p}: line {first_number}: the header {first} names {first[column]!r} more than once; "
                                 "name the action column once")
        rows = rows[1:]
        if not rows:
            raise ValueError(f"{p}: the actions file has a header and no values")
    elif len(first) > 1:
        raise ValueError(f"{p}: {len(first)} columns and no header row; add a header that names the action column "
                         f"'u' or 'action'")
    # a blank line before a value: a missing value there would shift every action after it by a frame, unseen
    # wherever the count still matches the frames (trailing blank lines are the file's end); so would a comment line
    # there, which may be a commented-out action (``#0.53``): both are skipped only before the header and at the end
    start = first_number if header else 0
    if skipped := next(((number, line.strip()) for number, line in enumerate(text.splitlines(), start=1)
                        if start < number < rows[-1][0] and (not line.strip() or line.lstrip().startswith("#"))), None):
        number, line = skipped
        after = next(n for n, _ in rows if n > number)
        if line:
            raise ValueError(f"{p}: line {number} is a comment ({line[:40]!r}), and actions follow it (line {after}): a "
                             "commented-out action would shift every later action by one frame; delete the line, or "
                             "write the action there")
        raise ValueError(f"{p}: line {number} is empty, and actions follow it (line {after}): a missing value would "
                         "shift every later action by one frame; write the missing action there, or delete the line")
    for number, row in rows:  # a ragged row: a stray separator, or a column shifted; which value is meant is unknown
        if len(row) != len(first):
            raise ValueError(f"{p}: line {number}: {len(row)} column(s), but line {first_number} has {len(first)}; give "
                             "every row the same columns")
    values = np.empty(len(rows), np.float64)
    for i, (number, row) in enumerate(rows):
        cell = row[column] if column < len(row) else ""
        value = _number(cell)
        if value is None:
            raise ValueError(f"{p}: line {number}: expected a finite number, got {cell!r} (write it in ASCII decimal "
                             "digits, such as -0.5 or 1e-3)")
        if math.isnan(value) or (math.isinf(value) and cell.strip("+-").isalpha()):  # written as nan, inf or infinity
            raise ValueError(f"{p}: line {number}: expected a finite number, got {cell!r}; write the action there")
        if abs(value) > MAX_ABS_ACTION:  # beyond float32 it would be stored as inf (1e400: beyond float64 too)
            raise ValueError(f"{p}: line {number}: the action {cell} is beyond ±{MAX_ABS_ACTION:g} (the pendulum's torque "
                             "is at most ±2); check the column's unit")
        if value != 0 and abs(value) < FLOAT32_TINY:  # float32 would store it as 0 or a rounded subnormal
            raise ValueError(f"{p}: line {number}: the action {cell} is nonzero and below {FLOAT32_TINY!s} in "
                             "magnitude, float32's smallest normal number: the file's float32 actions would hold it as 0 "
                             "or rounded; scale the actions to the env's units (the pendulum's torque is at most ±2)")
        values[i] = value
    return values.astype(np.float32)


#: The frames and actions written to the file at a time (whole sequences, at least one): the room the writer keeps
#: free on the disk as it writes is one slice, not the whole recording uncompressed.
WRITE_SLICE_BYTES = 16 * 1024**2


def _slice_sequences(steps: int, size: int) -> int:
    """Sequences of ``steps`` frames of ``size`` x ``size`` (and their actions) per write: at most
    :data:`WRITE_SLICE_BYTES`, at least one."""
    return max(1, WRITE_SLICE_BYTES // (steps * (size * size + 4)))


def _check_resources(n_frames: int, size: int, steps: int, target: Path) -> None:
    """Refuses, before decoding, a frame count and size (one frame per action) that cannot fit.

    Memory: the converted frames twice (the list and the stacked array) and one frame's conversion
    (~48 bytes per output pixel). Disk: the frames gzip-compressed
    (:data:`piga.io.resources.RECORDED_FRAME_COMPRESSION`) with HDF5's own bytes, and the room to write one slice of
    sequences of ``steps`` frames (:func:`_slice_sequences`).
    """
    from piga.io.resources import RECORDED_FRAME_COMPRESSION, check_memory, hdf5_file_overhead

    pixels = size * size
    what = f"{n_frames} frames of {size}x{size}"
    check_memory(2 * n_frames * pixels + 48 * pixels, what)
    # with the room the writer keeps free as it writes a slice, so that it does not refuse later
    step_bytes = pixels / RECORDED_FRAME_COMPRESSION + 4  # a frame compressed, its action raw
    sequences = -(-n_frames // steps)
    written = min(n_frames, _slice_sequences(steps, size) * steps) * step_bytes
    check_data_disk(target, n_frames * step_bytes + hdf5_file_overhead(sequences), written, sequences, what,
                    advice="free some space, write --out elsewhere, or give a smaller --image-size")  # (no count to lower)


def import_recording(
    recording: str | Path,
    actions: str | Path,
    out: str | Path,
    config: ImportConfig,
    overwrite: bool = False,
    command: str | None = None,
) -> ImportResult:
    """Reads a recording and its actions and writes them to ``out`` atomically, in piga's schema.

    Args:
        recording: a video file or a folder of frames.
        actions: the CSV of actions, one row per frame.
        out: the HDF5 file to write.
        config: the frame interval, the sequence length, the frame size and the split.
        overwrite: allow replacing an existing ``out``.
        command: stored in the attrs; None means this process's command line.

    Raises:
        FileNotFoundError, ValueError: missing or unreadable input, a count of actions that differs
            from the count of frames, or too few frames for one sequence. The message says which.
        OutputExistsError: ``out`` exists and ``overwrite`` is False.
    """
    target = check_writable_target(out, overwrite)  # before any decoding
    check_not_an_input(target, {"recording": recording, "actions file": actions})
    recording, actions = Path(recording), Path(actions)
    if not recording.exists():
        raise FileNotFoundError(f"{recording}: no such video file or frame folder")
    u = read_actions(actions)  # (F,)
    _check_resources(len(u), config.image_size, config.steps, target)
    frames, shape = _read_recording(recording, config.image_size)  # (F, S, S)
    if len(u) != len(frames):
        raise ValueError(f"{actions} has {counted(len(u), 'action')} but {recording} has "
                         f"{counted(len(frames), 'frame')}; give one action per frame")
    if not frames_have_signal(frames[None]):  # the recording's fault, said before a file is written (not the file's)
        raise blank_error(recording, int(frames.min()), int(frames.max()), recorded=True)
    t = config.steps
    n = len(frames) // t
    if n < 1:
        lower = f"lower --steps to {len(frames)}" if len(frames) >= 2 else "a recording needs at least 2"
        raise ValueError(f"{recording} has {counted(len(frames), 'frame')}, too few for one "
                         f"sequence of {t} frames ({lower})")
    if not frames_move(frames[: n * t].reshape(n, t, *frames.shape[1:])):  # the recording's fault, said as such
        raise still_error(recording, recorded=True)
    counts = split_counts(n, config.split)
    dropped = len(frames) - n * t
    size = config.image_size
    attrs = {
        "system": "pendulum",
        "dt": float(config.dt),
        "params": {},
        "seed": -1,
        "command": command if command is not None else shlex.join(sys.argv),
        "source": str(recording),
        "source_actions": str(actions),
        "source_frames": len(frames),
        "dropped_frames": dropped,
        "split_counts": dict(zip(SPLITS, counts)),
    }
    with DatasetWriter(target, n, t, (size, size), 1, None, attrs, overwrite=overwrite) as writer:
        sequences, sequence_actions = frames[: n * t].reshape(n, t, size, size), u[: n * t].reshape(n, t, 1)
        step = _slice_sequences(t, size)
        for start in range(0, n, step):
            writer.write(start, sequences[start : start + step], sequence_actions[start : start + step])
        writer.set_split(np.repeat(np.arange(3, dtype=np.int8), counts))
    return ImportResult(target, n, len(frames), dropped, dict(zip(SPLITS, counts)), shape)


__all__ = ["ImportConfig", "ImportResult", "frame_files", "import_recording", "read_actions", "read_recording",
           "recording_frame_seconds"]
