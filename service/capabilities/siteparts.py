"""The parts a /v1/sites placement is made of (docs/math.md, section 13): a zone's
triangles open to sites, or the region's, or the region's at a density map's densities;
each part's quota of a count; and what the answer says of each part."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from transforms import Framing, MapTriangles, cover_zone
from transforms.sites import SitePart

from ..errors import InvalidInput
from .drawn import Outline
from .region.resolve import MeshRegion


@dataclass(frozen=True)
class SiteZoneResult:
    """One part that got sites: a zone, or the whole region (``outline`` None).

    Attributes
    ----------
    name : str
    outline : Outline or None
    area : float, its surface area, mesh units²
    open_area : float, the part of it sites may go on (flagged triangles left out unless
        allowed), mesh units²
    density_per_cm2 : float, the density asked for
    quota : int, its sites
    spacing : float or None, the least distance between its sites and any other, mesh units
        (None without sites)
    achieved : float, its sites per cm² of ``open_area``
    """

    name: str
    outline: Outline | None
    area: float
    open_area: float
    density_per_cm2: float
    quota: int
    spacing: float | None
    achieved: float


@dataclass(frozen=True)
class Part:
    """A zone's (or the region's) triangles open to sites, as the core's part before its
    quota and spacing (known once every part's expected count is), with what the answer says
    of the zone: its outline, its whole surface area and the one density asked for (None for
    a density map). ``core.density`` is the density asked for on each triangle, per cm²."""

    core: SitePart
    outline: Outline | None
    area: float
    asked: float | None

    def sites(self, quota: int, spacing: np.ndarray) -> SitePart:
        """The core's part: ``quota`` sites at ``spacing`` ((j,) float) on these triangles."""
        return replace(self.core, quota=quota, spacing=spacing)

    def result(self, quota: int, spacing: float | None, unit_area: float) -> SiteZoneResult:
        weight, density = self.core.area, self.core.density
        open_area = float(weight[density > 0].sum())
        mean = self.asked
        if mean is None:  # a density map: its mean over the area it puts sites on
            mean = float(np.dot(weight, density) / open_area) if open_area else 0.0
        open_cm2 = open_area * unit_area
        achieved = quota / open_cm2 if open_cm2 > 0 else 0.0
        return SiteZoneResult(
            self.core.name, self.outline, self.area, open_area, mean, quota, spacing, achieved
        )


def zone_parts(triangles: MapTriangles, params, outlines, open_faces):
    """A part for each zone (its own density, or params.density_per_cm2), or the region's."""
    area = triangles.surface_area
    if not outlines:
        faces = np.flatnonzero(open_faces)
        asked = float(params.density_per_cm2)
        density = np.full(len(faces), asked)
        core = SitePart(faces, area[faces], 0, 0.0, density, name="region")
        yield Part(core, None, float(area.sum()), asked)
        return
    for outline, zone in zip(outlines, params.zones, strict=True):
        cover = cover_zone(triangles, outline.rings)
        faces = np.concatenate([cover.inside, cover.partial])
        weight = np.concatenate([area[cover.inside], area[cover.partial] * cover.share])
        partial = np.r_[np.zeros(len(cover.inside), bool), np.ones(len(cover.partial), bool)]
        keep = open_faces[faces]
        asked = float(zone.density_per_cm2 or params.density_per_cm2)
        density = np.full(int(keep.sum()), asked)

        def inside(faces, weights, cover=cover):
            return cover.winding(triangles.on_map(faces, weights)) != 0

        core = SitePart(
            faces[keep], weight[keep], 0, 0.0, density, partial[keep], inside,
            area[faces[keep]], outline.name,
        )  # fmt: skip
        yield Part(core, outline, cover.total(area), asked)


def density_map_part(region: MeshRegion, triangles: MapTriangles, image, open_faces) -> Part:
    """The region's open triangles, each at the density of the pixel under its centroid on
    the map, in the framing of the PNG answer (:class:`transforms.Framing`)."""
    height, width = image.shape
    x, y = region.layout
    framing = Framing.of(x, y, region.flat.layout, width, height)
    centroids = np.column_stack([triangles.corner_x.mean(axis=0), triangles.corner_y.mean(axis=0)])
    column, row = np.floor(framing.pixels(centroids)).astype(np.int64).T
    shown = (column >= 0) & (column < width) & (row >= 0) & (row < height)
    density = np.zeros(len(centroids))
    density[shown] = image[row[shown], column[shown]]
    faces = np.flatnonzero(open_faces)
    area = triangles.surface_area
    core = SitePart(faces, area[faces], 0, 0.0, density[faces], name="density map")
    return Part(core, None, float(area.sum()), None)


def part_quotas(expected: list[float], count: int | None) -> list[int]:
    """Each part's sites: its expected number rounded, or, with ``count``, its share of
    ``count`` by the largest remainders (the total exact, the ratios kept)."""
    expected = np.asarray(expected, dtype=np.float64)
    if count is None:
        return np.rint(expected).astype(int).tolist()
    if not expected.sum() > 0:
        raise InvalidInput("count", "no part of the region is open to sites at a density above 0")
    share = expected / expected.sum() * count
    quotas = np.floor(share).astype(int)
    order = np.argsort(-(share - quotas), kind="stable")
    quotas[order[: count - quotas.sum()]] += 1
    return quotas.tolist()
