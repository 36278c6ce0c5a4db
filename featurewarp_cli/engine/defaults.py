"""The engine's choices and default settings, declared once.

The engine (:class:`featurewarp_cli.engine.warper.FeatureWarper`), the pipeline's
settings and the command line's options all read them from here. This module
imports no numpy, so that the command line can build its options and help from
it at start-up.

The numeric settings are declared as :class:`featurewarp_cli.plugins.Param`, as
a preset declares its parameters: one declaration gives the default, the range,
the help and the check (:meth:`Param.check`) for the command line and the API.

Examples
--------
>>> from featurewarp_cli.engine.defaults import DECAY_PARAM, MODES
>>> MODES[0]
'similarity'
>>> DECAY_PARAM.check("3")
3.0
>>> DECAY_PARAM.check(0)
Traceback (most recent call last):
...
featurewarp_cli.plugins.ParamError: decay: 0 is out of range (0.001 <= CELLS <= 1000)
"""

from __future__ import annotations

from ..plugins import Param

#: similarity: features rotate and scale uniformly; rigid: they also keep their size;
#: plain: the warp itself, mask ignored.
MODES = ("similarity", "rigid", "plain")
MODE = "similarity"
#: exact: each feature component moves as one similarity; paper: the paper's soft
#: per-quad targets.
FORMULATIONS = ("exact", "paper")
FORMULATION = "exact"
#: fixed: border nodes stay on W (the paper); slide: they may slide along the sides W
#: maps onto axis-parallel lines; release: the preset's own, but a feature cut by a border
#: that no similarity of it can follow (an arc's curved side) lets go of that border to keep
#: its shape. The default is the preset's own (``Warp.boundary``), the outline held.
BOUNDARIES = ("fixed", "slide", "release")
#: Resampling filters of the renderer (OpenCV's nearest-neighbour, linear, cubic and Lanczos-4
#: interpolation). Nearest copies source values only (label maps, pixel art): no prefilter,
#: no feathered silhouette.
INTERPOLATIONS = ("nearest", "linear", "cubic", "lanczos")
INTERPOLATION = "cubic"
#: w_F, the weight of the feature equations.
FEATURE_WEIGHT = 10.0
#: rho, the width of the transition band around features, in cells.
DECAY = 2.0
#: Weight of the scale-and-rotation prior of similarity mode: 1 holds a component's scale
#: as firmly as its own shape equations would hold a target scale; 0 leaves it free.
SCALE_PRIOR = 1.0
#: The smallest grid cell a caller may ask for, in pixels.
MIN_CELL = 1.0

CELL_PARAM = Param(
    "cell", float, None,
    "Grid cell size in pixels. Default: automatic: 4 px, or sqrt(w*h/30000) above 0.48 MP; "
    "then divided by sqrt(2) until the grid is within 0.5 px of the warp and the warp "
    "folds none of its triangles (sub-pixel allowed, at most 800 000 nodes).",
    min=MIN_CELL, metavar="PX")
FEATURE_WEIGHT_PARAM = Param(
    "feature_weight", float, FEATURE_WEIGHT,
    "How firmly features keep their shape against the background: their equations count W^2 "
    "times the background's (the paper's w_F). From 0.0001 to 10 000: beyond either end the two "
    "kinds of equations are too far apart for the solve to keep both (below, the paper "
    "formulation's system cannot be factored: a feature's inner nodes lose their equations).",
    min=1e-4, max=1e4, metavar="W")
DECAY_PARAM = Param(
    "decay", float, DECAY,
    "Width of the band around features where the weight falls smoothly from W to 1 "
    "(the paper's rho), in cells (at least 0.001).",
    min=0.001, max=1000.0, metavar="CELLS")
SCALE_PRIOR_PARAM = Param(
    "scale_prior", float, SCALE_PRIOR,
    "Similarity mode: how firmly each feature's scale and rotation are pulled towards the warp's "
    "own (its best-fit rotation and the scale the mode picks). 1 holds them as firmly as the "
    "feature's own shape equations; smaller values let features that fill a row or column grow "
    "or shrink uniformly so the background is not streaked; 0 leaves them free. At most 10 000 "
    "(beyond, its square outweighs the shape equations by more than double precision keeps apart).",
    min=0.0, max=1e4, metavar="P")
