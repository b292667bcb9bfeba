"""Warnings: what is legal but probably wrong (a metre mesh declared in millimetres, a zone
drawn in degrees off the map), said beside the answer rather than kept silent.

The one vocabulary of their codes (:class:`WarningCode`, documented in docs/api.md's table),
the warning a use-case adds (``ctx.warn(code, field, message)``: one call, from any
use-case, see :class:`~.context.Context`), and the base of every capability's JSON answer
(:class:`WarnedAnswer`), whose ``warnings`` the row fills from the context when it encodes
the answer (:meth:`.rows.Capability.encoded`): no capability plumbs them through its result.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from pydantic import Field

from ..encoding import Answer
from ..errors import ErrorPlaces
from .fields import choice


class WarningCode(StrEnum):
    """The codes of the answers' warnings: stable snake_case strings (a client may switch on
    them), one per kind of doubt, each described in :data:`MEANINGS`."""

    UNITS_IMPLAUSIBLE = "units_implausible"
    DRAWN_OUTSIDE_MAP = "drawn_outside_map"
    DENSITY_IMPLAUSIBLE = "density_implausible"
    SITES_IMPLAUSIBLE = "sites_implausible"
    REGION_PIECES = "region_pieces"
    SEAM_ON_REGION = "seam_on_region"
    REGION_FOLDS = "region_folds"
    VALUES_MISSING = "values_missing"
    SPOT_OFF_SCAN = "spot_off_scan"


#: What each code means: the table of docs/api.md (tests/test_warnings.py keeps them equal;
#: the bounds are those of units.PLAUSIBLE_ACROSS_CM and of the scalp module).
MEANINGS = {
    WarningCode.UNITS_IMPLAUSIBLE: "With these units the region is smaller or larger across "
    "than a scalp region. The message gives its size in cm and the unit that would fit.",
    WarningCode.DRAWN_OUTSIDE_MAP: "A zone or curve lies wholly outside the region's map: "
    "it measures nothing and holds no site. The message gives the map's extent in the "
    "layout's coordinates, and says when the numbers look like degrees.",
    WarningCode.DENSITY_IMPLAUSIBLE: "Sites placed denser than a scalp holds hair.",
    WarningCode.SITES_IMPLAUSIBLE: "More sites in all than a whole scalp holds.",
    WarningCode.REGION_PIECES: "The region is several pieces that share no edge (a stray "
    "part of the scan, an eye, a box beside the head). The message gives their face counts; "
    "validation.stray_faces lists the faces outside the largest, and region.pieces "
    '"largest" keeps the largest alone.',
    WarningCode.SEAM_ON_REGION: "The seam or a singular point lies on the region, so the map "
    "is not one patch (validation.seam_faces, singular_point_faces). The message says whether "
    'a cap of directions is free of the region (then "auto" puts the seam there) or, when none '
    "is, that the region closes round the centre or how large the largest gap between its "
    "vertices' directions is.",
    WarningCode.REGION_FOLDS: "Triangles of the region are folded in the map or face away "
    "from the centre, so the map overlaps itself there (validation.folded_faces, "
    "backfacing_faces). The message gives how many, and whether untangling was asked for.",
    WarningCode.VALUES_MISSING: "Part of a /v1/compare zone has no values on a scan: a "
    "follow-up cropped there, a zone beyond a scan's region, a picture transparent there. "
    "The message gives each scan's share of the zone with values; the means are over those "
    "parts alone (zones[].baseline_coverage, follow_up_coverage).",
    WarningCode.SPOT_OFF_SCAN: "A /v1/compare spot lies on no triangle of the baseline's map, "
    "or the follow-up has no surface within 2 mm of where the registration puts it: its "
    "follow-up position is null.",
}


@dataclass(frozen=True)
class Warned:
    """A warning as a use-case adds it.

    Attributes
    ----------
    code : WarningCode
    field : str, the parameter (dotted, as an error's: ``units``, ``zones.2``) or part it
        concerns, placed in the request as errors are (``params.units`` on a mesh route)
    message : str, plain words with the numbers
    """

    code: WarningCode
    field: str
    message: str


class AnswerWarning(Answer):
    code: choice(WarningCode) = Field(
        description="What kind of doubt: a stable code (docs/api.md, Warnings)."
    )
    field: str = Field(
        description="The parameter or part it concerns, dotted as a problem's field: "
        "params.units, params.zones.2."
    )
    message: str = Field(description="What looks wrong, in plain words with the numbers.")


class WarnedAnswer(Answer):
    warnings: list[AnswerWarning] = Field(
        default_factory=list,
        description="What is legal but probably wrong about the request (a unit that makes "
        "the region implausibly small, a zone off the map); empty when nothing looks wrong.",
    )

    def warned(self, warnings: list[Warned], places: ErrorPlaces) -> WarnedAnswer:
        """This answer with ``warnings`` first (an empty list without any), their fields
        placed in the request by ``places``; the same warning twice is said once."""
        unique = list(dict.fromkeys(warnings))
        self.warnings = [
            AnswerWarning.build(code=w.code, field=places.named(w.field), message=w.message)
            for w in unique
        ]
        self._order = ("warnings", *(name for name in self._order if name != "warnings"))
        return self
