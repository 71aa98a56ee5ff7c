"""Force from acceleration: İlme's angular-harmonic Kalman filter (seed 003,
:mod:`.harmonic_kf`) and Aslan Ch. 4 multi-sensor fusion (:mod:`.fusion`).
"""
