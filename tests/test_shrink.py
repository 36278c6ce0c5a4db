"""Features that cannot keep their shape at the size least squares picked, but can smaller
(similarity mode): the guard asks for the smaller similarities before it releases any feature
(``guard.guard(before_release=...)``), so no release is computed only to be thrown away."""

from __future__ import annotations

import os

import cv2
import numpy as np

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.engine import guard, scale_search

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _coins(size):
    mask = cv2.imread(os.path.join(ROOT, "samples", "coins_mask.png"), cv2.IMREAD_GRAYSCALE)
    h, w = mask.shape
    w, h = round(w * size / max(w, h)), round(h * size / max(w, h))
    return w, h, cv2.resize(mask, (w, h), interpolation=cv2.INTER_NEAREST) >= 128


def _solve(w, h, mask):
    return FeatureWarper(w, h, mask).solve(load_warp("stretch")(w, h, sx=0.6, sy=1.2), "similarity")


def test_smaller_similarities_are_tried_before_a_release_and_give_what_the_release_first_order_gave(monkeypatch):
    w, h, mask = _coins(128)                # packed coins squeezed to 0.6 of their width
    calls = {"release": 0, "shrink": []}
    release, shrink, original = guard._release, scale_search.shrink_to_fit, guard.guard

    def counted_release(*args):
        calls["release"] += 1
        return release(*args)

    def counted_shrink(*args):
        found = shrink(*args)
        calls["shrink"].append(found is not None)
        return found

    monkeypatch.setattr(guard, "_release", counted_release)
    monkeypatch.setattr(scale_search, "shrink_to_fit", counted_shrink)
    mesh = _solve(w, h, mask)
    assert calls == {"release": 0, "shrink": [True]}
    assert mesh.record.guard.release_rounds == 0 and mesh.flips() == 0
    assert all(c.kept for c in mesh.record.components)

    def release_first(problem, x, record, before_release=None):     # the order until 2026-11-28
        result = original(problem, x, record)
        if before_release is not None and record.release_rounds and before_release():
            return None
        return result

    monkeypatch.setattr(guard, "guard", release_first)
    reference = _solve(w, h, mask)
    assert calls["release"] == 1 and calls["shrink"] == [True, True]
    assert np.array_equal(mesh.target, reference.target)
