"""The integrated online session (seed 000 ch. 6, seed 002 ch. 4–5): the virtual plan and
the on-line monitors side by side, arbitration of actions, the event log. To come (issue 16);
the streaming contract it runs on is :mod:`millsense.streaming`.
"""
