"""Tune a coupled drive (:mod:`.truth_drive`) to resemble Yamada's ball-screw stages (issue 12).

Seed 001 prints no disturbance FRF; what it gives of machine B is the identified dual-inertia
model of Table 3-3 (J_rn = 5.2e-5 kg·m², M_tn = 6.6 kg, resonance 408 Hz, ζ_k ≈ 0.055 by
the digest's derivation from C_kn), the screw torsional mode of §3.4 (778.5 Hz, the notch
of Table 4-5) and the pitching mode at 1598 Hz (§3.4). The virtual machine is *tuned to
resemble* these, it is not them: the same :class:`~.truth_drive.CoupledDrive` as the Quaser
truth (motor, screw, nut–table, bed on its mount) with

- the inertias kept: J_m + J_s = J_rn (rotor + screw, Yamada Eq. 2-46 "incl. screw inertia"),
  J_s of a Ø15 mm × 350 mm steel screw with a disk-coupling hub, M_t = M_tn;
- a Ø15 × 5 ball screw fixed at both ends ("double anchor", Table 3-2), root Ø12.5 mm,
  bearing span 300 mm, table position 0 at mid-span, angular-contact bearings 150 N/µm;
- the bed (20 kg) on its mount standing in for the pitching mode of §3.4;

and chooses the coupling torsion k_c, the nut stiffness (through the total k(0)), the mount
stiffness k_b and the three motor-locked damping ratios by nonlinear least squares
(``scipy.optimize.least_squares``, deterministic start) on

    ``40·ln(f_k/f_target,k)`` and ``20·(ζ_k − ζ_target,k)``

for the three modes of the servo-off (motor-free) structure, whose undamped frequencies and
damping come from the eigenvalues of the plant at position 0. Targets: (408 Hz, 0.055),
(778.5 Hz, 0.02 — the old hand-built torsional mode's damping), (1598 Hz, 0.03 — chosen).
The fit error is written into the truth data file with the values.

Machine A (decision 1711) is fitted the same way on what Table 3-3 gives of it: J_rn = 3.8e-5
kg·m², M_tn = 6.2 kg, resonance 335 Hz with ζ_k ≈ 0.099 (the digest's derivation from C_kn).
The thesis gives A no torsional or structural mode; chosen: the same screw and disk coupling as
B (Table 3-2: Ø15 × 5 on both), so its torsion is B's 778.5 Hz moved by A's lighter rotor
(:func:`torsion_like_b_hz`, 849 Hz, ζ 0.02), and B's bed on its mount (1598 Hz, ζ 0.03). A's
screw is "single anchor" (Table 3-2): fixed at the motor end, free axially at the other
(``fixed-free``), nut 150 mm from the fixed bearing at position 0, so its axial stiffness
falls along the stroke.

Run ``python -m millsense.simulator.truth_fit_stage`` to refit and rewrite
``millsense/simulator/data/yamada-{a,b}-truth-mechanics.toml``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.optimize

from millsense.simulator.truth_drive import CoupledDrive, ScrewGeometry
from millsense.simulator.truth_fit import drive_to_toml

_E_STEEL = 210e9
_RHO_STEEL = 7850.0
W_FREQ = 40.0
W_ZETA = 20.0


@dataclass(frozen=True)
class StageTargets:
    """What the fit keeps and what it aims at for one Yamada stage (SI)."""

    name: str
    rotor_inertia: float  # J_rn, Table 3-3 (motor + screw)
    table_mass: float  # M_tn, Table 3-3
    lead_m: float
    efficiency: float
    screw_length_m: float
    screw_diameter_m: float
    root_diameter_m: float
    hub_inertia: float
    span_m: float
    offset_m: float
    support: Literal["fixed-fixed", "fixed-free"]
    bearing_stiffness_n_m: float
    base_mass: float
    mode_hz: tuple[float, ...]
    mode_zeta: tuple[float, ...]
    source: str


#: J_s of the Ø15 mm × 350 mm screw with its disk-coupling hub (both stages, Table 3-2) and the
#: motor-side inertia J_rn − J_s of stage B: the torsion of A is B's (§3.4, 778.5 Hz) moved by
#: A's lighter rotor (see :func:`torsion_like_b_hz`)
_J_SCREW = math.pi * _RHO_STEEL * 0.35 * 0.015**4 / 32.0 + 2.0e-6
_B_TORSION_HZ = 778.5


def torsion_like_b_hz(rotor_inertia: float) -> float:
    """Motor–screw torsion of a stage with B's screw and disk coupling and rotor+screw
    inertia ``rotor_inertia`` (J_rn), Hz: the two-inertia frequency ``√(k_c(1/J_m + 1/J_s))``
    with the k_c that puts B's at 778.5 Hz (Yamada §3.4), i.e.
    ``778.5·√((1/J_m + 1/J_s)/(1/J_m,B + 1/J_s))``, J_m = J_rn − J_s.

    Yamada gives machine A no torsional mode; A has the same Ø15 × 5 screw (Table 3-2) and a
    direct disk coupling as B (§3.1), so the coupling and screw torsion are taken as B's and
    only the motor's inertia differs (a choice, decision 1711).
    """
    inv_b = 1.0 / (5.2e-5 - _J_SCREW) + 1.0 / _J_SCREW
    inv = 1.0 / (rotor_inertia - _J_SCREW) + 1.0 / _J_SCREW
    return _B_TORSION_HZ * math.sqrt(inv / inv_b)


STAGES = {
    "yamada-a": StageTargets(
        name="yamada-a",
        rotor_inertia=3.8e-5,
        table_mass=6.2,
        lead_m=5e-3,
        efficiency=0.95,
        screw_length_m=0.35,
        screw_diameter_m=0.015,
        root_diameter_m=0.0125,
        hub_inertia=2.0e-6,
        span_m=0.30,
        offset_m=0.15,
        support="fixed-free",
        bearing_stiffness_n_m=150e6,
        base_mass=20.0,
        mode_hz=(335.0, round(torsion_like_b_hz(3.8e-5), 1), 1598.0),
        mode_zeta=(0.099, 0.02, 0.03),
        source="Yamada (2017) Table 3-3 (335 Hz, J_rn, M_tn, C_kn); torsion B's coupling with "
        "A's rotor (§3.4 scaled, chosen); bed as B's (chosen)",
    ),
    "yamada-b": StageTargets(
        name="yamada-b",
        rotor_inertia=5.2e-5,
        table_mass=6.6,
        lead_m=5e-3,
        efficiency=0.95,
        screw_length_m=0.35,
        screw_diameter_m=0.015,
        root_diameter_m=0.0125,
        hub_inertia=2.0e-6,
        span_m=0.30,
        offset_m=0.15,
        support="fixed-fixed",
        bearing_stiffness_n_m=150e6,
        base_mass=20.0,
        mode_hz=(408.0, 778.5, 1598.0),
        mode_zeta=(0.055, 0.02, 0.03),
        source="Yamada (2017) Table 3-3 (408 Hz, J_rn, M_tn, C_kn), §3.4 (778.5, 1598 Hz)",
    ),
}


def screw_inertia(t: StageTargets) -> float:
    """J_s = π·ρ·L·d⁴/32 of the screw shaft plus the coupling hub, kg·m²."""
    return math.pi * _RHO_STEEL * t.screw_length_m * t.screw_diameter_m**4 / 32.0 + t.hub_inertia


def free_modes(drive: CoupledDrive, position: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Undamped frequencies (Hz) and damping ratios of the motor-free structure at a load
    position, ascending; the rigid-body pair (zero eigenvalues) is left out."""
    lam = np.linalg.eigvals(drive.plant(position).a)
    lam = lam[(lam.imag > 0.0) & (np.abs(lam) > 1.0)]
    wn = np.abs(lam)
    order = np.argsort(wn)
    return wn[order] / (2.0 * math.pi), -lam.real[order] / wn[order]


class _Layout:
    """Maps the fit vector ``ln[k_c, k(0), k_b, ζ_1, ζ_2, ζ_3]`` to a drive."""

    def __init__(self, t: StageTargets) -> None:
        self.t = t
        self.rg = t.lead_m / (2.0 * math.pi)
        self.js = screw_inertia(t)
        self.jm = t.rotor_inertia - self.js
        if self.jm <= 0.0:
            raise ValueError(f"{t.name}: the screw inertia exceeds J_rn")
        self.ea = _E_STEEL * math.pi * t.root_diameter_m**2 / 4.0

    def start(self) -> np.ndarray:
        t = self.t
        w = [2.0 * math.pi * f for f in t.mode_hz]
        m_r = t.rotor_inertia / self.rg**2
        k_axial = w[0] ** 2 / (1.0 / m_r + 1.0 / t.table_mass)
        k_c = w[1] ** 2 / (1.0 / self.jm + 1.0 / self.js)
        k_b = t.base_mass * w[2] ** 2
        return np.log([k_c, k_axial, k_b, *t.mode_zeta])

    def drive(self, p: np.ndarray) -> CoupledDrive:
        t = self.t
        kc, k0, kb = np.exp(p[:3])
        zeta = tuple(float(z) for z in np.exp(p[3:]))
        probe = ScrewGeometry(
            self.ea, t.span_m, t.offset_m, t.support, 1e30, t.bearing_stiffness_n_m
        )
        rest = 1.0 / k0 - 1.0 / float(probe.stiffness(0.0))
        k_nut = 1.0 / max(rest, 1e-12)
        screw = ScrewGeometry(
            self.ea, t.span_m, t.offset_m, t.support, k_nut, t.bearing_stiffness_n_m
        )
        return CoupledDrive(
            kind="linear",
            transmission=self.rg,
            efficiency=t.efficiency,
            motor_inertia=self.jm,
            screw_inertia=self.js,
            coupling_stiffness=float(kc),
            table_mass=t.table_mass,
            base_mass=t.base_mass,
            base_stiffness=float(kb),
            attached_mass=(),
            attached_stiffness=(),
            damping_ratio=zeta,
            screw=screw,
            name=f"{t.name} x truth",
        )


def fit_stage(t: StageTargets, max_nfev: int = 300) -> CoupledDrive:
    """Least-squares fit of the stage (module docstring)."""
    lay = _Layout(t)
    f_t = np.asarray(t.mode_hz)
    z_t = np.asarray(t.mode_zeta)

    def residuals(p: np.ndarray) -> np.ndarray:
        f, z = free_modes(lay.drive(p))
        n = len(f_t)
        return np.concatenate([W_FREQ * np.log(f[:n] / f_t), W_ZETA * (z[:n] - z_t)])

    p0 = lay.start()
    lo, hi = p0 - 3.0, p0 + 3.0
    hi[3:] = math.log(0.5)
    sol = scipy.optimize.least_squares(residuals, p0, bounds=(lo, hi), max_nfev=max_nfev)
    return lay.drive(sol.x)


def fit_report(t: StageTargets, drive: CoupledDrive) -> dict[str, object]:
    """Fit errors of a drive against the stage's targets, and its frequencies over the stroke
    ends (±100 mm, Table 3-2's 200 mm stroke)."""
    n = len(t.mode_hz)
    f, z = free_modes(drive)
    f, z = f[:n], z[:n]
    f_lo = free_modes(drive, -0.1)[0][:n]
    f_hi = free_modes(drive, 0.1)[0][:n]
    err = 100.0 * (f / np.asarray(t.mode_hz) - 1.0)
    return {
        "source": t.source,
        "target_frequency_hz": list(t.mode_hz),
        "free_frequency_hz": [round(float(v), 3) for v in f],
        "frequency_error_pct": [round(float(v), 4) for v in err],
        "max_abs_frequency_error_pct": round(float(np.max(np.abs(err))), 4),
        "target_damping_ratio": list(t.mode_zeta),
        "free_damping_ratio": [round(float(v), 5) for v in z],
        "max_abs_damping_error": round(float(np.max(np.abs(z - np.asarray(t.mode_zeta)))), 5),
        "free_frequency_at_minus_100mm_hz": [round(float(v), 3) for v in f_lo],
        "free_frequency_at_plus_100mm_hz": [round(float(v), 3) for v in f_hi],
        "reflected_inertia_kg_m2": float(f"{drive.inertia:.6g}"),
        "table3_3_reflected_inertia_kg_m2": float(
            f"{t.rotor_inertia + t.table_mass * (t.lead_m / (2 * math.pi)) ** 2:.6g}"
        ),
    }


def main(argv: list[str] | None = None) -> int:
    """Refit the stage(s) and rewrite the mechanics file (``--print`` writes to stdout)."""
    args = sys.argv[1:] if argv is None else argv
    for name, t in STAGES.items():
        d = fit_stage(t)
        rep = fit_report(t, d)
        text = "\n".join(
            [
                f"# {name} truth: coupled lumped-mass feed drive (millsense.simulator.truth_drive)",
                "# GENERATED by `python -m millsense.simulator.truth_fit_stage`: the coupling",
                "# torsion, nut and mount stiffnesses and the locked-mode damping fitted so that",
                "# the motor-free modes sit on Yamada Table 3-3 / §3.4; [fit] holds the errors.",
                "# Units in the key names.",
                f'name = "{name}"',
                "",
                "[axes.x.mechanics]",
                drive_to_toml(d, rep).replace("{name}", "x"),
            ]
        )
        print(name, rep, flush=True)
        if "--print" in args:
            print(text)
        else:
            out = Path(__file__).resolve().parent / "data" / f"{name}-truth-mechanics.toml"
            out.write_text(text)
            print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
