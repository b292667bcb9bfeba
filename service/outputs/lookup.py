"""The answers of /v1/transfer that are not JSON: the look-up images (a face id, and its
weights, a pixel) and the 16-bit PNG of values drawn on the map.

Look-up images are little-endian arrays behind a 16-byte header::

    bytes 0-3    b"MFLU"
    bytes 4-5    uint16, the format's version (1)
    bytes 6-7    uint16, the layers: 1 (face ids) or 4 (face ids, then 3 weights)
    bytes 8-11   uint32, the width w
    bytes 12-15  uint32, the height h
    then         int32 (h, w): the file's face id whose triangle holds the pixel's centre,
                 -1 where none does, row by row from the top
    then (4)     float32 (h, w, 3): the centre's barycentric weights in that face's corners,
                 in the file's corner order (0 where the id is -1)

Pixels follow the PNG answer's convention (centres at half-integers, rows down with theta).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

MAGIC, VERSION = b"MFLU", 1
HEADER = struct.Struct("<4sHHII")


def lookup_bytes(ids: np.ndarray, weights: np.ndarray | None = None) -> bytes:
    """The look-up image of ``ids`` ((h, w) int32) and, given, ``weights`` ((h, w, 3))."""
    height, width = ids.shape
    layers = 1 if weights is None else 4
    parts = [HEADER.pack(MAGIC, VERSION, layers, width, height), ids.astype("<i4").tobytes()]
    if weights is not None:
        parts.append(np.asarray(weights, dtype="<f4").tobytes())
    return b"".join(parts)


def read_lookup(data: bytes) -> tuple[np.ndarray, np.ndarray | None]:
    """``(ids, weights or None)`` back from :func:`lookup_bytes`' bytes (clients, tests)."""
    magic, version, layers, width, height = HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise ValueError("not a meshflat look-up image")
    size = width * height
    ids = np.frombuffer(data, "<i4", size, HEADER.size).reshape(height, width)
    if layers == 1:
        return ids, None
    offset = HEADER.size + 4 * size
    return ids, np.frombuffer(data, "<f4", 3 * size, offset).reshape(height, width, 3)


def grey_alpha_png16(values: np.ndarray, alpha: np.ndarray) -> bytes:
    """A 16-bit grey and alpha PNG (colour type 4) of ``values`` and ``alpha`` ((h, w) in
    [0, 1] each), written with zlib: Pillow writes 16-bit grey without an alpha only."""
    height, width = values.shape
    samples = np.empty((height, width, 2), dtype=">u2")
    samples[..., 0] = np.rint(np.clip(values, 0, 1) * 65535)
    samples[..., 1] = np.rint(np.clip(alpha, 0, 1) * 65535)
    rows = np.zeros((height, 1 + 4 * width), dtype=np.uint8)  # filter byte 0: none
    rows[:, 1:] = samples.view(np.uint8).reshape(height, -1)
    header = struct.pack(">IIBBBBB", width, height, 16, 4, 0, 0, 0)
    return b"".join(
        (
            b"\x89PNG\r\n\x1a\n",
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)),
            _chunk(b"IEND", b""),
        )
    )


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
