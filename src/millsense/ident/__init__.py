"""System identification: from recordings to the models the estimators need.

FRF estimation (:mod:`millsense.ident.frf`), automated modal fitting
(:mod:`millsense.ident.modal_fit`), friction (:mod:`millsense.ident.friction`: Coulomb +
viscous, LuGre static parameters, presliding, spindle), drive parameters and dead times
(:mod:`millsense.ident.drive`), the spindle's residual modes and G_dτ
(:mod:`millsense.ident.spindle`), the idling disturbance table
(:mod:`millsense.ident.idle_table`) and TOML configuration fragments
(:mod:`millsense.ident.fragment`). Simulated commissioning tests are in
:mod:`millsense.simulator.commissioning`; the CLI is ``millsense identify``.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

#: Public names → their module. Loaded on first use (PEP 562): ``millsense.ident.idle_table``
#: and the other light submodules do not pay for scipy.signal and the modal fit (≈ 0.6 s) in
#: every process that imports them (each batch worker, ``estimate``).
_WHERE = {
    **dict.fromkeys(
        ("FrfEstimate", "ImpactHit", "check_records", "chirp_signal", "frf_from_recording",
         "h1_random_error", "impact_frf", "multisine_frf", "multisine_signal",
         "stepped_sine_frf", "stepped_sine_signal", "welch_frf"),
        "millsense.ident.frf",
    ),
    **dict.fromkeys(
        ("FittedMode", "ModalFit", "StabilisationDiagram", "fit_batch", "fit_modes",
         "vector_fit"),
        "millsense.ident.modal_fit",
    ),
}  # fmt: skip


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'millsense.ident' has no attribute {name!r}")
    value = getattr(import_module(where), name)
    globals()[name] = value
    return value


__all__ = [
    "FittedMode",
    "FrfEstimate",
    "ImpactHit",
    "ModalFit",
    "StabilisationDiagram",
    "check_records",
    "chirp_signal",
    "fit_batch",
    "fit_modes",
    "frf_from_recording",
    "h1_random_error",
    "impact_frf",
    "multisine_frf",
    "multisine_signal",
    "stepped_sine_frf",
    "stepped_sine_signal",
    "vector_fit",
    "welch_frf",
]
