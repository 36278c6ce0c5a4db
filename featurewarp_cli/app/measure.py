"""Distortion measured on the output image: an affine fit of keypoints per masked region.

The mesh says how the tool meant to move each feature; this module checks what the
written image shows. For every connected component of the input mask it matches SIFT
keypoints found inside the component (input) with keypoints of the whole output,
keeps the matches that pass Lowe's ratio test, and fits an affine map
input -> output with RANSAC (``cv2.estimateAffine2D``). The component's map is then the
least-squares affine fit over all its locally consistent matches (below): for a component
moved as one map that is the RANSAC map with less noise; for a bent one it is the best
single map over the whole component, as the report's ``distortion`` is over the mesh's
nodes, where RANSAC would speak for the largest part that moved as one. The linear part A
of that map gives the component's

* distortion  sigma_max / sigma_min - 1 of A: 0 for a similarity, 1 for 2x along one axis;
* scale       sqrt(|det A|);
* rotation    the angle of A's closest rotation, degrees, clockwise on screen (y down).

SIFT is rotation invariant but not affine invariant. Two steps keep the fit exact
under strong anisotropy: when plain matching gives no fit, simulated tilted views of
the component are matched too (as ASIFT does); and the output is then rectified by
the fit so far and matched again, where the residual map is near the identity
(validated: within 0.01 of exact affine maps of sigma ratio up to 2, at any rotation).
The rectified output is compared with the input's own box, keypoints found on both cut
the same way, and keypoints whose support reaches where the output has no pixels are
left out on both sides: an image measured against itself gives exactly 0, a feature
cut by the frame included.

A component that did not move as one affine map (a swirl turns the middle of a large
component and leaves its rim: RANSAC then fits the rim) is told apart by local fits:
each match's neighbourhood gets its own affine fit; ``explained`` is the share of the
locally consistent matches that the global map fits, and ``local_p90`` the 90th
percentile of the local distortions (the counterpart of the mesh's per-triangle
anisotropy). A component with too few matches gets no figures and a reason instead:
a number made up from three keypoints would be worse than none. So does one whose
matches fix its shape too loosely: ``noise`` is the distortion that their scatter alone
gives the fit (few matches, bunched, or along the frame that cuts the component), and a
figure is given only where it is at most :data:`NOISE_LIMIT`, or where the distortion is
at least :data:`SIGNAL` times it (a bent region's, say). Matches count once per output
keypoint (simulated views match one from several views).

Only numpy and OpenCV (SIFT is in OpenCV's main module since 4.4).

Examples
--------
A random texture stretched 2x along x: the square region in its middle comes out with
distortion 1 (sigma ratio 2) and scale sqrt(2). Turned a quarter counter-clockwise on
screen, it keeps its shape (distortion 0) and is rotated by -90 degrees.

>>> rng = np.random.default_rng(0)
>>> image = cv2.resize(rng.integers(0, 256, (30, 30), dtype=np.uint8), (240, 240))
>>> mask = np.zeros((240, 240), bool); mask[40:200, 40:200] = True
>>> fit, = measure(image, cv2.resize(image, (480, 240), interpolation=cv2.INTER_CUBIC), mask)
>>> round(fit.distortion, 2), round(fit.scale, 2)
(1.0, 1.41)
>>> fit, = measure(image, np.rot90(image), mask)
>>> round(fit.distortion, 2), round(fit.rotation)
(0.0, -90)
"""

from __future__ import annotations

import dataclasses

from dataclasses import dataclass

import cv2
import numpy as np

from ..io.depth import to_eight_bit
from .keypoints import (FLAT_GRAY, RATIO, Keypoints, detect, distinct, local_fits, refine, seed, tilts,
                        view_matches)

#: Fewest RANSAC inliers for a fit; below this a component gets a reason, not figures.
MIN_INLIERS = 10
#: RANSAC's reprojection threshold in output pixels.
REPROJECTION_PX = 3.0
#: A match enters the component's least-squares map when its neighbourhood's map holds it
#: this close (pixels of the images measured, as keypoints are located there).
FIT_PX = 1.0
#: A fit whose inliers are fewer than this share of its matches, or whose inliers span
#: less than this share of the component, is taken as bent: simulated views then add
#: matches for the local figures.
BENT_INLIERS = 0.9
BENT_COVERAGE = 0.5
#: Both images are scaled down by one common factor so that neither exceeds this many
#: pixels (the linear part of the fit does not change under a common scale).
MAX_PIXELS = 4_000_000
#: A component's figures are given when the distortion its matches' scatter alone would
#: give (``noise``) is at most this, or the distortion measured is at least SIGNAL times
#: it and the map is confirmed by the matches' neighbourhoods (not RANSAC's alone: ten
#: false matches that agree within its 3 px made one): else the figure could be noise.
NOISE_LIMIT = 0.005
SIGNAL = 3.0


@dataclass(frozen=True)
class ComponentFit:
    """The affine map fitted to one masked component, input -> output.

    Attributes
    ----------
    label : int
        1-based label of the component (8-connected, ordered as OpenCV labels them:
        by the first pixel in row-major order).
    pixels : int
        Area of the component in the input, in pixels.
    bbox : tuple of int
        (x, y, width, height) of the component in the input.
    centre : tuple of float
        (x, y): its pixels' mean position in the input, as the report's ``at`` and the warnings'
        "around (x, y)" place a feature (whose numbering, on the grid's quads, is its own).
    matches : int
        Keypoint matches that passed the ratio test (over every matching pass).
    inliers : int
        Matches the map was fitted to: those their neighbourhood's map holds within
        :data:`FIT_PX` (RANSAC's inliers when too few are).
    linear : (2, 2) ndarray or None
        A, the linear part (output = A @ input + translation).
    translation : (2,) ndarray or None
    distortion : float or None
        sigma_max / sigma_min - 1 of A.
    scale : float or None
        sqrt(|det A|).
    rotation : float or None
        Degrees, clockwise on screen, of A's closest rotation (in (-180, 180]).
    stretches : tuple of float or None
        (sigma_max, sigma_min) of A.
    reflected : bool
        det A < 0 (the output shows the component mirrored).
    rms_px : float or None
        Root mean square distance, in output pixels, of those matches from the map (large
        for a bent component: no one map fits it).
    coverage : float or None
        Area of the convex hull of RANSAC's inliers over the component's area.
    explained : float or None
        Share of the component's locally consistent matches (see ``local_p90``) that
        the fitted map puts within :data:`REPROJECTION_PX`: near 1 when the component
        moved as one affine map, lower when it was bent (a swirl leaves the rim of a
        large component in place and turns its middle: no one map then fits both).
    local_p90, local_median : float or None
        90th percentile and median, over the matches, of the distortion of an affine
        map fitted to each match's neighbourhood (radius max(24 px, sqrt(area) / 4)):
        the image's counterpart of the mesh's per-triangle anisotropy.
    local_scales : tuple of float or None
        10th, 50th and 90th percentiles of the local fits' scale sqrt(|det|): a
        similarity gives three equal values; a part crushed to save the rest shows
        as a low first value. Neighbourhoods whose matches are bunched in a spot or
        along a line fix no map and are left out of these three figures.
    noise : float or None
        The distortion that the scatter of the matches alone gives the map (its mean:
        see :func:`shape_noise`): the figure's noise floor; 0 for an image measured
        against itself.
    reason : str or None
        Why there are no figures (too few matches or inliers, or a shape they fix too
        loosely), else None.
    lands_on : tuple of int
        Labels of other measured components whose own maps claim the output spot this one's
        map puts its centre on (:func:`collisions`): a warp keeps apart what the mask keeps
        apart, so one of the two matched the other's likeness (the same subject twice).
    """

    label: int
    pixels: int
    bbox: tuple
    centre: tuple = ()
    matches: int = 0
    inliers: int = 0
    linear: np.ndarray | None = None
    translation: np.ndarray | None = None
    distortion: float | None = None
    scale: float | None = None
    rotation: float | None = None
    stretches: tuple | None = None
    reflected: bool = False
    rms_px: float | None = None
    coverage: float | None = None
    explained: float | None = None
    local_p90: float | None = None
    local_median: float | None = None
    local_scales: tuple | None = None
    noise: float | None = None
    reason: str | None = None
    lands_on: tuple = ()

    def as_dict(self) -> dict:
        """JSON-ready figures (arrays as nested lists, floats rounded to 6 decimals)."""
        out = {}
        for name, value in self.__dict__.items():
            if isinstance(value, np.ndarray):
                value = np.round(value, 6).tolist()
            elif isinstance(value, float):
                value = round(value, 6)
            elif isinstance(value, tuple):
                value = [round(v, 6) if isinstance(v, float) else v for v in value]
            out[name] = value
        return out


def gray8(image: np.ndarray) -> np.ndarray:
    """An 8-bit single-channel version of a gray/BGR/BGRA, 8/16-bit image.

    Alpha is composited over a flat :data:`FLAT_GRAY`, so that the edge of a
    transparent canvas looks like any other edge.
    """
    image = to_eight_bit(image)            # ValueError for other sample types
    if image.ndim == 2:
        return image
    if image.shape[2] == 4:
        alpha = image[:, :, 3:].astype(np.float32) / 255.0
        image = (image[:, :, :3] * alpha + FLAT_GRAY * (1.0 - alpha) + 0.5).astype(np.uint8)
    if image.shape[2] == 1:
        return image[:, :, 0]
    if image.shape[2] == 2:
        return image[:, :, 0]
    return cv2.cvtColor(image[:, :, :3], cv2.COLOR_BGR2GRAY)


def describe(linear: np.ndarray) -> dict:
    """Distortion, scale, rotation, stretches and reflection of a 2x2 linear map.

    Examples
    --------
    >>> d = describe(np.array([[2.0, 0.0], [0.0, 1.0]]))
    >>> round(d["distortion"], 6), round(d["scale"], 6), round(d["rotation"], 6)
    (1.0, 1.414214, 0.0)
    """
    u, sigma, vt = np.linalg.svd(linear)
    reflected = bool(np.linalg.det(linear) < 0)
    if reflected:                       # the closest rotation of a mirrored map
        u = u.copy()
        u[:, -1] *= -1
    rotation = u @ vt
    distortion = float(sigma[0] / sigma[1] - 1.0) if sigma[1] > 0 else float("inf")
    return {      # below 1e-12: the SVD's rounding (the identity read 3e-15, failing --max-distortion 0)
        "distortion": 0.0 if distortion < 1e-12 else distortion,
        "scale": float(np.sqrt(abs(np.linalg.det(linear)))),
        "rotation": float(np.degrees(np.arctan2(rotation[1, 0], rotation[0, 0]))),
        "stretches": (float(sigma[0]), float(sigma[1])),
        "reflected": reflected,
    }


def fit_component(gray_in, gray_out, component, src: Keypoints, dst: Keypoints, opts: dict) -> dict:
    """Fit one component (a uint8 mask of the input): figures for :class:`ComponentFit`."""
    ys, xs = np.nonzero(component)
    margin = 16
    box = (max(0, xs.min() - margin), max(0, ys.min() - margin),
           min(component.shape[1], xs.max() + margin + 1), min(component.shape[0], ys.max() + margin + 1))
    first = fit = seed(gray_in, component, box, dst, src, opts)
    if isinstance(fit, str):
        return {"reason": fit}
    if opts["refinements"]:
        x0, y0, x1, y1 = box
        in_box = detect(gray_in[y0:y1, x0:x1]).shifted(x0, y0)
        in_box = in_box.subset(inside(component, in_box.points))
    for _ in range(opts["refinements"]):
        fit = refine(gray_out, box, in_box, fit, opts) or fit
    keep = fit.inlier
    linear, translation = fit.matrix[:, :2], fit.matrix[:, 2]
    residual = fit.src[keep] @ linear.T + translation - fit.dst[keep]
    hull = cv2.contourArea(cv2.convexHull(fit.src[keep].astype(np.float32)))
    coverage = float(min(1.0, hull / len(xs)))
    pairs = [(first.src, first.dst), (fit.src, fit.dst)]
    # Bent or partly fitted (the inliers span less than half the component's keypoints:
    # the frame, where SIFT finds none, does not count): where SIFT's plain views miss,
    # simulated tilts find matches for the local figures.
    spanned = hull / max(1.0, cv2.contourArea(cv2.convexHull(src.points.astype(np.float32))))
    if keep.mean() < BENT_INLIERS or spanned < BENT_COVERAGE:
        pairs.append(view_matches(gray_in, component, box, dst, opts["ratio"],
                                  [view for views in tilts() for view in views]))
    local = local_figures(pairs, fit.matrix, len(xs), opts)
    matrix, fitted = local.pop("matrix"), local.pop("fitted")
    linear, translation = matrix[:, :2], matrix[:, 2]
    ransac = (int(keep.sum()), len(fit.src), float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))),
              shape_noise(fit.src[keep], residual, fit.matrix[:, :2]))
    used, matches, rms, noise = fitted or ransac
    shape = describe(linear)
    fixed = f"only to about {noise:.3f}" if np.isfinite(noise) else "not at all"
    if noise > NOISE_LIMIT and shape["distortion"] < SIGNAL * noise:
        return {"reason": f"its {used} matches fix the distortion {fixed}, and "
                          f"{shape['distortion']:.3f} is within {SIGNAL:g} times that"}
    if noise > NOISE_LIMIT and fitted is None:
        return {"reason": f"its {used} matches fix the distortion {fixed}, and fewer "
                          f"than {opts['min_inliers']} are confirmed by their neighbourhoods"}
    return shape | local | {
        "matches": matches, "inliers": used, "linear": linear, "translation": translation,
        "rms_px": rms, "coverage": coverage, "noise": noise,
    }


def inside(component: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: the points whose nearest pixel is on ``component`` (nonzero)."""
    cols = np.clip(np.rint(points[:, 0]).astype(int), 0, component.shape[1] - 1)
    rows = np.clip(np.rint(points[:, 1]).astype(int), 0, component.shape[0] - 1)
    return component[rows, cols] > 0


def local_figures(pairs, matrix: np.ndarray, pixels: int, opts: dict) -> dict:
    """How much of the component the global fit explains, and its local distortion.

    The matched (input, output) positions in ``pairs`` are pooled and each gets a
    local affine fit over a neighbourhood of radius max(24 px, sqrt(area) / 4).
    ``explained`` is the share of locally consistent matches that the global map
    ``matrix`` also fits; ``local_p90`` and ``local_median`` are the 90th percentile and
    the median of the local fits' distortion, ``local_scales`` the 10th, 50th and 90th
    percentiles of their scale. ``matrix`` comes back as the least-squares affine fit
    (2 x 3) over the locally consistent matches (unchanged when they are too few), and
    ``explained`` is measured against it.
    """
    pooled = np.hstack([np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs])])
    _, once = np.unique(np.round(pooled, 2), axis=0, return_index=True)
    src, dst = distinct(pooled[np.sort(once), :2], pooled[np.sort(once), 2:])
    radius = max(24.0 * opts["scale"], 0.25 * np.sqrt(pixels))
    consistent, linear, _ = local_fits(src, dst, radius, opts["threshold"])
    if consistent.sum() < opts["min_inliers"]:
        return {"explained": None, "local_p90": None, "local_median": None, "local_scales": None,
                "matrix": matrix, "fitted": None}
    # The map: least squares over the matches that a neighbourhood's map fitted within FIT_PX
    # holds (true matches, located to the precision the keypoints have, bent or not). A second
    # pass: the residuals of the first pass's looser local maps admitted strays (one bent
    # close-up's figure moved by 0.11 between two renderings of the same map, 0.047 here).
    fitting, _, scatter = local_fits(src, dst, radius, FIT_PX)
    if fitting.sum() >= opts["min_inliers"]:
        design = np.column_stack([src[fitting], np.ones(int(fitting.sum()))])
        matrix = np.linalg.lstsq(design, dst[fitting], rcond=None)[0].T
        variance = float(np.mean(scatter[fitting])) / 2.0
    else:
        fitting, variance = consistent, None
    miss = src[fitting] @ matrix[:, :2].T + matrix[:, 2] - dst[fitting]
    residual = src[consistent] @ matrix[:, :2].T + matrix[:, 2] - dst[consistent]
    explained = np.mean(np.hypot(residual[:, 0], residual[:, 1]) <= opts["threshold"])
    fitted = (int(fitting.sum()), len(src), float(np.sqrt(np.mean(np.sum(miss**2, axis=1)))),
              shape_noise(src[fitting], miss, matrix[:, :2], variance))
    shaped = consistent & np.isfinite(linear[:, 0, 0])        # neighbourhoods that fix a map
    if shaped.sum() < opts["min_inliers"]:
        return {"matrix": matrix, "fitted": fitted, "explained": float(explained), "local_p90": None,
                "local_median": None, "local_scales": None}
    sigma = np.linalg.svd(linear[shaped], compute_uv=False)
    local = sigma[:, 0] / sigma[:, 1] - 1.0
    scales = np.sqrt(sigma[:, 0] * sigma[:, 1])
    return {"matrix": matrix, "fitted": fitted,
            "explained": float(explained), "local_p90": float(np.percentile(local, 90)),
            "local_median": float(np.median(local)),
            "local_scales": tuple(float(v) for v in np.percentile(scales, [10, 50, 90]))}


def shape_noise(src: np.ndarray, miss: np.ndarray, linear: np.ndarray, variance: float | None = None) -> float:
    """The distortion that the scatter of the matches alone gives their affine fit (its mean).

    With positions of variance s^2 per coordinate, the linear part's error has an
    anti-conformal part (the one that changes the shape) of two independent components,
    each of variance s^2 tr((Xc^T Xc)^-1) / 4 (Xc: the centred input points); its norm is
    Rayleigh-distributed, and the distortion is twice it over the scale. Matches bunched
    together, or along a line, or few and scattered, give a large figure.

    Parameters
    ----------
    src : (n, 2) ndarray
        The input points the map was fitted to.
    miss : (n, 2) ndarray
        Their residuals from the map, in output pixels.
    linear : (2, 2) ndarray
        The fitted linear part.
    variance : float, optional
        s^2, when known otherwise (from the matches' local maps: a bent component's
        residuals from one map are not noise); else from ``miss``.

    Returns
    -------
    float
        inf for fewer than 4 points or points on a line.
    """
    n = len(src)
    centred = src - src.mean(axis=0)
    gram = centred.T @ centred
    scale = np.sqrt(abs(np.linalg.det(linear)))
    if n < 4 or np.linalg.det(gram) <= 1e-12 * max(1.0, np.trace(gram)) ** 2 or scale == 0:
        return float("inf")
    if variance is None:
        variance = np.sum(miss**2) / (2.0 * (n - 3))
    return float(np.sqrt(variance * np.trace(np.linalg.inv(gram)) * np.pi / 2.0) / scale)


def measure(image: np.ndarray, output: np.ndarray, mask: np.ndarray, *, min_inliers: int = MIN_INLIERS,
            ratio: float = RATIO, threshold: float = REPROJECTION_PX, refinements: int = 2,
            max_pixels: int = MAX_PIXELS) -> list[ComponentFit]:
    """Fit an affine map input -> output to each connected component of ``mask``.

    Parameters
    ----------
    image : (h, w) or (h, w, c) uint8 or uint16 ndarray
        The input image (BGR, BGRA or gray, as OpenCV reads it).
    output : (H, W) or (H, W, c) uint8 or uint16 ndarray
        The warped image; any size (its canvas).
    mask : (h, w) ndarray
        Nonzero (True) on features, same height and width as ``image``.
    min_inliers : int
        Fewest RANSAC inliers for a fit.
    ratio : float
        Lowe's ratio test.
    threshold : float
        RANSAC reprojection threshold in output pixels.
    refinements : int
        Rounds of re-matching on the output rectified by the current fit.
    max_pixels : int
        Both images are scaled down by one common factor so that neither has more
        pixels than this; the figures are given in full-size pixels.

    Returns
    -------
    list of ComponentFit
        One per 8-connected component, in label order; empty for an empty mask.

    Raises
    ------
    ValueError
        If the mask's size differs from the image's, or an image is not 8- or 16-bit.
    """
    if mask.shape[:2] != image.shape[:2]:
        raise ValueError(f"the mask is {mask.shape[1]}x{mask.shape[0]}, the image "
                         f"{image.shape[1]}x{image.shape[0]}")
    n_labels, labels, stats, centroids = cv2.connectedComponentsWithStats(
        (np.asarray(mask) != 0).astype(np.uint8), connectivity=8)
    largest = max(image.shape[0] * image.shape[1], output.shape[0] * output.shape[1])
    factor = min(1.0, float(np.sqrt(max_pixels / largest)))
    gray_in, gray_out, small = (shrink(a, factor, nearest) for a, nearest in
                                ((gray8(image), False), (gray8(output), False), (labels, True)))
    src_all = detect(gray_in) if n_labels > 1 else None
    dst = detect(gray_out) if n_labels > 1 else None
    opts = {"min_inliers": min_inliers, "ratio": ratio, "threshold": threshold * factor,
            "refinements": refinements, "scale": factor}
    fits = []
    for label in range(1, n_labels):
        x, y, bw, bh, area = (int(v) for v in stats[label])
        component = (small == label).astype(np.uint8)
        src = src_all.subset(inside(component, src_all.points))
        found = fit_component(gray_in, gray_out, component, src, dst, opts) if component.any() else {
            "reason": "the component vanishes at the measuring scale"}
        centre = tuple(round(float(v), 1) for v in centroids[label])
        fits.append(ComponentFit(label=label, pixels=area, bbox=(x, y, bw, bh), centre=centre,
                                 **full_size(found, factor)))
    return [dataclasses.replace(fit, lands_on=others) for fit, others in zip(fits, collisions(fits, labels))]


def collisions(fits: list[ComponentFit], labels: np.ndarray) -> list[tuple]:
    """Per fit, the labels of the other measured components onto whose output place its map
    puts its centre: the point, mapped back by the other's map, falls on that component's
    pixels (``labels``: the mask's components, full size). Disjoint regions of the input stay
    disjoint under a warp, so such a pair means one of the two was matched to the other's
    image (a subject that appears twice, at another size or mirrored)."""
    height, width = labels.shape
    claims = []
    for fit in fits:
        others = []
        for other in fits:
            if fit is other or fit.linear is None or other.linear is None or not fit.centre:
                continue
            spot = fit.linear @ np.asarray(fit.centre, float) + fit.translation
            back = np.linalg.solve(other.linear, spot - other.translation) if abs(np.linalg.det(other.linear)) > 1e-12 \
                else None
            if back is None or not np.all(np.isfinite(back)):
                continue
            col, row = int(round(back[0])), int(round(back[1]))
            if 0 <= row < height and 0 <= col < width and labels[row, col] == other.label:
                others.append(other.label)
        claims.append(tuple(others))
    return claims


def shrink(array: np.ndarray, factor: float, nearest: bool) -> np.ndarray:
    """``array`` resized by ``factor`` (area averaging, or nearest for labels); as is when 1."""
    if factor == 1.0:
        return array
    h, w = array.shape[:2]
    size = (max(1, int(round(w * factor))), max(1, int(round(h * factor))))
    if nearest:
        return cv2.resize(array.astype(np.float32), size, interpolation=cv2.INTER_NEAREST).astype(array.dtype)
    return cv2.resize(array, size, interpolation=cv2.INTER_AREA)


def full_size(found: dict, factor: float) -> dict:
    """Figures measured on images scaled by ``factor``, in full-size pixels.

    With x_s = f (x + h) - h on both sides (h = (1/2, 1/2): pixel centres), the map
    y_s = A x_s + t_s reads y = A x + (t_s + s) / f - s with s = (I - A) h: the linear
    part is unchanged, the translation changes, and distances divide by f.
    """
    if factor == 1.0 or "linear" not in found:
        return found
    half = np.full(2, 0.5)
    shift = half - found["linear"] @ half                  # (I - A) (1/2, 1/2)
    translation = (found["translation"] + shift) / factor - shift
    return found | {"translation": translation, "rms_px": found["rms_px"] / factor}


def worst(fits: list[ComponentFit]) -> float | None:
    """The largest measured distortion over ``fits`` (None if none was measured)."""
    values = [f.distortion for f in fits if f.distortion is not None]
    return max(values) if values else None
