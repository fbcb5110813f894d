"""The report: statistics and verdicts of a stored experiment, its figures (paper Figs. 9, 10,
11), report.md and report.html, the runs as one table, the notebook views, and what a search of
profiles reports (tune.md and its figures).

It reads what the experiments stored; nothing below it imports it.
"""
