"""Reporting: what a person reads and watches (matplotlib, Markdown, HTML, MP4).

``run_report`` writes a run's Result.md and Result.html, ``diagnosis_report`` a diagnosis's
evidence, ``videos`` the rollout videos, ``plots`` the figures and ``format`` the Markdown and
HTML helpers they share.
"""
