"""The one-call API: :func:`warp` an image with a preset while masked features keep their shape."""

from __future__ import annotations

import numpy as np

from .defaults import DECAY, FEATURE_WEIGHT, FORMULATION, INTERPOLATION, MODE, SCALE_PRIOR
from .warper import FeatureWarper, load_warp


def warp(image: np.ndarray, mask: np.ndarray | None, preset: str, *, mode: str = MODE,
         cell: int | None = None, feature_weight: float = FEATURE_WEIGHT, decay: float = DECAY,
         formulation: str = FORMULATION, boundary: str | None = None, interp: str = INTERPOLATION,
         background=None, scale_prior: float = SCALE_PRIOR, grow_past_edge: bool = False, strict: bool = False,
         **params) -> np.ndarray:
    """Warp ``image`` with a preset while the features in ``mask`` keep their shape.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray
        Grey, grey + alpha, RGB or RGBA; uint8, uint16, bool, integers, or floats in
        [0, 1] (returned in the same dtype; see :mod:`featurewarp_cli.engine.arrays`).
    mask : (h, w) ndarray or None
        Feature pixels: bool as is; a 0/1 mask its 1s; other integers >= 128 (32896 for
        uint16); floats >= 0.5. A mask that marks nothing gives a warning (a plain warp).
    preset : str
        A preset's name: one of the 14 built in (``featurewarp warps`` lists them) or a plugin's.
    mode, cell, feature_weight, decay, formulation, boundary, scale_prior, grow_past_edge
        See :class:`FeatureWarper`.
    interp : {'nearest', 'linear', 'cubic', 'lanczos'}
    background : (r, g, b) of 0..255, colour text such as ``"white"``, or None
        Fill for pixels no source pixel lands on; None: transparent (alpha added where
        needed: RGBA for colour, grey + alpha for grey).
    strict : bool
        Raise the first warning as an error (:class:`featurewarp_cli.FeatureWarpWarning`)
        instead of returning an image that has a compromise in it.
    **params
        The preset's parameters.

    Returns
    -------
    ndarray
        The warped image on the preset's canvas.

    Raises
    ------
    featurewarp_cli.FeatureWarpWarning
        With ``strict``: the first thing the solve could not do, as an error.
    featurewarp_cli.plugins.UnknownPreset
        No preset has that name (a LookupError; its message lists the closest).
    featurewarp_cli.plugins.ParamError
        A preset parameter out of its range or of the wrong type (a ValueError).
    ValueError
        An image, mask or option the API does not take.

    Warns
    -----
    featurewarp_cli.FeatureWarpWarning
        One per thing the solve could not do (a feature not kept, a warp with no effect):
        the lines of ``mesh.record.warnings``.
    """
    import warnings

    from .. import FeatureWarpWarning

    height, width = image.shape[:2]
    w = load_warp(preset)(width, height, **params)
    warper = FeatureWarper(width, height, mask, cell=cell, feature_weight=feature_weight, decay=decay,
                           formulation=formulation, boundary=boundary, scale_prior=scale_prior,
                           grow_past_edge=grow_past_edge)
    mesh = warper.solve(w, mode)
    lines = list(mesh.record.warnings)
    if mask is not None and not warper.mask.any() and mode != "plain":
        lines.insert(0, "the mask marks no feature (see the mask rule of featurewarp_cli.engine.arrays): plain warp")
    if strict and lines:
        raise FeatureWarpWarning(lines[0])
    for line in lines:
        warnings.warn(line, FeatureWarpWarning, stacklevel=2)
    return warper.render(image, mesh, interp, background)
