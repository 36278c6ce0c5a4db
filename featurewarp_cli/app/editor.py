"""The live editor's server: the browser draws, this process solves (``featurewarp edit``).

The standard library's :mod:`http.server` (a ``ThreadingHTTPServer``) serves one page, its
image, its mask, the grid, and four JSON calls: ``state``, ``solve``, ``save`` and
``export``. No framework: the editor is one local user's page, a dozen routes and no
templates, and the standard library keeps ``make install`` and the attack surface small.

Safety: the server listens on 127.0.0.1 only, on a free port unless one is given; every
request must carry the random token of the URL it prints (compared in constant time) and a
Host header naming 127.0.0.1 or localhost on its port (DNS rebinding), and POSTs must be
JSON and, when the browser says where they come from, from the editor's own origin (another
site's page cannot post to it). Idle connections are closed after a timeout and the open
ones are capped, so connections held open cannot tie up threads. It serves its own page and the one image; it writes only the handles file and the
output the user named on the command line, atomically, through the ``deform`` pipeline.
"""

from __future__ import annotations

import hmac
import json
import math
import secrets
import shlex
import socket
import struct
import threading
import time
from dataclasses import replace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..io import write
from .pipeline import Settings, WarpError, load_image_and_mask, warp_file

#: The live preview keeps its grid at about this many nodes at most (Export uses the full
#: pipeline, whose grid follows the warp).
PREVIEW_NODES = 65_000
#: Longest side of the image the browser gets as its texture.
TEXTURE_SIDE = 4096
#: The injective fallback's steps per update at most (a drag stays live; Export runs it fully).
EDITOR_INJECTIVE_STEPS = 8
#: Largest request body accepted (bytes).
MAX_BODY = 8 * 2**20


class EditorSession:
    """What the editor works on: the image, its mask, the deformer and the files it may write.

    Parameters
    ----------
    settings : Settings
        The ``deform`` options (mode, cell, weights, output format and quality).
    input, mask : str
        The image and its feature mask (mask may be None).
    handles_path, output_path : str or None
        Where Save and Export write (None: the browser downloads instead).
    handles : dict or None
        The handles to start from (a parsed handles file; ValueError when they do not fit).
    """

    def __init__(self, settings: Settings, input: str, mask: str | None, handles_path: str | None,
                 output_path: str | None, handles: dict | None = None):
        from ..engine.deform import Deformer
        from ..engine.fidelity import base_cell

        self.settings, self.input, self.mask = settings, input, mask
        self.handles_path, self.output_path = handles_path, output_path
        image, feature_mask, self.warnings = load_image_and_mask(replace(settings, mode="similarity"), input, mask)
        self.height, self.width = image.shape[:2]
        self.cell = settings.cell or max(base_cell(self.width, self.height),
                                         math.sqrt(self.width * self.height / PREVIEW_NODES))
        self.deformer = Deformer(self.width, self.height, feature_mask, quick=True, cell=self.cell,
                                 injective_steps=EDITOR_INJECTIVE_STEPS,
                                 feature_weight=settings.feature_weight, decay=settings.decay,
                                 scale_prior=settings.scale_prior)
        self.image_png = _png(_texture(image))
        self.mask_png = _png(_texture((feature_mask if feature_mask is not None else
                                       np.zeros((self.height, self.width), bool)).astype(np.uint8) * 255))
        self.notes = []
        self.initial = ({"version": 1, "points": [], "curves": [], "border": "free", "canvas": "fit"}
                        if handles is None else self._checked({"handles": handles}, self.notes))
        self.lock = threading.Lock()

    def state(self) -> dict:
        """What the page needs to start."""
        return {"width": self.width, "height": self.height, "handles": self.initial, "mode": self.settings.mode,
                "cell": self.cell, "save_to": self.handles_path, "export_to": self.output_path,
                "has_mask": self.mask is not None, "warnings": self.warnings + self.notes}

    def grid(self) -> bytes:
        """The preview grid: node count, triangle count, nodes per row and per column (uint32),
        texture coordinates (float32, 0..1) and triangles (uint32), little-endian."""
        from ..engine.grid import Grid

        grid = Grid.for_image(self.width, self.height, self.cell)
        nodes = grid.nodes()
        uv = np.stack([(nodes[:, 0] + 0.5) / self.width, (nodes[:, 1] + 0.5) / self.height], axis=1)
        triangles = grid.triangles()
        return (struct.pack("<IIII", len(nodes), len(triangles), grid.nx, grid.ny) + uv.astype("<f4").tobytes()
                + triangles.astype("<u4").tobytes())

    def solve(self, body: dict) -> tuple[dict, bytes]:
        """Solve the handles of ``body``: (status, node positions in input pixels as float32)."""
        from ..engine.handles import Handles

        mode = body.get("mode", self.settings.mode)
        if mode not in ("similarity", "rigid", "plain"):
            raise ValueError(f"mode {mode!r}: use similarity, rigid or plain")
        handles = Handles.from_dict(body.get("handles"), self.width, self.height)
        with self.lock:
            t0 = time.perf_counter()
            mesh = self.deformer.solve(handles, mode)
            seconds = time.perf_counter() - t0
            offset = np.asarray(self.deformer.warp.offset)
            ends = self.deformer.warp.ends(mesh)
        components = mesh.record.components
        status = {"ms": round(1000 * seconds, 1), "folds": mesh.flips() + mesh.crossings,
                  "components": len(components), "kept": sum(c.kept for c in components) if mode != "plain" else 0,
                  "canvas": list(mesh.canvas), "warnings": mesh.record.warnings[:3],
                  "ends": [] if ends is None else np.round(ends, 2).tolist()}
        return status, (mesh.target + offset).astype("<f4").tobytes()

    def save(self, body: dict) -> dict:
        """Write the handles to ``handles_path`` (checked first); return the file's content."""
        data = self._checked(body)
        if self.handles_path:
            write.write_atomic(self.handles_path, (json.dumps(data, indent=2) + "\n").encode())
        return {"saved": self.handles_path, "handles": data}

    def export(self, body: dict) -> dict:
        """Render the full-resolution result through exactly the ``deform`` pipeline."""
        from ..engine.deform import handles_factory

        data = self._checked(body)
        if not self.output_path:
            raise ValueError("start the editor with --output OUT to export")
        if self.handles_path:                   # the printed command must find these very handles
            self.save(body)
        mode = body.get("mode", self.settings.mode)
        settings = replace(self.settings, mode=mode, warp_factory=handles_factory(data))
        summary = warp_file(settings, self.input, self.output_path, self.mask,
                            also_read=((self.handles_path, "--handles"),) if self.handles_path else ())
        command = ["featurewarp", "deform", self.input, self.output_path] + (["-m", self.mask] if self.mask else [])
        command += ["--handles", self.handles_path or "H.json"] + (["--mode", mode] if mode != "similarity" else [])
        command += options_given(self.settings)
        return {"exported": self.output_path, "seconds": round(summary["seconds"], 2),
                "warnings": summary["warnings"][:3], "command": " ".join(shlex.quote(c) for c in command)}

    def _checked(self, body: dict, notes: list | None = None) -> dict:
        from ..engine.handles import Handles

        handles = Handles.from_dict(body.get("handles"), self.width, self.height)
        if notes is not None:
            notes.extend(handles.notes)
        return handles.as_dict()


def options_given(settings: Settings) -> list[str]:
    """The command-line options of ``settings`` that differ from deform's defaults (for the
    command Export prints)."""
    default = Settings(settings.preset)
    flags = {"cell": "--cell", "feature_weight": "--feature-weight", "decay": "--decay",
             "scale_prior": "--scale-prior", "background": "--background", "interp": "--interp",
             "fmt": "--format", "quality": "--quality", "max_pixels": "--max-pixels"}
    given = []
    for name, flag in flags.items():
        value = getattr(settings, name)
        if value != getattr(default, name):
            given += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return given + (["--strip"] if settings.strip else []) + (["--allow-folds"] if settings.allow_folds else [])


def _texture(image: np.ndarray) -> np.ndarray:
    """``image`` scaled down to :data:`TEXTURE_SIDE` at most (8 bits)."""
    import cv2

    if image.dtype != np.uint8:
        image = (image / (257.0 if image.dtype == np.uint16 else 1.0 / 255.0)).clip(0, 255).astype(np.uint8)
    side = max(image.shape[:2])
    if side > TEXTURE_SIDE:
        scale = TEXTURE_SIDE / side
        image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return image


def _png(image: np.ndarray) -> bytes:
    import cv2

    ok, data = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise WarpError("cannot encode the editor's texture")
    return data.tobytes()


def page() -> bytes:
    """The editor's page (HTML with its script and style inline)."""
    folder = resources.files("featurewarp_cli.app") / "static"
    html = (folder / "editor.html").read_text(encoding="utf-8")
    return (html.replace("/*EDITOR_CSS*/", (folder / "editor.css").read_text(encoding="utf-8"))
                .replace("/*EDITOR_JS*/", (folder / "editor.js").read_text(encoding="utf-8"))).encode()


#: Seconds a connection may sit idle (or trickle a request) before it is closed, and the
#: connections served at once; more are closed on arrival (each open one costs a thread).
SOCKET_TIMEOUT = 20.0
MAX_CONNECTIONS = 32
#: Seconds to receive a whole request (line, headers and body): one trickled a byte at a
#: time, each within the socket timeout, is cut off here.
REQUEST_DEADLINE = 30.0


class EditorServer(ThreadingHTTPServer):
    """The HTTP server of one :class:`EditorSession` on 127.0.0.1.

    Idle connections are closed after :data:`SOCKET_TIMEOUT` seconds, a request must arrive
    whole within :data:`REQUEST_DEADLINE`, and at most :data:`MAX_CONNECTIONS` are served at
    once, so held or trickling connections cannot exhaust threads for long."""

    daemon_threads = True
    open_connections = 0

    def __init__(self, session: EditorSession, port: int = 0, token: str | None = None):
        self.session = session
        self.token = token or secrets.token_urlsafe(24)
        self.page = page()
        self._count = threading.Lock()
        super().__init__(("127.0.0.1", port), EditorHandler)
        self.hosts = {f"127.0.0.1:{self.server_port}", f"localhost:{self.server_port}"}

    def handle_error(self, request, client_address):
        """A client that hangs up (a reload, a closed tab) is not news: no traceback on stderr."""

    def process_request(self, request, client_address):
        """Serve in a thread, or close the connection at once when :data:`MAX_CONNECTIONS` are open."""
        with self._count:
            full = self.open_connections >= MAX_CONNECTIONS
            if not full:
                self.open_connections += 1
        if full:
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:                       # no thread: the slot is free again
            with self._count:
                self.open_connections -= 1
            raise

    def process_request_thread(self, request, client_address):
        """Serve one connection, then free its slot."""
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._count:
                self.open_connections -= 1

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_port}/?token={self.token}"


class EditorHandler(BaseHTTPRequestHandler):
    """Routes of the editor; every one checks the Host header and the token first."""

    server_version = "featurewarp-edit"
    protocol_version = "HTTP/1.1"
    timeout = SOCKET_TIMEOUT

    def log_message(self, format, *args):       # quiet: the terminal belongs to the user
        pass

    def handle_one_request(self):
        """One request, received within :data:`REQUEST_DEADLINE` seconds in all."""
        self._deadline = threading.Timer(REQUEST_DEADLINE, self._cut_off)
        self._deadline.daemon = True
        self._deadline.start()
        try:
            super().handle_one_request()
        finally:
            self._deadline.cancel()

    def _cut_off(self):
        try:
            self.connection.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    def _allowed(self) -> bool:
        query = parse_qs(urlsplit(self.path).query)
        token = (query.get("token") or [""])[0]
        return (self.headers.get("Host", "") in self.server.hosts
                and hmac.compare_digest(token.encode(), self.server.token.encode()))

    def _send(self, code: int, body: bytes, kind: str = "application/json", extra: dict | None = None):
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Referrer-Policy", "no-referrer")
        self.send_header("Content-Security-Policy", "default-src 'self'; script-src 'unsafe-inline'; "
                         "style-src 'unsafe-inline'; img-src 'self' blob: data:; connect-src 'self'")
        for key, value in (extra or {}).items():
            self.send_header(key, value)
        self.end_headers()
        self.wfile.write(body)

    def _json(self, code: int, data: dict):
        self._send(code, json.dumps(data).encode())

    def do_GET(self):
        self._deadline.cancel()                      # received: the answer may take its time
        if not self._allowed():
            return self._send(403, b"forbidden: open the URL that featurewarp edit printed", "text/plain")
        session, route = self.server.session, urlsplit(self.path).path
        routes = {"/": (lambda: self.server.page, "text/html; charset=utf-8"),
                  "/image": (lambda: session.image_png, "image/png"),
                  "/mask": (lambda: session.mask_png, "image/png"),
                  "/grid": (session.grid, "application/octet-stream"),
                  "/state": (lambda: json.dumps(session.state()).encode(), "application/json")}
        if route not in routes:
            return self._send(404, b"not found", "text/plain")
        make, kind = routes[route]
        self._send(200, make(), kind)

    def do_POST(self):
        origin = self.headers.get("Origin")
        if not self._allowed() or (origin is not None and origin not in {f"http://{h}" for h in self.server.hosts}):
            return self._send(403, b"forbidden", "text/plain")         # a page of another site
        route = urlsplit(self.path).path
        calls = {"/solve": self._solve, "/save": self.server.session.save, "/export": self.server.session.export}
        if route not in calls:
            return self._send(404, b"not found", "text/plain")
        length = self.headers.get("Content-Length", "")
        if (not self.headers.get("Content-Type", "").startswith("application/json") or not length.isdigit()
                or not 0 < int(length) <= MAX_BODY):
            self.close_connection = True
            return self._json(400, {"error": "expected a JSON body (Content-Type: application/json, "
                                             f"Content-Length 1 to {MAX_BODY})"})
        try:
            data = self.rfile.read(int(length))
            self._deadline.cancel()
            body = json.loads(data)
            if not isinstance(body, dict):
                raise ValueError("a JSON object is expected")
            result = calls[route](body)
        except RecursionError:
            return self._json(400, {"error": "the JSON body is nested too deeply"})
        except json.JSONDecodeError as err:
            return self._json(400, {"error": f"the body is not valid JSON ({err})"})
        except (ValueError, TypeError, OverflowError, WarpError) as err:
            return self._json(400, {"error": str(err)})
        except OSError as err:
            return self._json(500, {"error": f"{err.strerror or err}: {err.filename or ''}"})
        except Exception as err:  # the server keeps serving; the page shows the one line
            return self._json(500, {"error": f"{type(err).__name__}: {err}"})
        if route == "/solve":
            return self._send(200, result, "application/octet-stream")
        self._json(200, result)

    def _solve(self, body: dict) -> bytes:
        status, positions = self.server.session.solve(body)
        header = json.dumps(status).encode()
        return struct.pack("<I", len(header)) + header + b" " * (-(4 + len(header)) % 4) + positions
