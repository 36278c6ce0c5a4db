"""Distortion measured on the output image: an affine fit of keypoints per masked region.

The mesh says how the tool meant to move each feature; this module checks what the
written image shows. For every connected component of the input mask it matches SIFT
keypoints found inside the component (input) with keypoints of the whole output,
keeps the matches that pass Lowe's ratio test, and fits an affine map
input -> output with RANSAC (``cv2.estimateAffine2D``). The linear part A of that map
gives the component's

* distortion  sigma_max / sigma_min - 1 of A: 0 for a similarity, 1 for 2x along one axis;
* scale       sqrt(|det A|);
* rotation    the angle of A's closest rotation, degrees, clockwise on screen (y down).

A component with too few matches gets no figures and a reason instead: a number made
up from three keypoints would be worse than none. SIFT is rotation invariant, so
swirls and arcs are measured as well as stretches; it tolerates moderate anisotropy
(the fit stays within 0.01 of an exact affine of sigma ratio 2).

Only numpy and OpenCV (SIFT is in OpenCV's main module since 4.4).

Examples
--------
>>> fits = measure(image, warped, mask)                          # doctest: +SKIP
>>> [(f.label, f.distortion) for f in fits]                      # doctest: +SKIP
[(1, 0.0032), (2, None)]
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: Fewest RANSAC inliers for a fit; below this a component gets a reason, not figures.
MIN_INLIERS = 10
#: Lowe's ratio: a match is kept when its best distance < RATIO * the second best.
RATIO = 0.75
#: RANSAC's reprojection threshold in output pixels.
REPROJECTION_PX = 3.0
#: Both images are scaled down by one common factor so that neither exceeds this many
#: pixels (the linear part of the fit does not change under a common scale).
MAX_PIXELS = 4_000_000
#: Background for transparent output pixels (flat: a checkerboard would make keypoints).
FLAT_GRAY = 128


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
    matches : int
        Keypoint matches that passed the ratio test.
    inliers : int
        Matches consistent with the fitted map within :data:`REPROJECTION_PX`.
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
        Root mean square distance, in output pixels, of the inliers from the map.
    coverage : float or None
        Area of the inliers' convex hull over the component's area: how much of the
        component the fit speaks for (a bent component fits only in parts).
    reason : str or None
        Why there are no figures (too few matches or inliers), else None.
    """

    label: int
    pixels: int
    bbox: tuple
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
    reason: str | None = None

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
    if image.dtype == np.uint16:
        image = (image // 257).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise ValueError(f"images must be 8- or 16-bit, not {image.dtype}")
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


@dataclass(frozen=True)
class Keypoints:
    """SIFT keypoints: positions (in the pixels of the image they describe) and descriptors.

    Attributes
    ----------
    points : (N, 2) float64 ndarray
        x, y of each keypoint (pixel centres at whole numbers).
    descriptors : (N, 128) float32 ndarray
    """

    points: np.ndarray
    descriptors: np.ndarray

    def __len__(self):
        return len(self.points)

    def subset(self, which) -> Keypoints:
        """The keypoints selected by an index or boolean array."""
        return Keypoints(self.points[which], self.descriptors[which])


def detect(gray: np.ndarray, where: np.ndarray | None = None) -> Keypoints:
    """SIFT keypoints of an 8-bit gray image (only inside ``where``, a uint8 mask, if given)."""
    found, descriptors = cv2.SIFT_create().detectAndCompute(gray, where)
    points = np.array([k.pt for k in found], np.float64).reshape(-1, 2)
    if descriptors is None:
        descriptors = np.zeros((0, 128), np.float32)
    return Keypoints(points, descriptors)


def tilts() -> list[list[tuple[float, float]]]:
    """(tilt, angle in degrees) of the affine views simulated when plain SIFT finds no fit.

    ASIFT's sampling (Morel and Yu 2009), one list per tilt: sqrt(2), 2 and 2 sqrt(2),
    each at angles 72 / tilt degrees apart over [0, 180). With SIFT's own tolerance
    this covers anisotropy up to about 4.
    """
    return [[(tilt, angle) for angle in np.arange(0.0, 180.0, 72.0 / tilt)]
            for tilt in (np.sqrt(2.0), 2.0, 2.0 * np.sqrt(2.0))]


def simulated(gray: np.ndarray, box: tuple, tilt: float, angle: float) -> Keypoints:
    """Keypoints of ``gray[box]`` seen rotated by ``angle`` and compressed ``tilt`` times along x.

    Positions are mapped back to ``gray``'s pixels, so the keypoints stand for the
    input as an affine camera with that tilt would see it.
    """
    x0, y0, x1, y1 = box
    crop = gray[y0:y1, x0:x1]
    h, w = crop.shape
    rotation = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle, 1.0)
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], float) @ rotation.T
    rotation[:, 2] -= corners.min(axis=0)
    size = np.ceil(corners.max(axis=0) - corners.min(axis=0)).astype(int) + 1
    turned = cv2.warpAffine(crop, rotation, (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR,
                            borderValue=FLAT_GRAY)
    squeezed = cv2.resize(turned, (max(1, int(round(size[0] / tilt))), int(size[1])),
                          interpolation=cv2.INTER_AREA)
    found = detect(squeezed)
    turned_points = np.column_stack([(found.points[:, 0] + 0.5) * size[0] / squeezed.shape[1] - 0.5,
                                     found.points[:, 1]])
    back = cv2.invertAffineTransform(rotation)
    points = turned_points @ back[:, :2].T + back[:, 2] + (x0, y0)
    return Keypoints(points, found.descriptors)


def ratio_matches(query: Keypoints, train: Keypoints, ratio: float = RATIO) -> np.ndarray:
    """Index pairs (i in query, j in train) whose best match beats the second best by ``ratio``.

    Returns
    -------
    (M, 2) int ndarray
    """
    if len(query) == 0 or len(train) < 2:
        return np.zeros((0, 2), int)
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(query.descriptors, train.descriptors, k=2)
    kept = [(m[0].queryIdx, m[0].trainIdx) for m in pairs
            if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    return np.array(kept, int).reshape(-1, 2)




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
    return {
        "distortion": float(sigma[0] / sigma[1] - 1.0) if sigma[1] > 0 else float("inf"),
        "scale": float(np.sqrt(abs(np.linalg.det(linear)))),
        "rotation": float(np.degrees(np.arctan2(rotation[1, 0], rotation[0, 0]))),
        "stretches": (float(sigma[0]), float(sigma[1])),
        "reflected": reflected,
    }



@dataclass(frozen=True)
class Fit:
    """One RANSAC affine fit: the 2x3 matrix and the matched points behind it."""

    matrix: np.ndarray            # (2, 3): output = matrix[:, :2] @ input + matrix[:, 2]
    src: np.ndarray               # (M, 2) matched input points
    dst: np.ndarray               # (M, 2) their matches (output, or rectified, pixels)
    inlier: np.ndarray            # (M,) bool


def ransac(src: np.ndarray, dst: np.ndarray, min_inliers: int, threshold: float) -> Fit | str:
    """Affine fit of ``src`` -> ``dst`` by RANSAC, or the reason why there is none."""
    if len(src) < min_inliers:
        return f"{len(src)} keypoint matches, fewer than {min_inliers}"
    matrix, flags = cv2.estimateAffine2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=threshold,
                                         maxIters=5000, confidence=0.999, refineIters=20)
    inlier = flags.ravel().astype(bool) if flags is not None else np.zeros(len(src), bool)
    if matrix is None or inlier.sum() < min_inliers:
        return f"{int(inlier.sum())} RANSAC inliers of {len(src)} matches, fewer than {min_inliers}"
    if abs(np.linalg.det(matrix[:, :2])) < 1e-9:
        return "the inliers are collinear: the fit is degenerate"
    return Fit(matrix, src, dst, inlier)


def matched(src: Keypoints, dst: Keypoints, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Matched positions (src points, dst points) that pass the ratio test."""
    pairs = ratio_matches(src, dst, ratio)
    return src.points[pairs[:, 0]], dst.points[pairs[:, 1]]


def seed(gray_in, component, box, dst: Keypoints, src: Keypoints, opts: dict) -> Fit | str:
    """A first fit from plain SIFT, else from ASIFT-like simulated views of the component
    (tilt by tilt, stopping at the first that gives a fit)."""
    pooled = [matched(src, dst, opts["ratio"])]
    first = ransac(*pooled[0], opts["min_inliers"], opts["threshold"])
    if isinstance(first, Fit):
        return first
    for views in tilts():
        for tilt, angle in views:
            view = simulated(gray_in, box, tilt, angle)
            cols = np.clip(np.rint(view.points[:, 0]).astype(int), 0, component.shape[1] - 1)
            rows = np.clip(np.rint(view.points[:, 1]).astype(int), 0, component.shape[0] - 1)
            pooled.append(matched(view.subset(component[rows, cols] > 0), dst, opts["ratio"]))
        fit = ransac(np.concatenate([p[0] for p in pooled]), np.concatenate([p[1] for p in pooled]),
                     opts["min_inliers"], opts["threshold"])
        if isinstance(fit, Fit):
            return fit
    return first


def compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The 2x3 affine map x -> outer(inner(x))."""
    return outer[:, :2] @ inner + np.hstack([np.zeros((2, 2)), outer[:, 2:]])


def refine(gray_out, box, src: Keypoints, fit: Fit, opts: dict) -> Fit | None:
    """Fit again after undoing ``fit`` on the output: the residual map is near the identity,
    where SIFT matches best, so the composed map is accurate even for strong anisotropy.

    Only ``box`` (x0, y0, x1, y1) of the input frame is rectified and searched.

    Returns
    -------
    Fit or None
        The composed fit (its ``dst`` in output pixels), or None if the rectified
        view gives no fit.
    """
    x0, y0, x1, y1 = box
    to_box = cv2.invertAffineTransform(fit.matrix)
    to_box[:, 2] -= (x0, y0)
    rectified = cv2.warpAffine(gray_out, to_box, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                               borderValue=FLAT_GRAY)
    found = detect(rectified)
    found = Keypoints(found.points + (x0, y0), found.descriptors)
    residual = ransac(*matched(src, found, opts["ratio"]), opts["min_inliers"], opts["threshold"])
    if not isinstance(residual, Fit):
        return None
    dst = residual.dst @ fit.matrix[:, :2].T + fit.matrix[:, 2]
    return Fit(compose(fit.matrix, residual.matrix), residual.src, dst, residual.inlier)


def fit_component(gray_in, gray_out, component, src: Keypoints, dst: Keypoints, opts: dict) -> dict:
    """Fit one component (a uint8 mask of the input): figures for :class:`ComponentFit`."""
    ys, xs = np.nonzero(component)
    margin = 16
    box = (max(0, xs.min() - margin), max(0, ys.min() - margin),
           min(component.shape[1], xs.max() + margin + 1), min(component.shape[0], ys.max() + margin + 1))
    fit = seed(gray_in, component, box, dst, src, opts)
    if isinstance(fit, str):
        return {"reason": fit}
    for _ in range(opts["refinements"]):
        fit = refine(gray_out, box, src, fit, opts) or fit
    keep = fit.inlier
    linear, translation = fit.matrix[:, :2], fit.matrix[:, 2]
    residual = fit.src[keep] @ linear.T + translation - fit.dst[keep]
    hull = cv2.convexHull(fit.src[keep].astype(np.float32))
    return describe(linear) | {
        "matches": len(fit.src), "inliers": int(keep.sum()), "linear": linear, "translation": translation,
        "rms_px": float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))),
        "coverage": float(min(1.0, cv2.contourArea(hull) / max(1, int(np.count_nonzero(component))))),
    }


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
    n_labels, labels, stats, _ = cv2.connectedComponentsWithStats(
        (np.asarray(mask) != 0).astype(np.uint8), connectivity=8)
    largest = max(image.shape[0] * image.shape[1], output.shape[0] * output.shape[1])
    factor = min(1.0, float(np.sqrt(max_pixels / largest)))
    gray_in, gray_out, small = (shrink(a, factor, nearest) for a, nearest in
                                ((gray8(image), False), (gray8(output), False), (labels, True)))
    src_all = detect(gray_in) if n_labels > 1 else None
    dst = detect(gray_out) if n_labels > 1 else None
    opts = {"min_inliers": min_inliers, "ratio": ratio, "threshold": threshold * factor,
            "refinements": refinements}
    fits = []
    for label in range(1, n_labels):
        x, y, bw, bh, area = (int(v) for v in stats[label])
        component = (small == label).astype(np.uint8)
        cols = np.clip(np.rint(src_all.points[:, 0]).astype(int), 0, component.shape[1] - 1)
        rows = np.clip(np.rint(src_all.points[:, 1]).astype(int), 0, component.shape[0] - 1)
        src = src_all.subset(component[rows, cols] > 0)
        found = fit_component(gray_in, gray_out, component, src, dst, opts) if component.any() else {
            "reason": "the component vanishes at the measuring scale"}
        fits.append(ComponentFit(label=label, pixels=area, bbox=(x, y, bw, bh), **full_size(found, factor)))
    return fits


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
