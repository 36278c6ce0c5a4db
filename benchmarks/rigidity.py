"""Issue 23's rigid map against libigl's converged ARAP (``make bench``, section ``rigid``).

Seven handle sets on a photo-sized frame (a lean, squashes to half width held by point
handles, by the left and right sides and by all four, a curve bend, a drag onto a feature
and a handle on a feature). For each: our rigid map (:class:`RigidMap`) and libigl's
``arap_solve`` run to 2 000 iterations on the same grid, its constraints the same samples
snapped to the nearest nodes (libigl takes fixed vertices). Printed and returned per case:
the area ratio (deformed over source), the rigidity error (mean |J - R|^2 over background
triangles, R the closest rotation of each triangle's Jacobian J), folded triangles, and our
Newton steps and time. libigl's ARAP folds triangles where the handles ask for it; ours
never does, so there it is less rigid by what the folds buy.

Usage::

    .venv/bin/python -m benchmarks.rigidity [--size W H]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _side(p0, p1, n=9):
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (np.asarray(p0, float) * (1 - t) + np.asarray(p1, float) * t).tolist()


def cases(width: int, height: int) -> dict:
    """The handle sets (handles-file dicts) on a ``width`` x ``height`` frame, and whether each
    needs the feature mask: {name: (handles, with_mask)}."""
    sx, sy = width / 512, height / 384
    r, b = width - 1, height - 1

    def pin(x, y):
        return {"from": [x * sx, y * sy], "to": [x * sx, y * sy]}

    def move(x, y, dx, dy):
        return {"from": [x * sx, y * sy], "to": [(x + dx) * sx, (y + dy) * sy]}

    arc = [[(20 + 470 * t) * sx, (190 - 120 * np.sin(np.pi * t)) * sy] for t in np.linspace(0, 1, 20)]
    corners = [pin(30, 30), pin(480, 30), pin(30, 350), pin(480, 350)]
    return {
        "lean": ({"points": [pin(60, 374), pin(450, 374), move(150, 40, 80, 0), move(360, 40, 80, 0)]}, False),
        "squash, point handles": ({"points": [pin(10, 40), pin(10, 340), move(500, 40, -250, 0),
                                              move(500, 340, -250, 0)]}, False),
        "squash, sides held": ({"border": {"left": _side([0, 0], [0, b]),
                                           "right": _side([r / 2, 0], [r / 2, b])}}, False),
        "squash, four sides": ({"border": {"top": _side([0, 0], [r / 2, 0]), "bottom": _side([0, b], [r / 2, b]),
                                           "left": _side([0, 0], [0, b]),
                                           "right": _side([r / 2, 0], [r / 2, b])}}, False),
        "bend (curve)": ({"curves": [{"from": _side([20 * sx, 190 * sy], [490 * sx, 190 * sy], 20), "to": arc}]},
                         False),
        "drag onto a feature": ({"points": corners + [move(100, 300, 120, -80)]}, True),
        "handle on a feature": ({"points": corners + [move(300, 200, 60, 40)]}, True),
    }


def measures(nodes: np.ndarray, source: np.ndarray, triangles: np.ndarray, background: np.ndarray) -> dict:
    """Area ratio, rigidity error over ``background`` triangles, and folded triangles."""
    from featurewarp_cli.engine.grid import signed_areas

    before, after = signed_areas(source, triangles), signed_areas(nodes, triangles)
    p, q = source[triangles], nodes[triangles]
    edges_p = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], -1)
    edges_q = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]], -1)
    jacobian = edges_q @ np.linalg.inv(edges_p)
    u, _, vt = np.linalg.svd(jacobian)
    error = np.sum((jacobian - u @ vt) ** 2, axis=(1, 2))
    return {"area_ratio": float(after.sum() / before.sum()), "rigidity": float(error[background].mean()),
            "folds": int(np.count_nonzero(after <= 0))}


def libigl_arap(grid, sources, targets, iterations: int = 2000) -> np.ndarray:
    """libigl's ARAP of ``grid`` with the nodes nearest ``sources`` held at ``targets`` (moved
    by the same displacement as their samples)."""
    import igl

    nodes = grid.nodes()
    spacing = np.array(grid.spacing)
    index = np.rint((sources + 0.5) / spacing).astype(int)
    index[:, 0] = np.clip(index[:, 0], 0, grid.nx - 1)
    index[:, 1] = np.clip(index[:, 1], 0, grid.ny - 1)
    held, first = np.unique(index[:, 1] * grid.nx + index[:, 0], return_index=True)
    positions = nodes[held] + (targets - sources)[first]
    data = igl.ARAPData()
    data.max_iter = iterations
    igl.arap_precomputation(nodes, grid.triangles().astype(np.int64), 2, held.astype(np.int32), data)
    return igl.arap_solve(positions, data, nodes.copy())


def compare(handles: dict, width: int, height: int, mask=None, iterations: int = 2000) -> dict:
    """Our rigid map and libigl's ARAP on one handle set: {'ours': ..., 'libigl': ...}."""
    from featurewarp_cli.engine.arap import _disc_offsets, disc_turn, rest_scale, similarity_fit
    from featurewarp_cli.engine.deform import DECAY, RigidMap, carried_features, default_radius
    from featurewarp_cli.engine.handles import Handles

    parsed = Handles.from_dict({"version": 1, "canvas": "input", **handles}, width, height)
    rigid = RigidMap(width, height, mask=mask)
    t0 = time.perf_counter()
    warp = rigid.deformation(parsed)
    seconds = time.perf_counter() - t0
    grid = rigid.grid
    source, triangles = grid.nodes(), grid.triangles()
    radius = parsed.radius if parsed.radius is not None else default_radius(width, height, max(grid.spacing))
    sources, targets, radii = parsed.constraints(grid, radius)
    if mask is not None:
        sources, targets, radii = carried_features(rigid.labels, source, parsed, sources, targets, radii,
                                                   DECAY * max(grid.spacing))
    offsets = _disc_offsets(radii)
    samples_from = (sources[:, None] + offsets).reshape(-1, 2)
    samples_to = (targets[:, None] + offsets @ disc_turn(*similarity_fit(sources, targets),
                                                         rest_scale(sources, targets)).T).reshape(-1, 2)
    t0 = time.perf_counter()
    reference = libigl_arap(grid, samples_from, samples_to, iterations)
    reference_seconds = time.perf_counter() - t0
    background = np.ones(len(triangles), bool)
    if mask is not None:
        centre = np.clip(np.rint(source[triangles].mean(axis=1)).astype(int), 0, [width - 1, height - 1])
        background = ~np.asarray(mask, bool)[centre[:, 1], centre[:, 0]]
    ours = measures(warp.nodes + np.asarray(warp.offset), source, triangles, background)
    ours.update(seconds=seconds, newton_steps=rigid.rigid.newton_steps, converged=rigid.rigid.converged)
    theirs = measures(reference, source, triangles, background)
    theirs.update(seconds=reference_seconds)
    return {"ours": ours, "libigl": theirs}


def bench_rigid(width: int = 512, height: int = 384) -> dict:
    """Every case of :func:`cases`, printed as a table."""
    import cv2

    mask = cv2.imread(str(ROOT / "samples" / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE)
    mask = cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST) > 127
    print(f"\nRigid map against libigl's converged ARAP (2 000 iterations), {width}x{height}")
    print(f"  {'case':22s} {'area ours':>9s} {'libigl':>7s} {'rigidity ours':>13s} {'libigl':>7s} {'ratio':>6s} "
          f"{'folds ours':>10s} {'libigl':>6s} {'steps':>5s} {'time':>7s}")
    results = {}
    for name, (handles, with_mask) in cases(width, height).items():
        r = compare(handles, width, height, mask if with_mask else None)
        ours, theirs = r["ours"], r["libigl"]
        print(f"  {name:22s} {ours['area_ratio']:9.3f} {theirs['area_ratio']:7.3f} {ours['rigidity']:13.4f} "
              f"{theirs['rigidity']:7.4f} {ours['rigidity'] / max(theirs['rigidity'], 1e-12):6.2f} "
              f"{ours['folds']:10d} {theirs['folds']:6d} {ours['newton_steps']:5d} {ours['seconds'] * 1000:5.0f} ms")
        results[name] = r
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", nargs=2, type=int, default=(512, 384), metavar=("W", "H"))
    args = parser.parse_args()
    bench_rigid(*args.size)


if __name__ == "__main__":
    main()
