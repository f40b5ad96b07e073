"""Camera images at the file edge: PNG and JPEG, 8- or 16-bit, grey or colour, any size.

Pixels are read as the sensor wrote them: a JPEG's EXIF orientation tag is ignored, so that
photographs taken with the camera turned share one pixel frame (one set of intrinsics)
instead of coming out rotated, at swapped sizes. A 16-bit image (a machine-vision camera's
10- or 12-bit data) is scaled linearly so that its brightest pixel is 255: its top byte
alone would leave 12-bit data at 0-15.

An IMAGES argument is a folder (its image files, sorted by name) or a list of files.
Pixel coordinates elsewhere in the package have integer values at pixel centres
(X = column, Y = row); the arrays here are indexed ``[row, column]``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from ..errors import DataError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
"""Suffixes of the image files taken from a folder (compared in lower case)."""


def is_image_file(path: str | Path) -> bool:
    """True if ``path`` has a PNG or JPEG suffix (any case)."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def list_images(folder: str | Path) -> list[Path]:
    """The PNG/JPEG files of ``folder`` (not recursive), sorted by file name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: not a folder")
    files = sorted((p for p in folder.iterdir() if p.is_file() and is_image_file(p)),
                   key=lambda p: p.name)
    if not files:
        raise DataError(f"{folder}: no .png, .jpg or .jpeg files")
    return files


def image_paths(images: str | Path | Iterable[str | Path]) -> list[Path]:
    """The files an IMAGES argument names: a folder's images sorted by name, or the list."""
    if isinstance(images, (str, Path)):
        path = Path(images)
        if path.is_dir():
            return list_images(path)
        return [path]
    paths = [Path(p) for p in images]
    if not paths:
        raise DataError("no image files given")
    return paths


def _decode(path: Path, flags: int) -> np.ndarray:
    import cv2

    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    if data.size == 0:
        raise DataError(f"{path}: empty file")
    image = cv2.imdecode(data, flags)
    if image is None:
        raise DataError(f"{path}: not a PNG or JPEG image that can be decoded")
    return image


def read_grey(path: str | Path) -> np.ndarray:
    """The image at ``path`` as 8-bit grey, shape (height, width), uint8 (colour is
    converted with the usual luma weights; 16 bits scaled to the brightest pixel; EXIF
    orientation ignored, see the module docstring)."""
    import cv2

    image = _decode(Path(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH
                    | cv2.IMREAD_IGNORE_ORIENTATION)
    if image.dtype != np.uint8:
        peak = max(float(image.max()), 1.0)
        image = np.round(image * (255.0 / peak)).astype(np.uint8)
    return image


def read_rgb(path: str | Path) -> np.ndarray:
    """The image at ``path`` as 8-bit RGB, shape (height, width, 3), uint8."""
    import cv2

    image = _decode(Path(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write an 8-bit grey (h, w) or RGB (h, w, 3) image as PNG, atomically."""
    import cv2

    from .atomic import write_bytes_atomic

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise DataError(f"{path}: expected an 8-bit grey or RGB image, got {image.dtype} "
                        f"{image.shape}")
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise DataError(f"{path}: cannot encode the image as PNG")
    write_bytes_atomic(path, encoded.tobytes())
