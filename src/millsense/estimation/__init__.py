"""millsense.estimation: estimators of cutting forces and torque from CNC and sensor signals.

Families (each a subpackage whose ``__init__`` says what is inside and which seed it implements):

- :mod:`~millsense.estimation.kalman` — the one Kalman toolkit (design, steady-state filters,
  fixed-lag smoother, time-varying filter, the streaming block, rational fits);
- :mod:`~millsense.estimation.feed` — feed-drive force estimation (Aslan Ch. 3);
- :mod:`~millsense.estimation.dob` — disturbance observers on ball-screw drives (Yamada);
- :mod:`~millsense.estimation.accel` — force from acceleration (İlme; Aslan Ch. 4 fusion);
- :mod:`~millsense.estimation.spindle_observer` — the spindle torque observer (Aslan Ch. 5);
- :mod:`~millsense.estimation.from_config` — estimator pipelines from a machine file.

Estimators never import the simulator (:mod:`millsense.simulator`) or the acceptance bench
(:mod:`millsense.bench`); shared physical models come from :mod:`millsense.models`.
"""
