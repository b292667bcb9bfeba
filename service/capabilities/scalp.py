"""What a scalp plausibly holds: its hair's density and its number of sites, the bounds of
/v1/sites' warnings (``density_implausible``, ``sites_implausible``; docs/api.md)."""

from __future__ import annotations

from .context import Context
from .units import in_cm2
from .warnings import WarningCode

#: The densest a scalp holds hair, per cm²: some 100 follicular units at the densest
#: (transplants place 20 to 60 grafts per cm²). Denser sites are warned of.
PLAUSIBLE_DENSITY_PER_CM2 = 120.0
#: A whole scalp's area, cm² (the hair-bearing scalp of an adult head is 500 to 700).
SCALP_CM2 = 700.0
#: The most sites a whole scalp holds at the densest; more are warned of.
PLAUSIBLE_SITES = round(PLAUSIBLE_DENSITY_PER_CM2 * SCALP_CM2)


def warn_implausible(ctx: Context, params, results, scale: float) -> None:
    """Warn of a part (of ``results``, the sites' ``SiteZoneResult``) placed denser than
    :data:`PLAUSIBLE_DENSITY_PER_CM2`, and of more sites in all than :data:`PLAUSIBLE_SITES`,
    naming the parameter of ``params`` (``SitesParams``) that asked for them."""
    for k, zone in enumerate(results):
        if zone.achieved > PLAUSIBLE_DENSITY_PER_CM2:
            ctx.warn(
                WarningCode.DENSITY_IMPLAUSIBLE,
                _asking(params, k),
                f"{zone.name!r} gets {zone.quota:,} sites on {in_cm2(zone.open_area, scale):.4g} "
                f"cm², {zone.achieved:,.1f} per cm², denser than a scalp holds hair (at most "
                f"{PLAUSIBLE_DENSITY_PER_CM2:g} per cm²)",
            )
    total = sum(zone.quota for zone in results)
    if total > PLAUSIBLE_SITES:
        ctx.warn(
            WarningCode.SITES_IMPLAUSIBLE,
            _asking(params, None),
            f"{total:,} sites in all, more than a whole scalp holds ({SCALP_CM2:g} cm² at "
            f"{PLAUSIBLE_DENSITY_PER_CM2:g} per cm²: {PLAUSIBLE_SITES:,})",
        )


def _asking(params, zone: int | None) -> str:
    """The parameter that asked for the sites of part ``zone`` (None: of them all)."""
    if params.count is not None:
        return "count"
    if params.density_range is not None:
        return "density_range"
    if zone is not None and params.zones and params.zones[zone].density_per_cm2 is not None:
        return f"zones.{zone}.density_per_cm2"
    if params.density_per_cm2 is not None:
        return "density_per_cm2"
    return "zones"
