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
    crossings : int
        Pairs of border edges that cross on the canvas, where counted (the deform
        command's handles can lay the image over itself without folding a triangle).
    """

    source: np.ndarray
    target: np.ndarray
    triangles: np.ndarray
    canvas: tuple[int, int]
    record: SolveRecord | None = None
    node_component: np.ndarray | None = None
    crossings: int = 0

    @property
    def info(self) -> dict:
        """The record as JSON-ready data (:meth:`SolveRecord.to_dict`)."""
        return self.record.to_dict() if self.record is not None else {}

    def check_image(self, width: int, height: int) -> None:
        """ValueError unless the mesh's grid spans a ``width`` x ``height`` image (a mesh of another
        warper rendered a crop of the image)."""
        spans = np.ptp(self.source, axis=0) if len(self.source) else np.zeros(2)
        if not np.allclose(spans, (width, height), atol=1e-6):
            raise ValueError(f"mesh is for a {spans[0]:g}x{spans[1]:g} image, not {width}x{height}")

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

    def to_obj(self) -> bytes:
        """The mapping as a Wavefront OBJ (for ``--save-grid x.obj``), for 3D tools.

        ``v x y 0``: the nodes on the output canvas, in pixels (y down, as in the image);
        ``vt u v``: their source positions as texture coordinates, the source image's edges
        at 0 and 1 (v up, as OBJ has it); ``f a/a b/b c/c``: the triangles, counter-clockwise
        in source coordinates with y down.
        """
        lo, hi = self.source.min(axis=0), self.source.max(axis=0)
        uv = (self.source - lo) / np.maximum(hi - lo, 1e-12)
        uv[:, 1] = 1.0 - uv[:, 1]
        faces = self.triangles.astype(np.int64) + 1
        lines = ["# featurewarp mesh: v = canvas pixels (y down), vt = source in [0, 1]",
                 f"# canvas {self.canvas[0]} x {self.canvas[1]}"]
        lines += [f"v {x:.6f} {y:.6f} 0" for x, y in self.target]
        lines += [f"vt {u:.8f} {v:.8f}" for u, v in uv]
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in faces]
        return ("\n".join(lines) + "\n").encode()
