"""A local HTTP server for the download tests: serves a folder on 127.0.0.1, honours Range
headers, counts what it sends, and can cut the connection after a number of bytes."""

import http.server
import re
import threading
from pathlib import Path
from urllib.parse import unquote, urlsplit

_PIECE = 1 << 16


class RangeHandler(http.server.BaseHTTPRequestHandler):
    """GET and HEAD of the files of the :class:`Server`'s root, with single ``bytes=a-b`` ranges."""

    protocol_version = "HTTP/1.1"

    def log_message(self, *args):
        pass

    def do_HEAD(self):
        self._respond(body=False)

    def do_GET(self):
        self._respond(body=True)

    def _respond(self, body):
        server = self.server.state
        path = server.root / unquote(urlsplit(self.path).path).lstrip("/")
        wanted = self.headers.get("Range")
        server.log.append((self.command, self.path, wanted))
        location = server.redirects.get(unquote(urlsplit(self.path).path))
        if location is not None:
            self.send_response(302)
            self.send_header("Location", location)
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        if not path.is_file():
            self.send_error(404)
            return
        size = path.stat().st_size
        start, end = 0, size
        match = re.fullmatch(r"bytes=(\d+)-(\d*)", wanted or "")
        if match and server.ranges:
            start = int(match[1])
            end = min(size, int(match[2]) + 1) if match[2] else size
            if start >= size or end <= start:
                self.send_error(416)
                return
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{end - 1}/{size}")
        else:
            self.send_response(200)
        self.send_header("Content-Length", str(end - start))
        self.send_header("Content-Type", "application/octet-stream")
        if server.ranges:
            self.send_header("Accept-Ranges", "bytes")
        self.end_headers()
        if body:
            self._send(path, start, end)

    def _send(self, path, start, end):
        server = self.server.state
        with open(path, "rb") as file:
            file.seek(start)
            while start < end:
                piece = file.read(min(_PIECE, end - start))
                with server.lock:
                    budget = None if server.cut_at is None else server.cut_at - server.sent
                    if budget is not None and budget < len(piece):
                        piece = piece[: max(budget, 0)]
                        server.cut_at = None  # the next connections work
                        cut = True
                    else:
                        cut = False
                    server.sent += len(piece)
                self.wfile.write(piece)
                start += len(piece)
                if cut:
                    self.wfile.flush()
                    self.close_connection = True
                    return


class Server:
    """Context manager: the server on 127.0.0.1 for ``root``; ``url`` is its base URL.

    ``sent`` counts the body bytes sent, ``log`` the requests (method, path, Range header);
    ``cut_after`` (bytes, counted over all requests) hangs up once, mid-body; ``ranges=False``
    ignores Range headers, as a plain file server does; ``redirects`` maps a path (such as
    ``"/Chunk_1.zip"``) to the ``Location`` it is redirected to (302).
    """

    def __init__(self, root, *, ranges=True, cut_after=None, redirects=None):
        self.root, self.ranges, self.cut_at = Path(root), ranges, cut_after
        self.redirects = dict(redirects or {})
        self.sent, self.log, self.lock = 0, [], threading.Lock()
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), RangeHandler)
        self.httpd.daemon_threads = True
        self.httpd.state = self
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/"
        self.thread = threading.Thread(
            target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True
        )

    def cut_after(self, n_bytes):
        """Hang up once after ``n_bytes`` more bytes."""
        with self.lock:
            self.cut_at = self.sent + n_bytes

    def reset(self):
        with self.lock:
            self.sent = 0
            self.log.clear()

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=5)
