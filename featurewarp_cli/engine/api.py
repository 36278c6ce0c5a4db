"""The one-call API: :func:`warp` an image with a preset while masked features keep their shape."""

from __future__ import annotations

import re
import warnings as python_warnings
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from . import arrays
from .defaults import (DECAY, FEATURE_WEIGHT, FORMULATION, INTERPOLATION, INTERPOLATIONS, MODE, MODES,
                       SCALE_PRIOR)
from .warper import FeatureWarper, load_warp

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..plugins import Warp
    from .mesh import Mesh

#: :func:`warp`'s own keywords (the others are the preset's parameters).
OPTIONS = ("mode", "cell", "feature_weight", "decay", "formulation", "boundary", "interp", "background",
           "scale_prior", "grow_past_edge", "injective", "antialias", "max_memory", "strict", "return_mesh")
#: The message of a mask that marks nothing (the command line's says so too).
EMPTY_MASK = "the mask marks no feature (see the mask rule of featurewarp_cli.engine.arrays): plain warp"


@overload
def warp(image: ArrayLike, mask: ArrayLike | str | None, preset: str | type[Warp] | Warp, *,
         return_mesh: Literal[False] = ..., **options: Any) -> np.ndarray: ...


@overload
def warp(image: ArrayLike, mask: ArrayLike | str | None, preset: str | type[Warp] | Warp, *,
         return_mesh: Literal[True], **options: Any) -> tuple[np.ndarray, Mesh]: ...


def warp(image, mask, preset, *, mode=MODE, cell=None, feature_weight=FEATURE_WEIGHT, decay=DECAY,
         formulation=FORMULATION, boundary=None, interp=INTERPOLATION, background=None, scale_prior=SCALE_PRIOR,
         grow_past_edge=False, injective=True, antialias=True, max_memory=None, strict=False, return_mesh=False,
         **params):
    """Warp ``image`` with a preset while the features in ``mask`` keep their shape.

    Parameters
    ----------
    image : (h, w) or (h, w, C) array-like
        Grey, grey + alpha, RGB or RGBA; uint8, uint16, bool, integers, or floats in [0, 1]
        (returned in the same dtype and number of dimensions; :mod:`featurewarp_cli.engine.arrays`).
    mask : (h, w) array-like, path or None
        Feature pixels, by the command line's mask rule (:func:`arrays.mask_array`).
    preset : str, Warp subclass or Warp instance
        A preset's name (``featurewarp warps`` lists them), or a preset not registered:
        its class (made with ``**params``) or an instance made for this image's size.
    mode, cell, feature_weight, decay, formulation, boundary, scale_prior, grow_past_edge, injective
        See :class:`FeatureWarper`.
    interp, antialias
        See :meth:`FeatureWarper.render`.
    background : (r, g, b) of 0..255, a grey 0..255, colour text such as ``"white"``, or None
        Fill for pixels no source pixel lands on; None: transparent (alpha added where needed).
    max_memory : int, str or None
        A memory budget in bytes (or ``"2G"``), as ``--max-memory``: a grid it cannot hold is
        refused before it is built (a ValueError). Default None: no limit, whatever the machine.
    strict : bool
        Raise the first warning as an error (:class:`featurewarp_cli.FeatureWarpWarning`).
    return_mesh : bool
        Return ``(image on the preset's canvas, mesh)``: ``mesh.record`` has the warnings too.
    **params
        The preset's parameters.

    Returns
    -------
    ndarray, or (ndarray, Mesh) with ``return_mesh``

    Raises
    ------
    featurewarp_cli.FeatureWarpWarning
        With ``strict``: the first thing the solve could not do, as an error.
    featurewarp_cli.plugins.UnknownPreset
        No preset has that name (a LookupError; its message lists the closest).
    featurewarp_cli.plugins.ParamError
        A parameter, the preset's or :func:`warp`'s own, unknown, out of range or of the
        wrong type (a ValueError; ``.names`` names it).
    ValueError, TypeError
        An image, mask or background the API does not take (checked before the solve).

    Warns
    -----
    featurewarp_cli.FeatureWarpWarning
        One per line of ``mesh.record.warnings``: a feature not kept, a warp with no effect,
        a mask that marks nothing, folded triangles.
    """
    from .. import FeatureWarpWarning

    samples, fill, dtype = arrays.prepare(image, background)           # every input is checked before the solve
    height, width = samples.shape[:2]
    marked = arrays.mask_array(mask, (height, width))
    _check_options(mode=mode, interp=interp, grow_past_edge=grow_past_edge, injective=injective,
                   antialias=antialias, strict=strict, return_mesh=return_mesh)
    w = _preset(preset, width, height, params)
    arrays.check_canvas(w)                       # a plugin's, before the budget reads it and the solve
    try:
        warper = FeatureWarper(width, height, marked, cell=cell, feature_weight=feature_weight, decay=decay,
                               formulation=formulation, injective=injective, boundary=boundary,
                               scale_prior=scale_prior, grow_past_edge=grow_past_edge,
                               max_nodes=_node_budget(max_memory, width, height, w.canvas))
        mesh = warper.solve(w, mode)
    except ValueError as err:
        raise _in_api_terms(err) from None
    lines = _report(mesh, w, marked, mode)
    if strict and lines:
        raise FeatureWarpWarning(lines[0])
    for line in lines:
        python_warnings.warn(line, FeatureWarpWarning, stacklevel=2)
    out = warper.render(samples, mesh, interp, fill, antialias, order="bgr")   # prepare's samples, as they are
    out = arrays.finish(out, 1 if samples.ndim == 2 else samples.shape[2], dtype, samples.ndim == 3)
    return (out, mesh) if return_mesh else out


def _check_options(mode, interp, **flags) -> None:
    """ParamError for a mode, interpolation or flag :func:`warp` does not take (before the solve)."""
    from ..plugins import ParamError

    for name, value, choices in (("mode", mode, MODES), ("interp", interp, INTERPOLATIONS)):
        if not isinstance(value, str) or value not in choices:
            raise ParamError(name, f"must be one of {', '.join(choices)}, not {value!r}")
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ParamError(name, f"must be True or False, not {value!r}")


def _preset(preset, width: int, height: int, params: dict):
    """The warp ``preset`` names (a name, a Warp subclass or instance) for this image size; a
    ParamError for a keyword neither :func:`warp` nor the preset takes."""
    import difflib

    from ..plugins import ParamError, Warp

    if isinstance(preset, Warp):
        if params:
            raise ParamError(tuple(sorted(params)), f"the preset {preset.name} is an instance, made with its "
                                                    "parameters: pass its class to give them here")
        if (preset.width, preset.height) != (width, height):
            raise ValueError(f"the preset {preset.name} is made for {preset.width}x{preset.height}, "
                             f"the image is {width}x{height}")
        return preset
    if isinstance(preset, str):
        preset = load_warp(preset)
    elif not (isinstance(preset, type) and issubclass(preset, Warp)):
        raise TypeError(f"preset must be a preset's name, a featurewarp_cli.plugins.Warp subclass or instance, "
                        f"not {preset!r}")
    own = [p.name for p in preset.params]
    unknown = sorted(set(params) - set(own))
    if unknown:
        near = difflib.get_close_matches(unknown[0], OPTIONS + tuple(own), 2, 0.5)
        hint = f" (did you mean {' or '.join(map(repr, near))}?)" if near else ""
        raise ParamError(tuple(unknown), f"neither warp() nor {preset.name} takes it{hint}; warp() takes "
                                         f"{', '.join(OPTIONS)}; {preset.name} takes {', '.join(own) or 'nothing'}")
    return preset(width, height, **params)


def _node_budget(max_memory, width: int, height: int, canvas) -> int | None:
    """The grid nodes ``max_memory`` allows, as the command line reckons them (None: no limit)."""
    from ..io import ImageError, limits
    from ..plugins import ParamError

    if max_memory is None:
        return None
    try:
        if isinstance(max_memory, float) and max_memory.is_integer():      # 2e9 bytes
            max_memory = int(max_memory)
        if isinstance(max_memory, bool) or not isinstance(max_memory, (str, int, np.integer)):
            raise ValueError(f"{max_memory!r} is not a size (bytes as an integer, or text such as '2G')")
        budget = limits.parse_size(str(max_memory))
        return limits.node_budget(width, height, tuple(canvas), budget)
    except (ValueError, ImageError) as err:
        raise ParamError("max_memory", _python_names(str(err))) from None


def _python_names(text: str) -> str:
    """``text`` with the command line's flags (``--max-memory``) as the API's keywords (``max_memory``)."""
    return re.sub(r"--([a-z][a-z-]*)", lambda m: m[1].replace("-", "_"), text)


def _in_api_terms(err: ValueError) -> ValueError:
    """An error of FeatureWarper's in the API's terms: flags as keywords; one that begins with
    an option of :func:`warp` as a ParamError naming it."""
    from ..plugins import ParamError

    if isinstance(err, ParamError):
        return err
    text = _python_names(str(err))
    named = re.match(r"(\w+):? (.*)", text, re.S)
    if named and named[1] in OPTIONS:
        return ParamError(named[1], named[2])
    return type(err)(text)


def _report(mesh, warp, marked, mode: str) -> list[str]:
    """The lines of ``mesh.record.warnings``, with what the command line adds to a solve's
    (the preset's review, folded triangles, which the command refuses, an empty mask), its
    flags named as the API's keywords."""
    record = mesh.record
    if getattr(warp, "review", None) is not None:
        record.warnings.extend(warp.review(mesh))
    first = []
    folded, crossings = mesh.flips(), getattr(mesh, "crossings", 0)
    if folded:
        first.append(f"the result has {folded} folded triangles (the warp turns the image over itself there)")
    if crossings:
        first.append(f"the result lays the image over itself (its border crosses itself {crossings} times)")
    if marked is not None and not marked.any() and mode != "plain":
        first.append(EMPTY_MASK)
    record.warnings[:] = [_python_names(line) for line in first + record.warnings]   # "a finer cell", not --cell
    return list(record.warnings)
