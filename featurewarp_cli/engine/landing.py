"""Handles that land where they were dragged: ``deform``'s rounds of re-aiming the rigid map.

The feature-aware solve follows the rigid map W of the handles only as closely as least
squares beside the features lets it (a background handle at 1 MP ended 14 px short, at 12 MP
42 px; a curve beside the face 8 px). :func:`land` solves again with W re-aimed past each
handle's target by what the last solve left it short (:func:`aim`), up to
:data:`LANDING_ROUNDS` times; :func:`better_round` says whether a round is kept. A point
handle is one target; a curve handle is :data:`handle_review.CURVE_SAMPLES` points evenly
spaced by arc length along it, each re-aimed as a point is (the polyline W is asked to follow
is the curve's own, its vertices and those points moved by their re-aims, interpolated by arc
length between them).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .handle_review import CURVE_SAMPLES, CRUSHED, HANDLE_SLACK_PX
from .handles import along, resample
from .injectivity import border_crossings
from .mesh import Mesh

#: Rounds of re-aiming the point and curve handles (:func:`land`), each one solve, until every
#: handle ends within LANDED_PX of its target; each round takes about three quarters of what
#: is left.
LANDING_ROUNDS = 3
LANDED_PX = 0.005
#: Newton steps of the rigid map a re-aim may take from the last map (a correction takes 1-3); one that
#: needs more is not used (towards a pinned border: 122 steps, 1.8 s, for a round not kept anyway).
AIM_STEPS = 20


def land(warp, mesh: Mesh, solve) -> Mesh:
    """``mesh`` (``solve(warp)``'s), solved again up to :data:`LANDING_ROUNDS` times with the
    handles re-aimed (:func:`aim`) so that they end where they were dragged. A round is kept
    only where :func:`better_round` says so; none runs after a mesh that folds or lays the image
    over itself (it is refused or warned as it is). Whether a round is kept is a discrete
    choice: near its edge one ulp can switch between the two results. Every round's time is in
    the report's stages (the rigid map's under ``grid``, as a preset's map), and a ``fit``
    canvas is the final map's bounding box (:func:`refit`)."""
    if mesh.flips() or border_crossings(mesh.source, mesh.target):
        return mesh                        # a kept round adds neither (:func:`better_round`)
    timings = dict(mesh.record.timings)
    for _ in range(LANDING_ROUNDS):
        before, start = (warp.nodes, warp.aimed, warp.aimed_curves, warp.fitted), time.perf_counter()
        aimed = aim(warp, mesh)
        timings["grid"] = timings.get("grid", 0.0) + time.perf_counter() - start
        if not aimed:
            break
        landed = solve(warp)
        for stage, seconds in landed.record.timings.items():
            timings[stage] = timings.get(stage, 0.0) + seconds
        if not better_round(warp, landed, mesh):
            warp.nodes, warp.aimed, warp.aimed_curves, warp.fitted = before
            break
        mesh = landed
    mesh.record.timings = timings
    return refit(warp, mesh)


def _shares(reach: np.ndarray) -> np.ndarray:
    """How much of its miss a target is re-aimed by, from how far W ends from where it was aimed
    (``reach``): all of it within 1 px, none beyond :data:`HANDLE_SLACK_PX`, in proportion between
    (no threshold for a one-ulp change to cross)."""
    return np.clip((HANDLE_SLACK_PX - reach) / (HANDLE_SLACK_PX - 1.0), 0.0, 1.0)


def curve_targets(warp) -> list[np.ndarray]:
    """Per curve handle, the :data:`CURVE_SAMPLES` points W was last aimed at along it (at first
    its own target's, evenly spaced by arc length)."""
    if warp.aimed_curves is not None:
        return warp.aimed_curves
    return [resample(end, CURVE_SAMPLES) for _, end in warp.handles.curves]


def aim(warp, mesh: Mesh) -> bool:
    """Re-aim ``warp``: each point handle (pins too) and each curve's sample points are aimed
    past their targets by as far as ``mesh`` left them short, scaled by :func:`_shares`; the map
    is solved again for those targets (warm, nothing factored). False, and nothing changed, where
    no target would move by more than :data:`LANDED_PX` or the map would need more than
    :data:`AIM_STEPS` Newton steps."""
    handles = warp.handles
    if warp.rigid_map is None or handles is None or not (len(handles.points_from) or handles.curves):
        return False
    offset = np.asarray(warp.offset)
    sources = [handles.points_from] + [resample(start, CURVE_SAMPLES) for start, _ in handles.curves]
    wanted = [handles.points_to] + [resample(end, CURVE_SAMPLES) for _, end in handles.curves]
    aimed = [handles.points_to if warp.aimed is None else warp.aimed] + curve_targets(warp)
    shares, steps = [], []
    for source, goal, target in zip(sources, wanted, aimed):
        if not len(source):
            shares.append(np.zeros(0))
            steps.append(np.zeros((0, 2)))
            continue
        shares.append(_shares(np.hypot(*(warp(source) + offset - target).T)))
        steps.append(shares[-1][:, None] * (goal - warp.mapped(mesh, source)))
    if max((float(np.hypot(*step.T).max()) for step in steps if len(step)), default=0.0) <= LANDED_PX:
        return False
    moved = [target + step for target, step in zip(aimed, steps)]
    curves = [(start, _reaimed(end, target)) for (start, end), target in zip(handles.curves, moved[1:])]
    last = warp.rigid_map._last
    again = warp.rigid_map.deformation(dataclasses.replace(handles, points_to=moved[0], curves=curves),
                                       warm=True, steps=AIM_STEPS)
    if again.capped:                   # not a correction: W pushed far (into a pinned border, 122 steps)
        warp.rigid_map._last = last
        return False
    warp.aimed, warp.aimed_curves, warp.shares = moved[0], moved[1:], shares
    warp.nodes = again.nodes + np.asarray(again.offset) - offset
    warp.fitted = again.canvas, again.offset
    return True


def _reaimed(line: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """The polyline ``line`` with the re-aims of its :data:`CURVE_SAMPLES` evenly spaced points
    (``samples``, where they are now aimed): those points and ``line``'s own vertices, each
    moved by the re-aim interpolated by arc length, in order along it (its corners stay
    corners)."""
    steps = np.hypot(*np.diff(line, axis=0).T)
    walked = np.concatenate([[0.0], np.cumsum(steps)])
    vertices = walked / walked[-1] if walked[-1] > 0 else np.linspace(0.0, 1.0, len(line))
    evenly = np.linspace(0.0, 1.0, len(samples))
    fractions = np.unique(np.concatenate([vertices, evenly]))          # in order along it
    shift = samples - along(line, evenly)
    return along(line, fractions) + np.stack([np.interp(fractions, evenly, shift[:, axis]) for axis in range(2)],
                                             axis=1)


def better_round(warp, landed: Mesh, mesh: Mesh) -> bool:
    """Whether a re-aimed round ``landed`` is kept over ``mesh`` (:func:`land`): it brings the
    targets it re-aimed closer (the worst of them: one W cannot reach is not re-aimed and does
    not count) and adds no fold, no crossing border, no feature given up, no crease
    (:data:`handle_review.CRUSHED`) and no streaks (record.STREAKS)."""
    from .record import STREAKS

    def kept(m):
        return sum(bool(component.kept) for component in m.record.components)

    def thinnest(m):                     # the smallest share of its area under W a triangle keeps
        return float(m.record.quality.get("area_ratio", {}).get("min", 1.0))

    handles = warp.handles
    sources = [handles.points_from] + [resample(start, CURVE_SAMPLES) for start, _ in handles.curves]
    wanted = [handles.points_to] + [resample(end, CURVE_SAMPLES) for _, end in handles.curves]
    re_aimed = [share > 0 for share in warp.shares]

    def missed(m):
        return max((float(np.hypot(*(warp.mapped(m, source[on]) - goal[on]).T).max())
                    for source, goal, on in zip(sources, wanted, re_aimed) if on.any()), default=0.0)

    worse = [landed.flips() > 0, border_crossings(landed.source, landed.target) > 0, kept(landed) < kept(mesh),
             thinnest(landed) < CRUSHED <= thinnest(mesh),
             landed.record.background_stretch > STREAKS >= mesh.record.background_stretch]
    return not any(worse) and any(on.any() for on in re_aimed) and missed(landed) < missed(mesh)


def refit(warp, mesh: Mesh) -> Mesh:
    """``mesh`` on the re-aimed map's own ``fit`` canvas (the first map's cut up to 4 px off
    an image the re-aimed one carried further); as it is on an ``input`` canvas."""
    if warp.fitted is None or warp.handles.canvas != "fit":
        return mesh
    (warp.canvas, offset), shift = warp.fitted, np.asarray(warp.offset) - np.asarray(warp.fitted[1])
    warp.offset, warp.nodes = offset, warp.nodes + shift
    return Mesh(mesh.source, mesh.target + shift, mesh.triangles, tuple(warp.canvas), mesh.record,
                mesh.node_component)
