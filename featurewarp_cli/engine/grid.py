"""The quad grid laid over the source image: nodes, quads, triangles, boundary."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """A regular grid covering the image's pixel extent [-0.5, w-0.5] x [-0.5, h-0.5].

    Nodes are numbered row by row (``j * nx + i``). Cells are ``w / (nx-1)`` by
    ``h / (ny-1)`` pixels, as close to ``cell`` as a whole number of cells allows.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    cell : int
        Requested cell size in pixels.
    nx, ny : int
        Nodes per row and per column.
    """

    width: int
    height: int
    cell: int
    nx: int
    ny: int

    @classmethod
    def for_image(cls, width: int, height: int, cell: int) -> "Grid":
        """Grid of about ``cell``-pixel cells over a ``width`` x ``height`` image."""
        nx = max(1, round(width / cell)) + 1
        ny = max(1, round(height / cell)) + 1
        return cls(int(width), int(height), int(cell), nx, ny)

    def refined(self, k: int) -> "Grid":
        """This grid with every cell cut into ``k`` x ``k``: its nodes are among the result's,
        and each triangle of the result lies inside one of this grid's triangles (both cut
        their quads along the same diagonal), so a map that is linear on this grid's
        triangles is linear on each of the result's, and folds none of them where it folds
        none of these."""
        k = max(1, int(k))
        return Grid(self.width, self.height, max(1, round(min(self.spacing) / k)),
                    (self.nx - 1) * k + 1, (self.ny - 1) * k + 1)

    @property
    def spacing(self) -> tuple[float, float]:
        """Cell width and height in pixels."""
        return self.width / (self.nx - 1), self.height / (self.ny - 1)

    @property
    def n_nodes(self) -> int:
        return self.nx * self.ny

    @property
    def quad_shape(self) -> tuple[int, int]:
        """(rows, columns) of quads."""
        return self.ny - 1, self.nx - 1

    def nodes(self) -> np.ndarray:
        """``(N, 2)`` source positions (x, y) of the nodes."""
        xs = np.linspace(-0.5, self.width - 0.5, self.nx)
        ys = np.linspace(-0.5, self.height - 0.5, self.ny)
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel()], axis=1)

    def quads(self) -> np.ndarray:
        """``(K, 4)`` node indices per quad, row by row: top-left, top-right,
        bottom-right, bottom-left (positive orientation in x-right, y-down pixels)."""
        j, i = np.mgrid[0 : self.ny - 1, 0 : self.nx - 1]
        a = (j * self.nx + i).ravel()
        return np.stack([a, a + 1, a + 1 + self.nx, a + self.nx], axis=1)

    def triangles(self) -> np.ndarray:
        """``(2K, 3)`` node indices, two per quad, with positive signed area in source space."""
        q = self.quads()
        return np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=0)

    def boundary(self) -> np.ndarray:
        """``(N,)`` bool: the node lies on the image border."""
        b = np.zeros((self.ny, self.nx), dtype=bool)
        b[0, :] = b[-1, :] = b[:, 0] = b[:, -1] = True
        return b.ravel()

    def quad_of_pixel(self) -> tuple[np.ndarray, np.ndarray]:
        """Quad row of each pixel row and quad column of each pixel column."""
        qy, qx = self.quad_shape
        rows = np.minimum(((np.arange(self.height) + 0.5) * qy / self.height).astype(int), qy - 1)
        cols = np.minimum(((np.arange(self.width) + 0.5) * qx / self.width).astype(int), qx - 1)
        return rows, cols


def grid_for(width: int, height: int, cell: float, lattice: Grid | None = None) -> Grid:
    """The grid of about ``cell``-pixel cells over a ``width`` x ``height`` image; where
    ``lattice`` is given (a warp that is linear on that grid's triangles, as the rigid map of
    handles), its refinement (:meth:`Grid.refined`) whose cells come closest to ``cell``,
    never coarser than the lattice itself (a coarser grid would cut across the map's kinks)."""
    if lattice is None:
        return Grid.for_image(width, height, cell)
    return lattice.refined(max(1, round(max(lattice.spacing) / cell)))


def grid_shape(nodes: np.ndarray) -> tuple[int, int]:
    """(nx, ny) of a grid from its nodes' source positions, row by row as :meth:`Grid.nodes`."""
    nx = int(np.count_nonzero(nodes[:, 1] == nodes[0, 1]))
    return nx, len(nodes) // nx


def signed_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Signed area of each triangle (positive: same orientation as the source grid).

    Parameters
    ----------
    points : (N, 2) ndarray
    triangles : (M, 3) ndarray of int

    Returns
    -------
    (M,) ndarray
    """
    # Gathering contiguous coordinates by contiguous index columns is ~6x faster than
    # gathering (M, 2) rows: this runs a few times per fold-over-guard step.
    x, y = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
    a, b, c = (np.ascontiguousarray(triangles[:, k]) for k in range(3))
    xa, ya = x.take(a), y.take(a)
    return 0.5 * ((x.take(b) - xa) * (y.take(c) - ya) - (y.take(b) - ya) * (x.take(c) - xa))
