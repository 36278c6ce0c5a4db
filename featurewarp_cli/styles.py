"""Which preset a style name that is not a preset's means (``fisheye``, ``twirl``, ``wave``).

The presets' summaries name the Photoshop, Illustrator and ImageMagick styles they
reproduce ("Fisheye, Bulge, Pinch (Photoshop's Fisheye style ...)", "Flag (--waves 1)
and Wave (--waves 2 or more)"); :func:`style_hint` reads them, so a new preset's
summary is all it takes. An unknown preset name that is one of those styles is
answered with the command that gives it, not with the nearest spelling (``fisheye``
was sent to ``fish``, ``resize`` to ``rise``).

The names are suggested, not accepted as aliases: several are ambiguous (Pinch is
bulge with a negative strength and inflate with a negative bend; Lower is arc's and
shell's; Photoshop's Bulge style is squeeze's negative bend, while the preset
``bulge`` is the Fisheye), some need an option (Wave is flag with ``--waves 2``),
and a plugin may register any of them as its own preset's name later.
"""

from __future__ import annotations

import re
import shlex

from . import plugins

#: Applications the summaries name beside the styles: no style is called that.
TOOLS = ("photoshop", "illustrator", "imagemagick")

#: Names that no summary gives, as ImageMagick and Photoshop users type them: preset and options.
UNNAMED = {"resize": ("stretch", ""), "scale": ("stretch", ""), "implode": ("bulge", "--strength -0.5")}

#: A capitalised word of a summary (Fisheye, Arc, Lower, Non-uniform).
WORD = re.compile(r"\b[A-Z][A-Za-z-]+")
#: The options a summary gives in brackets right after a style's name: ``Wave (--waves 2 or more)``.
OPTIONS = re.compile(r"\s*\((--[\w-]+ -?[\d.]+)")


def _key(name: str) -> str:
    """``name`` as it is compared: lower case, without spaces, hyphens and underscores."""
    return re.sub(r"[\s_-]", "", name.lower())


def summary_styles(summary: str) -> dict[str, tuple[str, str]]:
    """The style names ``summary`` gives, by :func:`_key`: each capitalised word (the tools'
    names and one- or two-letter words aside) and each pair of them ('Arc Lower'), to (the name
    as written, the options given in brackets after it or '')."""
    words = [m for m in WORD.finditer(summary) if m.group().lower() not in TOOLS]
    found = {}
    for i, match in enumerate(words):
        spans = [(match.start(), match.end())]
        following = words[i + 1] if i + 1 < len(words) else None
        if following is not None and summary[match.end():following.start()] == " ":
            spans.append((match.start(), following.end()))
        for start, end in spans:
            options = OPTIONS.match(summary, end)
            found.setdefault(_key(summary[start:end]), (summary[start:end], options.group(1) if options else ""))
    return found


def style_owners(name: str) -> list[tuple[str, str, str]]:
    """(preset, the style as its summary writes it, options) of every preset whose summary
    names the style ``name``; else what :data:`UNNAMED` gives; [] if none."""
    key, owners = _key(name), []
    for preset in plugins.names():
        try:
            summary = plugins.load(preset).summary or ""
        except plugins.UnknownPreset:                     # a broken plugin names nothing
            continue
        style = summary_styles(summary).get(key)
        if style is not None and key != _key(preset):
            owners.append((preset, *style))
    if not owners and key in UNNAMED:
        preset, options = UNNAMED[key]
        owners.append((preset, name, options))
    return owners


def style_hint(command: str, name: str, rest: list[str]) -> str | None:
    """The usage error's text for ``featurewarp COMMAND NAME REST...`` where NAME is a style
    some preset gives: which preset, and the command line that runs it (REST kept, the style's
    options added); None when no preset gives it."""
    owners = style_owners(name)
    if not owners:
        return None
    lines = [shlex.join(["featurewarp", command, preset, *rest, *shlex.split(options)])
             for preset, _, options in owners]
    if len(owners) == 1:
        preset, style, _ = owners[0]
        summary = plugins.load(preset).summary if plugins.known(preset) else ""
        about = f" ({preset}: {summary})" if summary else ""
        return f"unknown preset {name!r}: {style} is {preset}'s style: {lines[0]}{about}"
    which = " and of ".join(preset for preset, _, _ in owners)
    return f"unknown preset {name!r}: {owners[0][1]} is a style of {which}: " + " or ".join(lines)
