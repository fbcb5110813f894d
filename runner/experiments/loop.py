"""The step loop of an exploration with a simulated sensor, written once.

Probe the cells, perceive the readings, decide the next cells (:meth:`Explorer.step`): the
experiment (:func:`runner.experiments.experiment.simulate`), the report's replay of a run and
the notebook's step view (:func:`runner.report.build.replay`), and the parameter search
(through ``simulate``) all iterate :func:`steps`; a robot driving the explorer line by line over
stdio or ROS 2 (:class:`runner.robot.session.Session`) makes the same :meth:`Explorer.step` per
probe. What makes a run the run it is, its start cell and the seeds of its readings and
decisions, is here too.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from runner.attention.explorer import Explorer
from runner.world.physics import PhysicsSensor, ProbeSpec
from runner.world.readings import Perception, Readings
from runner.world.scenario import Scenario
from runner.world.sensor import HapticSensor, SimulatedSensor


def _replicated(key: list[int], replication: int) -> list[int]:
    """A random stream's key in replication ``replication`` (0: the key itself)."""
    if replication < 0:
        raise ValueError(f"replication: expected 0 or more, found {replication}")
    return key + [replication] if replication else key


def start_cell(shape: tuple[int, ...], seed: int, run: int, replication: int = 0) -> np.ndarray:
    """The start cell [dims] of run ``run`` of an experiment of ``seed`` on a grid of ``shape``:
    drawn from (seed, run) alone, so a run starts where it does whatever the number of runs
    (and a simulated robot, ``bayesprog robot --seed S --run R``, starts there too).

    >>> start_cell((30, 60), seed=2024, run=3).tolist() == start_cells((30, 60), 8, 2024)[3].tolist()
    True
    """
    rng = np.random.default_rng(_replicated([seed, 0xC0FFEE, run], replication))
    return np.array([rng.integers(0, n) for n in shape], dtype=np.int64)


def decision_seed(seed: int, run: int, replication: int = 0) -> tuple[int, ...]:
    """The seed of the decisions' tie breaking of run ``run`` of an experiment of ``seed``."""
    return tuple(_replicated([seed, run, 0], replication))


def reading_seed(seed: int, run: int, replication: int = 0) -> tuple[int, ...]:
    """The seed of the simulated sensor's readings of run ``run`` of an experiment of ``seed``."""
    return tuple(_replicated([seed, run, 1], replication))


def start_cells(shape: tuple[int, ...], runs: int, seed: int, replication: int = 0
                ) -> np.ndarray:
    """``runs`` start cells [runs, dims] on a grid of ``shape``, run r's from (seed, r) (and
    the replication's number, from replication 1 on)."""
    return np.stack([start_cell(shape, seed, r, replication)
                     for r in range(runs)]).reshape(runs, len(shape))


def make_sensor(scenario: Scenario, seeds: list, physics: ProbeSpec | None = None,
                perception: Perception | None = None) -> HapticSensor:
    """The simulated sensor of a scenario, one seed per run: the physics probes when its
    sensor is ``physics:`` or ``physics`` is given (a probe is seeded by its run's seed and its
    step), its sensor model or its recordings when it names them (so perception is
    misspecified, as on a robot), else draws from the perception program (``perception``,
    by default the scenario's) given each cell's material."""
    if physics is not None or scenario.spec.sensor.physics is not None:
        return PhysicsSensor(scenario.physics_scene(physics), seeds)
    noise = scenario.spec.sensor.extra_noise
    model = scenario.sensor_model or scenario.program_sensor(perception)
    return SimulatedSensor(scenario.material_map, model, seeds, noise)


def start_runs(explorer: Explorer, starts: np.ndarray, seed: int,
               run_ids: Sequence[int] | np.ndarray, replication: int = 0) -> HapticSensor:
    """Start runs ``run_ids`` of replication ``replication`` of an experiment of ``seed`` from
    ``starts`` [runs, dims]: the explorer reset with their decisions' seeds, and the simulated
    sensor with their readings'."""
    explorer.reset(starts, seed=[decision_seed(seed, int(r), replication) for r in run_ids])
    return make_sensor(explorer.scenario,
                       [reading_seed(seed, int(r), replication) for r in run_ids],
                       perception=explorer.readings)


@dataclass
class Step:
    """One step of every run: the cells probed [runs] (flat) and their readings, and the cells
    decided next (None after the last probe of a loop that does not decide there)."""

    k: int
    cells: np.ndarray
    readings: Readings
    next: np.ndarray | None


def steps(explorer: Explorer, sensor: HapticSensor, iterations: int,
          decide_last: bool = False) -> Iterator[Step]:
    """``iterations`` steps from the explorer's start cells: probe, perceive, decide (the last
    step decides only when ``decide_last``). The explorer's decision is read while a step is
    held (``explorer.decision``)."""
    cells = explorer.expected
    for k in range(iterations):
        readings = sensor.probe(cells)
        if k + 1 < iterations or decide_last:
            nxt: np.ndarray | None = explorer.step(cells, readings)
        else:
            explorer.perceive(cells, readings)
            nxt = None
        yield Step(k, cells, readings, nxt)
        if nxt is not None:
            cells = nxt
