"""The one Kalman toolkit every estimator uses (Aslan Ch. 3 and App. B, İlme Ch. 3).

- :mod:`.design` — models, augmentation with random-walk/harmonic disturbance states, ZOH and
  Van Loan discretisation, steady-state gains (DARE), compensated FRF and ±3 dB bandwidth;
- :mod:`.lti_filter` — frozen-gain filters run in numba (real modal form);
- :mod:`.smoother` — steady-state fixed-lag smoother (Aslan Appendix B);
- :mod:`.time_varying` — Kalman filter with a per-sample measurement matrix (İlme Eq. 3.14);
- :mod:`.block` — the streaming :class:`~millsense.streaming.block.Block`;
- :mod:`.rational_fit` — vector fitting of measured FRFs into state-space models.
"""
