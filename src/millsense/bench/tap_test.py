"""The tool's tap test, identified: the chatter avoidance's lobes from a measurement of the
plant, not from its table (issue 12, decision 1750).

The virtual machine's tool is tapped at rest along x and y
(:func:`millsense.simulator.tap_test.tap_test`: hammer and accelerometer records with the
noise and the errors of a real test); each direction is analysed as a shop does (seed 000
Ch. 4: tap tests at the tool tip, curve fitting over 200-1800 Hz):

1. H1 over the hits with its coherence (:func:`millsense.ident.frf.impact_frf`, force and
   exponential windows; Bendat & Piersol §9.1), accelerance [(m/s²)/N];
2. receptance = accelerance / (iω + 1/τ)² [m/N] (:func:`receptance`: the exponential
   window's shift 1/τ included);
3. modes in the band from the stabilisation diagram up to 8 pole pairs
   (:func:`millsense.ident.modal_fit.fit_modes`, relaxed vector fitting weighted by the H1
   random error, Bendat & Piersol Eq. 9.90; the exponential window's pole shift removed), in
   the residue form of Aslan Eq. 3.13 (α, β): the x and y modes of the controller's
   :class:`~millsense.stability.modal.ModalModel`.

The fitted structure is cached in the process and on disk (:mod:`millsense.core.disk_cache`,
keyed by the truth's table, the test's options and the code), so ``make demo`` pays the
test once (2-3 s; more on a loaded machine, where multi-threaded BLAS slows the fit's small
least-squares problems) and reads it in about 1 ms afterwards.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from millsense.core import disk_cache
from millsense.ident.frf import FrfEstimate, impact_frf
from millsense.ident.modal_fit import ModalFit, fit_modes
from millsense.simulator.process_coupling import ToolModes
from millsense.simulator.tap_test import TapRecord, TapTestOptions, tap_test
from millsense.stability.cases import MillingStabilityCase
from millsense.stability.modal import ModalModel, Mode

__all__ = [
    "BAND_HZ",
    "MAX_MODES",
    "RECORD_S",
    "TapFit",
    "identify",
    "receptance",
    "tap_test_fits",
    "tap_tested_case",
    "tap_tested_structure",
]

#: Fitting band [Hz] (seed 000 Ch. 4: curve fitting over 200-1800 Hz).
BAND_HZ = (200.0, 1800.0)
#: Analysed record per hit [s] (2 Hz lines).
RECORD_S = 0.5
#: Largest order of the stabilisation diagram: a tool tip has a handful of modes in the band
#: (T1: three per direction); 8 pairs leave room for noise and out-of-band poles, and cost
#: 0.1 s where fit_modes' default 16 costs 5-20 s for the same modes.
MAX_MODES = 8
_CACHE_NAMESPACE = "tap-test-fit"


@dataclass(frozen=True)
class TapFit:
    """One direction's test analysed: the receptance H1 (with coherence) and its modal fit."""

    direction: str
    frf: FrfEstimate
    fit: ModalFit

    @property
    def modes(self) -> tuple[Mode, ...]:
        """The identified modes in the band (Aslan Eq. 3.13, α and β)."""
        return tuple(self.fit.to_modes())


def receptance(est: FrfEstimate) -> FrfEstimate:
    """An accelerance estimate [(m/s²)/N] as receptance [m/N].

    Divided by (iω + 1/τ)², not (iω)²: the exponential window of an impact test turns the
    accelerance A(s) = s² H(s) into A(s + 1/τ) = (s + 1/τ)² H(s + 1/τ), so this gives the
    windowed receptance H(iω + 1/τ) whose poles the modal fit shifts back by 1/τ
    (``pole_shift_rad_s``). Dividing by (iω)² would leave a phase error 2/(ωτ) that biases a
    well-damped mode (T1's 282 Hz, ζ = 5.3 %: stiffness −1.9 % on noiseless records).
    """
    s = 2j * np.pi * est.freq_hz + est.pole_shift_rad_s
    return replace(est, h1=est.h1 / s**2, h2=est.h2 / s**2)


def identify(
    record: TapRecord, band_hz: tuple[float, float] = BAND_HZ, record_s: float = RECORD_S
) -> TapFit:
    """H1 of one direction's hits, as receptance, and its modes in ``band_hz`` (module notes)."""
    est = impact_frf(
        record.force_n,
        record.accel_m_s2,
        record.sample_rate_hz,
        record_s=record_s,
        names=("hammer", f"accel/{record.direction}"),
    )
    rec = receptance(est)
    return TapFit(record.direction, rec, fit_modes(rec, band_hz, max_modes=MAX_MODES))


def tap_test_fits(
    truth: ToolModes, opts: TapTestOptions = TapTestOptions()
) -> tuple[TapFit, TapFit]:
    """Tap the truth's tool at rest along x and along y and identify each direction."""
    x = identify(tap_test(truth.x, truth.y, "x", opts))
    y = identify(tap_test(truth.y, truth.x, "y", opts))
    return x, y


def _key(truth: ToolModes) -> tuple[tuple[float, ...], ...]:
    rows = []
    for d in (truth.x, truth.y):
        rows.append(tuple(float(v) for v in d.natural_hz))
        rows.append(tuple(float(v) for v in d.damping_ratio))
        rows.append(tuple(float(v) for v in d.stiffness_n_per_m))
    return tuple(rows)


@functools.lru_cache(maxsize=16)
def _structure(
    key: tuple[tuple[float, ...], ...], opts: TapTestOptions
) -> tuple[tuple[tuple[float, ...], ...], ...]:
    """Per direction (x, y) the fitted modes as (ω, ζ, α, β), from the disk cache or the test."""
    digest = disk_cache.key_digest(
        key,
        repr(opts),
        BAND_HZ,
        RECORD_S,
        MAX_MODES,
        disk_cache.code_digest(
            __name__,
            tap_test.__module__,
            impact_frf.__module__,
            fit_modes.__module__,
            "millsense.models.modal_ss",
        ),
    )
    hit = disk_cache.load(_CACHE_NAMESPACE, digest)
    if hit is not None and {"x", "y"} <= set(hit):
        return tuple(tuple(tuple(float(v) for v in m) for m in hit[d]) for d in ("x", "y"))
    from millsense.stability.time_domain import DirectionModes

    dirs = [DirectionModes.from_arrays(*key[i : i + 3]) if key[i] else DirectionModes.rigid()
            for i in (0, 3)]  # fmt: skip
    fits = tap_test_fits(ToolModes(dirs[0], dirs[1]), opts)
    out = tuple(tuple((m.omega, m.zeta, m.alpha, m.beta) for m in f.modes) for f in fits)
    disk_cache.store(_CACHE_NAMESPACE, digest, {"x": out[0], "y": out[1]})
    return out


def tap_tested_structure(truth: ToolModes, opts: TapTestOptions = TapTestOptions()) -> ModalModel:
    """The controller's structure: the modes fitted to the simulated tap tests of the truth's
    tool at rest, x and y (cached in the process and on disk)."""
    x, y = _structure(_key(truth), opts)
    return ModalModel(x=tuple(Mode(*m) for m in x), y=tuple(Mode(*m) for m in y))


def tap_tested_case(
    case: MillingStabilityCase, truth: ToolModes, opts: TapTestOptions = TapTestOptions()
) -> MillingStabilityCase:
    """``case`` with its structure replaced by the tap-tested one (the cutting coefficients,
    engagement and lobe settings are the case's)."""
    return replace(case, structure=tap_tested_structure(truth, opts))
