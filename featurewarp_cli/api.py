"""Python API: feature-aware warping of numpy images, with a reusable factorization.

Examples
--------
>>> import numpy as np
>>> from featurewarp_cli.api import FeatureWarper, load_warp, warp
>>> image = np.zeros((120, 160, 3), np.uint8)
>>> mask = np.zeros((120, 160), bool); mask[40:80, 60:100] = True
>>> out = warp(image, mask, "stretch", sy=2)
>>> out.shape
(240, 160, 3)

Warping the same image and mask again with other presets or parameters reuses
the factorization (the system matrix depends on the grid and mask only):

>>> warper = FeatureWarper(160, 120, mask)
>>> a = warper.render(image, warper.solve(load_warp("swirl")(160, 120, angle=90)))
>>> b = warper.render(image, warper.solve(load_warp("swirl")(160, 120, angle=180)))
>>> warper.factorizations
1
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import features as feat
from . import render as rnd
from . import system, targets
from .grid import Grid, signed_areas
from .solver import ReducedSystem

MODES = ("similarity", "rigid", "plain")
FORMULATIONS = ("exact", "paper")

#: Target node count of the automatic grid (see :func:`auto_cell`).
AUTO_NODES = 250_000


def auto_cell(width: int, height: int) -> int:
    """Automatic cell size: 4 px, or larger so that the grid keeps about 250 000 nodes.

    Parameters
    ----------
    width, height : int

    Returns
    -------
    int
    """
    return max(4, math.ceil(math.sqrt(width * height / AUTO_NODES)))


def load_warp(name: str):
    """The preset class registered under ``name`` in the ``featurewarp.warps`` group."""
    from .plugins import load

    return load(name)


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
    info : dict
        What was done: grid, components, solver, flips, stage timings.
    """

    source: np.ndarray
    target: np.ndarray
    triangles: np.ndarray
    canvas: tuple[int, int]
    info: dict = field(default_factory=dict)

    def flips(self) -> int:
        """Number of triangles whose signed area on the canvas is <= 0."""
        return int(np.count_nonzero(signed_areas(self.target, self.triangles) <= 0))


class FeatureWarper:
    """Feature-aware warping of one image size and one mask, factoring once.

    Parameters
    ----------
    width, height : int
        Source image size in pixels.
    mask : (height, width) bool ndarray or None
        True where a pixel belongs to a feature. None: no features.
    cell : int, optional
        Grid cell size in pixels; default :func:`auto_cell`.
    feature_weight : float
        w_F: each side of the feature equations is multiplied by it (default 10).
    decay : float
        rho: width of the transition band in cells (default 2).
    formulation : {'exact', 'paper'}
        exact (default): every feature component moves as one similarity
        (hard constraint), whose rotation is the warp's best fit over the
        component and whose scale follows :func:`targets.intuitive_scales`.
        A component that touches a fixed border node keeps soft constraints.
        paper: the paper's soft per-quad targets (lambda R_Q, weight w_F).

    Attributes
    ----------
    factorizations : int
        How many times the system matrix was factored (1 after any number of solves).
    timings : dict
        Seconds spent in each stage by the last solve (grid, assemble, factor, rhs, solve).
    """

    def __init__(self, width: int, height: int, mask: np.ndarray | None = None, *,
                 cell: int | None = None, feature_weight: float = 10.0, decay: float = 2.0,
                 formulation: str = "exact"):
        if mask is not None and mask.shape != (height, width):
            raise ValueError(f"mask is {mask.shape[1]}x{mask.shape[0]}, image is {width}x{height}")
        if not (feature_weight > 0 and math.isfinite(feature_weight)):
            raise ValueError(f"feature_weight must be a positive number, not {feature_weight}")
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {', '.join(FORMULATIONS)}, not {formulation!r}")
        if not (decay > 0 and math.isfinite(decay)):
            raise ValueError(f"decay must be a positive number, not {decay}")
        self.width, self.height = int(width), int(height)
        self.mask = np.zeros((height, width), bool) if mask is None else np.asarray(mask, bool)
        self.feature_weight = float(feature_weight)
        self.decay = float(decay)
        self.formulation = formulation
        self.cell = int(cell) if cell else auto_cell(width, height)
        if self.cell < 2:
            raise ValueError(f"cell must be at least 2 px, not {self.cell}")
        self.factorizations = 0
        self.timings: dict[str, float] = {}
        t0 = time.perf_counter()
        self.grid = Grid.for_image(self.width, self.height, self.cell)
        self.nodes = self.grid.nodes()
        self.triangles = self.grid.triangles()
        self.fixed = self.grid.boundary()
        self.features = feat.analyse(self.mask, self.grid, self.feature_weight, self.decay)
        self.rigid_component, self.unknown = self._parametrize()
        self._grid_seconds = time.perf_counter() - t0
        self._system: ReducedSystem | None = None

    @property
    def solver(self) -> str:
        """Name of the factorization in use ('cholmod' or 'scipy-splu'), once factored."""
        return self._system.method if self._system else "none"

    def _parametrize(self) -> tuple[np.ndarray, np.ndarray]:
        """Which component each node is tied to (-1: none) and the unknown of each node.

        Border nodes are fixed (unknown -1). With the exact formulation the
        nodes of a component that touches no fixed node share one unknown
        (the component's translation); all other nodes get their own.
        """
        n = self.grid.n_nodes
        tied = np.full(n, -1)
        if self.formulation == "exact" and self.features.n_components:
            quads = self.grid.quads()
            own = self.features.is_feature
            tied[quads[own].ravel()] = np.repeat(self.features.component[own], 4)
            touching = np.unique(tied[self.fixed & (tied >= 0)])
            tied[np.isin(tied, touching)] = -1
        free = ~self.fixed & (tied < 0)
        unknown = np.full(n, -1)
        unknown[free] = np.arange(np.count_nonzero(free))
        used = np.unique(tied[tied >= 0])
        renumber = np.zeros(self.features.n_components + 1, dtype=np.int64)
        renumber[used] = np.count_nonzero(free) + np.arange(used.size)
        unknown[tied >= 0] = renumber[tied[tied >= 0]]
        return tied, unknown

    def _factor(self) -> ReducedSystem:
        if self._system is None:
            t0 = time.perf_counter()
            matrix = system.normal_matrix(self.grid, self.features.weight)
            t1 = time.perf_counter()
            self._system = ReducedSystem(matrix, self.unknown)
            self.factorizations += 1
            self.timings.update(assemble=t1 - t0, factor=time.perf_counter() - t1)
        return self._system

    def solve(self, warp, mode: str = "similarity") -> Mesh:
        """Feature-aware mesh for ``warp`` (a :class:`warps.Warp` instance).

        Parameters
        ----------
        warp : callable
            Maps (N, 2) source positions to (N, 2) canvas positions; has ``canvas``.
        mode : {'similarity', 'rigid', 'plain'}
            similarity: features rotate and scale uniformly; rigid: they keep
            their size; plain: the warp itself, mask ignored.

        Returns
        -------
        Mesh
        """
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
        if (warp.width, warp.height) != (self.width, self.height):
            raise ValueError(f"warp is for {warp.width}x{warp.height}, warper for {self.width}x{self.height}")
        self.timings = {"grid": self._grid_seconds}
        warped = warp(self.nodes)
        info = {
            "mode": mode,
            "grid": {"cell": self.cell, "spacing": list(self.grid.spacing),
                     "nodes": self.grid.n_nodes, "quads": int(self.features.weight.size)},
            "components": [],
            "solver": "none",
        }
        if mode == "plain" or self.features.n_components == 0:
            target = warped
        else:
            reduced = self._factor()
            self.timings.setdefault("assemble", 0.0)
            self.timings.setdefault("factor", 0.0)
            t0 = time.perf_counter()
            jac = targets.quad_jacobians(self.grid, warped)
            quad_maps, component_maps = targets.quad_targets(jac, self.features, mode, self.formulation)
            edges = np.where(self.features.is_constrained[:, None, None],
                             system.edge_vectors(self.grid, quad_maps),
                             system.warp_edge_vectors(self.grid, warped))
            rhs = system.right_hand_side(self.grid, self.features.weight, edges)
            offset = np.zeros_like(warped)
            offset[self.fixed] = warped[self.fixed]
            tied = self.rigid_component >= 0
            offset[tied] = np.einsum("nij,nj->ni", component_maps[self.rigid_component[tied]], self.nodes[tied])
            t1 = time.perf_counter()
            target = reduced.solve(rhs, offset)
            self.timings.update(rhs=t1 - t0, solve=time.perf_counter() - t1)
            info["components"] = self._describe_components(component_maps)
            info["solver"] = reduced.method
        mesh = Mesh(self.nodes, target, self.triangles, tuple(warp.canvas), info)
        info["flipped_triangles"] = mesh.flips()
        info["timings"] = dict(self.timings)
        return mesh

    def _describe_components(self, component_maps: np.ndarray) -> list[dict]:
        """Per component: quads, target scale and rotation, and whether it is held exactly."""
        counts = np.bincount(self.features.component[self.features.is_feature],
                             minlength=self.features.n_components)
        exact = np.zeros(self.features.n_components, bool)
        exact[self.rigid_component[self.rigid_component >= 0]] = True
        scales = np.hypot(component_maps[:, 0, 0], component_maps[:, 1, 0])
        angles = np.degrees(np.arctan2(component_maps[:, 1, 0], component_maps[:, 0, 0]))
        return [{"quads": int(c), "scale": float(s), "rotation_deg": float(a), "exact": bool(e)}
                for c, s, a, e in zip(counts, scales, angles, exact)]

    def render(self, image: np.ndarray, mesh: Mesh, interp: str = "cubic", background=None) -> np.ndarray:
        """Resample ``image`` through ``mesh``; see :func:`featurewarp_cli.render.resample`."""
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, warper is for {self.width}x{self.height}")
        t0 = time.perf_counter()
        coords, covered = rnd.inverse_map(mesh.source, mesh.target, mesh.triangles, mesh.canvas)
        out = rnd.resample(image, coords, covered, interp, background)
        mesh.info["timings"]["render"] = time.perf_counter() - t0
        return out


def warp(image: np.ndarray, mask: np.ndarray | None, preset: str, *, mode: str = "similarity",
         cell: int | None = None, feature_weight: float = 10.0, decay: float = 2.0,
         formulation: str = "exact", interp: str = "cubic", background=None, **params) -> np.ndarray:
    """Warp ``image`` with a preset while the features in ``mask`` keep their shape.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
    mask : (h, w) bool ndarray or None
    preset : str
        Registered preset name ('stretch', 'arc', 'swirl', 'bulge', or a plugin's).
    mode, cell, feature_weight, decay, formulation
        See :class:`FeatureWarper`.
    interp : {'linear', 'cubic', 'lanczos'}
    background : tuple or None
        Fill for pixels no source pixel lands on, in the output's channel order;
        None: transparent (alpha added where needed).
    **params
        The preset's parameters.

    Returns
    -------
    ndarray
        The warped image on the preset's canvas.
    """
    height, width = image.shape[:2]
    w = load_warp(preset)(width, height, **params)
    warper = FeatureWarper(width, height, mask, cell=cell, feature_weight=feature_weight, decay=decay,
                           formulation=formulation)
    return warper.render(image, warper.solve(w, mode), interp, background)
