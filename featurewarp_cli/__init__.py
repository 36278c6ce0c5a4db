"""featurewarp: feature-aware image warping (Gal, Sorkine, Cohen-Or 2006, and beyond).

The Python API lives in :mod:`featurewarp_cli.api`; importing this package is cheap
(the numeric modules load on first use).
"""

__version__ = "0.1.0"


def __getattr__(name):
    if name in {"warp", "FeatureWarper", "load_warp", "Mesh"}:
        from . import api

        return getattr(api, name)
    raise AttributeError(name)
