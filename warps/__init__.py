"""The built-in presets (installed as ``featurewarp_warps``).

Each is a plugin like any third party's: a :class:`featurewarp_cli.plugins.Warp`
subclass registered under the entry-point group ``featurewarp.warps``.
"""
