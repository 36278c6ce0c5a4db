"""Issue 11's interactive case: moving one of 10 handles on a 1 MP photo through the API.

A :class:`featurewarp_cli.Deformer` in quick mode (the editor's) at the default cell solves
10 handles once (both factorizations), then one handle moves in small steps; each update
(rigid map, feature-aware mesh, per-component figures) is timed. Neither system may be
factored again.
"""

from __future__ import annotations

import time

import numpy as np

#: 10 handles on a 1000 x 1000 frame (scaled to the photo): pins near the corners and sides,
#: and the handle that moves (the last) on the body.
HANDLES = [(60, 60), (940, 60), (940, 940), (60, 940), (500, 60), (60, 500), (940, 500), (500, 940),
           (300, 700), (620, 760)]
STEPS = 12


def bench_deform(runs: int, photo1, mask1, median) -> dict:
    from featurewarp_cli import Deformer, Handles
    from featurewarp_cli.io.decode import mask_from_image, read_image

    image = read_image(str(photo1))
    mask = mask_from_image(read_image(str(mask1)))
    h, w = image.shape[:2]
    sources = [[x * (w - 1) / 999, y * (h - 1) / 999] for x, y in HANDLES]
    handles = Handles.from_dict({"version": 1, "canvas": "input",
                                 "points": [{"from": p, "to": p} for p in sources]}, w, h)
    deformer = Deformer(w, h, mask, quick=True)
    t0 = time.perf_counter()
    deformer.solve(handles)
    first = time.perf_counter() - t0
    factored, rigid = deformer.warper.factorizations, deformer.rigid.rigid
    targets = np.array(sources)
    times, flips = [], []
    for step in range(max(runs, 10)):
        targets[-1] += (3.0, 2.0)
        t0 = time.perf_counter()
        mesh = deformer.move(targets)
        times.append(time.perf_counter() - t0)
        flips.append(mesh.flips())
    assert deformer.warper.factorizations == factored and deformer.rigid.rigid is rigid, "an update refactored"
    result = {"size": [w, h], "handles": len(sources), "first_s": first, "seconds": times,
              "median_s": median(times), "flips": flips, "nodes": int(mesh.source.shape[0]),
              "kept": sum(c.kept for c in mesh.record.components), "components": len(mesh.record.components)}
    print(f"\nDeform through the API, {w}x{h}, {len(sources)} handles (first solve {first:.3f} s), "
          f"one handle moving, median of {len(times)}")
    print(f"  update {result['median_s'] * 1000:7.1f} ms  ({result['nodes']} nodes, folds {max(flips)}, "
          f"features kept {result['kept']}/{result['components']})")
    return result
