"""Measures of a solved mesh: how well features kept their shape, how the rest followed W."""

from __future__ import annotations

import numpy as np

from .grid import signed_areas


def similarity_fits(source: np.ndarray, target: np.ndarray, labels: np.ndarray, count: int) -> dict:
    """Best-fit similarity (least squares) from ``source`` to ``target`` per label.

    Parameters
    ----------
    source, target : (n, 2) ndarray
        Corresponding points.
    labels : (n,) int ndarray
        Group of each point, 0 .. count-1.
    count : int

    Returns
    -------
    dict of (count,) ndarrays
        ``scale``, ``rotation_deg``, ``rms_px`` (residual after the fit) and
        ``diameter_px`` (diagonal of the group's source bounding box).
    """
    def per_label(values):
        return np.bincount(labels, weights=values, minlength=count)

    n = np.maximum(per_label(np.ones(labels.size)), 1)
    centre_s = np.stack([per_label(source[:, k]) / n for k in range(2)], axis=1)
    centre_t = np.stack([per_label(target[:, k]) / n for k in range(2)], axis=1)
    p, q = source - centre_s[labels], target - centre_t[labels]
    norm = np.maximum(per_label((p * p).sum(axis=1)), 1e-12)
    a = per_label(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]) / norm
    b = per_label(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]) / norm
    fitted = np.stack([a[labels] * p[:, 0] - b[labels] * p[:, 1],
                       b[labels] * p[:, 0] + a[labels] * p[:, 1]], axis=1)
    rms = np.sqrt(per_label(((fitted - q) ** 2).sum(axis=1)) / n)
    # Bounding boxes: min and max over each label's run of the label-sorted points
    # (np.minimum.at does the same 7x slower).
    order = np.argsort(labels, kind="stable")
    first = np.searchsorted(labels[order], np.arange(count))
    present = first < np.searchsorted(labels[order], np.arange(count), side="right")
    lo = np.full((count, 2), np.inf)
    hi = np.full((count, 2), -np.inf)
    if present.any():
        lo[present] = np.minimum.reduceat(source[order], first[present])
        hi[present] = np.maximum.reduceat(source[order], first[present])
    return {"scale": np.hypot(a, b), "rotation_deg": np.degrees(np.arctan2(b, a)), "rms_px": rms,
            "diameter_px": np.hypot(*(hi - lo).T)}


def triangle_anisotropy(source: np.ndarray, target: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Ratio of the larger to the smaller singular value of each triangle's affine map, (M,)
    (inf for a degenerate image).

    The map is J = T S^-1 with S and T the triangle's edge matrices, S's inverse as the 2x2
    adjugate; its singular values in closed form (:func:`entry_anisotropy`).
    """
    a, b, c = (np.ascontiguousarray(triangles[:, k]) for k in range(3))
    sx, sy = np.ascontiguousarray(source[:, 0]), np.ascontiguousarray(source[:, 1])
    tx, ty = np.ascontiguousarray(target[:, 0]), np.ascontiguousarray(target[:, 1])
    s00, s10 = sx.take(b) - sx.take(a), sy.take(b) - sy.take(a)          # S's columns: edges ab, ac
    s01, s11 = sx.take(c) - sx.take(a), sy.take(c) - sy.take(a)
    t00, t10 = tx.take(b) - tx.take(a), ty.take(b) - ty.take(a)
    t01, t11 = tx.take(c) - tx.take(a), ty.take(c) - ty.take(a)
    det = s00 * s11 - s01 * s10
    j00, j01 = (t00 * s11 - t01 * s10) / det, (t01 * s00 - t00 * s01) / det
    j10, j11 = (t10 * s11 - t11 * s10) / det, (t11 * s00 - t10 * s01) / det
    return entry_anisotropy(j00, j01, j10, j11)


def conformal_parts(j00, j01, j10, j11) -> tuple[tuple, tuple]:
    """The 2x2 maps' conformal and anticonformal parts as vectors, ((j00 + j11, j10 - j01),
    (j00 - j11, j10 + j01)): their lengths p and q give the singular values (p + q) / 2 and
    |p - q| / 2, and p > q exactly where the map keeps its orientation."""
    return (j00 + j11, j10 - j01), (j00 - j11, j10 + j01)


def entry_anisotropy(j00, j01, j10, j11) -> np.ndarray:
    """sigma_max / sigma_min of the 2x2 maps [[j00, j01], [j10, j11]], given entry by entry
    (arrays of one shape; inf where singular), from :func:`conformal_parts`."""
    conformal, anticonformal = conformal_parts(j00, j01, j10, j11)
    p, q = np.hypot(*conformal), np.hypot(*anticonformal)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(p - q) > 1e-12 * (p + q), (p + q) / np.abs(p - q), np.inf)


def background_rms(target: np.ndarray, warped: np.ndarray, quads: np.ndarray) -> float:
    """RMS length of (solution edge - W's edge) over the four edges of each of ``quads``; 0 if none.

    Edge k of a quad runs from corner k to corner k + 1 (cyclically). Computed per
    coordinate on gathered columns, which costs a third of gathering (K, 4, 2) blocks.
    """
    if not quads.size:
        return 0.0
    ahead = np.roll(quads, -1, axis=1)
    dx = (target[ahead, 0] - target[quads, 0]) - (warped[ahead, 0] - warped[quads, 0])
    dy = (target[ahead, 1] - target[quads, 1]) - (warped[ahead, 1] - warped[quads, 1])
    return float(np.sqrt((dx * dx + dy * dy).mean()))


def mesh_quality(source, target, warped, triangles, quads, node_component, n_components,
                 background_quads, near_feature_triangles) -> dict:
    """Quality figures of a solved mesh (JSON-ready).

    Parameters
    ----------
    source, target, warped : (N, 2) ndarray
        Node positions: source, solution, and the warp W itself.
    triangles : (M, 3) ndarray of int
    quads : (K, 4) ndarray of int
    node_component : (N,) int ndarray
        Feature component of each node, -1 outside features.
    n_components : int
    background_quads : (K,) bool ndarray
        Quads with plain (W) equations.
    near_feature_triangles : (M,) bool ndarray
        Background triangles in the transition band around features.

    Returns
    -------
    dict
        ``components`` (per component: scale, rotation, residual RMS in px and in %
        of its diameter), ``background_rms_px`` (edge vectors against W's),
        ``area_ratio`` (min, max of solution area / W area), ``flipped_triangles``,
        ``max_anisotropy_near_features`` and the same for W there (for reference).
    """
    report = {"components": []}
    on = node_component >= 0
    if n_components and on.any():
        fits = similarity_fits(source[on], target[on], node_component[on], n_components)
        for k in range(n_components):
            report["components"].append({
                "scale": float(fits["scale"][k]),
                "rotation_deg": float(fits["rotation_deg"][k]),
                "residual_rms_px": float(fits["rms_px"][k]),
                "residual_percent": float(100.0 * fits["rms_px"][k] / max(fits["diameter_px"][k], 1e-12)),
            })
    report["background_rms_px"] = background_rms(target, warped, quads[background_quads])
    area = signed_areas(target, triangles)
    reference = signed_areas(warped, triangles)
    valid = np.abs(reference) > 1e-12
    ratio = area[valid] / reference[valid]
    report["area_ratio"] = {"min": float(ratio.min(initial=1.0)), "max": float(ratio.max(initial=1.0))}
    report["flipped_triangles"] = int(np.count_nonzero(area <= 0))
    if near_feature_triangles.any():
        tri = triangles[near_feature_triangles]
        report["max_anisotropy_near_features"] = float(triangle_anisotropy(source, target, tri).max())
        report["warp_anisotropy_near_features"] = float(triangle_anisotropy(source, warped, tri).max())
    return report


def affine_fits(source: np.ndarray, target: np.ndarray, labels: np.ndarray, count: int) -> np.ndarray:
    """Least-squares affine map source -> target per label: the (count, 2, 2) linear parts.

    A label with fewer than three points, or points on a line, gets NaN.
    """
    def per_label(values):
        return np.bincount(labels, weights=values, minlength=count)

    n = per_label(np.ones(labels.size))
    safe = np.maximum(n, 1)
    centre_s = np.stack([per_label(source[:, k]) / safe for k in range(2)], axis=1)
    centre_t = np.stack([per_label(target[:, k]) / safe for k in range(2)], axis=1)
    p, q = source - centre_s[labels], target - centre_t[labels]
    spp = np.stack([np.stack([per_label(p[:, i] * p[:, j]) for j in range(2)], -1) for i in range(2)], -2)
    sqp = np.stack([np.stack([per_label(q[:, i] * p[:, j]) for j in range(2)], -1) for i in range(2)], -2)
    det = spp[:, 0, 0] * spp[:, 1, 1] - spp[:, 0, 1] * spp[:, 1, 0]
    good = (n >= 3) & (det > 1e-9 * np.maximum(spp[:, 0, 0] * spp[:, 1, 1], 1e-300))
    fits = np.full((count, 2, 2), np.nan)
    fits[good] = sqp[good] @ np.linalg.inv(spp[good])
    return fits


def map_anisotropy(maps: np.ndarray) -> np.ndarray:
    """sigma_max / sigma_min of each 2x2 map (inf where singular): (K,)."""
    sv = np.linalg.svd(maps, compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sv[:, 1] > 0, sv[:, 0] / np.maximum(sv[:, 1], 1e-300), np.inf)


def component_figures(source, target, warped, triangles, tri_component, node_component, n_components,
                      plain: bool = True) -> dict:
    """Per component: how its triangles and its whole region came out, and under W.

    Parameters
    ----------
    source, target, warped : (N, 2) ndarray
        Node positions in the source, in the solution and under W.
    triangles : (M, 3) int ndarray
    tri_component : (M,) int ndarray
        Component of each triangle of a feature quad, -1 for the others.
    node_component : (N,) int ndarray
        Component of each node of a feature quad, -1 for the others.
    n_components : int
    plain : bool
        Also the figures under W (else the ``plain_`` ones are zeros).

    Returns
    -------
    dict of (n_components,) ndarrays
        ``distortion`` and ``plain_distortion`` (affine fit over the component's
        nodes, sigma_max / sigma_min - 1), ``anisotropy_worst``, ``anisotropy_mean``,
        ``plain_anisotropy_worst`` (its triangles, - 1), ``scale`` and
        ``rotation_deg`` of the fit, ``area_ratio``.
    """
    on = tri_component >= 0
    tris, comp = triangles[on], tri_component[on]
    count = np.maximum(np.bincount(comp, minlength=n_components), 1)
    out = {"plain_anisotropy_worst": np.zeros(n_components), "plain_distortion": np.zeros(n_components)}
    for name, points in (("", target), ("plain_", warped))[:2 if plain else 1]:
        aniso = triangle_anisotropy(source, points, tris) - 1.0
        out[name + "anisotropy_worst"] = np.zeros(n_components)
        np.maximum.at(out[name + "anisotropy_worst"], comp, aniso)
        if not name:
            out["anisotropy_mean"] = np.bincount(comp, aniso, minlength=n_components) / count
        nodes = np.flatnonzero(node_component >= 0)
        fits = affine_fits(source[nodes], points[nodes], node_component[nodes], n_components)
        out[name + "distortion"] = np.nan_to_num(map_anisotropy(np.nan_to_num(fits)) - 1.0, nan=0.0, posinf=1e9)
        if not name:
            det = fits[:, 0, 0] * fits[:, 1, 1] - fits[:, 0, 1] * fits[:, 1, 0]
            out["scale"] = np.sqrt(np.abs(np.nan_to_num(det)))
            out["rotation_deg"] = np.nan_to_num(np.degrees(np.arctan2(fits[:, 1, 0] - fits[:, 0, 1],
                                                                       fits[:, 0, 0] + fits[:, 1, 1])))
    area_t = np.bincount(comp, signed_areas(target, tris), minlength=n_components)
    area_s = np.bincount(comp, signed_areas(source, tris), minlength=n_components)
    out["area_ratio"] = area_t / np.maximum(area_s, 1e-12)
    return out



def frame_strip_figures(grid, nodes, target, node_component, n_components: int, points, labels) -> list:
    """Per component, where its mask stops short of the frame, how its pixels in the frame's
    outer cells ended (:attr:`featurewarp_cli.engine.features.Features.frame_strip`: ``points``
    (P, 2) and their components ``labels``): they follow the background, which the frame holds
    there, not the component's shape.

    Returns
    -------
    list of dict or None
        Per component, None without such pixels, else ``sides`` (the frame's sides they lie
        along), ``pixels``, ``off_px`` (the farthest any ends from where the component's
        affine fit over its nodes puts it: the piecewise-linear map of the mesh at the pixel
        against the fit) and ``cell_px`` (the ``--cell`` from which none of them lies in the
        outer cells: :func:`_cell_past`).
    """
    (sx, sy), (qy, qx) = grid.spacing, grid.quad_shape
    col = np.minimum(((points[:, 0] + 0.5) / sx).astype(int), qx - 1)
    row = np.minimum(((points[:, 1] + 0.5) / sy).astype(int), qy - 1)
    u, v = ((points[:, 0] + 0.5) / sx - col)[:, None], ((points[:, 1] + 0.5) / sy - row)[:, None]
    tl = row * grid.nx + col
    a, b, c, d = target[tl], target[tl + 1], target[tl + 1 + grid.nx], target[tl + grid.nx]   # TL TR BR BL
    mapped = a + np.where(u >= v, u * (b - a) + v * (c - b), v * (d - a) + u * (c - d))   # the quad's two triangles
    on = np.flatnonzero(node_component >= 0)
    linear = affine_fits(nodes[on], target[on], node_component[on], n_components)
    count = np.maximum(np.bincount(node_component[on], minlength=n_components), 1)
    centre_s, centre_t = (np.stack([np.bincount(node_component[on], p[on, k], minlength=n_components) / count
                                    for k in range(2)], axis=1) for p in (nodes, target))
    fitted = centre_t[labels] + np.einsum("kij,kj->ki", linear[labels], points - centre_s[labels])
    off = np.nan_to_num(np.hypot(*(mapped - fitted).T), nan=0.0)
    sides = {"top": (row == 0, points[:, 1], grid.height), "bottom": (row == qy - 1, grid.height - 1 - points[:, 1],
                                                                      grid.height),
             "left": (col == 0, points[:, 0], grid.width), "right": (col == qx - 1, grid.width - 1 - points[:, 0],
                                                                     grid.width)}
    out = []
    for k in range(n_components):
        mine = labels == k
        along = {side: (gap[on & mine].min(), length) for side, (on, gap, length) in sides.items() if (on & mine).any()}
        out.append(None if not mine.any() else {
            "sides": list(along), "pixels": int(mine.sum()), "off_px": round(float(off[mine].max()), 3),
            "cell_px": _cell_past(along.values())})
    return out


def _cell_past(gaps) -> float:
    """The largest ``--cell`` (floored to 0.001 px) whose grid (:meth:`Grid.for_image`: round(L /
    cell) cells of L / that each) puts a pixel ``gap`` px from its edge out of the outer cell,
    for every (gap, the side's length L) of ``gaps``: a cell under gap + 0.5, n = floor(L /
    (gap + 0.5)) + 1 of them (gap + 0.5 itself left the pixel there on a 399 px side)."""
    cell = min(length / (np.floor(length / (gap + 0.5)) + 1) for gap, length in gaps)
    return float(np.floor(cell * 1000) / 1000)
