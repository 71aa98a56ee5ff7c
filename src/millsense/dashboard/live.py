"""What the live dashboard shows, kept while a session runs (issue 19 item 2).

:class:`LiveState` is the session's observer (:func:`millsense.online.session.run_session`,
``observer=``): per chunk it keeps the minimum and maximum of each shown signal (a rolling
window of :data:`WINDOW_POINTS` chunks: no peak dropped), the last :data:`SPECTRUM_SAMPLES`
samples of the spindle torque for the rolling spectrum, the tool-centre point's trail, the
alarms and the override commands. :meth:`LiveState.snapshot` is what the page receives (JSON).
The operator's requests go to the :class:`~millsense.control.arbitration.Supervisor`
(:meth:`~millsense.control.arbitration.Supervisor.request_control`,
:meth:`~millsense.control.arbitration.Supervisor.acknowledge`), taken at its next control
period. The session thread writes and the server thread reads under one lock.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from typing import Any

import numpy as np

from millsense.control.arbitration import Supervisor
from millsense.report.labels import regulated_label
from millsense.streaming.block import Chunk, Event, EventKind

RPM = 60.0 / (2.0 * math.pi)
#: Plots of signals: key → [(channel, label, scale)], drawn if the session has the channel.
SIGNALS: dict[str, list[tuple[str, str, float]]] = {
    "torque": [("est/spindle/spindle/load", "estimated", 1.0),
               ("plan/expected_torque", "expected (plan)", 1.0)],
    "feed": [("supervisor/feed_override", "commanded", 100.0),
             ("cnc/feed_override", "in effect", 100.0)],
    "regulated": [("adaptive_feed/peak", "regulated (per control interval)", 1.0),
                  ("adaptive_feed/reference", "reference", 1.0)],
    "spindle": [("spindle/speed", "spindle speed", RPM)],
}  # fmt: skip
TITLES = {
    "torque": "spindle torque [N·m]",
    "feed": "feed override [%]",
    "regulated": "regulated quantity",
    "spindle": "spindle speed [rev/min]",
}
#: Chunks kept per signal (6 s of 10 ms chunks).
WINDOW_POINTS = 600
#: Samples of the rolling spectrum (0.41 s at 10 kHz: 2.4 Hz resolution).
SPECTRUM_SAMPLES = 4096
#: Highest frequency shown in the spectrum, Hz.
SPECTRUM_MAX_HZ = 2000.0
#: Points of the tool-centre trail kept.
TRAIL_POINTS = 3000
#: Override commands listed.
OVERRIDES_KEPT = 30
MODES = ("normal", "chatter", "fault", "feed hold")


class LiveState:
    """The dashboard's view of a running session (see the module).

    Parameters
    ----------
    supervisor : the session's supervisor (the operator's requests go to it), or None.
    plan_xy_mm : the programmed path (x, y in mm) drawn under the trail, or None.
    flutes : teeth of the tool (the tooth frequency marked on the spectrum).
    spectrum_channel : the signal of the rolling spectrum.
    regulated_unit : unit of ``adaptive_feed/peak`` (``W``, ``N*m``, ``N``): the regulated plot
        is titled with the quantity and its unit (``spindle power [W]``); "" for unknown.
    """

    def __init__(
        self,
        supervisor: Supervisor | None = None,
        plan_xy_mm: tuple[np.ndarray, np.ndarray] | None = None,
        flutes: int = 2,
        spectrum_channel: str = "est/spindle/spindle/load",
        regulated_unit: str = "",
    ) -> None:
        self.supervisor = supervisor
        self.titles = {**TITLES, "regulated": regulated_label(regulated_unit)}
        self.flutes = flutes
        self.spectrum_channel = spectrum_channel
        self._lock = threading.Lock()
        self._t: deque[float] = deque(maxlen=WINDOW_POINTS)
        self._lo: dict[str, deque[float]] = {}
        self._hi: dict[str, deque[float]] = {}
        self._spec = np.zeros(SPECTRUM_SAMPLES)
        self._spec_n = 0
        self._trail: deque[tuple[float, float]] = deque(maxlen=TRAIL_POINTS)
        self.alarms: list[dict[str, Any]] = []
        self.overrides: deque[dict[str, Any]] = deque(maxlen=OVERRIDES_KEPT)
        self.now: dict[str, float] = {}
        self.fs = 0.0
        self.time_s = 0.0
        self.chunks = 0
        self.finished = False
        self.plan = None
        if plan_xy_mm is not None:
            x, y = (np.asarray(v, dtype=float) for v in plan_xy_mm)
            step = max(1, len(x) // 5000)
            self.plan = {"x": x[::step].tolist(), "y": y[::step].tolist()}

    # ------------------------------------------------------------------ the session side
    def observe(self, chunk: Chunk, outputs: dict[str, np.ndarray], events: list[Event]) -> None:
        """The session's observer: one chunk, the blocks' outputs and events."""
        if chunk.n == 0:
            return
        data = {**chunk.data, **outputs}
        with self._lock:
            self.fs = chunk.sample_rate_hz
            self.time_s = chunk.t0_s + (chunk.start + chunk.n) / chunk.sample_rate_hz
            self.chunks += 1
            self._t.append(self.time_s)
            for group in SIGNALS.values():
                for ch, _, scale in group:
                    if ch in data:
                        v = np.asarray(data[ch], dtype=float) * scale
                        ok = v[np.isfinite(v)]
                        lo, hi = (float(ok.min()), float(ok.max())) if ok.size else (math.nan,) * 2
                        self._lo.setdefault(ch, deque(maxlen=WINDOW_POINTS)).append(lo)
                        self._hi.setdefault(ch, deque(maxlen=WINDOW_POINTS)).append(hi)
                        self.now[ch] = float(v[-1])
            for ch in ("supervisor/spindle_override", "supervisor/mode", "plan/nc_line"):
                if ch in data:
                    self.now[ch] = float(np.asarray(data[ch])[-1])
            if self.spectrum_channel in data:
                self._push_spectrum(np.asarray(data[self.spectrum_channel], dtype=float))
            if "tcp/x" in data and "tcp/y" in data:
                x, y = float(data["tcp/x"][-1]), float(data["tcp/y"][-1])
                if math.isfinite(x) and math.isfinite(y):
                    self._trail.append((1e3 * x, 1e3 * y))
            for e in events:
                self._event(e)

    def _push_spectrum(self, v: np.ndarray) -> None:
        v = np.nan_to_num(v[-SPECTRUM_SAMPLES:])
        self._spec = np.roll(self._spec, -len(v))
        self._spec[-len(v) :] = v
        self._spec_n = min(SPECTRUM_SAMPLES, self._spec_n + len(v))

    def _event(self, e: Event) -> None:
        if e.kind in (EventKind.ALARM, EventKind.CRASH):
            self.alarms.append({"id": len(self.alarms), "time_s": e.time_s, "name": e.name,
                                "severity": e.severity.value, "message": e.message,
                                "acknowledged": False})  # fmt: skip
        elif e.kind is EventKind.OVERRIDE:
            self.overrides.append({"time_s": e.time_s, "name": e.name, "value": e.value,
                                   "message": e.message})  # fmt: skip
        elif e.name == "alarm_acknowledged":
            at = e.values.get("alarm_s")
            for a in self.alarms:
                if at is not None and abs(a["time_s"] - at) < 1e-9:
                    a["acknowledged"] = True

    def finish(self) -> None:
        """The session ended."""
        with self._lock:
            self.finished = True

    # ------------------------------------------------------------------ the operator side
    def acknowledge(self, alarm_id: int) -> bool:
        """Acknowledge alarm ``alarm_id`` (False: no such alarm). The supervisor records it at
        its next control period; the alarm shows as acknowledged at once."""
        with self._lock:
            if not 0 <= alarm_id < len(self.alarms):
                return False
            a = self.alarms[alarm_id]
            a["acknowledged"] = True
        if self.supervisor is not None:
            self.supervisor.acknowledge(a["name"], a["time_s"])
        return True

    def set_control(self, on: bool) -> None:
        """Ask the supervisor to switch the control on or off."""
        if self.supervisor is not None:
            self.supervisor.request_control(on)

    # ------------------------------------------------------------------ the page's data
    @property
    def alarm_count(self) -> int:
        """Alarms so far (the server pushes a snapshot as soon as it grows)."""
        return len(self.alarms)

    def spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """Frequencies (Hz) and amplitudes of the last :data:`SPECTRUM_SAMPLES` samples of the
        spectrum signal (Hann window, mean removed, amplitude-scaled), up to
        :data:`SPECTRUM_MAX_HZ`; empty until the buffer is full."""
        if self._spec_n < SPECTRUM_SAMPLES or self.fs <= 0:
            return np.zeros(0), np.zeros(0)
        x = self._spec - self._spec.mean()
        w = np.hanning(len(x))
        amp = 2.0 * np.abs(np.fft.rfft(x * w)) / w.sum()
        f = np.fft.rfftfreq(len(x), 1.0 / self.fs)
        keep = f <= SPECTRUM_MAX_HZ
        return f[keep], amp[keep]

    def snapshot(self) -> dict[str, Any]:
        """Everything the page draws, JSON-able (NaN as None)."""
        with self._lock:
            t = list(self._t)
            plots: dict[str, Any] = {}
            for key, group in SIGNALS.items():
                traces = []
                for ch, label, _ in group:
                    if ch in self._lo:
                        n = len(self._lo[ch])
                        traces.append({"name": label, "t": t[-n:], "lo": _clean(self._lo[ch]),
                                       "hi": _clean(self._hi[ch])})  # fmt: skip
                if traces:
                    plots[key] = {"title": self.titles[key], "traces": traces}
            f, amp = self.spectrum()
            speed = self.now.get("spindle/speed", math.nan)
            sup = self.supervisor
            mode = int(self.now.get("supervisor/mode", 0))
            return {
                "time_s": self.time_s,
                "chunks": self.chunks,
                "finished": self.finished,
                "plots": plots,
                "spectrum": {"f": f.tolist(), "amp": amp.tolist(),
                             "tooth_hz": _num(self.flutes * speed / 60.0)},
                "trail": {"x": [p[0] for p in self._trail], "y": [p[1] for p in self._trail]},
                "plan": self.plan,
                "alarms": [dict(a) for a in self.alarms],
                "overrides": list(self.overrides),
                "status": {
                    # the shown signals are kept in their display units (%, rev/min)
                    "feed_pct": _num(self.now.get("supervisor/feed_override", math.nan)),
                    "feed_in_effect_pct": _num(self.now.get("cnc/feed_override", math.nan)),
                    "spindle_pct": _num(100 * self.now.get("supervisor/spindle_override",
                                                           math.nan)),
                    "spindle_rpm": _num(speed),
                    "nc_line": _num(self.now.get("plan/nc_line", math.nan)),
                    "mode": MODES[mode] if 0 <= mode < len(MODES) else str(mode),
                    "control": None if sup is None else sup.control,
                },
            }


def _num(v: float) -> float | None:
    return v if math.isfinite(v) else None


def _clean(d: deque[float]) -> list[float | None]:
    return [v if math.isfinite(v) else None for v in d]
