"""Stability case files (TOML): loading, validation and conversion to SI.

Schema (documented with examples in ``examples/stability/README.md``); field units are in the
key names and converted once, here::

    [tool]        diameter_mm, flutes, pitch_deg (optional list, angle from each flute to the next)
    [cutting]     kt_n_mm2 (alias ktc_n_mm2), kr_n_mm2 (aliases kn_n_mm2, krc_n_mm2)
    [operation]   mode = "down" | "up", radial_immersion_mm (0 < a <= diameter_mm)
    [[structure.x]], [[structure.y]]  modes: natural_frequency_hz, damping_ratio and one of
                  stiffness_n_m, modal_mass_kg or residue_alpha_m_n_s2 (+ residue_beta_m_n_s,
                  Aslan Eq. 3.13)
    [lobes]       rpm_min, rpm_max, rpm_step, depth_max_mm, steps_per_period, method

A bad file raises :class:`~millsense.core.errors.ConfigError` with one line naming the file,
the key and the allowed range.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import AliasChoices, BaseModel, ConfigDict, Field

from millsense.core import units
from millsense.core.config import parse_config, read_toml
from millsense.core.errors import ConfigError
from millsense.stability.modal import ModalModel, Mode

#: Allowed values of the cross-field checks, quoted in their error messages (single-field
#: ranges come from the pydantic constraints through core.config's formatter).
PITCH_ALLOWED = "one angle per flute, each in (0, 360), summing to 360"
#: Most spindle speeds in one chart (each needs a depth scan of ~50 spectral radii; minima
#: are refined to 1 rev/min anyway, so finer charts add nothing; decision 0906).
MAX_SPEEDS = 4001


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


class ModeSpec(_Model):
    """One mode: natural frequency, damping and stiffness or residues (Aslan Eq. 3.13)."""

    natural_frequency_hz: Annotated[float, Field(gt=0, le=1e5)]
    # an undamped mode chatters at a vanishing depth at its lobe speeds (decision 0906)
    damping_ratio: Annotated[float, Field(ge=1e-4, lt=1)]
    # tool-tip modal stiffness of real machines: 1e4..1e10 N/m (decision 0906)
    stiffness_n_m: Annotated[float, Field(ge=1e3, le=1e11)] | None = None
    modal_mass_kg: Annotated[float, Field(ge=1e-5, le=1e5)] | None = None
    residue_alpha_m_n_s2: Annotated[float, Field(gt=0, le=1e6)] | None = None
    residue_beta_m_n_s: float = 0.0

    def to_mode(self) -> Mode:
        if self.stiffness_n_m is not None:
            return Mode.from_stiffness(
                self.natural_frequency_hz, self.damping_ratio, self.stiffness_n_m
            )
        if self.modal_mass_kg is not None:
            # residue form α = 1/m (Aslan Eq. 3.13, mass-normalised mode)
            return Mode.from_residues(
                self.natural_frequency_hz, self.damping_ratio, 1.0 / self.modal_mass_kg
            )
        assert self.residue_alpha_m_n_s2 is not None
        return Mode.from_residues(
            self.natural_frequency_hz,
            self.damping_ratio,
            self.residue_alpha_m_n_s2,
            self.residue_beta_m_n_s,
        )


class StructureSpec(_Model):
    x: list[ModeSpec] = Field(default_factory=list)
    y: list[ModeSpec] = Field(default_factory=list)


class ToolSpec(_Model):
    diameter_mm: Annotated[float, Field(gt=0, le=500)]
    flutes: Annotated[int, Field(ge=1, le=16)]
    pitch_deg: list[Annotated[float, Field(gt=0, lt=360)]] | None = None


class CuttingSpec(_Model):
    kt_n_mm2: Annotated[
        float, Field(gt=0, le=20000, validation_alias=AliasChoices("kt_n_mm2", "ktc_n_mm2"))
    ]
    kr_n_mm2: Annotated[
        float,
        Field(ge=0, le=20000, validation_alias=AliasChoices("kr_n_mm2", "kn_n_mm2", "krc_n_mm2")),
    ]


class OperationSpec(_Model):
    mode: Literal["down", "up"]
    radial_immersion_mm: Annotated[float, Field(gt=0)]


class LobesSpec(_Model):
    rpm_min: Annotated[float, Field(gt=0)] = 5000.0
    rpm_max: Annotated[float, Field(gt=0, le=200000)] = 25000.0
    rpm_step: Annotated[float, Field(gt=0)] = 100.0
    depth_max_mm: Annotated[float, Field(gt=0, le=1000)] = 20.0
    steps_per_period: Annotated[int, Field(ge=4, le=2000)] = 20
    steps_per_cycle: Annotated[float, Field(ge=0, le=200)] = 10.0
    extrapolate: bool = True
    method: Literal["sdm", "zoa"] = "sdm"


class CaseSpec(_Model):
    name: str = ""
    description: str = ""
    tool: ToolSpec
    cutting: CuttingSpec
    operation: OperationSpec
    structure: StructureSpec
    lobes: LobesSpec = Field(default_factory=LobesSpec)


@dataclass(frozen=True)
class MillingStabilityCase:
    """A milling stability problem in SI units.

    Attributes
    ----------
    name : case name.
    structure : modes in x and y.
    flutes : N.
    kt, kr : cutting coefficients [N/m²].
    phi_st, phi_ex : engagement window [rad].
    pitch : pitch angles [rad] or None (uniform).
    rpm : default speed grid [rev/min].
    depth_max : largest depth searched [m].
    steps_per_period : SDM steps per tooth period (at least).
    steps_per_cycle : SDM steps per cycle of the fastest motion at least
        (:func:`millsense.stability.lobes.sdm_lobes`).
    extrapolate : Richardson extrapolation from m and 2m.
    method : "sdm" or "zoa".
    """

    name: str
    structure: ModalModel
    flutes: int
    kt: float
    kr: float
    phi_st: float
    phi_ex: float
    pitch: tuple[float, ...] | None
    rpm: np.ndarray
    depth_max: float
    steps_per_period: int
    steps_per_cycle: float
    extrapolate: bool
    method: str

    @property
    def natural_frequencies_hz(self) -> list[float]:
        return [md.natural_frequency_hz for md in self.structure.modes]


def load_case(path: str | Path) -> MillingStabilityCase:
    """Read and validate a stability case file; everything converted to SI.

    Raises
    ------
    ConfigError
        One line naming the file, the key and the allowed range.
    """
    p = Path(path)
    spec = parse_config(CaseSpec, read_toml(p), str(p))
    return case_from_spec(spec, str(p))


def _fail(source: str, key: str, value: object, allowed: str) -> ConfigError:
    return ConfigError(f"{source}: key '{key}' = {value!r} is out of range; allowed: {allowed}")


def case_from_spec(spec: CaseSpec, source: str) -> MillingStabilityCase:
    """Cross-field checks and conversion of a parsed case to SI."""
    D = spec.tool.diameter_mm
    a = spec.operation.radial_immersion_mm
    if not 0 < a <= D:
        raise _fail(
            source, "operation.radial_immersion_mm", a, f"0 < value <= tool.diameter_mm = {D:g}"
        )
    for d, modes in (("x", spec.structure.x), ("y", spec.structure.y)):
        for i, md in enumerate(modes):
            given = [
                k
                for k in ("stiffness_n_m", "modal_mass_kg", "residue_alpha_m_n_s2")
                if getattr(md, k) is not None
            ]
            if len(given) != 1:
                raise ConfigError(
                    f"{source}: structure.{d}[{i}]: give exactly one of 'stiffness_n_m', "
                    "'modal_mass_kg' or 'residue_alpha_m_n_s2'"
                )
            if md.modal_mass_kg is not None and md.residue_beta_m_n_s != 0.0:
                raise ConfigError(
                    f"{source}: structure.{d}[{i}]: 'residue_beta_m_n_s' needs "
                    "'residue_alpha_m_n_s2', not 'modal_mass_kg'"
                )
            k_eff = md.to_mode().stiffness  # ω²/α [N/m]
            if not 1e3 <= k_eff <= 1e11:
                raise _fail(
                    source,
                    f"structure.{d}[{i}]",
                    f"stiffness (2π f_n)²·m = {k_eff:.3g} N/m",
                    "a modal stiffness in [1e3, 1e11] N/m",
                )
    if not spec.structure.x and not spec.structure.y:
        raise ConfigError(
            f"{source}: key 'structure' has no modes; "
            "allowed: at least one [[structure.x]] or [[structure.y]]"
        )
    pitch = spec.tool.pitch_deg
    if pitch is not None and (len(pitch) != spec.tool.flutes or abs(sum(pitch) - 360.0) > 1e-6):
        raise _fail(source, "tool.pitch_deg", pitch, PITCH_ALLOWED)
    lb = spec.lobes
    if lb.rpm_min >= lb.rpm_max:
        raise _fail(
            source, "lobes.rpm_min", lb.rpm_min, f"0 < value < lobes.rpm_max = {lb.rpm_max:g}"
        )
    from millsense.stability.milling import immersion_angles

    phi_st, phi_ex = immersion_angles(a * units.MM, D * units.MM, spec.operation.mode)
    pitch_rad = None if pitch is None else tuple(v * units.DEG for v in pitch)
    if pitch_rad is not None:
        s = sum(pitch_rad)
        pitch_rad = tuple(v * 2 * math.pi / s for v in pitch_rad)  # exact closure
    n_speeds = math.floor((lb.rpm_max - lb.rpm_min) / lb.rpm_step + 0.5) + 1
    if n_speeds > MAX_SPEEDS:
        raise _fail(
            source,
            "lobes.rpm_step",
            lb.rpm_step,
            f">= (rpm_max - rpm_min)/{MAX_SPEEDS - 1} = "
            f"{(lb.rpm_max - lb.rpm_min) / (MAX_SPEEDS - 1):.4g} rev/min "
            f"(at most {MAX_SPEEDS} speeds per chart)",
        )
    rpm = np.arange(lb.rpm_min, lb.rpm_max + 0.5 * lb.rpm_step, lb.rpm_step)
    return MillingStabilityCase(
        name=spec.name or Path(source).stem,
        structure=ModalModel(
            x=tuple(m.to_mode() for m in spec.structure.x),
            y=tuple(m.to_mode() for m in spec.structure.y),
        ),
        flutes=spec.tool.flutes,
        kt=spec.cutting.kt_n_mm2 * units.N_PER_MM2,
        kr=spec.cutting.kr_n_mm2 * units.N_PER_MM2,
        phi_st=phi_st,
        phi_ex=phi_ex,
        pitch=pitch_rad,
        rpm=rpm,
        depth_max=lb.depth_max_mm * units.MM,
        steps_per_period=lb.steps_per_period,
        steps_per_cycle=lb.steps_per_cycle,
        extrapolate=lb.extrapolate,
        method=lb.method,
    )


def compute_lobes(
    case: MillingStabilityCase,
    method: str | None = None,
    rpm: np.ndarray | None = None,
    steps_per_period: int | None = None,
    extrapolate: bool | None = None,
    progress: Callable[[int], None] | None = None,
    robust: bool = True,
    refine_minima: bool = True,
    bands_up_to: float | None = None,
    tol: float | None = None,
) -> Any:
    """Lobe diagram of a case (:class:`millsense.stability.lobes.LobeResult`).

    Parameters default to the case file's ``[lobes]`` table. SDM charts use the robust search
    of :mod:`millsense.stability.robust` (a :class:`~millsense.stability.robust.RobustLobeResult`
    with bands, tolerances and refined minima); ``robust=False`` gives the earlier
    continuation search (:func:`millsense.stability.lobes.sdm_lobes`), kept as the baseline
    of the benchmarks. ``bands_up_to``: islands searched up to this multiple of the limit
    (default 3 for a chart, all of ``depth_max`` for a single speed).
    """
    from millsense.stability.lobes import sdm_lobes
    from millsense.stability.milling import milling_dde
    from millsense.stability.robust import TOLERANCE, robust_lobes
    from millsense.stability.zoa import zoa_lobes

    meth = method or case.method
    speeds = case.rpm if rpm is None else np.asarray(rpm, dtype=float)
    if meth == "zoa":
        if case.pitch is not None:
            raise ConfigError(f"{case.name}: method 'zoa' supports uniform pitch only; use 'sdm'")
        res = zoa_lobes(
            case.structure, case.flutes, case.kt, case.kr, case.phi_st, case.phi_ex, speeds
        )
        if progress is not None:
            for i in range(len(speeds)):
                progress(i)
        return res
    if meth != "sdm":
        raise ConfigError(f"--method {meth!r}: allowed 'sdm' or 'zoa'")

    def family_at(n: float, m: int) -> Any:
        return milling_dde(
            case.structure,
            case.flutes,
            case.kt,
            case.kr,
            case.phi_st,
            case.phi_ex,
            n,
            m,
            case.pitch,
        )

    def compliance(f: np.ndarray) -> np.ndarray:
        return np.asarray(np.abs(case.structure.frf(f)).max(axis=(-2, -1)))

    if robust:
        single = speeds.size == 1
        up_to = bands_up_to if bands_up_to is not None else (math.inf if single else 3.0)
        return robust_lobes(
            family_at,
            speeds,
            2.0 * max(case.natural_frequencies_hz),
            steps_per_period or case.steps_per_period,
            depth_max=case.depth_max,
            steps_per_cycle=case.steps_per_cycle,
            extrapolate=case.extrapolate if extrapolate is None else extrapolate,
            tol=TOLERANCE if tol is None else tol,
            bands_up_to=up_to,
            refine_minima=refine_minima and not single,
            progress=progress,
        )
    return sdm_lobes(
        family_at,
        speeds,
        compliance,
        2.0 * max(case.natural_frequencies_hz),
        steps_per_period or case.steps_per_period,
        depth_max=case.depth_max,
        extrapolate=case.extrapolate if extrapolate is None else extrapolate,
        progress=progress,
        steps_per_cycle=case.steps_per_cycle,
    )
