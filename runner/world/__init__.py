"""The world: a scenario (its grid, regions and materials, the tasks' borders), the solids that
lay out a volume, and the sensors that read a material where the hand probes.

It knows nothing of how the next cell is chosen: attention, the experiments, the report and the
robot build on it.
"""
