"""Benchmark of a transplant plan: 10 zones on a million-face scalp, their areas and the
plan's arithmetic (``make bench-plan``).

The region is ``make bench-measure``'s (:class:`benchmarks.measure_bench.Region`):
``fsaverage-head.ply`` subdivided 5 times, the faces within 52 degrees of up from the head's
box centre, 1,000,968 faces, flattened once with fixed parameters. Drawn on its map,
deterministically (seeded): 10 wobbly ellipses of 200 points
(:func:`benchmarks.measure_bench.wobbly_ellipse`), 5 % to 25 % of the map's extent across,
every point on the region and no two overlapping: 5 recipient zones (40 grafts per cm², the
hairs a graft of some from the donor zones' pooled mean) and 5 donor zones (70 to 90 grafts
per cm², each with a mix of 1- to 4-hair grafts, extraction fractions 0.25 to 0.3).

Timed on one thread (BLAS on one thread, the service's allocator settings), median of several
runs after a warm-up, the garbage collector off during each, what ``/v1/plan``'s use-case does
after the region is flattened (the params parsed once, untimed):

* the zones checked: rings (GEOS) and every pair's overlap
  (:func:`service.capabilities.plan.checked_zones`);
* the map's triangles: :class:`transforms.MapTriangles` from the arrays, with the per-face
  values it caches (as ``make bench-measure``'s prep);
* the zones' surface areas (:func:`service.capabilities.plan.zone_areas`, that is
  :func:`transforms.cover_zone` a zone);
* the arithmetic (:func:`service.capabilities.plan.tally`: demand, supply, balance).

Target (the issue): 0.5 s for all of it.

    python -m benchmarks.plan_bench [--runs 7] [--write-docs]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
import shapely

from benchmarks.docs import footer, publish
from benchmarks.measure_bench import HALF_ANGLE_DEG, SIGMA, SUBDIVISIONS, Region, wobbly_ellipse
from service.capabilities.context import Context
from service.capabilities.plan import PlanParams, checked_zones, tally, zone_areas
from service.server.allocator import keep_large_blocks
from transforms import MapTriangles

#: The issue's target: the zones checked, the map's triangles, 10 areas and the arithmetic.
TARGET_MS = 500.0
RECIPIENTS = DONORS = 5
#: Zone diameters, as shares of the map's extent (the larger side of its bounding box).
ZONE_SIZES = (0.05, 0.25)
SEED = 35


def progress(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def draw_apart(triangles: MapTriangles) -> list[np.ndarray]:
    """``RECIPIENTS + DONORS`` rings placed at random on the map, the largest first, every
    point on a triangle and no two overlapping."""
    rng = np.random.default_rng(SEED)
    low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
    extent = float(np.max(high - low))
    rings: list[np.ndarray] = []
    for size in np.geomspace(*ZONE_SIZES, RECIPIENTS + DONORS)[::-1]:
        shape = wobbly_ellipse(rng, size * extent)
        while True:
            ring = shape + rng.uniform(low - shape.min(axis=0), high - shape.max(axis=0))
            polygon = shapely.Polygon(ring)
            if (triangles.locate(ring)[0] >= 0).all() and not any(
                polygon.intersects(shapely.Polygon(other)) for other in rings
            ):
                break
        rings.append(ring)
    order = rng.permutation(len(rings))  # recipients and donors of every size
    return [rings[k] for k in order]


def plan_params(rings: list[np.ndarray]) -> PlanParams:
    """The params of a plan of ``rings``: the first ``RECIPIENTS`` recipient zones, the
    rest donor zones."""

    def zone(name: str, ring: np.ndarray) -> dict:
        return {"name": name, "outer": {"x": ring[:, 0].tolist(), "y": ring[:, 1].tolist()}}

    recipient = [
        {**zone(f"recipient {k + 1}", ring), "density_per_cm2": 40.0}
        | ({"hairs_per_graft": 2.3} if k % 2 else {})
        for k, ring in enumerate(rings[:RECIPIENTS])
    ]
    donor = [
        {
            **zone(f"donor {k + 1}", ring),
            "density_per_cm2": 70.0 + 5 * k,
            "hairs_per_graft": {"1": 0.15, "2": 0.5, "3": 0.3, "4": 0.05},
            "extraction_fraction": 0.3 - 0.0125 * k,
        }
        for k, ring in enumerate(rings[RECIPIENTS:])
    ]
    return PlanParams.model_validate(
        {"recipient": recipient, "donor": donor, "units": "mm", "max_grafts_per_session": 3000}
    )


def plan_run(region: Region, params: PlanParams) -> dict:
    """One timed run: each stage's seconds, and the numbers."""
    clock = time.perf_counter
    start = clock()
    outlines = checked_zones(Context(), params)
    checked = clock()
    triangles = region.triangles()
    prepared = clock()
    area = zone_areas(triangles, outlines)
    measured = clock()
    numbers = tally(params, area * 1.0**2 / 100.0)  # the mesh is in mm
    done = clock()
    return dict(
        check=checked - start,
        prep=prepared - checked,
        areas=measured - prepared,
        arithmetic=done - measured,
        total=done - start,
        tally=numbers,
    )


def quiet(work: Callable[[], dict]) -> dict:
    """``work()`` with the cyclic garbage collector off, after a collection (as timeit)."""
    gc.collect()
    gc.disable()
    try:
        return work()
    finally:
        gc.enable()


def ms(runs: list[dict], key: str) -> float:
    """The median over the timed runs (the warm-up, first, left out), in milliseconds."""
    return statistics.median(run[key] for run in runs[1:]) * 1e3


def zone_rows(params: PlanParams, numbers) -> list[str]:
    lines = [
        "| zone | area (cm²) | density (per cm²) | grafts needed | grafts available | hairs |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    count = len(params.recipient)
    for k, zone in enumerate(params.recipient):
        lines.append(
            f"| {zone.name} | {numbers.area_cm2[k]:,.2f} | {zone.density_per_cm2:g} "
            f"| {numbers.demand.grafts[k]:,} | - | {numbers.demand.hairs[k]:,.0f} |"
        )
    for k, zone in enumerate(params.donor):
        lines.append(
            f"| {zone.name} | {numbers.area_cm2[count + k]:,.2f} | {zone.density_per_cm2:g} "
            f"| - | {numbers.supply.grafts[k]:,} | {numbers.supply.hairs[k]:,.0f} |"
        )
    total = numbers.balance
    sessions = f"{total.sessions} session{'' if total.sessions == 1 else 's'}"
    lines.append(
        f"| balance | - | - | {total.grafts_needed:,} | {total.grafts_available:,} "
        f"| {total.hairs:+,.0f} ({total.grafts:+,} grafts; {sessions}) |"
    )
    return lines


def measure(runs: int) -> str:
    progress(f"fsaverage-head.ply subdivided {SUBDIVISIONS} times, flattened")
    region = Region.flattened()
    rings = draw_apart(region.triangles())
    params = plan_params(rings)
    results = [quiet(lambda: plan_run(region, params))]
    for run in range(runs):
        progress(f"run {run + 1} of {runs}")
        results.append(quiet(lambda: plan_run(region, params)))
    total = ms(results, "total")
    row = lambda name, key: f"| {name} | {ms(results, key):,.1f} | - | - |"  # noqa: E731
    lines = [
        f"`fsaverage-head.ply` subdivided {SUBDIVISIONS} times, the faces within "
        f"{HALF_ANGLE_DEG:g} degrees of up from the head's box centre: {len(region.faces):,} "
        f"faces, flattened once (pole at the chin, sigma {SIGMA}). Drawn on its map: "
        f"{RECIPIENTS} recipient and {DONORS} donor zones, wobbly ellipses of "
        f"{len(rings[0])} points, {ZONE_SIZES[0]:.0%} to {ZONE_SIZES[1]:.0%} of the map's "
        "extent across, on the region, none overlapping. One thread, BLAS on one thread; "
        f"median of {runs} runs after a warm-up, the garbage collector off during each.",
        "",
        "| stage | ms | target | met |",
        "|---|---:|---|---|",
        f"| total: zones checked, triangles, 10 areas, arithmetic | {total:,.1f} "
        f"| <= {TARGET_MS:.0f} ms | {'yes' if total <= TARGET_MS else 'no'} |",
        row("zones checked: rings and overlaps (GEOS)", "check"),
        row("`MapTriangles` and its per-face values", "prep"),
        row("10 zones' surface areas (`cover_zone`)", "areas"),
        row("the arithmetic (`tally`)", "arithmetic"),
        "",
        *zone_rows(params, results[0]["tally"]),
        "",
        footer(f"numpy {np.__version__}", f"shapely {shapely.__version__}"),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=7, help="timed runs (median)")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    report = measure(args.runs)
    publish("plan-bench", "A transplant plan (`make bench-plan`)", report, args.write_docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
