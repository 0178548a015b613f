"""The local web server of ``homocal ui``: Python's standard http.server, bound to 127.0.0.1.

The standard library is enough for one user's page and a few JSON endpoints, and adds nothing to install.
Routes: GET / (the page), /app.js, /frame.png, /map.png, /api/session; POST /api/<endpoint> with a JSON
object (``homocal.ui.api.ENDPOINTS``). Bad requests get 4xx and {"error": message}, which the page shows.
Requests must name this server in their Host header (no DNS rebinding) and POSTs must be JSON (which a
foreign web page cannot send here without a CORS preflight, which this server never grants).
"""
from __future__ import annotations

import json
import sys
import traceback
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib.resources import files

from homocal.ui import api
from homocal.ui.session import Session

HOST = "127.0.0.1"
MAX_BODY = 10 * 1024 * 1024
STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/app.js": ("app.js", "text/javascript; charset=utf-8")}


class UIServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, session: Session, port: int = 0) -> None:
        super().__init__((HOST, port), Handler)
        self.session = session

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.server_address[1]}/"


class Handler(BaseHTTPRequestHandler):
    server: UIServer

    def do_GET(self) -> None:
        if not self._host_ok():
            return
        session, path = self.server.session, self.path.split("?")[0]
        if path in STATIC:
            name, kind = STATIC[path]
            self._send(200, (files("homocal.ui") / "static" / name).read_bytes(), kind)
        elif path == "/frame.png":
            self._send(200, session.frame_png, "image/png")
        elif path == "/map.png":
            self._send(200, session.map_png, "image/png")
        elif path == "/api/session":
            self._json(200, session.info())
        else:
            self._json(404, {"error": f"no such page: {path}"})

    def do_POST(self) -> None:
        if not self._host_ok():
            return
        endpoint = api.ENDPOINTS.get(self.path.removeprefix("/api/")) if self.path.startswith("/api/") else None
        if endpoint is None:
            return self._json(404, {"error": f"no such endpoint: {self.path}"})
        if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
            return self._json(415, {"error": "send JSON (Content-Type: application/json)"})
        length = int(self.headers.get("Content-Length") or 0)
        if not 0 < length <= MAX_BODY:
            return self._json(400, {"error": f"expected a JSON body of 1 byte to {MAX_BODY} bytes, got {length}"})
        try:
            request = json.loads(self.rfile.read(length))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            return self._json(400, {"error": f"not valid JSON: {e}"})
        if not isinstance(request, dict):
            return self._json(400, {"error": "expected a JSON object"})
        try:
            self._json(200, endpoint(self.server.session, request))
        except FileExistsError as e:
            self._json(409, {"error": str(e), "exists": True})
        except (ValueError, OSError) as e:
            self._json(400, {"error": " ".join(str(e).split())})
        except Exception as e:  # a bug: tell the page, keep serving, print the traceback for the report
            traceback.print_exc(file=sys.stderr)
            self._json(500, {"error": f"internal error ({type(e).__name__}: {e}); see the terminal"})

    def _host_ok(self) -> bool:
        port = self.server.server_address[1]
        if self.headers.get("Host") in (f"{HOST}:{port}", f"localhost:{port}"):
            return True
        self._json(403, {"error": f"unexpected Host header {self.headers.get('Host')!r}"})
        return False

    def _json(self, status: int, obj: dict) -> None:
        self._send(status, json.dumps(obj, allow_nan=False).encode(), "application/json")

    def _send(self, status: int, body: bytes, kind: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args) -> None:  # noqa: A002 (the base class's name)
        """Only failed requests are logged (stderr)."""
        if len(args) >= 2 and str(args[1])[:1] in "45":
            super().log_message(format, *args)
