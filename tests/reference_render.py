"""A slow, plain reference for the compiled renderer: the tests' oracle.

:class:`ReferenceMap` tests every pixel centre against every triangle with
barycentric coordinates (numpy, one triangle at a time over its bounding box)
and interpolates the source position. :func:`reference_footprint` takes a
Jacobian's SVD and log2 from numpy. Neither shares code with
``featurewarp_cli.render``.
"""

from __future__ import annotations

import numpy as np

from featurewarp_cli.render.antialias import AA_MAX_STEPS, AA_START, BLEND_MARGIN, TENT_REACH


class ReferenceMap:
    """Which triangles hold each pixel centre of a canvas, and where they send it.

    Parameters
    ----------
    source, target : (N, 2) ndarray
        Node positions in the input image and on the canvas.
    triangles : (M, 3) ndarray of int
    canvas : (int, int)
        (width, height).
    tol : float
        Pixel centres within ``tol`` (canvas pixels) of a triangle's edge may go
        either way.

    Attributes
    ----------
    covered : (H, W) bool ndarray
        The centre lies more than ``tol`` inside some triangle.
    near_edge : (H, W) bool ndarray
        The centre lies within ``tol`` of some triangle's edge.
    jacobians : (K, 2, 2) ndarray
        d source / d target of each non-degenerate triangle (``kept`` holds their indices).
    """

    def __init__(self, source, target, triangles, canvas, tol=1e-6):
        width, height = canvas
        source, target = np.asarray(source, float), np.asarray(target, float)
        self.width, self.height = width, height
        self.covered = np.zeros((height, width), bool)
        self.near_edge = np.zeros((height, width), bool)
        self.candidates = []           # per triangle: (flat pixel indices, source positions)
        self.kept, jacobians = [], []
        for number, tri in enumerate(np.asarray(triangles)):
            p, s = target[tri], source[tri]
            e1, e2 = p[1] - p[0], p[2] - p[0]
            det = e1[0] * e2[1] - e1[1] * e2[0]
            if not abs(det) > 1e-12:
                continue
            self.kept.append(number)
            jacobians.append(np.column_stack([s[1] - s[0], s[2] - s[0]]) @ np.linalg.inv(np.column_stack([e1, e2])))
            pixels, q = self._box(p, tol)
            if pixels.size == 0:
                continue
            d = q - p[0]
            u = (d[:, 0] * e2[1] - d[:, 1] * e2[0]) / det            # barycentric coordinates
            v = (e1[0] * d[:, 1] - e1[1] * d[:, 0]) / det
            bary = np.stack([1 - u - v, u, v], 1)
            # signed distance to each edge, positive inside: bary_i times the height over edge i
            edge_length = np.hypot(*(p[[2, 0, 1]] - p[[1, 2, 0]]).T)
            margin = (bary * (abs(det) / edge_length)).min(axis=1)
            held = margin >= -tol
            self.covered.flat[pixels[margin > tol]] = True
            self.near_edge.flat[pixels[np.abs(margin) <= tol]] = True
            self.candidates.append((pixels[held], bary[held] @ s))
        self.jacobians = np.array(jacobians).reshape(-1, 2, 2)

    def _box(self, p, tol):
        """The pixel centres (flat index, (n, 2) position) in the bounding box of ``p``."""
        lo = np.maximum(np.floor(p.min(axis=0) - tol), 0).astype(int)
        hi = np.minimum(np.ceil(p.max(axis=0) + tol), [self.width - 1, self.height - 1]).astype(int)
        if (hi < lo).any():
            return np.zeros(0, int), np.zeros((0, 2))
        ys, xs = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
        return (ys * self.width + xs).ravel(), np.stack([xs.ravel(), ys.ravel()], 1).astype(float)

    def error(self, coords: np.ndarray) -> np.ndarray:
        """(H, W): distance from ``coords`` (H, W, 2) to the nearest source position that a
        triangle holding the pixel centre gives it (inf where no triangle holds it)."""
        best = np.full(self.width * self.height, np.inf)
        flat = np.asarray(coords, float).reshape(-1, 2)
        for pixels, positions in self.candidates:
            np.minimum.at(best, pixels, np.hypot(*(flat[pixels] - positions).T))
        return best.reshape(self.height, self.width)


def reference_footprint(jacobians: np.ndarray, max_steps: int = AA_MAX_STEPS, per_octave: int = 8,
                        start: float = AA_START, margin: float = BLEND_MARGIN, reach: float = TENT_REACH):
    """The filter of each Jacobian (n, 2, 2), from numpy's SVD and log2.

    m1 >= m2 >= 1 are the singular values less ``start^2 - 1`` in quadrature (floored at
    1). The level is made for m2 (at least reach m1 / sqrt(max_steps^2 + (reach start)^2),
    beyond which the tent would need more probes); the tent along the major left singular
    vector has radius reach sqrt(m1^2 - (start m2)^2) (0 below), probes at most m2 apart, at least 2 a side once it is
    1e-3 long, at most ``max_steps``. The pyramid level: ``b = floor(per_octave
    log2(m2))`` plus the weight of level b + 1, which rises linearly in m2 from 0 to 1
    between ``margin`` and ``1 - margin`` of the way from 2^(b / per_octave) to
    2^((b + 1) / per_octave). Returns (axis (n, 2), probes per side k (n,), spacing (n,),
    level b + weight (n,)).
    """
    u, sv, _ = np.linalg.svd(jacobians)
    slack = start ** 2 - 1
    m1, m2 = (np.sqrt(np.maximum(sv[:, i] ** 2 - slack, 1.0)) for i in (0, 1))
    m2 = np.maximum(m2, reach * m1 / np.sqrt(max_steps ** 2 + (reach * start) ** 2))
    radius = reach * np.sqrt(np.maximum(m1 ** 2 - (start * m2) ** 2, 0))
    k = np.where(radius < 1e-3, 1, np.clip(np.ceil(radius / m2 - 1e-9), 2, max_steps)).astype(int)
    b = np.floor(per_octave * np.log2(m2) + 1e-12)
    lo, hi = 2.0 ** (b / per_octave), 2.0 ** ((b + 1) / per_octave)
    weight = np.clip(((m2 - lo) / (hi - lo) - margin) / (1 - 2 * margin), 0, 1)
    return u[:, :, 0], k, radius / k, b + np.where(weight > 1 - 1e-4, 1.0, weight)
