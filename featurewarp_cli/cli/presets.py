"""The per-preset commands (``warp``, ``batch``, ``compare``, ``animate`` PRESET) and their groups.

Each group lists the registered presets and builds a preset's command from its
declaration when it is named, so that a broken third-party plugin shows up as
broken instead of taking the command line down. The commands parse, call
:mod:`featurewarp_cli.app` (imported inside the callbacks, so that ``--help``
stays fast) and print; they turn a :class:`WarpError` into click's exit codes.
"""

from __future__ import annotations

import contextlib
import inspect
import re
import shlex
import sys
from dataclasses import replace

import click

from .. import plugins
from .options import (FPS, FRAMES, JOBS, MASK_HELP, PANEL_WIDTH, engine_options, input_output_mask, param_option,
                      preset_options, settings_from)
from .progress import progress_line, say


def click_error(err, input: str | None = None) -> click.ClickException:
    """The click exception for a :class:`featurewarp_cli.app.pipeline.WarpError` (usage: exit 2, else 1)."""
    if err.usage:
        if err.param:
            return click.BadParameter(err.message, param_hint=f"'{err.param}'")
        return click.UsageError(err.message)
    refused = input is not None and "nothing written" in err.message     # --strict, folds: name the file
    return click.ClickException(failure_line("stdin" if input == "-" else input, str(err)) if refused else str(err))


def summary_line(s: dict) -> str:
    """The ``--verbose`` line of one warped image."""
    (w, h), (cw, ch) = s["size"], s["canvas"]
    return (f"{s['input']} {w}x{h} -> {s['output']} {cw}x{ch}: {s['preset']} ({s['mode']}), "
            f"{s['components']} feature components, solver {s['solver']}, "
            f"{s['flipped_triangles']} flipped triangles, {s['seconds']:.2f} s")


def report_warnings(summary: dict, quiet: bool, verbose: bool) -> None:
    """Print an image's warnings and notes (unless quiet) and its summary line (if verbose) on stderr."""
    if not quiet:
        for warning in summary["warnings"]:
            say(f"featurewarp: warning: {summary['input']}: {warning}")
        for note in summary.get("notes", ()):
            say(f"featurewarp: {summary['input']}: {note}")
    if verbose:
        say(f"featurewarp: {summary_line(summary)}")


class NoProgress:
    """The stand-in for a progress bar that is not shown."""

    def update(self, steps: int) -> None:
        """Count nothing."""


def progress_bar(length: int, label: str, quiet: bool):
    """click's progress bar on stderr when it is a terminal (and not ``quiet``), else :class:`NoProgress`.

    (click < 8.2 has no ``hidden`` argument.)
    """
    if quiet or not sys.stderr.isatty():
        return contextlib.nullcontext(NoProgress())
    return click.progressbar(length=length, label=label, file=sys.stderr)


class PresetCommand(click.Command):
    """A preset's command: an option it does not have names the presets that do (``--sx`` given
    to swirl: "Did you mean '--mask'?" was click's only word)."""

    def __init__(self, preset, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.preset = preset

    def parse_args(self, ctx, args):
        try:
            return super().parse_args(ctx, args)
        except click.NoSuchOption as err:
            flag = err.option_name
            owners = [name for name in plugins.names() if name != self.preset.name and plugins.known(name)
                      and any(f"--{p.cli_name}" == flag for p in _params_of(name))]
            if not owners:
                raise
            own = ", ".join(f"--{p.cli_name}" for p in self.preset.params) or "no options of its own"
            raise click.NoSuchOption(flag, f"No such option: {flag} ({flag} is {', '.join(owners)}'s; "
                                           f"{self.preset.name} has {own})", ctx=ctx) from None


def _params_of(name: str) -> tuple:
    """The parameters of the preset ``name`` (none where its plugin does not load)."""
    try:
        return plugins.load(name).params
    except plugins.UnknownPreset:
        return ()


def preset_command(preset, params: list, callback, doc: str) -> click.Command:
    """The command named after ``preset``: the arguments of ``params``, the preset's own options
    (first in --help, before some 25 shared ones), then the options of ``params``."""
    arguments = [p for p in params if isinstance(p, click.Argument)]
    shared = [p for p in params if not isinstance(p, click.Argument)]
    return PresetCommand(preset, preset.name, params=arguments + preset_options(preset) + shared, callback=callback,
                         help=doc, short_help=preset.summary, no_args_is_help=True)


#: Each command's example line, around a preset's ``example`` options (``animate``: ``{vary}``).
EXAMPLES = {
    "warp": "featurewarp warp {name} in.png out.png -m mask.png {options}",
    "compare": "featurewarp compare {name} in.png panel.png -m mask.png {options}",
    "batch": "featurewarp batch {name} photos/*.png --out-dir out {options}",
    "animate": "featurewarp animate {name} in.png out.gif -m mask.png {options} --frames 24",
}


def animated(preset, options: list[str]) -> list[str] | None:
    """``options`` with the first numeric one, ``--NAME VALUE``, turned into ``--vary
    NAME=START:VALUE`` (START 0 where the range allows it, else the default); None if none is numeric."""
    numeric = {p.cli_name: p for p in preset.params if p.type in (int, float)}
    for i, flag in enumerate(options[:-1]):
        param = numeric.get(flag[2:]) if flag.startswith("--") else None
        if param is None:
            continue
        try:
            start = param.check(0)
        except plugins.ParamError:
            start = param.default
        if start is None:
            continue
        return options[:i] + ["--vary", f"{param.name}={start:g}:{options[i + 1]}"] + options[i + 2:]
    return None


def preset_doc(preset, intro: str = "", command: str = "warp") -> str:
    """A preset command's help: ``intro``, what the preset does (the first paragraph of its
    docstring, else its summary; the rest is for developers), and one example line of
    ``command`` built from the preset's ``example``. reStructuredText literals and roles
    (````-swirl````, ``:data:`EDGE_MAX```) are quoted as a terminal shows them."""
    text = inspect.cleandoc(preset.__doc__ or "").split("\n\n")[0] or preset.summary
    text = re.sub(r":\w+:`~?([^`]+)`", r"'\1'", text).replace("``", "'")
    options = shlex.split(getattr(preset, "example", "") or "")
    if options and command == "animate":
        options = animated(preset, options)
    if options:
        line = EXAMPLES[command].format(name=preset.name, options=shlex.join(options))
        text += f"\n\n\b\nExample:\n  {line}"
    return f"{intro}\n\n{text}" if intro else text


def warp_command(preset) -> click.Command:
    """``featurewarp warp PRESET INPUT OUTPUT``."""
    params = input_output_mask(MASK_HELP) + [
        click.Option(["--report"], type=click.Path(dir_okay=False), metavar="PATH",
                     help="Write a JSON report of what the run did and how well: features_kept, "
                          "no_effect (the output is the input), each feature component (scale, rotation, distortion, kept), "
                          "background_stretch, blank canvas and outline against the plain warp, "
                          "the warnings, the grid, fold-overs before and after the guard, the "
                          "solver, seconds per stage; also when --strict or a fold refuses the run "
                          "(marked refused, no image written). Its JSON Schema: 'featurewarp schema "
                          "report'; its fields: README, 'The report'."),
        click.Option(["--save-grid"], type=click.Path(dir_okay=False), metavar="PATH.npz|PATH.obj",
                     help="Save the mapping: arrays source (N x 2 source pixel positions of "
                          "the grid nodes), target (N x 2 on the output canvas), triangles "
                          "(M x 3 node indices, of positive signed area in source pixel "
                          "coordinates, x right and y down: clockwise as seen on screen); "
                          ".obj: a textured mesh."),
        click.Option(["--grid", "draw_grid"], is_flag=True, help="Draw the deformed grid over the result."),
    ] + engine_options(preset)

    def callback(input, output, mask, report, save_grid, draw_grid, **kwargs):
        settings, quiet, verbose = settings_from(preset, kwargs)
        warp_one(settings, quiet, verbose, input, output, mask, report, save_grid, draw_grid)

    return preset_command(preset, params, callback, preset_doc(preset))


def warp_one(settings, quiet: bool, verbose: bool, *files, **options) -> None:
    """Run :func:`featurewarp_cli.app.pipeline.warp_file` on ``files`` (input, output, mask,
    report, save_grid, draw_grid; ``options``: its others) with the progress line, then print
    its warnings."""
    from ..app.pipeline import WarpError, warp_file

    try:
        with progress_line(quiet):
            summary = warp_file(settings, *files, **options)
    except WarpError as err:
        raise click_error(err, files[0]) from err
    report_warnings(summary, quiet, verbose)


def run_planned(settings, todo, jobs: int, scheduler, summary_path, resume: bool, quiet: bool,
                verbose: bool) -> int:
    """Run a batch's jobs (locally or on Dask), print errors and warnings, write the JSON-lines
    summary; returns how many failed.

    The summary is opened (and an existing one emptied) only once the run has started: a
    ``--scheduler`` that fails leaves it as it was. A summary that cannot be written stops the
    run (the jobs not finished are cancelled) with one error naming it."""
    from ..app.batch import run_jobs, summary_record
    from ..app.resume import resume_notes, resume_plan, settings_stamp
    from ..app.cluster_run import Unfinished

    stamp = settings_stamp(settings)
    skipped, redone = resume_plan(todo, stamp, summary_path) if resume else ({}, [])
    for note in resume_notes(todo, skipped, redone, summary_path) if not quiet else ():
        say(note)
    numbers = [i for i in range(len(todo)) if i not in skipped]
    remaining = [todo[i] for i in numbers]
    failed = 0
    with contextlib.closing(run_jobs(settings, remaining, jobs, scheduler, verbose)) as results, \
            _summary_sink(summary_path) as record:
        for i in sorted(skipped):
            record(summary_record(i, todo[i], "skipped", settings=skipped[i]))
        version_of, stamps = getattr(results, "version_of", lambda k: None), {None: stamp}
        with progress_bar(len(remaining), "warping", quiet) as bar:
            for k, job, error, summary, seconds in results:
                bar.update(1)
                if error:
                    failed += 1
                    if not isinstance(error, Unfinished):    # said once, for them all
                        say(f"featurewarp: error: {failure_line(job.input, error)}")
                elif summary is not None:
                    report_warnings(summary, quiet, verbose)
                made = version_of(k)            # a Dask worker's featurewarp, which the stamp holds
                if made not in stamps:
                    stamps[made] = settings_stamp(settings, made)
                record(summary_record(numbers[k], job, "failed" if error else "ok", seconds, summary, error,
                                      stamps[made]))
    return failed


def failure_line(input: str, error: str) -> str:
    """A failed file's line: its error, after the input's name unless the error starts with it."""
    return error if error.startswith((input + " ", input + ":")) else f"{input}: {error}"


def _summary_writable(path: str) -> None:
    """Usage error unless ``--summary PATH`` can be written; the file is not touched."""
    from ..io.write import check_writable

    try:
        check_writable(path)
    except ValueError as err:
        raise click.UsageError(f"--summary: {err}") from None


@contextlib.contextmanager
def _summary_sink(path: str | None):
    """A function that writes one JSON line to the ``--summary`` file (nothing without one); a
    failed write is a WarpError naming the file."""
    import json

    from ..app.pipeline import WarpError

    if not path:
        yield lambda line: None
        return
    try:
        sink = click.open_file(path, "w", lazy=False)
    except OSError as err:
        raise click.UsageError(f"--summary: cannot write {path} ({err.strerror})") from None

    def record(line: dict) -> None:
        try:
            sink.write(json.dumps(line) + "\n")
            sink.flush()
        except OSError as err:
            raise WarpError(f"cannot write {path} ({err.strerror or err}); the batch was stopped",
                            "--summary") from None

    try:
        yield record
    finally:
        if path != "-":
            with contextlib.suppress(OSError):
                sink.close()


def check_scheduler(scheduler: str | None) -> None:
    """Usage errors, before anything is read or written: ``--jobs`` given with ``--scheduler``
    (the cluster's workers run the files), or a ``--scheduler`` value that names no scheduler."""
    if scheduler is None:
        return
    from click.core import ParameterSource

    if click.get_current_context().get_parameter_source("jobs") not in (ParameterSource.DEFAULT, None):
        raise click.UsageError("--jobs and --scheduler exclude each other: the cluster's workers run the files "
                               "(local:N for N local processes on Dask)")
    from ..app.scheduler import resolve

    resolve(scheduler)


def batch_command(preset) -> click.Command:
    """``featurewarp batch PRESET INPUT... --out-dir DIR``."""
    params = [click.Argument(["inputs"], nargs=-1, required=True, metavar="INPUT...",
                             type=click.Path()),           # a folder among them fails that file only
              click.Option(["-o", "--out-dir"], required=True, metavar="DIR",
                           type=click.Path(file_okay=False),
                           help="Folder for the outputs (created, with its parents, if missing). Inputs, "
                                "masks and DIR may be fsspec URLs (s3://bucket/photos/*.jpg)."),
              click.Option(["--mask-pattern"], default="{stem}_mask.png", show_default=True,
                           metavar="PATTERN",
                           help="Mask file of each input; {stem} is the input's name without "
                                "extension (its only field); relative to the input's folder unless absolute; "
                                "'alpha': each input's own alpha channel (as warp's --mask alpha). "
                                "A missing mask fails that file. Inputs that are another "
                                "input's mask, or are named as masks by PATTERN (by default *_mask.png) "
                                "and have no mask of their own, are skipped, so 'photos/*.png' works."),
              click.Option(["--suffix"], default="", metavar="S",
                           help="Appended to each output's stem: DIR/{stem}S.{ext}."),
              param_option(JOBS, "-j", "--jobs"),
              click.Option(["--scheduler"], metavar="ADDRESS",
                           help="Run the jobs on a Dask cluster instead of --jobs local processes (not "
                                "with --jobs): a scheduler address (tcp://host:8786), a scheduler file (as "
                                "'dask scheduler --scheduler-file' writes it), or local:N for a local "
                                "cluster of N workers. Paths must be ones every worker sees (or URLs); "
                                "relative ones are sent absolute. A scheduler with no workers is waited "
                                "for. Needs pip install 'featurewarp[dask]'."),
              click.Option(["--summary"], metavar="FILE", type=click.Path(dir_okay=False, allow_dash=True),
                           help="Write one JSON line per file (job, input, mask, output, status: ok, "
                                "failed or skipped, seconds, warnings, error, settings: a stamp of the "
                                "options) as each finishes; '-' for stdout. --resume reads the "
                                "previous one first."),
              click.Option(["--resume"], is_flag=True,
                           help="Skip files whose output exists and is newer than their input and mask. "
                                "When --summary FILE exists (from the run that made them), only outputs "
                                "it records with these settings (each line's 'settings' stamp), input "
                                "and mask are skipped; the others are warped again, as a line says. "
                                "Without it the settings are unchecked (a warning says so).")
              ] + engine_options(preset, "; a file with a warning then fails, the others are still written")

    def callback(inputs, out_dir, mask_pattern, suffix, jobs, scheduler, summary, resume, **kwargs):
        from ..app.batch import plan
        from ..app.cluster_run import Stopped
        from ..app.masks import ALPHA
        from ..app.pipeline import WarpError

        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            check_scheduler(scheduler)
            if summary and summary != "-":             # before plan() creates --out-dir
                _summary_writable(summary)
            from ..io.formats import format_name

            fmt = format_name(settings.fmt) if settings.fmt else None
            if mask_pattern == ALPHA:                      # each input is its own mask: no file to plan
                settings, mask_pattern = replace(settings, alpha_mask=True), None
            named_masks = []
            todo = plan(inputs, out_dir, suffix, fmt, None if settings.mode == "plain" else mask_pattern,
                        summary, named_masks)
            if named_masks and not quiet:
                listed = ", ".join(named_masks[:3]) + (", ..." if len(named_masks) > 3 else "")
                say(f"featurewarp: skipped {len(named_masks)} input(s) named as masks by --mask-pattern, with no "
                    f"input of theirs and no mask of their own: {listed}")
            failed = run_planned(settings, todo, jobs, scheduler, summary, resume, quiet, verbose)
        except WarpError as err:
            raise click_error(err) from err
        except Stopped as stop:                  # the cluster's jobs are stopped: exit as for any signal
            from .main import stop_on_signal

            stop_on_signal(stop.signum, None)
        if failed:
            raise click.ClickException(f"{failed} of {len(todo)} files failed")

    intro = f"Warp every INPUT with {preset.name} into --out-dir, each with its own mask."
    return preset_command(preset, params, callback, preset_doc(preset, intro, "batch"))


def compare_command(preset) -> click.Command:
    """``featurewarp compare PRESET INPUT OUTPUT``: the labelled four-way panel."""
    params = input_output_mask("Feature mask (as for warp).") + [
        click.Option(["--grid", "draw_grid"], is_flag=True, help="Draw the deformed grid over the three results."),
        param_option(PANEL_WIDTH),
    ] + [o for o in engine_options(preset, "; a warning of any view (or no --mask) refuses the panel")
         if o.name != "mode"]

    def callback(input, output, mask, draw_grid, panel_width, **kwargs):
        from ..app.panel import compare_file
        from ..app.pipeline import WarpError

        kwargs["mode"] = "similarity"
        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            with progress_line(quiet):
                summary = compare_file(settings, input, output, mask, draw_grid, panel_width)
        except WarpError as err:
            raise click_error(err, input) from err
        report_warnings(summary, quiet, verbose)

    intro = (f"Write one labelled panel: input with the mask tinted | plain | rigid | similarity "
             f"({preset.name}).")
    return preset_command(preset, params, callback, preset_doc(preset, intro, "compare"))


def animate_command(preset) -> click.Command:
    """``featurewarp animate PRESET INPUT OUTPUT --vary NAME=START:END``."""
    params = input_output_mask("Feature mask (as for warp).", output_dash=False) + [
        click.Option(["--vary"], multiple=True, required=True, metavar="NAME=START:END",
                     help="A numeric option of the preset to vary linearly over the frames, "
                          "e.g. angle=0:360 (repeat for several)."),
        param_option(FRAMES), param_option(FPS),
    ] + [o for o in engine_options(preset, "; a warning of any frame refuses the animation (a frame at rest is "
                                           "not one; every frame at rest is)") if o.name != "fmt"]

    def callback(input, output, mask, vary, frames, fps, **kwargs):
        from ..app.animate import animate_file, parse_vary
        from ..app.pipeline import WarpError

        kwargs["fmt"] = None
        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            ranges = parse_vary(vary, preset)
            given = click.get_current_context().get_parameter_source
            for name in ranges:
                if given(name) == click.core.ParameterSource.COMMANDLINE:    # one value or a range, not both
                    flag = plugins.option_flag(name)
                    raise WarpError(f"{flag} is given and varied (--vary): give one", "--vary", usage=True)
            with progress_bar(frames, "frames", quiet) as bar:
                summary = animate_file(settings, input, output, mask, ranges, frames, fps, bar.update)
        except WarpError as err:
            raise click_error(err, input) from err
        if not quiet:
            for warning in summary["warnings"]:
                say(f"featurewarp: warning: {input}: {warning}")
        if verbose:
            say(f"featurewarp: {output}: {summary['frames']} frames {summary['canvas'][0]}x{summary['canvas'][1]}, "
                f"{summary['factorizations']} factorization(s), {summary['seconds']:.2f} s")

    intro = (f"Animate {preset.name}: vary its options over frames, factoring once. OUTPUT: .gif, "
             f".webp or .png (animated), .mp4 or .avi (video), or a numbered PNG sequence "
             f"such as out-%04d.png.")
    return preset_command(preset, params, callback, preset_doc(preset, intro, "animate"))


class PresetGroup(click.Group):
    """A group with one subcommand per registered preset, built from its declaration."""

    make_command = staticmethod(warp_command)

    def list_commands(self, ctx):
        return list(plugins.names())

    def get_command(self, ctx, name):
        if not plugins.known(name):
            return None
        try:
            preset = plugins.load(name)
        except plugins.UnknownPreset as err:
            message = str(err)

            @click.command(name, help=f"(broken plugin) {message}",
                           context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
            @click.argument("args", nargs=-1, type=click.UNPROCESSED)
            def broken(args):                      # whatever it is given, the load error is the news
                raise click.ClickException(message)

            return broken
        return self.make_command(preset)

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError:
            if args and args[0] not in plugins.names():
                from ..styles import style_hint

                style = style_hint(ctx.info_name, args[0], args[1:], lambda preset: self.get_command(ctx, preset))
                if style is not None:                # 'fisheye' is bulge's, not 'fish'
                    raise click.UsageError(style, ctx) from None
                hint = plugins.did_you_mean(args[0], plugins.names())
                raise click.UsageError(
                    f"unknown preset {args[0]!r}; {hint}available: {', '.join(plugins.names())} "
                    "(see 'featurewarp warps')", ctx) from None
            raise


class BatchGroup(PresetGroup):
    """``featurewarp batch``: the same presets, each as a batch command."""

    make_command = staticmethod(batch_command)


class CompareGroup(PresetGroup):
    """``featurewarp compare``: the same presets, each as a comparison panel."""

    make_command = staticmethod(compare_command)


class AnimateGroup(PresetGroup):
    """``featurewarp animate``: the same presets, each as an animation command."""

    make_command = staticmethod(animate_command)
