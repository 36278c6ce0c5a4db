"""The preset registry: entry points of the group ``featurewarp.warps``.

Built-in presets are registered in this package's metadata exactly as a
third-party package registers its own. A plugin that fails to import is
reported as broken instead of breaking the command line.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.metadata import entry_points

GROUP = "featurewarp.warps"


class UnknownPreset(LookupError):
    """No preset of that name is registered, or it failed to load."""


@lru_cache(maxsize=None)
def names() -> tuple[str, ...]:
    """Names of all registered presets, sorted."""
    return tuple(sorted({ep.name for ep in entry_points(group=GROUP)}))


@lru_cache(maxsize=None)
def load(name: str):
    """Load the preset class registered as ``name``.

    Raises
    ------
    UnknownPreset
        If ``name`` is not registered or its module fails to import.
    """
    matches = [ep for ep in entry_points(group=GROUP) if ep.name == name]
    if not matches:
        raise UnknownPreset(f"unknown preset {name!r}; available: {', '.join(names()) or 'none'}")
    try:
        return matches[0].load()
    except Exception as err:  # a broken third-party plugin must not take the CLI down
        raise UnknownPreset(f"preset {name!r} failed to load: {type(err).__name__}: {err}") from None
