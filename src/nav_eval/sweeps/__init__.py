"""Sweeps: many seeds of one or more configurations on Ray Tune, with rliable statistics.

``spec`` says what a sweep runs and names its files, ``runner`` runs and aggregates it,
``trial`` is one trial's stages (training and evaluation in a child process), ``tune`` the Ray
Tune side, ``report`` and ``figures`` the aggregate (Sweep.md, results.json, PNGs).
"""
