"""Benchmark of the OPC UA link (issue 18): a sustained 10 kHz × 16-channel stream over
loopback for 60 s with no loss, Basic256Sha256 SignAndEncrypt, the server in its own process.

The server (:class:`~millsense.link.server.MachineServer`, real-time pace) publishes a
synthetic source — 16 channels, each a deterministic function of the sample index — in 10 ms
blocks; the client (:class:`~millsense.link.client.OpcUaSource`) reads it as the engine does
and checks every sample against the same function (exact: Doubles on the wire). Figures: the
samples lost, duplicated or wrong (target 0), the CPU share of the server and of the client
process (CPU seconds per wall second, one core = 100 %), and the latency from the server's
write of a block to its notification at the client (median and 99th percentile).
``MILLSENSE_BENCH_OPCUA_S`` shortens the run (default 60 s).
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FS = 10000.0
N_CH = 16
ROOT = Path(__file__).resolve().parents[1]
NS = "urn:millsense:bench"
NODE = "s=Bench.Stream.Block"


def expected(start: int, n: int) -> np.ndarray:
    """The 16 channels of samples ``start … start+n−1`` (channels × samples)."""
    i = np.arange(start, start + n, dtype=np.float64)
    k = np.arange(1, N_CH + 1, dtype=np.float64)[:, None]
    return np.sin(2 * np.pi * 7.0 * k * i / FS) + 1e-3 * k * ((i * k) % 97.0)


def node_map() -> object:
    from millsense.link.nodemap import ChannelMap, MethodRef, NodeMap

    chans = tuple(ChannelMap(f"ch{j:02d}", NODE, "1", index=j) for j in range(N_CH))
    return NodeMap("bench", NS, FS, chans, run_id="s=Bench.Stream.RunId",
                   resend=MethodRef("s=Bench.Stream", "s=Bench.Stream.Resend"))  # fmt: skip


def _synthetic(duration_s: float) -> object:
    from millsense.core.recording import ChannelInfo
    from millsense.streaming.block import Chunk
    from millsense.streaming.sources import Source

    class Synthetic(Source):
        name = "bench"
        sample_rate_hz = FS

        def __init__(self) -> None:
            self.pos, self.stop = 0, round(duration_s * FS)

        @property
        def channel_info(self) -> list[ChannelInfo]:
            return [ChannelInfo(f"ch{j:02d}", "1", "synthetic") for j in range(N_CH)]

        def read(self, max_samples: int) -> Chunk | None:
            n = min(max_samples, self.stop - self.pos)
            if n <= 0:
                return None
            d = expected(self.pos, n)
            c = Chunk(self.pos, FS, 0.0, {f"ch{j:02d}": d[j] for j in range(N_CH)})
            self.pos += n
            return c

    return Synthetic()


def serve(port: int, pki: Path, duration_s: float) -> None:
    """The server process: serve, then print its CPU seconds and wall seconds."""
    from millsense.link.security import Users
    from millsense.link.server import MachineServer, ServeOptions

    opts = ServeOptions(endpoint=f"opc.tcp://127.0.0.1:{port}", pki=pki, buffer_s=5.0)
    srv = MachineServer(_synthetic(duration_s), opts, Users(pki / "users.toml"), node_map())  # type: ignore[arg-type]

    async def main() -> None:
        await srv.start()
        print("ready", flush=True)
        await asyncio.sleep(1.0)  # the client subscribes before the stream starts
        c0, w0 = time.process_time(), time.perf_counter()
        await srv.run()
        print(f"cpu {time.process_time() - c0} {time.perf_counter() - w0}", flush=True)
        await asyncio.sleep(2.0)
        await srv.stop()

    asyncio.run(main())


def measure(duration_s: float) -> dict[str, float]:
    """Run the server process and the client for ``duration_s`` of stream."""
    from millsense.link.client import OpcUaSource
    from millsense.link.security import add_user, ensure_identity, trust

    with tempfile.TemporaryDirectory() as tmp:
        pki = Path(tmp)
        asyncio.run(ensure_identity(pki, "server"))
        asyncio.run(ensure_identity(pki, "client"))
        trust(pki, pki / "server" / "cert.der", "server")
        trust(pki, pki / "client" / "cert.der", "client")
        add_user(pki / "users.toml", "bench", "bench-password", "viewer")
        import socket

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        cmd = [sys.executable, __file__, "serve", str(port), str(pki), str(duration_s)]
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready"
        src = OpcUaSource(f"opc.tcp://127.0.0.1:{port}", node_map(), user="bench",  # type: ignore[arg-type]
                          password="bench-password", pki=pki, link_timeout_s=1.0)  # fmt: skip
        wrong = got = 0
        c0, w0 = time.process_time(), time.perf_counter()
        try:
            while (c := src.read(100)) is not None:
                d = np.stack([c.data[f"ch{j:02d}"] for j in range(N_CH)])
                wrong += int(np.count_nonzero(d != expected(c.start, c.n)))
                got += c.n
        finally:
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
            src.close()
        out, _ = proc.communicate(timeout=30)
        s_cpu, s_wall = (float(v) for v in out.split("cpu", 1)[1].split())
        lat = np.array(src.latency_s)
        return {
            "samples": got, "expected": round(duration_s * FS), "wrong": wrong,
            "lost": sum(b - a for a, b in src.asm.gaps), "duplicates": src.asm.duplicates,
            "server_cpu_pct": 100 * s_cpu / s_wall, "client_cpu_pct": 100 * cpu / wall,
            "latency_median_ms": 1e3 * float(np.median(lat)),
            "latency_p99_ms": 1e3 * float(np.percentile(lat, 99)),
        }  # fmt: skip


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "serve":
    serve(int(sys.argv[2]), Path(sys.argv[3]), float(sys.argv[4]))
else:
    from _harness import Metric, benchmark

    @benchmark("link.opcua")
    def _opcua() -> list[Metric]:
        dur = float(os.environ.get("MILLSENSE_BENCH_OPCUA_S", "60"))
        r = measure(dur)
        note = (f"{dur:.0f} s of 10 kHz × {N_CH} channels in 10 ms blocks over loopback, "
                "Basic256Sha256 SignAndEncrypt, server and client in separate processes, "
                f"{r['samples']:.0f} of {r['expected']:.0f} samples received")  # fmt: skip
        missing = r["expected"] - r["samples"] + r["lost"]
        return [
            Metric("samples_lost", float(missing), "samples", target=0.0, higher_is_better=False,
                   note=note),
            Metric("samples_wrong", float(r["wrong"]), "values", target=0.0,
                   higher_is_better=False, note=note + " (each checked against the source)"),
            Metric("duplicates", float(r["duplicates"]), "blocks", higher_is_better=False,
                   note=note),
            Metric("server_cpu_pct", r["server_cpu_pct"], "%", higher_is_better=False,
                   note=note + " (server process CPU / wall, one core = 100 %)"),
            Metric("client_cpu_pct", r["client_cpu_pct"], "%", higher_is_better=False,
                   note=note + " (client process CPU / wall, reading and checking)"),
            Metric("latency_median_ms", r["latency_median_ms"], "ms", higher_is_better=False,
                   note=note + " (server write → client notification, 5 ms publishing)"),
            Metric("latency_p99_ms", r["latency_p99_ms"], "ms", higher_is_better=False,
                   note=note + " (server write → client notification, 5 ms publishing)"),
        ]  # fmt: skip
