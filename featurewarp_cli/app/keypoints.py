"""SIFT keypoints, ratio-test matches and robust affine fits: the machinery of :mod:`.measure`.

Numpy and OpenCV only. Positions are pixel coordinates with pixel centres at whole
numbers, x to the right and y down.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: Lowe's ratio: a match is kept when its best distance < RATIO * the second best.
RATIO = 0.75
#: Background for transparent or uncovered pixels (flat: a checkerboard would make keypoints).
FLAT_GRAY = 128


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


def view_matches(gray_in, component, box, dst: Keypoints, ratio: float, views) -> tuple[np.ndarray, np.ndarray]:
    """Matches of the component's keypoints in simulated ``views`` (tilt, angle), pooled.

    Returns
    -------
    src, dst : (M, 2) float ndarrays
        Input positions (inside ``component``, a uint8 mask) and their output matches.
    """
    pooled = [(np.zeros((0, 2)), np.zeros((0, 2)))]
    h, w = component.shape
    for tilt, angle in views:
        view = simulated(gray_in, box, tilt, angle)
        cols = np.clip(np.rint(view.points[:, 0]).astype(int), 0, w - 1)
        rows = np.clip(np.rint(view.points[:, 1]).astype(int), 0, h - 1)
        pooled.append(matched(view.subset(component[rows, cols] > 0), dst, ratio))
    return np.concatenate([p[0] for p in pooled]), np.concatenate([p[1] for p in pooled])


def seed(gray_in, component, box, dst: Keypoints, src: Keypoints, opts: dict) -> Fit | str:
    """A first fit from plain SIFT, else from ASIFT-like simulated views of the component
    (tilt by tilt, stopping at the first that gives a fit)."""
    pooled = [matched(src, dst, opts["ratio"])]
    first = ransac(*pooled[0], opts["min_inliers"], opts["threshold"])
    if isinstance(first, Fit):
        return first
    for views in tilts():
        pooled.append(view_matches(gray_in, component, box, dst, opts["ratio"], views))
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


def local_fits(src: np.ndarray, dst: np.ndarray, radius: float, threshold: float,
               min_points: int = 8, most: int = 1500) -> tuple[np.ndarray, np.ndarray]:
    """The affine map around each match, fitted (RANSAC) to the matches within ``radius``.

    A match is *locally consistent* when its own neighbourhood's fit holds at least
    ``min_points`` inliers and counts it among them: true matches of a smooth warp
    are, whatever the warp does globally, and stray false matches are not.

    Parameters
    ----------
    src, dst : (M, 2) float ndarray
        Matched input and output positions.
    radius : float
        Neighbourhood radius in input pixels (the local fit's precision grows with it).
    threshold : float
        RANSAC reprojection threshold in output pixels.
    min_points : int
    most : int
        At most this many matches are examined (evenly spaced ones), bounding the
        (M, M) distance table.

    Returns
    -------
    consistent : (M,) bool ndarray
    linear : (M, 2, 2) float ndarray
        Each consistent match's local linear map (NaN elsewhere).
    """
    m = len(src)
    consistent, linear = np.zeros(m, bool), np.full((m, 2, 2), np.nan)
    examined = np.unique(np.linspace(0, m - 1, min(m, most)).astype(int)) if m else np.zeros(0, int)
    near = np.sum((src[examined, None, :] - src[None, :, :]) ** 2, axis=2) <= radius * radius
    for row, i in enumerate(examined):
        idx = np.flatnonzero(near[row])
        if len(idx) < min_points:
            continue
        matrix, flags = cv2.estimateAffine2D(src[idx], dst[idx], method=cv2.RANSAC,
                                             ransacReprojThreshold=threshold, maxIters=500)
        if matrix is None or flags.sum() < min_points or not flags[np.searchsorted(idx, i), 0]:
            continue
        consistent[i], linear[i] = True, matrix[:, :2]
    return consistent, linear
