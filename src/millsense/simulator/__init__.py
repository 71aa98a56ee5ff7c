"""The virtual machine tool: closed-loop simulation of feed drives, spindle, structure and
cutting process producing the signals a CNC would (with ground truth under ``truth/``), and the
simulated commissioning tests run on it (seed 000 ch. 3 and 5, seed 001).

Estimation, monitoring and control never import this package (import-linter contract).
"""
