"""The OPC UA source of the on-line engine (issue 18 items 2 and 4).

:class:`OpcUaSource` is a live :class:`~millsense.streaming.sources.Source`: it subscribes to
the array nodes of a :class:`~millsense.link.nodemap.NodeMap`, reassembles the blocks by
their start index (:class:`Reassembler`: gaps and duplicates are counted, reported as events
and never filled — the guard marks a gap, decision 1801), converts to SI, and writes the
overrides and the feed hold back. The asyncua client runs on its own event loop in a thread;
:meth:`OpcUaSource.read` waits for the next complete block.

A link that drops (the server's socket closed, or no block for ``link_timeout_s``) raises
:class:`~millsense.online.guard.LinkInterrupted` at once: the guard raises the alarm and takes
the safe action (decision 1803). The next read reconnects for up to ``reconnect_s``: to the
same run, the missing blocks are re-sent from the server's buffer (nothing lost); to a
restarted server (a new run id), the stream goes on after the lost interval, which is reported.
After ``reconnect_s`` the link counts as lost (``ConnectionError``; the guard holds the feed
and ends the session).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from millsense.core.errors import UserError
from millsense.core.recording import ChannelInfo
from millsense.link.nodemap import ChannelMap, NodeMap
from millsense.link.security import status_name
from millsense.online.guard import LinkInterrupted
from millsense.streaming.block import Chunk, Event, EventKind, Severity
from millsense.streaming.sources import Source, SourceWrapper

log = logging.getLogger("millsense.link")


@dataclass
class Reassembler:
    """Blocks of several array nodes joined by start index into consecutive chunks.

    ``add(node, start, data)`` takes one node's block (``data``: its channels × n samples);
    a chunk is ready when every node delivered the block at the next expected index. A block
    that starts before that index or arrives twice is a **duplicate** (dropped, counted); when
    every node already holds a later block, the samples in between are a **gap**
    (:meth:`skip_gap` moves on, recording the lost interval) — nothing is interpolated.
    """

    nodes: dict[str, list[ChannelMap]]
    next: int = 0
    offset: int = 0  # added to the wire's indices (a restarted server starts again at 0)
    end: int | None = None
    started: bool = False  # a block was received
    #: the index the next block received gets (the first block of a session is sample 0;
    #: the first of a restarted server's run comes after the outage), then None
    rebase: int | None = 0
    first_start: int | None = None  # the wire index of the session's first sample
    duplicates: int = 0
    gaps: list[tuple[int, int]] = field(default_factory=list)
    pending: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)
    ready: deque[tuple[int, dict[str, np.ndarray]]] = field(default_factory=deque)

    def __post_init__(self) -> None:
        self.pending = {n: {} for n in self.nodes}

    def add_packed(self, node: str, value: np.ndarray) -> None:
        """A node's wire value ``[start, n, samples…]`` (several blocks back to back after a
        re-send)."""
        k = len(self.nodes[node])
        pos = 0
        while pos + 2 <= value.size:
            start, n = int(value[pos]), int(value[pos + 1])
            if self.rebase is not None:
                self.offset, self.rebase = self.rebase - start, None
            if not self.started:
                self.first_start, self.started = start, True
            body = value[pos + 2 : pos + 2 + k * n]
            pos += 2 + k * n
            if n == 0:
                self.end = start + self.offset
                continue
            self.add(node, start + self.offset, body.reshape(k, n))
        self._collect()

    def add(self, node: str, start: int, data: np.ndarray) -> None:
        slot = self.pending[node]
        if start < self.next or start in slot:
            self.duplicates += 1
            return
        slot[start] = data

    def _collect(self) -> None:
        while all(self.next in p for p in self.pending.values()):
            parts = [p.pop(self.next) for p in self.pending.values()]
            n = parts[0].shape[1]
            out: dict[str, np.ndarray] = {}
            for (_node, chans), d in zip(self.nodes.items(), parts, strict=True):
                for c in chans:
                    v = d[c.index, :n]
                    out[c.name] = v * c.scale + c.offset if (c.scale != 1 or c.offset) else v
            self.ready.append((self.next, out))
            self.next += n

    def gap(self) -> int | None:
        """The first index after the next expected one that every node holds (a gap), or None."""
        firsts = [min(p) if p else None for p in self.pending.values()]
        if any(f is None for f in firsts):
            return None
        later = max(f for f in firsts if f is not None)
        return (
            later if later > self.next and all(later in p for p in self.pending.values()) else None
        )

    def skip_to(self, start: int) -> None:
        """Record ``[next, start)`` as lost and continue at ``start``."""
        if start > self.next:
            self.gaps.append((self.next, start))
            for p in self.pending.values():
                for k in [k for k in p if k < start]:
                    del p[k]
            self.next = start
        self._collect()

    @property
    def done(self) -> bool:
        return self.end is not None and self.next >= self.end and not self.ready


class LinkRefused(UserError):
    """The server refused the session or could not be reached."""


class CommandRefused(UserError):
    """The server refused an override or the feed hold (the user's role, a bad value)."""


def _why(exc: BaseException) -> str:
    """One line of an asyncua failure (its status code name where there is one)."""
    if getattr(exc, "code", None) is not None:
        return f"refused by the server ({status_name(exc)})"
    return f"cannot connect ({type(exc).__name__}: {exc or 'no answer'})"


class _Handler:
    def __init__(self, owner: OpcUaSource) -> None:
        self.owner = owner

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        ts = getattr(getattr(data.monitored_item, "Value", None), "SourceTimestamp", None)
        if ts is not None:  # the link's latency: the server's write to this notification
            self.owner.latency_s.append(time.time() - ts.timestamp())
        self.owner._on_block(node, val)

    def status_change_notification(self, status: Any) -> None:
        self.owner._on_lost(ConnectionError(f"subscription status {status}"))


class OpcUaSource(Source):
    """The stream of an OPC UA server as a live source (see the module docstring).

    Parameters
    ----------
    url : ``opc.tcp://host:port``.
    node_map : channels, commands and flow nodes of the server.
    user, password : the session's user (None: anonymous, if the server allows it).
    pki : the link's configuration folder (None: the default).
    secure : Basic256Sha256 SignAndEncrypt (False: no security; a warning is logged).
    link_timeout_s : no block for this long (wall time) counts as an interrupted link, s (a
        closed socket is seen at once; this is for a link gone silent). Before the first
        block, ``step_timeout_s`` (the machine may still be starting).
    reconnect_s : how long to try reconnecting before the link counts as lost, s.
    connect_wait_s : how long the first connection waits for a server that is not listening
        yet, s (a machine started beside the client needs several seconds to load its plan
        and simulator; decision 1805).
    publish_ms : the subscription's publishing interval, ms.
    queue_blocks : the server-side queue of the block node, blocks.
    """

    def __init__(self, url: str, node_map: NodeMap, *, user: str | None = None,
                 password: str | None = None, pki: Path | None = None, secure: bool = True,
                 link_timeout_s: float = 0.1, step_timeout_s: float = 10.0,
                 reconnect_s: float = 5.0, connect_wait_s: float = 30.0,
                 publish_ms: float = 5.0,
                 queue_blocks: int = 500, name: str | None = None) -> None:  # fmt: skip
        self.url = url
        self.map = node_map
        self.name = name or url
        self.sample_rate_hz = node_map.sample_rate_hz
        self.user, self.password = user, password
        self.pki, self.secure = pki, secure
        self.link_timeout_s = link_timeout_s
        self.step_timeout_s = step_timeout_s
        self.reconnect_s = reconnect_s
        self.connect_wait_s = connect_wait_s
        self.publish_ms = publish_ms
        self.queue_blocks = queue_blocks
        self.asm = Reassembler(node_map.nodes)
        self.events: list[Event] = []
        #: (what, monotonic time, sample, why) of each interruption, restoration, loss
        self.link_log: list[tuple[str, float, int, str]] = []
        self.received = 0
        #: seconds from the server's write of each block to its arrival (the last 100 000)
        self.latency_s: deque[float] = deque(maxlen=100_000)
        self._cond = threading.Condition()
        self._lost: BaseException | None = None
        self._lost_at: float | None = None
        self._interrupted = False
        self._pending_cmds: list[Event] = []
        self._rest: tuple[int, dict[str, np.ndarray]] | None = None
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="opcua", daemon=True)
        self._thread.start()
        self.client: Any = None
        self.run_id: str | None = None
        self.pace = "realtime"
        try:
            self._connect_retrying()
            self._first_block(1.0)
        except UserError:
            self.close()
            raise
        except Exception as exc:
            self.close()
            raise LinkRefused(f"{url}: {_why(exc)}") from None

    # ------------------------------------------------------------------ plumbing
    def _call(self, coro: Any, timeout: float) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout)

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [ChannelInfo(c.name, c.unit, f"OPC UA {c.node}") for c in self.map.channels]

    def _nid(self, s: str) -> Any:
        from asyncua import ua

        return ua.NodeId.from_string(f"ns={self._ns};{s}")

    async def _connect(self) -> None:
        from asyncua import Client, ua
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

        from millsense.link.security import CLIENT_URI, ensure_identity, pki_dir

        c = Client(self.url, timeout=4)
        c.application_uri = CLIENT_URI
        if self.secure:
            pki = pki_dir(self.pki)
            ident = await ensure_identity(pki, "client")
            server_der = await _trusted_server_certificate(c, pki)
            await c.set_security(
                SecurityPolicyBasic256Sha256,
                str(ident.cert),
                str(ident.key),
                server_certificate=server_der,
                mode=ua.MessageSecurityMode.SignAndEncrypt,
            )
        else:
            log.warning("connecting WITHOUT encryption (--insecure)")
        if self.user is not None:
            c.set_user(self.user)
            c.set_password(self.password or "")

        async def lost(exc: Exception) -> None:
            self._on_lost(exc)

        c.connection_lost_callback = lost
        await c.connect()
        self.client = c
        self._ns = await c.get_namespace_index(self.map.namespace)
        if self.map.run_id:
            old, self.run_id = (
                self.run_id,
                str(await c.get_node(self._nid(self.map.run_id)).read_value()),
            )
            if old is not None and self.run_id != old:
                self._new_run()
        try:
            pace_node = self._nid(self.map.channels[0].node.rsplit(".", 1)[0] + ".Pace")
            self.pace = str(await c.get_node(pace_node).read_value())
        except Exception:  # a real CNC has no pace node: it runs in real time
            self.pace = "realtime"
        sub = await c.create_subscription(self.publish_ms, _Handler(self))
        nodes = [c.get_node(self._nid(n)) for n in self.map.nodes]
        self._node_names = {
            str(n.nodeid): key for n, key in zip(nodes, self.map.nodes, strict=True)
        }
        await sub.subscribe_data_change(nodes, queuesize=self.queue_blocks)
        self.sub = sub

    def _on_block(self, node: Any, val: Any) -> None:
        a = np.asarray(val, dtype=np.float64)
        if a.size < 2:
            return
        with self._cond:
            before = self.asm.next
            self.asm.add_packed(self._node_names[str(node.nodeid)], a)
            self.received += self.asm.next - before
            self._cond.notify_all()

    def _on_lost(self, exc: BaseException) -> None:
        with self._cond:
            if self._lost is None:
                self._lost = exc
                self._lost_at = time.monotonic()
            self._cond.notify_all()

    def _connect_retrying(self) -> None:
        """Connect; a server not yet listening is tried again every 0.2 s for
        ``connect_wait_s`` (it may be starting). Refusals are not retried."""
        t0 = time.monotonic()
        while True:
            try:
                self._call(asyncio.wait_for(self._connect(), 10.0), 11.0)
                return
            except OSError:
                if time.monotonic() - t0 > self.connect_wait_s:
                    raise
                time.sleep(0.2)

    def _first_block(self, wait_s: float) -> None:
        """Wait briefly for the block the server sends on subscribing (its latest): the
        session starts there, its sample 0 at the stream time ``t0_s`` (a fresh lock-step
        server has none yet: 0)."""
        with self._cond:
            self._cond.wait_for(lambda: self.asm.started, wait_s)
            if self.asm.first_start is not None:
                self.t0_s = self.asm.first_start / self.sample_rate_hz

    # ------------------------------------------------------------------ reading
    def read(self, max_samples: int) -> Chunk | None:
        """The next block (split if longer than ``max_samples``), None at the end of the
        stream; raises LinkInterrupted when the link drops (see the module docstring)."""
        if self._rest is not None:
            return self._take_rest(max_samples)
        if self._interrupted:
            self._reconnect()
        lockstep = self.pace == "lockstep" and self.map.step is not None
        slow = lockstep or not self.asm.started
        timeout = self.step_timeout_s if slow else self.link_timeout_s
        if lockstep and not self.asm.ready:
            try:
                self._call(self._step(), self.step_timeout_s)
            except Exception as exc:
                self._on_lost(exc)
        deadline = time.monotonic() + timeout
        resend_asked = False
        with self._cond:
            while True:
                if self.asm.ready:
                    start, data = self.asm.ready.popleft()
                    break
                if self.asm.done:
                    return None
                if self._lost is not None:
                    return self._interrupt()
                g = self.asm.gap()
                if g is not None:
                    nxt = self.asm.next - self.asm.offset
                    if not resend_asked and self.map.resend is not None and nxt >= 0:
                        resend_asked = True
                        self._cond.release()
                        try:
                            self._call(self._resend(nxt), 2.0)
                        except Exception as exc:
                            self._on_lost(exc)
                        finally:
                            self._cond.acquire()
                        continue
                    self._report_gap(g)
                    continue
                left = deadline - time.monotonic()
                if left <= 0:
                    self._on_lost(TimeoutError(f"no block for {timeout:.3g} s"))
                    continue
                self._cond.wait(left)
        self._rest = (start, data)
        return self._take_rest(max_samples)

    def _take_rest(self, max_samples: int) -> Chunk:
        assert self._rest is not None
        start, data = self._rest
        n = len(next(iter(data.values())))
        m = min(n, max_samples)
        self._rest = None if m == n else (start + m, {k: v[m:] for k, v in data.items()})
        return Chunk(start, self.sample_rate_hz, self.t0_s, {k: v[:m] for k, v in data.items()})

    async def _step(self) -> None:
        assert self.map.step is not None
        obj = self.client.get_node(self._nid(self.map.step.object))
        await obj.call_method(self._nid(self.map.step.method), _uint32(1))

    async def _resend(self, start: int) -> None:
        from asyncua import ua

        assert self.map.resend is not None
        obj = self.client.get_node(self._nid(self.map.resend.object))
        got = await obj.call_method(self._nid(self.map.resend.method),
                                    ua.Variant(start, ua.VariantType.UInt64))  # fmt: skip
        node = next(iter(self.map.nodes))
        a = np.asarray(got if got is not None else [], dtype=np.float64)
        with self._cond:
            before = self.asm.next
            self.asm.add_packed(node, a)
            self.received += self.asm.next - before
            self._cond.notify_all()

    def _new_run(self) -> None:
        """A restarted machine counts again from 0: its stream goes on after the outage,
        which is reported as lost (decision 1803); set before the new subscription."""
        with self._cond:
            outage = time.monotonic() - (self._lost_at or time.monotonic())
            self._report_gap(self.asm.next + round(outage * self.sample_rate_hz))
            self.asm.rebase = self.asm.next
            self.asm.end = None

    def _report_gap(self, later: int) -> None:
        lo = self.asm.next
        self.asm.skip_to(later)
        t = lo / self.sample_rate_hz
        msg = (f"{self.name}: samples {lo}–{later - 1} ({(later - lo) / self.sample_rate_hz:.3f} "
               "s) lost on the link")  # fmt: skip
        log.warning(msg)
        self.events.append(Event(t, EventKind.ALARM, "opcua", msg, name="samples_lost",
                                 value=float(later - lo), sample=lo,
                                 severity=Severity.WARNING))  # fmt: skip

    # ------------------------------------------------------------------ link loss
    def _interrupt(self) -> Chunk | None:
        exc = self._lost
        self._interrupted = True
        why = f"{type(exc).__name__}: {exc}"
        self.link_log.append(("interrupted", self._lost_at or time.monotonic(), self.asm.next, why))
        raise LinkInterrupted(f"{self.name}: link interrupted ({type(exc).__name__}: {exc})",
                              sample=self.asm.next)  # fmt: skip

    def _reconnect(self) -> None:
        """Reconnect within ``reconnect_s`` of the loss, re-send or report what was missed."""
        lost_at = self._lost_at or time.monotonic()
        try:
            self._call(self._drop(), 2.0)
        except Exception:
            pass
        while True:
            try:
                old = self.run_id
                self._call(asyncio.wait_for(self._connect(), 5.0), 6.0)
                break
            except Exception as exc:
                if time.monotonic() - lost_at > self.reconnect_s:
                    self.link_log.append(("lost", time.monotonic(), self.asm.next, str(exc)))
                    raise ConnectionError(
                        f"{self.name}: no link for {self.reconnect_s:g} s ({exc})"
                    ) from None
                time.sleep(0.2)
        with self._cond:
            self._lost, self._lost_at, self._interrupted = None, None, False
            outage = time.monotonic() - lost_at
            same_run = old is None or self.run_id == old
        self.link_log.append(("restored", time.monotonic(), self.asm.next, f"{outage:.3f} s"))
        msg = f"{self.name}: link restored after {outage:.2f} s" + (
            "" if same_run else " (the server restarted: a new run)"
        )
        self.events.append(
            Event(self.asm.next / self.sample_rate_hz, EventKind.NOTE, "opcua", msg,
                  name="link_restored", value=outage, sample=self.asm.next)
        )  # fmt: skip
        if same_run and self.map.resend is not None:
            try:
                self._call(self._resend(self.asm.next - self.asm.offset), 2.0)
            except Exception as exc:
                self._on_lost(exc)
        for ev in self._pending_cmds:
            self.command(ev)
        self._pending_cmds.clear()

    async def _drop(self) -> None:
        if self.client is not None:
            c, self.client = self.client, None
            try:
                await asyncio.wait_for(c.disconnect(), 1.0)
            except Exception:
                pass

    # ------------------------------------------------------------------ commands
    def command(self, event: Event) -> None:
        """Write an override (percent) or call the feed hold; while the link is down the
        command waits for the reconnection."""
        if event.kind is not EventKind.OVERRIDE:
            return
        if self._lost is not None or self._interrupted or self.client is None:
            self._pending_cmds.append(event)
            return
        try:
            self._call(self._command(event), 2.0)
        except Exception as exc:
            if getattr(exc, "code", None) is not None:  # the server answered: a refusal
                raise CommandRefused(f"{self.url}: {event.name} {_why(exc)}") from None
            self._pending_cmds.append(event)
            self._on_lost(exc)
            raise ConnectionError(
                f"{self.name}: command {event.name} not written ({exc})"
            ) from None

    async def _command(self, event: Event) -> None:
        from asyncua import ua

        if event.name == "feed_hold":
            if self.map.feed_hold is None:
                raise ConnectionError("the node map has no feed_hold method")
            hold = event.value is None or event.value != 0
            obj = self.client.get_node(self._nid(self.map.feed_hold.object))
            await obj.call_method(self._nid(self.map.feed_hold.method),
                                  ua.Variant(hold, ua.VariantType.Boolean))  # fmt: skip
            return
        node = self.map.commands.get(event.name)
        if node is None or event.value is None:
            return
        await self.client.get_node(self._nid(node)).write_value(
            ua.DataValue(ua.Variant(float(event.value), ua.VariantType.Double))
        )

    def take_events(self) -> list[Event]:
        out, self.events = self.events, []
        return out

    @property
    def metadata(self) -> dict[str, object]:
        return {"source": f"opcua {self.url}", "node_map": self.map.source,
                "run_id": self.run_id or "", "pace": self.pace}  # fmt: skip

    def close(self) -> None:
        try:
            self._call(self._drop(), 3.0)
        except Exception:
            pass
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(2.0)


async def _trusted_server_certificate(client: Any, pki: Path) -> bytes:
    """The server's certificate (DER) from its endpoints, if it is one of ``trusted/servers``
    (else a refusal naming the command that trusts it)."""
    from asyncua import ua
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    from millsense.link.security import UntrustedServer

    endpoints = await client.connect_and_get_server_endpoints()
    ep = client.find_endpoint(endpoints, ua.MessageSecurityMode.SignAndEncrypt,
                              SecurityPolicyBasic256Sha256.URI)  # fmt: skip
    der = bytes(ep.ServerCertificate)
    trusted = [p.read_bytes() for p in sorted((pki / "trusted" / "servers").glob("*.der"))]
    if der not in trusted:
        raise UntrustedServer(
            f"{client.server_url.geturl()}: the server's certificate is not trusted (trust it with "
            f"`millsense opcua-trust --kind server CERT.der`, folder {pki / 'trusted' / 'servers'})"
        )
    return der


def _uint32(n: int) -> Any:
    from asyncua import ua

    return ua.Variant(n, ua.VariantType.UInt32)


class StopAt(SourceWrapper):
    """A live source ended after ``duration_s`` of its stream (``record --duration-s``)."""

    def __init__(self, inner: Source, duration_s: float) -> None:
        super().__init__(inner)
        self.stop = max(1, round(duration_s * inner.sample_rate_hz))

    def read(self, max_samples: int) -> Chunk | None:
        c = self.inner.read(max_samples)
        if c is None or c.start >= self.stop:
            return None
        if c.start + c.n > self.stop:
            m = self.stop - c.start
            c = Chunk(c.start, c.sample_rate_hz, c.t0_s, {k: v[:m] for k, v in c.data.items()})
        return c
