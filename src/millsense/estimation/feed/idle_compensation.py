"""Idle (air-cut) compensation of load estimates: ``millsense estimate --idle``.

What an estimator reads in air at the cutting feed is not cutting load: friction the model
does not hold (drift with temperature, a mismatch of the friction table), the Coulomb friction
a MEDOB estimates with the cutting force, gravity on a vertical axis. Yamada §2.9 (seed 001 C8)
removes it by idling tests at the trajectory and feed of the cut; Aslan (seed 000 C2, Eq. 3.30)
takes the friction and R from air cuts. Here the air phase is found in the recording from
CNC-visible data only (:func:`find_air_window`) or given as a time window
(:func:`parse_air_window`); the same estimators run over it (:func:`measure_idle`), the mean of
each estimate per direction of the commanded velocity is the idle table
(:class:`~millsense.ident.idle_table.DirectionIdle`), and :class:`IdleCompensatedBlock`
subtracts it sample by sample while the estimate streams.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from millsense.core.config import FeedEstimatorConfig, MachineConfig
from millsense.core.errors import InputDataError
from millsense.core.recording import ChannelInfo, Recording
from millsense.estimation.feed.commanded import CommandedVelocity, velocity_source
from millsense.ident.idle_table import DirectionIdle, build_direction_idle
from millsense.streaming.block import Block, BlockOutput, Chunk
from millsense.streaming.engine import Pipeline

#: |commanded velocity| at or below which an axis is at rest, m/s or rad/s (0.6 mm/min): the
#: fine interpolator's command of an axis that does not move is constant to rounding.
VELOCITY_DEADBAND = 1e-5
#: Settling dropped at the start of the air phase, s: the drives' and estimators' transient
#: after the feed acceleration (the velocity loops settle in ≈ 10–30 ms).
AIR_SETTLE_S = 0.05
#: Path length kept clear before the stock, m: the process coupling lags one 3 ms block and
#: the estimators' filters a few ms, 0.5 mm is ≥ 25 ms at 1200 mm/min.
AIR_GUARD_M = 0.5e-3
#: Relative band of ``cnc/feed`` around the cutting feed that counts as steady.
FEED_TOLERANCE = 0.01
#: Relative band of the spindle speed around its command that counts as "at speed".
SPINDLE_TOLERANCE = 0.02
#: Shortest usable air phase, s.
MIN_AIR_S = 0.05
#: Metadata key: path length (m, ∫ cnc/feed dt from the start) where the tool enters the stock.
FIRST_ENGAGEMENT_KEY = "first_engagement_path_m"
#: Samples read at once when scanning a recording for its air phase.
SCAN_BLOCK = 65536


def find_air_window(rec: Recording | Any, where: str) -> slice:
    """The air phase at cutting feed before the first engagement, from CNC-visible data.

    Parameters
    ----------
    rec : the recording (in memory, or a :class:`~millsense.io.recording_reader.
        RecordingReader` read in blocks); its metadata :data:`FIRST_ENGAGEMENT_KEY` (written
        by ``millsense simulate`` from the program's set-up or the plan) says where along the
        path the tool enters the stock, ``cnc/feed`` gives the path length travelled.
    where : file name for error messages.

    Returns
    -------
    slice of samples: spindle at speed (within :data:`SPINDLE_TOLERANCE` of a non-zero
    command), ``cnc/feed`` within :data:`FEED_TOLERANCE` of the cutting feed (the feed where
    the path reaches the stock), the last such run before the stock minus
    :data:`AIR_GUARD_M`, its first :data:`AIR_SETTLE_S` dropped.

    Raises
    ------
    InputDataError (one line) when the metadata or a channel is missing or the phase is shorter
    than :data:`MIN_AIR_S`.

    Notes
    -----
    Two passes over blocks of :data:`SCAN_BLOCK` samples, nothing kept per sample (decision
    0961): the first integrates the path (``cumsum`` carried across blocks, the same
    sequential sum as over the whole channel) up to the stock; the second tracks the last run
    of steady samples before it.
    """
    from millsense.io.recording_reader import channel_window

    s_eng = rec.metadata.get(FIRST_ENGAGEMENT_KEY)
    if not isinstance(s_eng, (int, float)) or isinstance(s_eng, bool) or not s_eng >= 0:
        raise InputDataError(
            f"{where}: --idle auto: the recording does not say where the cut starts (metadata "
            f"'{FIRST_ENGAGEMENT_KEY}'); give the air phase with --air-s START:END"
        )
    if "cnc/feed" not in rec:
        raise InputDataError(f"{where}: no channel 'cnc/feed' (--idle auto needs the path feed)")
    fs = rec.sample_rate_hz
    n = rec.n_samples

    def feed_at(a: int, b: int) -> np.ndarray:
        return np.asarray(channel_window(rec, "cnc/feed", a, b), dtype=float)

    # pass 1: first samples whose path length reaches the stock (minus the guard)
    i_eng = i_end = n
    carry = 0.0
    for a in range(0, n, SCAN_BLOCK):
        b = min(n, a + SCAN_BLOCK)
        acc = np.cumsum(np.concatenate([[carry], feed_at(a, b)]))
        carry = float(acc[-1])
        path = acc[1:] / fs
        if i_end == n and path[-1] >= float(s_eng) - AIR_GUARD_M:
            i_end = a + int(np.searchsorted(path, float(s_eng) - AIR_GUARD_M))
        if path[-1] >= float(s_eng):
            i_eng = a + int(np.searchsorted(path, float(s_eng)))
            break
    feed_cut = float(feed_at(min(i_eng, n - 1), min(i_eng, n - 1) + 1)[0]) if n else 0.0
    if not feed_cut > 0:
        raise InputDataError(f"{where}: --idle auto: no feed where the cut starts")
    spindle = "spindle/speed_cmd" in rec and "spindle/speed" in rec
    # pass 2: the last run of steady samples before i_end
    run_start = last = -1
    prev = False
    for a in range(0, i_end, SCAN_BLOCK):
        b = min(i_end, a + SCAN_BLOCK)
        feed = feed_at(a, b)
        ok = np.abs(feed - feed_cut) <= FEED_TOLERANCE * feed_cut
        if spindle:
            cmd = np.asarray(channel_window(rec, "spindle/speed_cmd", a, b), dtype=float)
            spd = np.asarray(channel_window(rec, "spindle/speed", a, b), dtype=float)
            ok &= (cmd != 0) & (np.abs(spd - cmd) <= SPINDLE_TOLERANCE * np.abs(cmd))
        starts = np.flatnonzero(np.diff(np.concatenate([[prev], ok]).astype(np.int8)) == 1)
        if len(starts):
            run_start = a + int(starts[-1])
        idx = np.flatnonzero(ok)
        if len(idx):
            last = a + int(idx[-1])
        prev = bool(ok[-1])
    if last < 0:
        raise InputDataError(
            f"{where}: --idle auto: no sample at the cutting feed ({feed_cut * 6e4:.0f} mm/min) "
            "with the spindle at speed before the cut"
        )
    start, stop = run_start, last + 1
    start += round(AIR_SETTLE_S * fs)
    if (stop - start) < MIN_AIR_S * fs:
        raise InputDataError(
            f"{where}: --idle auto: the air phase at cutting feed before the cut lasts "
            f"{max(stop - start, 0) / fs + AIR_SETTLE_S:.3f} s, needs "
            f"{MIN_AIR_S + AIR_SETTLE_S:.2f} s (simulate --air-mm, or give --air-s START:END)"
        )
    return slice(start, stop)


def parse_air_window(text: str, rec: Recording | Any, where: str) -> slice:
    """``START:END`` (s from the start of the recording) as a slice of samples.

    Raises
    ------
    InputDataError (one line) for text that is not two numbers, a window outside the
    recording, reversed or shorter than :data:`MIN_AIR_S`.
    """
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        t0, t1 = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputDataError(f"--air-s {text!r}: expected START:END in s") from None
    dur = rec.n_samples / rec.sample_rate_hz
    if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 < t1 <= dur):
        raise InputDataError(
            f"--air-s {text!r}: needs 0 ≤ START < END ≤ {dur:.3f} s (the length of {where})"
        )
    if t1 - t0 < MIN_AIR_S:
        raise InputDataError(f"--air-s {text!r}: the air phase must last ≥ {MIN_AIR_S:g} s")
    fs = rec.sample_rate_hz
    return slice(round(t0 * fs), min(round(t1 * fs), rec.n_samples))


def _run_prefix(
    rec: Recording | Any,
    blocks: Sequence[Block],
    stop: int,
    where: str,
    chunk: int,
    keep: slice,
) -> tuple[dict[str, np.ndarray], Pipeline]:
    """Outputs of ``blocks`` (reset first) run over samples ``[0, stop)`` of ``rec``, kept only
    for the samples ``keep`` (the air phase): memory bounded by the air phase, not by where in
    the recording it lies (decision 0961). The returned arrays start at ``keep.start``."""
    from millsense.streaming.engine import run
    from millsense.streaming.sources import RecordingSource

    pipe = Pipeline(list(blocks))
    k0, k1 = keep.start, min(keep.stop, stop)
    pieces: dict[str, list[np.ndarray]] = {c.name: [] for c in pipe.output_channels()}

    def sink(ch: Chunk, outputs: dict[str, np.ndarray], _ev: object) -> None:
        a, b = max(k0, ch.start), min(k1, ch.start + ch.n)
        if b > a:
            for name, values in outputs.items():
                pieces[name].append(np.asarray(values[a - ch.start : b - ch.start]))

    needed = {c for b in blocks for c in b.inputs}
    source = RecordingSource(rec, where, stop_sample=stop, channels=sorted(needed))
    run(source, pipe, chunk, sink=sink, collect=False)
    outs = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in pieces.items()}
    return outs, pipe


def _commanded_window(
    rec: Recording | Any, axis: str, where: str, start: int, stop: int
) -> np.ndarray:
    """Samples ``[start, stop)`` of :func:`commanded_velocity` (the same values: the
    difference reads the sample before ``start``; sample 0 reads 0)."""
    from millsense.io.recording_reader import channel_window

    ch = velocity_source(axis)
    if ch not in rec:
        raise InputDataError(f"{where}: no channel '{ch}' (the commanded velocity of {axis})")
    stream = CommandedVelocity(axis)
    stream.reset(rec.sample_rate_hz)
    a = max(start - 1, 0)
    v = stream(np.asarray(channel_window(rec, ch, a, stop), dtype=float))
    return v[start - a :]


def measure_idle(
    rec: Recording | Any,
    blocks: Sequence[Block],
    estimates: Sequence[tuple[str, str, str, int]],
    window: slice,
    where: str,
    chunk: int = 1000,
) -> dict[tuple[str, str], DirectionIdle]:
    """Run fresh estimator blocks over ``rec`` up to the air phase; idle table per estimate.

    Parameters
    ----------
    rec : the recording holding the air phase (in memory or a windowed reader).
    blocks : estimator blocks not used elsewhere (they are reset and run here).
    estimates : (method, axis, channel, delay_samples) of ``blocks``.
    window : air samples (input time); each output is read ``delay_samples`` later.
    where : file name for error messages.
    chunk : samples per chunk.

    Returns
    -------
    (method, axis) → :class:`DirectionIdle` of the estimate over the window, binned by the
    commanded velocity (:func:`commanded_velocity`).
    """
    stop = min(rec.n_samples, window.stop + max((d for *_, d in estimates), default=0))
    outs, pipe = _run_prefix(rec, blocks, stop, where, chunk, slice(window.start, stop))
    units = {c.name: c.unit for c in pipe.output_channels()}
    tables: dict[tuple[str, str], DirectionIdle] = {}
    for m, ax, ch, d in estimates:
        i0, i1 = window.start + d, min(window.stop + d, stop)
        n = i1 - i0
        vel = _commanded_window(rec, ax, where, window.start, window.start + n)
        tables[(m, ax)] = build_direction_idle(
            vel,
            outs[ch][i0 - window.start : i1 - window.start],
            deadband=VELOCITY_DEADBAND,
            unit=units[ch],
            min_samples=min(100, max(n // 2, 1)),
        )
    return tables


class IdleCompensatedBlock(Block):
    """An estimator block whose load output has its idle table removed while streaming.

    Parameters
    ----------
    inner : the estimator block (outputs ``channel``, ``delay_samples`` behind its input).
    axis : axis of the estimate (its commanded velocity:
        :class:`~millsense.estimation.feed.commanded.CommandedVelocity`).
    channel : the load channel to compensate.
    idle : the idle table.
    delay_samples : output lag of ``inner``, samples (the velocity is delayed alike).

    Notes
    -----
    ``out[k] = est[k] − idle(v[k − delay])`` with ``v`` the commanded velocity (difference of
    the position command × f_s); the difference and the delay line carry state across chunks,
    so the output does not depend on the chunking.
    """

    def __init__(
        self, inner: Block, axis: str, channel: str, idle: DirectionIdle, delay_samples: int = 0
    ) -> None:
        self.inner = inner
        self.axis = axis
        self.channel = channel
        self.idle = idle
        self.delay = int(delay_samples)
        self.delay_samples = self.delay
        self.name = f"{inner.name}_idle"
        self._cmd = CommandedVelocity(axis)
        self._vel = self._cmd.channel
        self.inputs = tuple(inner.inputs) + ((self._vel,) if self._vel not in inner.inputs else ())
        self._hist = np.zeros(self.delay)

    def output_channels(self) -> list[ChannelInfo]:
        return self.inner.output_channels()

    def reset(self, sample_rate_hz: float) -> None:
        self.inner.reset(sample_rate_hz)
        self._cmd.reset(sample_rate_hz)
        self._hist = np.zeros(self.delay)

    def process(self, chunk: Chunk) -> BlockOutput:
        out = self.inner.process(chunk)
        v = self._cmd(np.asarray(chunk.data[self._vel], dtype=float))
        line = np.concatenate([self._hist, v])
        n = len(v)
        self._hist = line[n:]
        ch = dict(out.channels)
        ch[self.channel] = self.idle.compensate(line[:n], np.asarray(ch[self.channel]))
        return BlockOutput(ch, out.events)


def with_air_r(
    machine: MachineConfig,
    axes: Sequence[str],
    rec: Recording | Any,
    window: slice,
    where: str,
) -> tuple[MachineConfig, dict[str, float]]:
    """The machine with the feed estimators' R measured in the air phase (Aslan Eq. 3.30).

    Parameters
    ----------
    machine : the machine configuration.
    axes : axes whose R is measured (those whose ``[axes.<a>.estimator] r_nm2`` is set keep it).
    rec, window : the recording and its air samples.
    where : file name for error messages.

    Returns
    -------
    (machine with ``estimator.r_nm2`` set, axis → R in N²·m²).

    Notes
    -----
    Aslan: "R = RMS of the torque fluctuation in an air cut". Here R is
    :func:`~millsense.estimation.feed.tuning.air_cut_variance` (slow trend removed) of the C3 torque
    ``K_t·I − τ_f − J_e·dω/dt`` through the feed estimator's own low-pass
    (``estimator.lowpass_hz``, default 600 Hz) over the air phase: the raw estimate's force
    times ``r_g/η``. With Q tuned at
    start-up (:func:`~millsense.estimation.feed.tuning.tune_q`) the Kalman gain depends on Q/R only
    and the estimate does not change; with a configured ``q_nm2_s`` it does.
    """
    from millsense.estimation.feed.estimator import c3_front_end
    from millsense.estimation.feed.tuning import air_cut_variance
    from millsense.estimation.from_config import load_channel, raw_estimator

    axes_cfg = dict(machine.axes)
    found: dict[str, float] = {}
    for a in axes:
        cfg = machine.axis(a)
        est = cfg.estimator
        if est is not None and est.r_nm2 is not None:
            continue
        _, _, lowpass = c3_front_end(a, cfg, rec.sample_rate_hz, where)
        ch = load_channel("raw", a)
        outs, _ = _run_prefix(
            rec, [raw_estimator(a, machine, lowpass)], window.stop, where, 1000, window
        )
        torque = -outs[ch] * cfg.transmission_m_rad / cfg.efficiency
        r = air_cut_variance(torque, fs=rec.sample_rate_hz)
        if not r > 0:
            continue
        found[a] = r
        new_est = (est or FeedEstimatorConfig()).model_copy(update={"r_nm2": r})
        axes_cfg[a] = cfg.model_copy(update={"estimator": new_est})
    return machine.model_copy(update={"axes": axes_cfg}), found
