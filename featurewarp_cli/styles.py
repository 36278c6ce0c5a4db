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
#: The option a summary gives in brackets right after a style's name: ``Wave (--waves 2 or more)``,
#: ``Pinch (--strength -0.5: ...)``, ``Arc Lower (--where lower)``.
OPTIONS = re.compile(r"\s*\((--[\w-]+ -?[\w.]+)")
#: A command-line word that is an option (``--bend``, ``-m``), not a value (``-30``, ``-``).
FLAG = re.compile(r"-[A-Za-z-]")


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


def option_table(command) -> dict[str, tuple[str, bool]]:
    """Each option word of a click ``command`` (``--mask``, ``-m``) -> (its parameter's name,
    whether it takes a value); {} for None."""
    table = {}
    for param in getattr(command, "params", ()):
        if getattr(param, "param_type_name", "") == "option":
            for word in (*param.opts, *param.secondary_opts):
                table[word] = (param.name, not (param.is_flag or param.count))
    return table


def merged(rest: list[str], options: str, table: dict, others: dict) -> tuple[list[str], list[str], bool]:
    """The words after the preset in the suggested command: ``rest`` without the options the
    preset does not take (``table``: :func:`option_table`; empty: all kept), then the style's
    ``options`` the user did not give (the user's ``--waves 3`` is not overridden); and the
    options left out, as written; and whether ``options`` gave way to the user's. ``others`` tells
    whether an option left out takes a value."""
    kept, dropped, given = [], [], set()
    i = 0
    while i < len(rest):
        word, i = rest[i], i + 1
        if word == "--":
            kept.extend(rest[i - 1:])
            break
        if not FLAG.match(word):
            kept.append(word)
            continue
        flag, equals, _ = word.partition("=")
        name, takes = table.get(flag) or others.get(flag) or (flag, i < len(rest) and not FLAG.match(rest[i]))
        value = rest[i:i + 1] if takes and not equals else []
        i += len(value)
        varied = (word.partition("=")[2] if equals else "".join(value)).partition("=")[0] if flag == "--vary" else ""
        if table and (flag not in table or (varied and f"--{varied.replace('_', '-')}" not in table)):
            dropped.append(shlex.join([word, *value]))      # an option, or a varied one, it does not take
        else:
            kept += [word, *value]
            given.update({name, varied.replace("-", "_")} - {""})    # --vary waves=1:3 gives waves too
    words = shlex.split(options)
    yields = bool(words) and (table.get(words[0]) or (words[0],))[0] in given
    return kept + ([] if yields else words), dropped, yields


def style_hint(command: str, name: str, rest: list[str], command_of=None) -> str | None:
    """The usage error's text for ``featurewarp COMMAND NAME REST...`` where NAME is a style
    some preset gives: which preset, and the command line that runs it (REST kept but for the
    options the preset does not take, which it names; the style's options added where REST does
    not give them); None when no preset gives it. ``command_of(preset)``: the click command
    ``featurewarp COMMAND preset`` (without it every option of REST is kept)."""
    owners = style_owners(name)
    if not owners:
        return None
    tables = {preset: option_table(command_of(preset) if command_of else None) for preset, _, _ in owners}
    others = {}
    if command_of and any(FLAG.match(word) for word in rest):     # what the options left out take
        for preset in plugins.names():
            others.update(option_table(command_of(preset)))
    lines = []
    for preset, style, options in owners:
        words, dropped, yields = merged(rest, options, tables[preset], others)
        left = f" ({', '.join(dropped)} left out: not an option of {preset})" if dropped else ""
        left += f" ({style} is {options}; {shlex.split(options)[0]} kept as given)" if yields else ""
        lines.append(shlex.join(["featurewarp", command, preset, *words]) + left)
    if len(owners) == 1:
        preset, style, _ = owners[0]
        summary = plugins.load(preset).summary if plugins.known(preset) else ""
        about = f" ({preset}: {summary})" if summary else ""
        return f"unknown preset {name!r}: {style} is {preset}'s style: {lines[0]}{about}"
    which = " and of ".join(preset for preset, _, _ in owners)
    return f"unknown preset {name!r}: {owners[0][1]} is a style of {which}: " + " or ".join(lines)
