"""Benchmark of the growth field (``make bench-growth``): which way the hair grows at 100,000
sites on a million-face scalp, against potpourri3d's vector heat method.

The region: ``fsaverage-head.ply`` (millimetres) subdivided 5 times, the faces the service's
cone selects (``region.cone``: axis +z, its apex the whole mesh's box centre in its own axes)
at 52 degrees: about a million faces, one disk. The 70 degrees of the service's tests take
392,704 faces of the head subdivided 4 times and about 1.57M subdivided 5 times; 52 degrees
gives the million faces of ``make bench-measure``. It is flattened as ``/v1/sites`` flattens a
request with no parameters: :func:`transforms.default_choice` at the middle of the region's box
in its own axes. 100,000 sites are placed on it at the default spacing
(:func:`transforms.sites.place_sites`, then their normals and map points), timed in a row of
their own and in no other.

Drawn on the map, each point the map point of a direction seen from the frame's centre (the
head's axes: +x right, +y front, +z up): 5 flow curves of 100 points (a hairline across the
front from left to right; the left temple's hair growing forward; the right temple's growing
down; two parallel strokes on the top growing forward and to the right) and a whorl at the
crown turning clockwise seen from outside.

* meshflat: the flows lifted (:func:`transforms.lift_curve`), the field
  (:func:`transforms.growth.growth_field`), its map directions at the sites and their surface
  tangents (:func:`transforms.growth.pushed_forward`), on the map's triangles built afresh
  (:class:`transforms.MapTriangles`, its cached per-face values counted where growth first
  needs them). Target (issue 33): 1 s on one thread. The same with the flows alone (no whorl)
  is the like of the peer's.
* the peer, potpourri3d's vector heat method (geometry-central's), timed alternately with
  meshflat in the same process on the same surface (the region's vertices and faces):
  ``MeshVectorHeatSolver(V, F)`` with its defaults (``t_coef`` 1, the intrinsic Delaunay
  triangulation), the flows' tangents written in its vertex frames (``get_tangent_frames``),
  ``transport_tangent_vectors``, and the vertex vectors interpolated at the sites with their
  barycentric weights, in each site's tangent plane. The flows' tangent at a vertex of a
  triangle they cross is the sum of the lifted flows' pieces on such triangles around it
  (computed once, outside the timing). It has no whorls: it is compared with meshflat's field
  of the flows alone.

Agreement: the angle between the two fields' tangents at the sites, mean and 95th percentile,
over all the sites and by distance from the nearest flow. One thread (BLAS and OpenMP);
median of several runs, meshflat's after a warm-up (the peer's run, a minute, is not repeated
for one); the garbage collector off during each.

potpourri3d 1.4.0 (MIT) is a binary wheel of 3.6 MB (cp311, manylinux; nothing to build) that
needs numpy and scipy only. It installed in 0.4 s from the wheel (``pip install --no-deps``,
three times) and takes 12.9 MB (``du -b`` of the files its RECORD lists), of which 9.8 MB is a
static library the wheel puts in ``site-packages/lib`` and nothing loads, and 3.0 MB the
extension module.

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python -m benchmarks.growth_bench [--runs 3]
        [--write-docs]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from dataclasses import dataclass
from importlib.metadata import distribution, version
from pathlib import Path

import numpy as np
import scipy
import shapely
from scipy.spatial import cKDTree

from benchmarks.docs import footer, publish
from benchmarks.fit_bench import compact
from benchmarks.measure_bench import progress, quiet
from fixtures.meshes import subdivided
from service.server.allocator import keep_large_blocks
from transforms import (
    Chart,
    FitFixed,
    Frame,
    Layout,
    MapTriangles,
    Polyline,
    default_choice,
    layout_xy,
    lift_curve,
    world_to_angles,
)
from transforms.arrays import triangle_areas
from transforms.growth import growth_field, pushed_forward
from transforms.selection import bbox_center, cone_faces, named_center
from transforms.sites import SitePart, default_spacing, place_sites, site_normals

#: The issue's target for the field and the directions at the sites, in milliseconds.
TARGET_MS = 1000.0
SUBDIVISIONS = 5
CONE_AXIS = (0.0, 0.0, 1.0)
HALF_ANGLE_DEG = 52.0
SITES = 100_000
FLOW_POINTS = 100
#: The strokes on the top are drawn on a sphere about the size of the head, mm.
TOP_RADIUS = 90.0
#: The crown's direction from the frame's centre: azimuth (from the front towards the right)
#: and elevation, degrees.
CROWN = (180.0, 65.0)
#: Distances from the nearest flow (mm) that the agreement is reported by.
BANDS = (0.0, 5.0, 15.0, 30.0, 60.0, np.inf)
SEED = 2033
_NONE = np.empty(0)


# -- the region, what is drawn on it and the sites ------------------------------------------


@dataclass(frozen=True)
class Scalp:
    """The region flattened with the service's default choice, and how it was."""

    x: np.ndarray
    y: np.ndarray
    surface_points: np.ndarray
    faces: np.ndarray
    front: int
    frame: Frame
    chart: Chart
    layout: Layout
    flagged: int

    @classmethod
    def fitted(cls, subdivisions: int = SUBDIVISIONS, half_angle_deg: float = HALF_ANGLE_DEG):
        """The cone's region of the bundled head subdivided ``subdivisions`` times, fitted."""
        vertices, faces = subdivided("fsaverage-head.ply", subdivisions)
        apex = bbox_center(vertices, faces)
        chosen = cone_faces(vertices, faces, apex, CONE_AXIS, half_angle_deg)
        vertices, faces = compact(vertices, faces[chosen])
        fit = default_choice(
            vertices, faces, FitFixed(center=named_center(vertices, faces, "bbox_center"))
        )
        flat = fit.region
        front = flat.layout.front_orientation(flat.validation.winding)
        surface = np.ascontiguousarray(vertices[flat.vertex_ids])
        return cls(flat.x, flat.y, surface, flat.faces, front, fit.frame, fit.chart,
                   flat.layout, flat.flagged_faces)  # fmt: skip

    def triangles(self) -> MapTriangles:
        return MapTriangles.of(self.x, self.y, self.surface_points, self.faces, self.front)

    def seen(self, directions: np.ndarray) -> np.ndarray:
        """(p, 2): the map points of ``directions`` ((p, 3)) seen from the frame's centre
        (the map point of a surface point is its direction's)."""
        theta, phi, _ = world_to_angles(self.frame.center + directions, self.frame, self.chart)
        x, y = layout_xy(theta, phi, self.layout)
        return np.column_stack([x, y])


def around(azimuth_deg, elevation_deg) -> np.ndarray:
    """(p, 3) unit directions: azimuth from the front (+y) towards the right (+x), elevation
    above the horizontal, degrees."""
    azimuth, elevation = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.column_stack([
        np.cos(elevation) * np.sin(azimuth),
        np.cos(elevation) * np.cos(azimuth),
        np.sin(elevation),
    ])  # fmt: skip


def on_top(right, forward) -> np.ndarray:
    """(p, 3): the points of a sphere of ``TOP_RADIUS`` seen from above at ``right`` and
    ``forward`` (mm)."""
    right, forward = np.asarray(right, dtype=np.float64), np.asarray(forward, dtype=np.float64)
    return np.column_stack([right, forward, np.sqrt(TOP_RADIUS**2 - right**2 - forward**2)])


@dataclass(frozen=True)
class Drawn:
    """The flows (map polylines, in the way the hair grows) and the whorl at the crown."""

    names: tuple[str, ...]
    flows: tuple[np.ndarray, ...]
    whorl: np.ndarray  # (1, 2)

    def whorl_turns(self, triangles: MapTriangles) -> np.ndarray:
        """Clockwise seen from outside, on the map (as the service turns it)."""
        return np.array([-1 * triangles.front])


def draw(scalp: Scalp) -> Drawn:
    s = np.linspace(0.0, 1.0, FLOW_POINTS)
    level = np.ones(FLOW_POINTS)
    curves = {
        "hairline, left to right": around(-50 + 100 * s, 15 + 3 * np.sin(np.pi * s)),
        "left temple, forward": around(-105 + 35 * s, 10 * level),
        "right temple, down": around(75 * level, 40 - 40 * s),
        "top, forward and right": on_top(-35 + 35 * s, 35 * s),
        "top, forward and right, beside it": on_top(-15 + 35 * s, -20 + 35 * s),
    }
    drawn = Drawn(
        tuple(curves),
        tuple(scalp.seen(directions) for directions in curves.values()),
        scalp.seen(around([CROWN[0]], [CROWN[1]])),
    )
    triangles = scalp.triangles()
    for flow in (*drawn.flows, drawn.whorl):
        assert (triangles.locate(flow)[0] >= 0).all()  # all on the region
    lines = [shapely.LineString(flow) for flow in drawn.flows]
    assert not any(a.crosses(b) for i, a in enumerate(lines) for b in lines[i + 1 :])
    return drawn


@dataclass(frozen=True)
class Placed:
    """The sites: their triangles, weights, surface points, unit normals and map points."""

    triangles: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    map_points: np.ndarray


def place(scalp: Scalp) -> dict:
    """``SITES`` sites over the region at the default spacing, as ``/v1/sites`` places them."""
    start = time.perf_counter()
    triangles = scalp.triangles()
    area = triangle_areas(scalp.surface_points, scalp.faces)
    part = SitePart(np.arange(len(area)), area, SITES, default_spacing(SITES / area.sum()))
    placed = place_sites(scalp.surface_points, scalp.faces, [part], np.random.default_rng(SEED))
    normals = site_normals(scalp.surface_points, scalp.faces, placed, scalp.frame.center)
    map_points = triangles.on_map(placed.triangles, placed.weights)
    sites = Placed(placed.triangles, placed.weights, placed.points, normals, map_points)
    return {"seconds": time.perf_counter() - start, "sites": sites, "spacing": part.spacing}


# -- meshflat and the peer ------------------------------------------------------------------


def meshflat_run(scalp: Scalp, drawn: Drawn, sites: Placed, whorl: bool) -> dict:
    """One timed run: the flows lifted, the field, the directions and the tangents at the
    sites (seconds each), and the tangents."""
    clock = time.perf_counter
    start = clock()
    triangles = scalp.triangles()
    lifted = [lift_curve(triangles, flow) for flow in drawn.flows]
    lifted_at = clock()
    whorls, turns = (drawn.whorl, drawn.whorl_turns(triangles)) if whorl else (_NONE, _NONE)
    field = growth_field(triangles, lifted, whorls, turns)
    field_at = clock()
    directions = field.map_directions(sites.map_points, sites.triangles)
    directions_at = clock()
    tangent, _ = pushed_forward(triangles, sites.triangles, directions, sites.normals)
    done = clock()
    return {
        "total": done - start,
        "lift": lifted_at - start,
        "field": field_at - lifted_at,
        "directions": directions_at - field_at,
        "tangents": done - directions_at,
        "tangent": tangent,
        "grid": field.smooth.shape,
    }


@dataclass(frozen=True)
class Constraints:
    """The flows' tangents at the vertices of the triangles they cross: at each vertex, the
    sum of the lifted pieces (surface vectors) on those triangles around it."""

    vertices: np.ndarray
    tangents: np.ndarray

    @classmethod
    def of(cls, triangles: MapTriangles, lifted: list[Polyline]) -> Constraints:
        faces, pieces = [], []
        for line in lifted:
            on = line.faces >= 0
            faces.append(line.faces[on])
            pieces.append(np.diff(line.surface_points, axis=0)[on])
        corners = triangles.faces[np.concatenate(faces)].ravel()
        summed = np.zeros_like(triangles.surface_points)
        np.add.at(summed, corners, np.repeat(np.concatenate(pieces), 3, axis=0))
        vertices = np.unique(corners)
        return cls(vertices, summed[vertices])


def peer_run(scalp: Scalp, constraints: Constraints, sites: Placed) -> dict:
    """One timed run of the vector heat method: the solver, the transport (its frames, the
    flows' tangents in them) and the tangents at the sites (not finite where it gives none)."""
    import potpourri3d as pp3d

    clock = time.perf_counter
    start = clock()
    solver = pp3d.MeshVectorHeatSolver(scalp.surface_points, scalp.faces)
    built = clock()
    basis_x, basis_y, _ = solver.get_tangent_frames()
    at = constraints.vertices
    given = np.column_stack([
        np.einsum("pd,pd->p", constraints.tangents, basis_x[at]),
        np.einsum("pd,pd->p", constraints.tangents, basis_y[at]),
    ])  # fmt: skip
    given /= np.linalg.norm(given, axis=1, keepdims=True)
    field = solver.transport_tangent_vectors(at, given)
    transported = clock()
    # Far from every flow the peer's heat underflows and its direction is not finite: kept so,
    # and counted in the report.
    with np.errstate(invalid="ignore", divide="ignore"):
        on_vertices = field[:, :1] * basis_x + field[:, 1:] * basis_y
        corners = on_vertices[scalp.faces[sites.triangles]]
        tangent = np.einsum("pk,pkd->pd", sites.weights, corners)
        tangent -= np.einsum("pd,pd->p", tangent, sites.normals)[:, None] * sites.normals
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    done = clock()
    return {
        "total": done - start,
        "build": built - start,
        "transport": transported - built,
        "sites": done - transported,
        "tangent": tangent,
    }


# -- the runs and the report ----------------------------------------------------------------


@dataclass
class Runs:
    """The timed runs of each (dicts of seconds and results)."""

    placement: list[dict]
    ours: list[dict]
    alone: list[dict]
    peer: list[dict]


def alternate(scalp: Scalp, drawn: Drawn, sites: Placed, runs: int) -> Runs:
    """A warm-up of meshflat's, then ``runs`` rounds of the placement, meshflat with the
    whorl, meshflat with the flows alone and the peer, in turn."""
    lifted = [lift_curve(scalp.triangles(), flow) for flow in drawn.flows]
    constraints = Constraints.of(scalp.triangles(), lifted)
    timed = Runs([], [], [], [])
    for run in range(runs + 1):
        placed = quiet(lambda: place(scalp))
        ours = quiet(lambda: meshflat_run(scalp, drawn, sites, whorl=True))
        alone = quiet(lambda: meshflat_run(scalp, drawn, sites, whorl=False))
        seen = f"placement {placed['seconds']:.2f} s, growth {ours['total']:.2f} s, "
        seen += f"flows alone {alone['total']:.2f} s"
        if run == 0:
            progress(f"warm-up: {seen}")
            continue
        peer = quiet(lambda: peer_run(scalp, constraints, sites))
        progress(f"run {run} of {runs}: {seen}, potpourri3d {peer['total']:.1f} s")
        timed.placement.append(placed)
        timed.ours.append(ours)
        timed.alone.append(alone)
        timed.peer.append(peer)
    return timed


def ms(runs: list[dict], key: str) -> float:
    return statistics.median(run[key] for run in runs) * 1e3


def timing_rows(timed: Runs) -> list[str]:
    def row(measure, mine=None, theirs=None, target="-", met="-"):
        ratio = "-" if mine is None or theirs is None else f"{theirs / mine:,.0f}x"
        mine = "-" if mine is None else f"{mine:,.1f}"
        theirs = "-" if theirs is None else f"{theirs:,.1f}"
        return f"| {measure} | {mine} | {theirs} | {ratio} | {target} | {met} |"

    total, count = ms(timed.ours, "total"), len(timed.ours[0]["tangent"])
    return [
        "| measure | meshflat (ms) | potpourri3d (ms) | potpourri3d / meshflat | target | met |",
        "|---|---:|---:|---:|---|---|",
        row(
            f"growth: 5 flows and a whorl, tangents at {count:,} sites",
            total,
            None,
            f"<= {TARGET_MS:,.0f} ms",
            "yes" if total <= TARGET_MS else "no",
        ),
        row("of which the flows lifted (`lift_curve`)", ms(timed.ours, "lift")),
        row("of which the field (`growth_field`)", ms(timed.ours, "field")),
        row("of which the map directions at the sites", ms(timed.ours, "directions")),
        row("of which the tangents (`pushed_forward`)", ms(timed.ours, "tangents")),
        row(
            "growth: the 5 flows alone (no whorl)",
            ms(timed.alone, "total"),
            ms(timed.peer, "total"),
        ),
        row("of which the solver (`MeshVectorHeatSolver`)", None, ms(timed.peer, "build")),
        row(
            "of which the frames, the flows' tangents in them, `transport_tangent_vectors`",
            None,
            ms(timed.peer, "transport"),
        ),
        row("of which the tangents at the sites (interpolated)", None, ms(timed.peer, "sites")),
        row(
            f"the {count:,} sites placed, their normals and map points (in no row above)",
            ms(timed.placement, "seconds"),
        ),
    ]


def agreement_rows(scalp: Scalp, drawn: Drawn, sites: Placed, ours, theirs) -> list[str]:
    """The angle between meshflat's tangents of the flows alone and the peer's at the sites,
    over them all, on the flows' triangles and by distance from the nearest flow."""
    cosine = np.clip(np.einsum("pd,pd->p", ours, theirs), -1.0, 1.0)
    angle = np.degrees(np.arccos(cosine))
    given = np.isfinite(angle)
    triangles = scalp.triangles()
    lifted = [lift_curve(triangles, flow) for flow in drawn.flows]
    crossed = np.zeros(len(triangles), dtype=bool)
    for line in lifted:
        crossed[line.faces[line.faces >= 0]] = True
    on_flows = np.concatenate([line.surface_points for line in lifted])
    distance, _ = cKDTree(on_flows).query(sites.points)

    def row(name: str, chosen: np.ndarray) -> str:
        chosen = chosen & given
        mean, p95 = angle[chosen].mean(), np.percentile(angle[chosen], 95)
        return f"| {name} | {int(chosen.sum()):,} | {mean:.1f} | {p95:.1f} |"

    lines = [
        "| sites | count | mean angle (deg) | 95th percentile (deg) |",
        "|---|---:|---:|---:|",
        row("all (where the peer gives a direction)", given),
        row("on the triangles the flows cross", crossed[sites.triangles]),
    ]
    for low, high in itertools.pairwise(BANDS):
        name = (
            f"{low:g} to {high:g} mm from a flow"
            if high < np.inf
            else f"over {low:g} mm from a flow"
        )
        lines.append(row(name, (distance >= low) & (distance < high)))
    none = ~given
    where = f", all over {distance[none].min():.0f} mm from a flow" if none.any() else ""
    lines += ["", f"The peer gives no direction (not finite) at {int(none.sum()):,} sites{where}."]
    return lines


def installed_mb(package: str) -> float:
    """The size of the files ``package``'s RECORD lists, as installed, MB."""
    files = distribution(package).files or []
    paths = [Path(file.locate()) for file in files]
    return sum(path.stat().st_size for path in paths if path.is_file()) / 1e6


def measure(runs: int) -> str:
    progress(f"fsaverage-head.ply subdivided {SUBDIVISIONS} times, its cone, the default fit")
    scalp = Scalp.fitted()
    drawn = draw(scalp)
    placed = place(scalp)
    sites = placed["sites"]
    timed = alternate(scalp, drawn, sites, runs)
    peer = f"potpourri3d {version('potpourri3d')}"
    intro = (
        f"`fsaverage-head.ply` subdivided {SUBDIVISIONS} times, the faces of the cone about +z "
        f"from its box centre at {HALF_ANGLE_DEG:g} degrees: {len(scalp.faces):,} faces, "
        f"{len(scalp.x):,} vertices, flattened with the service's default choice (sigma "
        f"{scalp.chart.cap.sigma:.4g}; {scalp.flagged} faces flagged). {len(sites.points):,} "
        f"sites at the default spacing ({placed['spacing']:.3f} mm). Drawn: 5 flows of "
        f"{FLOW_POINTS} points ({'; '.join(drawn.names)}) and a whorl at the crown, "
        f"clockwise; the field's grid {timed.ours[0]['grid'][1]} x {timed.ours[0]['grid'][0]} "
        f"cells. One thread; median of {runs} runs, meshflat's after a warm-up, meshflat and "
        f"the peer in turn in the same process, the garbage collector off during each. The "
        f"peer, {peer} (`MeshVectorHeatSolver`, its defaults; {installed_mb('potpourri3d'):.1f}"
        " MB installed), has no whorls: it is timed and compared against meshflat's field of "
        "the flows alone."
    )
    ours, theirs = timed.alone[0]["tangent"], timed.peer[0]["tangent"]
    lines = [
        intro,
        "",
        *timing_rows(timed),
        "",
        "The angle between meshflat's tangents (the flows alone) and the peer's at the sites:",
        "",
        *agreement_rows(scalp, drawn, sites, ours, theirs),
        "",
        footer(f"numpy {np.__version__}", f"scipy {scipy.__version__}", peer),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="timed runs of each (median)")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    publish(
        "growth-bench",
        "The growth field (`make bench-growth`)",
        measure(args.runs),
        args.write_docs,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
