"""The preset registry: entry points of the group ``featurewarp.warps``.

Built-in presets are registered in this package's metadata exactly as a
third-party package registers its own. A plugin that fails to import is
reported as broken instead of breaking the command line.

Naming or loading a built-in preset does not scan the entry points:
importing :mod:`importlib.metadata` and scanning costs about 25 ms of every
command's start-up. The built-ins therefore always win over a third-party
entry point of the same name.
"""

from __future__ import annotations

import importlib
from functools import lru_cache

GROUP = "featurewarp.warps"

#: The built-in presets: name -> ``module:attribute``, as in pyproject.toml's entry points
#: (tests/test_presets.py checks that the two agree).
BUILTIN = {
    "stretch": "warps.stretch:Stretch",
    "arc": "warps.arc:Arc",
    "swirl": "warps.swirl:Swirl",
    "bulge": "warps.bulge:Bulge",
}


class UnknownPreset(LookupError):
    """No preset of that name is registered, or it failed to load."""


def entry_points() -> list:
    """The entry points of :data:`GROUP` (importing :mod:`importlib.metadata` on first use)."""
    from importlib.metadata import entry_points as scan

    return list(scan(group=GROUP))


@lru_cache(maxsize=None)
def names() -> tuple[str, ...]:
    """Names of all registered presets, sorted."""
    return tuple(sorted(set(BUILTIN) | {ep.name for ep in entry_points()}))


def known(name: str) -> bool:
    """Whether a preset ``name`` is registered (without a scan for the built-ins)."""
    return name in BUILTIN or name in names()


@lru_cache(maxsize=None)
def load(name: str):
    """Load the preset class registered as ``name``.

    Raises
    ------
    UnknownPreset
        If ``name`` is not registered or its module fails to import.
    """
    matches = [] if name in BUILTIN else [ep for ep in entry_points() if ep.name == name]
    if name not in BUILTIN and not matches:
        raise UnknownPreset(f"unknown preset {name!r}; available: {', '.join(names()) or 'none'}")
    try:
        if matches:
            return matches[0].load()
        module, _, attribute = BUILTIN[name].partition(":")
        return getattr(importlib.import_module(module), attribute)
    except Exception as err:  # a broken third-party plugin must not take the CLI down
        raise UnknownPreset(f"preset {name!r} failed to load: {type(err).__name__}: {err}") from None
