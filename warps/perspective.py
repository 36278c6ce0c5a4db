"""Perspective: the homography that sends the image's four corners to four given points."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, ParamError, Warp, resolve_pair

from .common import fit_canvas

CORNERS = ("tl", "tr", "br", "bl")
WORDS = {"tl": "top-left", "tr": "top-right", "br": "bottom-right", "bl": "bottom-left"}
#: Smallest interior angle of the quadrilateral, in degrees: a sharper corner squeezes part
#: of the image into a sliver no grid follows.
MIN_ANGLE = 5.0
#: Largest interior angle, in degrees: a flatter corner makes the quadrilateral nearly a
#: triangle, and --tl 45%,45% (174 degrees) needed a 2 px grid and took 34 s CPU at 1 MP with
#: features; 170 takes at most 5 s, and corners as sharp as 6 degrees 12 s.
MAX_ANGLE = 170.0
#: Shortest side of the quadrilateral, in the image's frame (its width and height are 1):
#: --tl 49.9%,0% --tr 50.1%,0% (0.2 %) took 60 to 120 s and 1.8 GB, and its grid was 16 px off.
MIN_SIDE = 0.05


def _corner(name: str, default: tuple[str, str]) -> Param:
    return Param(name, tuple, default, f"Where the {WORDS[name]} corner goes: X,Y from the image's top-left "
                 f"corner, pixels or percentages of its size (100%,100%: its bottom-right).", metavar="X,Y")


def homography(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The 3 x 3 matrix H (``H[2, 2] = 1``) that maps four ``(4, 2)`` source points onto four targets."""
    x, y = source[:, 0], source[:, 1]
    u, v = target[:, 0], target[:, 1]
    one, zero = np.ones(4), np.zeros(4)
    rows = np.concatenate([np.stack([x, y, one, zero, zero, zero, -u * x, -u * y], 1),
                           np.stack([zero, zero, zero, x, y, one, -v * x, -v * y], 1)])
    h = np.linalg.solve(rows, np.concatenate([u, v]))
    return np.append(h, 1.0).reshape(3, 3)


def check_quadrilateral(quad: np.ndarray) -> None:
    """Raise ParamError unless ``quad`` (tl, tr, br, bl) is convex, in the image's order, its
    angles from :data:`MIN_ANGLE` to :data:`MAX_ANGLE` degrees, its sides at least :data:`MIN_SIDE`.

    ``quad`` is in units of the image's width and height (its own corners at 0 and 1), so
    that a long strip's quadrilateral is judged as a square's.

    The turn at each corner is the cross product of the edges in and out; on screen (y down)
    the image's own corners turn positively. Two negative turns make a self-crossing
    quadrilateral, one or three a concave one, four a mirror image.
    """
    edges = np.roll(quad, -1, axis=0) - quad                 # edge i leaves corner i
    incoming = np.roll(edges, 1, axis=0)
    turn = incoming[:, 0] * edges[:, 1] - incoming[:, 1] * edges[:, 0]
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    if lengths.min() <= 1e-9 * max(lengths.max(), 1.0):
        raise ParamError(CORNERS, "two corners coincide")
    sines = turn / (lengths * np.roll(lengths, 1))
    negative = np.flatnonzero(sines < 0)
    if len(negative) == 2:
        raise ParamError(CORNERS, "the quadrilateral crosses itself (its sides cross)")
    if len(negative) == 4:
        raise ParamError(CORNERS, "the corners are in mirror order (the image would be flipped)")
    if len(negative):
        odd = negative[0] if len(negative) == 1 else np.flatnonzero(sines >= 0)[0]
        raise ParamError(CORNERS, f"the quadrilateral is concave at `{CORNERS[odd]}`")
    cosines = -(incoming * edges).sum(1) / (lengths * np.roll(lengths, 1))
    angles = np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0)))
    worst = int(np.argmin(angles)) if angles.min() < MIN_ANGLE else int(np.argmax(angles))
    if not MIN_ANGLE <= angles[worst] <= MAX_ANGLE:
        raise ParamError(CORNERS, f"the angle at `{CORNERS[worst]}` is {angles[worst]:.3g} degrees "
                                  f"({MIN_ANGLE:g} to {MAX_ANGLE:g})")
    short = int(np.argmin(lengths))
    if lengths[short] < MIN_SIDE:
        raise ParamError(CORNERS, f"the side from `{CORNERS[short]}` to `{CORNERS[(short + 1) % 4]}` is "
                                  f"{100 * lengths[short]:.3g} % of the image; at least {100 * MIN_SIDE:g} % "
                                  f"(a shorter one squeezes the image more than a grid can follow in bounded time)")


class Perspective(Warp):
    """Move the image's four corners to --tl, --tr, --br and --bl, the rest following in
    perspective (corner pinning). Each is X,Y from the image's top-left corner, in pixels or
    percentages of its size; a corner not given takes its default (10%,0% 90%,0% 100%,100%
    0%,100%: the image tilted back a little). The quadrilateral must be convex, in the
    image's order, its angles 5 to 170 degrees and its sides at least 5 % of the image. The
    canvas is its bounding box, so only the shape matters, not where it is.

    A projective map (homography) of the image's corners onto the four points. One-to-one:
    write ``W(p) = (a(p), b(p)) / c(p)`` with a, b, c affine. The corners must
    make a convex quadrilateral in the image's order (:func:`check_quadrilateral`, else a
    ParamError naming the problem). Then c has one sign at the four corners (checked
    too): were it to change sign on the rectangle, W would send part of it beyond the line
    at infinity and the image would be unbounded, not the quadrilateral. c is affine, so
    it keeps that sign on the whole rectangle, where W is smooth with Jacobian determinant
    ``det(H) / c^3`` of one sign, positive as the corners keep their order. W maps each
    side onto the segment between its corners, the border onto the quadrilateral's
    border once, so W is one-to-one onto the quadrilateral.
    """

    name = "perspective"
    summary = "Perspective (corner pinning, Distort > Perspective): the four corners go to four points."
    example = "--tl 20%,5% --tr 85%,0%"
    params = (_corner("tl", ("10%", "0%")), _corner("tr", ("90%", "0%")), _corner("br", ("100%", "100%")),
              _corner("bl", ("0%", "100%")))

    def _setup(self, tl, tr, br, bl):
        w, h = self.width, self.height
        source = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
        target = np.array([resolve_pair(p, w, h) for p in (tl, tr, br, bl)]) - 0.5
        check_quadrilateral((target + 0.5) / [w, h])     # in the image's frame: any size alike
        self.matrix = homography(source, target)
        denominators = np.c_[source, np.ones(4)] @ self.matrix[2]
        if not (np.all(denominators > 0) or np.all(denominators < 0)) or not math.isfinite(self.matrix.sum()):
            raise ParamError(CORNERS, "no perspective maps the image onto these corners")
        self._shift = 0.0
        self._shift = fit_canvas(self, self.forward)

    def forward(self, points):
        mapped = np.c_[points, np.ones(len(points))] @ self.matrix.T
        return mapped[:, :2] / mapped[:, 2:] - self._shift
