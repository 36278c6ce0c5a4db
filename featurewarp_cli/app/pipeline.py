"""Running warp jobs: one file (``featurewarp warp``) or many, optionally in parallel processes
(``featurewarp batch``). Both go through :func:`warp_file`; a batch only adds output naming,
mask lookup and a process pool. Nothing here depends on click: errors are :class:`WarpError`,
which the command line turns into exit codes."""

from __future__ import annotations

import importlib
import os
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from functools import partial

from .. import plugins, stages
from ..engine.defaults import DECAY, FEATURE_WEIGHT, FORMULATION, INTERPOLATION, MODE, SCALE_PRIOR
from ..io import ImageError, decode, formats, limits
from .masks import load_mask, mask_file, masked, uses_alpha
from .outputs import (background_colour, check_distinct, check_encodable, check_grid_name, check_outputs, depth_lost,
                      encoded, gray_alpha_form, kept_metadata, rendered, write_all)
from .report import refused_report, report_bytes, summary

#: What :func:`prefetch_engine` imports: the engine (grid, features, fold-over guard,
#: renderer), then, for a warp that factors, the solver (scipy.sparse and scikit-sparse).
ENGINE = "featurewarp_cli.engine.warper"
SOLVER = "featurewarp_cli.engine.solver"


class WarpError(Exception):
    """A warp that cannot be done.

    Parameters
    ----------
    message : str
        One line naming the problem.
    param : str, optional
        The argument or option at fault (``INPUT``, ``--mask`` ...).
    usage : bool
        True for a bad invocation (exit 2), False for a failure while processing (exit 1).
    warnings : sequence of str
        The warnings that made ``--strict`` refuse the run (a batch's summary keeps them).
    """

    def __init__(self, message: str, param: str | None = None, usage: bool = False, warnings=()):
        super().__init__(message)
        self.message, self.param, self.usage, self.warnings = message, param, usage, list(warnings)

    def __str__(self) -> str:
        return f"{self.param}: {self.message}" if self.param else self.message


@dataclass(frozen=True)
class Settings:
    """Everything about a warp except its files: the preset, its parameters, engine and output options.

    Attributes
    ----------
    preset : str
        Registered preset name.
    params : dict
        The preset's parameter values by name.
    mode, cell, feature_weight, decay, formulation, boundary, scale_prior, grow_past_edge
        See :class:`featurewarp_cli.engine.warper.FeatureWarper`.
    strict : bool
        Turn the solve's warnings (a feature not kept, features relaxed, an output
        that equals the input) into a failure with nothing written.
    background : str or None
        Colour text for uncovered pixels (see :func:`featurewarp_cli.io.colours.parse_colour`);
        None: transparent where the format has alpha, else white.
    interp : {'nearest', 'linear', 'cubic', 'lanczos'}
    fmt : str or None
        Output format name (``--format``); None: from the output's prefix or extension.
    max_pixels : int
        Largest accepted input width * height.
    max_memory : int or None
        Memory budget in bytes (images and grid; see :func:`limits.node_budget`).
    allow_folds : bool
        Write a result that still has folded triangles instead of failing.
    quality : int or None
        JPEG and WebP quality 1..100 (WebP lossy when given).
    strip : bool
        Drop the input's metadata (ICC profile, EXIF, XMP, resolution) instead of keeping it.
    alpha_mask : bool
        Where no mask is given, INPUT's alpha is its mask (``batch --mask-pattern alpha``; one
        run's ``--mask alpha`` says it by its mask): :mod:`featurewarp_cli.app.masks`.
    warp_factory : callable, optional
        ``warp_factory(width, height, feature_mask)`` gives the warp instead of the preset
        (``deform``'s handles); its ValueError is a usage error; its ``review(mesh)`` gives
        warnings.
    """

    preset: str
    params: dict = field(default_factory=dict)
    mode: str = MODE
    cell: int | None = None
    feature_weight: float = FEATURE_WEIGHT
    decay: float = DECAY
    formulation: str = FORMULATION
    boundary: str | None = None
    scale_prior: float = SCALE_PRIOR
    grow_past_edge: bool = False
    strict: bool = False
    background: str | None = None
    interp: str = INTERPOLATION
    fmt: str | None = None
    max_pixels: int = limits.MAX_PIXELS
    max_memory: int | None = limits.MAX_MEMORY
    allow_folds: bool = False
    quality: int | None = None
    strip: bool = False
    alpha_mask: bool = False
    warp_factory: object = None


def _check_paths(input: str, mask: str | None) -> None:
    """INPUT, then the mask, must be files (or '-'): a missing input is not its mask's fault."""
    for path, param in ((input, "INPUT"), (mask, "--mask")):
        if path not in (None, "-") and not os.path.isfile(path):
            raise WarpError(f"{path} {decode.path_problem(path)}", param, usage=True)


def read_input(path: str, param: str, max_pixels: int | None, data: bytes | None = None,
               max_bytes: int | None = None):
    """Decode an image argument (``-``: stdin; ``data``: its bytes if already read); a missing file
    is a usage error, a bad one a processing error (:class:`WarpError`); ``param`` names it."""
    if path != "-" and not os.path.isfile(path):
        raise WarpError(f"{path} {decode.path_problem(path)}", param, usage=True)
    try:
        if data is not None:
            return decode.decode_image(data, "stdin" if path == "-" else path, max_pixels, max_bytes)
        return decode.read_image(path, max_pixels, max_bytes)
    except ImageError as err:
        raise WarpError(str(err), None if param == "INPUT" else param) from err


def prefetch_engine(solver: bool = True) -> None:
    """Start importing the engine and, with ``solver``, the solver in a thread.

    Called just before the images are decoded: OpenCV releases the GIL while it decodes, so
    the imports run meanwhile instead of after it; the solver's (about 0.15 s, most of it
    scipy.sparse) goes on while the main thread builds the grid and the features. A failed
    import is left to the main thread, whose own import raises the error."""
    modules = [name for name in (ENGINE, SOLVER if solver else None) if name and name not in sys.modules]

    def work():
        try:
            for name in modules:
                importlib.import_module(name)
        except Exception:  # the main thread imports it again and reports the error
            pass

    if modules:
        threading.Thread(target=work, name="featurewarp-prefetch").start()


def load_image_and_mask(settings: Settings, input: str, mask: str | None, data: bytes | None = None):
    """Decode INPUT (from ``data``, its bytes if already read) and its mask, checked against each other.

    Returns
    -------
    image : ndarray
    feature_mask : (h, w) bool ndarray or None
        None without a mask or in plain mode.
    warnings : list of str
    """
    use_mask = masked(settings, mask)
    _check_paths(input, mask_file(settings, mask) if use_mask else None)
    data = input_bytes(settings, input) if data is None else data
    image = read_input(input, "INPUT", settings.max_pixels, data, settings.max_memory)
    height, width = image.shape[:2]
    header = decode.read_header(data) if data else None
    feature_mask, warnings = load_mask(settings, mask, (width, height), header, image) if use_mask else (None, [])
    return image, feature_mask, frames_warning(header) + warnings


def input_bytes(settings: Settings, input: str) -> bytes | None:
    """INPUT's bytes, read once within the limits (stdin's too); None where it is no file."""
    if not (input == "-" or os.path.isfile(input)):
        return None
    if input != "-":
        check_file_size(input, "INPUT", settings.max_memory, settings.max_pixels)
    try:
        return decode.read_bytes(input, settings.max_memory)
    except ImageError as err:
        raise WarpError(str(err)) from err


def frames_warning(header) -> list[str]:
    """The warning for an input of several frames, of which the first is used ([] for one frame;
    a camera's MPO JPEG, the photo and its previews, is one)."""
    if header is None or not header.animated or header.format == "MPO":
        return []
    return ["the input has several frames (animated or multi-page); the first is used"]


def check_file_size(path: str, param: str, max_memory: int | None, max_pixels: int | None) -> None:
    """Before a file is read whole: refuse it when its header (in its first 64 KiB) claims more
    than ``max_pixels`` or the file alone exceeds the memory budget (a sparse file of GBs)."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as handle:
            header = decode.read_header(handle.read(1 << 16))
    except OSError:
        return                                               # reading it says what is wrong
    if max_memory is not None and size > max_memory:
        raise WarpError(f"{path} is {limits.size_text(size, max_memory)}, above the memory limit of "
                        f"{limits.size_text(max_memory)} (--max-memory)")
    if header is not None:
        try:
            limits.check_size(header.width, header.height, path, max_pixels, max_memory)
        except ImageError as err:
            raise WarpError(str(err)) from None


class _Decoding:
    """INPUT decoding in a thread (OpenCV releases the GIL), from ``start()``, once every check
    that needs no pixels has passed: ``result()`` waits for the image."""

    def __init__(self, data: bytes, name: str, max_pixels: int | None, header=None, ahead: bool = False):
        self._image, self._error, self.header, self._done = None, None, header, threading.Event()

        def work():
            try:
                self._image = decode.decode_image(data, name, max_pixels)
            except ImageError as err:
                self._error = WarpError(str(err))
            except BaseException as err:  # re-raised in the main thread
                self._error = err
            finally:
                self._done.set()
            if ahead and self._error is None:     # the render's first octaves while the main thread solves
                importlib.import_module("featurewarp_cli.render.pyramid").prepare(self._image, self)

        self._thread = threading.Thread(target=work, name="featurewarp-decode")

    def start(self):
        self._thread.start()

    def result(self):
        if self._thread.ident is None:
            self.start()
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._image


def _piped(settings: Settings, input: str, output: str, mask: str | None) -> tuple[Settings, bytes | None]:
    """For ``- -`` without --format: settings with stdin's own format, and stdin's bytes (read
    now); else (settings, None). A usage error for INPUT and the mask both on stdin."""
    if mask == "-" and input == "-":
        raise WarpError("cannot be '-' when INPUT is '-' (stdin holds the image)", "--mask", usage=True)
    if not (input == output == "-" and settings.fmt is None):
        return settings, None
    try:
        data = decode.read_bytes("-", settings.max_memory)
    except ImageError as err:
        raise WarpError(str(err)) from None
    header = decode.read_header(data)
    kind = {"MPO": "JPEG"}.get(header.format, header.format) if header is not None else None   # a camera JPEG
    name = formats.format_name(kind) if kind else None
    if name is None:
        if header is None:                    # not an image (empty, text): the decoder says what is wrong
            try:
                decode.decode_image(data, "stdin", settings.max_pixels, settings.max_memory)
            except ImageError as err:
                raise WarpError(str(err)) from None
        raise WarpError("stdout takes stdin's format, and stdin's is not one featurewarp writes; use --format "
                        "or a prefix such as png:-", "OUTPUT", usage=True)
    return replace(settings, fmt=name), data


def start_loading(settings: Settings, input: str, mask: str | None, data: bytes | None = None):
    """Decode the mask, and start decoding INPUT in a thread when its header gives its size.

    The mesh needs only the size and the mask, so the solve runs while the
    image decodes (0.25 s at 12 MP). Errors come out as with
    :func:`load_image_and_mask`: the image's first, then the mask's.

    Returns
    -------
    image : object with ``result()`` -> ndarray (waits; raises WarpError)
    feature_mask : (h, w) bool ndarray or None
    warnings : list of str
    size : (int, int)
        (width, height) of INPUT.
    """
    use_mask = masked(settings, mask)
    _check_paths(input, mask_file(settings, mask) if use_mask else None)
    if input == "-" and data is None:
        data = input_bytes(settings, input)                  # read now: its header keeps its metadata
    header = decode.read_header(data) if data else None
    if input != "-" and os.path.isfile(input):
        check_file_size(input, "INPUT", settings.max_memory, settings.max_pixels)
        try:
            data = decode.read_bytes(input)                  # read once: both paths below use it
        except ImageError:
            pass                                             # reported by the serial path below
        header = decode.read_header(data) if data else None
    if header is None or (use_mask and uses_alpha(settings, mask)) or \
            not limits.fits(header.width, header.height, settings.max_pixels, settings.max_memory):
        image, feature_mask, warnings = load_image_and_mask(settings, input, mask, data)
        return _Ready(image, header), feature_mask, warnings, (image.shape[1], image.shape[0])
    size = header.upright_size
    feature_mask = None
    warnings = frames_warning(header)
    if use_mask:
        try:
            feature_mask, mask_warnings = load_mask(settings, mask, size, header)
            warnings += mask_warnings
        except WarpError:
            load_image_and_mask(settings, input, mask, data)   # the image's own error comes first
            raise
    return (_Decoding(data, "stdin" if input == "-" else input, settings.max_pixels, header,
                      ahead=use_mask and settings.interp != "nearest"), feature_mask, warnings, size)


def _check_decoded_size(image, input: str, width: int, height: int) -> None:
    """A WarpError where INPUT decoded to another size than its header gave (the solve's)."""
    if image.shape[:2] != (height, width):
        raise WarpError(f"{'stdin' if input == '-' else input} decodes to {image.shape[1]}x{image.shape[0]}, "
                        f"its header says {width}x{height}")


class _Ready:
    def __init__(self, image, header=None):
        self._image = image
        self.header = header

    def start(self):
        pass

    def result(self):
        return self._image


def make_warper(settings: Settings, width: int, height: int, feature_mask):
    """The preset's warp for this image size and a FeatureWarper (bad options: WarpError)."""
    from ..engine.warper import FeatureWarper

    try:
        if settings.warp_factory is not None:
            warp = settings.warp_factory(width, height, feature_mask)
        else:
            warp = plugins.load(settings.preset)(width, height, **settings.params)
    except plugins.UnknownPreset as err:
        raise WarpError(str(err), usage=True) from None
    except plugins.ParamError as err:           # the API names parameters, the command line its flags
        raise WarpError(err.render(plugins.option_flag), usage=True) from None
    except ValueError as err:
        raise WarpError(str(err), usage=True) from None
    try:
        limits.check_pixels(*warp.canvas, "the output canvas", settings.max_pixels)
        max_nodes = limits.node_budget(width, height, tuple(warp.canvas), settings.max_memory)
    except ImageError as err:
        raise WarpError(str(err)) from None
    try:
        warper = FeatureWarper(width, height, feature_mask, cell=settings.cell,
                               feature_weight=settings.feature_weight, decay=settings.decay,
                               formulation=settings.formulation, boundary=settings.boundary,
                               scale_prior=settings.scale_prior, max_nodes=max_nodes,
                               grow_past_edge=settings.grow_past_edge)
    except ValueError as err:
        raise WarpError(str(err), usage=True) from None
    return warp, warper


def solve_within_budget(warper, warp, mode: str):
    """``warper.solve(warp, mode)``, the warp's own ``review`` of the mesh (deform's: handles
    reached, an image laid over itself) joining its warnings; a grid above the memory budget
    is a WarpError (exit 1)."""
    from ..engine.fidelity import GridBudgetError

    try:
        mesh = warper.solve(warp, mode)
        mesh = warp.land(mesh, lambda aimed: warper.solve(aimed, mode)) if hasattr(warp, "land") else mesh
    except GridBudgetError as err:
        raise WarpError(str(err)) from None
    if getattr(warp, "review", None) is not None:
        mesh.record.warnings.extend(warp.review(mesh))
    return mesh


def check_solution(settings: Settings, mesh, refused=None) -> None:
    """WarpError when the solve left folded triangles (unless ``allow_folds``) or, under
    ``strict``, when it warned (the loading's warnings among its own: :func:`warp_file`):
    nothing is written then but what ``refused`` writes, called first with the error and the
    warnings that caused it (``warp_file``: the ``--report``, marked refused)."""
    error, causes = refusal(settings, mesh)
    if error is None:
        return
    if refused is not None:
        said = error.replace("nothing written", "nothing written but the report", 1)
        try:
            refused(said, causes)
            error = said
        except WarpError as err:                 # the refusal is still what is said first
            error = f"{error} ({err})"
    raise WarpError(error, warnings=causes)


def refusal(settings: Settings, mesh) -> tuple[str | None, list[str]]:
    """Why :func:`check_solution` refuses ``mesh`` (None: it does not), and the warnings that
    cause it (``strict``'s: all of them; none for folds)."""
    folded, crossings = mesh.flips(), getattr(mesh, "crossings", 0)
    if folded and not settings.allow_folds:
        return (f"the result has {folded} folded triangles (the warp turns the image over itself "
                f"there); nothing written (--allow-folds writes it anyway)"), []
    if crossings and not settings.allow_folds:
        times = "once" if crossings == 1 else f"{crossings} times"
        cause = getattr(mesh, "fold_cause", "handles dragged across each other or a pin's path, or turned far, do that")
        return (f"the result lays the image over itself (its border crosses itself {times}; {cause}): nothing "
                f"written (--allow-folds writes it)"), []
    if settings.strict and mesh.record.warnings:
        return f"--strict: {mesh.record.warnings[0]}; nothing written", list(mesh.record.warnings)
    return None, []


def warp_file(settings: Settings, input: str, output: str, mask: str | None = None,
              report: str | None = None, save_grid: str | None = None, draw_grid: bool = False,
              also_read: tuple = ()) -> dict:
    """Load, warp, render and write one image (the body of ``featurewarp warp PRESET``).

    Every check that needs no pixels runs before anything is decoded, and the output is written
    atomically, so a failure leaves no partial file and an existing OUTPUT untouched. OUTPUT may be INPUT.

    Parameters
    ----------
    settings : Settings
    input : str
        Image path, ``-`` for stdin (a ``png:``-style prefix is ignored: the format is sniffed).
    output : str
        Image path, ``-`` for stdout, optionally with a ``png:``-style format prefix.
    mask : str, optional
        Mask path (``-``: stdin, unless INPUT is stdin), ``alpha`` (INPUT's), None: plain warp.
    report : str, optional
        Where to write the JSON report.
    save_grid : str, optional
        Where to write the mesh: ``.npz`` (``source``, ``target``, ``triangles``) or ``.obj``.
    draw_grid : bool
        Draw the deformed grid over the result.
    also_read : tuple of (path, option)
        Other files the run reads (deform's ``--handles``): no output may name them.

    Returns
    -------
    dict
        Summary for ``--verbose``: input and output size, solver, feature
        components, flipped triangles, seconds, and warnings.

    Raises
    ------
    WarpError
    """
    t0 = time.perf_counter()
    input = formats.split_prefix(input)[1]
    settings, piped = _piped(settings, input, output, mask)
    out_path, fmt = check_outputs(settings, output, (report, "--report"), (save_grid, "--save-grid"),
                                  like=input)
    check_distinct([(out_path, "OUTPUT"), (report, "--report"), (save_grid, "--save-grid")],
                   [(input, "INPUT"), (mask_file(settings, mask), "--mask"), *also_read])
    check_grid_name(save_grid)
    background = background_colour(settings.background, fmt)
    prefetch_engine(solver=masked(settings, mask))
    pending, feature_mask, warnings, (width, height) = start_loading(settings, input, mask, piped)
    header = getattr(pending, "header", None)
    kept = kept_metadata(settings.strip, header, fmt, warnings)   # --strict sees it
    timings = {"load": time.perf_counter() - t0}
    warp, warper = make_warper(settings, width, height, feature_mask)    # the canvas and the budget, undecoded
    check_encodable(warp.canvas, fmt)
    pending.start()
    try:
        mesh = solve_within_budget(warper, warp, settings.mode)
    finally:
        t1 = time.perf_counter()
        image = pending.result()               # a decoding error outranks any from the solve
        timings["load"] += time.perf_counter() - t1
    _check_decoded_size(image, input, width, height)
    mesh.record.warnings[:0] = warnings + depth_lost(image, fmt)    # the loading's and the depth: said, refused
    stored = gray_alpha_form(image, header)    # the report's INPUT: gray + alpha as stored, not as decoded (BGRA)
    check_solution(settings, mesh, partial(refused_report, report, input, out_path, stored, warp, mesh, timings, t0,
                                           fmt) if report else None)   # a CI gate reads why: the report, no image
    result = rendered(warper, image, mesh, settings.interp, background, header, draw_grid)
    timings.update(mesh.info["timings"])
    stages.enter("write")
    t1 = time.perf_counter()
    outputs = [(out_path, encoded(out_path, fmt, result, background, settings.quality, kept))]
    timings["write"] = time.perf_counter() - t1
    if save_grid:
        outputs.append((save_grid, mesh.to_obj() if save_grid.lower().endswith(".obj") else mesh.to_npz()))
    if report:
        outputs.append((report, report_bytes(input, out_path, stored, result, warp, mesh, timings, t0, fmt,
                                             transparent=background is None)))
    write_all(outputs)
    return summary(settings.preset, mesh.record.mode, input, out_path, (width, height), mesh, t0,
                   list(mesh.record.warnings))
