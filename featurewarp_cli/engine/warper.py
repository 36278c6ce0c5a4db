"""Python API: feature-aware warping of numpy images, with a reusable factorization.

Examples
--------
>>> import numpy as np
>>> from featurewarp_cli import FeatureWarper, load_warp, warp
>>> image = np.zeros((120, 160, 3), np.uint8)
>>> mask = np.zeros((120, 160), bool); mask[40:80, 60:100] = True
>>> out = warp(image, mask, "stretch", sy=2)
>>> out.shape
(240, 160, 3)

Warping the same image and mask again with other presets or parameters reuses
the factorization: the system matrix depends on the grid and the mask only.

>>> warper = FeatureWarper(160, 120, mask)
>>> a = warper.render(image, warper.solve(load_warp("swirl")(160, 120, angle=45)))
>>> b = warper.render(image, warper.solve(load_warp("swirl")(160, 120, angle=90)))
>>> c = warper.render(image, warper.solve(load_warp("bulge")(160, 120, strength=0.5)))
>>> warper.factorizations
1

The automatic cell follows the warp's curvature: a swirl by 180 degrees needs a
finer grid, factored in turn. A sliding border (stretch's) holds x and y at
different nodes: one factorization per coordinate, shared by every stretch.

>>> mesh = warper.solve(load_warp("swirl")(160, 120, angle=180))
>>> warper.factorizations
2
>>> stretcher = FeatureWarper(160, 120, mask)
>>> meshes = [stretcher.solve(load_warp("stretch")(160, 120, sx=sx)) for sx in (1.5, 2, 3)]
>>> stretcher.factorizations
2
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import features as feat
from . import fidelity, injectivity, quality, system, targets
from .defaults import BOUNDARIES, DECAY, FEATURE_WEIGHT, FORMULATIONS, MODES
from ..render import raster as rnd
from .grid import Grid, signed_areas
from .solver import ReducedSystem, factor_concurrently


#: Bisection steps on how far released features go from the warp's shape to their own.
BLEND_BISECTIONS = 8
UNTANGLED_BISECTIONS = 3
#: Fraction of its area under the warp that the fold-over guard asks each triangle to keep.
UNTANGLE_FLOOR = 0.05
#: The fold-over guard first untangles a window around the folds, reaching this many
#: times the largest fold's extent beyond it (at least WINDOW_MIN_MARGIN quads), in at
#: most WINDOW_ITERATIONS steps (cheap ones; a hopeless window stops early for lack of
#: progress); where that fails, the whole grid. 12 MP swirl 180: 43 window steps on 15 %
#: of the triangles instead of 36 on all of them; at --cell 4 (750 k nodes) 150 window
#: steps, 9.8 s, where 60 left 3 folds and the global pass took 27 s in all.
WINDOW_MARGIN = 0.5
WINDOW_MIN_MARGIN = 8
WINDOW_ITERATIONS = 150
#: Windows larger than this fraction of the grid are left to the global pass.
WINDOW_MAX_FRACTION = 0.5


def load_warp(name: str):
    """The preset class registered under ``name`` in the ``featurewarp.warps`` group."""
    from ..plugins import load

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


@dataclass
class _GridState:
    """What depends on the grid and the mask but not on the warp (one per cell size)."""

    grid: Grid
    nodes: np.ndarray
    triangles: np.ndarray
    fixed_x: np.ndarray
    fixed_y: np.ndarray
    features: feat.Features
    tied: np.ndarray
    system: "AxisSystems | None" = None
    normal: object = None               # the normal matrix, once the fold-over guard needs it

    @property
    def fixed(self) -> np.ndarray:
        """Nodes with any coordinate held."""
        return self.fixed_x | self.fixed_y


class AxisSystems:
    """The factored system for x and for y: one shared factorization when both
    coordinates hold the same nodes, two when a sliding border frees one of them.
    The two are factored at once, in two threads (:func:`solver.factor_concurrently`).

    Parameters
    ----------
    matrix : (N, N) matrix
        The normal matrix (:func:`system.normal_matrix`).
    unknown_x, unknown_y : (N,) int ndarray
        Unknown numbering per coordinate (see :class:`solver.ReducedSystem`).
    """

    def __init__(self, matrix, unknown_x: np.ndarray, unknown_y: np.ndarray):
        if np.array_equal(unknown_x, unknown_y):
            self.x = self.y = ReducedSystem(matrix, unknown_x)
        else:
            self.x, self.y = factor_concurrently(matrix, [unknown_x, unknown_y])
        self.method = self.x.method
        self.factorizations = 1 if self.y is self.x else 2

    def solve(self, rhs: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Node positions (N, 2); see :meth:`solver.ReducedSystem.solve`."""
        if self.y is self.x:
            return self.x.solve(rhs, offset)
        return np.concatenate([self.x.solve(rhs[:, :1], offset[:, :1]),
                               self.y.solve(rhs[:, 1:], offset[:, 1:])], axis=1)


class FeatureWarper:
    """Feature-aware warping of one image size and one mask, factoring once.

    Parameters
    ----------
    width, height : int
        Source image size in pixels.
    mask : (height, width) bool ndarray or None
        True where a pixel belongs to a feature. None: no features.
    cell : float, optional
        Grid cell size in pixels. Default: automatic (:func:`fidelity.auto_cell`):
        4 px or larger for big images, finer where the warp curves so much that
        the grid would stray more than 0.5 px from it.
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
    injective : bool
        Guard against fold-overs (default True); see :meth:`solve`.
    boundary : {'fixed', 'slide'} or None
        fixed: border nodes stay where W puts them (the paper). slide: on a side
        that W maps onto an axis-parallel line, nodes may slide along it, so a
        feature cut by the border can keep its shape while the canvas stays
        exact. None (default): the preset's own choice (``warp.boundary``).

    Attributes
    ----------
    factorizations : int
        How many times a system matrix was factored. Solves that share a grid
        reuse its factorization; only the fold-over guard factors again.
    timings : dict
        Seconds spent in each stage by the last solve.
    """

    def __init__(self, width: int, height: int, mask: np.ndarray | None = None, *,
                 cell: float | None = None, feature_weight: float = FEATURE_WEIGHT, decay: float = DECAY,
                 formulation: str = "exact", injective: bool = True, boundary: str | None = None):
        if boundary not in (None,) + BOUNDARIES:
            raise ValueError(f"boundary must be one of {', '.join(BOUNDARIES)}, not {boundary!r}")
        if mask is not None and mask.shape != (height, width):
            raise ValueError(f"mask is {mask.shape[1]}x{mask.shape[0]}, image is {width}x{height}")
        if not (feature_weight > 0 and math.isfinite(feature_weight)):
            raise ValueError(f"feature_weight must be a positive number, not {feature_weight}")
        if not (decay > 0 and math.isfinite(decay)):
            raise ValueError(f"decay must be a positive number, not {decay}")
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {', '.join(FORMULATIONS)}, not {formulation!r}")
        if cell is not None and not (cell >= 1 and math.isfinite(cell)):
            raise ValueError(f"cell must be at least 1 px, not {cell}")
        self.width, self.height = int(width), int(height)
        self.mask = np.zeros((height, width), bool) if mask is None else np.asarray(mask, bool)
        self.feature_weight = float(feature_weight)
        self.decay = float(decay)
        self.formulation = formulation
        self.injective = injective
        self.boundary = boundary
        self.cell = cell
        self.factorizations = 0
        self.timings: dict[str, float] = {}
        self._states: dict[tuple, _GridState] = {}

    def _state(self, grid: Grid, warped: np.ndarray, boundary: str) -> _GridState:
        """Features, border conditions and ties on ``grid`` (built once per grid and border);
        ``warped``: W at the grid's nodes."""
        sides = (False,) * 4
        if boundary == "slide":
            sides = system.sliding_sides(grid, warped)
        key = ((grid.nx, grid.ny), sides)
        if key not in self._states:
            features = feat.analyse(self.mask, grid, self.feature_weight, self.decay)
            fixed_x, fixed_y = system.border_conditions(grid, sides)
            tied = (system.tie_features(grid, features, fixed_x | fixed_y) if self.formulation == "exact"
                    else np.full(grid.n_nodes, -1))
            self._states[key] = _GridState(grid, grid.nodes(), grid.triangles(), fixed_x, fixed_y,
                                           features, tied)
        return self._states[key]

    def _factor(self, state: _GridState, weights: np.ndarray, tied: np.ndarray) -> AxisSystems:
        """Assemble and factor the normal equations for these weights and ties."""
        t0 = time.perf_counter()
        matrix = system.normal_matrix(state.grid, weights)
        if state.normal is None and weights is state.features.weight:
            state.normal = matrix                         # the fold-over guard's products use it
        t1 = time.perf_counter()
        reduced = AxisSystems(matrix, system.number_unknowns(state.fixed_x, tied),
                              system.number_unknowns(state.fixed_y, tied))
        self.factorizations += reduced.factorizations
        self.timings["assemble"] = self.timings.get("assemble", 0.0) + t1 - t0
        self.timings["factor"] = self.timings.get("factor", 0.0) + time.perf_counter() - t1
        return reduced

    def _constants(self, state, weights, edges, tied, component_maps, warped):
        """A^T b for these edge targets, and q: fixed nodes at W, tied nodes at their
        component's linear map (see :meth:`solver.ReducedSystem.solve`)."""
        t0 = time.perf_counter()
        rhs = system.right_hand_side(state.grid, weights, edges)
        offset = np.zeros_like(warped)
        offset[state.fixed_x, 0] = warped[state.fixed_x, 0]
        offset[state.fixed_y, 1] = warped[state.fixed_y, 1]
        on = tied >= 0
        offset[on] = np.einsum("nij,nj->ni", component_maps[tied[on]], state.nodes[on])
        self.timings["rhs"] = self.timings.get("rhs", 0.0) + time.perf_counter() - t0
        return rhs, offset

    def _solver(self, state, reduced, weights, edges, tied, component_maps, warped):
        """``solve(force=None)``: least-squares node positions for these edge targets, the
        fixed border and tied features, plus an optional external force per node (N, 2)."""
        rhs, offset = self._constants(state, weights, edges, tied, component_maps, warped)

        def solve(force=None):
            t1 = time.perf_counter()
            result = reduced.solve(rhs if force is None else rhs + force, offset)
            self.timings["solve"] = self.timings.get("solve", 0.0) + time.perf_counter() - t1
            return result

        solve.rhs, solve.offset = rhs, offset
        return solve

    def _linear_solve(self, state, reduced, weights, edges, tied, component_maps, warped) -> np.ndarray:
        """Least-squares node positions (see :meth:`_solver`)."""
        return self._solver(state, reduced, weights, edges, tied, component_maps, warped)()

    def solve(self, warp, mode: str = "similarity") -> Mesh:
        """Feature-aware mesh for ``warp`` (a :class:`warps.Warp` instance).

        The least-squares solution is returned when it has no fold-over. When
        it has, the guard releases the constraints around the folds (the
        components there lose their exact tie, and the quads there are pulled
        towards the warp with doubling weight) and solves again; it keeps the
        furthest point on the way from the warp itself (injective on a grid that
        follows it) to each solution at which no triangle degenerates, so the
        result never folds.

        Parameters
        ----------
        warp : callable
            Maps (N, 2) source positions to (N, 2) canvas positions; has
            ``width``, ``height`` and ``canvas``.
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
        self.timings = {}
        t0 = time.perf_counter()
        if self.cell is None:
            cell, error = fidelity.auto_cell(self.width, self.height, warp)
        else:
            cell = float(self.cell)
            error = fidelity.pl_error(Grid.for_image(self.width, self.height, cell), warp)
        boundary = self.boundary or getattr(warp, "boundary", "fixed")
        grid = Grid.for_image(self.width, self.height, cell)
        warped = warp(grid.nodes())
        state = self._state(grid, warped, boundary)
        self.timings["grid"] = time.perf_counter() - t0
        info = {
            "mode": mode,
            "formulation": self.formulation,
            "boundary": boundary,
            "grid": {"cell": cell, "spacing": list(state.grid.spacing), "nodes": state.grid.n_nodes,
                     "quads": int(state.features.weight.size), "pl_error_px": error},
            "components": [],
            "solver": "none",
            "release_rounds": 0,
        }
        if mode == "plain" or state.features.n_components == 0:
            target = warped
            info["flipped_before_guard"] = int(np.count_nonzero(injectivity.flipped(target, state.triangles)))
        else:
            target, component_maps = self._feature_aware(state, warped, mode, info)
            info["components"] = self._describe_components(state, component_maps)
        mesh = Mesh(state.nodes, target, state.triangles, tuple(warp.canvas), info)
        features = state.features
        transition = np.tile(features.is_constrained & ~features.is_feature, 2)
        info["quality"] = quality.mesh_quality(
            state.nodes, target, warped, state.triangles, state.grid.quads(),
            system.feature_nodes(state.grid, features), features.n_components,
            ~features.is_constrained, transition)
        info["flipped_triangles"] = info["quality"]["flipped_triangles"]
        info["timings"] = dict(self.timings)
        return mesh

    def _feature_aware(self, state: _GridState, warped: np.ndarray, mode: str, info: dict):
        """Solve with the fold-over guard; returns node positions and component maps."""
        features, tris = state.features, state.triangles
        jac = targets.quad_jacobians(state.grid, warped)
        quad_maps, component_maps = targets.quad_targets(jac, features, mode, self.formulation)
        edges = np.where(features.is_constrained[:, None, None],
                         system.edge_vectors(state.grid, quad_maps),
                         system.warp_edge_vectors(state.grid, warped))
        if state.system is None:
            state.system = self._factor(state, features.weight, state.tied)
        info["solver"] = state.system.method
        x = self._linear_solve(state, state.system, features.weight, edges, state.tied, component_maps, warped)
        info["flipped_before_guard"] = int(np.count_nonzero(injectivity.flipped(x, tris)))
        if not self.injective or info["flipped_before_guard"] == 0:
            return x, component_maps
        warp_areas = signed_areas(warped, tris)
        if warp_areas.min() <= 0:
            return x, component_maps          # the grid cannot follow the warp: nothing injective to keep
        floor = UNTANGLE_FLOOR * warp_areas
        stiffness = system.node_stiffness(state.grid, features.weight)

        def untangled(reduced, edges, tied, start):
            solve = self._solver(state, reduced, features.weight, edges, tied, component_maps, warped)
            # Near the folds first: cheap, and usually enough.
            x, iterations, window_quads = self._untangle_window(state, solve.rhs, solve.offset, tied, start,
                                                                floor, stiffness)
            info["untangle_iterations"] = info.get("untangle_iterations", 0) + iterations
            if x is not None and not injectivity.flipped(x, tris).any():
                info["untangle_window_quads"] = window_quads
                return x, True
            x, iterations = injectivity.untangle(solve, self._normal(state).dot, start, tris, floor, stiffness,
                                                 areas=lambda points: injectivity.grid_areas(state.grid, points))
            info["untangle_iterations"] = info.get("untangle_iterations", 0) + iterations
            return x, not injectivity.flipped(x, tris).any()

        x, ok = untangled(state.system, edges, state.tied, x)
        if ok:
            return x, component_maps
        # Some features cannot keep their shape: untie those near the folds and blend
        # their targets towards the warp's, as little as injectivity allows.
        warp_edges = system.warp_edge_vectors(state.grid, warped)
        released = np.unique(features.component[injectivity.trouble_quads(state.grid, x, tris)
                                                & features.is_constrained])
        for round_ in (1, 2):
            info["release_rounds"] = round_
            if round_ == 2:
                released = np.arange(features.n_components)
            tied = np.where(np.isin(state.tied, released), -1, state.tied)
            reduced = self._factor(state, features.weight, tied)
            blend = np.isin(features.component, released) & features.is_constrained

            def blended(s):
                return np.where(blend[:, None, None], s * edges + (1.0 - s) * warp_edges, edges)

            def solve_at(s):
                return self._linear_solve(state, reduced, features.weight, blended(s), tied, component_maps,
                                          warped)

            lo, hi = 0.0, 1.0
            best = solve_at(0.0)
            if injectivity.flipped(best, tris).any():
                continue                      # folds come from features not released yet
            for _ in range(BLEND_BISECTIONS):        # cheap: plain solves
                mid = 0.5 * (lo + hi)
                x = solve_at(mid)
                if injectivity.flipped(x, tris).any():
                    hi = mid
                else:
                    lo, best = mid, x
            hi = 1.0
            for _ in range(UNTANGLED_BISECTIONS):    # further, where untangling opens the folds
                mid = 0.5 * (lo + hi)
                x, ok = untangled(reduced, blended(mid), tied, solve_at(mid))
                if ok:
                    lo, best = mid, x
                else:
                    hi = mid
            info["feature_blend"] = lo
            info["released_components"] = [int(c) for c in released]
            return best, component_maps
        info["fallback"] = True
        return warped + injectivity.max_step(warped, x, tris) * 0.95 * (x - warped), component_maps

    def _normal(self, state: _GridState) -> system.StencilMatrix:
        """The normal matrix of the state's weights, built once."""
        if state.normal is None:
            state.normal = system.normal_matrix(state.grid, state.features.weight)
        return state.normal

    def _untangle_window(self, state: _GridState, rhs, offset, tied, x, floor, stiffness):
        """:func:`injectivity.untangle` on a window around the folded or crushed triangles.

        A fold is a local defect, so the guard first works on the nodes within
        :data:`WINDOW_MARGIN` times the largest fold's extent of the folded and
        crushed triangles, everything else held where it is, except that a
        tied feature reaching into the window keeps its shared unknown (it may
        shift as a whole, as in the global pass). The window's system is the
        rows of the normal matrix for its unknowns: a small fraction of the
        grid, so each step costs a fraction of a global one.

        Returns
        -------
        x : (N, 2) ndarray or None
            New positions; None when the window would be about as large as the grid.
        iterations : int
        quads : int
            Quads whose shape the window may change.
        """
        grid, weights = state.grid, state.features.weight
        n_quads = weights.size
        crushed = np.flatnonzero(injectivity.grid_areas(grid, x) < 0.5 * floor) % n_quads
        quads = np.zeros(n_quads, bool)
        quads[crushed] = True
        margin = max(WINDOW_MIN_MARGIN, int(WINDOW_MARGIN * injectivity.extent(grid, crushed)))
        _, near, inner = injectivity.window(grid, quads, margin)
        moving = inner & ~state.fixed & (tied < 0)
        moving |= np.isin(tied, np.unique(tied[near & (tied >= 0)])) & (tied >= 0)
        corners = grid.quads()
        touched = moving[corners].any(axis=1)
        ties = tied[corners]
        rigid = (ties[:, 0] >= 0) & (ties == ties[:, :1]).all(axis=1)    # inside one tied feature
        changing = np.flatnonzero(touched & ~rigid)
        if changing.size > WINDOW_MAX_FRACTION * n_quads:
            return None, 0, 0
        in_system = np.zeros(grid.n_nodes, bool)
        in_system[corners[touched].ravel()] = True
        nodes = np.flatnonzero(in_system)
        local_moving = moving[nodes]
        unknown = system.number_unknowns(~local_moving, np.where(local_moving, tied[nodes], -1))
        matrix = self._normal(state).submatrix(nodes)
        reduced = ReducedSystem(matrix, unknown)
        held = np.where(local_moving[:, None], offset[nodes], x[nodes])
        local_rhs = rhs[nodes]

        def solve(force):
            t0 = time.perf_counter()
            result = reduced.solve(local_rhs + force, held)
            self.timings["solve"] = self.timings.get("solve", 0.0) + time.perf_counter() - t0
            return result

        local = np.full(grid.n_nodes, -1)
        local[nodes] = np.arange(nodes.size)
        quad_corners = local[corners[changing]]
        triangles = np.concatenate([quad_corners[:, [0, 1, 2]], quad_corners[:, [0, 2, 3]]])
        window_floor = np.concatenate([floor[changing], floor[changing + n_quads]])
        moved, iterations = injectivity.untangle(solve, matrix.dot, x[nodes], triangles, window_floor,
                                                 stiffness[nodes], max_iterations=WINDOW_ITERATIONS)
        x = x.copy()
        x[nodes] = moved
        return x, iterations, int(changing.size)

    def _describe_components(self, state: _GridState, component_maps: np.ndarray) -> list[dict]:
        """Per component: quads, target scale and rotation, and whether it is held exactly."""
        features = state.features
        counts = np.bincount(features.component[features.is_feature], minlength=features.n_components)
        exact = np.zeros(features.n_components, bool)
        exact[state.tied[state.tied >= 0]] = True
        scales = np.hypot(component_maps[:, 0, 0], component_maps[:, 1, 0])
        angles = np.degrees(np.arctan2(component_maps[:, 1, 0], component_maps[:, 0, 0]))
        return [{"quads": int(c), "scale": float(s), "rotation_deg": float(a), "exact": bool(e)}
                for c, s, a, e in zip(counts, scales, angles, exact)]

    def render(self, image: np.ndarray, mesh: Mesh, interp: str = "cubic", background=None,
               antialias: bool = True) -> np.ndarray:
        """Resample ``image`` through ``mesh``; see :func:`featurewarp_cli.render.raster.render`.

        With ``antialias`` (default) regions the warp shrinks are prefiltered and the
        mesh's silhouette gets partial coverage (alpha, or a blend with ``background``).
        """
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, warper is for {self.width}x{self.height}")
        t0 = time.perf_counter()
        out = rnd.render(image, mesh.source, mesh.target, mesh.triangles, mesh.canvas, interp, background,
                         antialias=antialias)
        mesh.info["timings"]["render"] = time.perf_counter() - t0
        return out


def warp(image: np.ndarray, mask: np.ndarray | None, preset: str, *, mode: str = "similarity",
         cell: int | None = None, feature_weight: float = FEATURE_WEIGHT, decay: float = DECAY,
         formulation: str = "exact", boundary: str | None = None, interp: str = "cubic",
         background=None, **params) -> np.ndarray:
    """Warp ``image`` with a preset while the features in ``mask`` keep their shape.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
    mask : (h, w) bool ndarray or None
    preset : str
        Registered preset name ('stretch', 'arc', 'swirl', 'bulge', or a plugin's).
    mode, cell, feature_weight, decay, formulation, boundary
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
                           formulation=formulation, boundary=boundary)
    return warper.render(image, warper.solve(w, mode), interp, background)
