"""``millsense serve-machine``, ``record``, ``opcua-user``, ``opcua-trust``: the OPC UA link
(issue 18, :mod:`millsense.link`; node map in docs/opcua.md)."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from millsense.cli import link_options as lo
from millsense.cli.main import app
from millsense.core.errors import ConfigError


@app.command("serve-machine")
def serve_machine(
    program: Path | None = typer.Option(None, "--program", help="Part program (G-code)."),
    stock: Path | None = typer.Option(None, "--stock", help="Stock TOML (with --program)."),
    tool: str | None = typer.Option(None, "--tool", help="Tool TOML or preset (with --program)."),
    material: str | None = typer.Option(
        None, "--material", help="Material TOML or preset (with --program)."
    ),
    plan: Path | None = typer.Option(None, "--plan", help="A virtual plan (.parquet)."),
    machine: str = typer.Option("quaser-ux600", "--machine", help="Virtual machine preset."),
    endpoint: str = typer.Option("opc.tcp://127.0.0.1:4840", "--endpoint", help="Listen here."),
    pace: str = typer.Option(
        "realtime", "--pace", help="realtime, or lockstep (a block per client step; tests)."
    ),
    speed: float = typer.Option(
        1.0, "--speed", help="Real-time factor of --pace realtime (2: twice as fast)."
    ),
    buffer_s: float = typer.Option(5.0, "--buffer-s", help="Stream kept for re-sending [s]."),
    node_map: Path | None = lo.NODE_MAP,
    pki: Path | None = lo.PKI,
    allow_insecure: bool = typer.Option(
        False, "--allow-insecure", help="Also serve unencrypted (warned)."
    ),
    allow_anonymous: bool = typer.Option(
        False, "--allow-anonymous", help="Accept anonymous read-only sessions (warned)."
    ),
    break_at_s: float | None = typer.Option(
        None, "--break-at-s", help="Break a tooth of the virtual tool at this time [s]."
    ),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every noise generator."),
    duration_s: float | None = typer.Option(None, "--duration-s", help="Stop after this [s]."),
    home_mm: str | None = typer.Option(
        None, "--home-mm", help="G28 reference X,Y,Z [mm] (machine frame), for programs with G28."
    ),
    linger_s: float | None = typer.Option(
        None, "--linger-s", help="Serve this long after the program ends [s] (default: until ^C)."
    ),
) -> None:
    """Serve the virtual machine running a program over OPC UA, as a CNC would."""
    import asyncio

    from millsense.cli.cmd_run import _check_times, virtual_machine
    from millsense.link.nodemap import load_node_map
    from millsense.link.security import Users, pki_dir
    from millsense.link.server import MachineServer, ServeOptions, SpindleNameplate, serve

    _check_times(duration_s, break_at_s, 0)
    if not (math.isfinite(buffer_s) and buffer_s >= 0):
        raise ConfigError(f"--buffer-s: must be finite and ≥ 0, got {buffer_s}")
    if linger_s is not None and not (math.isfinite(linger_s) and linger_s >= 0):
        raise ConfigError(f"--linger-s: must be finite and ≥ 0, got {linger_s}")
    lo.link_logging()
    opts = ServeOptions(endpoint=endpoint, pace=pace, speed=speed, buffer_s=buffer_s, pki=pki,
                        allow_insecure=allow_insecure, allow_anonymous=allow_anonymous)  # fmt: skip
    nmap = load_node_map(node_map)
    users = Users(pki_dir(pki) / "users.toml", allow_anonymous=allow_anonymous)
    if not users.users and not allow_anonymous:
        raise ConfigError(
            f"{users.path}: no users; add one with `millsense opcua-user NAME --role operator`"
        )
    vm = virtual_machine(
        program=program, stock=stock, tool=tool, material=material, plan=plan, plan_out=None,
        machine=machine, break_at_s=break_at_s, seed=seed, duration_s=duration_s,
        home_mm=home_mm,
    )  # fmt: skip
    for n in vm.notes:
        typer.echo(f"millsense: note: {n}", err=True)
    server = MachineServer(vm.sim, opts, users, nmap, vm.metadata, vm.sim.take_stream_rows,
                           SpindleNameplate.for_machine(vm.config.name))
    typer.echo(f"serving {vm.config.name} on {endpoint} ({pace}); ^C stops", err=True)
    try:
        asyncio.run(serve(server, linger_s))
    except KeyboardInterrupt:
        pass
    typer.echo(f"served {server.served} samples in {server.blocks} blocks", err=True)


@app.command()
def record(
    url: str = typer.Argument(..., help="opc.tcp://HOST:PORT of the CNC."),
    out: Path = typer.Option(..., "-o", "--output", help="Recording to write (.h5)."),
    events_out: Path | None = typer.Option(
        None, "--events", help="Event log (.parquet; default: beside the recording)."
    ),
    duration_s: float | None = typer.Option(None, "--duration-s", help="Stop after this [s]."),
    node_map: Path | None = lo.NODE_MAP,
    user: str | None = lo.USER,
    pki: Path | None = lo.PKI,
    insecure: bool = lo.INSECURE,
    reconnect_s: float = lo.RECONNECT,
    connect_wait_s: float = lo.CONNECT_WAIT,
) -> None:
    """Record a CNC's OPC UA stream (gaps and duplicates reported, nothing interpolated)."""
    from millsense.cli.cmd_run import link_summary
    from millsense.io.safe_output import SESSION_SUFFIXES, check_outputs
    from millsense.link.client import StopAt
    from millsense.online.session import run_session
    from millsense.streaming.event_log import default_event_log_path

    check_outputs({}, {"-o": out, "--events": events_out or default_event_log_path(out)},
                  SESSION_SUFFIXES)  # fmt: skip
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration-s: must be > 0, got {duration_s}")
    lo.link_logging()
    _nmap, connect = lo.link_opener(url, node_map, user, pki, insecure, reconnect_s,
                                    connect_wait_s)  # fmt: skip
    link = connect()
    ev = events_out or default_event_log_path(out)
    try:
        src = link if duration_s is None else StopAt(link, duration_s)
        res = run_session(src, [], out=out, events_out=ev, metadata=dict(link.metadata),
                          stop_after_hold_s=None)  # fmt: skip
    except KeyboardInterrupt:
        res = None
    finally:
        link.close()
    for line in link_summary(link):
        typer.echo(line)
    if res is not None:
        typer.echo(f"{res.seconds:.2f} s recorded; events: {len(res.events)}")
    typer.echo(f"wrote {out}")


@app.command("opcua-user")
def opcua_user(
    name: str = typer.Argument(..., help="User name."),
    role: str = typer.Option("viewer", "--role", help="operator (overrides, feed hold) or viewer."),
    pki: Path | None = lo.PKI,
) -> None:
    """Add or replace an OPC UA user of serve-machine (password from $MILLSENSE_OPCUA_PASSWORD
    or a prompt; only its salted PBKDF2 hash is stored)."""
    from millsense.link.security import add_user, pki_dir

    pw = lo.password_for(name)
    path = pki_dir(pki) / "users.toml"
    add_user(path, name, pw or "", role)
    typer.echo(f"user {name} ({role}) in {path}")


@app.command("opcua-cert")
def opcua_cert(
    kind: str = typer.Option(..., "--kind", help="server or client."),
    pki: Path | None = lo.PKI,
) -> None:
    """Make the server's or the client's certificate if it is missing; print its path (to
    give to ``opcua-trust`` on the other side)."""
    import asyncio

    from millsense.link.security import ensure_identity, pki_dir

    if kind not in ("server", "client"):
        raise ConfigError(f"opcua-cert: --kind server or client, got {kind!r}")
    typer.echo(asyncio.run(ensure_identity(pki_dir(pki), kind)).cert)


@app.command("opcua-trust")
def opcua_trust(
    cert: Path = typer.Argument(..., help="Certificate (DER) to trust."),
    kind: str = typer.Option(..., "--kind", help="client (the server trusts it) or server."),
    pki: Path | None = lo.PKI,
) -> None:
    """Trust a client's certificate (on the server) or a server's (on the client)."""
    from millsense.link.security import pki_dir, trust

    typer.echo(f"trusted {trust(pki_dir(pki), cert, kind)}")
