"""Disturbance observers on ball-screw drives (Yamada, seed 001 Ch. 2–4): DOB and the
multi-encoder MEDOB (:mod:`.observers`), phase-lag compensation (:mod:`.phase_lag`), the
mode-decoupled vibration estimator (:mod:`.mode_decoupled`) and predictive notches (:mod:`.notch`).
"""
