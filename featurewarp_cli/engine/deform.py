"""The interactive mode's warp: handles -> as-rigid-as-possible map W -> feature-aware mesh.

:class:`HandleWarp` is the map W that the handles define (a piecewise-linear map on a
coarse grid, :mod:`featurewarp_cli.engine.arap`), usable wherever a preset is;
:class:`Deformer` keeps both factorizations (the rigid map's per handle set, the
feature-aware system's per grid and mask) so that moving a handle costs
back-substitutions only.

Examples
--------
>>> import numpy as np
>>> from featurewarp_cli.engine.handles import Handles
>>> mask = np.zeros((120, 160), bool); mask[40:80, 60:100] = True
>>> handles = Handles.from_dict({"version": 1, "canvas": "input", "points": [
...     {"from": [10, 10], "to": [10, 10]}, {"from": [150, 110], "to": [140, 100]}]}, 160, 120)
>>> deformer = Deformer(160, 120, mask)
>>> mesh = deformer.solve(handles)
>>> mesh.canvas, mesh.flips()
((160, 120), 0)
>>> mesh = deformer.move([[10, 10], [130, 95]])      # back-substitutions only
>>> deformer.warper.factorizations
1
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np

from .arap import RigidDeformer, embed
from .defaults import MODE
from .grid import Grid
from .handles import Handles, default_radius
from .mesh import Mesh
from .warper import FeatureWarper

#: Nodes of the grid the rigid map is solved on (about; it is coarser than the feature grid:
#: the map is smooth away from the handles, and its solves must take milliseconds).
RIGID_NODES = 4096


def rigid_grid(width: int, height: int) -> Grid:
    """The coarse grid of the rigid map: about :data:`RIGID_NODES` nodes, cells of 4 px or more."""
    return Grid.for_image(width, height, max(4.0, math.sqrt(width * height / RIGID_NODES)))


class HandleWarp:
    """The map W of a set of handles, as a preset-like warp (``forward``, ``canvas``, ``offset``).

    Parameters
    ----------
    width, height : int
        Source image size.
    grid : Grid
        The rigid map's grid.
    nodes : (N, 2) ndarray
        Its nodes' images, in source pixel coordinates.
    canvas : {'fit', 'input'}
        fit: the canvas is the deformed image's bounding box; input: the input's size.
    values : dict, optional
        What the report shows as the warp's parameters.
    embeddings : dict, optional
        A cache of the barycentric embeddings of point sets (by their bytes' digest), shared
        by the warps of successive updates.
    """

    name = "deform"
    boundary = "fixed"

    def __init__(self, width: int, height: int, grid: Grid, nodes: np.ndarray, canvas: str = "fit",
                 values: dict | None = None, embeddings: dict | None = None):
        self.width, self.height, self.grid = int(width), int(height), grid
        self.values = values or {}
        self.offset = (0.0, 0.0)
        self.canvas = (self.width, self.height)
        if canvas == "fit":
            lo, hi = nodes.min(axis=0), nodes.max(axis=0)
            size = np.ceil(hi - lo - 1e-6).astype(int)
            self.canvas = (max(1, int(size[0])), max(1, int(size[1])))
            self.offset = (float(lo[0] + 0.5), float(lo[1] + 0.5))
        self.nodes = nodes - np.asarray(self.offset)
        self._embeddings = {} if embeddings is None else embeddings
        self.notes = []

    def __call__(self, points) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        key = hashlib.blake2b(np.ascontiguousarray(points).tobytes(), digest_size=16).digest()
        if key not in self._embeddings:
            if len(self._embeddings) > 4:
                self._embeddings.clear()
            self._embeddings[key] = embed(self.grid, points)
        return self._embeddings[key] @ self.nodes

    forward = __call__


class RigidMap:
    """The rigid map W of handles on one image size, its factorization kept per handle set.

    Parameters
    ----------
    width, height : int
        Source image size.
    """

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        self.grid = rigid_grid(width, height)
        self.rigid = None
        self._key = None
        self._last = None
        self._embeddings = {}

    def deformation(self, handles: Handles) -> HandleWarp:
        """The map W of ``handles``, a preset-like warp (factoring anew only when the handles'
        sources changed; a fold the handles ask for is noted in its ``notes``)."""
        radius = handles.radius if handles.radius is not None else default_radius(
            self.width, self.height, max(self.grid.spacing))
        sources, targets, radii = handles.constraints(self.grid, radius)
        key = (sources.tobytes(), radii.tobytes())
        if key != self._key:
            self.rigid = RigidDeformer(self.grid, sources, radii)
            self._key, self._last = key, None
        nodes = self.rigid.deform(targets, start=self._last)
        self._last = nodes
        values = {"points": len(handles.points_from), "curves": len(handles.curves),
                  "border": handles.border if isinstance(handles.border, str) else sorted(handles.border),
                  "canvas": handles.canvas, "radius": radius}
        warp = HandleWarp(self.width, self.height, self.grid, nodes, handles.canvas, values, self._embeddings)
        warp.notes = list(handles.notes)
        if self.rigid.injective_steps:
            warp.notes.append(f"the handles ask for a fold; they are held as far as the image can follow "
                              f"without one ({self.rigid.injective_steps} injective steps)")
        return warp


class Deformer:
    """Feature-aware deformation by handles, both systems factored once.

    Parameters
    ----------
    width, height : int
        Source image size.
    mask : (height, width) bool ndarray or None
        Feature mask.
    mode : {'similarity', 'rigid', 'plain'}
    quick : bool
        Skip what an interactive update can do without (see :meth:`FeatureWarper.solve`).
    **options
        :class:`FeatureWarper` options (cell, feature_weight, decay, scale_prior, max_nodes, ...).

    Attributes
    ----------
    warper : FeatureWarper
    rigid : RigidMap
    handles : Handles or None
        The last handles solved.
    """

    def __init__(self, width: int, height: int, mask: np.ndarray | None = None, *, mode: str = MODE,
                 quick: bool = False, **options):
        self.mode = mode
        self.quick = quick
        self.warper = FeatureWarper(width, height, mask, **options)         # the border: HandleWarp.boundary
        self.rigid = RigidMap(width, height)
        self.handles = None
        self.warp = None

    def solve(self, handles: Handles, mode: str | None = None) -> Mesh:
        """The feature-aware mesh for ``handles`` (whose sources may differ from the last call's:
        the rigid map is then factored anew)."""
        self.handles = handles
        self.warp = self.rigid.deformation(handles)
        mesh = self.warper.solve(self.warp, mode or self.mode, quick=self.quick)
        mesh.record.warnings.extend(self.warp.notes)
        return mesh

    def move(self, targets: np.ndarray, mode: str | None = None) -> Mesh:
        """The mesh with the last handles' points moved to ``targets`` ((K, 2), in their order);
        nothing is factored again."""
        targets = np.asarray(targets, dtype=np.float64).reshape(self.handles.points_from.shape)
        return self.solve(replace(self.handles, points_to=targets), mode)


def handles_factory(data):
    """``make(width, height)``: the map W of the handles file ``data`` (parsed JSON) for an image
    of that size (ValueError when the handles do not fit it)."""
    def make(width: int, height: int) -> HandleWarp:
        return RigidMap(width, height).deformation(Handles.from_dict(data, width, height))

    return make
