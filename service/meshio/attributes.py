"""The file's colours, texture coordinates and numeric properties, sorted from what a reader
found by name: one vocabulary for every format (:class:`mesh.Attributes`).

* colour channels by name: ``red green blue alpha`` (and ``r g b a``, ``diffuse_red`` ...);
  integer channels scale to [0, 1] by their type's largest value, float ones are taken as
  they are (clipped to [0, 1]); a missing alpha is 1;
* texture coordinates: ``u v``, ``s t`` or ``texture_u texture_v`` (the first pair found),
  ``v`` turned over (``1 - v``) as OBJ's are;
* every other numeric value is kept by its own name, the first ``MAX_PROPERTIES`` of a
  kind (a vertex's, a face's): each costs 8 bytes a vertex or triangle.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .mesh import Attributes

#: The most properties kept of each kind (besides position, colour and texture coordinates).
MAX_PROPERTIES = 8
#: Colour channel names (lower case) -> channel (0 red, 1 green, 2 blue, 3 alpha).
CHANNEL_NAMES = {
    **{name: k for k, name in enumerate(("red", "green", "blue", "alpha"))},
    **{name: k for k, name in enumerate(("r", "g", "b", "a"))},
    **{f"diffuse_{name}": k for k, name in enumerate(("red", "green", "blue", "alpha"))},
}
#: Texture coordinate pairs, in the order they are looked for.
UV_PAIRS = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"))


def kept_properties(names: list[str]) -> list[str]:
    """Of a kind's property ``names`` (position aside), the ones read: every colour channel
    and texture coordinate, and the first ``MAX_PROPERTIES`` others."""
    special = set(CHANNEL_NAMES) | {name for pair in UV_PAIRS for name in pair}
    others = [name for name in names if name.lower() not in special]
    return [name for name in names if name.lower() in special or name in others[:MAX_PROPERTIES]]


def unit_scale(dtype: np.dtype) -> float:
    """What a colour of ``dtype`` is multiplied by to lie in [0, 1]."""
    dtype = np.dtype(dtype)
    return 1.0 / float(np.iinfo(dtype).max) if dtype.kind in "iu" else 1.0


def colors_of(channels: Mapping[int, np.ndarray], count: int) -> np.ndarray:
    """(count, 4) float32 RGBA in [0, 1] from the channels found (channel -> (count,)
    values already scaled); alpha 1 and any other missing channel 0."""
    colors = np.zeros((count, 4), dtype=np.float32)
    colors[:, 3] = 1.0
    for channel, values in channels.items():
        colors[:, channel] = values
    np.clip(colors, 0.0, 1.0, out=colors)
    np.nan_to_num(colors, copy=False)  # a NaN colour is no colour: 0
    return colors


def vertex_attributes(
    values: dict[str, np.ndarray], dtypes: Mapping[str, np.dtype], faces: np.ndarray
) -> Attributes:
    """Sort a reader's per-vertex values (name -> (n,) float64, each of the file type
    ``dtypes[name]``) into colours, texture coordinates (whose corners are the faces' own
    vertices) and the rest; ``values`` is emptied as it goes (no copy is kept)."""
    count = len(next(iter(values.values()))) if values else 0
    channels = {}
    for name in list(values):
        channel = CHANNEL_NAMES.get(name.lower())
        if channel is not None and channel not in channels:
            channels[channel] = values.pop(name) * unit_scale(dtypes[name])
    colors = colors_of(channels, count) if channels else None
    uv = uv_faces = None
    lowered = {name.lower(): name for name in values}
    for first, second in UV_PAIRS:
        if first in lowered and second in lowered:
            # v turned over: PLY's, as OBJ's, grows up the image; the mesh's grows down.
            uv = np.column_stack((values.pop(lowered[first]), 1.0 - values.pop(lowered[second])))
            uv_faces = faces
            break
    return Attributes(colors=colors, uv=uv, uv_faces=uv_faces, vertex=values)
