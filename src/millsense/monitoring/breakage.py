"""Tool-breakage monitors on the average torque (or resultant force) per tooth period.

Three detectors behind one streaming :class:`BreakageBlock` (issue 15, item 2):

``virtual`` — seed 000 (Aslan ch. 6.3, digest §2.9, C17): the spindle torque is averaged over
    each tooth period (Eq. 6.1), differenced (Eq. 6.2) and whitened by an adaptive AR(1) filter
    whose parameter is re-estimated by RLS every tooth period (Eq. 6.3). The threshold is
    *virtual feedback*: LIMIT1(m) = σ_TB · τ_sa,sim(m) with σ_TB = 40 % of the torque the
    virtual plan expects in that tooth period (Eq. 6.6). A violation must also show in the
    measured torque itself (|τ_sa − τ_sa,sim| > σ_TB τ_sa,sim; digest: "an alert needs both the
    measured torque and the residual to violate their limits") and is confirmed over 3 tooth
    periods (C17 step 5): a run starts where both violate and continues while the torque does,
    the alarm comes with its third violating tooth period. A broken flute shows once a
    revolution at least (its own period; the next flute's double chip leaves the band only
    where the flute's pulse fills its period, a slot with 2 flutes), so the run bridges up to
    N − 1 periods in a row within the band (decision 1552; 2 flutes in a slot, both periods
    violating, alarm as before at the third period). The alarm also needs a broken flute's
    signature (decision 1681; seed 002 §2.5: a chipped tooth leaves its material to the next
    tooth): the next flute cuts the broken flute's chip, so the revolution's mean torque (the
    last N tooth periods, one revolution whatever their phase) stays within
    [1 − ``edge_share``/N − ``revolution_tol``, 1 + ``revolution_tol``] of the plan's (the
    broken flute takes away no more than its edge force), and its deviation is locked to the
    flute, the same sign at the same flute one revolution earlier. A weak chatter modulates
    the chip of every flute: its tooth periods drop and surge together, moving the revolution
    mean, and not at one flute's position (measured: 86 % drops where the chatter monitor's
    ratio was 0.66). Where the signature is missing at the third violation the run goes on and
    alarms at a later violation that shows it; a revolution mean under the other flutes'
    shares (1 − 1/N − ``revolution_tol``: more than one flute's torque missing) for
    ``lost_revolutions`` revolutions in a row (the whole cut lost: every flute, the tool off at
    its shank) alarms without it. A second way to confirm (decision 1684; seed 002 §2.5, the
    physics of a broken flute rather than one band's violations): the flute's drop against the
    other flutes and against its own previous revolutions (the plan's error and the flute's
    runout cancel), or the drop of one flute and the rise of the next, in standard deviations
    of its own scale, accumulated over up to 4 revolutions of the flute, alarms at
    ``pattern_z`` = 7 (a threshold set from the false-alarm rate of intact cuts) where the
    revolution keeps a broken flute's share; it confirms a drop at the band's edge in one or
    two revolutions where the seed's rule waits for the noise. The tooth periods' phase is
    that of the stream start; :class:`~millsense.monitoring.breakage_phased.PhasedBreakage`
    judges several phases (``phase_offset``, decision 1552). Tooth periods whose expected
    torque is below ``min_expected_nm`` (default 10 % of the plan's largest; air, the first
    touch of an entry) are not judged: there the virtual limit goes to zero (decision 1522).
    In the plan's transients, where the expected torque is not given (decisions 1622, 1627),
    the lowest torque the plan expects over its timing window (``floor_channel``) judges a
    drop only (decision 1674).
    The torque's band is never narrower than ``noise_k`` (4) standard deviations of the tooth-period
    average's noise, estimated on line from the median |x(m) − x(m−N)| of the last 128 periods
    (decision 1550): the seed's 40 % is a band for a cut whose torque stands well above the noise
    (Aslan's 1000 rev/min, several N·m); on a light cut at high speed (0.5 N·m at 8000 rev/min, the
    observer's tooth average scattering by 0.15 N·m) 40 % is 1.5σ, and the noise alone would confirm
    three periods in a row about once a second. The σ in use is the larger of that window's and
    its exponential mean over 256 periods (decision 1718): on the observer's coloured noise the
    window's median dips to half the true σ now and then, and a dip let noise confirm a break.
``constant`` — a constant reference: the same detector with τ_sa,sim replaced by a constant
    reference torque (given, or the mean over the first 5 revolutions in cut; decision 1523). It
    alarms wherever the torque leaves the band around the reference (a depth step). Its run
    bridges up to N − 2 periods (decision 1550). The thesis' own constant threshold in V7 is
    Eq. 6.5 on the residuals, i.e. ``dual`` (decision 1670).
``dual`` — seed 002 (Munasinghe Eqs. 3.43–3.49, digest §2.5), Aslan's classic Eq. 6.5: the
    same first-difference residual ε1 and a second AR(1) residual ε2 on the lag-N difference
    x(m) − x(m−N) (N flutes, which removes runout); thresholds 2 × max|ε_k| over the first 5
    revolutions;
    breakage when |ε1| > thr1 AND |ε2| > thr2 in the same tooth period (|ε|, as the thesis'
    figures show ±thresholds). The thresholds are learnt afresh on each cut (the gate's closing
    forgets them), are never inside ``noise_k`` · √2 σ̂ of a two-period difference's noise, and
    nothing is judged before σ̂ is known (decision 1719: learnt once and without a floor, they
    gave hundreds of false alarms on a stream of stable cuts at several speeds).

Residuals are a-priori (φ̂ of the previous tooth period; decision 1521). The RLS covariance is
capped (``rls_p_max``) so that a long steady cut (regressor ≈ 0) cannot wind it up and the AR(1)
parameter follows a new pattern over several tooth periods rather than one.

Tooth periods come from the spindle speed channel (integrated phase, so speed changes and
overrides are followed); the flute index in the event counts from the stream start. Per sample
the work is one compiled loop (:mod:`millsense.monitoring._tooth_kernels`); per tooth period a
second one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from millsense.core.errors import ConfigError, InputDataError
from millsense.core.recording import ChannelInfo
from millsense.monitoring import _tooth_kernels as _k
from millsense.plan.path import cnc_line
from millsense.plan.virtual_plan import VirtualPlan
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

Method = Literal["virtual", "constant", "dual"]
_MODES = {"virtual": _k.MODE_VIRTUAL, "constant": _k.MODE_CONSTANT, "dual": _k.MODE_DUAL}
#: Seed 000 Eq. 6.6: virtual threshold fraction σ_TB.
SIGMA_TB = 0.40
#: Tooth periods whose expected torque is below this fraction of the plan's largest (or below
#: MIN_EXPECTED_NM without a plan) are not judged (decision 1522).
MIN_EXPECTED_FRACTION = 0.10
MIN_EXPECTED_NM = 0.5
#: Seed 000 C17: violations needed in a row before the alarm.
CONFIRM_PERIODS = 3
#: Decision 1550: the band of the virtual and constant detectors is at least this many
#: standard deviations of the tooth-period average's noise (seed 004 ch. 3 triggers contact
#: at mean + 4σ; with 3 periods confirmed, a normal noise alone alarms with ≈ (6·10⁻⁵)³ per
#: period).
NOISE_K = 4.0
#: Decision 1681: the share of its own torque a broken flute takes from the revolution (its
#: edge force; the next flute cuts its chip), the tolerance of the revolution mean's ratio to
#: the plan's, and the revolutions in a row of a revolution mean under the other flutes'
#: shares (1 − 1/N − tol) that are the whole cut lost (alarmed without the flute signature;
#: weak chatter's lows measured 8 revolutions at most).
EDGE_SHARE = 0.5
REVOLUTION_TOL = 0.1
LOST_REVOLUTIONS = 10
#: Decision 1684: the flute pattern's threshold, in standard deviations of its evidence, set
#: from the false-alarm rate measured on the six general cuts run intact (and before their
#: breaks; not from the breaks): of 29 829 tooth periods judged at three phases, 1750 (5.9 %)
#: gave a drop of a breakage's size, and their evidence's 0.99 and 0.999 quantiles (3.27, 4.04;
#: largest 4.33) follow a normal tail of scale 1.41 at most. At 7.0 (4.96 of that scale) that
#: is 2.0e-8 per judged period: one false alarm per 7 h of cutting at 10 000 rev/min with 4
#: flutes (three phases: 2000 judged periods a second), per 46 h at 3000 rev/min with 2.
PATTERN_Z = 7.0
#: Seed 002 §2.5: threshold factor and learning length.
ALPHA = 2.0
LEARN_REVOLUTIONS = 5
#: Seed 002 §2.5 initial values φ₀ and P₀.
PHI0 = 0.01
P0 = 10.0
#: Cap of the RLS covariance for a torque in N·m (1/(N·m)²; forces in N: × 1e-4, i.e. a
#: scale of 100 N per N·m). Decision 1521: the adaptation gain stays ≤ x²P/(1 + x²P), so the
#: AR(1) parameter follows a breakage pattern over several tooth periods, not in one.
P_MAX_TORQUE = 0.01


class BreakageBlock(Block):
    """Streaming tool-breakage detector (see the module notes for the three methods).

    Parameters
    ----------
    n_flutes : number of flutes N (tooth period 2π/N).
    method : ``virtual`` (seed 000), ``constant`` (classic constant threshold) or ``dual``
        (seed 002).
    signal_channels : one channel (torque, N·m) or two (force x and y, N; their tooth-period
        averages are combined into the resultant, Munasinghe Eq. 3.45).
    speed_channel : spindle speed, rad/s.
    expected_channel : per-sample expected cutting torque from the plan, N·m (``virtual``;
        alternative to ``plan``).
    plan : virtual plan: its ``torque_avg_nm`` at the row matched to the TCP at the end of each
        tooth period is the expected torque, and the event gets the NC line and position.
    tcp_channels : TCP position channels (m) matched to the plan.
    sigma_tb : virtual threshold fraction (0.4).
    min_expected_nm : expected (or constant reference) torques below this are not judged;
        default: 10 % of the plan's largest expected torque when a plan is given, else 0.5 N·m
        (set it for small tools).
    check_deviation : also require |τ_sa − τ_sim| > σ_TB τ_sim (``virtual``).
    confirm_periods : violating periods before the alarm (3; 1 for ``dual``), in a run that
        bridges up to N − 1 (virtual; decision 1552) or N − 2 (constant; decision 1550)
        periods in a row without one.
    reference : constant reference τ_ref in the signal's unit (``constant``; 0 = the mean of the
        tooth-period averages over the learning revolutions).
    alpha, learn_revolutions, learn_from : learning over that many revolutions, starting at the
        first tooth period whose average is ≥ ``learn_from``: the constant reference, and the
        dual thresholds α·max|ε_k|.
    forgetting : RLS forgetting factor λ (Munasinghe does not state it; 0.98).
    rls_p_max : cap (and initial value) of the RLS covariance, 1/unit² (decision 1521).
    noise_k : the signal's band around its reference (``virtual``, ``constant``) is never
        narrower than ``noise_k`` standard deviations of the tooth-period average's noise (the
        ``dual`` thresholds than ``noise_k`` · √2 of them, decision 1719),
        estimated on line (decision 1550, held by its slow mean, decision 1718; 0: the seed's
        σ_TB band alone).
    phase_offset : the tooth periods end this fraction of a period earlier than at the
        multiples of 2π/N of the integrated angle (decision 1552), in [0, 1).
    enable_channel : optional 1/0 channel (e.g. ``spindle/at_speed``): a tooth period with a
        sample where it is 0 is not judged and restarts the differences (a spindle run-up or
        speed change, whose observer torque holds the acceleration torque; decision 1550).
    floor_channel : optional per-sample lower bound of the expected torque where the plan is in
        a transient and ``expected_channel`` reads 0 (``virtual``; the session's
        ``plan/torque_floor``): a tooth period with samples there is judged one-sided, a drop
        below the floor by the band (decision 1674).
    flute_signature : the virtual alarm needs a broken flute's signature (decision 1681):
        the revolution mean within [1 − ``edge_share``/N − ``revolution_tol``,
        1 + ``revolution_tol``] of the plan's (no upper bound where a period of the revolution
        is one-sided) and the deviation's sign repeated by the same flute one revolution
        earlier, not every flute below the plan by half the band and, with two flutes, the
        other flute risen by 1 − ``edge_share`` − ``revolution_tol`` of the drop (decision
        1742); or the revolution mean under 1 − 1/N − ``revolution_tol`` for
        ``lost_revolutions`` revolutions in a row (0: never without the signature).
    flute_pattern : a second way to confirm (``virtual``; decision 1684): a broken flute's
        pattern, the flute's drop against the other flutes (or the drop of one and the rise
        of the next) in its residual to the plan referenced to the same flute's previous
        revolutions, accumulated over up to 4 revolutions, at ``pattern_z`` standard
        deviations, with the revolution keeping a broken flute's share as above; at most one
        alarm of either way until a period not judged two-sided or a re-arm.
    pattern_z : the pattern's threshold in standard deviations (:data:`PATTERN_Z`).
    flute_check : the plan-free ``dual`` and ``constant`` detectors alarm only where two
        tooth periods at most ⌈N/2⌉ apart (consecutive for N = 2) show a broken flute's drop
        and the next flute's rise, in either order, the smaller at least 1 − ``edge_share`` −
        ``revolution_tol`` of the larger (the next flute cuts the broken flute's chip): the
        dual's changes over one revolution ago, at least its learnt lag-N threshold (decision
        1707), the constant's deviations from its reference, at least its band (decision
        1724). An entry, a step, an exit, a retract or a cavity moves neighbouring flutes the
        same way. Off: the seeds' detectors as they are.
    mean_resolution : the signal's resolution over a tooth period, in its unit × s: a tooth
        period's mean moves in steps of it divided by the period's duration (the spindle DOB's
        torque: an encoder count at an end of the period,
        :meth:`~millsense.estimation.spindle_dob.SpindleDobTorque.mean_resolution_nms`); no
        band, dual threshold, change or flute-pattern drop is smaller than three such steps
        (decision 1732). 0: none.
    name : block name (channel prefix and event source).
    """

    def __init__(
        self,
        n_flutes: int,
        method: Method = "virtual",
        signal_channels: tuple[str, ...] = ("spindle/torque_est",),
        speed_channel: str = "spindle/speed",
        expected_channel: str | None = None,
        plan: VirtualPlan | None = None,
        tcp_channels: tuple[str, str, str] = ("tcp_x", "tcp_y", "tcp_z"),
        sigma_tb: float = SIGMA_TB,
        min_expected_nm: float | None = None,
        check_deviation: bool = True,
        confirm_periods: int | None = None,
        reference: float = 0.0,
        alpha: float = ALPHA,
        learn_revolutions: int = LEARN_REVOLUTIONS,
        learn_from: float = 0.0,
        forgetting: float = 0.98,
        rls_p_max: float | None = None,
        noise_k: float = NOISE_K,
        enable_channel: str | None = None,
        phase_offset: float = 0.0,
        floor_channel: str | None = None,
        flute_signature: bool = True,
        edge_share: float = EDGE_SHARE,
        revolution_tol: float = REVOLUTION_TOL,
        lost_revolutions: int = LOST_REVOLUTIONS,
        flute_pattern: bool = True,
        pattern_z: float = PATTERN_Z,
        flute_check: bool = False,
        mean_resolution: float = 0.0,
        name: str | None = None,
    ) -> None:
        if int(n_flutes) != n_flutes or n_flutes < 1:
            raise ConfigError(f"breakage: n_flutes must be an integer ≥ 1, got {n_flutes!r}")
        if method not in _MODES:
            raise ConfigError(f"breakage: method must be one of {sorted(_MODES)}, got {method!r}")
        if len(signal_channels) not in (1, 2):
            raise ConfigError("breakage: signal_channels takes one torque or two force channels")
        if method == "virtual" and (expected_channel is None) == (plan is None):
            raise ConfigError(
                "breakage: the virtual threshold needs the plan's expected torque: give exactly "
                "one of expected_channel or plan"
            )
        if not (0.0 < forgetting <= 1.0):
            raise ConfigError(f"breakage: forgetting must be in (0, 1], got {forgetting!r}")
        if not (0.0 < sigma_tb < 10.0):
            raise ConfigError(f"breakage: sigma_tb must be in (0, 10), got {sigma_tb!r}")
        if learn_revolutions < 1:
            raise ConfigError(f"breakage: learn_revolutions must be ≥ 1, got {learn_revolutions}")
        if not (noise_k >= 0 and math.isfinite(noise_k)):
            raise ConfigError(f"breakage: noise_k must be ≥ 0 (0: no noise floor), got {noise_k!r}")
        if not (0.0 <= phase_offset < 1.0):
            raise ConfigError(
                f"breakage: phase_offset must be in [0, 1) of a tooth period, got {phase_offset!r}"
            )
        if not (0.0 <= edge_share <= 1.0 and 0.0 <= revolution_tol < 1.0):
            raise ConfigError(
                f"breakage: edge_share must be in [0, 1] and revolution_tol in [0, 1), got "
                f"{edge_share!r} and {revolution_tol!r}"
            )
        if int(lost_revolutions) != lost_revolutions or lost_revolutions < 0:
            raise ConfigError(
                f"breakage: lost_revolutions must be an integer ≥ 0, got {lost_revolutions!r}"
            )
        if not (mean_resolution >= 0 and math.isfinite(mean_resolution)):
            raise ConfigError(
                f"breakage: mean_resolution must be ≥ 0 (0: none), got {mean_resolution!r}"
            )
        if not (pattern_z > 0 and math.isfinite(pattern_z)):
            raise ConfigError(f"breakage: pattern_z must be positive, got {pattern_z!r}")
        self.flute_signature = bool(flute_signature) and method == "virtual"
        self.flute_pattern = bool(flute_pattern) and method == "virtual"
        self.flute_check = bool(flute_check) and method in ("dual", "constant")
        self.pattern_z = float(pattern_z)
        self.mean_resolution = float(mean_resolution)
        self.edge_share = float(edge_share)
        self.revolution_tol = float(revolution_tol)
        self.lost_revolutions = int(lost_revolutions)
        self.phase_offset = float(phase_offset)
        self.noise_k = float(noise_k)
        self.enable_channel = enable_channel
        self.n_flutes = int(n_flutes)
        self.method: Method = method
        self.signal_channels = tuple(signal_channels)
        self.speed_channel = speed_channel
        self.expected_channel = expected_channel if method == "virtual" else None
        self.floor_channel = floor_channel if method == "virtual" else None
        self.plan = plan
        self.tcp_channels = tcp_channels
        self.sigma_tb = float(sigma_tb)
        if min_expected_nm is None:
            if plan is not None and len(plan):
                tq = np.asarray(plan["torque_avg_nm"], dtype=np.float64)
                min_expected_nm = MIN_EXPECTED_FRACTION * float(np.nanmax(tq, initial=0.0))
            else:
                min_expected_nm = MIN_EXPECTED_NM
        if not (min_expected_nm > 0):
            raise ConfigError(
                f"breakage: min_expected_nm must be positive (a zero expected torque gives a "
                f"zero limit), got {min_expected_nm!r}"
            )
        self.min_expected_nm = float(min_expected_nm)
        self.check_deviation = bool(check_deviation)
        default_confirm = 1 if method == "dual" else CONFIRM_PERIODS
        self.confirm = int(confirm_periods if confirm_periods is not None else default_confirm)
        if self.confirm < 1:
            raise ConfigError(f"breakage: confirm_periods must be ≥ 1, got {confirm_periods}")
        self.reference = float(reference)
        self.alpha = float(alpha)
        self.learn_periods = int(learn_revolutions) * self.n_flutes
        self.learn_from = float(learn_from)
        self.forgetting = float(forgetting)
        self.unit = "N*m" if len(self.signal_channels) == 1 else "N"
        if rls_p_max is None:
            rls_p_max = P_MAX_TORQUE if self.unit == "N*m" else P_MAX_TORQUE * 1e-4
        if not (rls_p_max > 0):
            raise ConfigError(f"breakage: rls_p_max must be positive, got {rls_p_max!r}")
        self.p_max = float(rls_p_max)
        self.name = name or f"breakage.{method}"
        self._suffix = "nm" if self.unit == "N*m" else "n"
        ins = [*self.signal_channels, speed_channel]
        if self.expected_channel is not None:
            ins.append(self.expected_channel)
        if enable_channel is not None:
            ins.append(enable_channel)
        if self.floor_channel is not None:
            ins.append(self.floor_channel)
        if self.plan is not None:
            ins.extend(tcp_channels)
        self.inputs = tuple(ins)
        self.fs = 0.0
        self._names = [info.name for info in self.output_channels()]

    # ------------------------------------------------------------------ contract

    def output_channels(self) -> list[ChannelInfo]:
        u = self.unit
        return [
            ChannelInfo(f"{self.name}/tooth_avg", u, "signal averaged over the last tooth period"),
            ChannelInfo(f"{self.name}/residual1", u, "AR(1) residual of the first difference"),
            ChannelInfo(f"{self.name}/limit1", u, "threshold of residual 1 (NaN: none yet)"),
            ChannelInfo(f"{self.name}/residual2", u, "AR(1) residual of the lag-N difference"),
            ChannelInfo(f"{self.name}/limit2", u, "threshold of residual 2 (NaN: none yet)"),
            ChannelInfo(f"{self.name}/band", u, "half-width of the signal's band around its "
                        "reference, noise floor included (virtual, constant; NaN: not judged)"),
        ]

    def rearm(self) -> None:
        """Forget the running violation and judge afresh (an arbiter's call after a disturbance
        that invalidated the tooth-period torque, e.g. chatter): a tool that is still broken
        alarms again after ``confirm`` periods, on the torque deviation alone (decision 1625)."""
        self._det[_k.DET_RUN] = 0.0
        self._det[_k.DET_MISS] = 0.0
        self._det[_k.DET_GAP] = 1.0
        self._det[_k.DET_ALARMED] = 0.0
        self._det[_k.DET_PALARMED] = 0.0
        self._first_violation = -1
        if self._group_first is not None:  # a group's member: the group keeps it
            self._group_first[0][self._group_first[1]] = -1

    def reset(self, sample_rate_hz: float) -> None:
        if not (sample_rate_hz > 0 and math.isfinite(sample_rate_hz)):
            raise ConfigError(f"{self.name}: sample rate must be positive, got {sample_rate_hz}")
        self.fs = float(sample_rate_hz)
        self._seg = np.zeros(_k.SEG_SIZE)
        self._seg[_k.SEG_PHASE] = self.phase_offset  # the periods end a fraction earlier
        self._det = _k.detector_state(self.n_flutes, PHI0, self.p_max)
        self._held = np.array([math.nan, 0.0, math.nan, 0.0, math.nan, math.nan])
        self._first_violation = -1
        #: in a :class:`BreakageGroup`: the group's array of first violations and this
        #: member's slot in it, which then holds the running violation (decision 1700)
        self._group_first: tuple[np.ndarray, int] | None = None
        self._row = 0
        self._empty = np.zeros(0)
        self._params = np.array(
            [
                self.forgetting,
                self.p_max,
                self.sigma_tb,
                self.min_expected_nm,
                self.reference,
                self.alpha,
                self.learn_from,
                self.noise_k,
                self.edge_share,
                self.revolution_tol,
                self.pattern_z,
                self.mean_resolution * self.fs,  # the step summed over a period's samples
            ]
        )
        self._iparams = np.array(
            [
                self.n_flutes,
                _MODES[self.method],
                int(self.check_deviation),
                self.learn_periods,
                self.confirm,
                int(self.flute_signature),
                self.lost_revolutions * self.n_flutes,
                int(self.flute_pattern),
                int(self.flute_check),
            ],
            dtype=np.int64,
        )
        self._pp = np.empty((_k.PP_ROWS, 0))
        self._pi = np.empty((2, 0), dtype=np.int64)
        self._pb = np.empty((2, 0), dtype=np.bool_)
        self._bufs = (self._pp[0], self._pp[1], self._pp[2], self._pp[_k.PP_GATE],
                      self._pp[_k.PP_FLOOR], self._pp[_k.PP_COUNT], self._pi[0],
                      self._pi[1])  # fmt: skip
        self._n_last = -1
        self._ch_a = self.signal_channels[0]
        self._ch_b = self.signal_channels[1] if len(self.signal_channels) == 2 else None
        self._ch_e = self.expected_channel
        self._ch_g = self.enable_channel
        self._ch_f = self.floor_channel
        self._held_views: HeldViews | None = None
        compile_kernels()

    def _held_outputs(self, n: int) -> dict[str, np.ndarray]:
        """The held values for ``n`` samples (:func:`~millsense.streaming.block.held_views`;
        new views when the values change, at a tooth period's end, or the chunk length does)."""
        self._held_views, out = held_views(self._names, self._held, self._held_views, n)
        return out

    def process(self, chunk: Chunk) -> BlockOutput:
        k, n = self._segment(chunk.data)
        if k == 0:  # no tooth period ends in this chunk: the held values throughout
            views = self._held_views
            if views is not None and views[0] == n:
                return BlockOutput(dict(views[1]))
            return BlockOutput(self._held_outputs(n))
        return self._periods(chunk, k, n)

    def _segment(self, d: Any) -> tuple[int, int]:
        """The chunk's samples (channels ``d``) added to the tooth-period averages (Aslan
        Eq. 6.1): the tooth periods ending in it and its length."""
        a = np.asarray(d[self._ch_a], dtype=np.float64)
        n = a.shape[0]
        b = self._empty if self._ch_b is None else np.asarray(d[self._ch_b], dtype=np.float64)
        speed = np.asarray(d[self.speed_channel], dtype=np.float64)
        e = self._empty if self._ch_e is None else np.asarray(d[self._ch_e], dtype=np.float64)
        g = self._empty if self._ch_g is None else np.asarray(d[self._ch_g], dtype=np.float64)
        f = self._empty if self._ch_f is None else np.asarray(d[self._ch_f], dtype=np.float64)
        if n != self._n_last:
            self._size(n)
        r0, r1, r2, rg, rf, rc, r3, r4 = self._bufs
        # rows of pp: 0 mean0, 1 mean1, 2 expected, 3 x, 4 ε1, 5 limit1, 6 ε2, 7 limit2, 8 band,
        # 9 the gate's mean, 10 the floor's mean, 17 the samples
        k: int = _k.segment_periods(a, b, e, g, f, speed, self.fs, self.n_flutes, self._seg, r0,
                                    r1, r2, rg, rf, rc, r3, r4)  # fmt: skip
        return k, n

    def _periods(self, chunk: Chunk, k: int, n: int) -> BlockOutput:
        """Outputs and events of a chunk of ``n`` samples in which ``k`` ≥ 1 tooth periods end
        (after :meth:`_segment`): residuals, limits and detection per period (Eqs. 6.2–6.6)."""
        d = chunk.data
        self._held_views = None
        pp, pi, pb = self._pp, self._pi, self._pb
        values = np.empty((_k.OUT_ROWS, n))
        if self.plan is not None and self.expected_channel is None:
            pp[2, :k] = self._plan_expected(d, pi[0, :k])
        first = self._first_violation
        self._first_violation, alarms = _k.periods_step(
            pp, pb, k, self._ch_b is not None, self._params, self._iparams, self._det,
            self._held, values, first, pi[0], pi[1],
        )  # fmt: skip
        out = BlockOutput(dict(zip(self._names, values, strict=True)))
        if alarms:
            out.events.extend(self._alarms(chunk, k, first))
        return out

    def _alarms(self, chunk: Chunk, k: int, first: int) -> list[Event]:
        """The alarm events of the ``k`` tooth periods of a chunk just judged (``first``: the
        first period of the running violation before it)."""
        pp, pi, pb = self._pp, self._pi, self._pb
        x, expected, eps1, lim1, eps2, lim2, band = (pp[3], pp[2], pp[4], pp[5], pp[6], pp[7],
                                                     pp[8])  # fmt: skip
        end, index, viol, alarm = pi[0], pi[1], pb[0], pb[1]
        events = []
        for i in range(k):
            if viol[i]:
                if first < 0:
                    first = int(index[i])
            else:
                first = -1
            if alarm[i]:
                at, period = int(end[i]), int(index[i])
                values = (x[i], expected[i], eps1[i], lim1[i], eps2[i], lim2[i], band[i])
                below = bool(pp[_k.PP_FLOOR, i] > 0.0)
                signature = (float(pp[_k.PP_REV, i]), float(pp[_k.PP_LAG, i]))
                drop = (float(pp[_k.PP_CE1, i]), float(pp[_k.PP_CE2, i]))
                events.append(self._event(chunk, at, period, first, *values, below=below,
                                          signature=signature,
                                          pattern=float(pp[_k.PP_PAT, i])
                                          if pp[_k.PP_BY, i] > 0.0 else math.nan,
                                          drop=drop))  # fmt: skip
        return events

    def _size(self, n: int) -> None:
        """Work arrays for chunks of ``n`` samples."""
        cap = min(int(n * self.n_flutes * 5e3 / self.fs) + 2, n + 1)  # ≤ 300 000 rev/min
        if cap > self._pp.shape[1]:
            self._pp = np.empty((_k.PP_ROWS, 2 * cap))
            self._pi = np.empty((2, 2 * cap), dtype=np.int64)
            self._pb = np.empty((2, 2 * cap), dtype=np.bool_)
            self._bufs = (self._pp[0], self._pp[1], self._pp[2], self._pp[_k.PP_GATE],
                          self._pp[_k.PP_FLOOR], self._pp[_k.PP_COUNT], self._pi[0],
                          self._pi[1])  # fmt: skip
        self._n_last = n

    # ------------------------------------------------------------------ helpers

    def _plan_expected(self, d: Any, end: np.ndarray) -> np.ndarray:
        """Expected torque per tooth period from the plan row matched at its end sample."""
        assert self.plan is not None
        xyz = np.column_stack([np.asarray(d[c], dtype=np.float64)[end] for c in self.tcp_channels])
        rows = self.plan.match(xyz, from_row=self._row)
        self._rows = rows
        good = rows >= 0
        if good.any():
            self._row = int(rows[good][-1])
        tq = np.asarray(self.plan["torque_avg_nm"], dtype=np.float64)
        return np.where(good, tq[np.maximum(rows, 0)], math.nan)

    def _signature_text(self, ratio: float, lag: float) -> str:
        """What the flute signature (decision 1681) found at the alarm."""
        lost = 1.0 - 1.0 / self.n_flutes - self.revolution_tol
        if ratio < lost:
            return (f"; the revolution's torque {round(100 * ratio):d} % of the plan's for "
                    f"{self.lost_revolutions} revolutions (the whole cut lost: under the other "
                    f"flutes' {100 * lost:.0f} %)")  # fmt: skip
        return (f"; one flute: the revolution's torque {round(100 * ratio):d} % of the plan's, the "
                f"same flute {lag:+.3g} {self.unit} one revolution earlier")  # fmt: skip

    def _event(
        self,
        chunk: Chunk,
        at: int,
        period: int,
        first: int,
        x: float,
        expected: float,
        e1: float,
        l1: float,
        e2: float,
        l2: float,
        band: float,
        below: bool = False,
        signature: tuple[float, float] = (math.nan, math.nan),
        pattern: float = math.nan,
        drop: tuple[float, float] = (math.nan, math.nan),
    ) -> Event:
        sample = chunk.start + at
        t = chunk.t0_s + sample / chunk.sample_rate_hz
        tooth = period % self.n_flutes
        s = self._suffix
        values = {
            "tooth": float(tooth),
            "tooth_period": float(period),
            # NaN: confirmed by the flute pattern outside a run of violations (decision 1684)
            "first_violation_period": float(first) if first >= 0 else math.nan,
            f"tooth_avg_{s}": float(x),
            f"residual1_{s}": float(e1),
            f"limit1_{s}": float(l1),
            f"residual2_{s}": float(e2),
            f"limit2_{s}": float(l2),
        }
        if self.method == "virtual":
            values[f"expected_{s}"] = float(expected)
        if self.flute_signature:  # both known where the signature confirmed the alarm
            values["revolution_ratio"] = signature[0]
            values[f"same_flute_deviation_{s}"] = signature[1]
        if pattern == pattern:  # the flute pattern confirmed the alarm (decision 1684)
            values["pattern_evidence"] = pattern
        after = drop[0] == drop[0]  # a period after the violation completed the pair (1707)
        if after:
            values[f"violation_residual1_{s}"] = drop[0]
            values[f"violation_residual2_{s}"] = drop[1]
        if self.method != "dual":
            values[f"band_{s}"] = float(band)
        # the virtual and constant detectors confirm a violation over 3 tooth periods while the
        # *torque* stays out of its band (the residual that started the run need not still
        # exceed its limit at the third): the line states that torque against its reference;
        # the dual detector alarms where both residuals exceed their limits
        u = self.unit
        message = f"tool breakage ({self.method}): flute {tooth} at tooth period {period}"
        if self.method == "dual":
            at_prev = " at the violating period before" if after else ""
            r1, r2 = drop if after else (e1, e2)
            message += (f", |residual1| {abs(r1):.3g} > {l1:.3g} and |residual2| "
                        f"{abs(r2):.3g} > {l2:.3g} {u}{at_prev}")  # fmt: skip
        elif pattern == pattern:  # the flute pattern (decision 1684)
            message += (f": a broken flute's pattern, {pattern:.3g}σ ≥ {self.pattern_z:g}σ (the "
                        f"flute's drop against the other flutes and its own earlier "
                        f"revolutions); tooth average {x:.3g} {u} against {expected:.3g} "
                        f"expected, the revolution's torque {round(100 * signature[0]):d} % of "
                        f"the plan's")  # fmt: skip
        else:
            ref = "expected" if self.method == "virtual" else "reference"
            sign, side = ("-", "below") if below else ("±", "outside")
            if below:  # the plan's transient: its lowest torque over the timing window
                ref = "expected at least (the plan's transient)"
            if band > self.sigma_tb * expected * (1 + 1e-9):  # the noise floor (decision 1550)
                width = (f"{sign}{band:.3g} {u}, {self.noise_k:g}σ of the tooth average's noise, "
                         f"wider than {sign}{100 * self.sigma_tb:.0f} %")  # fmt: skip
            else:
                width = f"{sign}{100 * self.sigma_tb:.0f} %"
            message += (f": tooth average {x:.3g} {u} against {expected:.3g} {ref} ({side} "
                        f"{width}) since period {first}")  # fmt: skip
            if self.flute_signature:
                message += self._signature_text(*signature)
        if self.flute_check:
            message += ("; one flute's drop and the next flute's rise (it cut the broken "
                        "flute's chip)")  # fmt: skip
        nc_line = x_mm = y_mm = z_mm = None
        if self.plan is not None:
            row = int(
                self.plan.match(
                    np.array([[float(np.asarray(chunk.data[c])[at]) for c in self.tcp_channels]]),
                    from_row=max(self._row - 50, 0),
                )[0]
            )
            if row < 0:
                row = self._row
            # the N word, else the program line (a block without one read −1)
            nc_line = int(cnc_line(self.plan["nc_line"][row], self.plan["source_line"][row]))
            x_mm = float(self.plan["x_mm"][row])
            y_mm = float(self.plan["y_mm"][row])
            z_mm = float(self.plan["z_mm"][row])
        return Event(
            time_s=t,
            kind=EventKind.ALARM,
            source=self.name,
            message=message,
            name="breakage",
            value=float(tooth),
            sample=sample,
            severity=Severity.CRITICAL,
            values=values,
            nc_line=nc_line,
            x_mm=x_mm,
            y_mm=y_mm,
            z_mm=z_mm,
        )


class BreakageGroup(Block):
    """Several breakage detectors on one spindle-speed channel as one block: their tooth-period
    averages (Aslan Eq. 6.1, Munasinghe Eq. 3.43) in one compiled call per chunk
    (:func:`~millsense.monitoring._tooth_kernels.segment_group`), the per-period step of the
    detectors in which a period ends, and one dict of held outputs reused while none ends
    (decision 1536: the per-chunk Python work of three blocks in 10 ms chunks cost more than
    their compiled loops). Outputs and events are the members', unchanged.

    Parameters
    ----------
    members : breakage detectors with distinct names, one speed channel and flute count.
    name : block name.
    shown : the group's output channels are those of its first ``shown`` members (default:
        all); the others only judge and raise events (the extra phases of
        :class:`~millsense.monitoring.breakage_phased.PhasedBreakage`, decision 1552).
    """

    def __init__(
        self, members: Sequence[BreakageBlock], name: str = "breakage", shown: int | None = None
    ) -> None:
        if not members:
            raise ConfigError("breakage group: no detector")
        names = [m.name for m in members]
        if len(set(names)) != len(names):
            raise ConfigError(f"breakage group: detector names repeat: {names}")
        ref = members[0]
        for m in members[1:]:
            if (m.speed_channel, m.n_flutes) != (ref.speed_channel, ref.n_flutes):
                raise ConfigError(
                    f"breakage group: detector '{m.name}' reads another speed channel or flute "
                    f"count than '{ref.name}'"
                )
        self.members = list(members)
        self.shown = len(self.members) if shown is None else int(shown)
        if not (1 <= self.shown <= len(self.members)):
            raise ConfigError(f"breakage group: shown must be in 1..{len(self.members)}")
        self.name = name
        self.inputs = tuple(dict.fromkeys(c for m in members for c in m.inputs))
        # the channels averaged over tooth periods, and each detector's rows (a, b, expected)
        averaged = [_averaged(m) for m in members]
        chans = list(dict.fromkeys(c for row in averaged for c in row if c is not None))
        self._chans = tuple(chans)
        self._rows = np.array(
            [[-1 if c is None else chans.index(c) for c in row] for row in averaged],
            dtype=np.int64,
        )

    def output_channels(self) -> list[ChannelInfo]:
        return [c for m in self.members[: self.shown] for c in m.output_channels()]

    def reset(self, sample_rate_hz: float) -> None:
        ms = self.members
        for m in ms:
            m.reset(sample_rate_hz)
        # the members' state lives in rows of the group's packed arrays (one compiled call for
        # all, few arguments): fstate[j] = segment state, held outputs, params, detector state
        f = np.concatenate
        self._fstate = np.stack([f([m._seg, m._held, m._params, m._det]) for m in ms])
        self._istate = np.zeros((len(ms), _k.I_SIZE), dtype=np.int64)
        self._istate[:, _k.I_ROWS : _k.I_IPARAMS] = self._rows
        self._istate[:, _k.I_IPARAMS : _k.I_TWO] = np.stack([m._iparams for m in ms])
        self._istate[:, _k.I_TWO] = [len(m.signal_channels) == 2 for m in ms]
        self._istate[:, _k.I_FIRST] = -1
        for j, m in enumerate(ms):
            row = self._fstate[j]
            m._seg = row[_k.F_SEG : _k.F_HELD]
            m._held = row[_k.F_HELD : _k.F_PARAMS]
            m._params = row[_k.F_PARAMS : _k.F_DET]
            m._det = row[_k.F_DET :]
            m._iparams = self._istate[j, _k.I_IPARAMS : _k.I_TWO]
        self._planned = [(j, m) for j, m in enumerate(ms) if m.plan is not None
                         and m.expected_channel is None]  # fmt: skip
        self._counts = self._istate[:, _k.I_COUNT]  # views: periods ending in the chunk,
        self._firsts = self._istate[:, _k.I_FIRST]  # running violations, alarms
        self._alarms = self._istate[:, _k.I_ALARMS]
        for j, m in enumerate(ms):
            m._group_first = (self._firsts, j)
        self._names = tuple(c.name for c in self.output_channels())
        self._speed = ms[0].speed_channel
        self._fs = ms[0].fs
        self._flutes = ms[0].n_flutes
        self._n = -1
        self._held_views: HeldViews | None = None

    def _size(self, n: int) -> None:
        """Work arrays for chunks of ``n`` samples, shared with the members (rows)."""
        ms = self.members
        for m in ms:
            m._size(n)
        cap = max(m._pp.shape[1] for m in ms)
        self._pp = np.empty((len(ms), _k.PP_ROWS, cap))
        self._pi = np.empty((len(ms), _k.PI_ROWS, cap), dtype=np.int64)
        for j, m in enumerate(ms):
            pp, pi = self._pp[j], self._pi[j]
            m._pp, m._pi, m._pb = pp, pi[:2], pi[2:]
            m._bufs = (pp[0], pp[1], pp[2], pp[_k.PP_GATE], pp[_k.PP_FLOOR], pp[_k.PP_COUNT],
                       pi[0], pi[1])  # fmt: skip
        self._x = np.empty((len(self._chans), n))
        # (row, channel) pairs, copied per chunk
        self._x_rows = tuple(zip(self._x, self._chans, strict=True))
        self._values = np.empty((_k.OUT_ROWS * self.shown, n))  # the shown members' rows
        self._n = n

    def process(self, chunk: Chunk) -> BlockOutput:
        d = chunk.data
        n = len(d[self._speed])
        if n != self._n:
            self._size(n)
        x = self._x
        for row, c in self._x_rows:
            row[...] = d[c]
        speed = np.asarray(d[self._speed], dtype=np.float64)
        before = self._firsts.tolist()  # the members' running violations (``_group_first``)
        values = self._values  # the shown members' outputs if a period of theirs ends
        if self._planned:  # the plan is matched between the averages and the detection
            top = _k.segment_group(x, speed, self._fs, self._flutes, self._fstate,
                                   self._istate, self._pp, self._pi)  # fmt: skip
            total, changed = 0, False
            if top:
                for j, m in self._planned:
                    k = int(self._counts[j])
                    if k:
                        self._pp[j, 2, :k] = m._plan_expected(d, self._pi[j, 0, :k])
                total, changed = _k.periods_group(self._pp, self._pi, self._fstate,
                                                  self._istate, values, self.shown)  # fmt: skip
        else:  # one compiled call
            top, total, changed = _k.group_step(x, speed, self._fs, self._flutes, self._fstate,
                                                self._istate, self._pp, self._pi, values,
                                                self.shown)  # fmt: skip
        if changed:  # a shown member's period ended: its values from there on
            self._held_views = None
            self._values = np.empty_like(values)  # the outputs are the caller's now
            out = BlockOutput(dict(zip(self._names, values, strict=True)))
        else:  # the held values of every shown member (decision 1700)
            views = self._held_views
            if views is not None and views[0] == n:  # none changed since: the same views
                out = BlockOutput(dict(views[1]))
            else:
                shown = self._fstate[: self.shown, _k.F_HELD : _k.F_PARAMS].reshape(-1)
                self._held_views, held = held_views(self._names, shown, views, n)
                out = BlockOutput(held)
        if total:
            for j, m in enumerate(self.members):
                if self._alarms[j]:
                    out.events.extend(m._alarms(chunk, int(self._counts[j]), before[j]))
        return out


_KERNELS_READY = False


def compile_kernels() -> None:
    """Compile the tooth-period kernels, or load them from numba's cache, once per process and
    before a stream starts (decision 1547): a short dummy stream through one block and through
    a group. Without it the first chunk of a fresh installation compiles them, several seconds
    during which a paced on-line session falls behind real time, and its alarms with it
    (the dashboard's alarm 1.1 s after the break instead of 0.3 s, measured on a fresh clone)."""
    global _KERNELS_READY
    if _KERNELS_READY:
        return
    _KERNELS_READY = True
    fs, n = 10000.0, 2000
    data = {"a": np.ones(n), "b": np.ones(n), "e": np.ones(n),
            "s": np.full(n, 2 * math.pi * 1000.0 / 60.0)}  # fmt: skip
    two = BreakageBlock(2, "dual", signal_channels=("a", "b"), speed_channel="s",
                        expected_channel="e", name="warm-up")  # fmt: skip
    group = BreakageGroup([BreakageBlock(2, "virtual", signal_channels=("a",), speed_channel="s",
                                         expected_channel="e", floor_channel="e",
                                         name=f"warm-up-{j}")
                           for j in range(2)])  # fmt: skip
    for block in (two, group):
        block.reset(fs)
        block.process(Chunk(0, fs, 0.0, data))
    # a group with a plan matches it between its two calls (:meth:`BreakageGroup.process`)
    g = group
    _k.segment_group(g._x, data["s"], fs, 2, g._fstate, g._istate, g._pp, g._pi)
    _k.periods_group(g._pp, g._pi, g._fstate, g._istate, g._values, g.shown)


def _averaged(
    m: BreakageBlock,
) -> tuple[str, str | None, str | None, str | None, str | None]:
    """The channels a detector averages per tooth period: (a, b, expected, gate, floor),
    None where it has none (as :meth:`BreakageBlock._segment` reads them)."""
    sig = m.signal_channels
    b = sig[1] if len(sig) == 2 else None
    return sig[0], b, m.expected_channel, m.enable_channel, m.floor_channel


def check_speed(speed_rad_s: np.ndarray, channel: str) -> None:
    """One-line error if the spindle never turns (the tooth period is undefined)."""
    if not np.any(np.abs(speed_rad_s) > 1e-3):
        raise InputDataError(
            f"breakage: spindle speed channel '{channel}' is zero throughout; tooth periods "
            "are undefined"
        )


def make_breakage_virtual_block(**options: Any) -> Block:
    """Seed 000 virtual-threshold detector (needs ``n_flutes`` and ``plan`` or
    ``expected_channel``)."""
    return BreakageBlock(method="virtual", **options)


def make_breakage_constant_block(**options: Any) -> Block:
    """Classic constant-threshold detector (seed 000 Eq. 6.5; the V7 comparison)."""
    return BreakageBlock(method="constant", **options)


def make_breakage_dual_block(**options: Any) -> Block:
    """Seed 002 dual-residual detector (lag-1 and lag-N residuals, 2 × max over 5 revs)."""
    return BreakageBlock(method="dual", **options)
