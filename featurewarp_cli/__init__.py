"""featurewarp: warp images while the features in a mask keep their shape.

Feature-aware texturing (Gal, Sorkine, Cohen-Or 2006) and beyond. The pipeline,
one subpackage per stage::

    io/       decode the image and the mask, encode and write the outputs
    engine/   grid -> features -> W's Jacobians -> targets -> system -> factor
              (CHOLMOD) -> solve -> fold-over guard -> quality   => Mesh
    render/   Mesh -> inverse map (the compiled rasterizer) -> resampled image
    app/      one file, batch, animate, compare panel, diff, report
    cli/      the click commands

Presets are plugins (:mod:`featurewarp_cli.plugins`). The public API is
importable from here; importing this package is cheap (the numeric modules
load on first use):

>>> from featurewarp_cli import warp, FeatureWarper, Mesh
>>> from featurewarp_cli import Deformer, Handles       # the interactive mode (handles)
"""

from typing import TYPE_CHECKING

__version__ = "0.1.0"

__all__ = ["warp", "FeatureWarper", "Mesh", "load_warp", "Deformer", "Handles", "FeatureWarpWarning", "__version__"]


class FeatureWarpWarning(UserWarning):
    """What :func:`warp` could not do (a feature not kept, an output equal to its input), one
    warning per line of the solve's record."""


if TYPE_CHECKING:        # what type checkers see; at run time the names load on first use (__getattr__)
    from .engine.api import warp
    from .engine.deform import Deformer, Handles
    from .engine.mesh import Mesh
    from .engine.warper import FeatureWarper, load_warp


def __dir__():
    """The module's names with the lazily loaded ones (tab completion, ``help``)."""
    return sorted(set(globals()) | set(__all__))


def __getattr__(name):
    if name == "warp":
        from .engine import api

        return api.warp
    if name in {"FeatureWarper", "load_warp", "Mesh"}:
        from .engine import warper

        return getattr(warper, name)
    if name in {"Deformer", "Handles"}:
        from .engine import deform

        return getattr(deform, name)
    raise AttributeError(f"module 'featurewarp_cli' has no attribute {name!r}")
