"""One exploration driven line by line: a JSON object in, a JSON object out.

The step interfaces, JSON lines over standard input and output (:mod:`runner.robot.stdio`) and the
ROS 2 node (:mod:`runner.robot.ros`), hand each input line to :meth:`Session.answer` and send back
what it returns, so the same lines get the same replies whichever way they travel.

A probe reports the cell just probed and its readings by the names the scenario's perception
program gives them, ``{"cell": [ix, iy], "readings": {"pdc": 17.2, "tdc": -1.3, ...}}`` (the
paper's ``{"cell": [ix, iy], "texture": e, "compliance": c}``, its readings beside the cell, is
read the same way; add ``"maps": true`` for the full maps; in a volume of cells,
``[ix, iy, iz]``, and the maps nest [ix][iy][iz]). A reading given as null, as NaN or left out
is missing: it is summed out of the question, and the reply names it in ``"missing"`` (a probe
without any reading is refused: nothing to perceive). A discrete reading is its state's name
(or index). The reply is the cell to probe next, with what stood behind the choice::

    {"k": k, "next": [ix, iy], "missing": [names] (only when some are missing),
     "probed": {"cell": [ix, iy], "material": name, "probability": p, "task_material": p},
     "chosen": {"inhibition": i, "saliency": s or null, "uncertainty": u, "probability": p},
     "shape": {"in_force": bool, "posterior": {"rectangle": p, "triangle": p} or null},
     "maps": {"belief": [[...]], "inhibition": ..., "saliency": ..., "uncertainty": ...,
              "posterior": ...}}                           (only when asked; null: unknown)

Beside ``next``, ``"position"`` is the centre of that cell in metres, in the workspace's frame:
its origin at the grid's corner (the outer corner of cell [0, 0]), x along ix, y along iy (z
along iz), cells of the scenario's size. A reading outside the range the perception program
declares or observed when it was learned, or far from every material it knows (per reading,
in its own units: :meth:`runner.world.readings.Perception.far_warning`), is still decided on,
and the reply says so in ``"warning"``.

``{"maps": true}`` alone answers the maps of the last decision. ``{"reset": {...}}`` starts a
new exploration, with any of: ``"task"`` (a task of the scenario, by its name), ``"seed"``,
``"run"`` (the decisions' random stream of run ``r`` of an experiment of that seed; the seed
may then be left out: the session's) and ``"start"`` (the cell to probe first, answered as
``next`` with its ``position``). A malformed line gets ``{"error": "line N: ..."}`` and the
session goes on.
"""

from __future__ import annotations

import json
import math
import time
from typing import TYPE_CHECKING

import numpy as np

import bayesprog
from bayesprog import BayesprogError, short_repr
from runner.attention.explorer import Explorer
from runner.experiments.loop import decision_seed
from runner.robot.secret import REFUSED, take_secret
from runner.world.readings import Perception, Readings, shown

if TYPE_CHECKING:
    from runner.experiments.log import SessionLog

#: The longest line read (characters); a longer one is answered with an error.
MAX_LINE = 1 << 20
def _short(value: object) -> str:
    return short_repr(value, 40)


def _natural(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"expected a non-negative integer {what}, found {_short(value)}")
    return value


#: the keys a probe line may hold beside the readings, and a reset's options
PROBE_KEYS = frozenset({"cell", "readings", "maps", "k", "session"})
RESET_KEYS = frozenset({"seed", "run", "task", "start", "session"})


def _did_you_mean(unknown: list[str], known: frozenset[str]) -> str:
    """`` (did you mean 'compliance'?)`` for the first unknown key close to a known one."""
    import difflib

    for key in unknown:
        close = difflib.get_close_matches(str(key), sorted(known), n=1, cutoff=0.6)
        if close:
            return f" (did you mean {close[0]!r}?)"
    return ""


def _session_id(value: object) -> str | int:
    """A session's name: a non-empty string or an integer."""
    if isinstance(value, bool) or not isinstance(value, (str, int)) or value == "":
        raise ValueError(f"expected a session as a non-empty string or an integer, found "
                         f"{_short(value)}")
    return value


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


def _grid(values: np.ndarray, shape: tuple[int, ...]) -> list:
    """A field over the grid as nested lists [ix][iy](...); null where it is unknown (NaN)."""
    grid = np.asarray(values, float).reshape(shape)
    out: list = np.vectorize(_number, otypes=[object])(grid).tolist()
    return out


class Session:
    """One exploration of ``explorer`` (one run) answered line by line.

    ``seed`` is the seed of the decisions' tie breaking until a reset names another. Lines are
    numbered from 1 as they arrive, blank ones included (they get no reply). With a ``secret``
    (:mod:`runner.robot.secret`), a line is answered only when it carries it (``"secret"``);
    any other, a malformed one included, is refused with ``"refused": "secret"`` beside its
    error and changes nothing.

    >>> from runner.world.scenario import load_scenario
    >>> session = Session(Explorer(load_scenario("models/scenarios/paper.yaml"), "T2"))
    >>> reply = session.answer('{"cell": [5, 7], "readings": {"texture": 0.52, "compliance": 0.08}}')
    >>> reply["k"], reply["probed"]["material"], session.stepped
    (0, 'wood', True)
    >>> session.answer('{"cell": [5, 8], "texture": 0.5, "compliance": null}')["missing"]
    ['compliance']
    >>> session.answer("not json")
    {'error': 'line 3: Expecting value: line 1 column 1 (char 0)'}
    >>> session.answer("   ") is None
    True
    """

    def __init__(self, explorer: Explorer, seed: int = 0, frame: str = "workspace",
                 log: SessionLog | None = None, secret: str | None = None):
        self.explorer = explorer
        #: the word every line must carry (None: lines carry none)
        self.secret = secret
        #: where every probe is written, when asked (``--log``)
        self.log = log
        #: the frame the workspace's positions are given in (a reset's reply names it)
        self.frame = frame
        #: the session that holds the explorer (a reset claimed it), or None
        self.holder: str | int | None = None
        #: the cell the last reply asked to probe next (None before any)
        self.expected: list[int] | None = None
        #: the explorers of the tasks a reset has named (built once each)
        self._by_task = {explorer.task: explorer}
        self.seed = seed
        #: the decisions' seeds of the current exploration (an experiment run's when reset so)
        self._seeds: int | list[tuple[int, ...]] = seed
        #: the experiment's run whose decisions' stream a reset asked for (None: the seed's own)
        self.run: int | None = None
        self.line_no = 0
        #: the number of the next step (probes answered since the start or the last reset)
        self.k = 0
        self._started = False
        #: whether the last line answered was a probe (a decision was made)
        self.stepped = False
        self.shape_program: bayesprog.Program | None = None
        #: pi_obj's last answer, and the shape errors it was asked for
        self._shape_answer: tuple[bytes, dict[str, float]] | None = None
        if "P(R | O)" not in explorer.target.ablated:
            self.shape_program = explorer.scenario.load_shape()

    # what a reply says beyond the next cell --------------------------------------------------
    def probed(self, cell: list[int]) -> dict:
        e = self.explorer
        flat = int(e.flat(np.asarray(cell).reshape(1, -1))[0])
        belief = e.posterior[0, flat]
        best = int(np.argmax(belief))
        return {"cell": cell, "material": e.scenario.materials[best],
                "probability": float(belief[best]),
                "task_material": float(belief[e.target_material])}

    def chosen(self) -> dict:
        e = self.explorer
        d = e.decision
        nxt = int(d.next_cell[0])
        return {"inhibition": _number(d.inhibition[0, nxt]),
                "saliency": _number(d.saliency[0, nxt]),
                "uncertainty": _number(d.uncertainty[0, nxt]),
                "probability": float(e.target_probabilities[0, nxt])}

    def shape_posterior(self) -> dict[str, float] | None:
        """pi_obj's posterior over the templates at the last decision; None where the shape cue
        was not in force (too few probed cells on the followed border, or ablated)."""
        d = self.explorer.last
        if d is None or self.shape_program is None or d.shape_error is None:
            return None
        if d.shape_ready is None or not d.shape_ready[0]:
            return None
        # the registration changes only when the followed border does: most steps ask pi_obj
        # the question of the step before, whose answer is kept
        key = d.shape_error[0].tobytes()
        if self._shape_answer is not None and self._shape_answer[0] == key:
            return dict(self._shape_answer[1])
        answer = self.shape_program.ask("shape", {"L": d.shape_error[0]})
        assert isinstance(answer, bayesprog.Posterior)  # pi_obj's question "shape" is P(R | L)
        states = answer.states[answer.variables[0]]
        probabilities = [float(x) for x in answer.probabilities]
        found = dict(zip(states, probabilities, strict=True))
        self._shape_answer = (key, found)
        return dict(found)

    def shape(self) -> dict:
        posterior = self.shape_posterior()
        return {"in_force": posterior is not None, "posterior": posterior}

    def maps(self) -> dict:
        e = self.explorer
        if e.last is None:
            raise ValueError("no decision yet: send a probe first")
        shape = e.scenario.shape
        belief = e.belief()[0]
        return {"belief": _grid(belief, shape), "inhibition": _grid(e.last.inhibition[0], shape),
                "saliency": _grid(e.last.saliency[0], shape),
                "uncertainty": _grid(e.last.uncertainty[0], shape),
                "posterior": _grid(e.target_probabilities[0], shape)}

    def workspace(self) -> dict:
        """The grid's geometry, for a driver that moves a hand in metres: the size of a cell,
        the cells along each axis, and the frame positions are given in."""
        scenario = self.explorer.scenario
        return {"cell_m": scenario.spec.grid.cell, "size": list(scenario.shape),
                "frame": self.frame}

    def position(self, cell: list[int] | tuple[int, ...]) -> list[float]:
        """The centre of ``cell`` in metres (origin at the grid's corner, axes along ix, iy, iz)."""
        size = self.explorer.scenario.spec.grid.cell
        return [round((int(i) + 0.5) * size, 12) for i in cell]

    def material_at(self, cell: list[int]) -> str:
        """The material the scenario's layout has at ``cell``."""
        e = self.explorer
        return e.scenario.materials[int(e.scenario.material_map.ravel()[
            int(e.flat(np.asarray(cell).reshape(1, -1))[0])])]

    def _describe(self) -> None:
        """What the session explores, beside its log."""
        assert self.log is not None
        e = self.explorer
        meta = {"scenario": str(e.scenario.path.resolve()), "task": e.task, "seed": self.seed,
                "ablate": list(e.ablated)}
        if self.run is not None:  # the decisions' stream is that run's (decision_seed)
            meta["run"] = self.run
        self.log.start(e.readings, e.dims, meta)

    # one line --------------------------------------------------------------------------------
    def answer(self, line: str) -> dict | None:
        """The reply to one input line (None for a blank line, which is counted all the same)."""
        self.line_no += 1
        self.stepped = False
        if not line.strip():
            return None
        try:
            return self._answer(screened(line, self.secret, self.line_no))
        except Refused as refused:
            return refused.reply
        except (ValueError, BayesprogError) as exc:
            return {"error": f"line {self.line_no}: {exc}"}

    def _answer(self, obj: dict) -> dict:
        if "reset" in obj:
            return self._reset(obj)
        self._check_holder(obj)
        if set(obj) - {"session"} == {"maps"}:
            if obj["maps"] is not True:
                raise ValueError(f'expected {{"maps": true}}, found {_short(obj)}')
            return {"k": self.k - 1, "maps": self.maps()}
        return self._probe(obj)

    def _check_holder(self, obj: dict) -> None:
        """A line of another session than the one holding the explorer changes nothing."""
        if "session" not in obj and self.holder is None:
            return
        given = _session_id(obj["session"]) if "session" in obj else None
        if self.holder is None:
            raise ValueError(f"no session {_short(given)} holds the explorer: claim it with "
                             f'{{"reset": {{"session": {json.dumps(given)}}}}} first')
        if given != self.holder:
            raise ValueError(f"the explorer is held by session {json.dumps(self.holder)}: "
                             f"send its lines with \"session\": {json.dumps(self.holder)}, or "
                             "take it over with a reset that names another session "
                             f"(this line {'named ' + json.dumps(given) if given is not None else 'named none'}; nothing changed)")

    def _reset(self, obj: dict) -> dict:
        if set(obj) != {"reset"}:
            raise ValueError('expected {"reset": {"seed": S}} alone, found other keys: '
                             + ", ".join(sorted(set(obj) - {"reset"})))
        opts = obj["reset"]
        if not isinstance(opts, dict) or set(opts) - RESET_KEYS:
            unknown = sorted(set(opts) - RESET_KEYS) if isinstance(opts, dict) else []
            raise ValueError('expected {"reset": {...}} with any of task, seed, run, start and '
                             f"session, found {_short(opts)}" + _did_you_mean(unknown,
                                                                             RESET_KEYS))
        claim = _session_id(opts["session"]) if "session" in opts else None
        if self.holder is not None and claim is None:
            raise ValueError(f"the explorer is held by session {json.dumps(self.holder)}: a "
                             "reset must name a session to take it over (nothing changed)")
        seed = _natural(opts.get("seed", self.seed), "seed")
        start = self._cell(opts["start"], "start") if "start" in opts else None
        if "task" in opts:
            self._use_task(opts["task"])
        reply: dict = {"reset": True, "task": self.explorer.task, "seed": seed}
        if claim is not None:
            reply["session"] = claim
            if self.holder is not None and self.holder != claim:
                reply["taken_over_from"] = self.holder
        reply["workspace"] = self.workspace()
        if "run" in opts:
            run = _natural(opts["run"], "run")
            self._seeds = [decision_seed(seed, run)]
            reply["run"] = run
            self.run = run
        else:
            self._seeds = seed
            self.run = None
        self.seed = seed
        self.holder = claim
        self.k, self._started, self.expected = 0, False, None
        self.explorer.last = None  # the maps of the last session are not this one's
        if self.log is not None:
            self._describe()
        if start is not None:
            reply["next"], reply["position"] = start, self.position(start)
            self.expected = start
        return reply

    def _use_task(self, task: object) -> None:
        tasks = self.explorer.scenario.spec.tasks
        if not isinstance(task, str) or task not in tasks:
            raise ValueError(f"unknown task {_short(task)}: expected one of {', '.join(tasks)}")
        if task not in self._by_task:
            e = self.explorer
            self._by_task[task] = Explorer(e.scenario, task, ablate=e.ablated)
        self.explorer = self._by_task[task]

    def _cell(self, cell: object, what: str) -> list[int]:
        return checked_cell(cell, self.explorer.scenario.shape, what)

    def _readings(self, obj: dict) -> Readings:
        """The probe's readings: under ``"readings"``, or beside the cell as the paper's lines
        give them; every other key is refused, a misspelt reading named."""
        perception = self.explorer.readings
        names = perception.names
        beside = {k: v for k, v in obj.items() if k in names}
        extra = sorted(set(obj) - PROBE_KEYS - set(beside))
        if extra:  # named first: a misspelt key is why a reading is missing
            known = frozenset(PROBE_KEYS | set(names))
            given = beside if "readings" not in obj or not isinstance(obj["readings"], dict) \
                else obj["readings"]
            lacking = [n for n in names if n not in given]
            raise ValueError(f"unknown key(s) {', '.join(map(repr, extra))}"
                             + _did_you_mean(extra, known)
                             + (f" (missing {', '.join(lacking)})" if lacking else "")
                             + f": expected cell, readings ({', '.join(names)}) and maybe k, "
                             "maps, session")
        if "readings" in obj:
            sent = obj["readings"]
            if beside:
                raise ValueError(f"readings both under 'readings' and beside the cell "
                                 f"({', '.join(sorted(beside))}): expected one of the two")
            if not isinstance(sent, dict):
                raise ValueError(f"expected 'readings' as an object of name: value, found "
                                 f"{_short(sent)}")
        else:
            sent = beside
        if "cell" not in obj:
            raise ValueError(f"missing cell: expected "
                             f'{{"cell": [{", ".join(self._axes())}], "readings": {{...}}}}')
        readings = perception.readings_of(sent)
        if readings.missing.all():
            raise ValueError(f"nothing to perceive: the probe gives none of the readings "
                             f"{', '.join(names)} (null, NaN and left out are missing)")
        return readings

    def _axes(self) -> tuple[str, ...]:
        return ("ix", "iy", "iz")[:len(self.explorer.scenario.shape)]

    def _probe(self, obj: dict) -> dict:
        explorer = self.explorer
        started = time.perf_counter()
        readings = self._readings(obj)
        if "k" in obj:
            k = _natural(obj["k"], "k (the step the probe answers)")
            if k != self.k:
                raise ValueError(f"stale probe: it answers step {k}, the explorer waits for "
                                 f"step {self.k} (nothing changed)")
        cell = self._cell(obj["cell"], "cell")
        if "maps" in obj and obj["maps"] is not True and obj["maps"] is not False:
            raise ValueError(f"expected 'maps' true or false, found {_short(obj['maps'])}")
        if not self._started:
            explorer.reset(start=cell, seed=self._seeds)
            self._started = True
        warnings = []
        if self.expected is not None and cell != self.expected:
            warnings.append(f"probed {cell}, not the cell asked for, {self.expected} (a missed "
                            "target?): the reading is taken where it was made")
        readings, outside = explorer.readings.within_support(readings)
        if readings.missing.all():
            raise ValueError("nothing to perceive: " + "; ".join(outside))
        warnings += outside
        before = dict(explorer.timings)
        nxt = explorer.observe(cell, readings)
        missing = readings.missing_names()
        probed = self.probed(cell)
        reply: dict = {"k": self.k, "next": list(nxt), "position": self.position(nxt),
                       "probed": probed, "chosen": self.chosen(), "shape": self.shape()}
        if missing:  # named only when there are: a full probe's reply is as it always was
            reply["missing"] = missing
        if self.holder is not None:
            reply["session"] = self.holder
        perception = explorer.readings
        warnings += perception.warnings(readings)
        if warnings:
            reply["warning"] = "; ".join(warnings)
        self.expected = list(nxt)
        if obj.get("maps"):
            reply["maps"] = self.maps()
        if self.log is not None:
            if self.log.columns is None:
                self._describe()
            self.log.write(self.k, cell, self.position(cell), shown(perception, readings),
                           missing, warnings, self.material_at(cell),
                           probed["material"], probed["probability"],
                           list(nxt), {key: explorer.timings[key] - before.get(key, 0.0)
                                       for key in explorer.timings},
                           time.perf_counter() - started)
        self.k += 1
        self.stepped = True
        return reply


def checked_cell(cell: object, shape: tuple[int, ...], what: str = "cell") -> list[int]:
    """``cell`` as a line gives it: as many integers as the grid has axes, inside the grid
    (ValueError saying what was found otherwise)."""
    axes = ("ix", "iy", "iz")[:len(shape)]
    if (not isinstance(cell, list) or len(cell) != len(shape)
            or not all(isinstance(i, int) and not isinstance(i, bool) for i in cell)):
        raise ValueError(f"expected {what!r} as {len(shape)} integers "
                         f"[{', '.join(axes)}], found {_short(cell)}")
    if not all(0 <= i < n for i, n in zip(cell, shape, strict=True)):
        raise ValueError(f"cell {_short(cell)} is outside the {' x '.join(map(str, shape))} "
                         "grid")
    return list(cell)


class Refused(Exception):
    """A line answered with ``reply`` alone: malformed, or without the explorer's secret."""

    def __init__(self, reply: dict):
        super().__init__(reply["error"])
        self.reply = reply


def screened(line: str, secret: str | None, line_no: int, unchanged: str = "nothing changed"
             ) -> dict:
    """Line ``line_no`` as the JSON object it must be, its ``"secret"`` checked against
    ``secret`` and taken off (:func:`runner.robot.secret.take_secret`); else :class:`Refused`
    with the reply, which says ``"refused": "secret"`` when the explorer has a secret (a
    malformed line does not show it either)."""
    try:
        obj = json_object(line)
    except ValueError as exc:
        why = str(exc)
    else:
        refusal = take_secret(obj, secret)
        if refusal is None:
            return obj
        why = f"{refusal} ({unchanged})"
    reply = {"error": f"line {line_no}: {why}"}
    raise Refused(reply if secret is None else {**reply, "refused": REFUSED})


def json_object(line: str) -> dict:
    """One input line as the JSON object it must be (ValueError saying why it is not)."""
    if len(line.rstrip("\n")) >= MAX_LINE:
        raise ValueError(f"a line of more than {MAX_LINE:,} characters: expected one JSON "
                         "object (the rest of the line is skipped)")
    try:
        obj = json.loads(line)
    except RecursionError:
        raise ValueError("JSON nested too deeply: expected one flat JSON object") from None
    if not isinstance(obj, dict):
        raise ValueError("expected a JSON object")
    return obj


def probe_line(cell: list[int], readings: Readings, run: int = 0, k: int | None = None,
               perception: Perception | None = None) -> dict:
    """The probe line a driver sends for one run's readings (missing ones as null); with the
    ``perception`` that reads them, a discrete reading is sent by its state's name (without
    it, as its state's index)."""
    if perception is not None:
        values = shown(perception, readings, run)
    else:
        values = {n: (None if math.isnan(v) else float(v))
                  for n, v in zip(readings.names, readings.values[run], strict=True)}
    line: dict = {"cell": cell, "readings": values}
    if k is not None:
        line["k"] = k
    return line
