"""PNG parts of a form read into arrays: a density map, a texture mask, an image painted over
the map. One reader, so every part is checked alike: a PNG, its size from the header before
a pixel is decoded, its memory charged to the job, a refusal naming the part otherwise."""

from __future__ import annotations

import io
from collections.abc import Callable
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
) -> Png:
    """The PNG part ``part``: 8- or 16-bit grey, grey with alpha, RGB or RGBA (a palette
    image as its RGB(A)); of ``size`` (width, height) when given. What decoding it takes is
    given to ``charge`` (bytes) before a pixel is decoded.

    Raises
    ------
    InvalidInput
        Naming the part: not a PNG, another size, a mode it cannot be (``grey_only``: only
        grey, with alpha or not, 8 bits).
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
        if grey_only and image.mode not in ("L", "LA"):
            raise InvalidInput(
                part, f"8-bit grey (mode L, or LA: the alpha is left out), not mode {image.mode}"
            )
        charge(BYTES_PER_PIXEL * width * height)
        channels = _COLOUR_TYPES.get(data[_IHDR_DEPTH + 1])
        if channels is not None and data[_IHDR_DEPTH] == 16:
            # Pillow would read 8 bits of them; libspng gives RGB an alpha of its own.
            return _colour(pyspng.load(data)[..., :channels], 65535.0)
        return _pixels(image, part)
    except (OSError, ValueError, SyntaxError, RuntimeError, Image.DecompressionBombError) as error:
        raise InvalidInput(part, f"not a readable PNG ({type(error).__name__})") from None


def _pixels(image: Image.Image, part: str) -> Png:
    if image.mode == "P":
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
    values = np.clip((pixels[..., :3] @ _LUMA) / full, 0.0, 1.0)
    alpha = pixels[..., 3] / full if pixels.shape[-1] == 4 else None
    return Png(values, alpha)
