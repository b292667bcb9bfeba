"""A uniform grid of square cells over a box of the plane, and items (segments, points)
filed by the cells their boxes meet: how outlines drawn on the map find the few triangles
they cross among a million (docs/math.md, section 12).

Every cell index comes from one floor (:meth:`CellGrid.columns`, :meth:`CellGrid.rows`), so
an item and a triangle that share a point always share that point's cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Cells per side at most: a grid of at most a million cells (8 MB of offsets).
MAX_CELLS_PER_SIDE = 1024
#: A box spanning more cells than this is paired with every item instead of cell by cell.
MAX_CELLS_PER_BOX = 4096


@dataclass(frozen=True)
class CellGrid:
    """Square cells of side ``size``; cell ``(row, column)`` covers
    ``[x0 + column * size, x0 + (column + 1) * size) x [y0 + row * size, ...)``.
    Positions outside the grid are clamped to its border cells.
    """

    x0: float
    y0: float
    size: float
    n_columns: int
    n_rows: int

    @classmethod
    def covering(cls, low, high, size: float) -> CellGrid:
        """The grid over the box ``[low, high]`` ((2,) each) with cells of at least ``size``
        (larger when the box would need more than ``MAX_CELLS_PER_SIDE`` a side) and one
        empty cell of margin all round.

        The last row and column are counted with the floor that files items
        (:meth:`columns`, :meth:`rows`), so that ``high``'s cell is never the margin, even
        when the box spans a whole number of cells to rounding (a box of exactly
        ``MAX_CELLS_PER_SIDE - 3`` cells, the case of every wide one)."""
        low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        extent = float(np.max(high - low))
        size = max(float(size), extent / (MAX_CELLS_PER_SIDE - 3), extent * 1e-12, 1e-300)
        origin = low - size
        spans = np.floor((high - origin) / size).astype(np.int64) + 2
        return cls(float(origin[0]), float(origin[1]), size, int(spans[0]), int(spans[1]))

    @property
    def n_cells(self) -> int:
        return self.n_rows * self.n_columns

    def columns(self, x: np.ndarray) -> np.ndarray:
        """(n,) int64: the column of each ``x``, clamped to the grid."""
        return np.clip(np.floor((x - self.x0) / self.size), 0, self.n_columns - 1).astype(np.int64)

    def rows(self, y: np.ndarray) -> np.ndarray:
        """(n,) int64: the row of each ``y``, clamped to the grid."""
        return np.clip(np.floor((y - self.y0) / self.size), 0, self.n_rows - 1).astype(np.int64)

    def boxes(self, xmin, xmax, ymin, ymax) -> Boxes:
        """The cell rectangles of axis-aligned boxes ((n,) float each)."""
        return Boxes(self.columns(xmin), self.columns(xmax), self.rows(ymin), self.rows(ymax))

    def centres_x(self) -> np.ndarray:
        """(n_columns,) float: the x of the cell centres."""
        return self.x0 + (np.arange(self.n_columns) + 0.5) * self.size

    def centres_y(self) -> np.ndarray:
        """(n_rows,) float: the y of the cell centres."""
        return self.y0 + (np.arange(self.n_rows) + 0.5) * self.size


@dataclass(frozen=True)
class Boxes:
    """Inclusive cell rectangles: columns ``c0..c1``, rows ``r0..r1``, (n,) int64 each."""

    c0: np.ndarray
    c1: np.ndarray
    r0: np.ndarray
    r1: np.ndarray

    def __len__(self) -> int:
        return len(self.c0)

    def take(self, rows: np.ndarray) -> Boxes:
        return Boxes(self.c0[rows], self.c1[rows], self.r0[rows], self.r1[rows])

    @property
    def n_cells(self) -> np.ndarray:
        """(n,) int64: the cells each rectangle covers."""
        return (self.c1 - self.c0 + 1) * (self.r1 - self.r0 + 1)

    def cells(self, n_columns: int) -> tuple[np.ndarray, np.ndarray]:
        """Every cell of every rectangle: ``(owner, cell)``, (s,) int64 each, where ``cell``
        is ``row * n_columns + column`` and ``owner`` the rectangle's position."""
        widths = self.c1 - self.c0 + 1
        counts = self.n_cells
        owner = np.repeat(np.arange(len(self)), counts)
        rank = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
        width = widths[owner]
        column = self.c0[owner] + rank % width
        row = self.r0[owner] + rank // width
        return owner, row * n_columns + column


@dataclass(frozen=True)
class CellIndex:
    """Items filed by every cell their rectangle covers.

    Attributes
    ----------
    grid : CellGrid
    offsets : (n_cells + 1,) int64, the entries of cell ``k`` are ``offsets[k]:offsets[k+1]``
    items : (e,) int64, the item of each entry, grouped by cell
    cells : (e,) int64, the cell of each entry (ascending)
    first_cells : (2, n_items) int64, the first column and row of each item's rectangle
    n_items : int
    occupied : (n_rows + 1, n_columns + 1) int64, summed-area table of the occupied cells
    """

    grid: CellGrid
    offsets: np.ndarray
    items: np.ndarray
    cells: np.ndarray
    first_cells: np.ndarray
    n_items: int
    occupied: np.ndarray

    @classmethod
    def of(cls, grid: CellGrid, boxes: Boxes) -> CellIndex:
        """Index items by their cell rectangles (each a few cells: segments no longer than
        the cell size, or points)."""
        owner, cell = boxes.cells(grid.n_columns)
        order = np.argsort(cell, kind="stable")
        counts = np.bincount(cell, minlength=grid.n_cells)
        offsets = np.zeros(grid.n_cells + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        occupied = np.zeros((grid.n_rows + 1, grid.n_columns + 1), dtype=np.int64)
        occupied[1:, 1:] = (counts > 0).reshape(grid.n_rows, grid.n_columns)
        occupied = occupied.cumsum(axis=0).cumsum(axis=1)
        first = np.stack([boxes.c0, boxes.r0])
        return cls(grid, offsets, owner[order], cell[order], first, len(boxes), occupied)

    def any_in(self, boxes: Boxes) -> np.ndarray:
        """(n,) bool: whether any item lies in a cell of each rectangle."""
        s = self.occupied
        total = s[boxes.r1 + 1, boxes.c1 + 1] - s[boxes.r0, boxes.c1 + 1]
        total -= s[boxes.r1 + 1, boxes.c0] - s[boxes.r0, boxes.c0]
        return total > 0

    def pairs(self, boxes: Boxes) -> tuple[np.ndarray, np.ndarray]:
        """Every (rectangle, item) that share a cell, once each, grouped by rectangle in
        ascending order: ``(owner, item)``, (p,) int64 each. A rectangle wider than
        ``MAX_CELLS_PER_BOX`` cells is paired with every item."""
        wide = boxes.n_cells > MAX_CELLS_PER_BOX
        narrow = np.flatnonzero(~wide)
        owner, cell = boxes.take(narrow).cells(self.grid.n_columns)
        owner, entry = _ranges(self.offsets[cell], self.offsets[cell + 1], narrow[owner])
        item = self.items[entry]
        # A pair shares several cells; it is kept in one: where the two rectangles' common
        # part begins.
        column = np.maximum(boxes.c0[owner], self.first_cells[0, item])
        row = np.maximum(boxes.r0[owner], self.first_cells[1, item])
        once = self.cells[entry] == row * self.grid.n_columns + column
        owner, item = owner[once], item[once]
        if not wide.any():
            return owner, item
        wide = np.flatnonzero(wide)
        owner = np.concatenate([owner, np.repeat(wide, self.n_items)])
        item = np.concatenate([item, np.tile(np.arange(self.n_items), len(wide))])
        order = np.argsort(owner, kind="stable")
        return owner[order], item[order]

    def free_to_the_right(self) -> np.ndarray:
        """(n_rows, n_columns) int64: for each cell, the first cell at or to its right in its
        row that no item occupies (the last column is always free: the grid's margin)."""
        n_rows, n_columns = self.grid.n_rows, self.grid.n_columns
        occupied = np.diff(self.offsets).reshape(n_rows, n_columns) > 0
        columns = np.where(occupied, n_columns - 1, np.arange(n_columns))
        return np.minimum.accumulate(columns[:, ::-1], axis=1)[:, ::-1]

    def entries_between(
        self, start: np.ndarray, stop: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The entries of the cells ``start[i]`` to ``stop[i] - 1`` ((q,) int each):
        ``(owner, item, column)``, (p,) int64 each, ``owner`` the query's position."""
        owner, entry = _ranges(self.offsets[start], self.offsets[stop])
        return owner, self.items[entry], self.cells[entry] % self.grid.n_columns


def _ranges(
    start: np.ndarray, stop: np.ndarray, owner: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Every ``k`` in ``start[i]:stop[i]`` with its ``owner[i]`` (default ``i``): (s,) each."""
    counts = stop - start
    if owner is None:
        owner = np.arange(len(start))
    owners = np.repeat(owner, counts)
    entry = np.arange(len(owners)) - np.repeat(np.cumsum(counts) - counts - start, counts)
    return owners, entry
