"""Pictures of the scene converted as the environment converts its render (no torch).

The conversion is a centre crop to a square, ``cv2.resize(..., INTER_AREA)`` to the model's size,
then Gymnasium's gray weights (0.2125, 0.7154, 0.0721), truncated to uint8. That is
``ResizeObservation`` then ``GrayscaleObservation``, as in :func:`envs.make_pixel_pendulum`.
Goal images (:mod:`piga.control.goal`) and imported recordings (:mod:`piga.data.importer`) both use it.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np

#: Gymnasium's GrayscaleObservation weights (R, G, B).
GRAY_WEIGHTS = np.array([0.2125, 0.7154, 0.0721])


def scene_to_gray(img: np.ndarray, size: int) -> np.ndarray:
    """A gray or RGB(A) picture of any size, as the env would see it: uint8 (size, size).

    An opaque alpha channel (of gray or RGB) is dropped. A picture that is not uint8 is scaled by its own maximum to 0..255.

    Raises:
        ValueError: ``img`` is not a 2-D gray or RGB(A) picture of at least 2x2 pixels, it has transparent pixels
            (what the camera would see behind them is unknown), or (not uint8) values that are not finite or below 0.
    """
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] in (2, 4):  # gray or RGB, and alpha (a PNG's "LA" or "RGBA")
        alpha = img[..., -1]
        opaque = np.iinfo(alpha.dtype).max if np.issubdtype(alpha.dtype, np.integer) else 1.0
        if (see_through := int(np.count_nonzero(alpha < opaque))) > 0:
            raise ValueError(f"{see_through} of its {alpha.size} pixels are transparent (alpha below {opaque:g}), and "
                             "what the camera would see behind them is unknown; flatten it onto the scene's background "
                             "first")
        img = img[..., :-1]
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise ValueError(f"expected a 2-D gray or RGB image, got shape {img.shape}")
    if min(img.shape[:2]) < 2:
        raise ValueError(f"the image is {img.shape[1]}x{img.shape[0]} pixels, too small (at least 2x2)")
    if img.dtype != np.uint8:
        img = img.astype(np.float64)
        if (bad := int(np.count_nonzero(~np.isfinite(img)))) > 0:
            raise ValueError(f"{bad} of its {img.size} pixel values are not finite (NaN or infinity); a picture's values "
                             "are brightnesses: replace them (with 0, say) first")
        if (low := float(img.min())) < 0:
            raise ValueError(f"its values go below 0 (down to {low:g}); a picture's values are brightnesses from 0 "
                             "up: shift them (a picture in -1..1, say, to 0..2) first")
        img = np.clip(img / (img.max() or 1) * 255, 0, 255).astype(np.uint8)
    h, w = img.shape[:2]
    side = min(h, w)
    top, left = (h - side) // 2, (w - side) // 2
    img = img[top : top + side, left : left + side]  # (side, side[, 3])
    img = cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
    if img.ndim == 3:
        img = np.sum(img * GRAY_WEIGHTS, axis=-1).astype(np.uint8)  # (size, size)
    return img


#: Why a file whose reader warned of damage that it read past is refused (:func:`reader_log`).
DAMAGED_READ = "damaged: its reader could not find all of it, as in a file cut short"


@contextmanager
def reader_log() -> Iterator[list[logging.LogRecord]]:
    """Inside: the warnings that the TIFF reader logs (tifffile: "<tifffile.TiffPages @8> invalid page offset 21128")
    are kept in the list yielded, not written to stderr, where Python's last-resort handler put them above the
    command's own one line."""
    caught: list[logging.LogRecord] = []

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            caught.append(record)

    logger = logging.getLogger("tifffile")
    handler, propagate = _Keep(logging.WARNING), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield caught
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Reads a PNG, JPEG or other still image as an array, unconverted (an animation of one frame: that frame).

    Raises:
        FileNotFoundError: no such file.
        IsADirectoryError: ``path`` is a folder.
        ValueError: the file is not a readable image, or is an animation of several frames.
    """
    p = Path(path)
    if p.is_dir():
        raise IsADirectoryError(f"{p}: is a folder, not an image file")
    if not p.is_file():
        if p.exists():  # /dev/zero, a pipe: reading one could take all the memory, or wait for ever
            raise ValueError(f"{p}: not a regular file (a device or a pipe); give an image file")
        raise FileNotFoundError(f"{p}: no such image file")
    meta = _pillow_meta(p)
    # Pillow is asked for RGB where the file is CMYK (ink, not RGB and alpha), and for RGBA where it has a transparent
    # colour or palette entry (a PNG's tRNS, a GIF's), which it reads as opaque RGB or gray otherwise: its alpha is
    # then checked as any other's
    mode = "RGB" if meta.get("mode") == "CMYK" else "RGBA" if "transparency" in meta else None
    with reader_log() as caught:
        image = _read_image(p, mode, meta)
    if caught:  # a TIFF cut short: its first page was taken for the image
        raise ValueError(f"{p}: not a readable image ({DAMAGED_READ}); give a PNG or a JPEG")
    if image.size == 0:  # what a plugin made of a file that is not its own
        raise ValueError(f"{p}: not a readable image (it has no pixels)")
    if image.ndim == 4:  # (frames, H, W, C): an animation (a GIF, an APNG) is read whole
        if len(image) > 1:
            raise ValueError(f"{p}: an animation of {len(image)} frames; give one image")
        image = image[0]
    return image


def _read_image(p: Path, mode: str | None, meta: dict[str, Any]) -> np.ndarray:
    """:func:`read_image`'s array, as the file's reader gives it.

    Raises:
        ValueError: the file is not a readable image (the message names it and why).
    """
    import imageio.v3 as iio

    try:
        # imageio tries its plugins in turn, and some warn of a file that is not theirs (spe.py read a torch
        # checkpoint as 0 frames, warning "The file header ... claims there are 7 frames"): the one line of the
        # error says it. Pillow's warning of a huge image (above MAX_IMAGE_PIXELS, below twice that) is dropped
        # too: the image is read whole all the same, and past twice the limit the error below says so.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if mode is not None:
                image = np.asarray(iio.imread(p, plugin="pillow", mode=mode, rotate=True))
            else:
                try:
                    try:
                        image = np.asarray(iio.imread(p, rotate=True))  # turned as its EXIF orientation says
                    except TypeError:  # a plugin that has no orientation to apply (tifffile)
                        image = np.asarray(iio.imread(p))
                except Exception:
                    if not meta:
                        raise
                    # a file that Pillow reads, which the plugin imageio chose could not (an LZW TIFF, which tifffile
                    # decodes only with the imagecodecs package): Pillow's reading
                    image = np.asarray(iio.imread(p, plugin="pillow", rotate=True))
    except Exception as exc:  # imageio raises many types for foreign or corrupt files
        if exc.__class__.__name__ == "DecompressionBombError":  # Pillow's guard against huge images
            raise ValueError(f"{p}: the image is too large to read (more than Pillow's limit of "
                             f"{_pillow_limit()} pixels, twice its warning); give a smaller picture") from None
        why = ("the file is empty" if p.is_file() and p.stat().st_size == 0 else
               "no reader knows its format" if "Could not find a backend" in str(exc) else
               "damaged, or not a picture in the format its suffix names; give a PNG or a JPEG")
        raise ValueError(f"{p}: not a readable image ({why})") from None
    return image


def _pillow_meta(path: Path) -> dict[str, Any]:
    """Pillow's metadata of an image file ("mode": "RGB", "CMYK", ...; "transparency" where it has a transparent
    colour), or {} where Pillow does not read it."""
    import imageio.v3 as iio

    try:
        with warnings.catch_warnings():  # Pillow's of a huge image: see read_image
            warnings.simplefilter("ignore")
            return dict(iio.immeta(path, plugin="pillow"))
    except Exception:  # not Pillow's format: tifffile and the others read no CMYK or transparent colour here
        return {}


def _pillow_limit() -> str:
    """Pillow's error limit on pixels per image, for the message: twice ``Image.MAX_IMAGE_PIXELS``."""
    from PIL import Image

    return f"{2 * Image.MAX_IMAGE_PIXELS:,}" if Image.MAX_IMAGE_PIXELS else "no"


def load_scene_image(path: str | os.PathLike[str], size: int) -> np.ndarray:
    """Reads a PNG or JPEG of any size as the env would see it: uint8 (size, size).

    Raises:
        FileNotFoundError: no such file.
        IsADirectoryError: ``path`` is a folder.
        ValueError: the file is not a readable image, or too small.
    """
    img = read_image(path)
    try:
        return scene_to_gray(img, size)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
