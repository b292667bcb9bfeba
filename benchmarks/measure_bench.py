"""Benchmark of zones and curves drawn on the map, measured on the surface
(``make bench-measure``).

The region: ``fsaverage-head.ply`` subdivided 5 times (as ``make bench-fit``'s top rung), the
faces whose centroid lies within 52 degrees of up seen from the head's bounding-box centre
(the scalp of ``benchmarks.fit_bench.ladder_rung(5)`` narrowed from 70.86 to 52 degrees):
1,000,968 faces, one disk. It is flattened once from that centre with fixed parameters (pole
at the chin, ``Chart.distorted(PoleCap.from_sigma(0.3))``, as ``make bench-locate`` does);
the map is the layout ``x, y``.

Drawn on it, deterministically (seeded): 10 zones as a hair-transplant plan draws them, each a
closed wobbly ellipse of 200 points (counter-clockwise and clockwise in turn) from 5 % to 40 %
of the map's extent across, all on the region and some overlapping, and a hairline: a wavy
500-point polyline across the map. Timed on one thread (BLAS on one thread, the service's
allocator settings), median of several runs after a warm-up:

* meshflat: :class:`transforms.MapTriangles` built from the arrays with the per-face values it
  caches (bounds, signed map area, surface area, typical size), :func:`transforms.cover_zone`
  and the zone's surface area for each zone, and :func:`transforms.lift_curve` for the curve;
  target (the issue): 300 ms for all of it;
* the peer, shapely 2 (GEOS), timed alternately with meshflat in the same process: the
  triangles' polygons (``shapely.polygons``), an STRtree over them, their areas (numpy), then
  for each zone ``shapely.intersection`` with the triangles and ``shapely.area``, and for the
  curve ``shapely.intersection`` with the triangles, each piece lifted by its triangle's
  affine map. The warm-up times the peer's variants for the zones once (every triangle
  clipped; the triangles the STRtree finds meeting the zone clipped; only those meeting the
  zone's boundary clipped and those the zone contains counted whole) and the fastest is the
  one timed.

A zone's surface area from shapely is, over the triangles, the area of the triangle's
intersection with the zone over the triangle's map area times its surface area; a curve's
surface length is the sum of its pieces' lifted lengths. Both are compared with meshflat's
(relative difference).

    python -m benchmarks.measure_bench [--runs 7] [--write-docs]
"""

from __future__ import annotations

import argparse
import gc
import math
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import version

import numpy as np
import shapely

from benchmarks.docs import footer, publish
from benchmarks.fit_bench import compact
from fixtures.meshes import subdivided
from service.server.allocator import keep_large_blocks
from transforms import (
    LAYOUT_ORIENTATION,
    Chart,
    Frame,
    MapTriangles,
    PoleCap,
    cover_zone,
    flatten_region,
    lift_curve,
)

#: The issue's target: the map's triangles, 10 zones and a curve, in milliseconds.
TARGET_MS = 300.0
SIGMA = 0.3
#: The region: faces whose centroid is within this angle of up (+z) from the head's box centre.
HALF_ANGLE_DEG = 52.0
SUBDIVISIONS = 5
ZONES = 10
ZONE_POINTS = 200
#: Zone diameters, as shares of the map's extent (the larger side of its bounding box).
ZONE_SIZES = (0.05, 0.40)
CURVE_POINTS = 500
SEED = 2024


def progress(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


# -- the region and what is drawn on it -----------------------------------------------------


@dataclass(frozen=True)
class Region:
    """The flattened region's arrays, as the service holds them before measuring."""

    x: np.ndarray
    y: np.ndarray
    surface_points: np.ndarray
    faces: np.ndarray
    front: int
    flagged: int

    @classmethod
    def flattened(cls) -> Region:
        vertices, faces = subdivided("fsaverage-head.ply", SUBDIVISIONS)
        centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
        directions = vertices[faces].mean(axis=1) - centre
        cosine = directions[:, 2] / np.linalg.norm(directions, axis=1)
        vertices, faces = compact(vertices, faces[cosine >= math.cos(math.radians(HALF_ANGLE_DEG))])
        frame = Frame.from_pole_up([0, 0, -1], [0, 1, 0], centre)
        flat = flatten_region(vertices, faces, frame, Chart.distorted(PoleCap.from_sigma(SIGMA)))
        front = LAYOUT_ORIENTATION * flat.validation.winding
        surface = np.ascontiguousarray(vertices[flat.vertex_ids])
        return cls(flat.x, flat.y, surface, flat.faces, front, flat.flagged_faces)

    def triangles(self) -> MapTriangles:
        """The map's triangles with the per-face values they cache (what meshflat's prep
        times)."""
        triangles = MapTriangles.of(self.x, self.y, self.surface_points, self.faces, self.front)
        triangles.bounds, triangles.signed_map_area, triangles.surface_area  # noqa: B018
        triangles.typical_size  # noqa: B018
        return triangles


@dataclass(frozen=True)
class Zone:
    ring: np.ndarray  # (ZONE_POINTS, 2), not closed
    size: float  # diameter, share of the map's extent
    counter_clockwise: bool


def wobbly_ellipse(rng: np.random.Generator, diameter: float) -> np.ndarray:
    """A smooth closed wobbly ellipse of ``ZONE_POINTS`` points about the origin,
    counter-clockwise, ``diameter`` across its longer axis (before the wobble)."""
    t = np.linspace(0.0, 2.0 * np.pi, ZONE_POINTS, endpoint=False)
    a = diameter / 2
    b = a * rng.uniform(0.45, 1.0)
    radius = np.ones_like(t)
    for k in range(2, 7):  # a few low harmonics: smooth, star-shaped, so simple
        radius += rng.uniform(0.0, 0.12 / k) * np.cos(k * t + rng.uniform(0.0, 2.0 * np.pi))
    turn = rng.uniform(0.0, np.pi)
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return np.column_stack([a * radius * np.cos(t), b * radius * np.sin(t)]) @ rotation.T


def draw_zones(triangles: MapTriangles) -> list[Zone]:
    """``ZONES`` zones placed at random on the region's map, every point on a triangle."""
    rng = np.random.default_rng(SEED)
    low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
    extent = float(np.max(high - low))
    sizes = rng.permutation(np.geomspace(*ZONE_SIZES, ZONES))
    zones = []
    for number, size in enumerate(sizes):
        shape = wobbly_ellipse(rng, size * extent)
        while True:
            ring = shape + rng.uniform(low - shape.min(axis=0), high - shape.max(axis=0))
            if (triangles.locate(ring)[0] >= 0).all():
                break
        ccw = number % 2 == 0
        assert shapely.Polygon(ring).is_valid
        zones.append(Zone(ring if ccw else ring[::-1], float(size), ccw))
    return zones


def draw_hairline(triangles: MapTriangles) -> np.ndarray:
    """(CURVE_POINTS, 2): a wavy polyline across the map, an arc with two waves on it."""
    rng = np.random.default_rng(SEED + 1)
    low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
    width, middle = high - low, (low + high) / 2
    u = np.linspace(0.0, 1.0, CURVE_POINTS)
    x = low[0] + width[0] * (0.12 + 0.76 * u + 0.01 * np.sin(9 * np.pi * u))
    arc = 0.18 * (1.0 - 4.0 * (u - 0.5) ** 2)
    waves = 0.04 * np.sin(5 * np.pi * u + rng.uniform(0, np.pi))
    waves += 0.012 * np.sin(23 * np.pi * u + rng.uniform(0, np.pi))
    return np.column_stack([x, middle[1] + width[1] * (arc + waves - 0.05)])


# -- meshflat ----------------------------------------------------------------------------


def meshflat_run(region: Region, zones: list[Zone], curve: np.ndarray) -> dict:
    """One timed run: prep, zones, curve (seconds) and the areas and length."""
    clock = time.perf_counter
    start = clock()
    triangles = region.triangles()
    prepared = clock()
    areas = [cover_zone(triangles, [zone.ring]).total(triangles.surface_area) for zone in zones]
    zoned = clock()
    length = lift_curve(triangles, curve).length
    done = clock()
    return dict(
        prep=prepared - start,
        zones=zoned - prepared,
        curve=done - zoned,
        areas=areas,
        length=length,
    )


# -- the peer: shapely 2 -----------------------------------------------------------------


@dataclass(frozen=True)
class PeerTriangles:
    """The triangles as shapely polygons, an STRtree over them, their map and surface areas
    and what lifts a map vector of each onto the surface."""

    polygons: np.ndarray
    tree: shapely.STRtree
    map_area: np.ndarray
    surface_area: np.ndarray
    map_corners: np.ndarray  # (m, 3, 2)
    surface_corners: np.ndarray  # (m, 3, 3)


def peer_prep(region: Region, times: dict) -> PeerTriangles:
    clock = time.perf_counter
    start = clock()
    map_points = np.column_stack([region.x, region.y])
    closed = map_points[np.column_stack([region.faces, region.faces[:, :1]])]
    polygons = shapely.polygons(closed)  # closed rings: shapely need not close them
    built = clock()
    tree = shapely.STRtree(polygons)
    planted = clock()
    map_corners = closed[:, :3]
    e1, e2 = map_corners[:, 1] - map_corners[:, 0], map_corners[:, 2] - map_corners[:, 0]
    map_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    surface_corners = region.surface_points[region.faces]
    u = surface_corners[:, 1] - surface_corners[:, 0]
    v = surface_corners[:, 2] - surface_corners[:, 0]
    normal = [u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]]
    normal.append(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    surface_area = 0.5 * np.sqrt(sum(c * c for c in normal))
    done = clock()
    times.update(polygons=built - start, tree=planted - built, face_areas=done - planted)
    return PeerTriangles(polygons, tree, map_area, surface_area, map_corners, surface_corners)


def zone_all(peer: PeerTriangles, zone: shapely.Polygon) -> float:
    """Every triangle clipped by the (prepared) zone."""
    shapely.prepare(zone)
    share = shapely.area(shapely.intersection(peer.polygons, zone)) / peer.map_area
    return float(np.dot(share, peer.surface_area))


def zone_meeting(peer: PeerTriangles, zone: shapely.Polygon) -> float:
    """The triangles the STRtree finds meeting the zone clipped."""
    near = peer.tree.query(zone, predicate="intersects")
    share = shapely.area(shapely.intersection(peer.polygons[near], zone)) / peer.map_area[near]
    return float(np.dot(share, peer.surface_area[near]))


def zone_split(peer: PeerTriangles, zone: shapely.Polygon) -> float:
    """The triangles meeting the zone's boundary clipped, those it contains counted whole."""
    cut = peer.tree.query(zone.boundary, predicate="intersects")
    whole = np.setdiff1d(peer.tree.query(zone, predicate="contains"), cut)
    share = shapely.area(shapely.intersection(peer.polygons[cut], zone)) / peer.map_area[cut]
    return float(np.dot(share, peer.surface_area[cut]) + peer.surface_area[whole].sum())


ZONE_VARIANTS: dict[str, Callable[[PeerTriangles, shapely.Polygon], float]] = {
    "every triangle clipped (zone prepared)": zone_all,
    "STRtree query `intersects` zone, those clipped": zone_meeting,
    "STRtree: boundary's triangles clipped, `contains` counted whole": zone_split,
}


def curve_length(peer: PeerTriangles, curve: shapely.LineString) -> float:
    """The curve's pieces in the triangles the STRtree finds meeting it, each segment lifted
    by its triangle's affine map."""
    near = peer.tree.query(curve, predicate="intersects")
    pieces = shapely.intersection(peer.polygons[near], curve)
    parts, owner = shapely.get_parts(pieces, return_index=True)
    lines = shapely.get_type_id(parts) == shapely.GeometryType.LINESTRING
    parts, owner = parts[lines], owner[lines]
    coords, part = shapely.get_coordinates(parts, return_index=True)
    same = part[1:] == part[:-1]
    step = (coords[1:] - coords[:-1])[same]
    triangle = near[owner[part[:-1][same]]]
    m, s = peer.map_corners[triangle], peer.surface_corners[triangle]
    e1, e2 = m[:, 1] - m[:, 0], m[:, 2] - m[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    w1 = (step[:, 0] * e2[:, 1] - step[:, 1] * e2[:, 0]) / det
    w2 = (e1[:, 0] * step[:, 1] - e1[:, 1] * step[:, 0]) / det
    lifted = w1[:, None] * (s[:, 1] - s[:, 0]) + w2[:, None] * (s[:, 2] - s[:, 0])
    return float(np.linalg.norm(lifted, axis=1).sum())


def peer_run(region: Region, zones: list[Zone], curve: np.ndarray, variant: str) -> dict:
    clock = time.perf_counter
    times: dict = {}
    start = clock()
    peer = peer_prep(region, times)
    prepared = clock()
    polygons = [shapely.Polygon(zone.ring) for zone in zones]
    areas = [ZONE_VARIANTS[variant](peer, zone) for zone in polygons]
    zoned = clock()
    length = curve_length(peer, shapely.LineString(curve))
    done = clock()
    times.update(prep=prepared - start, zones=zoned - prepared, curve=done - zoned)
    return dict(times, areas=areas, length=length)


# -- the runs ------------------------------------------------------------------------------


def quiet(work: Callable[[], dict]) -> dict:
    """``work()`` with the cyclic garbage collector off, after a collection (as timeit)."""
    gc.collect()
    gc.disable()
    try:
        return work()
    finally:
        gc.enable()


def pick_variant(region: Region, zones: list[Zone]) -> tuple[str, dict[str, float]]:
    """Each of the peer's zone variants once (on triangles prepared once): its seconds for
    the zones; the fastest's name."""
    peer = peer_prep(region, {})
    polygons = [shapely.Polygon(zone.ring) for zone in zones]
    seconds = {}
    for name, variant in ZONE_VARIANTS.items():
        progress(f"peer variant: {name}")
        start = time.perf_counter()
        quiet(lambda variant=variant: {"areas": [variant(peer, zone) for zone in polygons]})
        seconds[name] = time.perf_counter() - start
    return min(seconds, key=seconds.get), seconds


def alternate(region: Region, zones: list[Zone], curve: np.ndarray, variant: str, runs: int):
    """A warm-up of each, then ``runs`` runs of meshflat and of the peer in turn."""
    ours = [quiet(lambda: meshflat_run(region, zones, curve))]
    peers = [quiet(lambda: peer_run(region, zones, curve, variant))]
    for run in range(runs):
        progress(f"run {run + 1} of {runs}")
        ours.append(quiet(lambda: meshflat_run(region, zones, curve)))
        peers.append(quiet(lambda: peer_run(region, zones, curve, variant)))
    return ours, peers


# -- the report --------------------------------------------------------------------------


def ms(runs: list[dict], key: str) -> float:
    """The median over the timed runs (the warm-up, first, left out), in milliseconds."""
    return statistics.median(run[key] for run in runs[1:]) * 1e3


def total_ms(runs: list[dict]) -> float:
    return statistics.median(run["prep"] + run["zones"] + run["curve"] for run in runs[1:]) * 1e3


def relative(ours: float, theirs: float) -> float:
    return (ours - theirs) / theirs


def timing_rows(ours: list[dict], peers: list[dict], zones_agree: float, curve_agree: float):
    def row(measure, mine, theirs, target="-", met="-", agreement="-"):
        ratio = f"{theirs / mine:,.1f}x" if mine is not None and theirs is not None else "-"
        mine = "-" if mine is None else f"{mine:,.1f}"
        theirs = "-" if theirs is None else f"{theirs:,.1f}"
        return f"| {measure} | {mine} | {theirs} | {ratio} | {target} | {met} | {agreement} |"

    total, peer_total = total_ms(ours), total_ms(peers)
    return [
        row(
            "total: prep + 10 zones + curve",
            total,
            peer_total,
            f"<= {TARGET_MS:.0f} ms",
            "yes" if total <= TARGET_MS else "no",
            f"{max(zones_agree, curve_agree):.1e}",
        ),
        row(
            "prep: MapTriangles and its per-face values / polygons, STRtree, areas",
            ms(ours, "prep"),
            ms(peers, "prep"),
        ),
        row("of which `shapely.polygons` of the triangles", None, ms(peers, "polygons")),
        row("of which the STRtree", None, ms(peers, "tree")),
        row("of which map and surface areas (numpy)", None, ms(peers, "face_areas")),
        row(
            f"{ZONES} zones of {ZONE_POINTS} points: surface area",
            ms(ours, "zones"),
            ms(peers, "zones"),
            agreement=f"{zones_agree:.1e}",
        ),
        row(
            f"hairline of {CURVE_POINTS} points: surface length",
            ms(ours, "curve"),
            ms(peers, "curve"),
            agreement=f"{curve_agree:.1e}",
        ),
    ]


def agreement_rows(zones: list[Zone], ours: dict, peer: dict) -> list[str]:
    lines = [
        "| drawn | turning | across (share of the map's extent) | meshflat | shapely 2 "
        "| relative difference |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for number, (zone, mine, theirs) in enumerate(
        zip(zones, ours["areas"], peer["areas"], strict=True)
    ):
        turning = "counter-clockwise" if zone.counter_clockwise else "clockwise"
        lines.append(
            f"| zone {number + 1}: surface area (mm²) | {turning} | {zone.size:.0%} | {mine:,.3f} "
            f"| {theirs:,.3f} | {relative(mine, theirs):.1e} |"
        )
    lines.append(
        f"| hairline: surface length (mm) | - | - | {ours['length']:,.4f} | {peer['length']:,.4f} "
        f"| {relative(ours['length'], peer['length']):.1e} |"
    )
    return lines


def overlapping_pairs(zones: list[Zone]) -> int:
    polygons = [shapely.Polygon(zone.ring) for zone in zones]
    return sum(
        bool(shapely.intersects(a, b)) for i, a in enumerate(polygons) for b in polygons[i + 1 :]
    )


def measure(runs: int) -> str:
    progress(f"fsaverage-head.ply subdivided {SUBDIVISIONS} times, flattened")
    region = Region.flattened()
    triangles = region.triangles()
    zones, curve = draw_zones(triangles), draw_hairline(triangles)
    on_region = float(np.mean(triangles.locate(curve)[0] >= 0))
    variant, variants = pick_variant(region, zones)
    ours, peers = alternate(region, zones, curve, variant, runs)
    zones_agree = max(
        abs(relative(a, b)) for a, b in zip(ours[0]["areas"], peers[0]["areas"], strict=True)
    )
    curve_agree = abs(relative(ours[0]["length"], peers[0]["length"]))
    tried = "; ".join(f"{name}: {seconds * 1e3:,.0f} ms" for name, seconds in variants.items())
    lines = [
        f"`fsaverage-head.ply` subdivided {SUBDIVISIONS} times, the faces within "
        f"{HALF_ANGLE_DEG:g} degrees of up from the head's box centre: {len(region.faces):,} "
        f"faces, {len(region.x):,} vertices, flattened once from that centre (pole at the chin, "
        f"sigma {SIGMA}; {region.flagged} faces flagged). Drawn on its map: {ZONES} wobbly "
        f"ellipses of {ZONE_POINTS} points, {ZONE_SIZES[0]:.0%} to {ZONE_SIZES[1]:.0%} of the "
        f"map's extent across, on the region, {overlapping_pairs(zones)} pairs overlapping; "
        f"a hairline of {CURVE_POINTS} points ({on_region:.0%} of them on the region). One "
        f"thread, BLAS on one thread; median of {runs} runs after a warm-up, meshflat and "
        "shapely in turn in the same process, the garbage collector off during each. "
        f"shapely {version('shapely')} (GEOS {shapely.geos_version_string}): its zones "
        f"variant timed is the fastest of those tried once ({tried}): **{variant}**. "
        "Agreement: the largest relative difference of the zones' surface areas and of the "
        "hairline's surface length, meshflat against shapely.",
        "",
        "| measure | meshflat (ms) | shapely 2 (ms) | shapely / meshflat | target | met "
        "| agreement |",
        "|---|---:|---:|---:|---|---|---:|",
        *timing_rows(ours, peers, zones_agree, curve_agree),
        "",
        *agreement_rows(zones, ours[0], peers[0]),
        "",
        footer(f"numpy {np.__version__}", f"shapely {version('shapely')}"),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=7, help="timed runs of each (median)")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    report = measure(args.runs)
    publish("measure-bench", "Zones on the map (`make bench-measure`)", report, args.write_docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
