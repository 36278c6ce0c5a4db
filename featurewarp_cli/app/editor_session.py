"""What ``featurewarp edit`` works on: the image, its mask, the deformer, and what Save and
Export write (the HTTP side is :mod:`featurewarp_cli.app.editor`).

Live updates follow a small protocol (issue 23): the page keeps at most one solve in flight
and numbers its requests (``client``, ``seq``); a request older than the newest one seen
from its page, on arrival or after waiting for the solver, is answered ``stale`` at once
without solving, so the newest pointer position always wins. A request marked ``drag``
caps the rigid map's Newton steps at :data:`DRAG_RIGID_STEPS` and, where the features'
least-squares solution folds, eases it towards the rigid map instead of untangling it
(``FeatureWarper.solve(drag=True)``); the page sends one unmarked request when the pointer is
released, so what stays on screen is the guarded preview (every answer is a bounded preview:
see ``FeatureWarper.solve(quick=True)``; Export runs the full pipeline).
"""

from __future__ import annotations

import base64
import math
import os
import shlex
import struct
import threading
import time
from dataclasses import replace

import numpy as np

from ..engine.handle_review import FOLD_ASK
from ..io import write
from .editor_files import (Snapshot, Unconfirmed, decode_mask, handles_json, naming, png,  # noqa: F401
                           texture, write_named)
from .pipeline import Settings, WarpError, load_image_and_mask, warp_file

#: The live preview's grid is the handles' rigid grid refined k times (:func:`deform.solve_grid`),
#: k from the cell of ``--cell`` or the pipeline's base cell (:func:`fidelity.base_cell`); the
#: densities ``fewer`` and ``more`` take k/2 (rounded up) and 2k. About this many nodes at most
#: at any density (a forced small ``--cell``; the capped cell is rounded to a refinement).
#: Export uses the full pipeline, whose grid also follows the warp.
PREVIEW_MAX_NODES = 260_000
#: The rigid map's Newton steps per update at most (each warm-started from the last update;
#: Export runs them to convergence), and while the pointer is still dragging.
EDITOR_RIGID_STEPS = 8
DRAG_RIGID_STEPS = 1
#: The page's mesh densities: the rigid grid's refinement at each, from the normal one's k.
DENSITIES = {"fewer": lambda k: -(-k // 2), "normal": lambda k: k, "more": lambda k: 2 * k}
#: Pages whose newest request number is remembered.
CLIENTS = 16


def companion(path: str | None, suffix: str) -> str | None:
    """``path`` with its extension replaced by ``suffix`` (``out.png`` -> ``out.handles.json``)."""
    if not path or path == "-":
        return None
    return os.path.splitext(path)[0] + suffix


class EditorSession:
    """What the editor works on: the image, its mask, the deformer and the files it may write.

    Parameters
    ----------
    settings : Settings
        The ``deform`` options (mode, cell, weights, output format and quality).
    input, mask : str
        The image and its feature mask (mask may be None).
    handles_path, output_path : str or None
        Where Save and Export write (None: the browser downloads instead). Export without
        ``handles_path`` writes the handles beside the output (``OUT.handles.json``).
    handles : dict or None
        The handles to start from (a parsed handles file; ValueError when they do not fit).
    mask_out : str or None
        Where Save and Export write a mask painted in the page (default: beside the output,
        or beside the handles file, ``*.mask.png``).
    """

    def __init__(self, settings: Settings, input: str, mask: str | None, handles_path: str | None,
                 output_path: str | None, handles: dict | None = None, mask_out: str | None = None):
        from ..engine.fidelity import base_cell

        self.settings, self.input, self.mask = settings, input, mask
        self.handles_path, self.output_path = handles_path, output_path
        self.export_handles_path = handles_path or companion(output_path, ".handles.json")
        self.mask_out = mask_out or companion(output_path or handles_path, ".mask.png")
        image, self.feature_mask, self.warnings = load_image_and_mask(replace(settings, mode="similarity"),
                                                                      input, mask)
        self.height, self.width = image.shape[:2]
        self.normal_cell = settings.cell or base_cell(self.width, self.height)
        self.density, self.cell, self.painted = "normal", self._density_cell("normal"), False
        tex = texture(image)
        self.texture_size = (tex.shape[1], tex.shape[0])
        self.image_png = png(tex)
        self.mask_texture = texture(self._mask_image())      # what the page paints on (it reads mask_png)
        self.mask_png = png(self.mask_texture)
        self.notes = []
        self.initial = ({"version": 1, "points": [], "curves": [], "border": "free", "canvas": "fit"}
                        if handles is None else self._checked({"handles": handles}, self.notes, handles_path))
        self.lock, self._seen = threading.Lock(), threading.Lock()
        self.files = threading.Lock()          # one Save or Export at a time: its files and command agree
        self.commit, self.snapshot, self.abandoned = threading.Lock(), None, False
        self.versions = {"grid": 0, "mask": 0}     # what another page changed (it reloads them)
        self.newest = {}
        self._build()

    def _build(self) -> None:
        """The deformer of the current mask and cell (factored on its first solve)."""
        from ..engine.deform import Deformer

        settings = self.settings
        mask = self.feature_mask if self.feature_mask is not None and self.feature_mask.any() else None
        self.deformer = Deformer(self.width, self.height, mask, quick=True, cell=self.cell,
                                 rigid_steps=EDITOR_RIGID_STEPS, feature_weight=settings.feature_weight,
                                 decay=settings.decay, scale_prior=settings.scale_prior)

    def _mask_image(self) -> np.ndarray:
        """The feature mask as 8 bits (0 or 255), at the image's size."""
        if self.feature_mask is None:
            return np.zeros((self.height, self.width), np.uint8)
        return self.feature_mask.astype(np.uint8) * 255

    def state(self) -> dict:
        """What the page needs to start (or to start over after a density change)."""
        return {"width": self.width, "height": self.height, "handles": self.initial, "mode": self.settings.mode,
                "cell": self.cell, "density": self.density, "densities": list(DENSITIES),
                "texture": list(self.texture_size), "save_to": self.handles_path,
                "export_to": self.output_path, "mask_to": self.mask_out,
                "has_mask": self.mask is not None or self.painted, "warnings": self.warnings + self.notes,
                "versions": dict(self.versions)}

    def grid(self) -> bytes:
        """The preview grid: node count, triangle count, nodes per row and per column (uint32),
        texture coordinates (float32, 0..1) and triangles (uint32), little-endian."""
        from ..engine.deform import solve_grid

        grid = solve_grid(self.width, self.height, self.cell)
        nodes = grid.nodes()
        uv = np.stack([(nodes[:, 0] + 0.5) / self.width, (nodes[:, 1] + 0.5) / self.height], axis=1)
        triangles = grid.triangles()
        return (struct.pack("<IIII", len(nodes), len(triangles), grid.nx, grid.ny) + uv.astype("<f4").tobytes()
                + triangles.astype("<u4").tobytes())

    def solve(self, body: dict) -> tuple[dict, bytes]:
        """Solve the handles of ``body``: (status, node positions in input pixels as float32);
        a request superseded by a newer one of its page: ({"stale": True, ...}, b"")."""
        from ..engine.handles import Handles

        mode = body.get("mode", self.settings.mode)
        if mode not in ("similarity", "rigid", "plain"):
            raise ValueError(f"mode {mode!r}: use similarity, rigid or plain")
        ticket = _ticket(body)
        if self._superseded(ticket, arriving=True):
            return {"stale": True, "seq": ticket[1]}, b""
        handles = Handles.from_dict(body.get("handles"), self.width, self.height)
        with self.lock:
            if self._superseded(ticket):            # a newer request came while this one waited
                return {"stale": True, "seq": ticket[1]}, b""
            self.deformer.rigid.rigid_steps = DRAG_RIGID_STEPS if body.get("drag") is True \
                else EDITOR_RIGID_STEPS
            t0 = time.perf_counter()
            mesh = self.deformer.solve(handles, mode, drag=body.get("drag") is True)
            seconds = time.perf_counter() - t0
            warp = self.deformer.warp
            offset = np.asarray(warp.offset)
            ends, curves = warp.ends(mesh), warp.curve_ends(mesh)
            turns = _turns(warp, mesh, handles, max(1.0, 0.5 * self.cell))
            versions = dict(self.versions)
        components = mesh.record.components
        warnings = mesh.record.warnings
        if body.get("drag") is True:        # a drag's updates are cut short by design: say so at the release
            warnings = [w for w in warnings if not w.startswith("preview: the rigid map")]
        # The status line shows the first warning: that the handles ask for a fold (which Export may refuse,
        # or pay for with features not kept) outranks the preview's notes, beside which it read "folds 0".
        warnings = sorted(warnings, key=lambda w: not w.startswith(FOLD_ASK))
        status = {"ms": round(1000 * seconds, 1), "folds": mesh.flips() + mesh.crossings,
                  "seq": ticket[1] if ticket else None,
                  "components": len(components), "kept": sum(c.kept for c in components) if mode != "plain" else 0,
                  "canvas": list(mesh.canvas), "warnings": warnings[:3],
                  "provisional": any(w.startswith((FOLD_ASK, "preview:", "dragging:")) for w in warnings),
                  "ends": [] if ends is None else np.round(ends, 2).tolist(), "turns": turns,
                  "curve_ends": [np.round(ended, 2).tolist() for _, ended in curves], "versions": versions}
        return status, (mesh.target + offset).astype("<f4").tobytes()

    def _superseded(self, ticket: tuple | None, arriving: bool = False) -> bool:
        """Whether a newer request than ``ticket`` (client, seq) has arrived from its page;
        ``arriving``: also record it as the newest."""
        if ticket is None:
            return False
        client, seq = ticket
        with self._seen:
            newest = self.newest.get(client, -1)
            if arriving and seq > newest:
                self.newest.pop(client, None)
                self.newest[client] = seq
                while len(self.newest) > CLIENTS:
                    self.newest.pop(next(iter(self.newest)))
            return seq < newest

    def set_density(self, body: dict) -> dict:
        """Change the preview mesh's density (``fewer``, ``normal``, ``more``); the new state."""
        density = body.get("density")
        if not isinstance(density, str) or density not in DENSITIES:
            raise ValueError(f"density {density!r}: use {', '.join(DENSITIES)}")
        cell = self._density_cell(density)
        with self.lock:
            before = self.density, self.cell, self.deformer
            self.density, self.cell = density, cell
            try:
                self._build()
            except Exception:              # the session stays as it was: later Exports still work
                self.density, self.cell, self.deformer = before
                raise
            self.versions["grid"] += 1
        return self.state()

    def _density_cell(self, density: str) -> float:
        """The preview's cell at ``density``: the rigid grid's spacing over its refinement
        (:data:`DENSITIES`), no finer than :data:`PREVIEW_MAX_NODES` allows nor than
        :data:`~featurewarp_cli.engine.defaults.MIN_CELL` (``--cell 1`` started the editor
        at 1 px, and "more" asked for 0.5, which every later Export refused)."""
        from ..engine.defaults import MIN_CELL
        from ..engine.deform import rigid_grid

        spacing = max(rigid_grid(self.width, self.height).spacing)
        refinement = DENSITIES[density](max(1, round(spacing / self.normal_cell)))
        cell = round(max(spacing / refinement, math.sqrt(self.width * self.height / PREVIEW_MAX_NODES)), 4)
        return max(cell, MIN_CELL)

    def set_mask(self, body: dict) -> dict:
        """Replace the feature mask by the one painted in the page (``png``: a data URL of a
        PNG of the texture's size; white is feature). Where the texture is smaller than the
        image, only the image pixels under texels that changed are taken from it: the rest of
        the mask keeps its full resolution (a stroke resampled the whole mask)."""
        import cv2

        painted = decode_mask(body.get("png"), self.texture_size)
        with self.lock:
            if painted.shape == (self.height, self.width):
                self.feature_mask = painted >= 128
            else:
                changed = cv2.dilate((painted != self.mask_texture).astype(np.uint8), np.ones((3, 3), np.uint8))
                under = cv2.resize(changed, (self.width, self.height), interpolation=cv2.INTER_LINEAR) > 0
                mask, full = self._mask_image() >= 128, cv2.resize(painted, (self.width, self.height),
                                                                    interpolation=cv2.INTER_LINEAR)
                mask[under] = full[under] >= 128
                self.feature_mask = mask
            self.painted, self.mask_texture, self.mask_png = True, painted, png(painted)
            self.versions["mask"] += 1
            self._build()
        return {"mask": True, "coverage": round(float(self.feature_mask.mean()), 4), "version": self.versions["mask"]}

    def save(self, body: dict) -> dict:
        """Write the handles to ``handles_path`` and a painted mask to ``mask_out`` (checked
        first); return what was written, and the content of what had nowhere to go."""
        data = self._checked(body)
        answer = {"saved": self.handles_path, "handles": data, "mask_saved": None}
        with self.files:
            if self.handles_path:
                self._confirmed(body, self.handles_path)
                write_named(self.handles_path, handles_json(data).encode())
                self.initial, self.notes = data, []   # a reloaded page goes on from what was saved
            if self.painted:
                if self.mask_out:
                    answer["mask_saved"] = self._write_mask()
                else:
                    answer["mask_png"] = base64.b64encode(png(self._mask_image())).decode()
        return answer

    def _write_mask(self) -> str:
        write_named(self.mask_out, png(self._mask_image()))
        return self.mask_out

    def _confirmed(self, body: dict, path: str) -> None:
        """Unconfirmed unless ``body`` says ``drop_ignored``, while the handles file loaded at
        start had keys the editor ignores (writing ``path`` would drop them for good)."""
        if self.notes and path == self.handles_path and body.get("drop_ignored") is not True:
            raise Unconfirmed(f"{path} holds what the editor ignores ({'; '.join(self.notes)}): "
                              "writing it drops that for good", self.notes)

    def export(self, body: dict) -> dict:
        """Render the full-resolution result through exactly the ``deform`` pipeline, after
        writing the handles file (and a painted mask) that the printed command names."""
        from ..engine.deform import handles_factory

        data = self._checked(body)
        if not self.output_path:
            raise ValueError("start the editor with --output OUT to export")
        handles_path = self.export_handles_path
        mode = body.get("mode", self.settings.mode)
        settings = replace(self.settings, mode=mode, warp_factory=handles_factory(data, self.settings.decay))
        if self.density != "normal":
            settings = replace(settings, cell=self.cell)
        with self.files:
            self._confirmed(body, handles_path)
            self.snapshot = Snapshot([self.output_path, handles_path] + ([self.mask_out] if self.painted else []))
            try:
                mask = self._write_mask() if self.painted else self.mask
                with naming(self.output_path):
                    summary = warp_file(settings, self.input, self.output_path, mask,
                                        also_read=((handles_path, "--handles"),))
                with self.commit:            # the handles after the image: Ctrl-C before it leaves the old pair
                    if self.abandoned:
                        raise WarpError(f"the export of {self.output_path} was abandoned")
                    write_named(handles_path, handles_json(data).encode())
            except BaseException:
                with self.commit:
                    self.snapshot.restore()
                raise
            finally:
                self.snapshot = None
            if handles_path == self.handles_path:
                self.initial, self.notes = data, []
        command = ["featurewarp", "deform", self.input, self.output_path] + (["-m", mask] if mask else [])
        command += ["--handles", handles_path] + (["--mode", mode] if mode != "similarity" else [])
        command += options_given(settings)
        return {"exported": self.output_path, "seconds": round(summary["seconds"], 2),
                "handles_saved": handles_path, "mask_saved": mask if self.painted else None,
                "warnings": list(summary["warnings"]), "command": " ".join(shlex.quote(c) for c in command)}

    def abandon(self) -> str | None:
        """Ctrl-C while an Export runs: put its files back as they were and make it write no
        more (:class:`Snapshot`); the output it was writing, or None when none was running."""
        with self.commit:
            self.abandoned = True
            if self.snapshot is None:
                return None
            self.snapshot.restore()
            write.remove_pending()
            return self.output_path

    def _checked(self, body: dict, notes: list | None = None, source: str | None = None) -> dict:
        from ..engine.handles import Handles

        handles = Handles.from_dict(body.get("handles"), self.width, self.height, source or "handles")
        if notes is not None:
            notes.extend(handles.notes)
        return handles.as_dict()


def _ticket(body: dict) -> tuple | None:
    """(client, seq) of a solve request, or None when it has none (ValueError when malformed)."""
    if "seq" not in body:
        return None
    client, seq = body.get("client", ""), body["seq"]
    if not (isinstance(client, str) and len(client) <= 64) or type(seq) is not int or seq < 0:
        raise ValueError("seq must be a whole number >= 0 and client a string of 64 characters at most")
    return client, seq


def _turns(warp, mesh, handles, step: float) -> list:
    """How far (degrees) the map turns the neighbourhood of each point handle: its angle
    if it has one, else what the solve gave, measured over ``step`` px (the page starts an
    Alt-drag from it)."""
    if not len(handles.points_from):
        return []
    along = warp.mapped(mesh, handles.points_from + [step, 0.0]) - warp.mapped(mesh, handles.points_from)
    solved = np.degrees(np.arctan2(along[:, 1], along[:, 0]))
    return np.round(np.where(np.isfinite(handles.angles), np.degrees(handles.angles), solved), 2).tolist()


def options_given(settings: Settings) -> list[str]:
    """The command-line options of ``settings`` that differ from deform's defaults (for the
    command Export prints; numbers exactly, so that it replays as printed)."""
    default = Settings(settings.preset)
    flags = {"cell": "--cell", "feature_weight": "--feature-weight", "decay": "--decay",
             "scale_prior": "--scale-prior", "background": "--background", "interp": "--interp",
             "fmt": "--format", "quality": "--quality", "max_pixels": "--max-pixels",
             "max_memory": "--max-memory"}
    given = []
    for name, flag in flags.items():
        value = getattr(settings, name)
        if value != getattr(default, name):
            given += [flag, _number(value) if isinstance(value, float) else str(value)]
    return given + (["--strip"] if settings.strip else []) + (["--allow-folds"] if settings.allow_folds else [])


def _number(value: float) -> str:
    """``value`` as short as it reads back exactly (``8`` for 8.0, ``7.8125``)."""
    short = f"{value:g}"
    return short if float(short) == value else repr(value)
