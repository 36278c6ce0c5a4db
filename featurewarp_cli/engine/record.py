"""The facts of one solve, as a typed record (JSON-ready through :meth:`SolveRecord.to_dict`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

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
        anisotropy_worst <= :data:`KEPT`.
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


#: Largest anisotropy - 1 of a component's triangles for it to count as kept.
KEPT = 0.02
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
        Largest ratio, over background triangles, of a triangle's area on the
        canvas to its area under W (1: the background follows W; large: streaks).
    warnings : list of str
        What the caller should be told: features not kept, features relaxed,
        an output that equals the input.
    timings : dict
        Seconds per stage.
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
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    @property
    def features_kept(self) -> bool:
        """Every component kept its shape."""
        return all(c.kept for c in self.components)

    @property
    def flipped_triangles(self) -> int:
        return int(self.quality.get("flipped_triangles", 0))

    def to_dict(self) -> dict:
        """The record as plain JSON-ready data (the report's and ``Mesh.info``'s view)."""
        guard = self.guard
        return {
            "mode": self.mode, "formulation": self.formulation, "boundary": self.boundary,
            "grid": dict(self.grid), "solver": self.solver,
            "components": [asdict(c) for c in self.components],
            "features_kept": self.features_kept,
            "background_stretch": self.background_stretch,
            "flipped_before_guard": guard.flipped_before,
            "untangle_iterations": guard.untangle_iterations,
            "untangle_window_quads": guard.window_quads,
            "release_rounds": guard.release_rounds,
            "released_components": list(guard.released_components),
            "feature_blend": guard.feature_blend,
            "fallback": guard.fallback,
            "plain_blend": guard.plain_blend,
            "degraded_components": list(guard.degraded_components),
            "quality": self.quality,
            "flipped_triangles": self.flipped_triangles,
            "warnings": list(self.warnings),
            "timings": dict(self.timings),
        }


def warnings_for(record: "SolveRecord", source, target, warped, warp) -> list[str]:
    """One line per thing the caller should know: features not kept or relaxed, a no-op."""
    lines = []
    if record.guard.plain_blend < 1.0:
        which = record.guard.degraded_components
        lines.append(f"features degraded towards the plain warp ("
                     + (f"components {', '.join(map(str, which))}; " if which else "")
                     + f"blend {record.guard.plain_blend:.2f}) so that none is more distorted than under it")
    if record.guard.release_rounds:
        lines.append(f"features relaxed towards the plain warp to avoid fold-overs "
                     f"(components {', '.join(map(str, record.guard.released_components))}; "
                     f"blend {record.guard.feature_blend:.2f})")
    for k, c in enumerate(record.components):
        if not c.kept:
            lines.append(f"feature {k} ({c.quads} quads) not kept: distortion {c.anisotropy_worst:.3f} "
                         f"(plain warp: {c.plain_anisotropy_worst:.3f})")
    if tuple(warp.canvas) == (warp.width, warp.height):
        wanted = np.hypot(*(warped - source).T)
        moving = wanted > NO_OP_OUTPUT
        if wanted.max(initial=0.0) > NO_OP_WARP:
            moved = float(np.sqrt(np.mean(np.sum((target - source)[moving] ** 2, axis=1))))
            asked = float(np.sqrt(np.mean(wanted[moving] ** 2)))
            if moved <= max(NO_OP_OUTPUT, NO_OP_FRACTION * asked):
                lines.append(f"the mask covers the region the warp moves; the output is the input "
                             f"(where the warp moves pixels by {asked:.0f} px RMS, they move by {moved:.1f} px)")
    return lines
