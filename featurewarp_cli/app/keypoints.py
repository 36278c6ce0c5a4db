"""SIFT keypoints, ratio-test matches and robust affine fits: the machinery of :mod:`.measure`.

Numpy and OpenCV only. Positions are pixel coordinates with pixel centres at whole
numbers, x to the right and y down.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..render.remap import LIMIT

#: Lowe's ratio: a match is kept when its best distance < RATIO * the second best.
RATIO = 0.75
#: Background for transparent or uncovered pixels (flat: a checkerboard would make keypoints).
FLAT_GRAY = 128
#: A keypoint's position depends on the pixels within this many times its size (OpenCV's
#: ``size`` is twice the scale sigma: the difference of Gaussians reads about 4 sigma out).
#: Where one image has pixels there and the other has none, the two keypoints differ.
SUPPORT = 2.0
#: A local fit is kept only if its inliers spread, along their narrower axis (standard
#: deviation), over at least this share of the neighbourhood's radius: matches bunched in
#: a spot or along a line fix no linear map (14 matches within 2.4 x 0.8 px gave a scale
#: of 0.0097 and a distortion of 8000 on an image measured against itself).
LOCAL_SPREAD = 0.125
#: Simulated views are made of pieces of the component's box at most this many times
#: longer than wide (a long strip turned by 45 degrees would need its length squared).
VIEW_ASPECT = 4
#: ... and at least this many pixels long (a strip a few pixels wide has few keypoints).
VIEW_LENGTH = 512


@dataclass(frozen=True)
class Keypoints:
    """SIFT keypoints: positions (in the pixels of the image they describe) and descriptors.

    Attributes
    ----------
    points : (N, 2) float64 ndarray
        x, y of each keypoint (pixel centres at whole numbers).
    descriptors : (N, 128) float32 ndarray
    sizes : (N,) float64 ndarray
        OpenCV's keypoint size (twice the scale sigma), in the same pixels as ``points``.
    """

    points: np.ndarray
    descriptors: np.ndarray
    sizes: np.ndarray

    def __len__(self):
        return len(self.points)

    def subset(self, which) -> Keypoints:
        """The keypoints selected by an index or boolean array."""
        return Keypoints(self.points[which], self.descriptors[which], self.sizes[which])

    def shifted(self, dx: float, dy: float) -> Keypoints:
        """The same keypoints with ``(dx, dy)`` added to their positions."""
        return Keypoints(self.points + (dx, dy), self.descriptors, self.sizes)


def detect(gray: np.ndarray, where: np.ndarray | None = None) -> Keypoints:
    """SIFT keypoints of an 8-bit gray image (only inside ``where``, a uint8 mask, if given)."""
    found, descriptors = cv2.SIFT_create().detectAndCompute(gray, where)
    points = np.array([k.pt for k in found], np.float64).reshape(-1, 2)
    if descriptors is None:
        descriptors = np.zeros((0, 128), np.float32)
    return Keypoints(points, descriptors, np.array([k.size for k in found], np.float64))


def warp_affine(image: np.ndarray, matrix: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``cv2.warpAffine`` (bilinear, :data:`FLAT_GRAY` outside ``image``) for any size.

    OpenCV asserts that source and destination have fewer than 32767 pixels a side; past
    :data:`~featurewarp_cli.render.remap.LIMIT` the destination is halved until each piece,
    and the window of ``image`` it reads, fit one call.

    Parameters
    ----------
    image : (h, w) uint8 ndarray
    matrix : (2, 3) float ndarray
        Source (``image``) pixel -> destination pixel.
    size : (width, height) of the destination.

    Returns
    -------
    (height, width) uint8 ndarray
    """
    out = np.empty((int(size[1]), int(size[0])), image.dtype)
    _warp_piece(image, np.asarray(matrix, np.float64), cv2.invertAffineTransform(matrix), out, (0, 0))
    return out


def _warp_piece(image, matrix, back, out, origin) -> None:
    """Fill ``out``, the destination's piece at ``origin`` (x, y), from the window of ``image`` it reads."""
    h, w = out.shape
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float) + origin
    reach = corners @ back[:, :2].T + back[:, 2]
    x0, y0 = np.clip(np.floor(reach.min(axis=0)) - 2, 0, image.shape[1::-1]).astype(int)
    x1, y1 = np.clip(np.ceil(reach.max(axis=0)) + 3, 0, image.shape[1::-1]).astype(int)
    if x1 <= x0 or y1 <= y0:
        out[...] = FLAT_GRAY
    elif max(h, w, x1 - x0, y1 - y0) <= LIMIT:           # a single pixel reads 6 at most
        window = image[y0:y1, x0:x1]
        shifted = matrix.copy()
        shifted[:, 2] += matrix[:, :2] @ (x0, y0) - origin
        out[...] = cv2.warpAffine(window, shifted, (w, h), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=FLAT_GRAY)
    elif h >= w:
        _warp_piece(image, matrix, back, out[: h // 2], origin)
        _warp_piece(image, matrix, back, out[h // 2:], (origin[0], origin[1] + h // 2))
    else:
        _warp_piece(image, matrix, back, out[:, : w // 2], origin)
        _warp_piece(image, matrix, back, out[:, w // 2:], (origin[0] + w // 2, origin[1]))


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
    input as an affine camera with that tilt would see it. A box longer than
    :data:`VIEW_ASPECT` times its width and :data:`VIEW_LENGTH` is seen piece by piece
    (overlapping by its width, each piece keeping the keypoints of its own part), so that
    no turned view needs more than a few times the box's pixels.
    """
    x0, y0, x1, y1 = box
    across = min(x1 - x0, y1 - y0)
    along = 0 if x1 - x0 >= y1 - y0 else 1
    start, end = box[along], box[along + 2]
    step = max(VIEW_ASPECT * across, VIEW_LENGTH) - across
    if end - start <= step + across:
        return simulated_piece(gray, box, tilt, angle)
    found = []
    for first in range(start, end - across, step):
        last = min(end, first + step + across)
        piece = list(box)
        piece[along], piece[along + 2] = first, last
        view = simulated_piece(gray, tuple(piece), tilt, angle)
        own_from = start if first == start else first + across / 2
        own_to = end if last == end else last - across / 2
        found.append(view.subset((view.points[:, along] >= own_from - 0.5)
                                 & (view.points[:, along] < own_to - 0.5)))
    return Keypoints(*(np.concatenate([getattr(k, name) for k in found])
                       for name in ("points", "descriptors", "sizes")))


def simulated_piece(gray: np.ndarray, box: tuple, tilt: float, angle: float) -> Keypoints:
    """:func:`simulated` for one box (the whole of it, whatever its shape)."""
    x0, y0, x1, y1 = box
    crop = gray[y0:y1, x0:x1]
    h, w = crop.shape
    rotation = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle, 1.0)
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], float) @ rotation.T
    rotation[:, 2] -= corners.min(axis=0)
    size = np.ceil(corners.max(axis=0) - corners.min(axis=0)).astype(int) + 1
    turned = warp_affine(crop, rotation, (int(size[0]), int(size[1])))
    squeezed = cv2.resize(turned, (max(1, int(round(size[0] / tilt))), int(size[1])),
                          interpolation=cv2.INTER_AREA)
    found = detect(squeezed)
    turned_points = np.column_stack([(found.points[:, 0] + 0.5) * size[0] / squeezed.shape[1] - 0.5,
                                     found.points[:, 1]])
    back = cv2.invertAffineTransform(rotation)
    points = turned_points @ back[:, :2].T + back[:, 2] + (x0, y0)
    return Keypoints(points, found.descriptors, found.sizes * tilt)


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


def distinct(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The matches ``src`` -> ``dst`` less those that give an output keypoint a second,
    other input position (the first one stays).

    Simulated views match one output keypoint from several views, at input positions
    that differ by up to a pixel or two: one measurement, not several (counted as many,
    a handful of keypoints passed for a fit of 20 matches, measured 0.05 off). The same
    pair twice (SIFT gives a keypoint of two orientations twice, on both sides) stays.
    """
    dst_key, src_key = np.round(dst, 2), np.round(src, 2)
    if len(dst) == 0:
        return src, dst
    _, first, owner = np.unique(dst_key, axis=0, return_index=True, return_inverse=True)
    keep = np.all(src_key == src_key[first[owner.ravel()]], axis=1)
    return src[keep], dst[keep]


def ransac(src: np.ndarray, dst: np.ndarray, min_inliers: int, threshold: float) -> Fit | str:
    """Affine fit of ``src`` -> ``dst`` (:func:`distinct` matches) by RANSAC, or the reason why there is none."""
    src, dst = distinct(src, dst)
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
    (tilt by tilt, stopping at the first that gives a fit); else the reason, for all the
    matches pooled."""
    pooled = [matched(src, dst, opts["ratio"])]
    fit = ransac(*pooled[0], opts["min_inliers"], opts["threshold"])
    for views in tilts():
        if isinstance(fit, Fit):
            break
        pooled.append(view_matches(gray_in, component, box, dst, opts["ratio"], views))
        fit = ransac(np.concatenate([p[0] for p in pooled]), np.concatenate([p[1] for p in pooled]),
                     opts["min_inliers"], opts["threshold"])
    return fit


def compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The 2x3 affine map x -> outer(inner(x))."""
    return outer[:, :2] @ inner + np.hstack([np.zeros((2, 2)), outer[:, 2:]])


def refine(gray_out, box, src: Keypoints, fit: Fit, opts: dict) -> Fit | None:
    """Fit again after undoing ``fit`` on the output: the residual map is near the identity,
    where SIFT matches best, so the composed map is accurate even for strong anisotropy.

    Only ``box`` (x0, y0, x1, y1) of the input frame is rectified and searched. ``src``
    are the component's keypoints found on the input's ``box`` alone (see :func:`detect`),
    so that both sides are cut at the same place: a region the output shows unchanged
    gives the same keypoints twice. Keypoints on either side whose support
    (:data:`SUPPORT`) reaches where the output has no pixels are left out: there the two
    images differ whatever the map.

    Returns
    -------
    Fit or None
        The composed fit (its ``dst`` in output pixels), or None if the rectified
        view gives no fit.
    """
    x0, y0, x1, y1 = box
    to_box = cv2.invertAffineTransform(fit.matrix)
    to_box[:, 2] -= (x0, y0)
    size = (x1 - x0, y1 - y0)
    rectified = warp_affine(gray_out, to_box, size)
    covered = warp_affine(np.full(gray_out.shape, 255, np.uint8), to_box, size) >= (255 + FLAT_GRAY) // 2
    clearance = cv2.distanceTransform(np.pad(covered.astype(np.uint8), 1, constant_values=1),
                                      cv2.DIST_L2, 5)[1:-1, 1:-1]
    found = detect(rectified).shifted(x0, y0)
    src, found = (k.subset(clear_of(k, clearance, (x0, y0))) for k in (src, found))
    residual = ransac(*matched(src, found, opts["ratio"]), opts["min_inliers"], opts["threshold"])
    if not isinstance(residual, Fit):
        return None
    dst = residual.dst @ fit.matrix[:, :2].T + fit.matrix[:, 2]
    return Fit(compose(fit.matrix, residual.matrix), residual.src, dst, residual.inlier)


def clear_of(keys: Keypoints, clearance: np.ndarray, origin: tuple) -> np.ndarray:
    """(N,) bool: the keypoints farther than :data:`SUPPORT` times their size from where
    ``clearance`` (distance to the nearest pixel to avoid, over the box at ``origin``) is 0."""
    h, w = clearance.shape
    cols = np.clip(np.rint(keys.points[:, 0] - origin[0]).astype(int), 0, w - 1)
    rows = np.clip(np.rint(keys.points[:, 1] - origin[1]).astype(int), 0, h - 1)
    return clearance[rows, cols] > SUPPORT * keys.sizes


def local_fits(src: np.ndarray, dst: np.ndarray, radius: float, threshold: float,
               min_points: int = 8, most: int = 1500) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        Each consistent match's local linear map; NaN elsewhere, and where the
        neighbourhood's inliers are bunched in a spot or along a line
        (:data:`LOCAL_SPREAD`): they confirm the match, but fix no linear map.
    scatter : (M,) float ndarray
        Each consistent match's squared distance from its neighbourhood's map, times
        k / (k - 3) for the k inliers the map was fitted to (an unbiased estimate of the
        variance of its position, in output pixels squared, summed over x and y): a bent
        region scatters no more than a kept one; NaN elsewhere.
    """
    m = len(src)
    consistent, linear, scatter = np.zeros(m, bool), np.full((m, 2, 2), np.nan), np.full(m, np.nan)
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
        consistent[i] = True
        inliers = src[idx[flags.ravel() > 0]]
        miss = matrix[:, :2] @ src[i] + matrix[:, 2] - dst[i]
        scatter[i] = float(miss @ miss) * len(inliers) / (len(inliers) - 3.0)
        spread = np.linalg.svd(inliers - inliers.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(inliers))
        if spread >= LOCAL_SPREAD * radius:
            linear[i] = matrix[:, :2]
    return consistent, linear, scatter
