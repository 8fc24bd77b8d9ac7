"""The annotation web app's HTTP server (stdlib ``ThreadingHTTPServer``); API in docs/annotate.md.

Security model in short: loopback only unless ``allow_remote``; every request but ``/login`` needs a
judge token (cookie ``pilworld_judge`` or ``Authorization: Bearer``), otherwise 401 JSON; a judge only
ever addresses their own opaque item ids (anything else is 404, whether it exists for another judge or
not); label bodies are validated field by field; every response carries no-store, nosniff, a strict
CSP and no-referrer. Request logging is off: a ``/login?token=…`` line would put a token in a log.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import re
import threading
from collections.abc import Sequence
from http import HTTPStatus
from http.cookies import CookieError, SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, quote, urlsplit

from pilworld.annotate.catalog import MAX_BODY, Catalog, LabelError, open_dataset, parse_label
from pilworld.annotate.media import MediaCache
from pilworld.annotate.store import DB_FILE, AnnotationStore
from pilworld.config.network import is_loopback

COOKIE = "pilworld_judge"
STATIC_DIR = Path(__file__).with_name("static")
SECURITY_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "Content-Security-Policy": "default-src 'self'; media-src 'self'; img-src 'self' data:; "
    "style-src 'self' 'unsafe-inline'; script-src 'self' 'unsafe-inline'",
    "Referrer-Policy": "no-referrer",
}
STATIC_TYPES = {
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".woff2": "font/woff2",
}
ITEM = r"([0-9a-f]{16})"
ROUTE_ITEM = re.compile(rf"/api/items/{ITEM}")
ROUTE_LABEL = re.compile(rf"/api/items/{ITEM}/label")
ROUTE_MEDIA = re.compile(rf"/media/{ITEM}/([A-Za-z0-9_.-]+)\.mp4")
ROUTE_STATIC = re.compile(r"/static/([A-Za-z0-9_-][A-Za-z0-9_.-]*)")
RANGE = re.compile(r"bytes=(\d*)-(\d*)")
PLACEHOLDER = (
    "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>PiL-World judging</title></head>"
    "<body><h1>PiL-World judging</h1><p>The judging page is not installed (pilworld/annotate/page.py); "
    "the API is at /api/me, /api/queue and /api/items/&lt;id&gt;.</p></body></html>"
)


class HttpError(Exception):
    """An error answer: status, message, the offending field (400s) and extra headers."""

    def __init__(self, status: int, message: str, field: str | None = None, headers: dict[str, str] | None = None):
        super().__init__(message)
        self.status = status
        self.field = field
        self.headers = headers or {}


def app_page() -> str:
    """The judging page from ``pilworld.annotate.page.app_html()``; a placeholder until that module exists."""
    try:
        module = importlib.import_module("pilworld.annotate.page")
    except ModuleNotFoundError as err:
        if err.name != "pilworld.annotate.page":
            raise
        return PLACEHOLDER
    return str(module.app_html())


def parse_range(header: str, size: int) -> tuple[int, int] | None:
    """(first, last) byte of a single ``bytes=`` range; None = serve it all; ``HttpError(416)`` if unsatisfiable."""
    m = RANGE.fullmatch(header.strip())
    if m is None:
        return None  # several ranges or another unit: a full 200 response is always allowed
    a, b = m.groups()
    if a == "" and b == "":
        return None
    if a == "":  # the last b bytes
        first, last = max(0, size - int(b)), size - 1
    else:
        first, last = int(a), min(int(b), size - 1) if b else size - 1
    if size == 0 or first >= size or first > last:
        raise HttpError(
            HTTPStatus.REQUESTED_RANGE_NOT_SATISFIABLE,
            "range not satisfiable",
            headers={"Content-Range": f"bytes */{size}"},
        )
    return first, last


class App:
    """Everything a request needs: the run's catalog, the label store and the media cache."""

    def __init__(self, run_dir: Path, store: AnnotationStore, episodes: Sequence[int] | None = None) -> None:
        self.run_dir = run_dir
        self.store = store
        self.dataset = open_dataset(run_dir)
        self.catalog = Catalog(self.dataset, store, episodes)
        self.media = MediaCache(run_dir, self.dataset, store)

    def progress(self, judge: int) -> tuple[int, int]:
        labelled = set(self.store.labels_of(judge))
        queue = self.catalog.queue(judge)
        return sum(1 for e in queue if e in labelled), len(queue)


class Handler(BaseHTTPRequestHandler):
    server_version = "pilworld-annotate"
    sys_version = ""
    protocol_version = "HTTP/1.1"  # keep-alive: a browser fetches several videos over few connections
    timeout = 60  # seconds a connection may idle before its thread gives up (no slow-loris pile-up)
    app: App  # set on the subclass made per server

    # ------------------------------------------------------------------ plumbing

    def log_message(self, format: str, *args: Any) -> None:
        pass

    def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        for k, v in SECURITY_HEADERS.items():
            self.send_header(k, v)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        for k, v in (headers or {}).items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, value: Any, headers: dict[str, str] | None = None) -> None:
        self._send(status, json.dumps(value).encode("utf-8"), "application/json", headers)

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """Every stdlib error (bad request line, unknown method, …) as JSON with the security headers."""
        if code == HTTPStatus.NOT_IMPLEMENTED:  # a method with no do_X: the contract says 405
            code = HTTPStatus.METHOD_NOT_ALLOWED
        self.close_connection = True
        with contextlib.suppress(OSError):  # the client may be gone already
            self._json(
                code, {"error": message or HTTPStatus(code).phrase}, {"Connection": "close", "Allow": "GET, PUT"}
            )

    def _dispatch(self, method: str) -> None:
        try:
            if method not in ("GET", "PUT"):
                raise HttpError(HTTPStatus.METHOD_NOT_ALLOWED, f"method {method} not allowed (GET, PUT)")
            path = urlsplit(self.path).path
            if method == "GET" and path == "/login":
                return self._login()
            judge = self._judge()
            if method == "GET":
                self._get(path, judge)
            else:
                self._put(path, judge)
        except HttpError as err:
            body: dict[str, Any] = {"error": str(err)}
            if err.field is not None:
                body["field"] = err.field
            headers = {"Allow": "GET, PUT"} if err.status == HTTPStatus.METHOD_NOT_ALLOWED else {}
            self._json(err.status, body, headers | err.headers)
        except (BrokenPipeError, ConnectionResetError):
            self.close_connection = True
        except Exception:  # never a traceback (with paths) to the browser; the operator's terminal gets one
            import traceback

            traceback.print_exc()
            self.close_connection = True
            self._json(HTTPStatus.INTERNAL_SERVER_ERROR, {"error": "internal error"})

    def do_GET(self) -> None:
        self._dispatch("GET")

    def do_PUT(self) -> None:
        self._dispatch("PUT")

    def do_POST(self) -> None:
        self._dispatch("POST")

    def do_DELETE(self) -> None:
        self._dispatch("DELETE")

    def do_PATCH(self) -> None:
        self._dispatch("PATCH")

    def do_HEAD(self) -> None:
        self._dispatch("HEAD")

    def do_OPTIONS(self) -> None:
        self._dispatch("OPTIONS")

    # ------------------------------------------------------------------ auth

    def _token(self) -> str | None:
        auth = self.headers.get("Authorization", "")
        if auth.startswith("Bearer "):
            return auth[len("Bearer ") :].strip()
        raw = self.headers.get("Cookie")
        if raw:
            try:
                jar = SimpleCookie(raw)
            except CookieError:
                return None
            if COOKIE in jar:
                return jar[COOKIE].value
        return None

    def _judge(self) -> int:
        token = self._token()
        if not token:
            raise HttpError(HTTPStatus.UNAUTHORIZED, "not logged in: open your login link (…/login?token=…)")
        judge = self.app.store.judge_of(token)
        if judge is None:
            raise HttpError(HTTPStatus.UNAUTHORIZED, "invalid token")
        return judge

    def _login(self) -> None:
        tokens = parse_qs(urlsplit(self.path).query).get("token", [])
        token = tokens[0] if len(tokens) == 1 else ""
        if not token or self.app.store.judge_of(token) is None:
            raise HttpError(HTTPStatus.UNAUTHORIZED, "invalid token")
        cookie = f"{COOKIE}={quote(token, safe='')}; HttpOnly; SameSite=Strict; Path=/"
        self._send(HTTPStatus.SEE_OTHER, b"", "text/plain", {"Location": "/", "Set-Cookie": cookie})

    # ------------------------------------------------------------------ routes

    def _episode(self, judge: int, item: str) -> int:
        episode = self.app.catalog.episode_of(judge, item)
        if episode is None:  # another judge's id, or no id at all: the same answer
            raise HttpError(HTTPStatus.NOT_FOUND, "no such item")
        return episode

    def _get(self, path: str, judge: int) -> None:
        app = self.app
        if path in ("/", "/index.html"):
            return self._send(HTTPStatus.OK, app_page().encode("utf-8"), "text/html; charset=utf-8")
        if path == "/api/me":
            done, total = app.progress(judge)
            return self._json(HTTPStatus.OK, {"judge": f"Judge {judge}", "total": total, "done": done})
        if path == "/api/queue":
            labelled = set(app.store.labels_of(judge))
            items = [{"id": app.catalog.item_id(judge, e), "done": e in labelled} for e in app.catalog.queue(judge)]
            return self._json(HTTPStatus.OK, {"items": items})
        if m := ROUTE_ITEM.fullmatch(path):
            episode = self._episode(judge, m[1])
            return self._json(HTTPStatus.OK, app.catalog.item_json(judge, episode, app.store.label(judge, episode)))
        if m := ROUTE_MEDIA.fullmatch(path):
            episode = self._episode(judge, m[1])
            if m[2] not in app.catalog.views:
                raise HttpError(HTTPStatus.NOT_FOUND, "no such view")
            return self._file(app.media.get(episode, m[2]), "video/mp4")
        if m := ROUTE_STATIC.fullmatch(path):
            file = STATIC_DIR / m[1]
            if file.suffix not in STATIC_TYPES or not file.is_file():
                raise HttpError(HTTPStatus.NOT_FOUND, "not found")
            return self._file(file, STATIC_TYPES[file.suffix])
        raise HttpError(HTTPStatus.NOT_FOUND, "not found")

    def _put(self, path: str, judge: int) -> None:
        m = ROUTE_LABEL.fullmatch(path)
        if m is None:
            if path.startswith("/api/items/") and path.endswith("/label"):
                raise HttpError(HTTPStatus.NOT_FOUND, "no such item")
            raise HttpError(HTTPStatus.METHOD_NOT_ALLOWED, "PUT is only for /api/items/<id>/label")
        episode = self._episode(judge, m[1])
        body = self._body()
        try:
            label = parse_label(body, self.app.catalog.num_frames(episode))
        except LabelError as err:
            raise HttpError(HTTPStatus.BAD_REQUEST, str(err), err.field) from None
        self.app.store.put_label(judge, episode, label)
        done, total = self.app.progress(judge)
        self._json(HTTPStatus.OK, {"ok": True, "done": done, "total": total})

    def _body(self) -> bytes:
        if self.headers.get("Transfer-Encoding"):
            self.close_connection = True
            raise HttpError(HTTPStatus.BAD_REQUEST, "body: send it with a Content-Length", "body")
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            self.close_connection = True
            raise HttpError(HTTPStatus.BAD_REQUEST, "body: Content-Length required", "body") from None
        if length < 0 or length > MAX_BODY:
            self.close_connection = True  # the unread body must not be parsed as the next request
            raise HttpError(HTTPStatus.BAD_REQUEST, f"body: larger than {MAX_BODY} bytes", "body")
        return self.rfile.read(length)

    def _file(self, path: Path, content_type: str) -> None:
        data = path.read_bytes()  # cache files are small (tens of kB per view); no streaming needed
        headers = {"Accept-Ranges": "bytes"}
        header = self.headers.get("Range")
        if header:
            span = parse_range(header, len(data))
            if span is not None:
                first, last = span
                headers["Content-Range"] = f"bytes {first}-{last}/{len(data)}"
                return self._send(HTTPStatus.PARTIAL_CONTENT, data[first : last + 1], content_type, headers)
        self._send(HTTPStatus.OK, data, content_type, headers)


def _has_judges(db: Path) -> bool:
    """Whether the annotation database ``db`` exists and holds at least one judge (read only)."""
    if not db.is_file():
        return False
    import sqlite3

    try:
        with contextlib.closing(sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro&immutable=1", uri=True)) as con:
            return bool(con.execute("SELECT COUNT(*) FROM judges").fetchone()[0] > 0)
    except sqlite3.Error:
        return True  # let the store say what is wrong with it


class AnnotationServer:
    """The app for one run folder: ``start()`` / ``stop()`` in tests, ``serve_forever()`` in the CLI.

    ``judges`` makes judges 1..N exist (tokens issued now are in ``tokens``; judges from an earlier
    start keep theirs, unless ``new_tokens``). ``episodes`` limits every queue to those episodes (default
    all; ``--abstained``: the ones a learned judge left to people). ``port=0`` picks a free port; ``url``
    is the base URL.
    """

    def __init__(
        self,
        run_dir: str | Path,
        *,
        judges: int | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        allow_remote: bool = False,
        new_tokens: bool = False,
        episodes: Sequence[int] | None = None,
    ) -> None:
        if not is_loopback(host) and not allow_remote:
            raise ValueError(
                f"--host: {host} is not a loopback address; judges' tokens and labels would travel unencrypted "
                "over the network. Pass --allow-remote to do it anyway (on a trusted network only)."
            )
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"--port: expected 0..65535, got {port!r}")
        self.run_dir = Path(run_dir)
        open_dataset(self.run_dir)  # fail on a folder that is not a dataset before creating the database in it
        if judges is None and not _has_judges(self.run_dir / DB_FILE):
            # none yet, or a first start stopped before it made them: the database stays as it is
            raise ValueError(f"--judges: {self.run_dir} has no judges yet; say how many (--judges N)")
        # The port is taken before the database is touched: a port in use leaves the run folder as it was.
        handler = type("BoundHandler", (Handler,), {})
        try:
            self.httpd = ThreadingHTTPServer((host, port), handler)
        except OSError as err:
            raise ValueError(f"--port: cannot listen on {host}:{port} ({err.strerror or err})") from None
        self.httpd.daemon_threads = True
        try:
            self.store = AnnotationStore(self.run_dir)
            self.tokens: dict[int, str] = {}
            if judges is not None:
                self.tokens = self.store.ensure_judges(judges, new_tokens=new_tokens)
            self.app = App(self.run_dir, self.store, episodes)
        except BaseException:
            self.httpd.server_close()
            raise
        handler.app = self.app  # type: ignore[attr-defined]
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        host = str(host)
        return f"http://{f'[{host}]' if ':' in host else host}:{port}"

    def login_url(self, token: str) -> str:
        return f"{self.url}/login?token={quote(token, safe='')}"

    def start(self) -> AnnotationServer:
        self._thread = threading.Thread(
            target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, name="annotate-http", daemon=True
        )
        self._thread.start()
        return self

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def stop(self) -> None:
        """Stop accepting requests and close the socket (labels are already on disk)."""
        if self._thread is not None:
            self.httpd.shutdown()
            self._thread.join(timeout=10)
            self._thread = None
        self.httpd.server_close()

    def __enter__(self) -> AnnotationServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
