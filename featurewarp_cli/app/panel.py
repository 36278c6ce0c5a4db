"""Pictures that explain a warp: the deformed grid drawn over a result, labelled panels, and
the ``compare`` command's four-way panel (:func:`compare_file`)."""

from __future__ import annotations

import cv2
import numpy as np

from ..io.depth import to_eight_bit

GRID_COLOUR = (255, 200, 0)        # BGR: light blue
MASK_TINT = (60, 60, 255)          # BGR: red


def as_bgr8(image: np.ndarray) -> np.ndarray:
    """An 8-bit BGR version of any gray/BGR/BGRA, 8/16-bit image (alpha over a checkerboard)."""
    image = to_eight_bit(image)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.shape[2] == 4:
        y, x = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
        checker = np.where(((x // 8) + (y // 8)) % 2 == 0, 200, 150).astype(np.float32)[:, :, None]
        alpha = image[:, :, 3:4].astype(np.float32) / 255.0
        return (image[:, :, :3] * alpha + checker * (1.0 - alpha)).astype(np.uint8)
    return image


def draw_grid(image: np.ndarray, mesh, spacing_px: float | None = None) -> np.ndarray:
    """Draw the deformed grid lines over ``image`` (a copy), its depth, background and alpha kept.

    Every k-th grid line is drawn so that lines are about ``spacing_px`` apart
    in the source (the paper's Fig. 3); default: 1/20 of the source's shorter
    side, at least 12 px. The lines are antialiased and laid over the image (a line is
    opaque where it covers a pixel whole); a gray image becomes BGR for their colour.
    (The lines were drawn on an 8-bit BGR copy: ``--grid`` dropped a transparent or
    translucent ``--background``, a cut-out's alpha and 16 bits, in silence.)

    Parameters
    ----------
    image : (H, W[, C]) ndarray, uint8 or uint16, C in 1..4
        The warped image (on the mesh's canvas), BGR(A); C = 2: gray + alpha.
    mesh : api.Mesh
    spacing_px : float

    Returns
    -------
    (H, W, 3 or 4) ndarray of ``image``'s dtype
    """
    grid_x = np.unique(mesh.source[:, 0])
    grid_y = np.unique(mesh.source[:, 1])
    if spacing_px is None:
        spacing_px = max(12.0, min(np.ptp(grid_x), np.ptp(grid_y)) / 20.0)
    nx, ny = grid_x.size, grid_y.size
    nodes = mesh.target.reshape(ny, nx, 2)
    step_x = max(1, round(spacing_px / max(grid_x[1] - grid_x[0], 1e-9))) if nx > 1 else 1
    step_y = max(1, round(spacing_px / max(grid_y[1] - grid_y[0], 1e-9))) if ny > 1 else 1
    rows = list(range(0, ny, step_y)) + [ny - 1]
    cols = list(range(0, nx, step_x)) + [nx - 1]
    lines = [nodes[j, :, :] for j in rows] + [nodes[:, i, :] for i in cols]
    shift = 4                                       # sub-pixel precision for polylines
    polylines = [np.round(line * (1 << shift)).astype(np.int32) for line in lines]
    cover = np.zeros(image.shape[:2], np.uint8)
    cv2.polylines(cover, polylines, False, 255, 1, cv2.LINE_AA, shift)
    return _lines_over(image, cover)


def _lines_over(image: np.ndarray, cover: np.ndarray) -> np.ndarray:
    """``image`` (BGR(A), gray or gray + alpha; as BGR(A)) with :data:`GRID_COLOUR` laid over it
    where ``cover`` (uint8, 255: whole) says, by the over operator on straight alpha."""
    planes = image.shape[2] if image.ndim == 3 else 1
    if planes <= 2:
        gray = image if image.ndim == 2 else image[:, :, 0]
        out = np.dstack([gray] * 3 + ([image[:, :, 1]] if planes == 2 else []))
    else:
        out = image.copy()
    top = float(np.iinfo(out.dtype).max)
    at = np.flatnonzero(cover)
    flat = out.reshape(-1, out.shape[2])
    a = cover.ravel()[at, None] / 255.0
    values, colour = flat[at].astype(np.float64), np.array(GRID_COLOUR, np.float64) * (top / 255.0)
    if out.shape[2] == 4:
        alpha = values[:, 3:] / top
        covered = a + alpha * (1.0 - a)
        values[:, :3] = (colour * a + values[:, :3] * alpha * (1.0 - a)) / np.maximum(covered, 1e-12)
        values[:, 3:] = covered * top
    else:
        values = colour * a + values * (1.0 - a)
    flat[at] = np.rint(values).astype(out.dtype)
    return out


def tint(image: np.ndarray, mask: np.ndarray | None, strength: float = 0.45) -> np.ndarray:
    """``image`` (8-bit BGR copy) with the feature ``mask`` tinted red."""
    out = as_bgr8(image).copy()
    if mask is not None and mask.any():
        tinted = out[mask].astype(np.float32) * (1.0 - strength) + np.array(MASK_TINT) * strength
        out[mask] = tinted.astype(np.uint8)
    return out


#: A panel's caption bar height and the gap between its views, in pixels, at the label's
#: smallest font scale (:data:`FONT`); taller views get larger labels (:func:`label_font`).
CAPTION_BAR, GAP = 28, 8
#: The labels' font scale (OpenCV's Hershey simplex) on views up to :data:`FONT_HEIGHT` px tall,
#: larger in proportion above it (a fixed 0.55 was a few hundredths of a 12 MP panel's height),
#: and the smallest it takes to fit a narrow view.
FONT, FONT_HEIGHT, SMALLEST_FONT = 0.55, 720, 0.3


def label_font(height: int) -> float:
    """The labels' font scale on views ``height`` pixels tall."""
    return FONT * max(1.0, height / FONT_HEIGHT)


def caption_bar(height: int) -> int:
    """The caption bar's height, in pixels, above views ``height`` pixels tall."""
    return round(CAPTION_BAR * label_font(height) / FONT)


def panel_size(sizes: list[tuple[int, int]], width: int | None = None) -> tuple[int, int]:
    """(width, height) of the :func:`labelled_panel` of views of these (width, height) sizes."""
    natural = sum(w for w, _ in sizes)
    scale = 1.0 if width is None else max(1, width - GAP * (len(sizes) - 1)) / natural
    edges = np.round(np.cumsum([0] + [w for w, _ in sizes]) * scale).astype(int)
    height = max(max(1, round(h * scale)) for _, h in sizes)
    return int(np.maximum(np.diff(edges), 1).sum()) + GAP * (len(sizes) - 1), height + caption_bar(height)


def fit_labels(labels: list, widths: list[int], height: int) -> tuple[list[str], float]:
    """Each view's label and the font scale they share, so that the views of a narrow or tall
    panel are still told apart ("featurewarp rigi" | "featur" were cut at the view's edge).

    Each label (a str, or its forms longest first) is written in its longest form that fits its
    view's width, at :func:`label_font` or, where that fits more of the labels' text, at
    :data:`FONT`; a view too narrow for even the shortest form shrinks the font (to
    :data:`SMALLEST_FONT`) until it fits.
    """
    forms = [[label] if isinstance(label, str) else list(label) for label in labels]

    def wide(text, scale):
        return cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0]

    def choose(font):
        room = [max(1, across - 2 * round(6 * font / FONT)) for across in widths]
        chosen = [next((text for text in options if wide(text, font) <= space), options[-1])
                  for options, space in zip(forms, room)]
        for text, space in zip(chosen, room):
            font = max(SMALLEST_FONT, min(font, font * space / max(1, wide(text, font))))
        return chosen, font

    tried = [choose(font) for font in dict.fromkeys((label_font(height), FONT))]
    return max(tried, key=lambda pair: (sum(map(len, pair[0])), pair[1]))


def check_panel(settings, size: tuple[int, int], fmt: str) -> None:
    """WarpError before any work where the panel (``size``) is more than ``fmt`` holds, more
    pixels than four views of ``--max-pixels`` each, or more bytes than ``--max-memory`` allows
    (the panel, its views scaled to it and its encoding, in 8-bit BGR: 4 times its own bytes,
    above the 3.1 measured at 12 000 px across)."""
    from ..io import limits
    from .outputs import check_encodable
    from .pipeline import WarpError

    check_encodable(size, fmt)
    pixels = size[0] * size[1]
    if settings.max_pixels is not None and pixels > 4 * settings.max_pixels:
        raise WarpError(f"the panel is {size[0]}x{size[1]} = {pixels} pixels, above four views of the limit of "
                        f"{settings.max_pixels} (--max-pixels; a smaller --panel-width)")
    need = pixels * 3 * 4
    if settings.max_memory is not None and need > settings.max_memory:
        raise WarpError(f"the {size[0]}x{size[1]} panel needs about {limits.size_text(need, settings.max_memory)}, "
                        f"above the memory limit of {limits.size_text(settings.max_memory)} (--max-memory; a smaller "
                        f"--panel-width)")


def labelled_panel(images: list[np.ndarray], labels: list, width: int | None = None) -> np.ndarray:
    """Side-by-side panel of ``images``, each with a caption bar.

    Each view keeps its own pixels (a retoucher judges pixels): the panel is as tall as
    the tallest, shorter views padded with white. ``width``: scale the whole panel to that
    many pixels across instead (a small panel for a page). ``labels``: each view's, a str or
    its forms longest first, written in the longest that fits (:func:`fit_labels`).

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    gap = GAP
    images = [as_bgr8(image) for image in images]
    natural = sum(image.shape[1] for image in images)
    scale = 1.0 if width is None else max(1, width - gap * (len(images) - 1)) / natural
    height = max(max(1, round(image.shape[0] * scale)) for image in images)
    bar = caption_bar(height)
    edges = np.round(np.cumsum([0] + [image.shape[1] for image in images]) * scale).astype(int)
    widths = [int(across) for across in np.maximum(np.diff(edges), 1)]
    labels, font = fit_labels(labels, widths, height)
    step = font / FONT                    # the margins and stroke grow with the font
    tiles = []
    for image, label, across in zip(images, labels, widths):
        size = (across, max(1, round(image.shape[0] * scale)))
        if scale != 1.0:
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC)
        tile = np.full((height, size[0], 3), 255, np.uint8)
        tile[:size[1]] = image
        caption = np.full((bar, size[0], 3), 255, np.uint8)
        cv2.putText(caption, label, (round(6 * step), bar - round(9 * step)), cv2.FONT_HERSHEY_SIMPLEX, font,
                    (30, 30, 30), max(1, round(step)), cv2.LINE_AA)
        tiles.append(np.vstack([caption, tile]))
        tiles.append(np.full((height + bar, gap, 3), 255, np.uint8))
    return np.hstack(tiles[:-1])


#: Each view's label, longest first (:func:`fit_labels`): ``{preset}`` is the preset's name.
LABELS = {"input + mask": ("input + mask", "input", "in"), "input": ("input", "in"),
          "plain": ("plain {preset}", "plain", "P"), "rigid": ("featurewarp rigid", "rigid", "R"),
          "similarity": ("featurewarp similarity", "similarity", "simil.", "S")}


def compare_file(settings, input: str, output: str, mask: str | None = None,
                 with_grid: bool = False, panel_width: int | None = None) -> dict:
    """Write one labelled panel: input with the mask tinted | plain | rigid | similarity.

    The three warps share one grid and one factorization. Every view keeps the input's
    resolution unless ``panel_width`` scales the panel to that many pixels across; ``with_grid``
    draws the deformed grid over the three results. Other
    arguments as for :func:`featurewarp_cli.app.pipeline.warp_file`; ``settings.mode`` is ignored.

    Returns
    -------
    dict
        :func:`featurewarp_cli.app.report.summary` of the similarity result; its warnings are
        every view's, each line naming its view.
    """
    import time
    from dataclasses import replace

    from ..engine.assess import STILL
    from ..engine.record import LISTED_IN_REPORT
    from ..io import formats
    from .animate import load_with_header
    from .outputs import background_colour, check_distinct, encoded, kept_metadata, rendered, write_all
    from .pipeline import (WarpError, check_outputs, check_solution, make_warper, prefetch_engine,
                           solve_within_budget)
    from .report import summary

    t0 = time.perf_counter()
    input = formats.split_prefix(input)[1]
    out_path, fmt = check_outputs(settings, output, like=input)
    check_distinct([(out_path, "OUTPUT")], [(input, "INPUT"), (mask, "--mask")])
    background = background_colour(settings.background, fmt)
    settings = replace(settings, mode="similarity")
    prefetch_engine()
    image, feature_mask, warnings, header = load_with_header(settings, input, mask)
    kept = kept_metadata(settings.strip, header, fmt, warnings)        # the views are in the input's colours
    height, width = image.shape[:2]
    warp, warper = make_warper(settings, width, height, feature_mask)
    check_panel(settings, panel_size([(width, height)] + [tuple(warp.canvas)] * 3, panel_width), fmt)
    tiles, labels = [tint(image, feature_mask)], [LABELS["input + mask" if feature_mask is not None else "input"]]
    if mask is None:
        warnings.append("no --mask: the rigid and similarity views are the plain warp (--mask marks the features "
                        "they keep)")
    if image.dtype == np.uint16:
        warnings.append("the input has 16 bits a sample; the comparison panel has 8 (warp keeps 16 bits)")
    for mode in ("plain", "rigid", "similarity"):
        mesh = solve_within_budget(warper, warp, mode)
        check_solution(replace(settings, strict=False), mesh)
        for line in mesh.record.warnings:         # the grid's and the warp's own: said once, for all views
            line = line.replace(LISTED_IN_REPORT, "")     # compare writes no report
            if "strays up to" not in line and not line.startswith(STILL):
                warnings.append(f"{mode} view: {line}")
            elif mode == "plain":
                warnings.append(f"all views: {line}")
        if settings.strict and warnings:          # named with its view
            raise WarpError(f"--strict: {warnings[0]}; nothing written")
        result = rendered(warper, image, mesh, settings.interp, background)
        tiles.append(draw_grid(result, mesh) if with_grid else result)
        labels.append(tuple(form.format(preset=settings.preset) for form in LABELS[mode]))
    panel = labelled_panel(tiles, labels, panel_width)
    write_all([(out_path, encoded(out_path, fmt, panel, (255, 255, 255), settings.quality, kept))])
    return summary(settings.preset, "compare", input, out_path, (width, height), mesh, t0, warnings)
