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

from millsense.ident.frf import (
    FrfEstimate,
    ImpactHit,
    check_records,
    chirp_signal,
    frf_from_recording,
    h1_random_error,
    impact_frf,
    multisine_frf,
    multisine_signal,
    stepped_sine_frf,
    stepped_sine_signal,
    welch_frf,
)
from millsense.ident.modal_fit import (
    FittedMode,
    ModalFit,
    StabilisationDiagram,
    fit_batch,
    fit_modes,
    vector_fit,
)

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
