"""The live dashboard's web server (issue 19 item 2; decision 1904): FastAPI on uvicorn in a
background thread, one page, a websocket pushing :meth:`~millsense.dashboard.live.LiveState.
snapshot` every :data:`PUSH_S` (and at once on a new alarm), two operator actions.

Access: bound to 127.0.0.1 by default with a random token (``secrets.token_urlsafe``); every
request carries it (``?token=`` or ``Authorization: Bearer``) or is refused with 401 (the
websocket handshake with 403). Serving beyond localhost needs ``allow_remote`` AND a TLS
certificate and key: an operator's station on the shop network then talks HTTPS/WSS only.

Routes: ``GET /`` the page; ``GET /plotly.min.js`` plotly.js (from the plotly package: the
page needs no network); ``GET /api/state`` one snapshot; ``WS /ws`` snapshots;
``POST /api/ack/{id}`` acknowledge alarm ``id``; ``POST /api/control?on=true|false``.
"""

# no `from __future__ import annotations`: FastAPI reads the route annotations at definition

import asyncio
import ipaddress
import secrets
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from millsense.core.errors import ConfigError
from millsense.dashboard.live import LiveState

#: Seconds between two snapshots pushed to the page.
PUSH_S = 0.1
#: Seconds between two looks for a new alarm, which is pushed at once.
ALARM_CHECK_S = 0.01
LOOPBACK_NAMES = ("localhost",)


@dataclass(frozen=True)
class DashboardOptions:
    """Where and how the dashboard serves.

    Attributes
    ----------
    host, port : address bound (port 0: a free port).
    allow_remote : serve on an address other than the loopback (needs TLS).
    tls_cert, tls_key : PEM certificate and key (HTTPS/WSS).
    token : the access token (default: a random one).
    """

    host: str = "127.0.0.1"
    port: int = 0
    allow_remote: bool = False
    tls_cert: Path | None = None
    tls_key: Path | None = None
    token: str = field(default_factory=lambda: secrets.token_urlsafe(24))

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ConfigError(f"--dashboard-port: 0…65535, got {self.port}")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ConfigError("--tls-cert and --tls-key: give both or neither")
        for opt, p in (("--tls-cert", self.tls_cert), ("--tls-key", self.tls_key)):
            if p is not None and not Path(p).is_file():
                raise ConfigError(f"{opt} {p}: no such file")
        if not is_loopback(self.host):
            if not self.allow_remote:
                raise ConfigError(
                    f"--dashboard-host {self.host}: not the loopback; serving beyond this "
                    "machine needs --dashboard-allow-remote and TLS (--tls-cert, --tls-key)"
                )
            if self.tls_cert is None:
                raise ConfigError(
                    f"--dashboard-host {self.host}: serving beyond this machine needs TLS "
                    "(--tls-cert and --tls-key)"
                )
        if len(self.token) < 16:
            raise ConfigError("dashboard token: at least 16 characters")

    @property
    def scheme(self) -> str:
        return "https" if self.tls_cert is not None else "http"


def is_loopback(host: str) -> bool:
    """``host`` names this machine only (127.0.0.0/8, ::1, localhost)."""
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def create_app(state: LiveState, token: str) -> Any:
    """The FastAPI application of ``state``, every route behind ``token``."""
    try:
        from fastapi import FastAPI, HTTPException, Request, WebSocket
        from fastapi.responses import HTMLResponse, JSONResponse, Response
        from starlette.websockets import WebSocketDisconnect
    except ImportError:
        raise ConfigError(
            "--dashboard: needs the dashboard extra (pip install 'millsense[dashboard]')"
        ) from None
    from plotly.offline import get_plotlyjs

    from millsense.dashboard.page import page_html

    app = FastAPI(docs_url=None, redoc_url=None, openapi_url=None)
    plotly_js = get_plotlyjs()

    def given(request_token: str | None, auth: str | None) -> str:
        if request_token:
            return request_token
        if auth and auth.lower().startswith("bearer "):
            return auth[7:].strip()
        return ""

    def check(request: Request) -> None:
        got = given(request.query_params.get("token"), request.headers.get("authorization"))
        if not secrets.compare_digest(got.encode(), token.encode()):
            raise HTTPException(status_code=401, detail="missing or wrong access token")

    @app.get("/", response_class=HTMLResponse)
    def index(request: Request) -> HTMLResponse:
        check(request)
        return HTMLResponse(page_html(token), headers={"Cache-Control": "no-store"})

    @app.get("/plotly.min.js")
    def plotly(request: Request) -> Response:
        check(request)
        return Response(plotly_js, media_type="text/javascript")

    @app.get("/api/state")
    def api_state(request: Request) -> JSONResponse:
        check(request)
        return JSONResponse(state.snapshot())

    @app.post("/api/ack/{alarm_id}")
    def api_ack(alarm_id: int, request: Request) -> JSONResponse:
        check(request)
        if not state.acknowledge(alarm_id):
            raise HTTPException(status_code=404, detail=f"no alarm {alarm_id}")
        return JSONResponse({"acknowledged": alarm_id})

    @app.post("/api/control")
    def api_control(on: bool, request: Request) -> JSONResponse:
        check(request)
        state.set_control(on)
        return JSONResponse({"control_requested": on})

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        got = given(websocket.query_params.get("token"), websocket.headers.get("authorization"))
        if not secrets.compare_digest(got.encode(), token.encode()):
            await websocket.close(code=1008)  # policy violation: the handshake gets 403
            return
        await websocket.accept()
        try:
            while True:
                await websocket.send_json(state.snapshot())
                # the next snapshot after PUSH_S, or at once when an alarm arrives (looked at
                # every ALARM_CHECK_S): an alarm does not wait for the cadence
                seen = state.alarm_count
                for _ in range(max(1, round(PUSH_S / ALARM_CHECK_S))):
                    await asyncio.sleep(ALARM_CHECK_S)
                    if state.alarm_count != seen:
                        break
        except (WebSocketDisconnect, RuntimeError):
            return

    return app


class DashboardServer:
    """The dashboard served in a daemon thread (:meth:`start`, :meth:`stop`)."""

    def __init__(self, state: LiveState, options: DashboardOptions | None = None) -> None:
        self.state = state
        self.options = options or DashboardOptions()
        self.app = create_app(state, self.options.token)
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self.port = 0

    @property
    def url(self) -> str:
        """The page's address with the token."""
        o = self.options
        host = f"[{o.host}]" if ":" in o.host else o.host
        return f"{o.scheme}://{host}:{self.port}/?token={o.token}"

    def start(self, timeout_s: float = 10.0) -> str:
        """Bind, serve in the background, return :attr:`url` once accepting."""
        import uvicorn

        o = self.options
        family = socket.AF_INET6 if ":" in o.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((o.host, o.port))
        except OSError as exc:
            sock.close()
            raise ConfigError(f"dashboard: cannot bind {o.host}:{o.port} ({exc})") from None
        self.port = int(sock.getsockname()[1])
        config = uvicorn.Config(
            self.app, log_level="warning", ws="websockets-sansio",
            ssl_certfile=str(o.tls_cert) if o.tls_cert else None,
            ssl_keyfile=str(o.tls_key) if o.tls_key else None,
        )  # fmt: skip
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(
            target=self._server.run, kwargs={"sockets": [sock]}, daemon=True,
            name="millsense-dashboard",
        )  # fmt: skip
        self._thread.start()
        t0 = time.monotonic()
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() - t0 > timeout_s:
                raise ConfigError(f"dashboard: the server did not start on {o.host}:{self.port}")
            time.sleep(0.02)
        return self.url

    def stop(self) -> None:
        """Stop serving (the open pages lose their connection)."""
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5.0)
