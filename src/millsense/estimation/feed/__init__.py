"""Feed-drive force estimation (Aslan Ch. 3: C2–C9, Eq. 3.1–3.51).

- :mod:`.rigid_body` — C3 inverse dynamics (Eq. 3.10) and the raw estimate;
- :mod:`.estimator` — disturbance Kalman filter over the identified Φ_d, tooth-harmonic states
  (Eq. 3.16–3.20), smoother, forces at the tool on the trunnion (Eq. 3.51);
- :mod:`.path_fit` — identification of Φ_d from a table-load sweep (C5);
- :mod:`.tuning` — R from air cuts, Q for the widest band or least noise (Eq. 3.28–3.30);
- :mod:`.schedule`, :mod:`.condition` — position-scheduled and moving/at-rest estimators;
- :mod:`.commanded`, :mod:`.idle_compensation` — commanded velocity, idle-load subtraction.

The thesis's printed designs (Table 3.4, Eq. 3.30) live with the validation cases' design checks
(:mod:`millsense.validation.cases._thesis_models`, decision 1790): they are the simulator's data,
not the estimators'.
"""
