"""The facts of one solve, as a typed record (JSON-ready through :meth:`SolveRecord.to_dict`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from . import guard as fold_guard
from .guard import GuardRecord


@dataclass
class ComponentRecord:
    """How one feature component came out (measured on the solved mesh).

    Attributes
    ----------
    quads : int
        Its feature quads.
    tied : bool
        Moved as one similarity (False: soft constraints only: held by pins that no
        similarity satisfies under an explicit ``--boundary fixed``, or released by the
        fold-over guard).
    unpinned : bool
        Cut by a border whose pins no similarity satisfies (an arc's curved sides): let go
        of them to keep its shape, so its cut edge leaves W's outline a little.
    scale, rotation_deg : float
        Of the affine map that best fits its nodes, source -> canvas.
    distortion : float
        sigma_max / sigma_min - 1 of that affine fit (what keypoints matched inside
        the region in the input and output images measure).
    anisotropy_worst, anisotropy_mean : float
        sigma_max / sigma_min - 1 of its triangles' maps: the worst and the mean.
    plain_anisotropy_worst, plain_distortion : float
        The same figures under the plain warp W, for comparison.
    area_ratio : float
        Its area on the canvas over its area in the source.
    kept : bool
        anisotropy_worst <= :data:`KEPT`, and in the rigid mode its scale within KEPT of 1 (its
        size is what rigid asks for: a rigid shrink to half, which no feature can follow at
        full size, gave them all W's 0.5 and read kept, with no warning).
    at : list of float or None
        Where it is in the input: the mean of its nodes' source positions, [x, y] in pixels
        (what a warning names it by, beside its number).
    frame_strip : dict or None
        Where its mask stops within a cell of the frame: its pixels in those outer cells, which
        the frame holds, follow the background
        (:func:`featurewarp_cli.engine.quality.frame_strip_figures`: ``sides``, ``pixels``,
        ``off_px``, ``cell_px``); beyond :data:`STRIP_PX` a warning says so (a rectangle 1 px
        short of the right edge, turned 6 degrees, kept that side straight down the frame).
    """

    quads: int
    tied: bool
    unpinned: bool
    scale: float
    rotation_deg: float
    distortion: float
    anisotropy_worst: float
    anisotropy_mean: float
    plain_distortion: float
    plain_anisotropy_worst: float
    area_ratio: float
    kept: bool
    at: list | None = None
    frame_strip: dict | None = None


#: Largest anisotropy - 1 of a component's triangles for it to count as kept (and, in the
#: rigid mode, the largest departure of its scale from 1).
KEPT = 0.02


def is_kept(anisotropy_worst: float, scale: float, mode: str) -> bool:
    """Whether a component with these figures kept what ``mode`` asks of it (:data:`KEPT`)."""
    return bool(anisotropy_worst <= KEPT and (mode != "rigid" or abs(scale - 1.0) <= KEPT))
#: A feature's pixels in the frame's outer cells (its mask stops short of the frame) ending
#: farther than this (px) from where its shape would put them get a warning.
STRIP_PX = 1.0
#: Background stretched beyond W by more than this (largest singular value) is said: from
#: about 8x, stars become needles and fine texture streaks (README: Limits, with pictures).
STREAKS = 8.0
#: Blank canvas beyond the plain warp's by more than this share of the canvas is said.
BLANK = 0.005
#: An outline leaving the plain warp's by more than this many pixels is said.
OUTLINE_PX = 1.0
#: Where W moves pixels by more than NO_OP_WARP px, an output that moves the nodes W moves
#: (by more than NO_OP_OUTPUT px) by at most NO_OP_OUTPUT px RMS, or by at most NO_OP_FRACTION
#: of W's RMS displacement there, is reported as "the output is the input" (a swirl whose
#: disc a frame-filling feature pins).
NO_OP_OUTPUT = 1.0
NO_OP_WARP = 5.0
NO_OP_FRACTION = 0.1


@dataclass
class SolveRecord:
    """What a :meth:`FeatureWarper.solve` did.

    Attributes
    ----------
    mode, formulation, boundary : str
    grid : dict
        ``cell``, ``spacing``, ``nodes``, ``quads``, ``pl_error_px``.
    solver : str
        'cholmod', 'scipy-splu' or 'none' (nothing factored: plain mode, no features).
    components : list of ComponentRecord
    guard : GuardRecord
    quality : dict
        Mesh-wide figures (:func:`quality.mesh_quality`).
    background_stretch : float
        Largest stretch, over background triangles, beyond W: the largest singular value
        of the affine map from a triangle's image under W to its image in the result (1:
        the background follows W; 8 and more: stars become needles, texture streaks).
    background_stretch_at : tuple of 2 floats or None
        Canvas position of that triangle.
    blank_share, plain_blank_share : float
        Shares of the canvas no source pixel lands on, in the result and under W.
    blank_extra_box : tuple of 4 ints or None
        ``(x0, y0, x1, y1)`` around the pixels W fills and the result leaves blank.
    outline_departure : float
        Largest distance (px) of the result's border from W's outline (0: the canvas is
        the warp's).
    outline_departure_at : tuple of 2 floats or None
        Where.
    warnings : list of str
        What the caller should be told: features not kept, features relaxed,
        an output that equals the input.
    timings : dict
        Seconds per stage.
    grown : dict or None
        ``--grow-past-edge``: ``k`` (how many times the features grew), ``components``
        (which), ``sides`` and ``past_px``; or, when it was due (the background streaked)
        but nothing grew, ``k`` 1 and ``declined`` (why). None: the option was off or not due.
    output_is_input : bool
        The mask covers what the warp moves: the output is the input (a warning says so).
    """

    mode: str
    formulation: str
    boundary: str
    grid: dict
    solver: str = "none"
    components: list = field(default_factory=list)
    guard: GuardRecord = field(default_factory=GuardRecord)
    quality: dict = field(default_factory=dict)
    background_stretch: float = 1.0
    background_stretch_at: tuple | None = None
    blank_share: float = 0.0
    plain_blank_share: float = 0.0
    blank_extra_box: tuple | None = None
    outline_departure: float = 0.0
    outline_departure_at: tuple | None = None
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    grown: dict | None = None
    output_is_input: bool = False

    @property
    def features_kept(self) -> bool | None:
        """Every component kept its shape (in the rigid mode, its size too: :func:`is_kept`); None
        where the result is the plain warp (the plain mode, or no feature in the mask): no shape
        was kept, nor asked to be."""
        return None if self.mode == "plain" else all(c.kept for c in self.components)

    @property
    def no_effect(self) -> bool:
        """The output is the input: the mask covers what the warp moves, or the warp moves no
        pixel (the two warnings that say so); ``features_kept`` is true of such a run."""
        from .assess import STILL

        return self.output_is_input or any(line.startswith(STILL) for line in self.warnings)

    @property
    def flipped_triangles(self) -> int:
        return int(self.quality.get("flipped_triangles", 0))

    def to_dict(self) -> dict:
        """The record as plain JSON-ready data (the report's and ``Mesh.info``'s view)."""
        guard = self.guard
        return {
            "mode": self.mode, "formulation": self.formulation, "boundary": self.boundary,
            "grid": {key: None if isinstance(value, float) and value != value else value      # NaN: not measured
                     for key, value in self.grid.items()}, "solver": self.solver,
            "components": [asdict(c) for c in self.components],
            "features_kept": self.features_kept,
            "no_effect": self.no_effect,
            "background_stretch": self.background_stretch,
            "background_stretch_at": _rounded(self.background_stretch_at),
            "blank_share": self.blank_share,
            "plain_blank_share": self.plain_blank_share,
            "blank_extra_box": None if self.blank_extra_box is None else list(self.blank_extra_box),
            "outline_departure": self.outline_departure,
            "outline_departure_at": _rounded(self.outline_departure_at),
            "grown": self.grown,
            "flipped_before_guard": guard.flipped_before,
            "untangle_iterations": guard.untangle_iterations,
            "untangle_window_quads": guard.window_quads,
            "path_steps": guard.path_steps,
            "release_rounds": guard.release_rounds,
            "released_components": list(guard.released_components),
            "feature_blend": guard.feature_blend,
            "release_cut": guard.release_cut,
            "fallback": guard.fallback,
            "plain_blend": guard.plain_blend,
            "degraded_components": list(guard.degraded_components),
            "newton_steps": guard.newton_steps,
            "barrier_converged": guard.converged,
            "quality": self.quality,
            "flipped_triangles": self.flipped_triangles,
            "warnings": list(self.warnings),
            "timings": dict(self.timings),
        }


def _rounded(point) -> list | None:
    return None if point is None else [round(float(v), 1) for v in point]


def canvas_warnings(record: "SolveRecord") -> list[str]:
    """One line per compromise the canvas shows: streaks, blank canvas, --grow-past-edge that grew
    nothing, the outline let go."""
    lines = []
    if record.background_stretch > STREAKS:
        x, y = record.background_stretch_at
        lines.append(f"background stretched {record.background_stretch:.1f}x beyond the plain warp near "
                     f"({x:.0f}, {y:.0f}) of the output: texture there turns into streaks")
    if record.blank_share > record.plain_blank_share + BLANK:
        x0, y0, x1, y1 = record.blank_extra_box
        lines.append(f"{100 * record.blank_share:.1f} % of the output is blank where the plain warp leaves "
                     f"{100 * record.plain_blank_share:.1f} % (between ({x0}, {y0}) and ({x1}, {y1})): "
                     f"the features' shapes pull the image off the canvas there")
    if record.grown and record.grown.get("declined"):
        lines.append(f"--grow-past-edge grew nothing: {record.grown['declined']}")
    if record.outline_departure > OUTLINE_PX:
        x, y = record.outline_departure_at
        lines.append(f"the output's outline leaves the plain warp's by up to {record.outline_departure:.0f} px "
                     f"near ({round(x)}, {round(y)}): a feature cut by the border let go of it to keep its shape")
    return lines


def grown_note(grown: dict | None) -> str | None:
    """The line that says where ``--grow-past-edge`` grew the features past the frame and how far
    the image runs past each edge, cropped there (``record.grown``; None where nothing runs past
    by more than :data:`OUTLINE_PX`). A note, not a warning: the crop is what the option asks for,
    and ``--strict`` passes it; the report's ``grown.past_px`` has the figures."""
    cropped = {side: px for side, px in ((grown or {}).get("past_px") or {}).items() if px > OUTLINE_PX}
    if not cropped:
        return None
    runs = " and ".join(f"the {side} edge by {px:.0f} px" for side, px in cropped.items())
    return (f"--grow-past-edge grew the features cut by the frame {grown['k']:.2f}x: the image runs past {runs}, "
            f"cropped there")


#: Components a warning names one by one at most; the rest are counted (a noisy mask of
#: 10 000 specks printed 4 000 lines).
MOST_LISTED = 10


def _listed(ids) -> str:
    """``1, 5, 9`` or ``1, 5, 9, ... and 4585 more``."""
    ids = list(ids)
    shown = ", ".join(map(str, ids[:MOST_LISTED]))
    return shown if len(ids) <= MOST_LISTED else f"{shown} and {len(ids) - MOST_LISTED} more"


def _why(record: "SolveRecord", k: int) -> str:
    """What made feature ``k`` give way, for its "not kept" line ('' when nothing did)."""
    guard, c = record.guard, record.components[k]
    causes = []
    if not c.tied and k not in guard.released_components and record.formulation == "exact":
        causes.append("cut by a border that no similarity of it can follow, it gives way so that the outline "
                      "stays the warp's (--boundary release keeps its shape instead where that folds nothing)")
    if k in guard.released_components:
        causes.append("relaxed to avoid fold-overs: untied, it keeps its own shape only as far as the background "
                      "can thin" if guard.feature_blend >= 1.0 else
                      f"relaxed to avoid fold-overs: untied, its targets {guard.feature_blend:.2f} of the way from the "
                      f"plain warp's shape to its own, " + (
                          f"where the blend's next step did not converge in {fold_guard.TRIAL_STEPS} Newton steps"
                          if guard.release_cut else
                          "where the background could thin no further or it would end worse than the plain warp"))
    if k in guard.degraded_components:
        causes.append(f"moved towards the plain warp (blend {guard.plain_blend:.2f}, 0 = the plain warp) to be "
                      f"no more distorted than under it")
    return "".join(": " + cause if i == 0 else "; " + cause for i, cause in enumerate(causes))


def _around(component: ComponentRecord) -> str:
    """", around (x, y)": where a component is in the input, for a warning (none unknown)."""
    return "" if component.at is None else f", around ({round(component.at[0])}, {round(component.at[1])})"


#: How the count of smaller features not kept points at the report (commands without one drop it).
LISTED_IN_REPORT = "; the report lists each"


def _held_still(record: "SolveRecord", moving, on_feature) -> str:
    """Why the output is the input though the warp moves pixels: the mask covers most of what it
    moves, or else the features, kept (in the rigid mode at their size), hold the rest still (a
    disc a fifth of a bulge's area, held at scale 1 where the bulge grows it by 1.07)."""
    if on_feature is None or np.mean(on_feature[moving]) >= 0.5:
        return "the mask covers the region the warp moves"
    if record.mode == "rigid":
        return ("the rigid mode holds the features at their size where the warp would scale them, and so holds "
                "still the region around them that the warp moves (--mode similarity lets them scale)")
    return "the features, kept at their shape, hold still the region around them that the warp moves"


def warnings_for(record: "SolveRecord", source, target, warped, warp, on_feature=None) -> list[str]:
    """One line per compromise the output shows: each feature not kept with its figure and
    why it gave way (the :data:`MOST_LISTED` largest one by one, the others in one line),
    every feature moved towards the plain warp, a feature's pixels by the frame that follow the
    background, the canvas's compromises, a no-op. A feature that gave way but still keeps its
    shape (within :data:`KEPT`; in the rigid mode, its size too) shows nothing: the report
    records it. ``on_feature``: the nodes of feature quads, for the no-op's cause."""
    lines = []
    if record.guard.plain_blend < 1.0 and not record.guard.degraded_components:
        lines.append(f"every feature moved evenly towards the plain warp (blend {record.guard.plain_blend:.2f}, "
                     f"0 = the plain warp) so that none is more distorted than under it")
    lost = sorted((k for k, c in enumerate(record.components) if not c.kept),
                  key=lambda k: -record.components[k].quads)
    for k in sorted(lost[:MOST_LISTED]):
        c = record.components[k]
        figure = (f"worst-triangle anisotropy {c.anisotropy_worst:.3f} (plain warp: {c.plain_anisotropy_worst:.3f})"
                  if c.anisotropy_worst > KEPT else f"scale {c.scale:.3f} where the rigid mode keeps 1")
        lines.append(f"feature {k} ({c.quads} quads{_around(c)}) not kept: {figure}" + _why(record, k))
    if len(lost) > MOST_LISTED:
        rest = [record.components[k] for k in lost[MOST_LISTED:]]
        lines.append(f"{len(rest)} smaller features not kept either ({min(c.quads for c in rest)} to "
                     f"{max(c.quads for c in rest)} quads{LISTED_IN_REPORT})")
    for k, c in enumerate(record.components):
        strip = c.frame_strip
        if strip and strip["off_px"] > STRIP_PX and c.kept:     # not kept: said above (and off its own fit)
            sides = " and ".join(strip["sides"]) + (" edges" if len(strip["sides"]) > 1 else " edge")
            lines.append(f"feature {k} ({c.quads} quads{_around(c)}): its mask stops just short of the {sides}; its "
                         f"{strip['pixels']} pixels in the frame's outer cells there follow the background, up to "
                         f"{strip['off_px']:.1f} px from its shape (--cell {strip['cell_px']:g} or finer may take "
                         f"them into it)")
    lines.extend(canvas_warnings(record))
    if tuple(warp.canvas) == (warp.width, warp.height):
        wanted = np.hypot(*(warped - source).T)
        moving = wanted > NO_OP_OUTPUT
        if wanted.max(initial=0.0) > NO_OP_WARP:
            moved = float(np.sqrt(np.mean(np.sum((target - source)[moving] ** 2, axis=1))))
            asked = float(np.sqrt(np.mean(wanted[moving] ** 2)))
            if moved <= max(NO_OP_OUTPUT, NO_OP_FRACTION * asked):
                record.output_is_input = True
                lines.append(_held_still(record, moving, on_feature) + f"; the output is the input (where the warp "
                             f"moves pixels by {asked:.0f} px RMS, they move by {moved:.1f} px)")
    return lines
