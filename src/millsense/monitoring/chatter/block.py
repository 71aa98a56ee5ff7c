"""The chatter monitor: a streaming block running one chatter criterion on any channel.

Input: one signal channel (compensated spindle torque/current, a compensated feed-drive
force, an accelerometer or microphone), the spindle speed (a channel in rad/s or rev/min, or a
constant), optionally the CNC's NC-line channel. Every ``hop`` samples (0.1 s, seed 000's
update period) the last ``window`` samples of the raw signal and of its comb-filtered version
(:mod:`.comb`) are transformed and judged by the method (:mod:`.methods`).

Outputs, one value per sample, held between decisions: ``{name}/chatter`` (0/1),
``{name}/chatter_hz`` (Hz, NaN without chatter) and ``{name}/energy_ratio`` (the method's
ratio; its threshold is in the event). An ALARM event ``chatter`` (severity WARNING, value
the chatter frequency) is raised when a run of chatter windows starts, a NOTE
``chatter_end`` when it ends. A window in the cut whose mean steps (an entry, an exit, a depth
step) is judged by ``chatter-comb`` on its part after the step when that part resolves the
lines beside the spindle harmonics (decision 1539). A window of ``chatter-comb`` whose ratio
counts and that straddles an entry or an exit without a mean step (one part of it, split at
the change of its harmonic power, out of the cut) is judged on its part in the cut: after an
entry as such a part, after an exit against that part's tooth line (decision 1542). At an entry
(the last window judged whole was out of the cut) a part is judged from two revolutions on,
also in a window the cutting gate takes for air, which still learns as an air window; such a
part needs the speed steady to 0.2 % over the settling time (decision 1543); a part is judged
on its detrended comb row against the background as its own window shows it (decision 1546).
After a speed change the background re-learns for 0.5 s (decision 1537); after a fall of the
cut's load, only the lines it already knew do (decision 1545). At the onset of a run of
chatter windows (not while chatter is flagged) the ``chatter-comb`` line must also stand out of
its own window's searched spectrum (:func:`.methods.line_level`, decision 1658): an observer's
encoder-quantisation lines sit on the spindle harmonics at one speed and spread between them
when the cut sags the speed by 1e-5, so a per-bin background cannot know them; the window's
own upper tail can. During the run's first settling a window in the cut is judged without
the background when its line carries chatter's signature (companions at ω_c ± l·N·Ω, Aslan
Eq. 5.25, not decaying over two windows), and such a window is not learned: chatter present
from the run's start is no longer learned away (decision 1680). At an onset the line must also
be power added to its band (decision 1687); with the spindle encoder's counts per revolution
(``ChatterSettings.encoder_counts_rev``) that test is skipped where the count rate swept
between the window's last two hops and made beyond the band's learned spread elsewhere
(decision 1697).

Chunk-size invariance: decisions fall on fixed absolute samples (``(k + 1) % hop == 0``)
and the per-sample part (rings, comb filter, speed smoothing) is a compiled loop whose state
persists between chunks, so chunks of 1, 7, 100 samples or the whole stream give identical
outputs and events.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from millsense.core.errors import ConfigError
from millsense.core.recording import ChannelInfo
from millsense.monitoring.chatter import _kernels as _kn
from millsense.monitoring.chatter.comb import comb_coefficients, ingest
from millsense.monitoring.chatter.methods import (
    METHODS,
    RUN_LEVEL,
    ChatterMethod,
    Spectra,
    Verdict,
    line_amplitude,
    line_level,
)
from millsense.streaming.block import (
    Block,
    BlockOutput,
    Chunk,
    Event,
    EventKind,
    HeldViews,
    Severity,
    held_views,
)


def _direct_rfft() -> Callable[[np.ndarray], np.ndarray]:
    """scipy.fft's pocketfft binding called as ``scipy.fft.rfft`` calls it, without the
    backend dispatch (≈ 5 µs of ≈ 20 per window); ``scipy.fft.rfft`` itself if this scipy
    lays it out otherwise (checked on a probe vector at import)."""
    try:
        from scipy.fft._pocketfft.pypocketfft import r2c

        def direct(x: np.ndarray) -> np.ndarray:
            return r2c(x, (0,), True, 0, None, 1)

        probe = np.cos(np.arange(16.0))
        if np.array_equal(direct(probe), sfft.rfft(probe)):
            return direct
    except Exception:  # pragma: no cover - another scipy layout
        pass
    return sfft.rfft  # pragma: no cover


#: ``scipy.fft.rfft`` of a contiguous float64 vector (the same numbers, bit for bit).
rfft = _direct_rfft()


def _rows_one_by_one(a: np.ndarray) -> np.ndarray:
    """:data:`rfft` of each row of ``a``."""
    out = np.empty((a.shape[0], a.shape[1] // 2 + 1), dtype=np.complex128)
    for i in range(a.shape[0]):
        out[i] = rfft(a[i])
    return out


def _direct_rfft_rows() -> Callable[[np.ndarray], np.ndarray]:
    """The transforms of the rows of a C-contiguous float64 array in one pocketfft call, which
    runs two rows at a time in the lanes of a vector register (two 4096-point windows ≈ 19 µs
    against 29 in two calls; decision 1536) — used when it gives the rows' single transforms
    bit for bit on probes of the window lengths (each lane does a single transform's
    operations), else the rows one by one."""
    try:
        from scipy.fft._pocketfft.pypocketfft import r2c

        def direct(a: np.ndarray) -> np.ndarray:
            return r2c(a, (1,), True, 0, None, 1)

        rng = np.random.default_rng(0)
        for n in (256, 2048, 4096):
            probe = rng.standard_normal((2, n))
            if not np.array_equal(direct(probe), _rows_one_by_one(probe)):
                return _rows_one_by_one  # pragma: no cover
        return direct
    except Exception:  # pragma: no cover - another scipy layout
        return _rows_one_by_one


#: :data:`rfft` of every row of a C-contiguous float64 array (the same numbers, bit for bit).
rfft_rows = _direct_rfft_rows()

#: Where an event happened on the tool path: (time s, NC line or None) → (NC line, x, y, z mm).
Locator = Callable[[float, int | None], tuple[int | None, float | None, float | None, float | None]]

#: Background learning time constants, s (decision 1504).
BACKGROUND_TAU_S = 2.0
BACKGROUND_TAU_AIR_S = 0.5
BACKGROUND_TAU_NOVEL_S = 30.0
#: A comb component is new when above this many times its background (decision 1504).
NOVELTY_FACTOR = 5.0
#: ... and, while chatter is flagged, above this many times (hysteresis, decision 1504).
NOVELTY_HOLD = 2.0
#: Cutting gate: the tooth-passing line over the raw spectrum's median in the band.
CUTTING_GATE = 3.0
#: Load gate: the window's mean away from the mean learned out of the cut, in air-floor units
#: (the median raw amplitude learned out of the cut; decision 1531).
LOAD_GATE = 10.0
#: Noise allowance of the steady-mean gate, in air-floor units (decision 1531).
STEADY_NOISE = 5.0
#: After a speed change the background learns every bin at the air rate for this long before
#: a verdict: lines bound to the speed (a compensated torque's encoder-quantisation tones) move
#: with it (decision 1537).
SPEED_SETTLE_S = 0.5
#: ... once the speed moved by more than this fraction since the last judged window (an
#: override step of 1 % moves every such line; a cut's speed wanders by about 1e-4).
SETTLE_SPEED = 0.002
#: After the cut's load falls (a depth step down, a narrower cut), for the next
#: :data:`SPEED_SETTLE_S` the lines that already stood :data:`KNOWN_LINE` times above the
#: background's median (widened by ±:data:`KNOWN_LINE_BINS` bins: a line between two bins of the
#: rectangular comb spectrum, and the speed's wander) re-learn at
#: the air rate and are not new; lines that were not there stay new (decision 1545).
KNOWN_LINE = 3.0
KNOWN_LINE_BINS = 2
#: Largest relative spread of the spindle speed over a window for a decision.
STEADY_SPEED = 0.02
#: Largest change of the mean between the halves of a window, in tooth-line amplitudes.
STEADY_MEAN = 0.5
#: A window's part after its mean step is judged when ``f_s / L`` (its rectangular
#: resolution) is at most this many times the half-width of the band not searched around each
#: spindle harmonic (Rayleigh's criterion: a line at the band's edge is resolved from the
#: harmonic; decision 1539).
SEGMENT_RESOLUTION = 1.0
#: A companion of a chatter line at ω_c ± l·N·Ω (decision 1680) carries at least this share of
#: the line's amplitude (the tooth angles modulate the line itself: 8-37 % in the simulated
#: slot's accelerometer; the comb's ring-down of a harmonic beside a tone, a few 0.1 %).
COMPANION_SHARE = 0.05
#: A chatter line found by its signature at the run's start must not be decaying (decision
#: 1680): at its onset its amplitude is at least this share of the same line (±2 bins) in the
#: previous window. Chatter grows or holds its limit cycle (±30 % from window to window in the
#: simulated slot); the free vibration after a stable cut's entry decays (÷2-3 per 0.1 s).
NOT_DECAYING = 0.7
#: Calibration of the threshold method: first seconds of the run, factor on their maximum.
CALIBRATION_S = 1.0
CALIBRATION_FACTOR = 2.0


@dataclass(frozen=True)
class ChatterSettings:
    """Settings of a :class:`ChatterMonitor`.

    Attributes
    ----------
    method : ``chatter-comb``, ``chatter-sdft`` or ``chatter-threshold``.
    signal : channel analysed.
    n_flutes : teeth of the tool (tooth-passing frequency = flutes × spindle frequency).
    speed_channel : spindle-speed channel, or None for ``speed_rpm``.
    speed_unit : unit of ``speed_channel``: ``rad/s`` or ``rev/min``.
    speed_rpm : constant spindle speed when there is no speed channel, rev/min.
    nc_line_channel : the CNC's NC-line channel, or None.
    band_hz : frequencies searched for chatter (the upper one is limited to 0.45·f_s).
    hop_s : time between decisions, s (0.1 s, seed 000).
    threshold : the method's threshold (None: the seed's; calibrated for the threshold
        method).
    min_speed_rpm : below this the spindle counts as stopped (no decision), rev/min.
    encoder_counts_rev : counts per revolution of the spindle drive's encoder (the machine
        file's ``[spindle] encoder_counts_rev``), or None (not known). With it, a window whose
        count rate changed between its last two hops by more than the spindle frequency is no
        window a line of the drive's encoder quantisation can stand in, and a new
        ``chatter-comb`` line there skips decision 1687's power test, and elsewhere it must
        pass the test's midpoint by the band's learned spread (decision 1697). None keeps
        decision 1687's test at its midpoint in every window.
    """

    method: str = "chatter-comb"
    signal: str = "spindle/torque_est"
    n_flutes: int = 2
    speed_channel: str | None = "spindle/speed"
    speed_unit: str = "rad/s"
    speed_rpm: float | None = None
    nc_line_channel: str | None = None
    band_hz: tuple[float, float] = (50.0, 5000.0)
    hop_s: float = 0.1
    threshold: float | None = None
    min_speed_rpm: float = 300.0
    encoder_counts_rev: float | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ConfigError(
                f"chatter monitor: unknown method {self.method!r} (known: {', '.join(METHODS)})"
            )
        if self.n_flutes < 1:
            raise ConfigError(f"chatter monitor: flutes must be ≥ 1, got {self.n_flutes}")
        if self.speed_channel is None and not (self.speed_rpm and self.speed_rpm > 0):
            raise ConfigError(
                "chatter monitor: give a spindle-speed channel or a speed > 0 rev/min"
            )
        if self.speed_unit not in ("rad/s", "rev/min"):
            raise ConfigError(f"chatter monitor: speed unit {self.speed_unit!r} (rad/s, rev/min)")
        lo, hi = self.band_hz
        if not 0 <= lo < hi:
            raise ConfigError(f"chatter monitor: band {self.band_hz} Hz must be 0 ≤ low < high")
        if not self.hop_s > 0:
            raise ConfigError(f"chatter monitor: hop {self.hop_s} s must be > 0")
        if self.encoder_counts_rev is not None and not self.encoder_counts_rev >= 1:
            raise ConfigError(
                f"chatter monitor: encoder counts {self.encoder_counts_rev} per rev must be ≥ 1"
            )


class _Stage:
    """The per-sample part shared by monitors reading one signal: rings of the raw and the
    comb-filtered signal, the speed statistics of the current hop, the samples written."""

    def __init__(self, size: int) -> None:
        self.ring_x = np.zeros(size)
        self.ring_y = np.zeros(size)
        self.state = np.array([0.0, 0.0, 0.0, np.inf, 0.0])
        self.pos = 0
        self.lows: list[float] = []  # smallest and largest smoothed speed of each hop
        self.highs: list[float] = []
        self.means: list[float] = []  # mean speed of each hop, rev/s (decision 1697)
        self.f_rev = 0.0

    def close_hop(self, keep: int) -> None:
        """At a decision sample: mean speed of the hop, its range kept (``keep`` hops)."""
        st = self.state
        _, total, count, low, high = st.tolist()  # Python floats: the same IEEE division
        self.f_rev = total / count if count > 0 else 0.0
        self.lows.append(low)
        self.highs.append(high)
        self.means.append(self.f_rev)
        del self.lows[:-keep], self.highs[:-keep], self.means[:-keep]
        st[1] = st[2] = st[4] = 0.0
        st[3] = np.inf


class ChatterMonitor(Block):
    """Streaming chatter detection by one criterion (see the module notes).

    Parameters
    ----------
    settings : what to read and which criterion.
    locate : maps (time, NC line) to the NC line and tool-tip position on the path (from the
        virtual plan), or None.
    name : block name (default: the method's name); prefixes the output channels.
    """

    def __init__(
        self, settings: ChatterSettings, locate: Locator | None = None, name: str | None = None
    ) -> None:
        self.settings = s = settings
        self.method: ChatterMethod = METHODS[s.method]
        if s.threshold is not None:
            from dataclasses import replace

            self.method = replace(self.method, threshold=float(s.threshold))
        self.name = name or s.method
        self.locate = locate
        ins = [s.signal]
        if s.speed_channel is not None:
            ins.append(s.speed_channel)
        if s.nc_line_channel is not None:
            ins.append(s.nc_line_channel)
        self.inputs = tuple(ins)
        self._alpha, self._beta = comb_coefficients()
        self._fs = 0.0

    # ------------------------------------------------------------------ contract
    def output_channels(self) -> list[ChannelInfo]:
        m = self.method
        return [
            ChannelInfo(f"{self.name}/chatter", "1", f"1 while chatter ({m.seed} {m.name})"),
            ChannelInfo(f"{self.name}/chatter_hz", "Hz", "chatter frequency (NaN: none)"),
            ChannelInfo(
                f"{self.name}/energy_ratio", "1", f"{m.name} ratio (chatter above the threshold)"
            ),
        ]

    def reset(self, sample_rate_hz: float) -> None:
        s = self.settings
        fs = self._fs = float(sample_rate_hz)
        self._hop = max(1, round(s.hop_s * fs))
        n = self.method.window
        d_max = fs * 60.0 / s.min_speed_rpm
        self._size = 1 << math.ceil(math.log2(max(n, d_max + 8)))
        self._stage = _Stage(self._size)
        self._smooth = 1.0 - math.exp(-1.0 / (0.01 * fs))  # 10 ms speed smoothing
        # the raw spectrum (tooth-passing line, threshold method) is Hann-tapered (−1.4 dB
        # scalloping at most); the comb-filtered one is rectangular as Eq. 5.30 and the SDFT:
        # it holds no strong harmonics to leak, and the newest samples keep full weight, which
        # is what the detection latency depends on (decision 1502)
        self._taper = np.hanning(n)
        self._scale = 2.0 / float(np.sum(self._taper))
        self._comb_taper = np.hanning(n) if self.method.taper == "hann" else np.ones(n)
        self._comb_scale = 2.0 / float(np.sum(self._comb_taper))
        # the comb row's taper as :func:`._kernels.decision_windows` applies it (empty: none)
        self._comb_row_taper = self._comb_taper if self.method.taper != "rect" else np.empty(0)
        self._no_mask = np.zeros(0, dtype=bool)
        f = np.asarray(np.fft.rfftfreq(n, 1.0 / fs), dtype=np.float64)
        self._f: np.ndarray = f
        lo, hi = s.band_hz
        self._band = (f >= lo) & (f <= min(hi, 0.45 * fs))
        nz = np.flatnonzero(self._band)
        self._band_slice = (int(nz[0]), int(nz[-1]) + 1) if len(nz) else (0, 0)
        # work arrays of the decision (nothing keeps them beyond it)
        self._xr = np.empty(n)
        # rows: the tapered raw window and (criteria that learn) the comb-filtered window,
        # transformed together (:data:`rfft_rows`)
        self._windows = np.empty((2 if self.method.learns_background else 1, n))
        # a window's part after its mean step, raw and comb-filtered (decision 1539)
        self._seg_windows = np.empty((2, n if self.method.judges_segments else 0))
        nf = len(f)
        self._raw, self._comb, self._novel, self._raw_rect = (np.empty(nf) for _ in range(4))
        # a part's amplitudes: apart from the full window's, which an air window with an entry
        # still learns from after its part is judged (decision 1543)
        self._part = tuple(np.empty(nf if self.method.judges_segments else 0) for _ in range(3))
        self._background = np.zeros(nf)
        self._has_background = False
        # the band's power learned as the background (Σ comb² off the harmonics; decision 1687)
        self._band_power = 0.0
        self._window_power = 0.0  # the last full window's (decision 1687)
        # the mean square of the band's power less the learned power (decision 1697) and
        # whether the test reads it: only where the encoder's resolution tells the windows a
        # quantisation line can stand in from those it cannot
        self._band_var = 0.0
        self._knows_counts = s.encoder_counts_rev is not None
        self._tests_power = self.method.name == "chatter-comb"  # the criterion that reads it
        self._rates = (self._learning_rates(False), self._learning_rates(True))
        self._judged_f_rev = 0.0  # spindle frequency of the last window that reached novelty
        self._level = 0.0  # mean of the last window decided
        self._settle_windows = max(1, round(SPEED_SETTLE_S / s.hop_s))
        self._settling = 0
        self._start_settling = False  # the settling is the run's start's (decision 1680)
        self._comb_at = -1  # the stage position of the window whose comb amplitudes
        # ``self._comb`` holds (decision 1680)
        # the cut's load (the mean away from the air mean) that a fall is measured from, and
        # the windows left re-learning the lines known before a fall (decision 1545)
        self._load_ref: float | None = None
        self._drop_settling = 0
        self._known = np.zeros(len(f), dtype=bool)
        self._air = np.zeros(_kn.AIR_SIZE)
        self._air_before = np.zeros(_kn.AIR_SIZE)  # the gate's state before this window's
        # the last window judged whole was out of the cut (or straddled an entry): a step now is
        # an entry (decision 1543)
        self._out_of_cut = True
        self._gate = np.array([CUTTING_GATE, LOAD_GATE, STEADY_SPEED, STEADY_MEAN, STEADY_NOISE,
                               min(1.0, s.hop_s / BACKGROUND_TAU_AIR_S)])  # fmt: skip
        self._flag = 0.0
        self._freq = math.nan
        self._ratio = 0.0
        # windows decided, and among them judged as a cut (the cutting gate open; every one
        # for the threshold criterion, which has no gate): a summary that reads "no alarm"
        # says how much it saw (decision 1689)
        self.windows_decided = 0
        self.windows_judged = 0
        self._run_start: float | None = None  # time of the first window of a rising run
        self._calib: list[float] = []
        self._calibrated: float | None = None
        if s.speed_channel is None:
            self._const_speed = abs(float(s.speed_rpm or 0.0)) / 60.0
        self._speed_factor = 1.0 / (2 * math.pi) if s.speed_unit == "rad/s" else 1.0 / 60.0
        self._min_rev_s = s.min_speed_rpm / 60.0
        # hops of speed ranges kept: a window's, and the settling time (decision 1543)
        self._window_hops = n // self._hop + 2  # the hops whose speed ranges a window spans
        self._keep_hops = max(self._window_hops, self._settle_windows)
        self._ch_flag = f"{self.name}/chatter"
        self._ch_hz = f"{self.name}/chatter_hz"
        self._ch_ratio = f"{self.name}/energy_ratio"
        self._mask_f_rev = -1.0
        self._harm_mask = np.zeros(len(f), dtype=bool)
        self._df = float(f[1])
        self._merged: HeldViews | None = None
        self._keep = self._keep_hops
        self._out_names = (self._ch_flag, self._ch_hz, self._ch_ratio)

    def process(self, chunk: Chunk) -> BlockOutput:
        return _run_chunk([self], chunk, self)

    # ------------------------------------------------------------------ decision
    def _ingest(self, x: np.ndarray, spd: np.ndarray, factor: float = 1.0) -> None:
        g = self._stage
        ingest(x, spd, self._fs, self._alpha, self._beta, g.ring_x, g.ring_y, g.pos, g.state,
               self._min_rev_s, self._smooth, factor)  # fmt: skip
        g.pos += len(x)

    def _spectra(self) -> Spectra | None:
        """The spectra of the window ending at the last decision sample, or None when no
        decision is taken (too few samples, the speed or, for the learning criteria, the mean
        moving within the window: entry, exit, a large depth step — unless the criterion
        judges the part after the step, :meth:`_segment_spectra`). The cutting gate, the
        novelty and the largest novel bin are compiled (:func:`._kernels.cutting_gate`,
        :func:`._kernels.novel_peak`; decisions 1504, 1531, 1536)."""
        g = self._stage
        f_rev = g.f_rev
        n = self.method.window
        if g.pos < n:
            return None
        w = self._window_hops
        if not max(g.highs[-w:]) <= (1.0 + STEADY_SPEED) * min(g.lows[-w:]):
            return None  # speed changing within the window: no decision (decision 1504)
        xr, raw, windows = self._xr, self._raw, self._windows
        # the raw window and (criteria that learn) the comb-filtered one, in one call
        level, half_step = _kn.decision_windows(g.ring_x, g.ring_y, g.pos, self._taper,
                                                self._comb_row_taper, xr, windows)  # fmt: skip
        self._level = level
        learns = self.method.learns_background
        if learns:  # the comb-filtered window, transformed with the raw one
            spectra = rfft_rows(windows)
            c_raw = spectra[0]
        else:
            c_raw = rfft(windows[0])
        f_t = self.settings.n_flutes * f_rev
        b0, b1 = self._band_slice
        air_before = self._air_before  # the gate's state before this window (1543, 1680)
        # with the tooth line's bins k0:k1 (:func:`._kernels.tooth_bins`)
        cutting, steady, tooth, tooth_ref, k0, k1 = _kn.cutting_gate(
            c_raw, self._scale, f_t, self._df, self.settings.min_speed_rpm, b0, b1, raw, level,
            half_step, f_rev, self._air, self._gate, air_before,
        )  # fmt: skip
        f = self._f
        if not learns:  # the threshold method reads the raw spectrum
            return Spectra(f, raw, raw, self._band, tooth, f_t, f_rev, cutting, raw,
                           band_slice=(b0, b1))  # fmt: skip
        if cutting and not steady:
            if not self._has_background or (self._start_settling and self._settling > 0):
                # the run's start: a window whose mean the chatter itself moves (an
                # accelerometer's limit cycle) is judged by chatter's signature (decision 1680)
                self._update_harm_mask(f_rev)
                at_start = self._unlearned_spectra(
                    spectra, f_t, f_rev, b0, b1, tooth, air_before, level
                )
                if at_start is not None:
                    return at_start[0]
            # entry, exit or a large step inside the window: the part after the step, if it
            # resolves the lines (decision 1539; at an entry down to two revolutions, decision
            # 1543), else no decision
            return self._segment_spectra(f_rev, f_t, k0, k1, b0, b1, level)
        air_part: Spectra | None = None
        if (
            not cutting
            and self._out_of_cut
            and self.method.judges_segments
            and air_before[_kn.HAS_FLOOR] > 0.0
            and abs(half_step) > max(STEADY_MEAN * tooth, STEADY_NOISE * air_before[_kn.AIR_FLOOR])
        ):
            # a window taken for air whose mean steps: an entry whose part in the cut is too
            # short to lift the whole window's tooth line or mean over the gate; its part after
            # the step is judged, the window learns as the air window it was taken for
            # (decision 1543)
            air_part = self._segment_spectra(f_rev, f_t, k0, k1, b0, b1, level, None, air_before)
        self._out_of_cut = not cutting
        self._update_harm_mask(f_rev)
        # hysteresis: while chatter is flagged a component stays new above 2 × its background
        factor = NOVELTY_HOLD if self._flag else NOVELTY_FACTOR
        comb, novel = self._comb, self._novel
        last = self._judged_f_rev
        if not self._has_background or abs(f_rev - last) > SETTLE_SPEED * last:
            self._settling = self._settle_windows  # a new speed: its lines are learned first
            # the run's start (no background yet), not a speed change (decision 1680)
            self._start_settling = not self._has_background
        self._judged_f_rev = f_rev
        if (
            self._start_settling
            and self._settling > 0
            and air_part is None
            and tooth > 0.0
            and cutting
        ):
            # the run's first windows in the cut: chatter the background and the air reference
            # have not seen is judged by its own signature and kept out of both (decision 1680;
            # a window taken for air is not: on a compensated torque in air, lines with
            # companions at ±f_tooth alarmed)
            at_start = self._unlearned_spectra(
                spectra, f_t, f_rev, b0, b1, tooth, air_before, level
            )
            if at_start is not None:
                return at_start[0]
        if self._flag and self._settling > 0:
            # the run's first chatter ended (or a settling after a speed change began): the
            # start is over, the rest of the settling learns as any (an exit's ring-down)
            self._start_settling = False
        settling = self._settling > 0
        rates = self._rates[False] if settling else self._rates[cutting]
        mask = self._harm_mask
        if settling or not cutting:
            self._load_ref, self._drop_settling = None, 0
        elif self._load_fell(level, tooth, b0, b1) or self._drop_settling > 0:
            # the lines known before the load fell re-learn at the air rate (decision 1545)
            self._drop_settling -= 1
            mask = mask | self._known
            rates = (self._rates[False][0], rates[1])
        first = not self._has_background
        # with the band's power off the harmonics for the criterion that reads it
        power_mask = self._harm_mask if self._tests_power else self._no_mask
        k, power = _kn.novel_peak(spectra[1], self._comb_scale, comb, self._background, first,
                                  factor, mask, novel, b0, b1, *rates, power_mask)  # fmt: skip
        excess: float | None = None
        noise = 0.0
        sweeps = self._count_rate_sweeps()
        if self._tests_power:
            # the band's power against the power learned at the background's plain rate
            # (decision 1687: a line that grows faster than e-fold in 2 τ is power added), and
            # the spread of that difference learned at the same rate from the windows in which
            # nothing is new and the count rate held (the null hypothesis's spread, decision
            # 1697)
            excess = power - self._band_power
            noise = math.sqrt(self._band_var) if self._knows_counts else 0.0
            self._window_power = power
            self._band_power = power if first else self._band_power + rates[0] * excess
            if not (first or sweeps or (b0 <= k < b1 and novel[k] > 0.0)):
                self._band_var += rates[0] * (excess * excess - self._band_var)
        self._comb_at = g.pos  # the window whose comb amplitudes ``comb`` holds (1680)
        self._has_background = True
        if settling:
            self._settling -= 1
            cutting = False  # no verdict while the background learns the new speed
        if air_part is not None:
            return air_part
        if (
            self.method.judges_segments
            and cutting
            and b0 <= k < b1
            and novel[k] > 0.0
            and line_amplitude(comb, k, 1.0, mask)
            > RUN_LEVEL * (self.method.threshold or 0.0) * tooth_ref
        ):
            # a ratio that counts (a rising run, a verdict) on a window straddling an entry or
            # an exit: read on the part in the cut (decision 1542)
            part = self._straddle(f_t, f_rev, level)
            if part is not None:
                start, entry, line = part
                if entry:
                    self._out_of_cut = True  # the tool entered within this window (1543)
                m = len(xr) - start if entry else start
                if m * f_rev < 2.0 * self._fs:
                    return None  # the part in the cut does not resolve its tooth line
                if entry:
                    return self._segment_spectra(f_rev, f_t, k0, k1, b0, b1, level, start)
                tooth_ref = max(tooth_ref, line)
        raw_rect = None
        if (
            self.method.name == "chatter-sdft"
            and self.method.taper == "rect"
            and cutting
            and b0 <= k < b1
            and novel[k] > 0.0
            and tooth_ref > 0.0
        ):
            # Parseval needs the raw spectrum with the comb's (rectangular) taper: computed only
            # for a window the criterion judges by its variances (:meth:`ChatterMethod.decide`)
            raw_rect = self._raw_rect
            _kn.amplitude(rfft(xr), 2.0 / n, raw_rect)
        return Spectra(f, raw, comb, self._band, tooth_ref, f_t, f_rev, cutting, novel, raw_rect,
                       band_slice=(b0, b1), peak_bin=k, masked=mask,
                       held=bool(self._flag), band_excess=excess, band_noise=noise,
                       sweeps=sweeps)  # fmt: skip

    def _not_learned(self, air: np.ndarray, sp: Spectra | None) -> tuple[Spectra | None]:
        """A run-start window kept out of what the run learns (decision 1680): the air
        reference as it was before it, the window counted in the cut; its spectra to judge
        (None: no verdict) in a 1-tuple."""
        self._air[:] = air
        self._out_of_cut = False
        return (sp,)

    def _unlearned_spectra(
        self,
        spectra: np.ndarray,
        f_t: float,
        f_rev: float,
        b0: int,
        b1: int,
        tooth: float,
        air: np.ndarray,
        level: float,
    ) -> tuple[Spectra | None] | None:
        """The spectra of a window during the run's first settling (decision 1680), judged
        without the learned background when its comb-filtered spectrum carries chatter's
        signature: in a 1-tuple, those spectra (a verdict, the window not learned) or None
        (the signature seen on this window only: no verdict, not learned); or None (the window
        learns and settles as any other). Called for a window in the cut (also one whose mean
        steps: chatter's limit cycle moves an accelerometer's mean).

        The background a run starts from is its first window's spectrum, learned for 0.5 s
        without a verdict (decision 1537). When the cut starts before the speed has been
        steady over a window (no air at speed, a record that starts in the cut), chatter
        present then or starting within the settling was learned into it and never judged:
        the ratio stayed 0. A steady tone there is not chatter (decision 1537) and a per-bin
        background cannot tell the two apart; the physics can. The cutting force is the
        vibration modulated by the tooth angles, so a chatter line at ω_c comes with lines at
        ω_c ± l·N·Ω (Aslan Eq. 5.25; decision 1501), and a regenerative vibration grows or
        holds its limit cycle where a stable cut's free vibration after its entry decays.

        The line judged is the window's largest comb line new to what the run learned so far
        (above 5 × the background if there is one, 2 × while chatter is flagged). It is chatter
        when the method's verdict on it is (the seed's ratio over the tooth line, the
        reference no less than 3 × the floor, Eq. 5.30; decision 1658's stand-out test) and:
        a companion at ±f_tooth or ±2 f_tooth (the largest of the nearest bin and its
        neighbours, not on a spindle harmonic) stands above the level Rayleigh noise reaches
        over the band with a chance of 1e-3 from the band's median (:func:`.methods.line_level`
        at the median) and carries :data:`COMPANION_SHARE` of the line (the comb's ring-down
        of a harmonic beside a steady tone does not); a window straddling an entry or an exit
        is read against its part's tooth line (decision 1542, as after an exit); the line is
        not below :data:`NOT_DECAYING` × its amplitude (±2 bins) in the previous window, and
        was seen there (two windows: 0.1 s). While
        chatter is flagged the line's hold suffices (as after the settling). The novelty the
        method reads is then the line and its companions. A window with chatter is not learned
        (neither the background nor the air floor and mean), so the settling resumes with the
        first window without it; once that first chatter has ended the start is over and the
        rest of the settling learns as any settling does."""
        comb, novel, raw = self._comb, self._novel, self._raw
        pos = self._stage.pos
        had_prev = self._comb_at == pos - self._hop  # the previous window's amplitudes
        prev = comb.copy()
        _kn.amplitude(spectra[1], self._comb_scale, comb)
        self._comb_at = pos
        mask = self._harm_mask
        if self._has_background:  # what the windows before it learned is not new
            factor = NOVELTY_HOLD if self._flag else NOVELTY_FACTOR
            _kn.novelty(comb, self._background, factor, mask, novel)
        else:
            _kn.novelty(comb, np.zeros_like(comb), 1.0, mask, novel)
        k = _kn.band_argmax(novel, b0, b1)
        if not (b0 <= k < b1 and novel[k] > 0.0):
            return None
        decaying = had_prev and comb[k] < NOT_DECAYING * float(np.max(prev[max(k - 2, 0) : k + 3]))
        if decaying and not self._flag:
            return None  # a stable cut's transient (decision 1680)
        # the ratio's reference as in the cut (decision 1531): the tooth line, no less than
        # 3 × the floor (the band median, or the smaller floor learned out of the cut)
        floor = float(np.median(raw[b0:b1]))
        if air[_kn.HAS_FLOOR] > 0.0:
            floor = min(floor, float(air[_kn.AIR_FLOOR]))
        tooth_ref = max(tooth, CUTTING_GATE * floor)
        df = self._df
        f_c = float(self._f[k])
        noise = line_level(comb, mask, b0, b1, 1.0, k, quantile=0.5)
        family = [k]
        for ell in (1, 2):
            for f in (f_c - ell * f_t, f_c + ell * f_t):
                j = round(f / df)
                lo, hi = max(j - 1, b0), min(j + 2, b1)
                if hi <= lo:
                    continue
                j = lo + int(np.argmax(np.where(mask[lo:hi], -1.0, comb[lo:hi])))
                if not mask[j] and comb[j] > max(noise, COMPANION_SHARE * comb[k]):
                    family.append(j)
        if len(family) == 1 and not self._flag:
            return None  # no companion (while flagged the line's hold suffices)
        part = self._straddle(f_t, f_rev, level)
        if part is not None:
            # an entry or an exit within the window (decision 1542): the reference is the tooth
            # line of its part in the cut, as after an exit, not the Hann-weighted line of a
            # window partly in air beside which the comb's ring-down reads as chatter
            tooth_ref = max(tooth_ref, part[2])
        keep = novel[family].copy()
        novel.fill(-1.0)
        novel[family] = keep
        raw_rect = None
        if self.method.name == "chatter-sdft" and self.method.taper == "rect":
            raw_rect = self._raw_rect
            _kn.amplitude(rfft(self._xr), 2.0 / len(self._xr), raw_rect)
        sp = Spectra(self._f, self._raw, comb, self._band, tooth_ref, f_t, f_rev, True, novel,
                     raw_rect, band_slice=(b0, b1), peak_bin=k, masked=mask,
                     held=bool(self._flag))  # fmt: skip
        if not self.method.decide(sp, None).chatter:
            return None
        if not (had_prev or self._flag):
            # chatter's signature seen once: neither judged nor learned yet
            return self._not_learned(air, None)
        return self._not_learned(air, sp)

    def _straddle(self, f_t: float, f_rev: float, level: float) -> tuple[int, bool, float] | None:
        """Whether the full window just decided straddles an entry or an exit (decision
        1542): if so (the first sample of the part after the change, whether that part is the
        one in the cut: an entry, the tooth line of the part in the cut), else None.

        At an entry or exit without a mean step (an accelerometer, a microphone) the window
        passes the steady-mean gate. Its comb-filtered spectrum (rectangular, Eq. 5.30) holds
        the comb's ring-down of the harmonics switched on or off (Eq. 5.27: β·α^j in
        revolution j, a Lorentzian of half-width f_rev/20, the band not searched) at full
        weight, while the Hann-tapered tooth line sees the part in the cut at the taper's low
        end: its reference shrinks (a window with 700 of 4096 samples in the cut: 3 % of the
        line), and the ring-down reads as chatter. The window's ratio is therefore read on
        its part in the cut: at an entry that part is judged as decision 1539's part after a
        step (:meth:`_segment_spectra`); after an exit the comb spectrum is the window's and
        the reference the part's tooth line (never less than the window's own). The part must
        hold two revolutions (its Hann main lobe, ±2 f_s/L, within the spindle frequency of
        the tooth line: resolved from the neighbouring harmonics), else no verdict.

        The window is split at the change point of its harmonic part's power
        (:func:`._kernels.power_step_start`); each part's tooth line is taken under a Hann
        taper of its own length at the tooth-passing frequency
        (:func:`._kernels.line_amplitude`) and is in the cut when above the cutting gate (3 ×
        the floor learned out of the cut, × √(n/L) for the part's noise, as decision 1539). A
        window loaded by its mean (the cutting gate's other test) is in the cut in both parts,
        its mean being steady. The window straddles when one part is in the cut and the other
        not. (A part whose line lies near its gate, a weak tooth line, may be classed either
        way; the comb's reference then is the larger of two measurements of the same line.)

        Work: only for a window whose ratio passes :data:`RUN_LEVEL` × the threshold (a rising
        run or a verdict), compiled: the change point (two passes over the window), the two
        parts' lines (one pass); none for the others."""
        air = self._air
        if not air[_kn.HAS_FLOOR] > 0.0 or not f_rev > 0.0 or _loaded(level, f_rev, air, 1.0):
            return None
        g = self._stage
        xr = self._xr
        n = len(xr)
        start = _kn.power_step_start(xr, g.ring_y, g.pos)
        cycles = f_t / self._fs
        before = _kn.line_amplitude(xr, 0, start, cycles)
        after = _kn.line_amplitude(xr, start, n, cycles)
        floor = CUTTING_GATE * air[_kn.AIR_FLOOR]
        cut_before = before > floor * math.sqrt(n / start)
        cut_after = after > floor * math.sqrt(n / (n - start))
        if cut_before == cut_after:
            return None  # both parts in the cut (a depth step, chatter) or neither
        return start, cut_after, after if cut_after else before

    def _cut_load(self, level: float) -> float:
        """The window's load: its mean away from the mean learned out of the cut (or from 0
        before there is one)."""
        air = self._air
        return abs(level - air[_kn.AIR_MEAN]) if air[_kn.HAS_MEAN] > 0.0 else abs(level)

    def _load_fell(self, level: float, tooth: float, b0: int, b1: int) -> bool:
        """Whether the load of this steady window in the cut fell below the reference by more
        than the steady-mean gate allows within a window (``STEADY_MEAN`` tooth lines or
        ``STEADY_NOISE`` air floors); if so the lines the background knows (:data:`KNOWN_LINE`
        × its median in the band, widened by :data:`KNOWN_LINE_BINS`) are kept in
        ``self._known`` and re-learned for :data:`SPEED_SETTLE_S` (decision 1545). Not while a
        chatter is flagged or a rising run is open: a line that is new already stays watched.
        The reference follows the load up at once and down only at a detected fall, so that a
        slow decrease counts once it adds up."""
        load = self._cut_load(level)
        ref = self._load_ref
        if ref is None or load >= ref:
            self._load_ref = load
            return False
        tol = max(STEADY_MEAN * tooth, STEADY_NOISE * self._air[_kn.AIR_FLOOR])
        if ref - load <= tol or self._flag or self._run_start is not None:
            return False
        self._load_ref = load
        bg = self._background
        line = bg >= KNOWN_LINE * float(np.median(bg[b0:b1]))
        known = self._known
        known[:] = line
        for d in range(1, KNOWN_LINE_BINS + 1):
            known[d:] |= line[:-d]
            known[:-d] |= line[d:]
        self._drop_settling = self._settle_windows
        return True

    def _update_harm_mask(self, f_rev: float) -> None:
        """Chatter is never on a spindle harmonic (that is forced vibration): bins within the
        comb's notch half-width ``f_rev / 20`` or 2 bins of one are not searched."""
        if f_rev > 0 and abs(f_rev - self._mask_f_rev) > 1e-6 * f_rev:
            self._harm_mask = self._near_harmonics(f_rev, self._mask_half_width(f_rev))
            self._mask_f_rev = f_rev

    def _near_harmonics(self, f_rev: float, half_width: float) -> np.ndarray:
        """A new mask of the bins within ``half_width`` Hz of a spindle harmonic (compiled:
        :func:`._kernels.near_harmonics`)."""
        out = np.empty(self._f.shape[0], dtype=np.bool_)
        _kn.near_harmonics(self._f, float(f_rev), float(half_width), out)
        return out

    def _mask_half_width(self, f_rev: float) -> float:
        """Half-width of the band around each spindle harmonic that is not searched, Hz."""
        return max(2.0 * self._df, 0.5 * f_rev / 10.0)

    def _segment_spectra(
        self,
        f_rev: float,
        f_t: float,
        k0: int,
        k1: int,
        b0: int,
        b1: int,
        level: float,
        start: int | None = None,
        air: np.ndarray | None = None,
    ) -> Spectra | None:
        """The spectra of the part of the window after its mean step (entry, exit, a depth
        step), for a window in the cut that fails the steady-mean gate (decision 1539).

        The step is the window's single change point of the mean (:func:`._kernels.step_start`).
        The segment from it to the window's end is judged when it resolves a line at the edge
        of the harmonic exclusion band from the harmonic (Rayleigh: ``f_s / L`` no wider than
        the band's half-width ``max(2 Δf, f_rev / 20)``, :data:`SEGMENT_RESOLUTION`), is itself
        in the cut and steady. Its raw (Hann) and comb-filtered (rectangular) spectra are
        zero-padded to the window's bins and scaled by the segment's own taper sums, so a line
        has the amplitude a full window gives it (the tooth line, the chatter line and their
        ratio are the seed's, Eq. 5.30); the noise per bin is ``g = √(n / L)`` times a full
        window's, so the learned floor, the load span and the background are taken ``g`` times
        higher (a segment cannot turn the floor into a new line; a real line must stand
        ``5 g`` times above its background). Nothing is learned from a segment: the background,
        the air floor and mean and the speed state stay those of the full windows.

        With ``start`` (decision 1542) the part from ``start`` is the in-cut part of a window
        straddling an entry without a mean step (:meth:`_straddle`, two revolutions at least).
        A part shorter than the length above is judged with the band not searched around each
        harmonic widened to ``f_s / L`` (Rayleigh at the part's own resolution: a line that
        far from a harmonic is resolved from it, and the comb's ring-down of the harmonic,
        a Lorentzian of half-width f_rev/20, reads there at most β/(2π) ≈ 0.14 of it).

        Decision 1543: such a short part (two revolutions at least) is judged after a mean step
        too when the step is an entry, i.e. the last window judged whole was out of the cut (a
        step inside the cut, a depth step, keeps the length above). With ``air`` (the cutting
        gate's state before the window) the window was taken for air although its mean steps:
        an entry whose part in the cut is too short to lift the whole window's tooth line or
        mean over the gate; the part's gate reads that state. A short part and a part of an air
        window are judged only while the smoothed speed has stayed within
        :data:`SETTLE_SPEED` over the settling time (:data:`SPEED_SETTLE_S`, decision 1537): a
        ramp that starts in the window moves the speed-bound lines and the acceleration torque
        steps the mean, and the 2 % window speed gate lets its first 0.03 s through. The part's
        amplitudes go to arrays of their own, so an air window still learns as one.

        Work per such window: one pass for the step, one for the tapers, the pair of
        transforms, the amplitudes and median, the novelty and its largest bin (the full
        window's steps again, compiled); windows passing the mean gate do none of it."""
        if not self.method.judges_segments:
            return None
        g = self._stage
        n = self.method.window
        if self._settling > 0 or not self._has_background or not f_rev > 0:
            return None
        last = self._judged_f_rev
        if abs(f_rev - last) > SETTLE_SPEED * last:
            return None  # a new speed: its lines are learned on full windows first
        straddle = start is not None
        if start is None:
            start = _kn.step_start(self._xr)
        m = n - start
        short = m * SEGMENT_RESOLUTION * self._mask_half_width(f_rev) < self._fs
        if m * f_rev < 2.0 * self._fs or (short and not (straddle or self._out_of_cut)):
            return None  # too short to resolve its tooth line, or (a step in the cut) the lines
            # beside the harmonics
        if (short or air is not None) and not straddle:
            w = self._settle_windows
            if not max(g.highs[-w:]) <= (1.0 + SETTLE_SPEED) * min(g.lows[-w:]):
                return None  # the speed moved within the settling time: its lines move too
        seg = self._seg_windows
        mean, half_step, w_sum, c_sum = _kn.segment_windows(
            self._xr, g.ring_y, g.pos, start, self.method.taper != "rect", seg
        )
        if self.method.taper == "rect":
            _detrend(seg[1, :m])  # the comb's ring-down of the step (decision 1546)
        spectra = rfft_rows(seg)
        raw, comb, novel = self._part
        grow = math.sqrt(n / m)
        tooth, med = _kn.amplitude_line_median(spectra[0], 2.0 / w_sum, k0, k1, b0, b1, raw)
        air = self._air if air is None else air
        gate = _segment_gate(tooth, med, level + mean, half_step, f_rev, air, grow)
        if gate is None:
            return None  # the segment is out of the cut (an exit) or not steady either
        self._update_harm_mask(f_rev)
        mask = self._harm_mask
        if self._load_fell(level + mean, tooth, b0, b1) or self._drop_settling > 0:
            mask = mask | self._known  # the part after a fall of the load (decision 1545)
        if short:  # an entry's short part: the band left out widened to f_s / L
            mask = mask | self._near_harmonics(f_rev, self._fs / m)
        _kn.amplitude(spectra[1], 2.0 / c_sum, comb)
        factor = NOVELTY_HOLD if self._flag else NOVELTY_FACTOR
        _kn.novelty(comb, _seen_through(self._background, m / n), factor * grow, mask, novel)
        k = _kn.band_argmax(novel, b0, b1)
        # the part's band power on a full window's scale (its transform holds n/m times a
        # full window's per line and per noise bin), off the harmonics as the learned sum
        excess = (
            _kn.band_power(comb, self._harm_mask, b0, b1) * (m / n) - self._band_power
            if self._tests_power
            else None
        )
        return Spectra(self._f, raw, comb, self._band, gate, f_t, f_rev, True, novel,
                       band_slice=(b0, b1), peak_bin=k, masked=mask, part=m / n,
                       band_excess=excess,
                       band_noise=math.sqrt(self._band_var * n / m) if self._knows_counts else 0.0,
                       sweeps=self._count_rate_sweeps(),
                       held=bool(self._flag))  # fmt: skip

    def _count_rate_sweeps(self) -> bool:
        """Whether the encoder's count rate changed between the window's last two hops by more
        than the spindle frequency (decision 1697): ``N·|f̄_rev,last − f̄_rev,before| > f_rev``
        with ``N`` the encoder's counts per revolution (False when not known).

        The drive's quantisation lines sit at ``frac(f_rev·N·T_v)/T_v + k·f_rev`` (decision
        1687): a line moves by the change of the count rate ``N·f_rev`` (counts/s = Hz), and
        the family's lines are ``f_rev`` apart. Once the count rate moved by more than that
        spacing the family the newest samples carry lies elsewhere than the one before, at no
        place the window has held as a line, and while it moves (a cut's entry sags the speed by
        1e-5-1e-4, thousands of Hz of ``f_q``) the quantisation spreads over the band as a
        sweep, whose power also leaves the band's bins (the harmonics' masked bins, the band's
        ends) so that the band's sum falls by more than it moved. A hop mean of an encoder's
        speed is exact to one count per hop (``1/hop`` Hz of the count rate, 10 Hz at 0.1 s),
        far below ``f_rev`` (50-400 Hz)."""
        n_enc = self.settings.encoder_counts_rev
        means = self._stage.means
        if n_enc is None or len(means) < 2:
            return False
        return n_enc * abs(means[-1] - means[-2]) > means[-1]

    def _learning_rates(self, cutting: bool) -> tuple[float, float]:
        """Background update weights per window (decision 1504), plain and novel bins: out of
        the cut every bin in 0.5 s; in the cut, bins that are new (possible chatter) in 30 s,
        the others in 2 s."""
        hop = self.settings.hop_s
        if not cutting:
            a = min(1.0, hop / BACKGROUND_TAU_AIR_S)
            return a, a
        return min(1.0, hop / BACKGROUND_TAU_S), min(1.0, hop / BACKGROUND_TAU_NOVEL_S)

    def _decide(self, k: int, chunk: Chunk, nc: int | None) -> list[Event]:
        sp = self._spectra()
        t = chunk.t0_s + k / chunk.sample_rate_hz
        if sp is None:
            return []
        self.windows_decided += 1
        if sp.cutting or not self.method.learns_background:
            self.windows_judged += 1
        v: Verdict
        if self.method.name == "chatter-threshold" and self.method.threshold is None:
            if t < chunk.t0_s + CALIBRATION_S and sp.f_rev_hz * 60 >= self.settings.min_speed_rpm:
                self._calib.append(float(np.max(np.where(sp.band, sp.raw, 0.0))))
            elif self._calibrated is None and self._calib:
                self._calibrated = CALIBRATION_FACTOR * max(self._calib)
        v = self.method.decide(sp, self._calibrated)
        if (
            self.method.name == "chatter-sdft"
            and v.ratio > RUN_LEVEL * v.threshold
            and self._straddle(sp.f_tooth_hz, sp.f_rev_hz, self._level) is not None
        ):
            # the SDFT's sums over a window straddling an entry or an exit hold the comb's
            # ring-down as chatter variance and less harmonic variance (raw² − comb²): no
            # verdict, as on a window whose mean steps (decisions 1539, 1542)
            return []
        if v.moved and sp.part == 1.0:
            # a line of power moved within the band (decision 1687): the window's band is the
            # background now, the line's lobe and the band's power
            lobe = slice(max(sp.peak_bin - 1, 0), sp.peak_bin + 2)
            np.maximum(self._background[lobe], sp.comb[lobe], out=self._background[lobe])
            self._band_power = self._window_power
        was = bool(self._flag)
        now = v.chatter
        if v.ratio > RUN_LEVEL * v.threshold:
            if self._run_start is None:
                self._run_start = t
        else:
            self._run_start = None
        self._ratio = v.ratio
        self._freq = v.frequency_hz if now else math.nan
        self._flag = 1.0 if now else 0.0
        if now and not was:
            return [self._alarm(t, k, sp, v, nc)]
        if was and not now:
            return [
                Event(
                    t,
                    EventKind.NOTE,
                    self.name,
                    f"chatter ended ({self.method.name})",
                    name="chatter_end",
                    sample=k,
                    severity=Severity.INFO,
                )
            ]
        return []

    def _alarm(self, t: float, k: int, sp: Spectra, v: Verdict, nc: int | None) -> Event:
        s = self.settings
        f_c = v.frequency_hz
        f_t = sp.f_tooth_hz
        rpm = sp.f_rev_hz * 60.0
        # the controller's data (Smith-Tlusty): the tooth frequency that puts the chatter
        # frequency on a whole number of tooth periods per vibration wave, one lobe faster
        lobe = f_c / f_t if f_t > 0 else math.nan
        j = max(1, math.floor(lobe)) if math.isfinite(lobe) else 1
        suggested = 60.0 * f_c / (s.n_flutes * j) if math.isfinite(f_c) else math.nan
        onset = self._run_start if self._run_start is not None else t
        values = {
            "energy_ratio": v.ratio,
            "threshold": v.threshold,
            "chatter_hz": f_c,
            "tooth_passing_hz": f_t,
            "spindle_rpm": rpm,
            "flutes": float(s.n_flutes),
            "lobe_number": lobe,
            "suggested_spindle_rpm": suggested,
            "onset_s": onset,
        }
        loc: tuple[int | None, float | None, float | None, float | None] = (nc, None, None, None)
        if self.locate is not None:
            loc = self.locate(t, nc)
        return Event(
            t,
            EventKind.ALARM,
            self.name,
            f"chatter at {f_c:.1f} Hz ({self.method.name}: ratio {v.ratio:.2f} > "
            f"{v.threshold:g}; tooth passing {f_t:.1f} Hz, {rpm:.0f} rev/min)",
            name="chatter",
            value=f_c,
            sample=k,
            severity=Severity.WARNING,
            values=values,
            nc_line=loc[0],
            x_mm=loc[1],
            y_mm=loc[2],
            z_mm=loc[3],
        )


def _segment_gate(
    tooth: float,
    med: float,
    level: float,
    half_step: float,
    f_rev: float,
    air: np.ndarray,
    grow: float,
) -> float | None:
    """The cutting and steady-mean gates of :func:`._kernels.cutting_gate` on a window's part
    after its mean step (decision 1539), learning nothing: the floor learned out of the cut and
    the load span are taken ``grow`` (√(n / L)) times higher, as the segment's noise. Returns
    the reference of the ratio (the tooth line, no less than 3 × the floor), or None when the
    segment is out of the cut or its own halves' means differ."""
    has_floor = air[_kn.HAS_FLOOR] > 0.0
    air_floor = air[_kn.AIR_FLOOR] * grow
    floor = air_floor if has_floor and air_floor < med else med
    loaded = _loaded(level, f_rev, air, grow)
    if not (tooth > 0.0 and (tooth > CUTTING_GATE * floor or loaded)):
        return None
    if abs(half_step) > max(STEADY_MEAN * tooth, STEADY_NOISE * floor):
        return None
    return max(tooth, CUTTING_GATE * floor)


def _detrend(y: np.ndarray) -> None:
    """``y`` less its least-squares line, in place (decision 1546). The comb filter answers a
    step of the mean with a ring-down of its DC notch that decays over ten revolutions (Eq.
    5.27, α per revolution); over a part of a few revolutions after the step that is a slow
    baseline whose rectangular spectrum's sidelobes (the first at 1.5 f_s/L, −13 dB) fall
    beside the band left out around the harmonics."""
    m = y.shape[0]
    if m < 2:
        return
    t = np.arange(m, dtype=np.float64) - 0.5 * (m - 1)
    # (the mean as ndarray.mean takes it, the same pairwise sum, without its Python layer)
    y -= np.add.reduce(y) / m + t * (float(t @ y) / float(t @ t))


def _seen_through(background: np.ndarray, frac: float) -> np.ndarray:
    """The background as a part of ``frac`` of the window (rectangular, zero-padded to the
    window) shows it (decision 1546): a line of the background (learned on full windows, one
    bin wide) spreads in the part over the main lobe of the part's own window, ``1/frac`` bins
    to each side, with the amplitude |sinc(d·frac)| at ``d`` bins; each bin's reference is the
    largest such contribution of its neighbours within the main lobe. ``frac`` = 1: the
    background itself."""
    widen = math.ceil(1.0 / frac) - 1
    if widen <= 0:
        return background
    gains = np.array(
        [abs(math.sin(math.pi * d * frac) / (math.pi * d * frac)) for d in range(1, widen + 1)]
    )
    ref = np.empty_like(background)
    _kn.widened_maximum(background, gains, ref)
    return ref


def _loaded(level: float, f_rev: float, air: np.ndarray, grow: float) -> bool:
    """The cutting gate's load test (:func:`._kernels.air_loaded`) with this module's
    :data:`LOAD_GATE` and :data:`STEADY_SPEED`."""
    return bool(_kn.air_loaded(level, f_rev, air, LOAD_GATE, STEADY_SPEED, grow))


def _run_chunk(
    monitors: Sequence[ChatterMonitor], chunk: Chunk, holder: ChatterMonitor | ChatterGroup
) -> BlockOutput:
    """Feed ``chunk`` to monitors sharing one stage (the first one's inputs and hop): one
    ingest per run of samples, each monitor's decision at the decision samples. ``holder``
    (the block) keeps the merged held outputs between decisions."""
    lead = monitors[0]
    s = lead.settings
    x = np.ascontiguousarray(chunk.data[s.signal], dtype=np.float64)
    n = len(x)
    if s.speed_channel is not None:
        spd = np.ascontiguousarray(chunk.data[s.speed_channel], dtype=np.float64)
        factor = lead._speed_factor
    else:
        spd = np.full(n, lead._const_speed)
        factor = 1.0
    hop = lead._hop
    first = (hop - 1 - chunk.start) % hop  # offset of the first decision sample
    if first >= n:  # no decision in this chunk (the common case for short chunks)
        lead._ingest(x, spd, factor)
        views = holder._merged
        if views is not None and views[0] == n:  # nothing decided since: the same views
            return BlockOutput(dict(views[1]))
        held = np.array([v for m in monitors for v in (m._flag, m._freq, m._ratio)])
        holder._merged, out = held_views(holder._out_names, held, views, n)
        return BlockOutput(out)
    holder._merged = None
    # rows 3q, 3q + 1, 3q + 2: flag, frequency, ratio of monitor q
    values = np.empty((3 * len(monitors), n))
    events: list[Event] = []
    keep = holder._keep
    i = 0
    for j in [*range(first + 1, n + 1, hop), n]:
        if j <= i:
            continue
        lead._ingest(x[i:j], spd[i:j], factor)
        held = np.array([v for m in monitors for v in (m._flag, m._freq, m._ratio)])
        if (chunk.start + j) % hop == 0:
            lead._stage.close_hop(keep)
            nc = None
            if s.nc_line_channel is not None:
                nc = int(chunk.data[s.nc_line_channel][j - 1])
            # outputs before the decision sample hold the old values
            values[:, i : j - 1] = held[:, None]
            for m in monitors:
                events.extend(m._decide(chunk.start + j - 1, chunk, nc))
            values[:, j - 1] = [v for m in monitors for v in (m._flag, m._freq, m._ratio)]
        else:
            values[:, i:j] = held[:, None]
        i = j
    return BlockOutput(dict(zip(holder._out_names, values, strict=True)), events)


class ChatterGroup(Block):
    """Several chatter monitors on the same signal and speed as one block: the rings, the comb
    filter and the speed statistics are computed once (the criteria differ only in their
    windows and decisions). Outputs and events are those of the members, unchanged.

    Parameters
    ----------
    monitors : monitors reading the same signal, speed, NC-line channel, with the same hop.
    name : block name.
    """

    def __init__(self, monitors: Sequence[ChatterMonitor], name: str = "chatter") -> None:
        if not monitors:
            raise ConfigError("chatter group: no monitor")
        ref = monitors[0].settings
        for m in monitors[1:]:
            t = m.settings
            if (t.signal, t.speed_channel, t.speed_unit, t.speed_rpm, t.nc_line_channel,
                    t.hop_s, t.min_speed_rpm) != (ref.signal, ref.speed_channel, ref.speed_unit,
                                                  ref.speed_rpm, ref.nc_line_channel,
                                                  ref.hop_s, ref.min_speed_rpm):  # fmt: skip
                raise ConfigError(
                    f"chatter group: monitor '{m.name}' reads other channels or settings than "
                    f"'{monitors[0].name}'"
                )
        self.monitors = list(monitors)
        self.name = name
        self.inputs = monitors[0].inputs

    def output_channels(self) -> list[ChannelInfo]:
        return [c for m in self.monitors for c in m.output_channels()]

    def reset(self, sample_rate_hz: float) -> None:
        for m in self.monitors:
            m.reset(sample_rate_hz)
        stage = _Stage(max(m._size for m in self.monitors))
        for m in self.monitors:
            m._stage = stage
        self._merged: HeldViews | None = None
        self._keep = max(m._keep_hops for m in self.monitors)  # hops of speed ranges kept
        self._out_names = tuple(c for m in self.monitors for c in m._out_names)

    def process(self, chunk: Chunk) -> BlockOutput:
        return _run_chunk(self.monitors, chunk, self)
