"""A USD text stage (``.usda``) of a region and strands on it: the region as a ``Mesh`` with
its map as ``primvars:st``, the strands as one ``BasisCurves`` (linear) with their widths,
each curve's root ``st`` and root face id.

Written here rather than through Pixar's ``usd-core`` (about 160 MB installed, against a few
dozen lines of text): a stage of two prims needs only the text format's grammar. The tests
open it with ``usd-core`` when it is installed.
"""

from __future__ import annotations

import io

import numpy as np


def _array(values: np.ndarray, fmt: str, per_row: int) -> str:
    """``[a, b, ...]`` of ``values`` ((n, per_row) or (n,)), each row through ``fmt``."""
    rows = np.asarray(values).reshape(len(values), per_row)
    out = io.StringIO()
    np.savetxt(out, rows, fmt=fmt, newline=", ")
    text = out.getvalue()
    return "[" + (text[:-2] if text.endswith(", ") else text) + "]"


def strands_usda(
    positions: np.ndarray,
    triangles: np.ndarray,
    st: np.ndarray,
    face_ids: np.ndarray,
    strands: np.ndarray,
    root_st: np.ndarray,
    root_faces: np.ndarray,
    width: float,
    metres_per_unit: float,
) -> bytes:
    """The stage's text.

    Parameters
    ----------
    positions : (k, 3) float, the region's vertices
    triangles : (m, 3) int, indices into ``positions``
    st : (k, 2) float, the map's coordinates in [0, 1] (the GLB's UVs)
    face_ids : (m,) int, the file's id of each triangle
    strands : (n, p, 3) float, the strands' points
    root_st : (n, 2) float, each root's ``st``
    root_faces : (n,) int, the file's id of each root's triangle
    width : float, the strands' width, mesh units
    metres_per_unit : float, the stage's ``metersPerUnit``
    """
    n, p, _ = strands.shape
    points3 = "(%.9g, %.9g, %.9g)"
    lines = [
        "#usda 1.0",
        "(",
        '    defaultPrim = "meshflat"',
        f"    metersPerUnit = {metres_per_unit:.9g}",
        '    doc = "meshflat: a region and the strands grown on it"',
        ")",
        "",
        'def Xform "meshflat"',
        "{",
        '    def Mesh "region"',
        "    {",
        f"        int[] faceVertexCounts = {_array(np.full(len(triangles), 3), '%d', 1)}",
        f"        int[] faceVertexIndices = {_array(triangles.reshape(-1), '%d', 1)}",
        f"        point3f[] points = {_array(positions, points3, 3)}",
        f"        texCoord2f[] primvars:st = {_array(st, '(%.9g, %.9g)', 2)} (",
        '            interpolation = "vertex"',
        "        )",
        f"        int[] primvars:faceId = {_array(face_ids, '%d', 1)} (",
        '            interpolation = "uniform"',
        "        )",
        '        uniform token subdivisionScheme = "none"',
        "    }",
        "",
        '    def BasisCurves "strands"',
        "    {",
        '        uniform token type = "linear"',
        f"        int[] curveVertexCounts = {_array(np.full(n, p), '%d', 1)}",
        f"        point3f[] points = {_array(strands.reshape(-1, 3), points3, 3)}",
        f"        float[] widths = [{width:.9g}] (",
        '            interpolation = "constant"',
        "        )",
        f"        texCoord2f[] primvars:st = {_array(root_st, '(%.9g, %.9g)', 2)} (",
        '            interpolation = "uniform"',
        "        )",
        f"        int[] primvars:faceId = {_array(root_faces, '%d', 1)} (",
        '            interpolation = "uniform"',
        "        )",
        "    }",
        "}",
        "",
    ]
    return "\n".join(lines).encode("ascii")
