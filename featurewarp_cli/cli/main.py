"""The ``featurewarp`` command line: the top-level group, its subcommands and the entry point.

The modules beside this one hold the pieces: :mod:`.options` (the shared options
and the click type that checks numbers through their declarations),
:mod:`.presets` (``warp``, ``batch``, ``compare`` and ``animate`` PRESET),
:mod:`.diff` and :mod:`.measure`. They parse, check and print; the work lives in
:mod:`featurewarp_cli.app`, imported inside the commands so that ``--help`` stays
fast. Only image bytes ever go to stdout when OUTPUT is ``-``; every message goes
to stderr.
"""

from __future__ import annotations

import os
import signal
import sys
import textwrap
import time
import warnings

import click

from .. import __version__, blas, plugins, stages
from .deform import deform_command
from .diff import diff_command
from .edit import edit_command
from .measure import measure_command
from .presets import AnimateGroup, BatchGroup, CompareGroup, PresetGroup
from .progress import say

#: click >= 8.2 raises this UsageError (exit 2), whose message is the help, for a command
#: run without its arguments; click 8.1 has no such class: it prints the help and exits 0.
NoArgsIsHelpError = getattr(click.exceptions, "NoArgsIsHelpError", ())


EPILOG = """\b
Shell completion (bash; use zsh_source or fish_source for zsh or fish):
  eval "$(_FEATUREWARP_COMPLETE=bash_source featurewarp)"
"""


class Commands(click.Group):
    """The top-level group: a preset's name or ``presets`` in a command's place says where it goes."""

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError:
            name = args[0] if args else ""
            if name in ("presets", "list", "styles"):
                raise click.UsageError(f"No such command {name!r}: 'featurewarp warps' lists the presets", ctx) \
                    from None
            if plugins.known(name):
                raise click.UsageError(f"No such command {name!r}: a preset is run as 'featurewarp warp {name} "
                                       f"INPUT OUTPUT' (or compare, batch, animate)", ctx) from None
            raise


@click.group(cls=Commands, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
             epilog=EPILOG)
@click.version_option(__version__, "-V", "--version", prog_name="featurewarp")
@click.option("--debug", is_flag=True, help="Show a traceback with processing errors.")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors (as each command's -q).")
@click.option("-v", "--verbose", is_flag=True, help="A summary line per image (as each command's -v).")
@click.pass_context
def cli(ctx, debug, quiet, verbose):
    """Warp images while the features marked in a mask keep their shape.

    Features (faces, people, logos, products) only rotate and scale uniformly;
    the background absorbs the rest of the warp. Exit status: 0 success,
    1 processing failure (or images that differ, for diff), 2 usage error.

    \b
    Examples:
      featurewarp warp stretch banner.jpg wide.jpg --mask banner_mask.png --sx 2
      featurewarp warp swirl in.png out.png -m mask.png --angle 120 --report r.json
      cat in.jpg | featurewarp warp bulge - png:- -m mask.png > out.png
      featurewarp batch swirl photos/*.jpg --out-dir out --jobs 8 --angle 90
      featurewarp compare arc photo.jpg panel.png -m mask.png --angle 120 --grid
      featurewarp animate swirl photo.jpg swirl.gif -m mask.png --vary angle=0:360 --frames 36
      featurewarp deform photo.jpg out.jpg -m mask.png --handles h.json
      featurewarp diff out.png golden.png --max-rmse 0.5
      featurewarp warps            # presets, their options, defaults and ranges
    """
    ctx.meta["featurewarp.quiet"], ctx.meta["featurewarp.verbose"] = quiet, verbose
    stages.quiet = quiet                   # a command's own -q sets it too (settings_from)


@cli.group(cls=PresetGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT [OPTIONS]",
           short_help="Warp INPUT with PRESET into OUTPUT, masked features kept.")
def warp():
    """Warp INPUT with PRESET into OUTPUT, keeping masked features in shape.

    The output format follows OUTPUT's extension (png, jpg, webp, tif, bmp, gif), an
    ImageMagick-style prefix (png:out.bin) or --format. '-' as INPUT reads stdin,
    '-' as OUTPUT writes stdout. Run 'featurewarp warp PRESET --help' for a preset's
    own options.

    \b
    Common options (with the preset's own, all in 'featurewarp warp PRESET --help'):
      -m, --mask PATH|alpha  the features to keep in shape: gray >= 128 in an
                             image of INPUT's size, or alpha: INPUT's own alpha
      --mode MODE            similarity (default), rigid (features keep their
                             size too) or plain (the standard warp)
      --report PATH          a JSON report: features_kept, no_effect, warnings ...
      --strict               exit 1 and write no image if the run has a warning
      --grow-past-edge       features cut by the frame may grow past it
      --background, --interp, --format, --quality, --strip, --save-grid,
      --grid, --cell, --boundary, --allow-folds, -q, -v

    \b
    Making a mask: paint it in 'featurewarp edit INPUT --save-mask MASK.png'
    (the brush, then Save), or with ImageMagick:
      convert cutout.png -alpha extract MASK.png      (or just -m alpha)
      convert -size WxH xc:black -fill white -draw "ellipse X,Y RX,RY 0,360" MASK.png

    \b
    Example:
      featurewarp warp swirl photo.jpg out.jpg -m mask.png --angle 120 --report report.json
    """


@cli.group(cls=BatchGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT... --out-dir DIR [OPTIONS]",
           short_help="Warp many images with PRESET, each with its own mask.")
def batch():
    """Warp many images with PRESET, each with its mask, into one folder.

    One line on stderr per failed file; the others are still written; exit 1
    if any failed. A progress bar is shown when stderr is a terminal.

    \b
    The batch's own options (with the preset's and warp's; all in
    'featurewarp batch PRESET --help'):
      -o, --out-dir DIR      folder for the outputs (created if missing)
      --mask-pattern P       each input's mask, default {stem}_mask.png (alpha: its own)
      --suffix S             outputs are DIR/{stem}S.ext
      -j, --jobs N           local worker processes (same bytes as 1)
      --scheduler ADDRESS    a Dask cluster instead: tcp://host:8786,
                             a scheduler file, or local:N
      --summary FILE         one JSON line per file ('-': stdout)
      --resume               skip outputs newer than their input and mask

    \b
    Example:
      featurewarp batch swirl photos/*.jpg --out-dir out --jobs 2 --angle 90
    """


@cli.group(cls=CompareGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT [OPTIONS]",
           short_help="One panel: input and mask | plain | rigid | similarity.")
def compare():
    """Show what featurewarp does: input with the mask tinted | plain | rigid | similarity.

    One factorization serves the three warps. Run 'featurewarp compare PRESET --help'
    for the options.

    \b
    Example:
      featurewarp compare arc photo.jpg panel.png -m mask.png --angle 120 --grid
    """


@cli.group(cls=AnimateGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT --vary NAME=START:END [OPTIONS]")
def animate():
    """Animate a preset: vary its options over frames, factoring once.

    Writes an animated GIF, WebP or PNG, an MP4/AVI video, or a numbered PNG
    sequence (out-%04d.png). --vary NAME=START:END varies a numeric option of the
    preset (repeatable), --frames N and --fps F set the frames. A progress bar is
    shown when stderr is a terminal. Run 'featurewarp animate PRESET --help' for
    the options (the preset's and warp's).

    \b
    Example:
      featurewarp animate swirl photo.jpg swirl.gif -m mask.png --vary angle=0:180 --frames 24
    """


cli.add_command(deform_command())
cli.add_command(edit_command())
cli.add_command(diff_command)
cli.add_command(measure_command)


@cli.command("schema", short_help="Print the JSON Schema of the report or the handles file.")
@click.argument("kind", type=click.Choice(["report", "handles"]))
def schema_command(kind):
    """Print the JSON Schema (Draft 2020-12) of the --report file or of the handles file.

    Each schema has a version of its own: the report's 'schema' key
    (featurewarp-report/3), the handles file's 'version' key (1 or 2; 2 when a point has an angle).

    \b
    Example:
      featurewarp schema report > report.schema.json
    """
    from .. import schema

    click.echo(schema.text(kind), nl=False)


@cli.command("warps", short_help="List the presets with their options, defaults and ranges.")
@click.argument("names", nargs=-1, metavar="[PRESET]...")
@click.option("--json", "as_json", is_flag=True, help="Print machine-readable JSON.")
def list_warps(names, as_json):
    """List every registered preset, or the PRESETs named, with its options, defaults and ranges.

    Each preset's border default (--boundary) is listed too.

    \b
    Examples:
      featurewarp warps swirl
      featurewarp warps --json
    """
    for name, value in plugins.shadowing():
        say(f"featurewarp: warning: a plugin registers the built-in name {name!r} ({value}); the built-in is used")
    for name in names:
        if name not in plugins.names():
            try:
                plugins.load(name)              # raises, saying what the name may have meant
            except plugins.UnknownPreset as err:
                raise click.UsageError(str(err)) from None
    entries = []
    for name in names or plugins.names():
        try:
            preset = plugins.load(name)
        except plugins.UnknownPreset as err:
            entries.append({"name": name, "broken": str(err), "params": []})
            continue
        entries.append({"name": name, "summary": preset.summary, "boundary": getattr(preset, "boundary", "slide"),
                        "params": [p.as_dict() for p in preset.params]})
    if as_json:
        import json

        click.echo(json.dumps(entries, indent=2))
        return
    for entry in entries:
        if "broken" in entry:
            click.echo(f"{entry['name']}  (broken: {entry['broken']})\n")
            continue
        click.echo(f"{entry['name']}  {entry['summary']}")
        for p in plugins.load(entry["name"]).params:     # None: the help says what it means
            default = "" if p.default is None else f"default: {p.default_text()}; "
            click.echo(f"  --{p.cli_name} {p.metavar}  [{default}{p.range_text()}]")
            click.echo(textwrap.fill(p.help, 96, initial_indent=" " * 6, subsequent_indent=" " * 6))
        click.echo(f"  (--boundary default: {entry['boundary']})\n")


def one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Show a Python warning (e.g. numpy's overflow) as one line on stderr (not with -q)."""
    from .. import stages

    if stages.quiet:
        return
    click.echo(f"featurewarp: warning: {message} ({os.path.basename(filename)}:{lineno})", err=True)


def _release_semaphores() -> None:
    """Unlink the semaphores of this process's worker pools as their finalizers would at a normal
    exit: exiting at once, Python's resource tracker warned about each one ("leaked semaphore
    objects") after "stopped by SIGINT"."""
    util, synchronize = sys.modules.get("multiprocessing.util"), sys.modules.get("multiprocessing.synchronize")
    cleanup = getattr(getattr(synchronize, "SemLock", None), "_cleanup", None)
    for finalizer in list(getattr(util, "_finalizer_registry", {}).values()):
        if cleanup is not None and getattr(finalizer, "_callback", None) is cleanup:
            try:
                finalizer()
            except Exception:             # already unlinked: nothing left to release
                pass


def stop_on_signal(signum, frame) -> None:
    """SIGTERM or SIGINT: remove this run's temporary files, stop worker processes, exit at once
    (128 + the signal's number). Outputs not yet put in place never appear: they wait in
    unnamed files or in temporary ones removed here."""
    for other in (signal.SIGTERM, signal.SIGINT):     # a second signal must not re-enter this
        signal.signal(other, signal.SIG_IGN)
    from ..io import capture, write

    write.remove_pending()
    stopped = [os.getpid()]
    processes = sys.modules.get("multiprocessing")    # none started if it was never imported;
    if getattr(processes, "active_children", None):   # half imported when the signal came: none either
        children = processes.active_children()
        for child in children:
            child.kill()
        deadline = time.monotonic() + 2.0              # one wait for all, not a second each
        for child in children:                        # dead before their copies are removed
            child.join(max(0.0, deadline - time.monotonic()))
            stopped.append(child.pid)
        _release_semaphores()
    remote = sys.modules.get("featurewarp_cli.app.remote")
    if remote is not None:                            # a batch's copies of URL inputs (its workers' too)
        remote.remove_copies(stopped)
    try:
        os.write(capture.real_stderr(), f"featurewarp: stopped by {signal.Signals(signum).name}\n".encode())
    except OSError:
        pass
    os._exit(128 + signum)


def main(argv=None):
    """Console-script entry point.

    Every error is one line on stderr: exit 2 for usage errors, 1 for processing
    failures (and for anything unexpected). ``--debug``, before the command or
    anywhere after it (up to a ``--``), also prints the traceback of processing failures.
    """
    blas.one_thread()                      # before numpy loads OpenBLAS (see featurewarp_cli.blas)
    argv = sys.argv[1:] if argv is None else list(argv)
    end = argv.index("--") if "--" in argv else len(argv)
    debug = "--debug" in argv[:end]
    if debug:                              # accepted after the command too: moved in front of it
        argv = ["--debug"] + [arg for arg in argv[:end] if arg != "--debug"] + argv[end:]
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, stop_on_signal)
    try:
        with warnings.catch_warnings():
            if not debug:
                warnings.showwarning = one_line_warning
            code = cli.main(args=argv, prog_name="featurewarp", standalone_mode=False)
    except NoArgsIsHelpError as err:
        err.show()
        code = err.exit_code
    except click.UsageError as err:
        say(f"featurewarp: error: {err.format_message()}")
        code = err.exit_code
    except click.exceptions.Abort:
        click.echo("featurewarp: aborted", err=True)
        code = 1
    except BrokenPipeError:                # the reader of stdout went away: nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 1
    except Exception as err:  # ClickException (processing) and anything unanticipated
        if debug:
            import traceback

            traceback.print_exception(err, file=sys.stderr)
        if isinstance(err, click.ClickException):
            message, code = err.format_message(), err.exit_code
        elif _writing_stdout(err):
            message, code = f"cannot write stdout: {err.strerror}", 1
        else:
            message, code = f"{_error_name(err)}: {' '.join(str(err).split())} (--debug shows a traceback)", 1
        say(f"featurewarp: error: {message}")
    finally:
        stages.quiet = False               # -q was this run's: a process that goes on (tests, the API) speaks
        stages.said.clear()
    sys.exit(code if isinstance(code, int) else 0)


def _writing_stdout(err: Exception) -> bool:
    """Whether ``err`` is an OSError of writing stdout (``featurewarp warps > /dev/full``): raised
    in click.echo to it, or in flushing it; it read "OSError: [Errno 28] ..." with no file named."""
    if not isinstance(err, OSError) or err.filename is not None or not err.strerror:
        return False
    tb = err.__traceback__
    while tb is not None:
        frame = tb.tb_frame
        if frame.f_code.co_name in ("echo", "flush", "write") and _is_stdout(
                frame.f_locals.get("self", frame.f_locals.get("file"))):
            return True
        tb = tb.tb_next
    return False


def _is_stdout(stream) -> bool:
    """Whether ``stream`` writes to file descriptor 1: sys.stdout, its buffer, or the text wrapper
    click puts around them where stdout's encoding is ASCII (``PYTHONIOENCODING=ascii``); not
    None, where there is no stdout at all."""
    try:
        return stream is not None and stream.fileno() == 1
    except (AttributeError, OSError, ValueError):   # io.UnsupportedOperation is both of the last two
        return False


def _error_name(err: Exception) -> str:
    """What an unanticipated error is called in its one line: OpenCV's ``cv2.error`` is 'OpenCV'
    (its class name, 'error', made the line read 'error: error:')."""
    name = type(err).__name__
    return "OpenCV" if name == "error" and type(err).__module__.startswith("cv2") else name


if __name__ == "__main__":
    main()
