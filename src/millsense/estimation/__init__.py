"""millsense.estimation: estimators of cutting forces and torque from CNC and sensor signals.

Kalman toolkit shared by every estimator (issue 7 item 1):

- :mod:`~millsense.estimation.kalman` — models, augmentation with disturbance states, ZOH and
  Van Loan discretisation, steady-state gains (DARE), compensated FRF and ±3 dB bandwidth;
- :mod:`~millsense.estimation.lti_filter` — frozen-gain filters run in numba (real modal form);
- :mod:`~millsense.estimation.smoother` — steady-state fixed-lag smoother (Aslan Appendix B);
- :mod:`~millsense.estimation.kalman_tv` — Kalman filter with a per-sample measurement matrix
  (İlme);
- :mod:`~millsense.estimation.kalman_block` — the streaming :class:`~millsense.online.block.Block`.
"""
