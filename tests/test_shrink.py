"""Features that cannot keep their shape at the size least squares picked, but can smaller
(similarity mode): the guard asks for the smaller similarities (``scale_search.shrink_to_fit``)
where it would release a feature and before it does (``guard.guard(before_release=...)``), so no
release is computed only to be thrown away; where the window opens the folds, it does not ask."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.engine import guard, scale_search

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _sample_mask(name, size):
    mask = cv2.imread(os.path.join(ROOT, "samples", name), cv2.IMREAD_GRAYSCALE)
    h, w = mask.shape
    w, h = round(w * size / max(w, h)), round(h * size / max(w, h))
    return cv2.resize(mask, (w, h), interpolation=cv2.INTER_NEAREST) >= 128


def _discs(width, height):
    y, x = np.mgrid[0:height, 0:width]
    return (((x - width / 2) ** 2 + (y - height / 2) ** 2 < (0.15 * height) ** 2)
            | ((x - 0.2 * width) ** 2 + (y - 0.3 * height) ** 2 < (0.1 * height) ** 2))


def _solve(mask, preset, quick=False, **params):
    h, w = mask.shape
    return FeatureWarper(w, h, mask).solve(load_warp(preset)(w, h, **params), "similarity", quick=quick)


@pytest.fixture
def calls(monkeypatch):
    """The releases and the shrinks (their results) of the solves that follow."""
    seen = {"release": 0, "shrink": []}
    release, shrink = guard._release, scale_search.shrink_to_fit

    def counted_release(*args):
        seen["release"] += 1
        return release(*args)

    def counted_shrink(*args):
        seen["shrink"].append(shrink(*args))
        return seen["shrink"][-1]

    monkeypatch.setattr(guard, "_release", counted_release)
    monkeypatch.setattr(scale_search, "shrink_to_fit", counted_shrink)
    return seen


def test_smaller_similarities_that_fit_are_guarded_instead_of_a_release(calls):
    mesh = _solve(_sample_mask("coins_mask.png", 160), "stretch", sx=0.5)    # packed coins at half their width
    assert calls["release"] == 0 and len(calls["shrink"]) == 1 and calls["shrink"][0] is not None
    ab, (smaller, *_) = calls["shrink"][0]                  # the smaller similarities and their solution
    record = mesh.record
    assert record.guard.release_rounds == 0 and mesh.flips() == 0
    assert record.guard.path_steps == 0 and record.guard.untangle_iterations == 0    # the second guard's record
    kept = [c for c in record.components if c.kept]
    assert len(kept) == len(record.components) > 0
    assert np.allclose(sorted(c.scale for c in kept), sorted(np.hypot(*ab[:len(kept)].T)), rtol=1e-9)
    assert np.abs(mesh.target - smaller).max() < 1e-9     # it crushes no triangle: guarded, it stays as it is


def test_where_the_smaller_ones_do_not_fit_the_release_follows(calls):
    mesh = _solve(_discs(80, 60), "stretch", sx=0.05)      # two discs pressed to a twentieth of their width
    assert calls["shrink"] == [None] and calls["release"] == 1
    assert mesh.record.guard.release_rounds > 0 and mesh.flips() == 0


def test_where_the_window_opens_the_folds_or_in_a_preview_nothing_is_shrunk(calls):
    mesh = _solve(_sample_mask("shapes_mask.png", 128), "swirl", angle=150)
    assert mesh.record.guard.flipped_before > 0 and mesh.record.guard.window_quads > 0
    assert all(c.kept for c in mesh.record.components) and mesh.flips() == 0
    preview = _solve(_sample_mask("coins_mask.png", 160), "stretch", quick=True, sx=0.5)
    assert preview.record.guard.flipped_before > 0 and preview.record.guard.preview_eased
    assert calls == {"release": 0, "shrink": []}
