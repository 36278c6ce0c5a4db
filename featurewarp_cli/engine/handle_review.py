"""What ``deform`` says about a solved mesh of handles: the handles that did not land (named
as they were given, with a cause), a crushed crease, a fold the handles ask for.

The functions take the :class:`deform.HandleWarp` of the handles (``warp``) and keep what the
report shows in its ``values`` (``handle_error_px``, ``handle_ends``, ``curve_error_px``,
``curve_ends``, ``area_kept``).
"""

from __future__ import annotations

import numpy as np

from .barrier import SAFE_FRACTION
from .grid import signed_areas
from .injectivity import CRUSHED_SHARE
from .handles import RING_POINTS, resample

#: A point or curve handle may end this far from its target (px) before a warning says so
#: (it was 2 % of the diagonal, 100 px at 12 MP, before handles were re-aimed until they land).
HANDLE_SLACK_PX = 3.0
#: Warnings name this many handles that miss, and count the rest.
NAMED = 5
#: A triangle of the result crushed below this share of its area under W gets a warning: a
#: crease (a feature carried against a pin did 0.014). Half the fold-over guard's safe area:
#: the barrier lets the thinnest triangles of a hard solve down to 40-70 % of it (at 0.1, a
#: handle dragged 60 px with two pins warned at 0.097).
CRUSHED = CRUSHED_SHARE * SAFE_FRACTION
#: Points along a curve handle where it is measured (its target and where it ended).
CURVE_SAMPLES = 32
#: A point handle with an ``angle`` may end turned this many degrees off it before a warning
#: says so (a handle turned 90 degrees beside a pin on the same disc turned it -0.08, in silence).
ANGLE_SLACK_DEG = 5.0


def fold_cause(warp, at=None) -> str:
    """What makes these handles crush or fold the image: a feature a handle carries (with
    its band, one similarity) turned far, or pressed against a pin or a held border, or else
    handles dragged across each other or a pin's path, or turned far. With ``at`` (where a
    crease is, in the source), a turned feature is blamed only where the crease lies within
    four bands of its box (a badge turned 40 degrees was blamed for a crease 400 px away), and
    a pin only where the crease lies nearer it than the carried feature's handle does."""
    handles = warp.handles
    if handles is None:                   # no handle to blame (a warp without a handles file)
        return "the warp folds the image where its map crosses itself; warp it less, or use --mode plain"
    pins = np.all(handles.points_from == handles.points_to, 1)
    turned = ("; a pin without an angle turns with the handles' overall rotation: give it \"angle\": 0 in a "
              "version-2 handles file to hold it unturned") if np.any(pins & ~np.isfinite(handles.angles)) else ""
    carried = sorted(warp.carried)
    far = [k for k in carried if np.isfinite(handles.angles[k]) and abs(handles.angles[k]) > TURNED_FAR
           and (at is None or _within_band(warp, k, at))]
    if far:
        return (f"the feature that handle {handles.name(far[0])} turns by {np.degrees(handles.angles[far[0]]):.0f}° "
                f"swings the band around it (one piece with it) over the image; turn it less, or use --mode plain")
    pressed = [k for k in carried if not pins[k] and (handles.border != "free" or at is None and np.any(pins) or any(
        np.hypot(*(at - pin)) < np.hypot(*(handles.points_from[k] - pin)) for pin in handles.points_from[pins]))]
    if pressed:
        return ("a feature carried by a handle (with the band around it, as one piece) is pressed against a pin "
                f"or the held border; drag it less far, move the pin, or use --mode plain{turned}")
    return f"handles dragged across each other or a pin's path, or turned far, do that{turned}"


def _labels_and_reach(warp):
    """(the mask's feature labels, four bands in px) of the rigid map behind ``warp``; None
    where there is none (a place can then not be told apart)."""
    rigid = getattr(warp, "rigid_map", None)
    if rigid is None or rigid.labels is None:
        return None
    return rigid.labels, rigid.decay * max(rigid.grid.spacing) * 4.0


def _feature_near(warp, point) -> bool:
    """Whether a feature pixel lies within four bands of ``point`` (True where that is unknown)."""
    if (known := _labels_and_reach(warp)) is None:
        return True
    labels, reach = known[0], int(np.ceil(known[1]))
    x, y = np.rint(point).astype(int)
    return bool(labels[max(0, y - reach):y + reach + 1, max(0, x - reach):x + reach + 1].any())


def _on_feature(warp, point) -> bool:
    """Whether ``point`` lies on a feature pixel (False where that is unknown)."""
    if (known := _labels_and_reach(warp)) is None:
        return False
    labels = known[0]
    x, y = np.clip(np.rint(point).astype(int), 0, [labels.shape[1] - 1, labels.shape[0] - 1])
    return bool(labels[y, x])


def _within_band(warp, k: int, at) -> bool:
    """Whether the source point ``at`` lies within four bands of the box of the feature handle
    ``k`` carries; True where that is unknown."""
    if (known := _labels_and_reach(warp)) is None:
        return True
    labels, reach = known
    x, y = np.clip(np.rint(warp.handles.points_from[k]).astype(int), 0, [labels.shape[1] - 1, labels.shape[0] - 1])
    ys, xs = np.nonzero(labels == labels[y, x])
    return bool(xs.min() - reach <= at[0] <= xs.max() + reach and ys.min() - reach <= at[1] <= ys.max() + reach)


def crushed(warp, mesh) -> list[str]:
    """A warning when a triangle of ``mesh`` keeps under :data:`CRUSHED` of its area under W
    (a crease the feature-aware solve makes: W's barrier keeps half the rest area, the solve
    does not), else of its area in the input (a crease of the handles' map itself, where handles
    press the image against a pin or the held border: the plain mode said nothing of it, its
    quality.area_ratio, against W, reading 1); ``values["area_kept"]``: the smallest share of its
    input area a triangle keeps and where (input px)."""
    tris, result = mesh.triangles, signed_areas(mesh.target, mesh.triangles)
    source = signed_areas(mesh.source, tris)
    kept = result / np.maximum(source, 1e-12)
    weakest = mesh.source[tris[np.argmin(kept)]].mean(axis=0)
    warp.values["area_kept"] = {"min": round(float(kept.min()), 6), "at": _plain(weakest, 1)}
    under_w = signed_areas(warp(mesh.source), tris)
    ratio = result[under_w > 1e-12] / under_w[under_w > 1e-12]
    if ratio.size and ratio.min() < CRUSHED:
        worst = mesh.source[tris[under_w > 1e-12][np.argmin(ratio)]].mean(axis=0)
        return [f"the result crushes the image into a crease near ({worst[0]:.0f}, {worst[1]:.0f}): triangles keep "
                f"{100 * ratio.min():.1f} % of their area under the handles' map (quality.area_ratio.min): "
                f"{fold_cause(warp, worst)}"]
    if kept.min() >= CRUSHED:
        return []
    share = f"{100 * kept.min():.1f} %" if kept.min() >= 0.001 else "under 0.1 %"
    cause = fold_cause(warp, weakest)        # a carried feature pressed or turned; else where handles pull
    if cause.startswith("handles dragged across"):
        cause = ("handles pull it towards or past a pin, the held border or each other there, or turn a feature "
                 "against them; drag or turn them less, or move the pin")
    return [f"the handles crush the image into a crease near ({weakest[0]:.0f}, {weakest[1]:.0f}): triangles keep "
            f"{share} of their area in the input (params.area_kept): {cause}"]


def review_points(warp, mesh) -> list[str]:
    """Warnings for the point handles that end farther than :data:`HANDLE_SLACK_PX` from their
    targets, as they were given (:meth:`Handles.name`), the first :data:`NAMED` and a count
    of the rest, each with its cause; ``values``: ``handle_error_px`` (largest, mean) and
    ``handle_ends`` (per handle: from, to, where it ended, its error)."""
    ends = warp.ends(mesh)
    if ends is None:
        return []
    handles = warp.handles
    error = np.hypot(*(ends - handles.points_to).T)
    warp.values["handle_error_px"] = {"max": round(float(error.max()), 3), "mean": round(float(error.mean()), 3)}
    warp.values["handle_ends"] = [
        {"given": handles.name(k), "from": _plain(handles.points_from[k]), "to": _plain(handles.points_to[k]),
         "ended": _plain(ends[k], 3), "error_px": round(float(e), 3)} for k, e in enumerate(error)]
    turns = _turn_misses(warp, mesh, ends)
    aimed = handles.points_to if warp.aimed is None else warp.aimed
    reach = np.hypot(*(warp(handles.points_from) + np.asarray(warp.offset) - aimed).T)
    missed = np.flatnonzero(error > HANDLE_SLACK_PX)
    missed = missed[np.argsort(-error[missed], kind="stable")]          # the worst first
    warnings = [f"handle {handles.name(k)} ends {_px(error[k])} from its target: {_cause(warp, k, reach[k])}"
                for k in missed[:NAMED]]
    if len(missed) > NAMED:
        more = len(missed) - NAMED
        warnings.append(f"and {more} more handle{'s' * (more > 1)} end{'s' * (more == 1)} over "
                        f"{HANDLE_SLACK_PX:g} px from their targets (the report's params.handle_ends lists every handle)")
    return warnings + turns


def turned_by(warp, mesh, points: np.ndarray, ends: np.ndarray, radius: float) -> np.ndarray:
    """Degrees (clockwise on screen, as a handle's ``angle``) by which ``mesh`` turns the ring of
    ``radius`` around each of ``points`` (whose centres ended at ``ends``): the rotation that best
    fits the ring's :data:`handles.RING_POINTS` points as they ended, in (-180, 180]."""
    around = np.arange(RING_POINTS) * (2.0 * np.pi / RING_POINTS)
    ring = radius * np.stack([np.cos(around), np.sin(around)], axis=1)
    ended = warp.mapped(mesh, (points[:, None, :] + ring).reshape(-1, 2)).reshape(len(points), -1, 2) - ends[:, None]
    cross = (ring[:, 0] * ended[..., 1] - ring[:, 1] * ended[..., 0]).sum(axis=1)
    return np.degrees(np.arctan2(cross, (ring[:, 0] * ended[..., 0] + ring[:, 1] * ended[..., 1]).sum(axis=1)))


def _turn_misses(warp, mesh, ends) -> list[str]:
    """Each point handle with an ``angle``: how far it turned (``angle_deg`` and
    ``angle_ended_deg`` in its ``handle_ends`` entry) and a warning where that is more than
    :data:`ANGLE_SLACK_DEG` off (turns compared modulo a full turn)."""
    handles = warp.handles
    turned = np.flatnonzero(np.isfinite(handles.angles))
    if not turned.size:
        return []
    asked = np.degrees(handles.angles[turned])
    radius = float(warp.values.get("radius") or 0.0) or 1.0          # the discs' radius as solved
    ended = turned_by(warp, mesh, handles.points_from[turned], ends[turned], radius)
    off = np.abs((ended - asked + 180.0) % 360.0 - 180.0)
    warnings = []
    for k, want, got, miss in zip(turned, asked, ended, off):
        warp.values["handle_ends"][k].update(angle_deg=round(float(want), 3), angle_ended_deg=round(float(got), 3))
        if miss > ANGLE_SLACK_DEG:
            warnings.append(f"handle {handles.name(k)} turned {round(got)}° where its angle asks {round(want)}° ({miss:.0f}° "
                            f"off): pins, other handles or a feature near it hold the turn (params.handle_ends)")
    return warnings


def _cause(warp, k: int, reach: float) -> str:
    """Why point handle ``k`` missed, ``reach`` px being where the rigid map W itself left it: the
    feature it carries (whatever W did: two handles on one feature pulling apart were told "a
    feature beside it"), the feature it sits on, which the held border keeps from being carried
    (it was told "beside it", and the note said the point moves: it did not), a feature beside
    it, the ground, or other handles."""
    if k in warp.carried:
        return ("the feature it carries keeps its shape, and the other handles on that feature (or pins beside "
                "it) pull it another way")
    if reach <= HANDLE_SLACK_PX:
        if _on_feature(warp, warp.handles.points_from[k]):
            return ("it sits on a feature that keeps its shape and that the held border holds, so its point cannot "
                    "move (the handles' map W reaches the target; --mode plain moves it)")
        if _feature_near(warp, warp.handles.points_from[k]):
            return "a feature beside it keeps its shape and holds it (the handles' map W reaches the target)"
        held = "the held border and " if warp.handles.border != "free" else ""
        return f"{held}the features kept in shape hold the ground it is on (the handles' map W reaches the target)"
    border = " or the pinned border" if warp.handles.border != "free" else ""
    return f"other handles{border} pull the same place another way (the handles' map W ends {reach:.0f} px away)"


def review_curves(warp, mesh) -> list[str]:
    """Warnings for the curve handles that end farther from their targets than
    :data:`HANDLE_SLACK_PX` anywhere along them, the first :data:`NAMED` and a count of the
    rest (``values["curve_error_px"]``: the largest and the mean distance over their
    samples; ``values["curve_ends"]``: per curve, its largest and mean)."""
    curves = warp.curve_ends(mesh)
    if not curves:
        return []
    errors = [np.hypot(*(ended - wanted).T) for wanted, ended in curves]
    every = np.concatenate(errors)
    warp.values["curve_error_px"] = {"max": round(float(every.max()), 3), "mean": round(float(every.mean()), 3)}
    warp.values["curve_ends"] = [{"given": f"curves[{k}]", "error_px": round(float(e.max()), 3),
                                  "mean_px": round(float(e.mean()), 3)} for k, e in enumerate(errors)]
    missed = sorted((k for k, e in enumerate(errors) if e.max() > HANDLE_SLACK_PX), key=lambda k: -errors[k].max())
    warnings = [f"curve curves[{k}] ends up to {_px(errors[k].max())} from its target: a feature that keeps "
                f"its shape, other handles or the border hold it" for k in missed[:NAMED]]
    if len(missed) > NAMED:
        warnings.append(f"and {len(missed) - NAMED} more curve(s) end far from their targets")
    return warnings


#: How :func:`fold_notes` begins (the editor shows it first: its status line shows one warning).
FOLD_ASK = "the handles ask for a fold"


def fold_notes(warp, handles, held: float) -> list[str]:
    """The note for handles that ask for a fold: how far W leaves the user's handles (points and
    curves) from their targets, or, when they reach them and only a feature they carry is
    held (``held`` px: every constraint's largest miss), how far that feature is."""
    if held <= HANDLE_SLACK_PX:
        return []
    offset = np.asarray(warp.offset)
    misses = [np.hypot(*(warp(handles.points_from) + offset - handles.points_to).T)] + [
        np.hypot(*(warp(resample(a, CURVE_SAMPLES)) + offset - resample(b, CURVE_SAMPLES)).T) for a, b in handles.curves]
    miss = max((float(m.max()) for m in misses if m.size), default=0.0)
    if miss > HANDLE_SLACK_PX:
        return [f"{FOLD_ASK}; they are held as far as the image can follow without one (up to "
                f"{miss:.0f} px from their targets)"]
    return [f"{FOLD_ASK}: a feature a handle carries is held as far as the image can follow "
            f"without one (up to {held:.0f} px from where its handle carries it; the handles reach their targets)"]


#: A carried feature turned by its handle's angle beyond this (radians) is named as the cause of
#: a fold (a badge turned 90 degrees in place was blamed on pins 450 px away).
TURNED_FAR = np.radians(30.0)
#: Several handles on one carried feature whose best similarity scales it beyond this factor
#: (or below its inverse) get a note: the feature must grow (shrink) as a whole to follow them.
CARRIED_SCALE = 2.0


def carried_scale_notes(labels: np.ndarray, handles, carried) -> list[str]:
    """A note per feature carried by several handles (``carried``: their indices) whose best
    similarity scales it by more than :data:`CARRIED_SCALE`: two handles on a face dragged
    apart ask the whole face to grow (7.6x in the editor trial, whose preview, a few steps of
    the rigid map from the last drag, showed a plausible picture that Export then refused)."""
    from .arap import similarity_fit

    carried = np.asarray(sorted(carried), int)
    if carried.size < 2:
        return []
    at = np.clip(np.rint(handles.points_from[carried]).astype(int), 0, [labels.shape[1] - 1, labels.shape[0] - 1])
    on, notes = labels[at[:, 1], at[:, 0]], []
    for label in np.unique(on):
        held = carried[on == label]
        if held.size < 2:
            continue
        scale = float(np.hypot(*similarity_fit(handles.points_from[held], handles.points_to[held])))
        if max(scale, 1.0 / max(scale, 1e-12)) > CARRIED_SCALE:
            names = ", ".join(handles.name(int(k)) for k in held)
            notes.append(f"the handles {names} on one feature ask it to {'grow' if scale > 1 else 'shrink'} "
                         f"{max(scale, 1 / scale):.1f}x as a whole (a feature keeps its shape: to bend it, use "
                         f"--mode plain or take it out of the mask)")
    return notes


def _px(distance: float) -> str:
    """``distance`` in pixels as a warning gives it: one decimal under 10 px (a 3.31 px miss read
    "3 px", within the 3 px slack), whole pixels beyond."""
    return f"{distance:.1f} px" if distance < 10 else f"{distance:.0f} px"


def _plain(point, digits: int = 6) -> list:
    return [round(float(point[0]), digits), round(float(point[1]), digits)]


def off_canvas(mesh) -> list[str]:
    """A warning per feature that the canvas cuts (an ``input`` canvas the handles move it off):
    the share of its nodes that end more than 1 px outside, where over 1 %, and how far (two of
    three discs moved 300 px right on an input canvas were cut in silence: the plain warp, the
    handles' map, is cut as much, so the canvas's own warnings said nothing)."""
    if mesh.node_component is None:
        return []
    high = np.array(mesh.canvas, float) - 0.5
    beyond = np.maximum(np.maximum(-0.5 - mesh.target, mesh.target - high), 0.0).max(axis=1)
    on = mesh.node_component >= 0
    comp, beyond = mesh.node_component[on], beyond[on]
    share = np.bincount(comp, beyond > 1.0) / np.maximum(np.bincount(comp), 1)
    far = np.zeros(share.size)
    np.maximum.at(far, comp, beyond)
    named = mesh.record.components if mesh.record is not None else []
    return [f"feature {k}{_named(named, k)} lies {100 * cut:.0f} % outside the canvas (up to {far[k]:.0f} px), "
            f"which cuts it (--canvas fit shows it whole)" for k, cut in enumerate(share) if cut > 0.01]


def _named(components, k: int) -> str:
    """`` (218 quads, around (335, 43))``: how the record's warnings name feature ``k``."""
    from .record import _around

    return f" ({components[k].quads} quads{_around(components[k])})" if k < len(components) else ""
