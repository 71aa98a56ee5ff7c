"""Node maps: which OPC UA nodes of a CNC carry which millsense channels, in which units, and
where overrides and the feed hold are written (issue 18 item 2; docs/opcua.md).

A node map is a TOML file::

    name = "millsense virtual machine"
    namespace = "urn:millsense:virtual-machine"   # ns=<index of this URI> in the node ids

    [stream]
    sample_rate_hz = 10000.0
    run_id = "s=Machines.VM.Monitoring.Stream.RunId"          # optional: a new run restarts
    step = { object = "s=...Stream", method = "s=...Stream.Step" }     # optional: lock-step
    resend = { object = "s=...Stream", method = "s=...Stream.Resend" } # optional: buffer

    [[channel]]
    name = "x/current_cmd"      # the millsense channel
    node = "s=...Stream.Block"  # an array node: [start index, n, its channels' n samples each]
    unit = "A"                  # the SI unit millsense uses
    scale = 1.0                 # SI value = scale * value on the wire (+ offset)

    [commands]
    feed_override = "s=...FeedOverride"        # Double, percent
    spindle_override = "s=...SpindleOverride"  # Double, percent
    feed_hold = { object = "s=...Channel1", method = "s=...Channel1.FeedHold" }

Channels sharing a ``node`` are packed in that node's array in the order they are listed
(the virtual machine packs all of them in one node: one notification per 10 ms block, not
one per channel); a CNC publishing one trace array per signal gives each channel its own
node. Every array starts with the index of its first sample and its sample count, so the
client reassembles blocks by index and sees gaps and duplicates (decision 1801).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from millsense.core.errors import ConfigError

#: The node map of the virtual machine served by ``millsense serve-machine``.
VIRTUAL_MACHINE_MAP = Path(__file__).parent / "data" / "virtual-machine.toml"


@dataclass(frozen=True)
class MethodRef:
    """An OPC UA method: the object it is called on and the method node (ids within the map's
    namespace)."""

    object: str
    method: str


@dataclass(frozen=True)
class ChannelMap:
    """One channel: its millsense name and SI unit, its node and position in that node's
    packed array, and the conversion ``SI = scale * wire + offset``."""

    name: str
    node: str
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    index: int = 0  # position among the channels of its node


@dataclass(frozen=True)
class NodeMap:
    """A CNC's OPC UA nodes as millsense channels and commands (see the module docstring)."""

    name: str
    namespace: str
    sample_rate_hz: float
    channels: tuple[ChannelMap, ...]
    commands: dict[str, str] = field(default_factory=dict)
    feed_hold: MethodRef | None = None
    run_id: str | None = None
    step: MethodRef | None = None
    resend: MethodRef | None = None
    source: str = ""

    @property
    def nodes(self) -> dict[str, list[ChannelMap]]:
        """The array nodes and the channels each carries, in packing order."""
        out: dict[str, list[ChannelMap]] = {}
        for c in self.channels:
            out.setdefault(c.node, []).append(c)
        return out


def _method(where: str, key: str, v: object) -> MethodRef | None:
    if v is None:
        return None
    if not (isinstance(v, dict) and isinstance(v.get("object"), str)
            and isinstance(v.get("method"), str)):  # fmt: skip
        raise ConfigError(f'{where}: {key} must be {{ object = "…", method = "…" }}')
    return MethodRef(v["object"], v["method"])


def load_node_map(path: str | Path | None = None) -> NodeMap:
    """Read a node map (None: the virtual machine's); one-line errors name the file and key."""
    p = Path(path) if path is not None else VIRTUAL_MACHINE_MAP
    where = str(p)
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{where}: no such node map") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{where}: not a TOML file ({exc})") from None
    stream = raw.get("stream", {})
    fs = stream.get("sample_rate_hz")
    if not isinstance(fs, int | float) or not fs > 0:
        raise ConfigError(f"{where}: [stream] sample_rate_hz must be a number > 0")
    if not isinstance(raw.get("namespace"), str):
        raise ConfigError(f"{where}: namespace (the URI of the node ids' namespace) is missing")
    chans: list[ChannelMap] = []
    count: dict[str, int] = {}
    seen: set[str] = set()
    for i, c in enumerate(raw.get("channel", [])):
        key = f"channel[{i}]"
        for k in ("name", "node", "unit"):
            if not isinstance(c.get(k), str):
                raise ConfigError(f"{where}: {key}.{k} must be a string")
        if c["name"] in seen:
            raise ConfigError(f"{where}: {key}: channel '{c['name']}' given twice")
        seen.add(c["name"])
        scale, offset = c.get("scale", 1.0), c.get("offset", 0.0)
        if not isinstance(scale, int | float) or not isinstance(offset, int | float) or scale == 0:
            raise ConfigError(f"{where}: {key}: scale (≠ 0) and offset must be numbers")
        idx = count.get(c["node"], 0)
        count[c["node"]] = idx + 1
        chans.append(ChannelMap(c["name"], c["node"], c["unit"], float(scale), float(offset), idx))
    if not chans:
        raise ConfigError(f"{where}: no [[channel]] entries")
    cmd = raw.get("commands", {})
    commands = {k: v for k, v in cmd.items() if k in ("feed_override", "spindle_override")}
    for k, v in commands.items():
        if not isinstance(v, str):
            raise ConfigError(f"{where}: commands.{k} must be a node id string")
    return NodeMap(
        name=str(raw.get("name", p.stem)),
        namespace=raw["namespace"],
        sample_rate_hz=float(fs),
        channels=tuple(chans),
        commands=commands,
        feed_hold=_method(where, "commands.feed_hold", cmd.get("feed_hold")),
        run_id=stream.get("run_id"),
        step=_method(where, "stream.step", stream.get("step")),
        resend=_method(where, "stream.resend", stream.get("resend")),
        source=where,
    )
