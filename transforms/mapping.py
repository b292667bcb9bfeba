"""The map's correspondence with the surface (docs/math.md, section 12): inside each region
triangle the map is linear, so a map point in a triangle's image stands for the surface
point with the same barycentric weights, as the GLB's UVs and the pictures draw it.

:class:`MapTriangles` holds a region's triangles in both places and answers what the
measurements of :mod:`.zones` and a click on the picture need: which triangles a box meets,
which triangle holds a map point, and the surface point of a map point in a triangle.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .arrays import as_faces, as_points, combine, triangle_areas
from .cellgrid import CellGrid, CellIndex
from .errors import TransformInputError

#: The typical triangle size is the median box side of this many triangles at most.
SIZE_SAMPLE = 4096
#: A point this close to a triangle's edge, in its barycentric weights, is in the triangle.
BARYCENTRIC_SLACK = 1e-12
#: Slack around a triangle's box, in typical sizes, beyond what its weights' slack reaches.
BOX_SLACK = 1e-9


@dataclass(frozen=True)
class MapTriangles:
    """A region's triangles on the map (the layout) and on the surface.

    Attributes
    ----------
    map_points : (k, 2) float, the vertices on the map (the layout's ``x``, ``y``)
    surface_points : (k, 3) float, the same vertices on the surface
    faces : (m, 3) int, positions in both arrays
    front : int, the sign of a front-facing triangle's signed area on the map (+1 or -1)
    """

    map_points: np.ndarray
    surface_points: np.ndarray
    faces: np.ndarray
    front: int = 1

    @classmethod
    def of(cls, x, y, surface_points, faces, front: int = 1) -> MapTriangles:
        """Check and hold the layout ``x``, ``y`` ((k,) each), the surface points
        ((k, 3)) and the faces ((m, 3))."""
        surface = as_points(surface_points, "surface_points")
        map_points = as_points(np.column_stack([np.ravel(x), np.ravel(y)]), "map_points", dims=2)
        if len(map_points) != len(surface):
            raise TransformInputError(
                "map_points",
                f"one map point per surface point: {len(map_points)} and {len(surface)}",
            )
        return cls(map_points, surface, as_faces(faces, len(surface)), 1 if front >= 0 else -1)

    def __len__(self) -> int:
        return len(self.faces)

    # -- per face --------------------------------------------------------------------

    @cached_property
    def corner_x(self) -> np.ndarray:
        """(3, m) float: the map x of each triangle's corners, corner by corner."""
        return self.map_points[:, 0][self.faces.T]

    @cached_property
    def corner_y(self) -> np.ndarray:
        """(3, m) float: the map y of each triangle's corners, corner by corner."""
        return self.map_points[:, 1][self.faces.T]

    def corners(self, triangles: np.ndarray) -> np.ndarray:
        """(p, 3, 2) float: the map corners of ``triangles`` ((p,) int)."""
        return np.stack([self.corner_x[:, triangles].T, self.corner_y[:, triangles].T], axis=2)

    @cached_property
    def signed_map_area(self) -> np.ndarray:
        """(m,) float: each triangle's signed area on the map (counter-clockwise positive)."""
        x, y = self.corner_x, self.corner_y
        return 0.5 * ((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]))

    @cached_property
    def front_map_area(self) -> np.ndarray:
        """(m,) float: each triangle's map area, negative for the back-facing ones."""
        return self.signed_map_area * self.front

    @cached_property
    def surface_area(self) -> np.ndarray:
        """(m,) float: each triangle's area on the surface."""
        return triangle_areas(self.surface_points, self.faces)

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(m,) float each: ``xmin, xmax, ymin, ymax`` of each triangle on the map."""
        x, y = self.corner_x, self.corner_y
        return (
            np.minimum(np.minimum(x[0], x[1]), x[2]),
            np.maximum(np.maximum(x[0], x[1]), x[2]),
            np.minimum(np.minimum(y[0], y[1]), y[2]),
            np.maximum(np.maximum(y[0], y[1]), y[2]),
        )

    @cached_property
    def typical_size(self) -> float:
        """The median side of the triangles' boxes on the map (of an even sample)."""
        xmin, xmax, ymin, ymax = self.bounds
        step = max(1, len(self) // SIZE_SAMPLE)
        sides = np.maximum(xmax[::step] - xmin[::step], ymax[::step] - ymin[::step])
        return float(np.median(sides))

    # -- boxes and points ---------------------------------------------------------------

    def meeting(self, low, high) -> np.ndarray:
        """(j,) int: the triangles whose box meets the box ``[low, high]`` ((2,) each)."""
        xmin, xmax, ymin, ymax = self.bounds
        inside = (xmax >= low[0]) & (xmin <= high[0])
        inside &= (ymax >= low[1]) & (ymin <= high[1])
        return np.flatnonzero(inside)

    def cell_boxes(self, grid: CellGrid, triangles: np.ndarray):
        """The cell rectangles of ``triangles``' boxes (:meth:`CellGrid.boxes`)."""
        xmin, xmax, ymin, ymax = self.bounds
        return grid.boxes(xmin[triangles], xmax[triangles], ymin[triangles], ymax[triangles])

    def barycentric(self, triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(p, 3) float: the weights of map ``points`` ((p, 2)) in ``triangles`` ((p,) int);
        rows of triangles of no area on the map are NaN."""
        x, y = self.corner_x[:, triangles], self.corner_y[:, triangles]
        e1x, e1y, e2x, e2y = x[1] - x[0], y[1] - y[0], x[2] - x[0], y[2] - y[0]
        dx, dy = points[:, 0] - x[0], points[:, 1] - y[0]
        det = e1x * e2y - e1y * e2x
        weights = np.empty((len(triangles), 3))
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(dx * e2y - dy * e2x, det, out=weights[:, 1])
            np.divide(e1x * dy - e1y * dx, det, out=weights[:, 2])
        weights[:, 0] = 1.0 - weights[:, 1] - weights[:, 2]
        weights[det == 0] = np.nan
        return weights

    def lift(self, triangles: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(p, 3) float: the surface points with ``weights`` ((p, 3)) in ``triangles``."""
        return combine(self.surface_points, self.faces, triangles, weights)

    def on_map(self, triangles: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(p, 2) float: the map points with ``weights`` ((p, 3)) in ``triangles``."""
        return combine(self.map_points, self.faces, triangles, weights)

    def locate(self, points) -> tuple[np.ndarray, np.ndarray]:
        """The triangle that holds each map point, and the point's weights in it.

        A point on an edge or in several triangles (a folded map) takes the front-facing one
        first, then the first in face order.

        Parameters
        ----------
        points : (p, 2) float, map points

        Returns
        -------
        triangles : (p,) int, position in ``faces``, -1 where no triangle holds the point
        weights : (p, 3) float, barycentric weights of the triangle's corners (NaN for -1)
        """
        points = as_points(points, "points", dims=2)
        if len(points) == 0:
            return np.full(0, -1, dtype=np.int64), np.full((0, 3), np.nan)
        low, high = points.min(0), points.max(0)
        grid = CellGrid.covering(low, high, self.typical_size)
        x, y = points[:, 0], points[:, 1]
        index = CellIndex.of(grid, grid.boxes(x, x, y, y))
        near = self.meeting(low, high)
        boxes = self.cell_boxes(grid, near)
        held = index.any_in(boxes)
        near, boxes = near[held], boxes.take(np.flatnonzero(held))
        owner, point = index.pairs(boxes)
        return self._holding(points, near[owner], point)

    def cell_index(self) -> TriangleCells:
        """The triangles filed by the cells of a grid over the map (:class:`TriangleCells`):
        for locating batch after batch of points in the same triangles, as a march does."""
        return TriangleCells.of(self)

    def _holding(self, points: np.ndarray, triangle: np.ndarray, point: np.ndarray):
        """:meth:`locate`'s answer from candidate pairs (``triangle``, ``point``), (c,) int
        each: of the triangles that hold a point, the front-facing one first, then the
        first in face order."""
        found = np.full(len(points), -1, dtype=np.int64)
        weights = np.full((len(points), 3), np.nan)
        w = self.barycentric(triangle, points[point])
        inside = np.all(w >= -BARYCENTRIC_SLACK, axis=1)
        triangle, point, w = triangle[inside], point[inside], w[inside]
        if len(point) == 0:
            return found, weights
        # A point held by one triangle needs no choosing; those on edges or folds do.
        shared = np.bincount(point, minlength=len(points))[point] > 1
        first = np.flatnonzero(~shared)
        if shared.any():
            chosen = np.flatnonzero(shared)
            back = np.sign(self.signed_map_area[triangle[chosen]]) != self.front
            order = chosen[np.lexsort((triangle[chosen], back, point[chosen]))]
            first = np.concatenate(
                [first, order[np.r_[True, point[order][1:] != point[order][:-1]]]]
            )
        found[point[first]] = triangle[first]
        kept = np.clip(w[first], 0.0, 1.0)
        weights[point[first]] = kept / kept.sum(axis=1, keepdims=True)
        return found, weights


@dataclass(frozen=True)
class TriangleCells:
    """A region's map triangles filed by every cell of a grid over the map that their boxes
    meet (:class:`~transforms.cellgrid.CellIndex`; cells half the triangles' typical size,
    which leaves a point's cell the fewest candidates for the entries filed), built once:
    a point's triangles are among its cell's. :meth:`MapTriangles.locate` builds its grid
    over each call's points instead, which costs a pass over the triangles a call."""

    triangles: MapTriangles
    index: CellIndex

    @classmethod
    def of(cls, triangles: MapTriangles) -> TriangleCells:
        low, high = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
        grid = CellGrid.covering(low, high, 0.5 * triangles.typical_size)
        boxes = triangles.cell_boxes(grid, np.arange(len(triangles)))
        return cls(triangles, CellIndex.of(grid, boxes))

    def locate(self, points) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`MapTriangles.locate`: each map point's triangle ((p,) int, -1 where
        none) and its weights there ((p, 3), NaN for -1)."""
        points = as_points(points, "points", dims=2)
        grid = self.index.grid
        cell = grid.rows(points[:, 1]) * grid.n_columns + grid.columns(points[:, 0])
        point, triangle, _ = self.index.entries_between(cell, cell + 1)
        # Most of a cell's triangles do not reach the point: their boxes say so for less.
        xmin, xmax, ymin, ymax = self.triangles.bounds
        pad = BOX_SLACK * self.triangles.typical_size
        x, y = points[point, 0], points[point, 1]
        near = (xmin[triangle] - pad <= x) & (x <= xmax[triangle] + pad)
        near &= (ymin[triangle] - pad <= y) & (y <= ymax[triangle] + pad)
        return self.triangles._holding(points, triangle[near], point[near])
