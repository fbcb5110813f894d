"""The action-perception loop: perceive the probed cell, compute the cues, ask where to go next.

Every decision is asked of the YAML programs through the engine: the material posterior of the
probed cell is ``pi_per``'s answer (its previous posterior enters as soft evidence on M, which
makes the per-cell map a recursive Bayes filter); the next cell is ``pi_tar``'s MAP answer, with
``pi_obj``'s shape posterior entering ``pi_tar`` as soft evidence on R. R runs advance in
lockstep as arrays with a leading run axis: one engine call per program per step.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

import bayesprog
from bayesprog import Program, check_size
from runner.attention._kernels import followed_border_2d, marked_first, perceived_sobel_2d_around
from runner.attention.cues import inhibition_at_distance, perceived_border, saliency, uncertainty
from runner.attention.shape import (
    MIN_POINTS,
    SEARCH_GROWTH_3D,
    Registration,
    ShapeTracker,
    pad_outlines,
)
from runner.world.readings import Perception, Readings
from runner.world.scenario import Scenario

#: The five configurations of the paper's ablation study (Fig. 9, 10): the term made uniform.
CONFIGURATIONS: dict[str, tuple[str, ...]] = {
    "full": (),
    "without_R": ("P(R | O)",),
    "without_S": ("P(S | O, T)",),
    "without_I": ("P(I | O)",),
    "without_U": ("P(U | O)",),
}


@dataclass
class Decision:
    """What stood behind one step's choice, per run (arrays with a leading run axis)."""

    k: int
    inhibition: np.ndarray
    saliency: np.ndarray
    uncertainty: np.ndarray
    shape_error: np.ndarray | None
    templates: np.ndarray | None
    next_cell: np.ndarray
    #: the runs whose shape cue was in force (enough probed cells on the perceived border)
    shape_ready: np.ndarray | None = None


def state_entries(scenario: Scenario, runs: int) -> int:
    """The largest array the explorer holds for ``runs`` runs on ``scenario``: the material
    posterior of every cell (runs x cells x materials), the table of inhibition over every
    offset between two cells (about 2^dims x cells), or the shape cue over every template and
    cell (runs x templates x cells)."""
    cells = int(np.prod(scenario.shape))
    offsets = int(np.prod([2 * n - 1 for n in scenario.shape]))
    return max(runs * cells * len(scenario.materials), offsets,
               runs * len(scenario.spec.templates) * cells)


class Explorer:
    """Touch-attention exploration of a grid, for ``runs`` runs in lockstep.

    >>> from runner.world.scenario import load_scenario
    >>> scenario = load_scenario("models/scenarios/paper.yaml")
    >>> explorer = Explorer(scenario, task="T2")
    >>> explorer.reset(start=(5, 7), seed=1)
    >>> nxt = explorer.observe((5, 7), {"texture": 0.52, "compliance": 0.08})
    >>> len(nxt), all(0 <= i < n for i, n in zip(nxt, scenario.shape))
    (2, True)
    """

    def __init__(
        self,
        scenario: Scenario,
        task: str,
        ablate: Sequence[str] = (),
        runs: int = 1,
        programs: dict[str, Program] | None = None,
    ):
        if task not in scenario.spec.tasks:
            raise bayesprog.QuestionError(f"unknown task {task!r}: expected one of "
                                          f"{', '.join(scenario.spec.tasks)}")
        check_size(state_entries(scenario, runs), f"exploring {runs:,} run(s) of a "
                   f"{' x '.join(map(str, scenario.shape))} grid at once",
                   hint="; fewer runs at once (an experiment's chunk) need less")
        self.scenario = scenario
        self.task = task
        self.runs = runs
        programs = programs or {}
        #: how the probed cell's readings are perceived (pi_per and the readings it reads)
        self.readings: Perception = scenario.readings
        if programs.get("perception") is not None:
            self.readings = scenario.readings.with_program(programs["perception"])
        self.perception = self.readings.program
        target = programs.get("target") or scenario.target
        self.target = target.ablate(*ablate) if ablate else target
        self.ablated = tuple(ablate)
        names = self.target.variables["R"].states  # type: ignore[union-attr]
        self.shape_names = names
        self.outlines = pad_outlines([scenario.templates[n][0] for n in names])
        self.template_points = np.stack([scenario.templates[n][1] for n in names])
        self.materials = len(self.readings.materials)
        self.target_material = scenario.task_material(task)
        #: the other side of the task's discontinuity: the remaining materials of the workspace
        self.counter_materials = scenario.counter_materials(task)
        self.centres = scenario.centres
        self.dims = scenario.dims
        self.diagonal = float(np.linalg.norm(np.asarray(scenario.shape) * scenario.cell))
        self.tracker = ShapeTracker(self.outlines, self.template_points,
                                    method=scenario.spec.shape_matcher,
                                    growth=SEARCH_GROWTH_3D if self.dims == 3 else None)
        # I over every offset between two cells, from the offsets' lengths built axis by axis
        squares = np.ix_(*[(np.arange(-n + 1, n) * scenario.cell) ** 2 for n in scenario.shape])
        self._inhibition_table = inhibition_at_distance(
            np.sqrt(sum(squares, np.zeros(()))) / self.diagonal)
        self.last: Decision | None = None
        self.registration: Registration | None = None
        self._stacked = np.empty((0, runs), np.int64)
        self._stacked_from: list[np.ndarray] | None = None
        self._stacked_steps = 0
        #: seconds spent per phase since construction (perception, cues, shape, decision)
        self.timings: dict[str, float] = defaultdict(float)

    @property
    def decision(self) -> Decision:
        """The last decision: what stood behind the cells chosen at the last step."""
        if self.last is None:
            raise bayesprog.QuestionError("no decision yet: step the explorer first")
        return self.last

    # state --------------------------------------------------------------------------------------
    def reset(self, start: Sequence[int] | np.ndarray,
              seed: int | Sequence[int | tuple[int, ...]] = 0) -> None:
        """Start new runs: ``start`` is a cell (ix, iy(, iz)) or one per run [runs, dims];
        ``seed`` one integer (run r then uses seed ``(seed, r)``) or one seed per run (an
        integer or a tuple of them, as numpy's generators take)."""
        start = np.asarray(start, dtype=int)
        if start.ndim not in (1, 2) or start.shape[-1] != self.dims:
            raise bayesprog.QuestionError(f"expected a start cell of {self.dims} coordinates, or "
                                          f"one per run [runs, {self.dims}], found the shape "
                                          f"{list(start.shape)}")
        start = start.reshape(-1, self.dims)
        if start.shape[0] == 1 and self.runs > 1:
            start = np.repeat(start, self.runs, axis=0)
        if start.shape[0] != self.runs:
            raise bayesprog.QuestionError(f"expected {self.runs} start cells, got {start.shape[0]}")
        seeds = [(int(seed), r) for r in range(self.runs)] if np.ndim(seed) == 0 else list(seed)  # type: ignore[arg-type]
        if len(seeds) != self.runs:
            raise bayesprog.QuestionError(f"expected {self.runs} seeds, got {len(seeds)}")
        self.rngs = [np.random.default_rng(s) for s in seeds]
        self.posterior = np.full((self.runs, len(self.centres), self.materials), 1.0 / self.materials)
        # U of every cell, kept up to date one probed cell per step (uniform maps: U = 1)
        self.uncertainty = uncertainty(self.posterior[:, :1]).repeat(len(self.centres), axis=1)
        self.path: list[np.ndarray] = []
        self.expected = self.flat(start)
        self.visits = np.zeros((self.runs, len(self.centres)), dtype=int)
        # the perceived stimulus (see percept), kept up to date one probed cell per step
        self._target = np.zeros((self.runs, len(self.centres)), bool)
        self._perceived = np.zeros((self.runs, len(self.centres)), bool)
        # and its saliency (eq. 12), brought up to date around the cells probed since the last
        # decision (a cell's saliency reads its 3^dims neighbourhood); nothing perceived: 0
        self._saliency = np.zeros((self.runs, *self.scenario.shape))
        self._changed: list[np.ndarray] = []
        self.tracker.reset()
        self._border = np.zeros((self.runs, len(self.centres)), bool)
        self.last = None

    def inhibition_at(self, last: np.ndarray) -> np.ndarray:
        """Eq. (10) around the last probed cells [runs] -> [runs, cells], by lookup in the table
        of I over every offset between two cells (I depends only on the offset)."""
        shape = self.scenario.shape
        at = np.unravel_index(np.asarray(last), shape)
        # the map around cell (lx, ly) is the window of the table that starts at offset
        # (-lx, -ly): one block copy per run
        windows = np.lib.stride_tricks.sliding_window_view(self._inhibition_table, shape)
        corner = tuple(n - 1 - i for n, i in zip(shape, at, strict=True))
        return windows[corner].reshape(len(at[0]), -1)

    def flat(self, cells: np.ndarray) -> np.ndarray:
        """Flat cell indices of ``cells`` [..., dims] (ix, iy(, iz)), checked against the grid."""
        cells = np.asarray(cells, dtype=int)
        shape = self.scenario.shape
        if cells.shape[-1:] != (len(shape),):
            raise bayesprog.QuestionError(f"expected cells of {len(shape)} coordinates on the "
                                          f"{' x '.join(map(str, shape))} grid, found "
                                          f"{cells.tolist()}")
        if np.any(cells < 0) or np.any(cells >= np.asarray(shape)):
            raise bayesprog.QuestionError(f"cell outside the {' x '.join(map(str, shape))} grid: "
                                          f"{cells.tolist()}")
        return np.ravel_multi_index(tuple(np.moveaxis(cells, -1, 0)), shape)

    def cell(self, flat: np.ndarray) -> np.ndarray:
        """Cells (ix, iy(, iz)) [..., dims] of flat indices."""
        return np.stack(np.unravel_index(np.asarray(flat), self.scenario.shape), axis=-1)

    # the loop -----------------------------------------------------------------------------------
    def perceive(self, cells: np.ndarray, readings: Readings) -> None:
        """Update the perceptual map at the probed cells (one per run) from their readings:
        recursive Bayes by pi_per, each run's missing readings summed out."""
        start = time.perf_counter()
        rows = np.arange(self.runs)
        prior = self.posterior[rows, cells]
        probabilities = self.readings.posterior(readings, prior)
        self.posterior[rows, cells] = probabilities
        self.uncertainty[rows, cells] = uncertainty(probabilities)
        target = probabilities[:, self.target_material] >= 0.5
        other = probabilities[:, self.counter_materials].sum(axis=-1) >= 0.5
        self._target[rows, cells] = target
        self._perceived[rows, cells] = target | other
        self._changed.append(np.asarray(cells, dtype=np.int64))
        self.path.append(cells)
        self.visits[rows, cells] += 1
        self.timings["perception"] += time.perf_counter() - start

    def belief(self) -> np.ndarray:
        """P(M_v = the task's material) at every probed cell, NaN where nothing was probed;
        [runs, cells]."""
        return np.where(self.visits > 0, self.posterior[..., self.target_material], np.nan)

    def percept(self) -> tuple[np.ndarray, np.ndarray]:
        """The perceived stimulus of the task: where the task's material is perceived (its
        posterior P(M_v = material) >= 1/2), and where a side of the task's discontinuity is
        perceived at all: a probed cell perceived as the task's material or as one of the
        remaining materials of the workspace; [runs, *grid shape] each. A probed cell perceived as
        neither (a misperception, another material than any of the task) says nothing about
        the task's discontinuity: it counts as not perceived."""
        shape = (self.runs, *self.scenario.shape)
        return self._target.reshape(shape), self._perceived.reshape(shape)

    def cue_fields(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inhibition I (eq. 10), saliency S (eq. 12) and uncertainty U (eq. 11): [runs, cells]."""
        target, perceived = self.percept()
        for cells in self._changed:
            if self.dims == 2:
                perceived_sobel_2d_around(target, perceived, self._saliency, cells)
            else:
                self._saliency_around(target, perceived, cells)
        self._changed.clear()
        s = self._saliency.reshape(self.runs, -1).copy()
        # a run where no cell has any saliency (nothing left to compare: the probed region is
        # homogeneous and has no unprobed tip) learns nothing from S: it is not observed there
        vetoed = ~np.any(np.isnan(s) | (s > 0), axis=1)
        s[vetoed] = np.nan
        return self.inhibition_at(self.path[-1]), s, self.uncertainty.copy()

    def _saliency_around(self, target: np.ndarray, perceived: np.ndarray,
                         cells: np.ndarray) -> None:
        """Eq. (12) brought up to date around each run's probed cell ``cells`` [runs] (flat):
        only the 3^dims cells around it read it. They are computed on the 5^dims block around
        it, whose inner cells have their whole neighbourhood in the block (cells outside the
        grid are not perceived, there as in the whole map)."""
        shape = self.scenario.shape
        dims = len(shape)
        at = np.unravel_index(np.asarray(cells), shape)
        steps = np.arange(-2, 3)
        index = [np.arange(self.runs).reshape((-1,) + (1,) * dims)]
        valid: np.ndarray | bool = True
        for axis, (a, n) in enumerate(zip(at, shape, strict=True)):
            along = (a[:, None] + steps).reshape((-1,) + tuple(5 if b == axis else 1
                                                             for b in range(dims)))
            valid = valid & (along >= 0) & (along < n)
            index.append(np.clip(along, 0, n - 1))
        block = tuple(index)
        values = saliency(target[block].astype(float), perceived[block] & valid, dims=dims)
        inner = (slice(None),) + (slice(1, 4),) * dims
        keep = np.broadcast_to(valid, values.shape)[inner]
        where = tuple(np.broadcast_to(i, values.shape)[inner][keep] for i in block)
        self._saliency[where] = values[inner][keep]

    def stacked_path(self) -> np.ndarray:
        """The path as one array [steps, runs] (flat cells): a view of a buffer into which only
        the steps probed since the last call are copied, and which doubles when full. Stacking
        the whole list at every step made a step's cost grow with the exploration's length: a
        robot's session of 4,000 probes ended at about half its first rate. A new path (a
        reset) is copied from its start."""
        steps = len(self.path)
        if self._stacked_from is not self.path:
            self._stacked_from, self._stacked_steps = self.path, 0
        done = self._stacked_steps
        if done < steps:
            if steps > len(self._stacked):
                grown = np.empty((max(2 * len(self._stacked), steps, 64), self.runs), np.int64)
                grown[:done] = self._stacked[:done]
                self._stacked = grown
            self._stacked[done:steps] = np.stack(self.path[done:steps])
            self._stacked_steps = steps
        return self._stacked[:steps]

    def border_cells(self) -> np.ndarray:
        """The probed cells of the perceived border that the walker follows, [runs, cells]: of
        the perceived border of the task's material, the connected part (8-neighbours; 26 in a
        volume) that holds the last probed border cell."""
        if self.dims == 2:  # a flood fill from that cell (the border's other parts untouched)
            target, perceived = self.percept()
            part = np.empty((self.runs, len(self.centres)), bool)
            followed_border_2d(target, perceived, self.stacked_path(), part)
            return part
        from scipy import ndimage

        border = perceived_border(*self.percept(), dims=self.dims)
        structure = np.zeros((3,) * (1 + self.dims), bool)
        structure[1] = True  # connected within a run's grid, never across runs
        labels, _ = ndimage.label(border, structure=structure)
        labels = labels.reshape(self.runs, -1)
        rows = np.arange(self.runs)
        followed = np.full(self.runs, -1)
        todo = labels.max(axis=1) > 0  # runs with a border: its cells were probed, so on the path
        for cells in reversed(self.path):  # back from the last probe, usually a step or two
            if not todo.any():
                break
            label = labels[rows, cells]
            hit = todo & (label > 0)
            followed[hit] = label[hit]
            todo &= ~hit
        return labels == followed[:, None]

    def border_points(self, border: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cells ``border`` [runs, cells] as points [runs, K, dims] (each run's first ``counts[r]``
        rows, in the cells' order; the rest padding: the first other cells) and their counts
        [runs]."""
        counts = border.sum(axis=1)
        cells = marked_first(border, max(int(counts.max()), 1))
        return self.centres[cells], counts

    def shape_cue(self) -> tuple[Registration, np.ndarray]:
        """The templates registered onto the part of every run's path that lies on the perceived
        border (eq. 6-7), and which runs have enough such cells (``MIN_POINTS``) for a shape cue.
        Runs whose set of border cells did not change keep their registration."""
        border = self.border_cells()
        points, counts = self.border_points(border)
        ready = counts >= MIN_POINTS
        changed = ready & np.any(border != self._border, axis=1)
        self._border = border
        registration = self.tracker.update(points, np.maximum(counts, 1), np.flatnonzero(changed))
        return registration, ready

    def decide(self) -> np.ndarray:
        """Ask pi_tar for the next cell of every run (flat indices)."""
        start = time.perf_counter()
        i, s, u = self.cue_fields()
        evidence = {"T": self.task, "I": i, "S": s, "U": u}
        shape_start = time.perf_counter()
        self.timings["cues"] += shape_start - start
        reg, ready = None, np.zeros(self.runs, bool)
        if "P(R | O)" not in self.target.ablated:
            reg, ready = self.shape_cue()
            self.registration = reg
        ask_start = time.perf_counter()
        self.timings["shape"] += ask_start - shape_start
        if reg is None:
            # no shape cue: P(R | O) is uniform, and so the soft evidence on R is moot
            inputs: dict[str, np.ndarray] = {"errors": np.full(len(self.shape_names), 0.5)}
            ablate: dict[str, np.ndarray] | None = None
        else:
            # one question for every run: the runs without enough border cells for a shape
            # cue ask with P(R | O) uniform (their template points are not read: zeros stand
            # in for those never registered) and errors of 1/2, which make the soft evidence
            # on R uniform: summed over R it then doubles their cells' products exactly, and
            # their answers are those of pi_tar without P(R | O) to the bit (another likelihood
            # would scale them by a number that is not a power of two)
            inputs = {"templates": np.where(ready[:, None, None, None], reg.points, 0.0),
                      "errors": np.where(ready[:, None], reg.error, 0.5)}
            ablate = {"P(R | O)": ~ready}
        answer = self.target.ask("next_target", evidence, inputs=inputs, rng=self.rngs,
                                 ablate=ablate)
        assert isinstance(answer, bayesprog.MapResult)
        nxt = answer.indices[:, 0]
        probabilities = answer.posterior.probabilities
        self.last = Decision(len(self.path), i, s, u, None if reg is None else reg.error,
                             None if reg is None else reg.points, nxt, ready)
        self.target_probabilities = probabilities
        self.timings["decision"] += time.perf_counter() - ask_start
        return nxt

    def step(self, cells: np.ndarray, readings: Readings) -> np.ndarray:
        """Perceive then decide, batched: flat cells [runs] and their readings -> next flat
        cells [runs]."""
        self.perceive(np.asarray(cells), readings)
        nxt = self.decide()
        self.expected = nxt
        return nxt

    def observe(self, cell: Sequence[int], readings: Readings | Mapping[str, object]
                ) -> tuple[int, ...]:
        """One run, one probe: the cell (ix, iy(, iz)) just probed and its readings (by name;
        one left out, None or NaN is missing) -> next cell."""
        if self.runs != 1:
            raise bayesprog.QuestionError("observe() drives one run; use step() for batches")
        if not isinstance(readings, Readings):
            readings = self.readings.readings_of(readings)
        flat = self.flat(np.asarray(cell).reshape(1, -1))
        nxt = self.step(flat, readings)
        return tuple(int(i) for i in self.cell(nxt)[0])
