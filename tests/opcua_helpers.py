"""Shared pieces of the OPC UA link tests: certificates and users in a temporary folder, a
free loopback port, the short slot program."""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

from millsense.link.security import add_user, ensure_identity, trust

PASSWORD = "correct-horse"
#: a slot beside the demo stock, entered at depth: the cut starts 0.15 s after the run-up
PROGRAM = "G21 G90 G17\nT1 M6\nS1000 M3\nG0 X-11 Y40 Z5\nG0 Z-3\nG1 X40 F400\nG0 Z5\nM30\n"
ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def make_pki(folder: Path) -> Path:
    """Server and client certificates trusting each other, an operator and a viewer."""
    asyncio.run(ensure_identity(folder, "server"))
    asyncio.run(ensure_identity(folder, "client"))
    trust(folder, folder / "server" / "cert.der", "server")
    trust(folder, folder / "client" / "cert.der", "client")
    add_user(folder / "users.toml", "op", PASSWORD, "operator")
    add_user(folder / "users.toml", "view", PASSWORD, "viewer")
    return folder


def make_plan(folder: Path) -> Path:
    """The slot's virtual plan (Parquet) in ``folder``."""
    from millsense.cli.cmd_run import _plan

    (folder / "slot.nc").write_text(PROGRAM)
    out = folder / "plan.parquet"
    _plan(folder / "slot.nc", ROOT / "examples/demo_part/stock.toml", "aslan-d20-2flute",
          "al7050", None, out, 0.4, 0.2)  # fmt: skip
    return out
