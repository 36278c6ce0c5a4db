"""``featurewarp edit``: the live editor in the browser (a local server that solves)."""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import replace

import click

from ..plugins import Param
from .deform import Deform, load_handles
from .options import engine_options, param_option
from .presets import MASK_HELP, click_error

PORT = Param("port", int, 0, "Port on 127.0.0.1 (0: a free one).", min=0, max=65535, metavar="N")
KEEP = {"mode", "cell", "feature_weight", "decay", "scale_prior", "background", "interp", "fmt", "max_pixels",
        "max_memory", "allow_folds", "quality", "strip", "quiet", "verbose"}


def check_files(settings, input: str, mask: str | None, handles: str | None, output: str | None,
                save_mask: str | None = None) -> None:
    """Before the editor starts: every file Save and Export may write (those named, and the
    handles file and painted mask they write beside the output when none is named) can be
    written, and none names INPUT, the mask or another (WarpError otherwise)."""
    from ..app.editor_session import companion
    from ..app.outputs import check_distinct
    from ..app.pipeline import WarpError, check_outputs

    writes = {"-o": output, "--handles": handles or companion(output, ".handles.json"),
              "--save-mask": save_mask or companion(output or handles, ".mask.png")}
    named = {**writes, "INPUT": input, "--mask": mask}
    pairs = [(a, b) for i, a in enumerate(writes) for b in list(named)[i + 1:]]
    same = [(a, b) for a, b in pairs
            if named[a] and named[b] and os.path.realpath(named[a]) == os.path.realpath(named[b])]
    if same:
        a, b = same[0]
        given = {"-o": output, "--handles": handles, "--save-mask": save_mask}
        how = f" (the default beside {'-o' if output else '--handles'}; name another with {a})" if not given[a] else ""
        raise WarpError(f"{a} {named[a]}{how} is also {b}: the editor would overwrite it", usage=True)
    extra = [(writes[key], key) for key in ("--handles", "--save-mask")]
    try:
        if output:
            check_outputs(settings, output, *extra)
            check_distinct([(output, "-o")] + extra, [(input, "INPUT"), (mask, "--mask")])
        elif any(path for path, _ in extra):
            check_outputs(replace(settings, quality=None), "unused.png", *extra)    # no image: no --quality
    except WarpError as err:
        if err.param == "OUTPUT":
            err.param = "-o"
        raise


def serve(server, quiet: bool, no_browser: bool) -> None:
    """Print the editor's URL and what loading said, open the URL unless ``no_browser``, serve
    until Ctrl-C (exit 0; 130 when an Export was running: it is abandoned, its files put back)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)     # Ctrl-C stops it cleanly, exit 0
    abandoned = None
    try:
        click.echo(server.url)
        sys.stdout.flush()
        if not quiet:
            for warning in server.session.state()["warnings"]:
                click.echo(f"featurewarp: warning: {warning}", err=True)
            click.echo("featurewarp: editor running; Ctrl-C stops it", err=True)
        if not no_browser:
            import webbrowser

            webbrowser.open(server.url)
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        abandoned = server.session.abandon()
    finally:
        server.server_close()
    if abandoned:
        click.echo(f"featurewarp: export of {abandoned} abandoned (Ctrl-C): its files are as they were", err=True)
        raise click.exceptions.Exit(130)
    if not quiet:
        click.echo("featurewarp: editor stopped", err=True)


def edit_command() -> click.Command:
    """``featurewarp edit INPUT -m MASK [--handles H.json] [--output OUT] [--port N] [--no-browser]``."""
    params = [
        click.Argument(["input"], type=click.Path(dir_okay=False)),
        click.Option(["-m", "--mask"], type=click.Path(dir_okay=False), metavar="PATH|alpha", help=MASK_HELP),
        click.Option(["--handles"], type=click.Path(dir_okay=False), metavar="H.json",
                     help="Handles file: loaded at start if it exists; Save writes it."),
        click.Option(["-o", "--output"], type=click.Path(dir_okay=False), metavar="OUT",
                     help="Where Export writes the full-resolution image (exactly what "
                          "'featurewarp deform INPUT OUT --handles H.json' writes)."),
        click.Option(["--save-mask"], type=click.Path(dir_okay=False), metavar="PATH",
                     help="Where Save and Export write a mask painted in the page (default: beside -o, "
                          "or beside --handles, as NAME.mask.png)."),
        param_option(PORT),
        click.Option(["--no-browser"], is_flag=True, help="Print the URL only; do not open a browser."),
    ] + [o for o in engine_options() if o.name in KEEP]

    def callback(input, mask, handles, output, save_mask, port, no_browser, **kwargs):
        from ..app.editor import EditorServer, EditorSession
        from ..app.pipeline import WarpError
        from .options import settings_from

        if "-" in (input, handles, output, save_mask):
            raise click.UsageError("the editor reads INPUT again on Export and writes --handles, -o and "
                                   "--save-mask: give files, not '-'")
        kwargs.update(formulation="exact", boundary=None, grow_past_edge=False, strict=False)
        settings, quiet, _ = settings_from(Deform, kwargs)
        try:
            check_files(settings, input, mask, handles, output, save_mask)
            data = load_handles(handles) if handles and os.path.exists(handles) else None
            session = EditorSession(settings, input, mask, handles, output, data, save_mask)
        except WarpError as err:
            raise click_error(err) from err
        except ValueError as err:
            raise click.BadParameter(f"{handles}: {err}", param_hint="'--handles'") from None
        try:
            server = EditorServer(session, port)
        except OSError as err:
            raise click.BadParameter(f"cannot listen on 127.0.0.1:{port}: {err.strerror or err} "
                                     f"(--port 0 takes a free one)", param_hint="'--port'") from None
        serve(server, quiet, no_browser)

    doc = """Edit handles live in the browser: the result follows the pointer.

    Opens INPUT with its mask tinted. Click to add a handle, drag to move it,
    shift-drag to draw a curve handle, Alt-drag near a handle to turn around
    it, shift-click or Ctrl-drag to select several (arrow keys nudge them),
    Alt-click or Delete to remove; drag the square markers to reshape a side
    of the border; paint or erase the mask with the brush; the wheel zooms,
    space-drag pans; Ctrl+Z undoes, Ctrl+Shift+Z or Ctrl+Y redoes. Save
    writes --handles (and a painted mask, --save-mask); Export writes
    --output through exactly the deform pipeline and prints the command that
    replays it (without --handles it writes OUT.handles.json for it). The
    server listens on 127.0.0.1 only and requires the token in the URL it
    prints. Ctrl-C stops it.

    \b
    Example:
      featurewarp edit photo.jpg -m mask.png --handles h.json -o out.jpg
      featurewarp deform photo.jpg out.jpg -m mask.png --handles h.json   # the same bytes
    """
    return click.Command("edit", params=params, callback=callback, help=doc, no_args_is_help=True,
                         short_help="Live editor in the browser for deform's handles.")
