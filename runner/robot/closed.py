"""``bayesprog robot SCENARIO --physics --task T --steps N --seed S [--json]``: the closed loop
in one process: the explorer decides, the simulated fingertip probes (MuJoCo), for N probes.

The robot is run R of an experiment of seed S: its start cell, the seeds of its probes and of
the explorer's decisions are that run's (:mod:`runner.experiments.loop`). The outcome:
``gamma_m`` (eq. 16 at the end, metres), ``border_cells``, ``path_m`` (the distance between
the probed cells' centres), ``steps`` and ``probes``, one per step with its ``cell``, its
``readings`` by name (null where one is missing) and the ``material`` truly there.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from runner.attention.explorer import Explorer
from runner.experiments.loop import decision_seed, make_sensor, reading_seed, start_cell, steps
from runner.experiments.metrics import BorderDistance, moves
from runner.world.physics import ProbeSpec
from runner.world.readings import shown
from runner.world.scenario import Scenario


def closed_loop(scenario: Scenario, task: str, count: int, seed: int = 0, run: int = 0,
                physics: ProbeSpec | None = None, ablate: tuple[str, ...] = ()) -> dict[str, Any]:
    """Run the loop for ``count`` probes; returns the outcome (see the module)."""
    explorer = Explorer(scenario, task, ablate=list(ablate))
    start = start_cell(scenario.shape, seed, run)
    explorer.reset(start[None], seed=[decision_seed(seed, run)])
    sensor = make_sensor(scenario, [reading_seed(seed, run)], physics)
    gamma = BorderDistance(scenario.centres, scenario.border(task), 1)
    truth = scenario.material_map.ravel()
    probes, cells = [], []
    for step in steps(explorer, sensor, count):
        cell = int(step.cells[0])
        gamma.probe(step.cells)
        cells.append(cell)
        probes.append({"cell": [int(i) for i in np.unravel_index(cell, scenario.shape)],
                       "readings": shown(explorer.readings, step.readings),
                       "material": scenario.materials[int(truth[cell])]})
    path = float(moves(np.asarray(cells)[None], scenario.centres).sum()) if cells else 0.0
    return {"gamma_m": float(gamma.gamma()[0]),
            "border_cells": int(scenario.border(task).sum()), "path_m": path,
            "steps": len(cells), "probes": probes}
