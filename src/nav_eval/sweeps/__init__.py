"""Sweeps: many seeds of one or more configurations on Ray Tune, with rliable statistics.

``spec`` says what a sweep runs and names its files, ``runner`` runs and aggregates it,
``trial`` is one trial's stages (training and evaluation in a child process, in a ROS domain
that ``domain`` reserves), ``tune`` the Ray Tune side and ``cluster`` the check before
attaching to a Ray cluster.  The aggregate is ``collect`` (the trials, grouped),
``statistics`` (rliable), ``report`` (Sweep.md, Sweep.html, results.json) and ``figures``.
"""
