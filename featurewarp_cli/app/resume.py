"""``batch --resume``: which up-to-date outputs an earlier run's ``--summary`` vouches for.

Each summary line records the output, input and mask as given, the folder they are relative to
(``dir``: the run's working folder) and :func:`settings_stamp`, the normalized values that decide
the output's bytes and the featurewarp version. ``--resume`` skips an up-to-date output only where
a line records it with this input, mask and stamp (:func:`resume_plan`), whatever folder either
run is started from, and says of the others which of the three differs (:func:`resume_notes`).
"""

from __future__ import annotations

import os

from .. import plugins
from ..io import urls
from .batch import Job, _identity, up_to_date
from .pipeline import Settings

#: Settings that change no output byte (they only refuse a file), left out of :func:`settings_stamp`.
UNSTAMPED = ("max_pixels", "max_memory", "warp_factory", "strict")
#: The odd image sizes at which :func:`_meaning` samples the preset's map.
PROBES = ((997, 613), (331, 1201))


def settings_stamp(settings: Settings, version: str | None = None) -> str:
    """``sha256:`` and 16 hex digits of what makes a batch's outputs what they are: the preset, its
    parameters, the engine and output options (not the limits, nor ``--strict``, which only
    refuses) by their meaning (``jpeg`` as ``jpg``, ``#FFF`` as ``white``, an explicit default as
    none), and the featurewarp version (an upgrade may change the bytes): ``version``, that of the
    Dask worker that made the output, else this one's. Each ``--summary`` line records it, for
    ``--resume`` to compare (:func:`resume_plan`)."""
    import hashlib
    import json

    from .. import __version__
    from ..io.formats import format_name

    chosen = {name: value for name, value in vars(settings).items() if name not in UNSTAMPED}
    chosen.update(params=_meaning(settings.preset, settings.params), version=version or __version__,
                  fmt=settings.fmt and (format_name(settings.fmt) or settings.fmt),
                  background=settings.background and _colour(settings.background))
    text = json.dumps(chosen, sort_keys=True, default=str)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()[:16]


def _colour(text: str):
    """The colour ``--background`` names, as parsed (the text where it is not one)."""
    from ..io.colours import parse_colour

    try:
        return ["colour", parse_colour(text, alpha=True)]
    except ValueError:
        return text


def _meaning(preset: str, params: dict):
    """What the preset's ``params`` do: its map at the :data:`PROBES` sizes (canvas, offset,
    boundary, and 7 x 7 points to 10 digits), so that spellings of the same values stamp alike
    (``--center 50%,50%`` and the default, ``--angle 90`` and ``9e1``); the values themselves
    where the preset cannot be made there."""
    import numpy as np

    try:
        kind, made = plugins.load(preset), []
        for width, height in PROBES:
            warp = kind(width, height, **params)
            y, x = np.mgrid[0:1:7j, 0:1:7j]
            points = warp(np.stack([x.ravel() * (width - 1), y.ravel() * (height - 1)], 1))
            made.append([list(warp.canvas), [f"{v:.10g}" for v in warp.offset], getattr(warp, "boundary", None),
                         [f"{v:.10g}" for v in np.ravel(points)]])
        return made
    except Exception:                             # noqa: BLE001  a plugin's error: its values stand
        return params


def recorded_outputs(summary: str | None) -> dict | None:
    """What an earlier ``--summary`` file records of the outputs it wrote or found up to date:
    output -> ((input, mask), settings stamp), by what they name (:func:`_places`; a line that
    is not a job's JSON is passed over); None where there is no file to read (none given, ``-``,
    not there or unreadable)."""
    import json

    if not summary or summary == "-" or not os.path.isfile(summary):
        return None
    lines = {}
    try:
        with open(summary, encoding="utf-8", errors="replace") as file:
            for text in file:
                try:
                    line = json.loads(text)
                except ValueError:
                    continue
                places = _places(line)
                if places is not None and line.get("status") in ("ok", "skipped"):
                    lines[places[0]] = (places[1:], line.get("settings"))
    except OSError:
        return None
    return lines


def _places(line) -> tuple | None:
    """What the output, input and mask of a summary line name (:func:`_identity`; a relative path
    in the folder the line's ``dir`` gives, that of the run that wrote it, else in this one; the
    mask None where it had none); None for a line that is not a job's, or names a store not
    installed."""
    try:
        output, input, mask = (line[name] for name in ("output", "input", "mask"))
        if not (isinstance(output, str) and isinstance(input, str) and isinstance(mask, (str, type(None)))):
            return None
        base = line.get("dir") if isinstance(line.get("dir"), str) else ""

        def named(path):
            return _identity(path if urls.is_url(path) else os.path.join(base, path))

        return named(output), named(input), mask and named(mask)
    except (TypeError, KeyError, ValueError, OSError, ImportError):
        return None


def resume_plan(jobs: list[Job], stamp: str, summary: str | None) -> tuple[dict, list]:
    """What ``--resume`` does with ``jobs`` whose outputs are up to date by their times
    (:func:`up_to_date`): with the ``summary`` file of an earlier run to read, each is skipped only
    where a line of it records this input, mask and ``stamp`` (:func:`settings_stamp`), else warped again;
    without one, each is skipped unchecked.

    Returns
    -------
    skipped : dict
        Index -> the stamp its output is known to be made with, None where unchecked.
    redone : list of (int, str)
        The jobs whose outputs are up to date but not recorded as made with these settings,
        input and mask, and what differs ('settings', 'input', 'mask', joined by ', ', or
        'not recorded').
    """
    known = recorded_outputs(summary)
    skipped, redone = {}, []
    for i, job in enumerate(jobs):
        if not up_to_date(job):
            continue
        if known is None:
            skipped[i] = None
            continue
        record = known.get(_identity(job.output))
        if record is None:
            redone.append((i, "not recorded"))
            continue
        (input, mask), made = record
        differs = [name for name, same in (("settings", made == stamp), ("input", input == _identity(job.input)),
                                           ("mask", mask == (job.mask and _identity(job.mask)))) if not same]
        if differs:
            redone.append((i, "other " + ", ".join(differs)))
        else:
            skipped[i] = stamp
    return skipped, redone


def resume_notes(jobs: list[Job], skipped: dict, redone: list, summary: str | None) -> list[str]:
    """The lines ``--resume`` says about :func:`resume_plan`'s outcome: the outputs warped again
    (each with what differs), and (a warning) those skipped unchecked."""
    def listed(items):
        names = [jobs[i].output + why for i, why in items[:3]]
        return ", ".join(names) + (f" and {len(items) - 3} more" if len(items) > 3 else "")

    notes = []
    if redone:
        notes.append(f"featurewarp: --resume: warping {len(redone)} up-to-date output(s) again, which {summary} does "
                     f"not record as made with these settings, input and mask: "
                     f"{listed([(i, f' ({why})') for i, why in redone])}")
    unchecked = sorted(i for i, stamp in skipped.items() if stamp is None)
    if unchecked:
        notes.append(f"featurewarp: warning: --resume skipped {len(unchecked)} output(s) by their times alone, the "
                     f"settings that made them unchecked (give the --summary FILE of the run that made them): "
                     f"{listed([(i, '') for i in unchecked])}")
    return notes
