"""The editor prepares the feature-aware systems while its page loads (``Deformer.prepare``):
the page's first update then factors only its own handle set, and no result changes."""

from __future__ import annotations

import os

import cv2
import numpy as np

from featurewarp_cli.app.editor_session import EditorSession
from featurewarp_cli.app.pipeline import Settings
from featurewarp_cli.engine.deform import Deformer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMAGE = os.path.join(ROOT, "samples", "astronaut.png")
MASK = os.path.join(ROOT, "samples", "astronaut_mask.png")
SIZE = 256
PINS = [{"from": [20, 235], "to": [20, 235]}, {"from": [235, 235], "to": [235, 235]},
        {"from": [20, 20], "to": [20, 20]}]


def _handles(start, to):
    return {"version": 1, "canvas": "fit", "points": PINS + [{"from": list(start), "to": list(to)}]}


def _drag(deformer, start, end, updates=3):
    """The meshes of a drag as the editor solves it: the handle set's first solve, drag updates, the release."""
    meshes = [deformer.solve(_handles(start, start))]
    for k in range(1, updates + 1):
        to = np.add(start, np.subtract(end, start) * k / updates).round(3).tolist()
        meshes.append(deformer.solve(_handles(start, to), drag=k < updates))
    return meshes


def _deformer():
    mask = cv2.resize(cv2.imread(MASK, cv2.IMREAD_GRAYSCALE), (SIZE, SIZE), interpolation=cv2.INTER_NEAREST) >= 128
    return Deformer(SIZE, SIZE, mask, quick=True, rigid_steps=8)


def test_a_prepared_deformer_gives_the_same_meshes_and_factors_only_the_rigid_map():
    prepared, fresh = _deformer(), _deformer()
    prepared.prepare()
    factored = prepared.warper.factorizations
    assert factored > 0 and prepared.handles is None and prepared.rigid.rigid is None
    for start, end in (((212, 75), (140, 65)), ((128, 140), (40, 220))):    # onto the head; towards a pin
        ours, theirs = _drag(prepared, start, end), _drag(fresh, start, end)
        for a, b in zip(ours, theirs):
            assert np.array_equal(a.target, b.target) and a.canvas == b.canvas
            assert a.record.warnings == b.record.warnings
    assert fresh.warper.factorizations > 0
    assert prepared.warper.factorizations == factored       # the page's handle sets: nothing factored anew


def test_the_editor_prepares_while_the_page_loads(tmp_path):
    image = tmp_path / "small.png"
    cv2.imwrite(str(image), cv2.resize(cv2.imread(IMAGE), (SIZE, SIZE), interpolation=cv2.INTER_AREA))
    mask = tmp_path / "small_mask.png"
    cv2.imwrite(str(mask), cv2.resize(cv2.imread(MASK, cv2.IMREAD_GRAYSCALE), (SIZE, SIZE),
                                      interpolation=cv2.INTER_NEAREST))
    session = EditorSession(Settings("deform"), str(image), str(mask), None, str(tmp_path / "out.png"))
    session.preparing.join(timeout=60)
    factored = session.deformer.warper.factorizations
    assert not session.preparing.is_alive() and factored > 0
    status, _ = session.solve({"handles": _handles((212, 75), (150, 70)), "seq": 1, "client": "page"})
    assert status["folds"] == 0 and session.deformer.warper.factorizations == factored
    session.set_density({"density": "fewer"})                # a new deformer is prepared too
    session.preparing.join(timeout=60)
    assert session.deformer.warper.factorizations > 0
