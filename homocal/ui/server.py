"""The local web server of ``homocal ui``: Python's standard http.server, bound to 127.0.0.1.

The standard library is enough for one user's page and a few JSON endpoints, and adds nothing to install.
Routes: GET / (the page), /app.js, /frame.png, /map.png, /api/session; POST /api/<endpoint> with a JSON
object (``homocal.ui.api.ENDPOINTS``). Every answer to an API request is JSON; bad requests get 4xx and
{"error": message naming the field}, which the page shows; 5xx only for a bug (500) or a busy server (503).
Requests must name this server in their Host header (no DNS rebinding); POSTs must be JSON (which a foreign
web page cannot send here without a CORS preflight, which this server never grants) and carry the per-launch
token of the printed URL (``?token=...``, as Jupyter's) in the X-Homocal-Token header, or get 403.
Bounds: a body of at most MAX_BODY bytes (the checkerboard's photographs: MAX_BOARD_BODY), JSON nested at most
MAX_DEPTH deep, integers of at most MAX_INTEGER_DIGITS digits, MAX_CONCURRENT POSTs read and answered at once
(another one waits up to QUEUE_SECONDS, then gets 503).
"""
from __future__ import annotations

import json
import re
import secrets
import sys
import threading
import traceback
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib.resources import files

from homocal.ui import api
from homocal.ui.session import Session

HOST = "127.0.0.1"
MAX_BODY = 10 * 1024 * 1024  # bytes
MAX_BOARD_BODY = 128 * 1024 * 1024  # bytes: POST /api/checkerboard's, its photographs in base64 (96 MiB of files, some
# 50 full-HD PNGs); at most MAX_CONCURRENT such bodies in memory, each with its decoded JSON and photographs
LARGER_BODIES = {api.checkerboard.__name__: MAX_BOARD_BODY}  # endpoint -> its body bound (others: MAX_BODY)
MAX_DEPTH = 20  # nesting of JSON arrays and objects (the page's deepest request nests 5)
MAX_INTEGER_DIGITS = 20  # a seed is below 2**64, 20 digits
MAX_CONCURRENT = 2  # POSTs read and computed at once (2 cores): at most 2 bodies in memory
QUEUE_SECONDS = 10.0  # a POST waits this long for one of them, then gets 503
TOKEN_HEADER = "X-Homocal-Token"
STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/app.js": ("app.js", "text/javascript; charset=utf-8")}


class BadRequest(ValueError):
    """A request refused before it reaches an endpoint: (status, message)."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


class UIServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, session: Session, port: int = 0) -> None:
        super().__init__((HOST, port), Handler)
        self.session = session
        self.token = secrets.token_urlsafe(24)
        self.slots = threading.BoundedSemaphore(MAX_CONCURRENT)
        self.queue_seconds = QUEUE_SECONDS

    @property
    def address(self) -> str:
        """http://127.0.0.1:PORT/"""
        return f"http://{HOST}:{self.server_address[1]}/"

    @property
    def url(self) -> str:
        """The page's URL with this launch's token, as printed: http://127.0.0.1:PORT/?token=..."""
        return f"{self.address}?token={self.token}"


def parse_body(body: bytes) -> dict:
    """The request's JSON object; BadRequest (400) for text that is not UTF-8 JSON, nesting deeper than
    MAX_DEPTH, an integer of more than MAX_INTEGER_DIGITS digits, or a value that is not an object."""
    def integer(text: str) -> int:
        if len(text.lstrip("-")) > MAX_INTEGER_DIGITS:
            raise BadRequest(400, f"body: an integer of {len(text.lstrip('-'))} digits (at most {MAX_INTEGER_DIGITS})")
        return int(text)

    if _depth(body) > MAX_DEPTH:
        raise BadRequest(400, f"body: JSON nested deeper than {MAX_DEPTH} levels")
    try:
        request = json.loads(body, parse_int=integer)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadRequest(400, f"body: not valid JSON: {e}") from None
    if not isinstance(request, dict):
        raise BadRequest(400, "body: expected a JSON object")
    return request


_STRING_OR_BRACKET = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"|[\[\]{}]')  # a string's plain
# characters in one step of the loop (a photograph's base64: millions of them)


def _depth(body: bytes) -> int:
    """The deepest nesting of [ and { in a JSON text (brackets inside strings not counted)."""
    depth = deepest = 0
    for match in _STRING_OR_BRACKET.finditer(body):
        token = match.group()
        if token in (b"[", b"{"):
            depth += 1
            deepest = max(deepest, depth)
            if deepest > MAX_DEPTH:
                break
        elif token in (b"]", b"}"):
            depth -= 1
    return deepest


class Handler(BaseHTTPRequestHandler):
    server: UIServer
    timeout = 30  # seconds a client may take to send its request (a stalled one frees its slot)

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
            self._json(200, {**session.info(), "max_board_body": MAX_BOARD_BODY})  # the page checks an upload against it
        else:
            self._json(404, {"error": f"no such page: {path}"})

    def do_POST(self) -> None:
        if not self._host_ok():
            return
        try:
            endpoint = self._check_post()
        except BadRequest as e:
            self.close_connection = True  # an unread body must not be taken for the next request
            return self._json(e.status, {"error": str(e)})
        if not self.server.slots.acquire(timeout=self.server.queue_seconds):
            self.close_connection = True
            return self._json(503, {"error": f"busy: {MAX_CONCURRENT} requests were being answered for "
                                             f"{self.server.queue_seconds:g} s; try again"})
        try:
            self._answer_post(endpoint)
        finally:
            self.server.slots.release()

    def _answer_post(self, endpoint) -> None:
        try:
            request = self._read_body()
        except BadRequest as e:
            self.close_connection = True
            return self._json(e.status, {"error": str(e)})
        try:
            self._json(200, endpoint(self.server.session, request))
        except FileExistsError as e:
            self._json(409, {"error": str(e), "exists": True})
        except api.Refused as e:
            self._json(409, {"error": str(e)})
        except (ValueError, OSError) as e:
            self._json(400, {"error": " ".join(str(e).split())})
        except Exception as e:  # noqa: BLE001  a bug: tell the page, keep serving, print the traceback for the report
            traceback.print_exc(file=sys.stderr)
            self._json(500, {"error": f"internal error ({type(e).__name__}: {e}); see the terminal"})

    def _check_post(self):
        """The endpoint of a POST whose headers pass, or BadRequest: an unknown endpoint (404), no or a wrong
        token (403), not JSON (415)."""
        endpoint = api.ENDPOINTS.get(self.path.removeprefix("/api/")) if self.path.startswith("/api/") else None
        if endpoint is None:
            raise BadRequest(404, f"no such endpoint: {self.path}")
        if not secrets.compare_digest(self.headers.get(TOKEN_HEADER, "").encode(), self.server.token.encode()):
            raise BadRequest(403, f"{TOKEN_HEADER}: missing or wrong (open the URL homocal ui printed, with its "
                                  "token)")
        if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
            raise BadRequest(415, "Content-Type: send JSON (Content-Type: application/json)")
        return endpoint

    def _read_body(self) -> dict:
        """The request's JSON object (``parse_body``), or BadRequest: a Content-Length that is not 1..MAX_BODY
        (MAX_BOARD_BODY for /api/checkerboard) (400, 413), fewer bytes than it says, a bad body (400)."""
        text = self.headers.get("Content-Length", "").strip()
        if not text.isdigit() or len(text) > 12:
            raise BadRequest(400, f"Content-Length: expected a number of bytes, got {text!r}")
        length, most = int(text), LARGER_BODIES.get(self.path.removeprefix("/api/"), MAX_BODY)
        if not 0 < length <= most:
            raise BadRequest(413 if length else 400,
                             f"Content-Length: expected a JSON body of 1 byte to {most} bytes, got {length}")
        try:
            body = self.rfile.read(length)
        except OSError:
            body = b""
        if len(body) != length:
            raise BadRequest(400, f"body: {len(body)} of the {length} bytes of Content-Length arrived")
        return parse_body(body)

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
