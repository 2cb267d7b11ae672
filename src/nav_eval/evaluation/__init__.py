"""Evaluation: run policies on seeded scenarios and record their episodes (imports no reporting).

``sets`` names what to evaluate, ``runner`` plays the episodes through the run's own env and writes
the results and traces, ``selection`` picks the episode a diagnosis looks at, ``policies`` are the
frozen DQN and the scripted policies (on nav_gym's one acting protocol), ``baselines`` runs the
scripted ones on both banks, ``closed_loop`` and ``realtime`` evaluate the policy node driving a
realtime sim.  The numbers (outcomes, SPL, summaries) are :mod:`nav_eval.analysis.metrics`.
"""
