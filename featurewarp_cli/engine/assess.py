"""Quality figures, per-component records and warnings of a solved mesh."""

from __future__ import annotations

import numpy as np

from . import canvas, fidelity, grow, quality
from .record import ComponentRecord, SolveRecord, is_kept, warnings_for

#: Features (quads holding a mask pixel) covering more than this share of the grid get a warning.
MASK_COVERAGE = 0.9
#: A warp whose nodes all stay within this many pixels of where they were, on the input's own
#: canvas, is said to move nothing (``stretch`` at its 1 x 1 defaults, a swirl centred far off;
#: a mask over all a warp moves is said otherwise, by record.warnings_for).
STILL_PX = 0.01
#: How that warning begins (an animation's frames say it once for all of them).
STILL = "the warp moves no pixel"


def assess(state, target, warped, tied, unpinned, warp, record: SolveRecord, notes: list,
           quick: bool = False, chosen_cell: bool = False) -> None:
    """Fill ``record`` with the quality figures, per-component records and warnings of the mesh
    ``target`` (``state``: the warper's grid state; ``notes``: the warper's own warnings;
    ``quick``: the per-component records and the warnings only; ``chosen_cell``: the grid's
    cell was given, not automatic)."""
    features = state.features
    if not quick:
        transition = np.tile(features.is_constrained & ~features.is_feature, 2)
        record.quality = quality.mesh_quality(
            state.nodes, target, warped, state.triangles, state.grid.quads(), state.node_component,
            features.n_components, ~features.is_constrained, transition)
    figures = quality.component_figures(state.nodes, target, warped, state.triangles, state.tri_component,
                                        state.node_component, features.n_components, plain=not quick)
    strips = ([None] * features.n_components if quick or features.frame_strip is None else
              quality.frame_strip_figures(state.grid, state.nodes, target, state.node_component,
                                          features.n_components, *features.frame_strip))
    counts = np.bincount(features.component[features.is_feature], minlength=features.n_components)
    at = _centres(state.nodes, state.node_component, features.n_components)
    record.components = [
        ComponentRecord(int(counts[c]), bool(tied[c]), bool(unpinned[c]), *(float(figures[k][c]) for k in (
            "scale", "rotation_deg", "distortion", "anisotropy_worst", "anisotropy_mean",
            "plain_distortion", "plain_anisotropy_worst", "area_ratio")),
            kept=is_kept(figures["anisotropy_worst"][c], figures["scale"][c], record.mode), at=at[c],
            frame_strip=strips[c])
        for c in range(features.n_components)]
    if not quick:
        stretch, where = canvas.largest_stretch(target, warped, state.triangles[state.tri_component < 0])
        record.background_stretch, record.background_stretch_at = stretch, where
        grid = state.grid
        record.blank_share, record.plain_blank_share, record.blank_extra_box = canvas.blank_shares(
            target, warped, grid.nx, grid.ny, tuple(warp.canvas))
        past = None
        if record.grown:
            beyond = grow.beyond(target, grid.nx, grid.ny, record.grown["sides"])
            record.grown["past_px"] = {side: float(np.max(np.abs(target[nodes, 1 if side in ("top", "bottom") else 0]
                                                                 - record.grown["sides"][side]), initial=0.0))
                                       for side, nodes in beyond.items()}
            past = np.any(list(beyond.values()), axis=0) if beyond else None
        record.outline_departure, record.outline_departure_at = canvas.outline_departure(
            target, warped, grid.nx, grid.ny, past)
    if record.guard.drag_step < 1.0:        # a drag's update or a preview: solved in full later
        where, later = (("folds the fold guard's window could not open", "Export solves") if record.guard.preview_eased
                        else ("the folds they would make", "the release untangles them where it can and Export "
                              "solves"))
        record.warnings.append(f"{'preview' if record.guard.preview_eased else 'dragging'}: the features are eased to "
                               f"{record.guard.drag_step:.0%} of the way from the handles' map to their shapes around "
                               f"{where}; {later} them in full")
    if record.mode != "plain" and not quick:
        record.warnings.extend(warnings_for(record, state.nodes, target, warped, warp, state.node_component >= 0))
        if not record.guard.converged:       # fold-free all the same, but not the energy's minimum
            record.warnings.append(f"the fold guard stopped before its energy converged ({record.guard.newton_steps} "
                                   f"Newton steps): the result folds nothing but is not that energy's minimum, so "
                                   f"another machine may give a different one")
        coverage = float(np.mean(features.is_feature))
        if coverage > MASK_COVERAGE:
            causes = "the mask inverted, or a JPEG whose noise crosses the threshold"
            record.warnings.append(f"the mask's features cover {100 * coverage:.0f} % of the grid: little background "
                                   f"is left to take the warp (is {causes}" + (
                                       f", or --cell {record.grid['cell']:.6g} too coarse for the mask's "
                                       f"features?)" if chosen_cell else "?)"))
    error = record.grid.get("pl_error_px", 0.0)
    if not quick and tuple(warp.canvas) == (state.grid.width, state.grid.height) and \
            np.max(np.abs(warped - state.nodes), initial=0.0) <= STILL_PX:     # W at the nodes (a covering mask: above)
        # The output is the input all the same; where the grid strays from W, the grid is why (a
        # swirl under a one-quad --cell leaves its corners in place and moves pixels by 55 px).
        coarse = error > STILL_PX
        where, cause = ((" at the grid's nodes", f"the grid is too coarse to follow the warp, which moves pixels by up "
                         f"to {error:.1f} px between them") if coarse else
                        ("", "options at their identity, a centre far off the image, or handles that stay put?"))
        record.warnings.append(f"{STILL} by more than {STILL_PX:g} px{where}: the output is the input ({cause})")
    if not quick and error > fidelity.MAX_PL_ERROR:          # NaN (a preview's grid) is not above
        chosen = "the given cell's grid" if chosen_cell else "the finest automatic grid (800 000 nodes at most)"
        record.warnings.append(f"{chosen} (cell {record.grid['cell']:.4g} px) strays up to {error:.1f} px from "
                               f"the warp: the output follows the warp only that closely"
                               + ("; a finer --cell, or the automatic grid (within 0.5 px), follows it more "
                                  "closely" if chosen_cell else ""))
    record.warnings.extend(notes)


def _centres(nodes: np.ndarray, node_component: np.ndarray, count: int) -> list:
    """[x, y] per component: the mean source position of its nodes (0.1 px), None without any."""
    on = node_component >= 0
    weights = np.bincount(node_component[on], minlength=count).astype(np.float64)
    sums = [np.bincount(node_component[on], nodes[on, axis], minlength=count) for axis in range(2)]
    return [[round(float(sums[0][c] / weights[c]), 1), round(float(sums[1][c] / weights[c]), 1)]
            if weights[c] else None for c in range(count)]
