"""The live editor's server: the browser draws, this process solves (``featurewarp edit``).

The standard library's :mod:`http.server` (a ``ThreadingHTTPServer``) serves one page, its
image, its mask, the grid, and JSON calls: ``state``, ``solve`` (see
:mod:`featurewarp_cli.app.editor_session` for its protocol), ``save``, ``export``, ``mask``
(a mask painted in the page) and ``density`` (the preview mesh's). No framework: the editor
is one local user's page, a dozen routes and no templates, and the standard library keeps
``make install`` and the attack surface small.

Safety: the server listens on 127.0.0.1 only, on a free port unless one is given; every
request must carry the random token of the URL it prints (compared in constant time) and a
Host header naming 127.0.0.1 or localhost on its port (DNS rebinding), and POSTs must be
JSON and, when the browser says where they come from, from the editor's own origin (another
site's page cannot post to it). Idle connections are closed after a timeout and the open
ones are capped, so connections held open cannot tie up threads. It serves its own page and
the one image; it writes only the files named on the command line (or beside them: Export's
handles file when no ``--handles`` was given, a painted mask), atomically, and the output
through the ``deform`` pipeline.
"""

from __future__ import annotations

import hmac
import json
import re
import secrets
import socket
import struct
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from .editor_session import EditorSession, Unconfirmed  # noqa: F401  (the CLI takes both from here)
from .pipeline import WarpError

#: Largest request body accepted (bytes; a painted mask of 4096 x 4096 fits).
MAX_BODY = 8 * 2**20
#: The page's scripts, in the order they run (one script: they share its scope).
SCRIPTS = ("state.js", "render.js", "view.js", "overlay.js", "edit.js", "border.js", "mask.js", "solve.js",
           "start.js")


def page() -> bytes:
    """The editor's page (HTML with its scripts, :data:`SCRIPTS`, and style inline)."""
    folder = resources.files("featurewarp_cli.app") / "static"
    html = (folder / "editor.html").read_text(encoding="utf-8")
    script = "\n".join((folder / name).read_text(encoding="utf-8") for name in SCRIPTS)
    return (html.replace("/*EDITOR_CSS*/", (folder / "editor.css").read_text(encoding="utf-8"))
                .replace("/*EDITOR_JS*/", script)).encode()


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
        route, session = urlsplit(self.path).path, self.server.session
        calls = {"/solve": self._solve, "/save": session.save, "/export": session.export, "/mask": session.set_mask,
                 "/density": session.set_density}
        refused = (403, "forbidden") if not self._allowed() or (
            origin is not None and origin not in {f"http://{h}" for h in self.server.hosts}) else \
            (404, "not found") if route not in calls else None                  # 403: a page of another site
        length = self.headers.get("Content-Length", "")
        if refused is None and (not self.headers.get("Content-Type", "").startswith("application/json")
                                or not re.fullmatch(r"[0-9]{1,9}", length) or not 0 < int(length) <= MAX_BODY):
            refused = (400, "expected a JSON body (Content-Type: application/json, "
                            f"Content-Length 1 to {MAX_BODY})")
        if refused is not None:
            self.close_connection = True              # its body unread: never taken for the next request
            return self._json(refused[0], {"error": refused[1]})
        try:
            data = self.rfile.read(int(length))
        except TimeoutError:
            data = b""
        self._deadline.cancel()
        if len(data) < int(length):
            self.close_connection = True
            return self._json(408, {"error": "the body ended before its Content-Length"})
        try:
            result = calls[route](_parsed(data))
        except RecursionError:
            return self._json(400, {"error": "the JSON body is nested too deeply"})
        except json.JSONDecodeError as err:
            return self._json(400, {"error": f"the body is not valid JSON ({err})"})
        except Unconfirmed as err:               # the page asks the user, then posts again with drop_ignored
            return self._json(409, {"error": str(err), "confirm": err.notes})
        except (ValueError, TypeError, OverflowError, WarpError) as err:
            return self._json(400, {"error": str(err)})
        except OSError as err:
            return self._json(500, {"error": f"{err.strerror or err}" + (f": {err.filename}" if err.filename else "")})
        except Exception as err:  # the server keeps serving; the page shows the one line
            return self._json(500, {"error": f"{type(err).__name__}: {err}"})
        if route == "/solve":
            return self._send(200, result, "application/octet-stream")
        self._json(200, result)

    def _solve(self, body: dict) -> bytes:
        status, positions = self.server.session.solve(body)
        header = json.dumps(status).encode()
        return struct.pack("<I", len(header)) + header + b" " * (-(4 + len(header)) % 4) + positions


def _parsed(data: bytes) -> dict:
    """The JSON object of a request body (ValueError saying what is wrong with it)."""
    try:
        body = json.loads(data)
    except json.JSONDecodeError:
        raise
    except ValueError as err:                 # CPython's digit limit: a number of thousands of digits
        raise ValueError("the body is not valid JSON (a number is too long)") from err
    if not isinstance(body, dict):
        raise ValueError("a JSON object is expected")
    return body
