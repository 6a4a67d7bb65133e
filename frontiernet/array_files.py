"""Arrays and images read from the user's files, checked before they are decoded: a ``.npy`` whose header
claims more than the file holds, another format named ``.npy``, an array of Python objects, an image whose
header claims more pixels than OpenCV decodes or a truncated JPEG or PNG are refused in one line naming the file
(:class:`~frontiernet.errors.InputError`); what the image libraries print to stderr themselves (libpng's "Read Error")
never reaches the user beside it (:func:`native_stderr`)."""

from __future__ import annotations

import os
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from .errors import InputError
from .io import input_file

NPY_MAGIC = b"\x93NUMPY"
"""The first bytes of every .npy file."""
OTHER_FORMATS = {b"\x89PNG": "a PNG image", b"\xff\xd8\xff": "a JPEG image", b"PK\x03\x04": "a zip archive (.npz?)",
                 b"II*\x00": "a TIFF image", b"MM\x00*": "a TIFF image"}
"""Signatures of files that are named .npy by mistake, and what they are."""


def npy_overclaim(stream, size: int) -> str | None:
    """Why the .npy bytes of binary `stream` (at their start; `size` bytes from there) cannot hold the array
    their header describes, or None when they can (or the header is not one this reads: numpy says so then).
    A header is a promise: (100000, 100000) float32 over 64 bytes of data made numpy allocate 37 GiB before it
    found out (issue 55's tenth probe)."""
    from numpy.lib import format as npy_format

    readers = {(1, 0): npy_format.read_array_header_1_0, (2, 0): npy_format.read_array_header_2_0}
    try:
        shape, _, dtype = readers[npy_format.read_magic(stream)](stream)
    except (KeyError, ValueError, OSError, EOFError):
        return None
    claimed, held = int(np.prod(shape, dtype=object)) * dtype.itemsize, size - stream.tell()
    return (f"its header claims a {'x'.join(map(str, shape)) or 'scalar'} {dtype} array of {claimed:,} bytes, "
            f"the file holds {held:,}") if claimed > held else None


def read_npy(path: str | Path, mmap_mode: str | None = None) -> np.ndarray:
    """The array of .npy file `path` (memory-mapped with `mmap_mode`; never unpickled); InputError
    naming the file when it is missing, empty, another format named .npy (a PNG renamed) or an
    array of Python objects."""
    path = input_file(path, ".npy array")
    with open(path, "rb") as handle:
        head = handle.read(len(NPY_MAGIC))
    if not head.startswith(NPY_MAGIC):
        kind = next((name for magic, name in OTHER_FORMATS.items() if head.startswith(magic)), None)
        reason = ("empty file" if not head else f"the file is {kind}, named .npy" if kind
                  else "no .npy header: another format named .npy?")
        raise InputError(f"{path}: not a readable .npy array ({reason})")
    with open(path, "rb") as handle:
        overclaim = npy_overclaim(handle, path.stat().st_size)
    if overclaim is not None:
        raise InputError(f"{path}: not a readable .npy array ({overclaim}: truncated or corrupt)")
    try:
        return np.load(path, mmap_mode=mmap_mode, allow_pickle=False)
    except ValueError as error:
        if "pickle" in str(error):  # numpy's advice is to unpickle it: code could run
            raise InputError(f"{path}: not a readable .npy array (it holds Python objects, not numbers)") from None
        raise InputError(f"{path}: not a readable .npy array ({error})") from None
    except (OSError, EOFError) as error:  # EOFError: a truncated file
        raise InputError(f"{path}: not a readable .npy array ({error or 'truncated file'})") from None


def cv_max_image_pixels() -> int:
    """The most pixels OpenCV decodes of one image (``CV_IO_MAX_IMAGE_PIXELS``, 2**30 unless the environment
    sets it): it refuses a larger header before it decodes anything."""
    try:
        return int(os.environ.get("CV_IO_MAX_IMAGE_PIXELS", 2**30))
    except ValueError:
        return 2**30


def _check_jpeg_complete(path: Path, what: str) -> None:
    """InputError naming JPEG file `path` when it ends before its image does: no end-of-image marker
    (FF D9) after its last start-of-scan (FF DA; entropy-coded data never holds FF DA, and a thumbnail's
    end marker comes before the main image's scans). libjpeg would decode what is there and print its
    own "Premature end of JPEG file" line to stderr beside ours; other formats pass untouched."""
    with open(path, "rb") as file:
        if file.read(3) != b"\xff\xd8\xff":
            return
        data = file.read()
    if data.rfind(b"\xff\xd9") < data.rfind(b"\xff\xda"):
        raise InputError(f"{path}: a truncated JPEG (the file ends inside its image data) ({what})")


PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
"""The first bytes of every PNG file."""


def _check_png_complete(path: Path, what: str) -> None:
    """InputError naming PNG file `path` when it ends before its last chunk (IEND) does: a chunk whose length
    runs past the file's end, or no IEND chunk at all (the chunks are walked by their headers; nothing is
    decoded). libpng would print its own "libpng error: Read Error" line to stderr beside ours; other formats
    pass untouched."""
    size = path.stat().st_size
    with open(path, "rb") as file:
        if file.read(len(PNG_MAGIC)) != PNG_MAGIC:
            return
        at, kind = len(PNG_MAGIC), None
        while kind != b"IEND":
            header = file.read(8)
            if len(header) < 8:
                break
            length, kind = int.from_bytes(header[:4], "big"), header[4:]
            at += 12 + length  # length, type, data, CRC
            if at > size:
                break
            file.seek(at)
    if kind != b"IEND" or at > size:
        where = "before its first chunk" if kind is None else \
            f"inside its {kind.decode('latin-1')} chunk" if at > size else "before its closing IEND chunk"
        raise InputError(f"{path}: a truncated PNG (the file ends {where}) ({what})")


class _Captured:
    """What :func:`native_stderr` caught from the image libraries (``lines``, libpng's), once its block has ended."""

    def __init__(self) -> None:
        self.lines: list[str] = []


@contextmanager
def native_stderr() -> Iterator[_Captured]:
    """Catch what C libraries write to file descriptor 2 during the block (libpng's ``libpng error: Read Error``
    for a damaged PNG, printed beside our own one-line refusal): the block's ``as`` value holds libpng's lines as
    ``lines`` afterwards, for the caller's message; anything else written there meanwhile (another thread's
    output) is written out again. Python's own stderr is flushed first."""
    captured = _Captured()
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no descriptor 2 to redirect: nothing reaches a user there either
        yield captured
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield captured
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            lines = sink.read().decode("utf-8", "replace").splitlines(keepends=True)
            captured.lines = [line.strip() for line in lines if line.startswith("libpng ")]
            rest = "".join(line for line in lines if not line.startswith("libpng "))
            if rest:
                sys.stderr.write(rest)
                sys.stderr.flush()


def read_image(path: str | Path, flags: int, what: str = "image") -> np.ndarray:
    """``cv2.imread(path, flags)`` of input file `path` (:func:`input_file`, `what`: what the file is to the
    user); InputError naming it when OpenCV cannot read it, or when its header claims more pixels than OpenCV
    decodes (:func:`cv_max_image_pixels`: a PNG whose header says 100,000 px a side, refused before any
    pixel is decoded)."""
    import cv2

    path = input_file(path, what)
    _check_jpeg_complete(path, what)
    _check_png_complete(path, what)
    try:
        with native_stderr() as caught:  # libpng's own lines for a damaged PNG: in our message, not beside it
            image = cv2.imread(str(path), flags)
    except cv2.error as error:
        if "CV_IO_MAX_IMAGE_PIXELS" in str(error):
            raise InputError(f"{path}: its header claims more than {cv_max_image_pixels():,} pixels, the most "
                             f"OpenCV decodes (CV_IO_MAX_IMAGE_PIXELS); refused before decoding ({what})") from None
        raise InputError(f"{path}: not a readable {what} (OpenCV: {str(error).strip().splitlines()[-1]})") from None
    if image is None:
        reason = "; ".join(line.replace("libpng error: ", "") for line in caught.lines if "error" in line)
        raise InputError(f"{path}: not a readable {what}{f' (libpng: {reason})' if reason else ''}")
    return image


__all__ = ["NPY_MAGIC", "OTHER_FORMATS", "PNG_MAGIC", "npy_overclaim", "read_npy", "cv_max_image_pixels",
           "native_stderr", "read_image"]
