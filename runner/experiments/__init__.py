"""Experiments: the step loop and its seeds, an experiment file and its runs, where the runs
are stored (chunks, resumable), the processes and Dask clusters that compute them, what a run
measures (Gamma, visits, moves) and the search of cue profiles (``bayesprog tune``).

It drives attention on the world; it knows nothing of the report or the robot.
"""
