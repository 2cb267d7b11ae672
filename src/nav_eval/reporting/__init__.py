"""Reporting: what a person reads and watches (matplotlib, Markdown, HTML, MP4).

A run's report is made in order: ``run_inputs`` reads the run directory, ``run_figures`` draws
the figures and ``videos`` encodes the rollout videos, then ``run_report`` builds the sections'
text and writes Result.md and Result.html (``closed_loop`` is the closed-loop section).
``diagnosis_report`` writes a diagnosis's evidence, ``plots`` draws the figures and ``format``
holds the Markdown and HTML helpers they share.
"""
