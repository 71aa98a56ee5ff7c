"""Issue 12's review criterion (second audit, 2026-11-28): a case whose estimator shares its
plant's parameters by design says so where docs/validation.md shows it, its description."""

from __future__ import annotations

from millsense.validation.registry import select_cases

#: Identification cases that run the simulator file's model (ideal) or Aslan's Ch. 5 spindle
#: model with that model's own K_t, J, gains, lead or current loop: algorithm checks against
#: printed values, not acceptances of an estimator on a machine.
ALGORITHM_CHECKS = (
    "ident.friction_*",
    "ident.drive_yamada_*",
    "ident.idle_table_yamada_*",
    "ident.spindle_friction_worst",
    "ident.spindle_gdtau_db",
)


def test_identification_on_the_file_model_is_labelled_an_algorithm_check() -> None:
    seen = 0
    for pattern in ALGORITHM_CHECKS:
        for c in select_cases(pattern):
            seen += 1
            assert c.description.startswith("Algorithm check on "), c.id
    # 4 friction, 5 drive (2 machines × params/dead times + A's T1), 2 idle, 2 spindle
    assert seen == 13


#: Estimation cases whose plant is the estimator's (or observer's) own model by design (decision
#: 1790): design and code checks, reported "pass (self-check)", never plain passes.
DESIGN_CHECKS = (
    "estimation.kalman_*",
    "estimation.dob.medob_frf_*",
    "estimation.feed_robust_band_at_lti_limit",
)


def test_estimation_design_checks_are_self_checks() -> None:
    seen = 0
    for pattern in DESIGN_CHECKS:
        for c in select_cases(pattern):
            seen += 1
            assert c.self_check, c.id
    # 3 Kalman (C band, C and A flatness), 2 MEDOB FRF, 1 robust band
    assert seen == 6


def test_every_estimation_case_declared_by_design_is_a_self_check() -> None:
    for c in select_cases("estimation.*"):
        d = c.description
        if "by design" in d and not d.startswith("Algorithm check on "):
            assert c.self_check, c.id
