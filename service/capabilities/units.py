"""A mesh's length unit: the ``units`` parameter (a unit, or a distance known in
millimetres), millimetres per mesh unit from it, lengths and areas in mm and cm², and the
warning when the unit makes the region implausibly small or large for a scalp."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

import numpy as np
from pydantic import Field

from transforms.ownframe import OwnFrame

from ..encoding import Answer
from ..errors import InvalidInput
from .context import Context
from .fields import PositiveNumber, Strict, Vector3
from .warnings import WarningCode

#: Millimetres per mesh unit a known distance may give (areas in cm² stay finite).
MM_PER_UNIT = (1e-3, 1e6)


class LengthUnit(StrEnum):
    """The length units a mesh may be in."""

    MM = "mm"
    CM = "cm"
    M = "m"

    @property
    def mm(self) -> float:
        """Millimetres in one unit."""
        return {"mm": 1.0, "cm": 10.0, "m": 1000.0}[self.value]


class KnownDistance(Strict):
    """The mesh's scale from a distance known in millimetres."""

    between: Annotated[list[Vector3], Field(min_length=2, max_length=2)] = Field(
        description="Two world points of the mesh, [[x, y, z], [x, y, z]] (the pupils, say)."
    )
    mm: PositiveNumber = Field(description="Their distance in millimetres.")


def mm_per_unit(units: LengthUnit | KnownDistance | None, field: str = "units") -> float | None:
    """Millimetres per mesh unit, from ``units`` (the params' ``field``); None without.

    Raises
    ------
    InvalidInput
        The two points of a known distance coincide, or give a scale beyond
        :data:`MM_PER_UNIT`.
    """
    if units is None:
        return None
    if not isinstance(units, KnownDistance):
        return LengthUnit(units).mm
    start, end = (np.asarray(point, dtype=np.float64) for point in units.between)
    distance = float(np.linalg.norm(end - start))
    if not distance > 0:
        raise InvalidInput(
            f"{field}.between",
            "the two points coincide; give two points the known distance apart",
        )
    scale = units.mm / distance
    low, high = MM_PER_UNIT
    if not low <= scale <= high:
        raise InvalidInput(
            field,
            f"{units.mm:g} mm over a distance of {distance:g} mesh units is {scale:.3g} mm per "
            f"unit; the scale must be within {low:g} to {high:g} mm per unit (a micron to a "
            "kilometre)",
        )
    return scale


def in_mm(length: float, mm_per_unit: float | None) -> float | None:
    """A length in mm, None without units."""
    return None if mm_per_unit is None else length * mm_per_unit


def in_cm2(area: float, mm_per_unit: float | None) -> float | None:
    """An area in cm², None without units."""
    return None if mm_per_unit is None else area * mm_per_unit**2 / 100.0


def area_text(area: float, mm_per_unit: float | None) -> str:
    """An area as a picture labels it: cm² with units, mesh units² without."""
    if mm_per_unit is None:
        return f"{area:.4g} units²"
    return f"{in_cm2(area, mm_per_unit):.2f} cm²"


def length_text(length: float, mm_per_unit: float | None) -> str:
    """A length as a picture labels it: mm with units, mesh units without."""
    if mm_per_unit is None:
        return f"{length:.4g} units"
    return f"{length * mm_per_unit:.1f} mm"


#: The sizes across a scalp region may plausibly have, cm: a patch of the crown is some 5 cm
#: across, a whole head with its shoulders under 60 cm. Outside them, a units warning.
PLAUSIBLE_ACROSS_CM = (5.0, 60.0)


def size_across(vertices: np.ndarray, faces: np.ndarray) -> float:
    """A region's size across, in its mesh's units: the diagonal of the box around the
    vertices ``faces`` ((m, 3) int) use, along the triangles' own axes
    (:class:`~transforms.ownframe.OwnFrame`). Free of the mesh's pose, and between the
    vertices' largest distance apart and sqrt(3) times it."""
    low, high = OwnFrame.of_triangles(vertices, faces).box(vertices[np.unique(faces)])
    return float(np.linalg.norm(high - low))


def _cm(value: float) -> str:
    return f"{value:,.0f}" if value >= 100 else f"{value:.3g}"


def implausible_size(units, scale: float, across: float) -> str | None:
    """Why ``units`` (the params' value, giving ``scale`` mm per unit) look wrong for a
    region ``across`` mesh units across (:func:`size_across`), with the unit that would fit;
    None when its size is within :data:`PLAUSIBLE_ACROSS_CM`."""
    low, high = PLAUSIBLE_ACROSS_CM
    size = across * scale / 10.0
    if low <= size <= high or across == 0:
        return None
    if isinstance(units, KnownDistance):
        declared = f"the known distance ({scale:.4g} mm per mesh unit)"
    else:
        declared = f"units {LengthUnit(units).value!r}"
    fits = [unit for unit in LengthUnit if low <= across * unit.mm / 10.0 <= high]
    if fits:
        fit = fits[0]
        hint = f"with units {fit.value!r} it would be {_cm(across * fit.mm / 10.0)} cm across"
    else:
        hint = "no unit of mm, cm or m fits: give the scale as a known distance"
    return (
        f"with {declared} the region is {_cm(size)} cm across (the diagonal of its box along "
        f"its principal axes), where a scalp region is {low:g} to {high:g} cm; {hint}"
    )


def warn_of_size(ctx: Context, units, scale: float | None, region) -> str | None:
    """Warn (``units_implausible``, naming ``units``) when ``units`` make ``region`` (a
    :class:`~.region.resolve.MeshRegion`) implausibly small or large
    (:func:`implausible_size` of its vertices); the words, or None (also without units)."""
    if scale is None:
        return None
    faces = region.mesh.faces[region.selection.faces]
    words = implausible_size(units, scale, size_across(region.mesh.vertices, faces))
    if words is not None:
        ctx.warn(WarningCode.UNITS_IMPLAUSIBLE, "units", words)
    return words


class Units(Answer):
    mm_per_unit: float = Field(description="Millimetres per mesh unit, as params.units gives it.")
