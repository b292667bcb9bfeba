"""PNG parts of a form read into arrays: a density map, a texture mask, an image painted over
the map. One reader, so every part is checked alike: a PNG, its size from the header before
a pixel is decoded, its chunks whole and its rows all there (the compressed rows inflate to
exactly the header's rows), a palette image's indices within its palette, its memory charged
to the job, a refusal naming the part otherwise."""

from __future__ import annotations

import io
import math
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pyspng
from PIL import Image

from .errors import InvalidInput

#: Bytes a pixel costs while read and used: the decoded pixels, the float64 planes (values,
#: alpha, their product) and a plane's running sums (measured: 32 to 41 for RGB and RGBA).
BYTES_PER_PIXEL = 48
#: The largest side of a PNG part (a texture mask of 8192 x 8192 is a large one).
MAX_SIDE = 8192
#: The most pixels of a PNG part by default (MESHFLAT_MAX_IMAGE_PIXELS): 4096 x 4096, the
#: largest framed image (params.image_width and image_height), some 800 MB decoded.
MAX_PIXELS = 4096 * 4096
#: The PNG signature, and the channels of each colour type (grey, RGB, palette, grey and
#: alpha, RGBA).
_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
#: Adam7's passes: the first column and row of each, and its steps across and down.
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
          (0, 1, 1, 2))  # fmt: skip
#: The bytes inflated at a time while the rows are counted (none of them kept).
_INFLATE_BLOCK = 1 << 20
#: Where a PNG's header gives its bit depth (after the signature, the IHDR chunk's length,
#: type, width and height); its colour type follows.
_IHDR_DEPTH = 24
#: The PNG colour types read by libspng at 16 bits, and their channels: RGB and RGBA (not
#: grey and alpha, 4, which Pillow reads, at 8 bits, as RGBA).
_COLOUR_TYPES = {2: 3, 6: 4}
#: Grey from red, green and blue (Rec. 709, on the stored values).
_LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class Png:
    """A PNG's pixels: ``values`` (h, w) float in [0, 1] (grey, or the luminance of a colour
    image), ``alpha`` (h, w) float in [0, 1] or None. 16-bit grey and colour PNGs keep their
    16 bits; a 16-bit grey-and-alpha one is read at 8 bits (neither Pillow nor libspng
    decodes it at 16)."""

    values: np.ndarray
    alpha: np.ndarray | None


def read_png(
    data: bytes,
    part: str,
    charge: Callable[[int], None],
    size: tuple[int, int] | None = None,
    grey_only: bool = False,
    max_pixels: int = MAX_PIXELS,
) -> Png:
    """The PNG part ``part``: 8- or 16-bit grey, grey with alpha, RGB or RGBA (a palette
    image as its RGB(A)); of ``size`` (width, height) when given, of at most ``max_pixels``.
    What decoding it takes is given to ``charge`` (bytes) before a pixel is decoded.

    Raises
    ------
    InvalidInput
        Naming the part: not a PNG, another size, too many pixels, truncated or inconsistent
        (a chunk cut short or corrupt, rows missing or too many, a palette image without its
        palette or with indices past it), a mode it cannot be (``grey_only``: only grey, with
        alpha or not, 8 bits).
    """
    try:
        image = Image.open(io.BytesIO(data))
        if image.format != "PNG":
            raise InvalidInput(part, f"a PNG, not {image.format}")
        width, height = image.size
        if size is not None and image.size != size:  # from the header: nothing decoded yet
            raise InvalidInput(
                part,
                f"{width} x {height} pixels; the PNG answer's framing is params.image_width x "
                f"image_height, {size[0]} x {size[1]}",
            )
        if max(width, height) > MAX_SIDE:
            raise InvalidInput(part, f"{width} x {height} pixels; at most {MAX_SIDE} a side")
        if width * height > max_pixels:
            raise InvalidInput(
                part,
                f"{width} x {height} pixels ({width * height:,}); at most {max_pixels:,} "
                "(MESHFLAT_MAX_IMAGE_PIXELS)",
            )
        if grey_only and image.mode not in ("L", "LA"):
            raise InvalidInput(
                part, f"8-bit grey (mode L, or LA: the alpha is left out), not mode {image.mode}"
            )
        palette = _checked(data, part)
        charge(BYTES_PER_PIXEL * width * height)
        channels = _COLOUR_TYPES.get(data[_IHDR_DEPTH + 1])
        if channels is not None and data[_IHDR_DEPTH] == 16:
            # Pillow would read 8 bits of them; libspng gives RGB an alpha of its own.
            return _colour(pyspng.load(data)[..., :channels], 65535.0)
        image.load()
        return _pixels(image, part, palette)
    except (
        OSError, ValueError, SyntaxError, RuntimeError, zlib.error, Image.DecompressionBombError,
    ) as error:  # fmt: skip
        raise InvalidInput(part, f"not a readable PNG ({type(error).__name__})") from None


def _checked(data: bytes, part: str) -> int:
    """The entries of the PNG's palette (0 without one), once its chunks are found whole
    (each CRC right, up to IEND), its compressed rows one run of IDAT chunks that inflates to
    exactly the header's rows (a filter byte and the row's bytes each, Adam7's passes for an
    interlaced image) and a palette image has its palette. Pillow would read missing rows as
    0, silently.

    Raises
    ------
    InvalidInput
        Naming the part and what is wrong.
    """
    chunks = list(_chunks(data, part))
    if chunks[0][0] != b"IHDR" or len(chunks[0][1]) != 13:
        raise InvalidInput(part, "not a readable PNG: it does not start with its IHDR chunk")
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    kinds = [kind for kind, _ in chunks]
    first = kinds.index(b"IDAT") if b"IDAT" in kinds else len(kinds)
    run = kinds[first:].count(b"IDAT")
    if run == 0 or kinds[first : first + run] != [b"IDAT"] * run:
        raise InvalidInput(part, "its image data (IDAT chunks) is missing or not in one run")
    palette = next((len(body) // 3 for kind, body in chunks if kind == b"PLTE"), 0)
    if colour == 3 and not 0 < palette <= 1 << depth:
        raise InvalidInput(
            part, f"a palette image needs its palette (PLTE), of 1 to {1 << depth} colours"
        )
    expected = _row_bytes(width, height, _CHANNELS[colour] * depth, interlace)
    found, complete = _inflated(chunks[first : first + run], expected)
    rows = f"the {expected:,} bytes of the {height} rows its header gives"
    if found > expected:
        raise InvalidInput(part, f"inconsistent: its image data inflates to more than {rows}")
    if found < expected:
        raise InvalidInput(
            part, f"truncated: its image data inflates to {found:,} bytes, not {rows}"
        )
    if not complete:
        raise InvalidInput(part, "truncated: its image data's zlib stream has no end")
    return palette


def _row_bytes(width: int, height: int, bits: int, interlace: int) -> int:
    """The bytes of an image's rows, each a filter byte and ``bits`` a pixel rounded up to
    bytes; an interlaced image's, Adam7's seven passes' (an empty pass has no rows)."""
    total = 0
    for x, y, dx, dy in _ADAM7 if interlace else ((0, 0, 1, 1),):
        columns, rows = math.ceil(max(width - x, 0) / dx), math.ceil(max(height - y, 0) / dy)
        if columns and rows:
            total += rows * (1 + math.ceil(columns * bits / 8))
    return total


def _chunks(data: bytes, part: str) -> Iterator[tuple[bytes, memoryview]]:
    """The PNG's chunks, ``(type, body)``, up to IEND, each CRC checked."""
    view, at = memoryview(data), len(_SIGNATURE)
    while True:
        if at + 12 > len(data):
            raise InvalidInput(part, "truncated: the PNG ends before its IEND chunk")
        length, kind = struct.unpack_from(">I4s", data, at)
        end = at + 12 + length
        if end > len(data):
            raise InvalidInput(part, f"truncated: its {kind.decode('latin-1')} chunk is cut short")
        body = view[at + 8 : end - 4]
        if zlib.crc32(body, zlib.crc32(kind)) != struct.unpack_from(">I", data, end - 4)[0]:
            raise InvalidInput(part, f"corrupt: its {kind.decode('latin-1')} chunk's CRC is wrong")
        yield kind, body
        if kind == b"IEND":
            return
        at = end


def _inflated(chunks, expected: int) -> tuple[int, bool]:
    """The bytes the IDAT ``chunks`` inflate to (counted a block at a time, none kept; a
    count past ``expected`` stops there) and whether their zlib stream ends."""
    inflater, found = zlib.decompressobj(), 0
    for _, body in chunks:
        pending = body
        while pending and found <= expected and not inflater.eof:
            found += len(inflater.decompress(pending, _INFLATE_BLOCK))
            pending = inflater.unconsumed_tail
    if found <= expected and not inflater.eof:
        found += len(inflater.flush())
    return found, inflater.eof


def _pixels(image: Image.Image, part: str, palette: int) -> Png:
    if image.mode == "P":
        if np.asarray(image).max(initial=0) >= palette:
            raise InvalidInput(part, f"a palette index past its palette's {palette} colours")
        image = image.convert("RGBA" if "transparency" in image.info else "RGB")
    if image.mode in ("L", "LA"):
        values = np.asarray(image.getchannel(0), dtype=np.float64) / 255.0
        alpha = image.getchannel(1) if image.mode == "LA" else None
    elif image.mode in ("I;16", "I;16B", "I"):
        values, alpha = np.asarray(image, dtype=np.float64) / 65535.0, None
    elif image.mode in ("RGB", "RGBA"):
        return _colour(np.asarray(image), 255.0)
    else:
        raise InvalidInput(
            part, f"grey, grey and alpha, RGB or RGBA, 8 or 16 bits; not mode {image.mode}"
        )
    if alpha is not None:
        alpha = np.asarray(alpha, dtype=np.float64) / 255.0
    np.clip(values, 0.0, 1.0, out=values)
    return Png(values, alpha)


def _colour(pixels: np.ndarray, full: float) -> Png:
    """``pixels`` (h, w, 3 or 4), RGB or RGBA of which ``full`` is the top value: the
    luminance and the alpha, if any."""
    # A channel at a time: two float planes at most beside the pixels.
    values = pixels[..., 0] * (_LUMA[0] / full)
    for channel in (1, 2):
        values += pixels[..., channel] * (_LUMA[channel] / full)
    np.clip(values, 0.0, 1.0, out=values)
    alpha = pixels[..., 3] / full if pixels.shape[-1] == 4 else None
    return Png(values, alpha)
