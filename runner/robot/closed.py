"""``bayesprog robot SCENARIO --physics --task T --steps N --seed S [--json]``: the closed loop
in one process: the explorer decides, the simulated fingertip probes (MuJoCo), for N probes.

The robot is run R of an experiment of seed S: its start cell, the seeds of its probes and of
the explorer's decisions are that run's (:mod:`runner.experiments.loop`). The outcome:
``gamma_m`` (eq. 16 at the end, metres), ``border_cells``, ``path_m`` (the distance between
the probed cells' centres), ``steps`` and ``probes``, one per step with its ``cell``, its
``readings`` by name (null where one is missing) and the ``material`` truly there.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from runner.attention.explorer import Explorer
from runner.experiments.log import SessionLog
from runner.experiments.loop import decision_seed, make_sensor, reading_seed, start_cell, steps
from runner.experiments.metrics import BorderDistance, moves
from runner.world.physics import ProbeSpec
from runner.world.readings import shown
from runner.world.scenario import Scenario


def closed_loop(scenario: Scenario, task: str, count: int, seed: int = 0, run: int = 0,
                physics: ProbeSpec | None = None, ablate: tuple[str, ...] = (),
                log: SessionLog | None = None) -> dict[str, Any]:
    """Run the loop for ``count`` probes, each written to ``log`` when given; returns the
    outcome (see the module)."""
    explorer = Explorer(scenario, task, ablate=list(ablate))
    start = start_cell(scenario.shape, seed, run)
    explorer.reset(start[None], seed=[decision_seed(seed, run)])
    sensor = make_sensor(scenario, [reading_seed(seed, run)], physics)
    gamma = BorderDistance(scenario.centres, scenario.border(task), 1)
    truth = scenario.material_map.ravel()
    probes, cells = [], []
    perception = explorer.readings
    if log is not None:
        log.start(perception, scenario.dims, {"scenario": str(scenario.path.resolve()),
                                              "task": task, "seed": seed, "run": run,
                                              "ablate": list(ablate)})
    clock, before = time.perf_counter(), dict(explorer.timings)
    for step in steps(explorer, sensor, count):
        cell = int(step.cells[0])
        gamma.probe(step.cells)
        cells.append(cell)
        probes.append({"cell": [int(i) for i in np.unravel_index(cell, scenario.shape)],
                       "readings": shown(explorer.readings, step.readings),
                       "material": scenario.materials[int(truth[cell])]})
        if log is not None:
            at = [int(i) for i in np.unravel_index(cell, scenario.shape)]
            belief = explorer.posterior[0, cell]
            now = time.perf_counter()
            log.write(step.k, at, [(i + 0.5) * scenario.cell for i in at],
                      shown(perception, step.readings), step.readings.missing_names(),
                      perception.warnings(step.readings), scenario.materials[int(truth[cell])],
                      scenario.materials[int(np.argmax(belief))], float(np.max(belief)),
                      None if step.next is None else
                      [int(i) for i in np.unravel_index(int(step.next[0]), scenario.shape)],
                      {k: explorer.timings[k] - before.get(k, 0.0) for k in explorer.timings},
                      now - clock)
            clock, before = now, dict(explorer.timings)
    path = float(moves(np.asarray(cells)[None], scenario.centres).sum()) if cells else 0.0
    return {"gamma_m": float(gamma.gamma()[0]),
            "border_cells": int(scenario.border(task).sum()), "path_m": path,
            "steps": len(cells), "probes": probes}
