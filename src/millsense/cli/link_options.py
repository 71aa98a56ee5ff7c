"""Options shared by the commands that open an OPC UA link (``run --source``, ``record``):
the node map, the user (password from ``$MILLSENSE_OPCUA_PASSWORD`` or a prompt, never on the
command line), the certificate folder, and the explicit ``--insecure``."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import typer

from millsense.core.errors import ConfigError

PASSWORD_ENV = "MILLSENSE_OPCUA_PASSWORD"

NODE_MAP = typer.Option(
    None, "--node-map", help="Node map TOML of the CNC (default: the virtual machine's)."
)
USER = typer.Option(
    None, "--user", help=f"OPC UA user (password from ${PASSWORD_ENV} or a prompt)."
)
PKI = typer.Option(
    None,
    "--pki",
    help="Certificates and users folder (default $MILLSENSE_OPCUA_DIR or "
    "~/.config/millsense/opcua).",
)
INSECURE = typer.Option(
    False, "--insecure", help="No encryption (only where the server allows it; warned)."
)
RECONNECT = typer.Option(
    5.0, "--reconnect-s", help="Keep reconnecting this long before the link counts as lost [s]."
)
CONNECT_WAIT = typer.Option(
    30.0,
    "--connect-wait-s",
    help="Wait this long for a server that is not listening yet (still starting) [s].",
)


def link_logging() -> None:
    """The link's refusals and warnings on stderr (asyncua's own chatter only if serious)."""
    import logging

    logging.basicConfig(level=logging.WARNING, format="millsense: %(levelname)s: %(message)s")
    logging.getLogger("millsense.link").setLevel(logging.INFO)
    logging.getLogger("asyncua").setLevel(logging.ERROR)


def password_for(user: str | None) -> str | None:
    """The password of ``user``: the environment variable, else a hidden prompt."""
    if user is None:
        return None
    pw = os.environ.get(PASSWORD_ENV)
    if pw is not None:
        return pw
    if not sys.stdin.isatty():
        raise ConfigError(f"--user {user}: set ${PASSWORD_ENV} (no terminal to ask on)")
    return str(typer.prompt(f"password of {user}", hide_input=True))


def link_opener(url: str, node_map: Path | None, user: str | None, pki: Path | None,
                insecure: bool, reconnect_s: float,
                connect_wait_s: float = 30.0) -> tuple[Any, Any]:  # fmt: skip
    """The node map of ``url`` and a function connecting to it (an
    :class:`~millsense.link.client.OpcUaSource`); the options are checked and the password
    asked for at once, the connection is made when the caller is ready for the stream."""
    from millsense.link.client import OpcUaSource
    from millsense.link.nodemap import load_node_map

    if not url.startswith("opc.tcp://"):
        raise ConfigError(f"--source: an opc.tcp:// address, got {url!r}")
    if not reconnect_s >= 0:
        raise ConfigError(f"--reconnect-s: must be ≥ 0, got {reconnect_s}")
    if not connect_wait_s >= 0:
        raise ConfigError(f"--connect-wait-s: must be ≥ 0, got {connect_wait_s}")
    link_logging()
    if insecure:
        typer.echo("millsense: warning: --insecure: the link is not encrypted", err=True)
    nmap = load_node_map(node_map)
    password = password_for(user)

    def connect() -> Any:
        return OpcUaSource(url, nmap, user=user, password=password, pki=pki,
                           secure=not insecure, reconnect_s=reconnect_s,
                           connect_wait_s=connect_wait_s)  # fmt: skip

    return nmap, connect
