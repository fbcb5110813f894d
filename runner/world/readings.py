"""Readings: what a sensor reports of a probed cell, named as the lab's perception program names
them, and the perception that turns them into P(material | readings).

pi_tar needs one thing from perception: the material posterior of the probed cell. Which
features a sensor gives is the lab's choice (the paper's texture and compliance; a BioTac's
pressure, vibration, temperature and electrodes; a vision-based sensor's image features), so a
reading is a named value of a variable of the scenario's pi_per: real, or discrete (one of the
variable's states), or missing (NaN) on a press that failed. :class:`Readings` carries the
readings of one probe per run through the sensor, the explorer, the session, the log and the
recordings; :class:`Perception` asks the program ``P(material | the readings at hand)``,
summing the missing ones out.

By default the readings are every variable of pi_per but the material, each named by its
variable; a scenario may name them (``readings: [pdc, tdc]``, or ``readings: {texture: E}`` to
give a variable another name on the lines and in the columns). The paper's program, whose
readings are its variables E and C, names them ``texture`` and ``compliance`` (the names its
lines, recordings and sensor models have always used).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import bayesprog
from bayesprog import BayesprogError, Program, short_repr

#: the names of the paper's readings, by variable, when a scenario does not name them
PAPER_NAMES = {"E": "texture", "C": "compliance"}

#: a reading farther than this many standard deviations from every material's mean, in the
#: perception program's Normals (or, for other forms, farther than this many times each
#: material's observed spread beyond its observed range), gets a warning
FAR = 6.0


class ReadingError(BayesprogError, ValueError):
    """A reading that cannot be perceived: an unknown name, a state not declared, no reading."""


@dataclass(frozen=True)
class Reading:
    """One reading: its ``name`` (on the lines, in the columns) and the ``variable`` of pi_per
    it observes; ``states`` for a discrete variable (its values are state indices), else
    None, and the variable's declared support."""

    name: str
    variable: str
    states: tuple[str, ...] | None = None
    support: tuple[float, float] = (-math.inf, math.inf)

    @property
    def discrete(self) -> bool:
        return self.states is not None

    def value(self, raw: object) -> float:
        """A reading as sent (a number; a state's name or index for a discrete reading; None
        or NaN: missing) -> the float it is kept as (NaN: missing). Raises ReadingError."""
        if raw is None:
            return math.nan
        if self.states is not None:
            if isinstance(raw, str):
                if raw in self.states:
                    return float(self.states.index(raw))
                from bayesprog import did_you_mean

                raise ReadingError(f"{self.name}: state {short_repr(raw, 40)} is not one of "
                                   f"{', '.join(self.states)}"
                                   + did_you_mean(raw, self.states))
            if isinstance(raw, (int, np.integer, float, np.floating)) \
                    and not isinstance(raw, bool) and float(raw).is_integer() \
                    and 0 <= raw < len(self.states):  # a state's index (2.0 as 2)
                return float(raw)
            if isinstance(raw, float) and math.isnan(raw):
                return math.nan
            raise ReadingError(f"{self.name}: expected one of {', '.join(self.states)} (or its "
                               f"index, or null when missing), found {short_repr(raw, 40)}")
        if isinstance(raw, bool) or not isinstance(raw, (int, float, np.integer, np.floating)):
            raise ReadingError(f"{self.name}: expected a number (or null when missing), found "
                               f"{short_repr(raw, 40)}")
        try:
            number = float(raw)
        except OverflowError:
            number = math.inf
        if math.isinf(number):
            raise ReadingError(f"{self.name}: expected a finite number (or null when missing), "
                               f"found {short_repr(raw, 40)}")
        return number

    def shown(self, value: float) -> float | str | None:
        """A kept value as it is written out: the number, the state's name, None if missing."""
        if math.isnan(value):
            return None
        return self.states[int(value)] if self.states is not None else float(value)


@dataclass
class Readings:
    """The readings of one probe per run: ``values`` [runs, len(names)] as floats, a discrete
    reading as its state's index, NaN where a reading is missing.

    >>> r = Readings.of(("texture", "compliance"), {"texture": [0.5, 0.1],
    ...                                              "compliance": [0.08, float("nan")]})
    >>> r["texture"].tolist(), r.missing_names(1)
    ([0.5, 0.1], ['compliance'])
    """

    names: tuple[str, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        self.names = tuple(self.names)
        self.values = np.asarray(self.values, dtype=float).reshape(-1, len(self.names))

    @classmethod
    def of(cls, names: Sequence[str], columns: Mapping[str, Any]) -> Readings:
        """Readings from one array [runs] per name (any order of ``columns``)."""
        return cls(tuple(names), np.stack([np.asarray(columns[n], float).reshape(-1)
                                           for n in names], axis=1))

    @classmethod
    def stack(cls, parts: Sequence[Readings]) -> Readings:
        """The runs of several Readings of the same names, one after another."""
        return cls(parts[0].names, np.concatenate([p.values for p in parts], axis=0))

    @property
    def runs(self) -> int:
        return int(self.values.shape[0])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.values[:, self.names.index(name)]

    @property
    def missing(self) -> np.ndarray:
        """[runs, names]: True where a reading is missing."""
        return np.isnan(self.values)

    def missing_names(self, run: int = 0) -> list[str]:
        return [n for n, gone in zip(self.names, np.isnan(self.values[run]), strict=True)
                if gone]

    def columns(self) -> dict[str, np.ndarray]:
        return {n: self.values[:, i] for i, n in enumerate(self.names)}


@dataclass
class Perception:
    """The scenario's perception program and the readings it perceives through.

    ``readings``: the variables read (a list), or reading names and the variable each observes
    (a mapping); by default every variable of the program but ``material``, each named by its
    variable (the paper's E and C: ``texture`` and ``compliance``). Raises ReadingError naming
    what the program lacks.

    >>> import bayesprog
    >>> perception = Perception(bayesprog.load("models/pi_per.yaml"))
    >>> perception.names
    ('texture', 'compliance')
    >>> r = perception.readings_of({"texture": 0.52, "compliance": None})
    >>> perception.posterior(r).argmax(-1).tolist() == [perception.materials.index("wood")]
    True
    """

    program: Program
    material: str = "M"
    named: Sequence[str] | Mapping[str, str] | None = None
    readings: tuple[Reading, ...] = field(init=False)

    def __post_init__(self) -> None:
        problems = perception_problems(self.program, self.material, self.named)
        if problems:
            raise ReadingError("; ".join(message for _, message in problems))
        variables = self.program.variables
        pairs = reading_pairs(self.program, self.material, self.named)
        out = []
        for name, variable in pairs:
            v = variables[variable]
            if v.is_discrete:
                out.append(Reading(name, variable, tuple(v.states)))  # type: ignore[union-attr]
            else:
                out.append(Reading(name, variable, None, (float(v.low), float(v.high))))  # type: ignore[union-attr]
        self.readings = tuple(out)
        self._by_name = {r.name: r for r in self.readings}
        self._questions: dict[tuple[bool, ...], str] = {}
        self.ranges = learned_ranges(self.program, self.material, self.readings)
        self._normals = {r.name: normal_of(self.program, r.variable, self.material)
                         for r in self.readings if not r.discrete}

    def with_program(self, program: Program) -> Perception:
        """The same readings perceived through another program (a learned or ablated
        pi_per)."""
        return Perception(program, self.material, self.named)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.readings)

    @property
    def materials(self) -> tuple[str, ...]:
        return tuple(self.program.variables[self.material].states)  # type: ignore[union-attr]

    def reading(self, name: str) -> Reading:
        return self._by_name[name]

    def normal(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """Mean and standard deviation per material of the reading ``name`` when its term is a
        Normal given the material alone, of literal parameters; else None."""
        return self._normals.get(name)

    @property
    def naive_normals(self) -> bool:
        """Whether the program is the paper's kind: every reading a Normal given the material
        alone, the readings independent given it (what :class:`ProgramNormals` draws from)."""
        return all(self._normals.get(r.name) is not None
                   and [p.name for p in self.program.term_of(r.variable).parents]
                   == [self.material] for r in self.readings)

    # the question --------------------------------------------------------------------------
    def question(self, missing: Sequence[bool] | np.ndarray | None = None) -> str:
        """``P(M | the readings not missing)``."""
        key = tuple(bool(m) for m in missing) if missing is not None else (False,) * len(
            self.readings)
        if key not in self._questions:
            known = [r.variable for r, gone in zip(self.readings, key, strict=True) if not gone]
            self._questions[key] = f"P({self.material} | {', '.join(known)})"
        return self._questions[key]

    def posterior(self, readings: Readings, prior: np.ndarray | None = None) -> np.ndarray:
        """P(material | readings) [runs, materials], each run's missing readings summed out;
        ``prior`` [runs, materials] enters as soft evidence on the material (the cell's
        previous posterior). Raises ReadingError for a run with no reading at all."""
        values = self._ordered(readings)
        missing = np.isnan(values)
        if not missing.any():  # the usual case: one question for every run
            return self._ask(self.question(), values, prior)
        empty = missing.all(axis=1)
        if empty.any():
            raise ReadingError(f"nothing to perceive: every reading of the probe is missing "
                               f"({', '.join(self.names)})")
        out = np.empty((values.shape[0], len(self.materials)))
        patterns, which = np.unique(missing, axis=0, return_inverse=True)
        for p, pattern in enumerate(patterns):
            rows = np.flatnonzero(which.ravel() == p)
            out[rows] = self._ask(self.question(pattern), values[rows][:, ~pattern],
                                  None if prior is None else prior[rows], pattern)
        return out

    def _ask(self, question: str, values: np.ndarray, prior: np.ndarray | None,
             missing: np.ndarray | None = None) -> np.ndarray:
        known = [r for i, r in enumerate(self.readings) if missing is None or not missing[i]]
        evidence = {r.variable: (values[:, i].astype(np.int64) if r.discrete else values[:, i])
                    for i, r in enumerate(known)}
        answer = self.program.ask(question, evidence,
                                  soft=None if prior is None else {self.material: prior})
        assert isinstance(answer, bayesprog.Posterior)
        return np.asarray(answer.probabilities, float)

    def _ordered(self, readings: Readings) -> np.ndarray:
        """The values [runs, readings] in this perception's order of its readings; a reading
        the sensor does not give is missing (NaN), one it gives that is not read, refused."""
        if readings.names == self.names:
            return readings.values
        extra = [n for n in readings.names if n not in self._by_name]
        if extra:
            raise ReadingError(f"unknown reading(s) {', '.join(map(repr, extra))}: the "
                               f"perception program reads {', '.join(self.names)}")
        out = np.full((readings.runs, len(self.names)), np.nan)
        for i, name in enumerate(self.names):
            if name in readings.names:
                out[:, i] = readings.values[:, readings.names.index(name)]
        return out

    # readings as sent ----------------------------------------------------------------------
    def readings_of(self, sent: Mapping[str, object]) -> Readings:
        """One probe's readings from a mapping of name -> value as sent (a reading left out,
        null or NaN is missing). Raises ReadingError for a name the program does not read."""
        unknown = [k for k in sent if k not in self._by_name]
        if unknown:
            from bayesprog import did_you_mean

            raise ReadingError(f"unknown reading(s) {', '.join(map(repr, unknown))}"
                               + did_you_mean(str(unknown[0]), self.names)
                               + f": the perception program reads {', '.join(self.names)}")
        return Readings(self.names, np.array([[r.value(sent.get(r.name))
                                               for r in self.readings]]))

    # what a reading says about the sensor --------------------------------------------------
    def within_support(self, readings: Readings, run: int = 0) -> tuple[Readings, list[str]]:
        """Run ``run``'s readings with each one outside the support its variable declares
        made missing (the program gives it no density: it is summed out, not refused), and
        the warnings that say so."""
        values = self._ordered(readings)[run].copy()
        out = []
        for i, r in enumerate(self.readings):
            low, high = r.support
            if r.discrete or math.isnan(values[i]) or low <= values[i] <= high:
                continue
            out.append(f"{r.name} {values[i]:g} is outside [{low:g}, {high:g}], the support "
                       f"the perception program declares for it ({r.variable}): taken as "
                       "missing")
            values[i] = math.nan
        return Readings(self.names, values[None]), out

    def range_warnings(self, readings: Readings, run: int = 0) -> list[str]:
        """Readings outside the range the program declares (a bounded support) or observed
        when it was learned (over every material); never from a description's text."""
        out = []
        for r, value in zip(self.readings, self._ordered(readings)[run], strict=True):
            if r.discrete or math.isnan(value):
                continue
            low, high = r.support
            source = "declares for it"
            if not (math.isfinite(low) or math.isfinite(high)) and r.name in self.ranges:
                low, high = self.ranges[r.name]["*"]
                source = "observed for it in the data it was learned from"
            if not low <= value <= high:
                out.append(f"{r.name} {value:g} is outside [{low:g}, {high:g}], the range the "
                           f"perception program {source} ({r.variable})")
        return out

    def warnings(self, readings: Readings, run: int = 0) -> list[str]:
        """What run ``run``'s readings say about the sensor: :meth:`range_warnings` and
        :meth:`far_warning`."""
        far = self.far_warning(readings, run)
        return self.range_warnings(readings, run) + ([far] if far else [])

    def far_warning(self, readings: Readings, run: int = 0) -> str | None:
        """Why a reading is far from every material the program knows, per reading in its own
        units: more than :data:`FAR` standard deviations from each material's mean (a Normal
        per material), else more than :data:`FAR` spreads beyond every material's observed
        range (a program learned from data); None when no reading is far."""
        far = []
        materials = self.materials
        for r, value in zip(self.readings, self._ordered(readings)[run], strict=True):
            if r.discrete or math.isnan(value):
                continue
            normal = self._normals.get(r.name)
            if normal is not None:
                mean, sd = normal
                z = np.abs(value - mean) / sd
                if float(np.min(z)) > FAR:
                    m = int(np.argmin(z))
                    far.append(f"{r.name} {value:g} is {float(z[m]):.0f} standard deviations "
                               f"from the nearest material's mean ({materials[m]}, "
                               f"{float(mean[m]):.3g})")
                continue
            by = self.ranges.get(r.name, {})
            spans = [(m, by[m]) for m in materials if m in by]
            if not spans:
                continue
            beyond = [(max(lo - value, value - hi, 0.0) / max(hi - lo, 1e-300), m, lo, hi)
                      for m, (lo, hi) in spans]
            ratio, nearest, lo, hi = min(beyond)
            if ratio > FAR:
                far.append(f"{r.name} {value:g} is {ratio:.0f} spreads beyond the nearest "
                           f"material's observed range ({nearest}, [{lo:g}, {hi:g}])")
        if not far:
            return None
        return ("; ".join(far) + ": outside what the perception program was built for (a "
                "sensor on another scale?); the decision is made all the same")


def reading_pairs(program: Program, material: str,
                  named: Sequence[str] | Mapping[str, str] | None) -> list[tuple[str, str]]:
    """(name, variable) of each reading (see :class:`Perception`)."""
    if named is None:
        variables = [v for v in program.variables if v != material]
        pairs = [(v, v) for v in variables]
        if set(variables) == set(PAPER_NAMES):
            pairs = [(PAPER_NAMES[v], v) for v in variables]
        return pairs
    if isinstance(named, Mapping):
        return [(str(k), str(v)) for k, v in named.items()]
    return [(str(v), str(v)) for v in named]


def perception_problems(program: Program, material: str,
                        named: Sequence[str] | Mapping[str, str] | None
                        ) -> list[tuple[str, str]]:
    """What keeps ``program`` from perceiving the readings ``named``: an undeclared material
    or reading variable, a material that is not discrete, a field, a name given twice; each
    as (``"material"`` or ``"readings"``: what it is about, the message)."""
    from bayesprog import did_you_mean

    variables = program.variables
    problems: list[tuple[str, str]] = []
    if material not in variables:
        problems.append(("material", f"{program.name} declares no material variable {material!r}"
                        + did_you_mean(material, variables)
                        + f" (its variables: {', '.join(variables)})"))
    elif not variables[material].is_discrete:
        problems.append(("material", f"the material {material!r} of {program.name} is real: "
                         "expected a discrete variable, one state per material"))
    pairs = reading_pairs(program, material, named)
    if not pairs:
        problems.append(("readings", f"{program.name} declares no reading: expected "
                         f"variables beside the material {material!r}"))
    seen: set[str] = set()
    observed: dict[str, str] = {}
    for name, variable in pairs:
        if name in seen:
            problems.append(("readings", f"reading {name!r} is named twice"))
        seen.add(name)
        if variable in observed:
            problems.append(("readings", f"readings {observed[variable]!r} and {name!r} are "
                             f"both the variable {variable!r}: expected one reading per "
                             "variable"))
        observed.setdefault(variable, name)
        if variable == material:
            problems.append(("readings", f"reading {name!r} is the material {material!r} "
                             "itself"))
        elif variable not in variables:
            problems.append(("readings", f"{program.name} declares no variable {variable!r} "
                             f"for the reading {name!r}"
                             + did_you_mean(variable, [v for v in variables if v != material])
                             + f" (its variables: {', '.join(variables)})"))
        elif getattr(variables[variable], "index", None) is not None:
            problems.append(("readings", f"reading {name!r}: {variable} is a field (indexed "
                             f"by {variables[variable].index}), not one value per probe"))  # type: ignore[union-attr]
    return problems


def learned_ranges(program: Program, material: str, readings: Sequence[Reading]
                   ) -> dict[str, dict[str, tuple[float, float]]]:
    """Per real reading, the range its values covered in the data the program was learned
    from: over every row (key ``"*"``) and per material (by name), from the ``ranges`` of
    its ``learned:`` records (a fit that continued an earlier one learned from both data
    sets: the ranges of both); empty for a program written by hand."""
    out: dict[str, dict[str, tuple[float, float]]] = {}
    for record in program.learned:
        ranges = getattr(record, "ranges", None) or {}
        for r in readings:
            got = ranges.get(r.variable)
            if not got or r.discrete:
                continue
            per = out.setdefault(r.name, {})
            for key, span in got.items():
                if key == "*":
                    at = "*"
                elif key.startswith(f"{material}="):
                    at = key[len(material) + 1:]
                else:
                    continue
                low, high = float(span[0]), float(span[1])
                if at in per:
                    low, high = min(low, per[at][0]), max(high, per[at][1])
                per[at] = (low, high)
    return {name: per for name, per in out.items() if "*" in per}


def normal_of(program: Program, variable: str, material: str
               ) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean and standard deviation per material of ``P(variable | material)`` when it is a
    mean plus Gaussian noise (a Normal) of literal parameters, else None."""
    try:
        term = program.term(f"P({variable} | {material})")
    except BayesprogError:
        return None
    form = term.form
    if form.mean_param is None or form.scale_param is None:  # not a mean plus Gaussian noise
        return None
    card = program.variables[material].card  # type: ignore[union-attr]
    values = []
    for name in (form.mean_param, form.scale_param):
        p = term.params.get(name)
        array = getattr(p, "array", None)
        if array is None:
            return None
        values.append(np.broadcast_to(np.asarray(array, float), (card,)).copy())
    return values[0], values[1]


def shown(perception: Perception, readings: Readings, run: int = 0
          ) -> dict[str, float | str | None]:
    """One run's readings as they are written out (JSON, a log's row): by name, a discrete
    reading by its state's name, None where missing."""
    values = perception._ordered(readings)[run]
    return {r.name: r.shown(float(v)) for r, v in zip(perception.readings, values, strict=True)}


def paper_readings(texture: Any, compliance: Any) -> Readings:
    """The paper's two readings of one probe per run (arrays or numbers).

    >>> paper_readings([0.52], [0.08]).names
    ('texture', 'compliance')
    """
    return Readings.of(("texture", "compliance"), {"texture": np.atleast_1d(texture),
                                                   "compliance": np.atleast_1d(compliance)})
