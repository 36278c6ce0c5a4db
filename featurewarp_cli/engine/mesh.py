"""The solved mapping a warper returns: grid nodes in the source and on the canvas."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .grid import signed_areas
from .record import SolveRecord


@dataclass
class Mesh:
    """A solved mapping: grid nodes in the source and on the output canvas.

    Attributes
    ----------
    source : (N, 2) ndarray
    target : (N, 2) ndarray
    triangles : (M, 3) ndarray of int
        Positively oriented in source space.
    canvas : (int, int)
        Output (width, height).
    record : SolveRecord or None
        What was done: grid, components, solver, guard, quality, warnings, timings.
    node_component : (N,) int ndarray or None
        Feature component of each node of a feature quad (as in ``record.components``), -1
        for the others.
    """

    source: np.ndarray
    target: np.ndarray
    triangles: np.ndarray
    canvas: tuple[int, int]
    record: SolveRecord | None = None
    node_component: np.ndarray | None = None

    @property
    def info(self) -> dict:
        """The record as JSON-ready data (:meth:`SolveRecord.to_dict`)."""
        return self.record.to_dict() if self.record is not None else {}

    def flips(self) -> int:
        """Number of triangles whose signed area on the canvas is <= 0."""
        return int(np.count_nonzero(signed_areas(self.target, self.triangles) <= 0))

    def to_npz(self) -> bytes:
        """The mapping as ``.npz`` bytes (for ``--save-grid``).

        Arrays: ``source`` (N, 2) source pixel positions of the nodes, ``target``
        (N, 2) their positions on the output canvas, ``triangles`` (M, 3) node
        indices, counter-clockwise in source coordinates (positive signed area
        with x and y as pixel coordinates; on screen, where y points down, they
        appear clockwise).
        """
        import io

        buffer = io.BytesIO()
        np.savez(buffer, source=self.source, target=self.target, triangles=self.triangles.astype(np.int32))
        return buffer.getvalue()
