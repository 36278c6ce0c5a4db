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
import numbers
import os

import numpy as np

from . import arrays
from .arap import RigidDeformer, embed, similarity_fit
from .defaults import DECAY, MODE, MODES
from .grid import Grid, grid_for, grid_shape, signed_areas
from .injectivity import border_crossings
from .handles import Handles, default_radius, resample
from .handle_review import (CURVE_SAMPLES, HANDLE_SLACK_PX, carried_scale_notes, crushed, fold_cause, fold_notes,
                            off_canvas, review_curves, review_points)
from . import landing
from .mesh import Mesh
from ..plugins import canvas_size, check_canvas_side
from .warper import FeatureWarper

#: Deformed images smaller than this share of the input's area get a warning.
SHRUNK = 0.01
#: Nodes of the grid the rigid map is solved on (about; it is coarser than the feature grid:
#: the map is smooth away from the handles, and its solves must take milliseconds).
RIGID_NODES = 4096


def rigid_grid(width: int, height: int) -> Grid:
    """The coarse grid of the rigid map: about :data:`RIGID_NODES` nodes, cells of 4 px or more."""
    return Grid.for_image(width, height, max(4.0, math.sqrt(width * height / RIGID_NODES)))


def solve_grid(width: int, height: int, cell: float) -> Grid:
    """The grid a handles solve of about ``cell``-pixel cells uses: the rigid grid refined."""
    return grid_for(width, height, cell, rigid_grid(width, height))


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
    #: A feature cut by the image's border keeps its shape and lets go of it (the border is
    #: where the handles put it, not an envelope the output must fill); presets: "give".
    cut_features = "keep"

    def __init__(self, width: int, height: int, grid: Grid, nodes: np.ndarray, canvas: str = "fit",
                 values: dict | None = None, embeddings: dict | None = None):
        self.width, self.height, self.grid = int(width), int(height), grid
        self.values = values or {}
        self.offset = (0.0, 0.0)
        self.canvas = (self.width, self.height)
        if canvas == "fit":
            lo, hi = nodes.min(axis=0), nodes.max(axis=0)
            self.canvas = canvas_size(hi - lo)
            self.offset = (float(lo[0] + 0.5), float(lo[1] + 0.5))
            check_canvas_side(self.canvas, "deform", "the canvas 'input' keeps the input's size")
        self.nodes = nodes - np.asarray(self.offset)
        self._embeddings = {} if embeddings is None else embeddings
        self.notes = []
        self.handles = None
        #: The map is linear on this grid's triangles: a solve refines it (:func:`grid.grid_for`),
        #: so that no triangle straddles two of the map's and W folds none.
        self.lattice = grid
        self.capped = False                 # the rigid map stopped at its step cap, not converged
        self.rigid_map = None               # the RigidMap that made it (:meth:`aim` asks it again)
        self.aimed = None                   # the point handles' targets the map was solved for
        self.aimed_curves = None            # the curves' sample points' (:mod:`landing`)
        self.fitted = None                  # (canvas, offset) of the re-aimed map, for a fit canvas
        self.shares = None                  # how much of its miss each handle was last re-aimed by
        self.carried = set()                # the point handles that carry a feature

    def review(self, mesh: Mesh, quick: bool = False) -> list[str]:
        """Warnings on the solved ``mesh`` of these handles (also kept in ``values`` for the
        report): how far each point and curve handle ended from its target, a border that crosses
        itself (``mesh.crossings``), an image shrunk away or moved off the canvas; ``quick``
        (the editor's live updates) notes a rigid map cut short, and a full solve one that
        did not converge within :data:`rigid_energy.MAX_STEPS` steps."""
        warnings = list(self.notes)
        if quick and self.capped:
            warnings.append("preview: the rigid map was not run to convergence to stay live; Export "
                            "finishes it (and may differ)")
        elif self.capped:
            warnings.append("the rigid map did not converge within its step limit: the result has no "
                            "fold but may differ slightly between machines")
        mesh.crossings = border_crossings(mesh.source, mesh.target)
        mesh.fold_cause = self.fold_cause()
        if mesh.crossings:
            times = {1: "once", 2: "twice"}.get(mesh.crossings, f"{mesh.crossings} times")
            warnings.append(f"the handles lay the image over itself (its border crosses itself {times}): "
                            f"{mesh.fold_cause}")
        warnings += review_points(self, mesh) + crushed(self, mesh) + review_curves(self, mesh) + off_canvas(mesh)
        area = float(np.sum(signed_areas(mesh.target, mesh.triangles)))
        if area < SHRUNK * self.width * self.height:
            warnings.append(f"the handles shrink the image to {100 * area / (self.width * self.height):.1f} % "
                            f"of its area")
        lo, hi = mesh.target.min(axis=0), mesh.target.max(axis=0)
        if np.any(hi < -0.5) or np.any(lo > np.array(mesh.canvas) - 0.5):
            warnings.append("the deformed image lies outside the canvas: the output is empty")
        return warnings

    def fold_cause(self) -> str:
        """What makes these handles crush or fold the image (:func:`handle_review.fold_cause`)."""
        return fold_cause(self)

    def land(self, mesh: Mesh, solve) -> Mesh:
        """``mesh`` solved again with the handles re-aimed until they land (:func:`landing.land`)."""
        return landing.land(self, mesh, solve)

    def ends(self, mesh: Mesh) -> np.ndarray | None:
        """Where the point handles ended in ``mesh``, in input pixel coordinates (None: no handles)."""
        if self.handles is None or not len(self.handles.points_from):
            return None
        return self.mapped(mesh, self.handles.points_from)

    def curve_ends(self, mesh: Mesh) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per curve handle, (its target, where it ended in ``mesh``): :data:`CURVE_SAMPLES`
        points each, evenly spaced by arc length, in input pixel coordinates."""
        if self.handles is None:
            return []
        return [(resample(end, CURVE_SAMPLES), self.mapped(mesh, resample(start, CURVE_SAMPLES)))
                for start, end in self.handles.curves]

    def mapped(self, mesh: Mesh, points: np.ndarray) -> np.ndarray:
        """Where the source ``points`` (K, 2) went in ``mesh``, in input pixel coordinates."""
        nx, ny = grid_shape(mesh.source)
        grid = Grid(self.width, self.height, 0, nx, ny)
        return embed(grid, points) @ mesh.target + np.asarray(self.offset)

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
    rigid_steps : int, optional
        Cap on the rigid map's Newton steps (default :data:`rigid_energy.MAX_STEPS`).
    mask : (height, width) bool ndarray, optional
        The feature mask: a point handle on a feature carries the whole feature (see
        :func:`carried_features`).
    decay : float
        rho, the feature-aware solve's transition band in cells: a carried feature takes
        this many cells of the rigid grid around it along.
    """

    def __init__(self, width: int, height: int, rigid_steps: int | None = None, mask=None, decay: float = DECAY):
        self.width, self.height = int(width), int(height)
        self.rigid_steps = rigid_steps
        self.decay = float(decay)
        self.grid = rigid_grid(width, height)
        self.labels = None
        if mask is not None and np.any(mask):
            import cv2

            self.labels = cv2.connectedComponents(np.asarray(mask, np.uint8), connectivity=8)[1]
        self.rigid = None
        self._key = None
        self._last = None
        self._embeddings = {}

    def deformation(self, handles: Handles, warm: bool = True, steps: int | None = None) -> HandleWarp:
        """The map W of ``handles``, a preset-like warp (factoring anew only when the handles'
        sources changed; a fold the handles ask for is noted in its ``notes``); ``warm``: from
        the last map (a drag's updates), else from the similarity step, whatever came before;
        ``steps``: Newton steps at most (default the map's own cap)."""
        radius = handles.radius if handles.radius is not None else default_radius(
            self.width, self.height, max(self.grid.spacing))
        sources, targets, radii = handles.constraints(self.grid, radius)
        uncarried, carried, band = [], [], self.decay * max(self.grid.spacing)
        if self.labels is not None and len(handles.points_from):
            sources, targets, radii = carried_features(self.labels, self.grid.nodes(), handles, sources, targets,
                                                       radii, band, uncarried, carried)
        notes = [f"the handle at ({x:g}, {y:g}) sits on a feature within {band:.0f} px of the held border: it does not "
                 "carry the feature (the border stays), and moves its point only as far as the feature gives way"
                 for x, y in handles.points_from[uncarried]]
        key = (sources.tobytes(), radii.tobytes())
        if key != self._key:
            self.rigid = RigidDeformer(self.grid, sources, radii)
            self._key, self._last = key, None
        nodes = self.rigid.deform(targets, start=self._last if warm else None, steps=steps or self.rigid_steps)
        self._last = nodes
        values = {"points": len(handles.points_from), "curves": len(handles.curves),
                  "border": handles.border if isinstance(handles.border, str) else sorted(handles.border),
                  "canvas": handles.canvas, "radius": radius}
        warp = HandleWarp(self.width, self.height, self.grid, nodes, handles.canvas, values, self._embeddings)
        warp.notes, warp.handles = list(handles.notes) + notes, handles
        warp.capped, warp.rigid_map, warp.carried = not self.rigid.converged, self, set(carried)
        warp.notes += fold_notes(warp, handles, np.hypot(*(self.rigid.centres(nodes) - targets).T).max())
        warp.notes += carried_scale_notes(self.labels, handles, carried) if self.labels is not None else []
        if handles.border == "pinned":
            moved = float(np.hypot(*(nodes - self.grid.nodes())[self.grid.boundary()].T).max())
            if moved > HANDLE_SLACK_PX:
                warp.notes.append(f"the pinned border gives way by up to {moved:.0f} px where the handles pull "
                                  f"it past itself (it holds only as hard as a handle)")
        return warp


def carried_features(labels, nodes, handles: Handles, sources, targets, radii, band: float = 0.0,
                     uncarried: list | None = None, carried: list | None = None):
    """The constraints with every point handle that sits on a feature replaced by that feature.

    Dragging a point of a face moves the face: the nodes of the rigid grid inside the
    feature's connected component are held to one similarity, the best fit of the handles on
    it (with one handle: the handles' overall rotation, or the handle's own angle, and scale,
    and that handle's translation), so the feature-aware solve, which keeps features as
    similarities of W, keeps the handle where it was dragged. Point handles come first in
    ``sources`` (as :meth:`Handles.constraints` orders them). The nodes within ``band`` px
    of the feature move with it too (:class:`RigidMap` gives rho cells of the rigid grid,
    at least the rho cells of the finer grid the feature-aware solve refines it into): that
    solve asks its transition band to be the feature's similarity, and a band that W
    compresses instead pulls the feature off the handle (by about the band's width).

    A feature whose band reaches a side the handles hold (``border``: pinned, or that side's
    curve) is not carried: the border holds, and the handle on it moves its own disc (carried,
    the band's border nodes and the pinned border pulled against each other and the border
    slid by 22 px).
    The indices of its point handles are appended to ``uncarried``, those of the handles that
    carry a feature to ``carried``.
    """
    h, w = labels.shape
    sides = {"top", "bottom", "left", "right"} if handles.border == "pinned" else set(
        handles.border if isinstance(handles.border, dict) else ())
    on_side = {"top": nodes[:, 1] <= -0.5, "bottom": nodes[:, 1] >= h - 0.5,
               "left": nodes[:, 0] <= -0.5, "right": nodes[:, 0] >= w - 0.5}
    held_border = np.any([on_side[side] for side in sides], axis=0) if sides else np.zeros(len(nodes), bool)
    at = np.clip(np.rint(handles.points_from).astype(int), 0, [w - 1, h - 1])
    on = labels[at[:, 1], at[:, 0]]
    node_at = np.clip(np.rint(nodes).astype(int), 0, [w - 1, h - 1])
    overall = similarity_fit(sources, targets)
    keep = np.ones(len(sources), bool)
    extra_sources, extra_targets = [], []
    for label in np.unique(on[on > 0]):
        near = _near_label(labels, label, band, node_at)
        inside = nodes[near]
        held = np.flatnonzero(on == label)
        if len(inside) < 3:
            continue
        if np.any(near & held_border):
            if uncarried is not None:
                uncarried.extend(int(k) for k in held)
            continue
        a, b = similarity_fit(handles.points_from[held], handles.points_to[held]) if len(held) > 1 else overall
        if len(held) == 1 and np.isfinite(handles.angles[held[0]]):      # turned by its own angle
            scale, angle = math.hypot(*overall), handles.angles[held[0]]
            a, b = scale * math.cos(angle), scale * math.sin(angle)
        turn = np.array([[a, -b], [b, a]])
        shift = np.mean(handles.points_to[held] - handles.points_from[held] @ turn.T, axis=0)
        keep[held] = False
        if carried is not None:
            carried.extend(int(k) for k in held)
        extra_sources.append(inside)
        extra_targets.append(inside @ turn.T + shift)
    if not extra_sources:
        return sources, targets, radii
    extra = np.concatenate(extra_sources)
    return (np.concatenate([sources[keep], extra]), np.concatenate([targets[keep], *extra_targets]),
            np.concatenate([radii[keep], np.zeros(len(extra))]))


def _near_label(labels: np.ndarray, label: int, band: float, at: np.ndarray) -> np.ndarray:
    """(K,) bool: the pixels ``at`` ((K, 2) int, x and y) within ``band`` px of the label's.

    The exact Euclidean distance (OpenCV's precise mask, rounded through its square as
    :mod:`features` does: an ulp must not move a node in or out), on the label's bounding
    box grown by the band only."""
    import cv2

    ys, xs = np.nonzero(labels == label)
    reach = int(math.ceil(band)) + 1
    x0, y0 = max(0, xs.min() - reach), max(0, ys.min() - reach)
    x1, y1 = min(labels.shape[1], xs.max() + reach + 1), min(labels.shape[0], ys.max() + reach + 1)
    box = at[:, 0] >= x0
    box &= (at[:, 0] < x1) & (at[:, 1] >= y0) & (at[:, 1] < y1)
    outside = np.ascontiguousarray(labels[y0:y1, x0:x1] != label, dtype=np.uint8)
    distance = cv2.distanceTransform(outside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    exact = np.sqrt(np.rint(distance.astype(np.float64) ** 2))
    near = np.zeros(len(at), bool)
    near[box] = exact[at[box, 1] - y0, at[box, 0] - x0] <= band
    return near


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
    rigid_steps : int, optional
        Cap on the rigid map's Newton steps per update (see :class:`RigidMap`).
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
                 quick: bool = False, rigid_steps: int | None = None, **options):
        arrays.check_size(width, height, "Deformer")
        if mode not in MODES:
            raise ValueError(f"Deformer: mode={mode!r}; use one of {', '.join(map(repr, MODES))}")
        if rigid_steps is not None and (isinstance(rigid_steps, bool) or not isinstance(rigid_steps, numbers.Integral)
                                        or rigid_steps < 1):
            raise ValueError(f"Deformer: rigid_steps={rigid_steps!r}; use a whole number of steps, at least 1, or None")
        self.mode, self.quick = mode, quick
        try:
            self.warper = FeatureWarper(width, height, mask, **options)     # the border: HandleWarp.boundary
        except TypeError as err:
            raise TypeError(str(err).replace("FeatureWarper.__init__()", "Deformer()")) from None
        self.rigid = RigidMap(width, height, rigid_steps, self.warper.mask, self.warper.decay)
        self.handles = None
        self.warp = None

    def solve(self, handles: Handles, mode: str | None = None, drag: bool = False) -> Mesh:
        """The feature-aware mesh for ``handles`` (Handles, a handles dict, or a handles file's
        path: :meth:`Handles.from_file`; whose sources may differ from the last call's:
        the rigid map is then factored anew); ``drag``: an update while a handle is dragged
        (with ``quick``: a fold is not untangled, see :meth:`FeatureWarper.solve`). With
        ``quick``, the features' tie decisions are those of the first solve of this handle set
        (the same sources), a drag's or not, so no later solve of the set factors anew."""
        if isinstance(handles, (str, os.PathLike)):
            handles = Handles.from_file(handles, self.warper.width, self.warper.height)
        if isinstance(handles, dict):
            handles = Handles.from_dict(handles, self.warper.width, self.warper.height)
        if not isinstance(handles, Handles):
            raise TypeError(f"handles must be Handles, a handles dict or a handles file's path, not "
                            f"{type(handles).__name__}")
        handles.check_image(self.warper.width, self.warper.height)
        self.handles = handles
        factored = self.rigid.rigid
        self.warp = self.rigid.deformation(handles, warm=drag or self.quick)     # a full solve: no history
        same_set = factored is not None and self.rigid.rigid is factored     # the handles' sources unchanged
        mesh = self.warper.solve(self.warp, mode or self.mode, quick=self.quick, drag=drag, keep_ties=same_set)
        if not self.quick:             # the editor's previews are not re-aimed (Export is)
            mesh = self.warp.land(mesh, lambda warp: self.warper.solve(warp, mode or self.mode))
        mesh.record.warnings.extend(self.warp.review(mesh, self.quick))
        return mesh

    def move(self, targets: np.ndarray, mode: str | None = None) -> Mesh:
        """The mesh with the last handles' points moved to ``targets`` ((K, 2), in their order);
        nothing is factored again."""
        if self.handles is None:
            raise ValueError("move() moves the handles of the last solve(): call solve() first")
        targets = np.asarray(targets, dtype=np.float64)
        if targets.size != self.handles.points_from.size:
            raise ValueError(f"targets: {len(self.handles.points_from)} points (x, y) expected, "
                             f"got an array of shape {targets.shape}")
        data = self.handles.as_dict()
        for point, (x, y) in zip(data["points"], targets.reshape(-1, 2)):
            point["to"] = [float(x), float(y)]                 # its angle stays (a turned handle)
        return self.solve(Handles.from_dict(data, self.warper.width, self.warper.height), mode)


def handles_factory(data, decay: float = DECAY, names: list | None = None, source: str = "handles"):
    """``make(width, height, mask)``: the map W of the handles file ``data`` (parsed JSON) for an
    image of that size and feature mask (ValueError when the handles do not fit it); ``decay``
    as the feature-aware solve's (see :class:`RigidMap`); ``names``: how each point handle
    was given (:attr:`Handles.names`); ``source``: the file's name in its notes."""
    def make(width: int, height: int, mask=None) -> HandleWarp:
        handles = Handles.from_dict(data, width, height, source)
        handles.names = names
        return RigidMap(width, height, mask=mask, decay=decay).deformation(handles)

    return make
