"""``POST /v1/plan``: a transplant plan's supply and demand from zones drawn on the map: the
grafts and hairs recipient zones need, those donor zones can give, the balance and the
sessions (docs/math.md, section 21). The zones' areas are /v1/measure's."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, ConfigDict, Field, model_validator

from transforms import MapTriangles, cover_zone
from transforms.plan import (
    Balance,
    Demand,
    Supply,
    balance,
    graft_demand,
    graft_supply,
    mix_means,
    pooled_mean,
)

from ..encoding import Answer
from ..errors import InvalidInput
from ..outputs import Output
from ..outputs.picture import Drawn
from .context import Context
from .drawn import (
    Outline,
    Zone,
    check_drawn,
    check_names,
    checked_zone,
    overlaps,
    warn_outside,
    zone_points,
)
from .fields import PictureParams, choice, output_choice
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.pictures import map_renderers
from .region.resolve import MeshInput, MeshRegion, flatten, map_triangles
from .rows import MeshCapability
from .scalp import PLAUSIBLE_DENSITY_PER_CM2
from .units import KnownDistance, LengthUnit, Units, in_cm2, mm_per_unit, warn_of_size
from .warnings import WarnedAnswer

#: The share of a donor zone's grafts that can be taken without visible thinning, by default:
#: published guidance on follicular unit extraction puts it at about 25 to 30 % of the
#: donor's follicular units (docs/api.md, "Plan", gives the sources).
EXTRACTION_FRACTION = 0.3
#: Grafts a session places at the most, by default: a large session of follicular unit
#: extraction or strip harvesting (docs/api.md, "Plan").
MAX_GRAFTS_PER_SESSION = 3000
#: Hairs a graft of a recipient zone carries when neither it nor the donor says: follicular
#: units hold 1 to 4 hairs, about 2 to 2.3 on average (docs/api.md, "Plan").
DEFAULT_HAIRS_PER_GRAFT = 2.2
#: The most hairs a graft (a follicular unit) is taken to hold: 1 to 4, rarely 5 or 6.
MAX_HAIRS_PER_GRAFT = 6
#: A mix's shares sum to 1 within this.
MIX_TOLERANCE = 1e-6

#: Grafts per cm², measured or aimed at: above 0, at most what a scalp holds
#: (scalp.PLAUSIBLE_DENSITY_PER_CM2).
GraftDensity = Annotated[float, Field(allow_inf_nan=False, gt=0, le=PLAUSIBLE_DENSITY_PER_CM2)]
MeanHairs = Annotated[float, Field(allow_inf_nan=False, ge=1, le=MAX_HAIRS_PER_GRAFT)]
HairCount = Annotated[str, Field(pattern=f"^[1-{MAX_HAIRS_PER_GRAFT}]$")]
Share = Annotated[float, Field(allow_inf_nan=False, ge=0, le=1)]


def _sums_to_one(mix: dict[str, float]) -> dict[str, float]:
    total = math.fsum(mix.values())
    if abs(total - 1.0) > MIX_TOLERANCE:
        raise ValueError(
            f"a mix's shares sum to 1 (within {MIX_TOLERANCE:g}); these sum to {total:.9g}"
        )
    return mix


#: The grafts of a zone by the hairs they hold: shares of 1-, 2-, ... hair grafts.
HairMix = Annotated[
    dict[HairCount, Share],
    Field(min_length=1, max_length=MAX_HAIRS_PER_GRAFT),
    AfterValidator(_sums_to_one),
]
HairsPerGraft = Annotated[
    MeanHairs | HairMix,
    Field(
        description="The hairs a graft holds: a mean (1 to 6), or the mix of grafts by their "
        'hairs, shares of the keys "1" to "6" summing to 1, such as {"1": 0.2, "2": 0.5, '
        '"3": 0.3} (a mean of 2.1).'
    ),
]


class RecipientZone(Zone):
    """A zone to transplant into (as /v1/measure's zones) and its target density."""

    density_per_cm2: GraftDensity = Field(
        description="The grafts per cm² to place: the target density."
    )
    hairs_per_graft: HairsPerGraft | None = Field(
        None,
        description="The hairs a graft placed here holds (a mean or a mix). Default: the "
        "donor zones' pooled mean (their hairs available over their grafts available), or "
        "2.2 when they give none.",
    )


class DonorZone(Zone):
    """A zone to take grafts from (as /v1/measure's zones) and what it holds."""

    density_per_cm2: GraftDensity = Field(
        description="The grafts (follicular units) per cm² the zone holds, measured."
    )
    hairs_per_graft: HairsPerGraft
    extraction_fraction: Annotated[float, Field(allow_inf_nan=False, ge=0, le=1)] = Field(
        EXTRACTION_FRACTION,
        description="The share of the zone's grafts that can be taken. Default 0.3: "
        "published guidance puts safe extraction at about 25 to 30 % of the donor's "
        "follicular units (docs/api.md, Plan).",
    )


class PlanParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/plan: a region and its frame as for
    /v1/measure, the recipient and donor zones drawn on its map, and the units."""

    recipient: Annotated[list[RecipientZone], Field(min_length=1, max_length=256)] = Field(
        description="The zones to transplant into, each with its target density; they must "
        "not overlap each other or a donor zone."
    )
    donor: Annotated[list[DonorZone], Field(max_length=256)] = Field(
        [],
        description="The zones to take grafts from, each with its measured density, its "
        "hairs a graft and the share that can be taken; they must not overlap. None: "
        "nothing is available, the balance is what is needed, negative.",
    )
    max_grafts_per_session: int = Field(
        MAX_GRAFTS_PER_SESSION,
        ge=1,
        le=100_000,
        description="The most grafts one session places (default 3,000: a large session); "
        "sessions = ceil(grafts_needed / this).",
    )
    units: choice(LengthUnit) | KnownDistance = Field(
        description="The mesh's length unit (mm, cm or m), or its scale from a known "
        "distance: needed to turn grafts per cm² into grafts."
    )
    output: output_choice(
        (Output.JSON, Output.SVG, Output.PNG),
        "json (application/json), svg (image/svg+xml) or png (image/png): the map with the "
        "recipient and donor zones, each labelled with its area and grafts, and the balance "
        "in the caption.",
    ) = None

    @model_validator(mode="after")
    def _names_tell_apart(self) -> PlanParams:
        check_names("recipient", self.recipient)
        check_names("donor", self.donor)
        taken = {zone.name: k for k, zone in enumerate(self.recipient)}
        for i, zone in enumerate(self.donor):
            if zone.name in taken:
                raise ValueError(
                    f"donor.{i}: the name {zone.name!r} is that of recipient.{taken[zone.name]}; "
                    "each needs its own"
                )
        return self

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    **MESH_PARAMS_EXAMPLE,
                    "recipient": [
                        {
                            "name": "crown",
                            "outer": {
                                "x": [-1.8, -1.35, -1.35, -1.8],
                                "y": [1.4, 1.4, 1.75, 1.75],
                            },
                            "density_per_cm2": 30,
                        }
                    ],
                    "donor": [
                        {
                            "name": "occipital",
                            "outer": {
                                "x": [-1.25, -0.9, -0.9, -1.25],
                                "y": [1.3, 1.3, 1.85, 1.85],
                            },
                            "density_per_cm2": 80,
                            "hairs_per_graft": {"1": 0.2, "2": 0.5, "3": 0.3},
                        }
                    ],
                    "units": {"between": [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "mm": 100.0},
                }
            ]
        }
    )


def _hairs(given: float | dict[str, float]) -> float:
    """The mean hairs a graft of a mean or a mix (transforms.plan.mix_means)."""
    if not isinstance(given, dict):
        return float(given)
    shares = np.zeros((1, MAX_HAIRS_PER_GRAFT))
    for hairs, share in given.items():
        shares[0, int(hairs) - 1] = share
    return float(mix_means(shares)[0])


@dataclass(frozen=True)
class Tally:
    """The plan's numbers (docs/math.md, section 21).

    Attributes
    ----------
    area_cm2 : (r + d,) float, the zones' surface areas, the recipient zones first
    demand : Demand, of the recipient zones
    supply : Supply, of the donor zones
    hairs_per_graft : (r + d,) float, the mean hairs a graft of each zone holds
    hairs_from : tuple of str, where each recipient zone's mean came from: zone, donor or
        default
    balance : Balance
    """

    area_cm2: np.ndarray
    demand: Demand
    supply: Supply
    hairs_per_graft: np.ndarray
    hairs_from: tuple[str, ...]
    balance: Balance


def tally(params: PlanParams, area_cm2: np.ndarray) -> Tally:
    """The plan's numbers from the zones' areas (cm², the recipient zones first)."""
    recipient, donor = params.recipient, params.donor
    given = np.array([_hairs(zone.hairs_per_graft) for zone in donor], dtype=float)
    supply = graft_supply(
        area_cm2[len(recipient) :],
        [zone.density_per_cm2 for zone in donor],
        [zone.extraction_fraction for zone in donor],
        given,
    )
    pooled = pooled_mean(supply)
    pooled_from = "default" if pooled is None else "donor"
    pooled = DEFAULT_HAIRS_PER_GRAFT if pooled is None else pooled
    own = [zone.hairs_per_graft is not None for zone in recipient]
    hairs = np.array(
        [
            _hairs(z.hairs_per_graft) if mine else pooled
            for z, mine in zip(recipient, own, strict=True)
        ]
    )
    demand = graft_demand(
        area_cm2[: len(recipient)], [zone.density_per_cm2 for zone in recipient], hairs
    )
    return Tally(
        area_cm2,
        demand,
        supply,
        np.concatenate([hairs, given]),
        tuple("zone" if mine else pooled_from for mine in own),
        balance(demand, supply, params.max_grafts_per_session),
    )


def checked_zones(ctx: Context, params: PlanParams) -> list[Outline]:
    """The recipient zones' outlines then the donor zones', checked, their points charged.

    Raises
    ------
    OverLimit
        More points than MESHFLAT_MAX_DRAWN_POINTS.
    InvalidInput
        A bad ring (naming its zone), or two zones that overlap (naming both).
    """
    many = zone_points(params.recipient) > ctx.settings.max_drawn_points
    field = "recipient" if many or not params.donor else "donor"
    check_drawn(ctx, [*params.recipient, *params.donor], zones_field=field)
    outlines = [checked_zone(zone, k, "recipient") for k, zone in enumerate(params.recipient)]
    outlines += [checked_zone(zone, k, "donor") for k, zone in enumerate(params.donor)]
    _apart(outlines, len(params.recipient))
    return outlines


#: Why two zones may not overlap, by (the first's kind, the second's).
_WHY = {
    ("recipient", "recipient"): "the grafts needed there would be counted twice",
    ("recipient", "donor"): "a zone cannot both give grafts and take them",
    ("donor", "donor"): "the grafts available there would be counted twice",
}


def _apart(outlines: list[Outline], recipients: int) -> None:
    """Refuse two zones that share area, naming the later (a donor after every recipient)
    and the earlier one."""

    for pair in overlaps(outlines):
        first, second = (_field(k, recipients) for k in (pair.i, pair.j))
        raise InvalidInput(
            second,
            _WHY[first.split(".")[0], second.split(".")[0]],
            name=outlines[pair.j].name,
            about=f" overlaps params.{first} ({outlines[pair.i].name!r})",
        )


def _field(k: int, recipients: int) -> str:
    """The params' field of the ``k``-th zone, the recipient zones first."""
    return f"recipient.{k}" if k < recipients else f"donor.{k - recipients}"


def zone_areas(triangles: MapTriangles, outlines: list[Outline]) -> np.ndarray:
    """(z,) float: each zone's surface area in mesh units², as /v1/measure's
    (:func:`transforms.cover_zone`)."""
    area = triangles.surface_area
    return np.array([cover_zone(triangles, o.rings).total(area) for o in outlines], dtype=float)


@dataclass(frozen=True)
class Planned:
    """A plan on a region.

    Attributes
    ----------
    params : PlanParams
    region : MeshRegion, the region flattened
    outlines : list of Outline, the recipient zones then the donor zones
    tally : Tally, the numbers
    mm_per_unit : float
    """

    params: PlanParams
    region: MeshRegion
    outlines: list[Outline]
    tally: Tally
    mm_per_unit: float


def plan(given: MeshInput[PlanParams], ctx: Context) -> Planned:
    """The zones of ``params`` on the map of the region it names, measured on the surface,
    and the plan's numbers from their areas (:func:`tally`)."""
    params = given.params
    scale = mm_per_unit(params.units)
    outlines = checked_zones(ctx, params)
    region = flatten(given, ctx)
    triangles = map_triangles(region, ctx)
    area = zone_areas(triangles, outlines)
    warn_of_size(ctx, params.units, scale, region)
    for k, (outline, value) in enumerate(zip(outlines, area, strict=True)):
        if value == 0:
            field = _field(k, len(params.recipient))
            warn_outside(ctx, region, field, outline.name, outline.rings[0])
    numbers = tally(params, in_cm2(area, scale))  # /v1/measure's areas to the last bit
    return Planned(params, region, outlines, numbers, scale)


class RecipientPlan(Answer):
    name: str
    area_cm2: float = Field(description="The zone's surface area, cm² (as /v1/measure's).")
    density_per_cm2: float = Field(description="The target grafts per cm², as asked.")
    grafts_needed: int = Field(description="round(area_cm2 x density_per_cm2).")
    hairs_per_graft: float = Field(description="The mean hairs a graft placed here holds.")
    hairs_per_graft_from: Literal["zone", "donor", "default"] = Field(
        description="Where that mean comes from: 'zone' (its hairs_per_graft), 'donor' (the "
        "donor zones' pooled mean) or 'default' (2.2: no donor graft available)."
    )
    hairs_needed: float = Field(
        description="grafts_needed x hairs_per_graft: an expected count, not rounded."
    )


class DonorPlan(Answer):
    name: str
    area_cm2: float = Field(description="The zone's surface area, cm² (as /v1/measure's).")
    density_per_cm2: float = Field(description="The measured grafts per cm², as given.")
    extraction_fraction: float = Field(description="The share of its grafts that can be taken.")
    hairs_per_graft: float = Field(description="The mean hairs a graft of its mix holds.")
    grafts_present: float = Field(description="area_cm2 x density_per_cm2: the grafts it holds.")
    grafts_available: int = Field(
        description="floor(area_cm2 x density_per_cm2 x extraction_fraction)."
    )
    hairs_available: float = Field(
        description="grafts_available x hairs_per_graft: an expected count, not rounded."
    )


class PlanBalance(Answer):
    grafts: int = Field(description="grafts_available - grafts_needed: negative when short.")
    hairs: float = Field(description="hairs_available - hairs_needed.")


class PlanResponse(WarnedAnswer):
    params: ResolvedParams
    units: Units = Field(description="The scale used.")
    recipient: list[RecipientPlan] = Field(description="The recipient zones, in the order given.")
    donor: list[DonorPlan] = Field(description="The donor zones, in the order given.")
    grafts_needed: int = Field(description="The recipient zones' grafts_needed, summed.")
    grafts_available: int = Field(description="The donor zones' grafts_available, summed.")
    hairs_needed: float = Field(description="The recipient zones' hairs_needed, summed.")
    hairs_available: float = Field(description="The donor zones' hairs_available, summed.")
    balance: PlanBalance
    max_grafts_per_session: int = Field(description="As asked (default 3,000).")
    sessions: int = Field(description="ceil(grafts_needed / max_grafts_per_session).")

    @classmethod
    def of(cls, planned: Planned) -> PlanResponse:
        t, params, total = planned.tally, planned.params, planned.tally.balance
        count = len(params.recipient)
        return cls.build(
            params=ResolvedParams.of_region(planned.region),
            units=Units.build(mm_per_unit=planned.mm_per_unit),
            recipient=[
                RecipientPlan.build(
                    name=zone.name,
                    area_cm2=float(t.area_cm2[k]),
                    density_per_cm2=zone.density_per_cm2,
                    grafts_needed=int(t.demand.grafts[k]),
                    hairs_per_graft=float(t.hairs_per_graft[k]),
                    hairs_per_graft_from=t.hairs_from[k],
                    hairs_needed=float(t.demand.hairs[k]),
                )
                for k, zone in enumerate(params.recipient)
            ],
            donor=[
                DonorPlan.build(
                    name=zone.name,
                    area_cm2=float(t.area_cm2[count + k]),
                    density_per_cm2=zone.density_per_cm2,
                    extraction_fraction=zone.extraction_fraction,
                    hairs_per_graft=float(t.hairs_per_graft[count + k]),
                    grafts_present=float(t.supply.present[k]),
                    grafts_available=int(t.supply.grafts[k]),
                    hairs_available=float(t.supply.hairs[k]),
                )
                for k, zone in enumerate(params.donor)
            ],
            grafts_needed=total.grafts_needed,
            grafts_available=total.grafts_available,
            hairs_needed=total.hairs_needed,
            hairs_available=total.hairs_available,
            balance=PlanBalance.build(grafts=total.grafts, hairs=total.hairs),
            max_grafts_per_session=params.max_grafts_per_session,
            sessions=total.sessions,
        )


#: The zones' colours on the map: the recipient zones in one, the donor zones in another
#: (of the overlays' palette, apart from the flags' colours).
RECIPIENT_COLOUR, DONOR_COLOUR = "#0072b2", "#009e73"


def _drawn(planned: Planned) -> tuple[Drawn, ...]:
    """Each zone in its kind's colour, labelled on the map and in the legend with its area
    and its grafts needed or available."""
    t, count = planned.tally, len(planned.params.recipient)
    area = [f"{value:.2f} cm²" for value in t.area_cm2.tolist()]  # as units.area_text
    needed = [f"{area[k]}, {int(t.demand.grafts[k]):,} grafts needed" for k in range(count)]
    given = [
        f"{area[count + k]}, {int(t.supply.grafts[k]):,} grafts available"
        for k in range(len(planned.outlines) - count)
    ]
    recipient = tuple(
        Drawn(outline.rings, True, outline.name, words, RECIPIENT_COLOUR, words)
        for outline, words in zip(planned.outlines[:count], needed, strict=True)
    )
    donor = tuple(
        Drawn(outline.rings, True, outline.name, words, DONOR_COLOUR, words)
        for outline, words in zip(planned.outlines[count:], given, strict=True)
    )
    return recipient + donor


def headline(balance: Balance) -> str:
    """The plan's caption line: the balance, and the sessions."""
    sessions = "session" if balance.sessions == 1 else "sessions"
    return (
        f"meshflat plan: balance {balance.grafts:+,} grafts, {balance.hairs:+,.0f} hairs "
        f"({balance.grafts_available:,} available, {balance.grafts_needed:,} needed); "
        f"{balance.sessions:,} {sessions}"
    )


#: The forms of a plan besides JSON, by :class:`Output`: the map with the zones, labelled
#: with their areas and grafts, and the balance in the caption.
RENDERERS = map_renderers(
    lambda planned: planned.region,
    _drawn,
    headline_of=lambda planned: headline(planned.tally.balance),
)


ROWS = (
    MeshCapability(
        name="plan",
        path="/v1/plan",
        summary="Plan a transplant: the grafts needed and available",
        description="Multipart like /v1/measure; `params` also holds `recipient` zones (as "
        "/v1/measure's zones, at least one), each with `density_per_cm2` (the target grafts "
        'per cm²) and optional `hairs_per_graft` (a mean, or a mix such as {"1": 0.2, '
        '"2": 0.5, "3": 0.3}); `donor` zones, each with `density_per_cm2` (the grafts '
        "per cm² measured), `hairs_per_graft` and `extraction_fraction` (default 0.3); "
        "`max_grafts_per_session` (default 3,000); and `units` (required). No two zones may "
        "overlap (a 422 naming both). Each zone's area is /v1/measure's. Answers, per "
        "recipient zone in the order given, its `area_cm2`, `grafts_needed` = round(area x "
        "density) and `hairs_needed`; per donor zone its `area_cm2`, `grafts_present` = area "
        "x density, `grafts_available` = floor(area x density x extraction_fraction) and "
        "`hairs_available`; the totals, the `balance` (available minus needed, in grafts and "
        "hairs) and the `sessions` = ceil(grafts_needed / max_grafts_per_session) "
        "(docs/math.md, section 21). Or, by the Accept header or params.output, the map with "
        "the recipient and donor zones, each labelled with its area and grafts, and the "
        "balance in the caption (SVG or PNG).",
        params=PlanParams,
        operation=plan,
        response=PlanResponse,
        renderers=RENDERERS,
    ),
)
