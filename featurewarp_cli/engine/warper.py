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

The automatic cell follows the warp's curvature: a swirl by 180 degrees needs a finer grid,
factored in turn. A sliding border (stretch's): one factorization per coordinate.

>>> mesh = warper.solve(load_warp("swirl")(160, 120, angle=180))
>>> warper.factorizations
2
>>> stretcher = FeatureWarper(160, 120, mask)
>>> meshes = [stretcher.solve(load_warp("stretch")(160, 120, sx=sx)) for sx in (1.5, 2, 3)]
>>> stretcher.factorizations
2
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .. import stages
from ..plugins import CheckedWarp
from . import arrays, attempts, components, fidelity, injectivity, plain_bound, scale_search, system, targets
from . import features as feat
from .defaults import (BOUNDARIES, DECAY, DECAY_PARAM, FEATURE_WEIGHT, FEATURE_WEIGHT_PARAM, FORMULATION,
                       FORMULATIONS, INTERPOLATION, MODE, MODES, SCALE_PRIOR, SCALE_PRIOR_PARAM)
from .grid import Grid, grid_for, signed_areas
from .mesh import Mesh
from .assess import assess
from .record import SolveRecord


#: Images thinner than this (px) are warped without features: one base cell cannot hold a shape.
MIN_FEATURE_SIDE = 4
#: A drag's update that folds stops, around its folds, this share of the way from W to where
#: the first triangle would degenerate (below 1, so that none is a sliver), and goes all the
#: way DRAG_REACH cells further out (:func:`injectivity.eased`).
DRAG_STEP = 0.8
DRAG_REACH = 16.0


def load_warp(name: str):
    """The preset class registered under ``name`` in the ``featurewarp.warps`` group."""
    from ..plugins import load

    return load(name)


@dataclass
class _GridState:
    """What depends on the grid and the mask but not on the warp (one per cell size)."""

    grid: Grid
    nodes: np.ndarray
    triangles: np.ndarray
    fixed_x: np.ndarray
    fixed_y: np.ndarray
    features: feat.Features
    node_component: np.ndarray            # component of each feature-quad node, -1 elsewhere
    tri_component: np.ndarray             # component of each triangle of a feature quad, -1 elsewhere
    stiffness: np.ndarray
    normal: object = None                 # scipy.sparse normal matrix, built when first factored
    systems: dict = field(default_factory=dict)         # factored systems by unknown numbering
    systems_by_ties: dict = field(default_factory=dict) # the same, by Ties.key() (skips the numbering)
    scale_solvers: dict = field(default_factory=dict)   # components.ScaleSolver by ties
    node_middle: np.ndarray | None = None  # nodes in their component's middle (plain_bound.middle_nodes)
    figures: object = None                # plain_bound.FeatureFigures, made at its first use


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
        exact (default): every feature component moves as one similarity (hard
        constraint); in similarity mode its scale and rotation are unknowns of
        the least squares, pulled towards the preset's lambda R by a prior of
        weight ``scale_prior`` (:mod:`featurewarp_cli.engine.components`). A
        component cut by the frame keeps its shape as the border condition
        allows (on a side that slides it slides along it); one held by pins no
        similarity satisfies keeps soft constraints.
        paper: the paper's soft per-quad targets (lambda R_Q, weight w_F).
    injective : bool
        Guard against fold-overs (default True); see :meth:`solve`.
    boundary : {'fixed', 'slide', 'release'} or None
        fixed: border nodes stay where W puts them (the paper). slide: on a side
        that W maps onto an axis-parallel line, nodes may slide along it. None
        (default): the preset's own choice (``warp.boundary``); either way the output's
        outline is W's, and a feature cut by a border that no similarity of it can
        follow gives way (it is held by soft constraints, and a warning says so).
        release: the preset's own, but such a feature lets go of the border to keep its
        shape, and the outline leaves W's there.
    scale_prior : float
        Weight of the pull of each component's scale and rotation towards the
        preset's (similarity mode, exact formulation; default
        :data:`defaults.SCALE_PRIOR`). 0 lets features grow or shrink freely to
        spare the background; large values fix them at lambda R.
    max_nodes : int, optional
        Largest grid allowed (a memory budget; see :func:`featurewarp_cli.io.limits.node_budget`).
        It only refuses: an explicit ``cell`` beyond it is a ValueError here, an automatic
        grid beyond it a :class:`fidelity.GridBudgetError` from :meth:`solve`. It never changes the
        grid, so a result does not depend on the machine's memory. Default: no limit (the
        automatic cell stops at :data:`fidelity.MAX_NODES`).
    grow_past_edge : bool
        Similarity mode, exact formulation: where the background is stretched beyond W by
        more than :data:`record.STREAKS`, a feature cut by the frame grows past the edges that
        cut it (cropped there) until it is not, as far as the background it stretches allows
        (:mod:`featurewarp_cli.engine.grow`; ``record.grown`` says how much). Default False.

    Attributes
    ----------
    factorizations : int
        How many times a system matrix was factored. Solves that share a grid
        and the same ties reuse the factorization.
    timings : dict
        Seconds spent in each stage by the last solve.
    """

    def __init__(self, width: int, height: int, mask: np.ndarray | None = None, *,
                 cell: float | None = None, feature_weight: float = FEATURE_WEIGHT, decay: float = DECAY,
                 formulation: str = FORMULATION, injective: bool = True, boundary: str | None = None,
                 scale_prior: float = SCALE_PRIOR, max_nodes: int | None = None, grow_past_edge: bool = False):
        arrays.check_size(width, height)
        if boundary not in (None,) + BOUNDARIES:
            raise ValueError(f"boundary must be one of {', '.join(BOUNDARIES)}, not {boundary!r}")
        for param, value in ((FEATURE_WEIGHT_PARAM, feature_weight), (DECAY_PARAM, decay),
                             (SCALE_PRIOR_PARAM, scale_prior)):
            try:
                param.check(value)
            except ValueError as err:
                raise ValueError(f"{param.name}: {str(err).split(': ', 1)[-1]}") from None
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {', '.join(FORMULATIONS)}, not {formulation!r}")
        arrays.check_cell_and_flags(cell, injective=injective, grow_past_edge=grow_past_edge)
        if cell is not None and max_nodes is not None:
            nodes = Grid.for_image(width, height, cell).n_nodes
            if nodes > max_nodes:
                raise ValueError(f"--cell {cell:g} makes a grid of {nodes} nodes, above the {max_nodes} that the "
                                 f"memory limit allows (a larger --cell, or a larger --max-memory)")
        self.width, self.height = int(width), int(height)
        # A copy: the mask's analysis is kept per grid, so the caller's array must not change it.
        self.mask = np.zeros((height, width), bool) if mask is None else arrays.mask_array(mask, (height, width)).copy()
        self.notes = []
        if min(width, height) < MIN_FEATURE_SIDE and self.mask.any():
            self.notes.append(f"the image is {width}x{height}: too thin for a feature to keep a shape "
                              f"(under {MIN_FEATURE_SIDE} px); the mask is ignored")
            self.mask = np.zeros((height, width), bool)
        self.feature_weight, self.decay = float(feature_weight), float(decay)
        self.formulation = formulation
        self.injective = injective
        self.boundary = boundary
        self.scale_prior = float(scale_prior)
        self.cell = cell
        self.max_nodes = max_nodes
        #: The cell is automatic though set (animate's one grid for every frame): not "given".
        self.cell_chosen_automatically = False
        self.grow_past_edge = bool(grow_past_edge)
        self.factorizations = 0
        self.timings: dict[str, float] = {}
        self._states: dict[tuple, _GridState] = {}
        self._decided = None            # the last solve's tie decisions, which a drag's update keeps

    def _state(self, grid: Grid, warped: np.ndarray, boundary: str) -> _GridState:
        """Features and border conditions on ``grid`` (built once per grid and border);
        ``warped``: W at the grid's nodes."""
        sides = (False,) * 4
        if boundary == "slide":
            sides = system.sliding_sides(grid, warped)
        key = ((grid.nx, grid.ny), sides)
        if key not in self._states:
            features = feat.analyse(self.mask, grid, self.feature_weight, self.decay)
            fixed_x, fixed_y = system.border_conditions(grid, sides)
            tri_component = np.tile(np.where(features.is_feature, features.component, -1), 2)
            nodes, node_component = grid.nodes(), system.feature_nodes(grid, features)
            self._states[key] = _GridState(grid, nodes, grid.triangles(), fixed_x, fixed_y, features,
                                           node_component, tri_component,
                                           system.node_stiffness(grid, features.weight),
                                           node_middle=plain_bound.middle_nodes(nodes, node_component,
                                                                          features.n_components))
        return self._states[key]

    def _systems(self, state: _GridState, ties: components.Ties, border=None):
        """The factored :class:`solver.AxisSystems` for these ties (cached per numbering);
        ``border``: (fixed_x, fixed_y) in place of the grid's border conditions.

        SciPy and scikit-sparse are imported here, by warps that factor (not by plain mode)."""
        from .solver import AxisSystems

        if state.normal is None:
            state.normal = system.normal_matrix(state.grid, state.features.weight)
        memo = ties.key() + (b"" if border is None else np.packbits(border).tobytes())
        if memo in state.systems_by_ties:
            return state.systems_by_ties[memo]
        unknowns = [system.number_unknowns(fixed | ties.held(axis), ties.unknown_ties(axis))
                    for axis, fixed in enumerate(ties.border_fixed(*(border or (state.fixed_x, state.fixed_y))))]
        key = b"".join(u.astype(np.int32).tobytes() for u in unknowns)
        if key not in state.systems:
            t0 = time.perf_counter()
            with stages.within("factor", {"grid": "solve"}):
                state.systems[key] = AxisSystems(state.normal, *unknowns)
            self.factorizations += state.systems[key].factorizations
            self.timings["factor"] = self.timings.get("factor", 0.0) + time.perf_counter() - t0
        state.systems_by_ties[memo] = state.systems[key]
        return state.systems[key]

    def _releases(self, warp) -> bool:
        """Whether a feature cut by a border no similarity of it can follow lets go of it: ``boundary=
        'release'``, or by default where the warp asks (``cut_features='keep'``: the handles' map)."""
        if self.boundary is not None:
            return self.boundary == "release"
        return getattr(warp, "cut_features", "give") == "keep"

    def _offsets(self, state: _GridState, ties: components.Ties, ab: np.ndarray, warped: np.ndarray,
                 border=None, pins=None):
        """q: fixed coordinates at W, tied nodes at their component's similarity (``border``:
        (fixed_x, fixed_y) in place of the grid's; ``pins``: where pinned nodes go, W's default)."""
        offset = np.zeros_like(warped)
        fixed_x, fixed_y = ties.border_fixed(*(border or (state.fixed_x, state.fixed_y)))
        offset[fixed_x, 0] = warped[fixed_x, 0]
        offset[fixed_y, 1] = warped[fixed_y, 1]
        placed = components.placement(ties, state.nodes, warped if pins is None else pins, ab)
        on = ties.placed(0)
        for axis, fixed in enumerate((fixed_x, fixed_y)):
            free = on & ~fixed                          # border coordinates stay exactly at W
            offset[free, axis] = placed[free, axis]
        return offset

    def solve(self, warp, mode: str = MODE, quick: bool = False, drag: bool = False,
              keep_ties: bool | None = None) -> Mesh:
        """Feature-aware mesh for ``warp`` (a :class:`featurewarp_cli.plugins.Warp` instance).

        The least-squares solution is returned when it has no fold-over. When it
        has, the guard (:mod:`featurewarp_cli.engine.guard`) opens the folds near
        the optimum and, where that fails, relaxes the features around them
        towards the warp, as little as injectivity allows; the result never folds.

        Parameters
        ----------
        warp : callable
            Maps (N, 2) source positions to (N, 2) canvas positions; has
            ``width``, ``height`` and ``canvas``.
        mode : {'similarity', 'rigid', 'plain'}
            similarity: features rotate and scale uniformly; rigid: they keep
            their size; plain: the warp itself, mask ignored.
        quick : bool
            For interactive updates: the given or base cell, the least-squares similarities
            without the scale search's safeguards, the guard only where the result folds
            and as a preview (its window only; where it fails the features are eased as for
            ``drag``, with a warning), and only the per-component quality figures.
        drag : bool
            With ``quick``, an update while a handle is dragged: a least-squares solution
            that folds is not guarded; around its folds the nodes stop at :data:`DRAG_STEP`
            of the way from W (injective) to where the first triangle would degenerate
            (``record.guard.drag_step``) and go all the way :data:`DRAG_REACH` cells further
            out (:func:`injectivity.eased`): no untangling. The release is a quick solve.
        keep_ties : bool, optional
            With ``quick``: the features' tie decisions (pinned to the border, let go of it,
            or untied: :func:`components.parametrize`) are the last solve's, not decided
            anew from W, so nothing is factored anew (the editor keeps them per handle set).
            Default: as ``drag``.

        Returns
        -------
        Mesh
            Its ``record`` says what was done and what could not be.
        """
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
        arrays.check_warp(warp, self.width, self.height)
        self.timings = {}
        stages.enter("grid")
        t0 = time.perf_counter()
        warp, lattice = CheckedWarp(warp), getattr(warp, "lattice", None)   # lattice: W linear on its triangles
        if quick:
            cell, error = (self.cell or fidelity.auto_cell(self.width, self.height, None)[0]), float("nan")
        elif self.cell is None:
            cell, error = fidelity.auto_cell(self.width, self.height, warp)
            fidelity.check_budget(self.width, self.height, cell, self.max_nodes, lattice)
        else:
            cell, error = float(self.cell), None
        grid = grid_for(self.width, self.height, cell, lattice)
        if error is None:
            error = fidelity.pl_error(grid, warp)
        boundary = self.boundary if self.boundary in ("fixed", "slide") else getattr(warp, "boundary", "fixed")
        warped = warp(grid.nodes())
        state = self._state(grid, warped, boundary)
        self.timings["grid"] = time.perf_counter() - t0
        produced = "plain" if state.features.n_components == 0 else mode      # what the output is
        record = SolveRecord(produced, self.formulation, _border_used(self.boundary, boundary, state),
                             {"cell": max(grid.spacing) if lattice else cell, "spacing": list(grid.spacing),
                              "nodes": grid.n_nodes, "quads": int(state.features.weight.size), "pl_error_px": error})
        tied = unpinned = np.zeros(state.features.n_components, bool)
        if mode == "plain" or state.features.n_components == 0:
            target = warped
            record.guard.flipped_before = int(np.count_nonzero(signed_areas(target, state.triangles) <= 0))
        else:
            keep = quick and bool(drag if keep_ties is None else keep_ties)
            target, tied, unpinned = self._feature_aware(state, warped, mode, record, quick, self._releases(warp),
                                                         drag and quick, keep)
        t1 = time.perf_counter()
        assess(state, target, warped, tied, unpinned, warp, record, self.notes, quick,
               self.cell is not None and not self.cell_chosen_automatically)
        self.timings["quality"] = time.perf_counter() - t1
        record.timings = dict(self.timings)
        return Mesh(state.nodes.copy(), target, state.triangles.copy(), tuple(warp.canvas), record, state.node_component)

    def _feature_aware(self, state: _GridState, warped: np.ndarray, mode: str, record: SolveRecord,
                       quick: bool = False, unpin: bool = False, drag: bool = False, keep_ties: bool = False):
        """Solve for the features' similarities and the nodes, then guard against folds.

        Returns the node positions, which components stayed tied, and which of those were
        let go of their border conditions."""
        features, grid = state.features, state.grid
        jac = targets.quad_jacobians(grid, warped)
        quad_maps, prior_maps = targets.quad_targets(jac, features, mode, self.formulation)
        prior = components.as_ab(prior_maps)
        key = (grid.n_nodes, features.n_components, mode, unpin, state.fixed_x.tobytes(), state.fixed_y.tobytes())
        decided = self._decided[1] if keep_ties and self._decided is not None and self._decided[0] == key else None
        ties = components.parametrize(state.nodes, state.fixed_x, state.fixed_y, warped, state.node_component,
                                      features.n_components, prior, solve_scale=mode == "similarity",
                                      unpin=unpin, decided=decided)
        self._decided = (key, ties.decisions())
        if self.formulation == "paper":
            ties.tied[:] = False
        ab = np.where(ties.tied[:, None], ties.base, prior)
        systems = self._systems(state, ties)
        record.solver = systems.method
        warp_edges = system.warp_edge_vectors(grid, warped)
        index = np.maximum(features.component, 0)

        def constants(ab, ties, edges=None, border=None, pins=None):
            if edges is None:
                maps = quad_maps if self.formulation == "paper" else components.as_maps(ab)[index]
                edges = np.where(features.is_constrained[:, None, None], system.edge_vectors(grid, maps), warp_edges)
            t0 = time.perf_counter()
            rhs = system.right_hand_side(grid, features.weight, edges)
            offset = self._offsets(state, ties, ab, warped, border, pins)
            self.timings["rhs"] = self.timings.get("rhs", 0.0) + time.perf_counter() - t0
            return edges, rhs, offset

        attempt = attempts.Attempt(self, state, constants, ties, warp_edges=warp_edges)
        ab, solved, scale_solver = self._similarities(state, ties, systems, attempt.solve, ab, attempt.solve(ab),
                                                      prior, warped, quick)
        x, edges = solved[:2]
        if edges is None:                       # quick: moved without a solve, and no fold
            return x, ties.tied, ties.unpinned & ties.tied
        if not self.injective or (quick and np.all(signed_areas(x, state.triangles) > 0)):
            return x, ties.tied, ties.unpinned & ties.tied
        def ease(x):                            # a drag's update, or a preview its guard's window left folded
            return injectivity.eased(grid, warped, x, state.triangles, DRAG_STEP, DRAG_REACH)

        if drag and np.all(signed_areas(warped, state.triangles) > 0):
            record.guard.flipped_before = int(np.count_nonzero(signed_areas(x, state.triangles) <= 0))
            x, record.guard.drag_step = ease(x)
            return x, ties.tied, ties.unpinned & ties.tied
        attempt.ab, attempt.solved = ab, solved

        def low():                              # the similarities the features shrink towards
            return np.where(ties.tied[:, None], ties.project(prior * _smallest_scale(jac, features, prior)), prior)

        # A preview's guard eases only where W is injective: it leaves a folding W's solution as it is.
        result = attempts.guarded(self, state, warped, record, attempt, scale_solver, low, ease if quick else None)
        if self.grow_past_edge:
            result = attempts.grown(self, state, warped, record, attempt, result, mode)
        return result

    def _similarities(self, state: _GridState, ties, systems, solve, ab, solved, prior, warped, quick):
        """The features' scales and rotations where they are unknowns (similarity mode): the
        least-squares optimum under the prior, kept within what the scale search allows (not
        when ``quick``: then the optimum, reached without a solve when that does not fold).

        Returns (ab, (x, edges, rhs, offset), scale_solver); edges is None when the nodes were
        moved without a solve."""
        scale_solver = self._scale_solver(state, ties, systems)
        if scale_solver is None or not scale_solver.n_columns:
            return ab, solved, scale_solver
        x, edges, rhs, _ = solved
        features = state.features
        gradient = scale_solver.gradient(x, rhs, edges, features, state.grid.spacing)
        weights = components.prior_weights(features, state.grid.spacing, self.scale_prior)
        optimum = np.where(ties.tied[:, None], scale_solver.solve(ties.base, gradient, prior, weights), prior)
        if quick:
            moved = scale_solver.moved(x)
            if moved is not None and np.all(signed_areas(moved, state.triangles) > 0):
                return optimum, (moved, None, None, None), scale_solver
            return optimum, solve(optimum), scale_solver
        start = np.where(ties.tied[:, None], ties.project(prior), prior)
        ab, solved = scale_search.fitting_scales(solve, start, optimum, state.triangles, warped)
        ab, solved = scale_search.spread_stretch(solve, ab, solved, ties.tied, state.triangles, warped,
                                                 state.tri_component < 0)
        return ab, solved, scale_solver

    def _scale_solver(self, state: _GridState, ties: components.Ties, systems):
        """The cached :class:`components.ScaleSolver` for these ties (None without free scales)."""
        if not ties.columns()[0].size:
            return None
        key = ties.key()
        if key not in state.scale_solvers:
            t0 = time.perf_counter()
            state.scale_solvers[key] = components.ScaleSolver(ties, state.grid, state.features, state.normal,
                                                              systems)
            self.timings["scale_setup"] = time.perf_counter() - t0
        return state.scale_solvers[key]

    def render(self, image: np.ndarray, mesh: Mesh, interp: str = INTERPOLATION, background=None,
               antialias: bool = True, order: str = "rgb") -> np.ndarray:
        """Resample ``image`` through ``mesh``; see :func:`featurewarp_cli.render.raster.render`.

        Parameters
        ----------
        image : (h, w) or (h, w, C) ndarray
            Grey, grey + alpha, RGB or RGBA (:mod:`featurewarp_cli.engine.arrays` has the
            rules): uint8, uint16, bool, integers, or floats in [0, 1]; returned in the same
            dtype, grey staying grey.
        mesh : Mesh
        interp : {'nearest', 'linear', 'cubic', 'lanczos'}
            'nearest' copies source values only (label maps, pixel art), so it also turns ``antialias`` off.
        background : (r, g, b) of 0..255, colour text, or None
            Fill where no source pixel lands; None: transparent (alpha added where needed).
        antialias : bool
            Prefilter regions the warp shrinks and give the mesh's silhouette partial
            coverage (alpha, or a blend with ``background``).
        order : {'rgb', 'bgr'}
            The image's channel order: 'rgb' for the API; 'bgr' (uint8 or uint16 only) for
            images as OpenCV reads them, which the command line uses.
        """
        from ..render import raster

        arrays.check_cell_and_flags(None, antialias=antialias)
        image = arrays.as_array(image, "image") if order == "rgb" else image       # a list, a PIL image
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, warper is for {self.width}x{self.height}")
        mesh.check_image(self.width, self.height)
        stages.enter("render")
        t0 = time.perf_counter()
        if order not in ("rgb", "bgr"):
            raise ValueError(f"order must be 'rgb' or 'bgr', not {order!r}")
        channels, text = 1 if image.ndim == 2 else image.shape[2], isinstance(background, str)
        samples, fill, dtype = arrays.prepare(image, background) if order == "rgb" else (
            image, arrays.background_rgb(background) if text else background, None)
        out = raster.render(samples, mesh.source, mesh.target, mesh.triangles, mesh.canvas, interp, fill,
                            antialias=antialias and interp != "nearest")       # nearest: source values only
        if mesh.record is not None:
            mesh.record.timings["render"] = time.perf_counter() - t0
        return arrays.finish(out, channels, dtype, image.ndim == 3) if order == "rgb" else out


def _border_used(asked: str | None, boundary: str, state: _GridState) -> str:
    """The border conditions a solve used (the report's ``boundary``): ``release`` when ``asked``; ``slide``
    where a side W keeps straight let its nodes slide, else ``fixed`` (a swirl holds every border node)."""
    if asked == "release":
        return "release"
    held = state.fixed_x & state.fixed_y
    return "fixed" if boundary == "slide" and held.sum() == state.grid.boundary().sum() else boundary


def _smallest_scale(jac: np.ndarray, features, prior: np.ndarray) -> np.ndarray:
    """Per component, the factor from the prior's scale down to the warp's smallest principal
    scale over it (the paper's lambda), at which a feature fits wherever W fits it: (C, 1)."""
    size = np.maximum(np.hypot(prior[:, 0], prior[:, 1]), 1e-12)
    return (np.minimum(targets.paper_scales(jac, features), size) / size)[:, None]

