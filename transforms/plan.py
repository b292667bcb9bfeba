"""A transplant plan's supply and demand: the grafts recipient zones need, the grafts donor
zones can give, in hairs too, and the sessions it takes (docs/math.md, section 21).

Over arrays of the zones' surface areas (cm²) and what is known of each: a target or a
measured density (grafts per cm²), the share of a donor's grafts that may be taken, and the
hairs a graft carries (a mean, or a mix of one-, two-, ... hair grafts). Counts of grafts are
whole; hairs are expected counts (a whole number of grafts times a mean), not rounded. Totals
are exact sums (integers, and :func:`math.fsum` of the hairs), so the zones' order changes
nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def mix_means(shares: np.ndarray) -> np.ndarray:
    """(n,) float: the mean hairs a graft of each mix (21.3).

    Parameters
    ----------
    shares : (n, k) float, row ``i`` the shares of grafts of 1, 2, ..., k hairs in mix ``i``
        (non-negative, summing to 1: the service checks this)
    """
    shares = np.asarray(shares, dtype=np.float64)
    return shares @ np.arange(1, shares.shape[1] + 1, dtype=np.float64)


@dataclass(frozen=True)
class Demand:
    """What recipient zones need (21.1).

    Attributes
    ----------
    grafts : (r,) int64, ``round(area x density)`` (half to even, as Python's ``round``)
    hairs : (r,) float, ``grafts x hairs_per_graft``
    """

    grafts: np.ndarray
    hairs: np.ndarray


def graft_demand(area_cm2, density, hairs_per_graft) -> Demand:
    """The grafts and hairs recipient zones need (21.1).

    Parameters
    ----------
    area_cm2 : (r,) float, the zones' surface areas
    density : (r,) float, the target grafts per cm²
    hairs_per_graft : (r,) float, the mean hairs a graft placed there carries
    """
    area, density = np.asarray(area_cm2, np.float64), np.asarray(density, np.float64)
    grafts = np.rint(area * density).astype(np.int64)
    return Demand(grafts, grafts * np.asarray(hairs_per_graft, np.float64))


@dataclass(frozen=True)
class Supply:
    """What donor zones hold and can give (21.2).

    Attributes
    ----------
    present : (d,) float, ``area x density``: the grafts the zone holds
    grafts : (d,) int64, ``floor(area x density x fraction)``: the grafts it can give
    hairs : (d,) float, ``grafts x hairs_per_graft``
    """

    present: np.ndarray
    grafts: np.ndarray
    hairs: np.ndarray


def graft_supply(area_cm2, density, fraction, hairs_per_graft) -> Supply:
    """The grafts donor zones hold and can give, and their hairs (21.2).

    Parameters
    ----------
    area_cm2 : (d,) float, the zones' surface areas
    density : (d,) float, the measured grafts per cm²
    fraction : (d,) float in [0, 1], the share of its grafts a zone can give
    hairs_per_graft : (d,) float, the mean hairs a graft of the zone carries
    """
    area, density = np.asarray(area_cm2, np.float64), np.asarray(density, np.float64)
    present = area * density  # first, as (area x density) x fraction is floored
    grafts = np.floor(present * np.asarray(fraction, np.float64)).astype(np.int64)
    return Supply(present, grafts, grafts * np.asarray(hairs_per_graft, np.float64))


def pooled_mean(supply: Supply) -> float | None:
    """The mean hairs a graft taken from all the donor zones carries: their hairs over their
    grafts (each zone's mean weighted by the grafts it gives, 21.3); None when they give
    none."""
    grafts = int(supply.grafts.sum())
    return math.fsum(supply.hairs.tolist()) / grafts if grafts else None


@dataclass(frozen=True)
class Balance:
    """Supply against demand (21.4).

    Attributes
    ----------
    grafts_needed, grafts_available : int
    hairs_needed, hairs_available : float
    grafts, hairs : available minus needed
    sessions : ceil(grafts_needed / per_session)
    """

    grafts_needed: int
    grafts_available: int
    hairs_needed: float
    hairs_available: float
    grafts: int
    hairs: float
    sessions: int


def balance(demand: Demand, supply: Supply, per_session: int) -> Balance:
    """The totals of ``demand`` and ``supply``, what is left over (negative: short), and the
    sessions of at most ``per_session`` grafts (>= 1) that place the grafts needed (21.4)."""
    needed, available = int(demand.grafts.sum()), int(supply.grafts.sum())
    hairs_needed = math.fsum(demand.hairs.tolist())
    hairs_available = math.fsum(supply.hairs.tolist())
    return Balance(
        needed,
        available,
        hairs_needed,
        hairs_available,
        available - needed,
        hairs_available - hairs_needed,
        -(-needed // per_session),
    )
