"""PNG parts (a ``mask``, a ``density_map``, an ``image``) are read whole or not at all: a PNG
cut short, with more rows than its header gives or a corrupt chunk, a palette image without
its palette or with indices past it, or more pixels than MESHFLAT_MAX_IMAGE_PIXELS is a 422
naming the part, decided before its pixels are decoded or charged where it can be."""

from __future__ import annotations

import json
import struct
import zlib
from functools import cache

import httpx
import numpy as np
import pytest

from service.settings import MiB, Settings

from .conftest import started
from .test_api import problem
from .test_painted import VERTICES, textured_obj
from .test_sites import sites_with_map
from .test_transfer import transfer

pytestmark = [pytest.mark.anyio, pytest.mark.filterwarnings("error::RuntimeWarning")]

#: fsaverage's texture coordinates from x and y: every face on a mask image.
UV = np.column_stack([VERTICES[:, 0], VERTICES[:, 1]]) / 260 + 0.5


@cache
def textured() -> bytes:
    return textured_obj(UV)


#: The framings of the parts: transfer's (test_transfer.PARAMS) and sites' default.
SIZES = {"image": (900, 600), "density_map": (1200, 800), "mask": (256, 256)}


def chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def png(width: int, height: int, colour: int, depth: int, raw: bytes, *before: bytes) -> bytes:
    """A PNG of the filtered rows ``raw``, whatever the header says; ``before`` are chunks
    ahead of its IDAT (a palette)."""
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + b"".join(before)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def grey(width: int, height: int, rows: int, depth: int = 8, level: int = 200) -> bytes:
    """A grey PNG whose header gives ``height`` rows and whose data holds ``rows`` of them,
    each of ``level`` (of 255)."""
    row = b"\x00" + bytes([level]) * (width * depth // 8)
    return png(width, height, 0, depth, row * rows)


async def send(client, part: str, data: bytes) -> httpx.Response:
    """``data`` as the ``part`` its route reads, with the params that want it."""
    if part == "image":
        return await transfer(client, {}, {"image": ("map.png", data)})
    if part == "density_map":
        return await sites_with_map(client, {"density_range": [0, 20]}, data)
    form = {"mesh": ("head.obj", textured()), "mask": ("mask.png", data)}
    params = {"region": {"texture_mask": {"min": 0.5}}, "center": "bbox_center"}
    return await client.post("/v1/flatten", files=form, data={"params": json.dumps(params)})


@pytest.mark.parametrize(
    ("part", "depth"), [("image", 8), ("image", 16), ("density_map", 8), ("mask", 8)]
)
async def test_a_png_part_with_rows_missing_is_a_422_naming_it(client, part, depth):
    """10 rows of the header's in the image data: Pillow read the rest as 0 (every transfer
    value at the range's low end, coverage 1; no site from a density map)."""
    width, height = SIZES[part]
    whole = await send(client, part, grey(width, height, height, depth))
    assert whole.status_code == 200, whole.text
    body = problem(await send(client, part, grey(width, height, 10, depth)), 422, part)
    assert "truncated" in body["detail"] and f"the {height} rows" in body["detail"]


@pytest.mark.parametrize("part", ["image", "density_map", "mask"])
async def test_a_png_part_with_more_rows_than_its_header_or_a_corrupt_chunk_is_a_422(client, part):
    width, height = SIZES[part]
    body = problem(await send(client, part, grey(width, height, height + 1)), 422, part)
    assert "inconsistent" in body["detail"]
    data = bytearray(grey(width, height, height))
    data[-20] ^= 0xFF  # in the IDAT's CRC, which Pillow skips
    body = problem(await send(client, part, bytes(data)), 422, part)
    assert "CRC" in body["detail"]


async def test_a_palette_png_needs_its_palette_and_indices_within_it(client):
    rows = b"".join(b"\x00" + bytes([k % 2]) * 256 for k in range(256))  # indices 0 and 1
    white, black = b"\xff\xff\xff", b"\x00\x00\x00"
    good = png(256, 256, 3, 8, rows, chunk(b"PLTE", white + black))
    assert (await send(client, "mask", good)).status_code == 200
    body = problem(await send(client, "mask", png(256, 256, 3, 8, rows)), 422, "mask")
    assert "needs its palette (PLTE)" in body["detail"]
    short = png(256, 256, 3, 8, rows, chunk(b"PLTE", white))
    body = problem(await send(client, "mask", short), 422, "mask")
    assert "past its palette's 1 colours" in body["detail"]


async def test_a_png_part_beyond_the_pixel_limit_is_a_422_from_its_header():
    """A 8192 x 8192 palette mask with transparency, a few hundred KB, decoded to 3 GB. It is
    refused from its header before its pixels are charged: the 256 MiB budget, which it
    would overrun, is never asked."""
    width = height = 8192
    rows = zlib.compress(bytes((width + 1) * height), 9)
    trns = chunk(b"PLTE", b"\x00\x00\x00\xff\xff\xff") + chunk(b"tRNS", b"\x00")
    header = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    data = b"".join(
        [
            b"\x89PNG\r\n\x1a\n",
            chunk(b"IHDR", header),
            trns,
            chunk(b"IDAT", rows),
            chunk(b"IEND", b""),
        ]
    )
    assert len(data) < 1 * MiB
    async with started(Settings(memory_budget=256 * MiB)) as client:
        body = problem(await send(client, "mask", data), 422, "mask")
    assert "8192 x 8192 pixels (67,108,864)" in body["detail"]
    assert "at most 16,777,216 (MESHFLAT_MAX_IMAGE_PIXELS)" in body["detail"]


async def test_the_pixel_limit_is_a_setting():
    limited = Settings.from_env({"MESHFLAT_MAX_IMAGE_PIXELS": str(1200 * 800 - 1)})
    async with started(limited) as client:
        body = problem(await send(client, "density_map", grey(1200, 800, 800)), 422)
        assert body["field"] == "density_map" and "at most 959,999" in body["detail"]
        assert (await send(client, "image", grey(900, 600, 600))).status_code == 200
