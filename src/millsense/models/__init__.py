"""Shared physical models: what the simulator, identification and the estimators all
believe about friction (Coulomb/viscous, LuGre), modal state spaces (Aslan Eq. 3.13),
kinematics (3-axis, A/C trunnion, Aslan Eq. 3.35–3.51), drive plants (rigid, Yamada dual/triple
inertia ball screw) and the spindle drive's linear model (Aslan Ch. 5, App. E).

No simulation runs here; :mod:`millsense.simulator` integrates these models in time.
"""
