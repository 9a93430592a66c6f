"""`fractalc studio`'s server: the page, its files and one WebSocket per
page, on Tornado.

Safe by default: it listens on 127.0.0.1 unless told otherwise, and every
request, the WebSocket's included, must carry the session's random token
(`?token=`), name a host the studio answers to in its Host header (a
page whose name was rebound to this machine's address is refused) and,
where it has an Origin header, come from the studio's own page (another
site's page cannot drive it). Anything else is a 403. The page can reach
only the scene file and the output files it names; what goes back to a
page waits in one slot per kind of message, so a page that does not read
cannot make the server's memory grow.
"""
from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import os
import secrets
import socket
import struct
import sys
from pathlib import Path

import tornado.httpserver
import tornado.ioloop
import tornado.netutil
import tornado.web
import tornado.websocket

from ..errors import RenderError
from ..source import MAX_FILE_BYTES
from .live import Frame
from .session import Options, Studio

STATIC = Path(__file__).resolve().parent / "static"
DEFAULT_PORT = 8765
PORTS_TRIED = 20                # from DEFAULT_PORT on, when --port is not given
POLL_MILLISECONDS = 500         # how often the scene file is looked at
LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
WILDCARD_HOSTS = frozenset({"0.0.0.0", "::", ""})
# a text as JSON: escapes can make it longer than the file it is
MAX_MESSAGE_BYTES = 3 * MAX_FILE_BYTES
HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff",
           "X-Frame-Options": "DENY"}


def _host_name(host_header: str) -> str:
    """The name in a Host header, without its port or brackets."""
    if host_header.startswith("["):
        return host_header[1:host_header.find("]")].lower() if "]" in host_header else ""
    return host_header.rsplit(":", 1)[0].lower() if host_header.count(":") == 1 else host_header.lower()


class Guard:
    """Who may talk to the studio (the module's docstring)."""

    def __init__(self, token: str, bind_host: str):
        self.token = token
        self.names = set(LOOPBACK_NAMES) | {bind_host.lower().strip("[]")}
        self.any_address = bind_host in WILDCARD_HOSTS
        if self.any_address:
            self.names |= {socket.gethostname().lower(), socket.getfqdn().lower()}

    def host_allowed(self, host_header: str) -> bool:
        name = _host_name(host_header)
        if name in self.names:
            return True
        if self.any_address:       # an address is no name an attacker's page can rebind
            try:
                ipaddress.ip_address(name)
                return True
            except ValueError:
                return False
        return False

    @staticmethod
    def origin_allowed(request) -> bool:
        """No Origin header (not a browser's page), or the studio's own page."""
        origin, host = request.headers.get("Origin"), request.headers.get("Host", "")
        return origin is None or origin in (f"http://{host}", f"https://{host}")

    def allows(self, handler: tornado.web.RequestHandler) -> bool:
        token = handler.get_query_argument("token", "")
        return self.host_allowed(handler.request.headers.get("Host", "")) \
            and self.origin_allowed(handler.request) \
            and hmac.compare_digest(token.encode(), self.token.encode())


class _Guarded(tornado.web.RequestHandler):
    def initialize(self, server: "StudioServer", **kwargs):
        self.server = server
        super().initialize(**kwargs)

    def set_default_headers(self):
        for name, value in HEADERS.items():
            self.set_header(name, value)

    def prepare(self):
        if not self.server.guard.allows(self):
            raise tornado.web.HTTPError(403)


class PageHandler(_Guarded):
    def get(self):
        host = self.request.headers["Host"]
        self.set_header("Content-Security-Policy",
                        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
                        f"connect-src 'self' ws://{host} wss://{host}; frame-ancestors 'none'; base-uri 'none'; "
                        "form-action 'none'")
        self.set_header("Content-Type", "text/html; charset=utf-8")
        self.write((STATIC / "index.html").read_text().replace("{{token}}", self.server.guard.token))


class StaticHandler(_Guarded, tornado.web.StaticFileHandler):
    def initialize(self, server: "StudioServer", path: str):
        _Guarded.initialize(self, server, path=path)


class SocketHandler(tornado.websocket.WebSocketHandler):
    """One page: its requests go to the studio; messages to it wait in one
    slot per kind (the newest of each kind wins) while one is being sent."""

    def initialize(self, server: "StudioServer"):
        self.server = server
        self.waiting: dict[str, object] = {}
        self.sending = False

    def prepare(self):
        if not self.server.guard.allows(self):
            raise tornado.web.HTTPError(403)

    def check_origin(self, origin: str) -> bool:
        return self.server.guard.origin_allowed(self.request)

    def open(self):
        self.server.sockets.add(self)
        self.server.studio.hello(self.queue)

    def on_close(self):
        self.server.sockets.discard(self)

    def on_message(self, message):
        if isinstance(message, bytes):
            self.server.studio.notice("the studio takes text messages only", error=True)
            return
        try:
            request = json.loads(message)
        except ValueError:
            self.server.studio.notice("a request that is not JSON", error=True)
            return
        self.server.studio.receive(request)

    def queue(self, message) -> None:
        kind = "frame" if isinstance(message, Frame) else message["type"]
        self.waiting.pop(kind, None)
        self.waiting[kind] = message
        if not self.sending:
            self.sending = True
            tornado.ioloop.IOLoop.current().spawn_callback(self._send_waiting)

    async def _send_waiting(self) -> None:
        try:
            while self.waiting:
                kind = next(iter(self.waiting))
                message = self.waiting.pop(kind)
                data, binary = (frame_bytes(message), True) if isinstance(message, Frame) \
                    else (json.dumps(message), False)
                await self.write_message(data, binary=binary)
        except tornado.websocket.WebSocketClosedError:
            self.waiting.clear()
        finally:
            self.sending = False


def frame_bytes(frame: Frame) -> bytes:
    """A frame as one binary message: the header's length (4 bytes, big
    endian), the header (JSON), the JPEG."""
    header = json.dumps({"seq": frame.seq, "width": frame.width, "height": frame.height,
                         "samples": frame.samples, "builds": frame.builds,
                         "milliseconds": round(frame.milliseconds, 1)}).encode()
    return struct.pack(">I", len(header)) + header + frame.jpeg


def _quiet(handler) -> None:
    """No access log: the terminal keeps the one line with the address."""


class StudioServer:
    def __init__(self, path: str, options: Options, host: str = "127.0.0.1", port: int | None = None,
                 token: str | None = None):
        self.path, self.options, self.host, self.port = path, options, host, port
        self.guard = Guard(token or secrets.token_urlsafe(24), host)
        self.sockets: set[SocketHandler] = set()
        self.studio: Studio | None = None

    def broadcast(self, message) -> None:
        for page in list(self.sockets):
            page.queue(message)

    def _listen(self) -> list:
        ports = [self.port] if self.port is not None else range(DEFAULT_PORT, DEFAULT_PORT + PORTS_TRIED)
        for port in ports:
            try:
                return tornado.netutil.bind_sockets(port, self.host)
            except OSError as error:
                last = error
        if self.port is not None:
            raise RenderError(f"cannot listen on {self.host} port {self.port}: {last.strerror}")
        raise RenderError(f"ports {DEFAULT_PORT} to {DEFAULT_PORT + PORTS_TRIED - 1} are in use: choose one "
                          f"with --port (0: any free port)")

    def url(self, port: int) -> str:
        host = socket.gethostname() if self.host in WILDCARD_HOSTS else self.host
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{port}/?token={self.guard.token}"

    async def serve(self, ready) -> None:
        """Serve until cancelled (Ctrl-C); `ready(url)` once listening."""
        loop = tornado.ioloop.IOLoop.current()
        sockets = self._listen()       # a port in use fails before any work
        self.studio = Studio(self.path, self.options, self.broadcast, loop.add_callback)
        application = tornado.web.Application(
            [(r"/", PageHandler, {"server": self}),
             (r"/static/(.*)", StaticHandler, {"server": self, "path": str(STATIC)}),
             (r"/socket", SocketHandler, {"server": self})],
            websocket_max_message_size=MAX_MESSAGE_BYTES, log_function=_quiet)
        server = tornado.httpserver.HTTPServer(application, max_buffer_size=MAX_MESSAGE_BYTES)
        server.add_sockets(sockets)
        watcher = tornado.ioloop.PeriodicCallback(self.studio.poll_disk, POLL_MILLISECONDS)
        watcher.start()
        try:
            ready(self.url(sockets[0].getsockname()[1]))
            await asyncio.Event().wait()
        finally:
            watcher.stop()
            server.stop()
            for page in list(self.sockets):
                page.close()
            self.studio.close()


def has_display() -> bool:
    """Whether a browser opened here would show on a screen (not a text
    browser taking over an SSH terminal)."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or
                                                       os.environ.get("WAYLAND_DISPLAY"))


def serve(path: str, options: Options, host: str, port: int | None, open_browser: bool) -> None:
    """Run the studio until Ctrl-C; print its address on one line."""
    def ready(url: str) -> None:
        print(f"fractalc studio: {url}", flush=True)
        if open_browser and has_display():
            import webbrowser
            webbrowser.open(url)

    try:
        asyncio.run(StudioServer(path, options, host, port).serve(ready))
    except KeyboardInterrupt:
        print("fractalc studio: stopped", file=sys.stderr)
