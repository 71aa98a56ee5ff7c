"""The virtual machine as an OPC UA server (issue 18 item 1; node map in docs/opcua.md).

:class:`MachineServer` runs a live :class:`~millsense.streaming.sources.Source` (the virtual
machine tool) block by block and publishes it the way a CNC would, in an address space laid
out after OPC 40501 (Machine Tools: ``Machines/<machine>/Identification``, ``Monitoring``)
and OPC 40502 (CNC Systems: ``CncInterface/CncAxisList/<axis>``, ``CncSpindleList``,
``CncChannelList/Channel1`` with the NC line, program state, tool-centre point, the writable
feed and spindle overrides and the ``FeedHold`` method):

- the 10 kHz channels as **one packed array per 10 ms block** (``Monitoring/Stream/Block``:
  ``[start index, n, channel 0's n samples, channel 1's …]`` in the node map's order; decision
  1801), Double, so the transport adds no quantisation;
- the per-axis and spindle values, NC line, TCP and program state as scalars refreshed at
  ``display_hz`` (what an HMI shows; the client reads the blocks);
- a ring of the last ``buffer_s`` of blocks, re-sent on request (``Stream/Resend``) after a
  reconnect or a gap, so a short interruption loses nothing (decision 1803);
- pacing: ``realtime`` (block k is published at k·10 ms / ``speed`` of wall time) or
  ``lockstep`` (block k is made only after the client's ``Stream/Step`` grants it, and the
  overrides written before that step act before block k, as in process; decision 1804).

Security (decision 1802, :mod:`~millsense.link.security`): Basic256Sha256 SignAndEncrypt and
user names by default; ``allow_insecure`` adds the unencrypted endpoint, ``allow_anonymous``
anonymous sessions (read-only), each with a warning.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
import uuid
from collections import deque
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import ConfigError
from millsense.link.nodemap import NodeMap, load_node_map
from millsense.link.security import status_name
from millsense.streaming.block import Event, EventKind
from millsense.streaming.sources import Source

log = logging.getLogger("millsense.link")

PACES = ("realtime", "lockstep")


@dataclass(frozen=True)
class SpindleNameplate:
    """What a CNC knows of its spindle to show its power and load: the torque constant per
    winding range (above ``switch_rad_s`` the second; Aslan Table 5.1) and the rated power.

    ``power_w``: the mean drive power of a block, K_t·I·Ω (the motor torque from the current,
    times the speed); the load in % is that over the rated power, as a CNC's spindle-load display.
    """

    torque_constant_nm_a: float
    torque_constant_range2_nm_a: float | None = None
    switch_rad_s: float | None = None
    rated_power_w: float | None = None

    @classmethod
    def from_config(cls, machine: Any) -> SpindleNameplate | None:
        """From a machine file (``[spindle]``, ``[limits] spindle_power_kw``); None without
        a spindle."""
        sp = getattr(machine, "spindle", None)
        if sp is None:
            return None
        lim = getattr(machine, "limits", None)
        kw = getattr(lim, "spindle_power_kw", None) if lim is not None else None
        switch = sp.range_switch_rpm * math.pi / 30 if sp.range_switch_rpm else None
        return cls(sp.torque_constant_nm_a, sp.torque_constant_range2_nm_a, switch,
                   None if kw is None else kw * 1e3)  # fmt: skip

    @classmethod
    def for_machine(cls, name: str) -> SpindleNameplate | None:
        """The nameplate preset of machine ``name`` (``millsense/data/machines``: the
        catalogue values a CNC is set up with, not the simulator's truth); None if none ships."""
        from millsense.core.config import MachineConfig
        from millsense.core.presets import load_preset

        try:
            return cls.from_config(load_preset(MachineConfig, name))
        except ConfigError:
            return None

    def power_w(self, current_a: np.ndarray, speed_rad_s: np.ndarray) -> float:
        """Mean K_t(Ω)·I·Ω over the samples, W."""
        i = np.asarray(current_a, dtype=np.float64)
        w = np.asarray(speed_rad_s, dtype=np.float64)
        kt = np.full(w.shape, self.torque_constant_nm_a)
        if self.switch_rad_s is not None and self.torque_constant_range2_nm_a is not None:
            kt = np.where(np.abs(w) > self.switch_rad_s, self.torque_constant_range2_nm_a, kt)
        return float(np.mean(kt * i * w)) if w.size else 0.0

    def load_pct(self, power_w: float) -> float:
        """|P| over the rated power, % (NaN without a rating)."""
        if not self.rated_power_w:
            return math.nan
        return 100.0 * abs(power_w) / self.rated_power_w


@dataclass(frozen=True)
class ServeOptions:
    """How the machine is served.

    endpoint : ``opc.tcp://host:port``.
    pace : ``realtime`` or ``lockstep`` (decision 1804).
    speed : wall-clock speed-up of ``realtime`` (1: real time, 4: four times faster).
    block_samples : samples per published block (100: 10 ms at 10 kHz).
    buffer_s : how much of the stream the server keeps for re-sending, s.
    display_hz : refresh rate of the scalar (HMI) nodes, Hz.
    pki : the link's configuration folder (None: :func:`~millsense.link.security.pki_dir`).
    allow_insecure : also offer the unencrypted endpoint (a warning is logged).
    allow_anonymous : accept anonymous (read-only) sessions (a warning is logged).
    """

    endpoint: str = "opc.tcp://127.0.0.1:4840"
    pace: str = "realtime"
    speed: float = 1.0
    block_samples: int = 100
    buffer_s: float = 5.0
    display_hz: float = 10.0
    pki: Path | None = None
    allow_insecure: bool = False
    allow_anonymous: bool = False

    def __post_init__(self) -> None:
        if self.pace not in PACES:
            raise ConfigError(f"--pace: one of {', '.join(PACES)}, got {self.pace!r}")
        if not (self.speed > 0 and math.isfinite(self.speed)):
            raise ConfigError(f"--speed: must be > 0, got {self.speed}")
        if not self.endpoint.startswith("opc.tcp://"):
            raise ConfigError(f"--endpoint: must start with opc.tcp://, got {self.endpoint!r}")
        if not (self.block_samples >= 1 and self.buffer_s >= 0):
            raise ConfigError("serve-machine: block samples ≥ 1 and buffer ≥ 0 s needed")


def pack(start: int, data: np.ndarray) -> np.ndarray:
    """One block as the wire carries it: ``[start, n, data row by row]`` (``data``: channels ×
    samples)."""
    k, n = data.shape
    out = np.empty(2 + k * n)
    out[0], out[1] = float(start), float(n)
    out[2:] = data.reshape(-1)
    return out


def _sid(node: str) -> str:
    """``s=...`` of a node map id → the string identifier."""
    if not node.startswith("s="):
        raise ConfigError(f"node map: the virtual machine's node ids are s=…, got {node!r}")
    return node[2:]


class MachineServer:
    """An OPC UA server publishing ``source`` (see the module docstring).

    ``take_rows``: a callable returning the source's 333 Hz CNC rows (``tcp_x``… as
    :meth:`~millsense.simulator.machine.MachineSimulator.take_stream_rows`), or None.
    ``users``: a :class:`~millsense.link.security.Users`.
    ``nameplate``: the spindle's :class:`SpindleNameplate` for its power and load, or None.
    """

    def __init__(self, source: Source, options: ServeOptions, users: Any,
                 node_map: NodeMap | None = None, metadata: dict[str, Any] | None = None,
                 take_rows: Any = None,
                 nameplate: SpindleNameplate | None = None) -> None:  # fmt: skip
        self.source = source
        self.nameplate = nameplate
        self.o = options
        self.users = users
        self.map = node_map or load_node_map()
        self.metadata = dict(metadata or {})
        self.take_rows = take_rows
        have = set(source.channel_names)
        missing = [c.name for c in self.map.channels if c.name not in have]
        if missing:
            raise ConfigError(
                f"{self.map.source}: the machine has no channels {', '.join(missing)}"
            )
        if abs(self.map.sample_rate_hz - source.sample_rate_hz) > 1e-9:
            raise ConfigError(f"{self.map.source}: sample_rate_hz {self.map.sample_rate_hz} ≠ "
                              f"the machine's {source.sample_rate_hz}")  # fmt: skip
        self.run_id = uuid.uuid4().hex
        self.buffer: deque[tuple[int, np.ndarray]] = deque(
            maxlen=max(1, round(options.buffer_s * source.sample_rate_hz / options.block_samples))
        )
        self.credit = 0
        self.served = 0  # samples published
        self.blocks = 0
        self.finished = False
        self.ready = asyncio.Event()
        self._credit_changed: asyncio.Event | None = None
        self._pending: list[tuple[str, float]] = []
        self._applied = {"feed_override": 100.0, "spindle_override": 100.0}
        self.commands: list[Event] = []  # what reached the machine
        self.server: Any = None

    # ------------------------------------------------------------------ address space
    async def start(self) -> None:
        """Create the server, its certificates and address space, and start listening."""
        from asyncua import Server, ua
        from asyncua.crypto.truststore import TrustStore
        from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

        from millsense.link.security import SERVER_URI, RoleRuleset, ensure_identity, pki_dir

        pki = pki_dir(self.o.pki)
        ident = await ensure_identity(pki, "server")
        srv = Server(user_manager=self.users)
        await srv.init()
        srv.set_endpoint(self.o.endpoint)
        srv.set_server_name(f"millsense virtual machine ({self.metadata.get('machine', '')})")
        await srv.set_application_uri(SERVER_URI)
        await srv.load_certificate(str(ident.cert))
        await srv.load_private_key(str(ident.key))
        store = TrustStore([pki / "trusted" / "clients"], [])
        await store.load()
        opts = CertificateValidatorOptions
        validator = CertificateValidator(opts.TRUSTED_VALIDATION | opts.PEER_CLIENT, store)

        async def validate(cert: Any, app: Any) -> None:
            try:
                await validator.validate(cert, app)
            except Exception as exc:
                log.warning("refused: client certificate of %s (%s)",
                            getattr(app, "ApplicationUri", "?"), status_name(exc))  # fmt: skip
                raise

        srv.set_certificate_validator(validate)
        ns = await srv.register_namespace(self.map.namespace)
        self.ns = ns
        policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
        if self.o.allow_insecure:
            log.warning("serving WITHOUT encryption too (--allow-insecure): anyone on the "
                        "network can read the stream and see the passwords")  # fmt: skip
            policies.append(ua.SecurityPolicyType.NoSecurity)
        ids: list[Any] = [ua.UserNameIdentityToken]
        if self.o.allow_anonymous:
            log.warning("anonymous sessions allowed (--allow-anonymous): read-only")
            ids.append(ua.AnonymousIdentityToken)
        self._data_methods: set[Any] = set()
        srv.set_security_policy(policies, permission_ruleset=None)
        srv.set_identity_tokens(ids)
        await self._build(srv, ns, ua)
        self.ruleset = RoleRuleset(self._data_methods)
        # asyncua types the argument as its SimpleRoleRuleset; it takes any ruleset
        srv.set_security_policy(policies, permission_ruleset=self.ruleset)  # type: ignore[arg-type]
        await srv.start()
        self.server = srv
        self._credit_changed = asyncio.Event()

    async def _build(self, srv: Any, ns: int, ua: Any) -> None:
        def nid(s: str) -> Any:
            return ua.NodeId(s, ns)

        objects = srv.nodes.objects
        machines = await objects.add_folder(nid("Machines"), ua.QualifiedName("Machines", ns))
        vm = "Machines.VirtualMachine"
        mach = await machines.add_object(nid(vm), ua.QualifiedName("VirtualMachine", ns))
        ident = await mach.add_object(
            nid(f"{vm}.Identification"), ua.QualifiedName("Identification", ns)
        )
        model = str(self.metadata.get("machine", ""))
        for k, v in (("Manufacturer", "millsense"), ("Model", model),
                     ("ProductInstanceUri", f"urn:millsense:vm:{self.run_id}")):  # fmt: skip
            await ident.add_variable(nid(f"{vm}.Identification.{k}"), k, v)
        mon = await mach.add_object(nid(f"{vm}.Monitoring"), ua.QualifiedName("Monitoring", ns))
        sp = f"{vm}.Monitoring.Stream"
        stream = await mon.add_object(nid(sp), ua.QualifiedName("Stream", ns))
        self.n_block = await stream.add_variable(
            nid(_sid(self.map.channels[0].node)), "Block", ua.Variant([], ua.VariantType.Double)
        )  # empty until the first block
        names = [c.name for c in self.map.channels]
        await stream.add_variable(
            nid(f"{sp}.Channels"), "Channels", ua.Variant(names, ua.VariantType.String)
        )
        await stream.add_variable(
            nid(f"{sp}.Units"),
            "Units",
            ua.Variant([c.unit for c in self.map.channels], ua.VariantType.String),
        )
        await stream.add_variable(nid(f"{sp}.SampleRate"), "SampleRate", self.source.sample_rate_hz)
        await stream.add_variable(nid(f"{sp}.Pace"), "Pace", self.o.pace)
        await stream.add_variable(nid(f"{sp}.BufferSeconds"), "BufferSeconds", self.o.buffer_s)
        if self.map.run_id:
            await stream.add_variable(nid(_sid(self.map.run_id)), "RunId", self.run_id)
        if self.map.step:
            m = await stream.add_method(
                nid(_sid(self.map.step.method)), "Step", self._step,
                [ua.VariantType.UInt32], [ua.VariantType.UInt64],
            )  # fmt: skip
            self._data_methods.add(m.nodeid)
        if self.map.resend:
            m = await stream.add_method(
                nid(_sid(self.map.resend.method)), "Resend", self._resend,
                [ua.VariantType.UInt64], [ua.VariantType.Double],
            )  # fmt: skip
            self._data_methods.add(m.nodeid)
        # OPC 40502: CncInterface with the axis, spindle and channel lists (HMI scalars)
        cnc = await mach.add_object(nid(f"{vm}.CncInterface"), ua.QualifiedName("CncInterface", ns))
        axes_list = await cnc.add_folder(nid(f"{vm}.CncInterface.CncAxisList"), "CncAxisList")
        self.scalars: list[tuple[Any, str]] = []
        have = set(self.source.channel_names)
        axis_vars = (("CmdPos", "position_cmd"), ("ActMotorAngle", "motor_angle"),
                     ("ActSpeed", "motor_speed"), ("CmdCurrent", "current_cmd"),
                     ("ActCurrent", "current"))  # fmt: skip
        for a in sorted({c.split("/")[0] for c in have if c.endswith("/position_cmd")}):
            base = f"{vm}.CncInterface.CncAxisList.{a.upper()}"
            ax = await axes_list.add_object(nid(base), a.upper())
            for label, ch in axis_vars:
                if f"{a}/{ch}" in have:
                    v = await ax.add_variable(nid(f"{base}.{label}"), label, 0.0)
                    self.scalars.append((v, f"{a}/{ch}"))
        sl = await cnc.add_folder(nid(f"{vm}.CncInterface.CncSpindleList"), "CncSpindleList")
        base = f"{vm}.CncInterface.CncSpindleList.S1"
        spn = await sl.add_object(nid(base), "S1")
        for label, ch in (("ActSpeed", "speed"), ("CmdSpeed", "speed_cmd"),
                          ("CmdCurrent", "current_cmd"), ("ActCurrent", "current")):  # fmt: skip
            if f"spindle/{ch}" in have:
                v = await spn.add_variable(nid(f"{base}.{label}"), label, 0.0)
                self.scalars.append((v, f"spindle/{ch}"))
        self.spindle_power = await spn.add_variable(nid(f"{base}.ActPower"), "ActPower", 0.0)
        self.spindle_load = await spn.add_variable(nid(f"{base}.ActLoad"), "ActLoad", 0.0)
        cl = await cnc.add_folder(nid(f"{vm}.CncInterface.CncChannelList"), "CncChannelList")
        chb = "Machines.VirtualMachine.CncInterface.CncChannelList.Channel1"
        chan = await cl.add_object(nid(chb), "Channel1")
        self.nc_line = await chan.add_variable(nid(f"{chb}.ActBlockNumber"), "ActBlockNumber", 0)
        self.state = await chan.add_variable(nid(f"{chb}.ProgramState"), "ProgramState", "ready")
        self.tcp = [await chan.add_variable(nid(f"{chb}.PosTcpBcs{k}"), f"PosTcpBcs{k}", 0.0)
                    for k in "XYZ"]  # fmt: skip
        self.feed_var = await chan.add_variable(nid(f"{chb}.ActFeedrate"), "ActFeedrate", 0.0)
        self.ovr: dict[str, Any] = {}
        for key, label in (
            ("feed_override", "FeedOverride"),
            ("spindle_override", "SpindleOverride"),
        ):
            node = self.map.commands.get(key)
            if node is None:
                continue
            v = await chan.add_variable(
                nid(_sid(node)), label, ua.Variant(100.0, ua.VariantType.Double)
            )
            await v.set_writable()
            self.ovr[key] = v
        if self.map.feed_hold:
            await chan.add_method(nid(_sid(self.map.feed_hold.method)), "FeedHold",
                                  self._feed_hold, [ua.VariantType.Boolean], [])  # fmt: skip

    # ------------------------------------------------------------------ methods
    async def _step(self, parent: Any, n: Any) -> list[Any]:
        from asyncua import ua

        self.credit += int(n.Value if hasattr(n, "Value") else n)
        if self._credit_changed is not None:
            self._credit_changed.set()
        return [ua.Variant(self.credit, ua.VariantType.UInt64)]

    async def _resend(self, parent: Any, start: Any) -> list[Any]:
        from asyncua import ua

        s = int(start.Value if hasattr(start, "Value") else start)
        parts = [b for a, b in self.buffer if a >= s][:100]  # at most 1 s per call
        flat = np.concatenate(parts) if parts else np.zeros(0)
        return [ua.Variant(flat.tolist(), ua.VariantType.Double)]

    async def _feed_hold(self, parent: Any, hold: Any) -> list[Any]:
        h = bool(hold.Value if hasattr(hold, "Value") else hold)
        self._pending.append(("feed_hold", 1.0 if h else 0.0))
        return []

    # ------------------------------------------------------------------ the machine
    def _apply_commands(self) -> None:
        """Overrides written and feed holds called since the last block, to the machine at its
        next unread sample (validated: a value outside 0–200 % is refused and reset)."""
        t = self.served / self.source.sample_rate_hz
        todo = list(self._pending)
        self._pending.clear()
        for key, var in self.ovr.items():
            v = self.server.read_attribute_value(var.nodeid).Value.Value
            if v != self._applied[key]:
                if not (isinstance(v, float) and math.isfinite(v) and 0.0 <= v <= 200.0):
                    log.warning(
                        "refused: %s = %r (0–200 %%); kept %.1f %%", key, v, self._applied[key]
                    )
                    continue
                todo.append((key, float(v)))
                self._applied[key] = float(v)
        for name, value in todo:
            ev = Event(t, EventKind.OVERRIDE, "opcua", f"{name} {value:g} over OPC UA",
                       name=name, value=value, sample=self.served)  # fmt: skip
            self.source.command(ev)
            self.commands.append(ev)

    async def run(self) -> None:
        """Produce and publish the stream until the source ends (then the end marker
        ``[end index, 0]`` and program state ``finished``)."""
        from asyncua import ua

        o = self.o
        fs = self.source.sample_rate_hz
        names = [c.name for c in self.map.channels]
        every = max(1, round(fs / o.block_samples / o.display_hz))
        await self.state.write_value("running")
        t0 = time.perf_counter()
        self.ready.set()
        while True:
            if o.pace == "lockstep":
                while self.credit <= self.blocks:
                    assert self._credit_changed is not None
                    self._credit_changed.clear()
                    await self._credit_changed.wait()
            else:
                due = t0 + self.served / fs / o.speed
                # always yield: a machine behind its schedule must not starve the publishing
                await asyncio.sleep(max(0.0, due - time.perf_counter()))
            self._apply_commands()
            chunk = self.source.read(o.block_samples)
            if chunk is None or chunk.n == 0:
                break
            data = np.stack([np.asarray(chunk.data[n], dtype=np.float64) for n in names])
            packed = pack(chunk.start, data)
            self.buffer.append((chunk.start, packed))
            now: Any = datetime.now(UTC)  # the client's latency is measured from here
            await self.n_block.write_value(
                ua.DataValue(ua.Variant(packed.tolist(), ua.VariantType.Double),
                             SourceTimestamp=now, ServerTimestamp=now)
            )  # fmt: skip
            self.served = chunk.start + chunk.n
            self.blocks += 1
            if self.blocks % every == 0:
                await self._display(chunk)
        self.buffer.append((self.served, pack(self.served, np.zeros((len(names), 0)))))
        await self.n_block.write_value(ua.Variant([float(self.served), 0.0], ua.VariantType.Double))
        await self.state.write_value("finished")
        self.finished = True
        log.info("program finished: %d samples in %d blocks", self.served, self.blocks)

    async def _display(self, chunk: Any) -> None:
        for var, ch in self.scalars:
            await var.write_value(float(chunk.data[ch][-1]))
        if self.nameplate is not None and {"spindle/current", "spindle/speed"} <= set(chunk.data):
            p = self.nameplate.power_w(chunk.data["spindle/current"], chunk.data["spindle/speed"])
            await self.spindle_power.write_value(p)
            load = self.nameplate.load_pct(p)
            if math.isfinite(load):
                await self.spindle_load.write_value(load)
        if "cnc/nc_line" in chunk.data:
            await self.nc_line.write_value(int(chunk.data["cnc/nc_line"][-1]))
        if "cnc/feed" in chunk.data:
            await self.feed_var.write_value(float(chunk.data["cnc/feed"][-1]) * 60e3)  # mm/min
        if self.take_rows is not None:
            rows = self.take_rows()
            if len(rows.get("time_s", ())):
                for var, k in zip(self.tcp, ("tcp_x", "tcp_y", "tcp_z"), strict=True):
                    await var.write_value(float(rows[k][-1]) * 1e3)  # mm
        held = any(e.name == "feed_hold" and e.value for e in self.commands[-1:])
        await self.state.write_value("held" if held else "running")

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None


async def serve(server: MachineServer, linger_s: float | None = None) -> None:
    """Start ``server``, run the machine, then keep serving ``linger_s`` (None: until
    cancelled) so clients read the end of the stream."""
    await server.start()
    try:
        await server.run()
        if linger_s is None:
            await asyncio.Event().wait()
        else:
            await asyncio.sleep(linger_s)
    finally:
        await server.stop()


class ServerThread:
    """A :class:`MachineServer` on its own event loop in a thread (tests, benchmarks, and a
    client and server in one process): ``with ServerThread(server): …`` starts it and runs
    the machine; leaving stops it."""

    def __init__(self, server: MachineServer) -> None:
        import threading

        self.server = server
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(
            target=self.loop.run_forever, name="opcua-server", daemon=True
        )
        self.future: Any = None

    def __enter__(self) -> MachineServer:
        self.thread.start()
        asyncio.run_coroutine_threadsafe(self.server.start(), self.loop).result(60)
        self.future = asyncio.run_coroutine_threadsafe(self.server.run(), self.loop)
        return self.server

    def __exit__(self, *exc: object) -> None:
        if self.future is not None and not self.future.done():
            self.future.cancel()
        asyncio.run_coroutine_threadsafe(self.server.stop(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
