"""A step interface for a real robot: JSON lines in, JSON lines out.

Each input line reports one probe, ``{"cell": [ix, iy], "texture": e, "compliance": c}`` (add
``"maps": true`` for the full maps; in a volume of cells, ``[ix, iy, iz]``, and the maps nest
[ix][iy][iz]); the reply is the cell to probe next, with what stood behind the choice::

    {"k": k, "next": [ix, iy],
     "probed": {"cell": [ix, iy], "material": name, "probability": p, "task_material": p},
     "chosen": {"inhibition": i, "saliency": s or null, "uncertainty": u, "probability": p},
     "shape": {"in_force": bool, "posterior": {"rectangle": p, "triangle": p} or null},
     "maps": {"belief": [[...]], "inhibition": ..., "saliency": ..., "uncertainty": ...,
              "posterior": ...}}                           (only when asked; null: unknown)

``{"maps": true}`` alone answers the maps of the last decision. ``{"reset": {"seed": s}}``
starts a new exploration. A malformed line gets ``{"error": "..."}`` and the session goes on.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from typing import IO

import numpy as np

import bayesprog
from bayesprog.errors import BayesprogError, short_repr
from runner.explorer import Explorer


def _reading(obj: dict, key: str) -> float:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"expected a finite number for {key!r}, found {value!r}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ValueError(f"expected a finite number for {key!r}, found {_short(value)}")
    return number


def _short(value: object) -> str:
    return short_repr(value, 40)


def _seed(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"expected a non-negative integer seed, found {_short(value)}")
    return value


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


def _grid(values: np.ndarray, shape: tuple[int, ...]) -> list:
    """A field over the grid as nested lists [ix][iy](...); null where it is unknown (NaN)."""
    grid = np.asarray(values, float).reshape(shape)
    out: list = np.vectorize(_number, otypes=[object])(grid).tolist()
    return out


class _Session:
    """What the replies say beyond the next cell, read from the explorer after a decision."""

    def __init__(self, explorer: Explorer):
        self.explorer = explorer
        self.shape_program: bayesprog.Program | None = None
        if "P(R | O)" not in explorer.target.ablated:
            self.shape_program = explorer.scenario.load_shape()

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
        d, nxt = e.last, int(e.last.next_cell[0])
        return {"inhibition": _number(d.inhibition[0, nxt]),
                "saliency": _number(d.saliency[0, nxt]),
                "uncertainty": _number(d.uncertainty[0, nxt]),
                "probability": float(e.target_probabilities[0, nxt])}

    def shape(self) -> dict:
        d = self.explorer.last
        ready = bool(d.shape_ready is not None and d.shape_ready[0])
        if not ready or self.shape_program is None or d.shape_error is None:
            return {"in_force": False, "posterior": None}
        answer = self.shape_program.ask("shape", {"L": d.shape_error[0]})
        states = answer.states[answer.variables[0]]
        probabilities = [float(x) for x in answer.probabilities]
        return {"in_force": True, "posterior": dict(zip(states, probabilities, strict=True))}

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


#: The longest line read (characters); a longer one is answered with an error and skipped.
MAX_LINE = 1 << 20


def _lines(stdin: IO[str] | Iterable[str]) -> Iterator[str]:
    """The lines of ``stdin``; from a file, one longer than ``MAX_LINE`` is cut there (its
    rest dropped, never held)."""
    if not hasattr(stdin, "readline"):
        yield from stdin
        return
    while True:
        line = stdin.readline(MAX_LINE + 1)
        if not line:
            return
        if len(line) > MAX_LINE and not line.endswith("\n"):
            while True:  # drop the rest of the long line without holding it
                rest = stdin.readline(MAX_LINE)
                if not rest or rest.endswith("\n"):
                    break
        yield line


def serve(explorer: Explorer, stdin: IO[str] | Iterable[str], stdout: IO[str], seed: int = 0) -> int:
    """Answer probes until end of input. Returns the number of probes answered."""
    k = 0
    started = False
    answered = 0
    session = _Session(explorer)
    for line_no, line in enumerate(_lines(stdin), 1):
        if not line.strip():
            continue
        try:
            if len(line) > MAX_LINE:
                raise ValueError(f"a line of more than {MAX_LINE:,} characters: expected one "
                                 "JSON object of a probe (the rest of the line is skipped)")
            try:
                obj = json.loads(line)
            except RecursionError:
                raise ValueError("JSON nested too deeply: expected one flat JSON object") \
                    from None
            if not isinstance(obj, dict):
                raise ValueError("expected a JSON object")
            if set(obj) == {"maps"}:
                if obj["maps"] is not True:
                    raise ValueError(f'expected {{"maps": true}}, found {_short(obj)}')
                reply: dict = {"k": k - 1, "maps": session.maps()}
            elif "reset" in obj:
                if set(obj) != {"reset"}:
                    raise ValueError('expected {"reset": {"seed": S}} alone, found other keys: '
                                     + ", ".join(sorted(set(obj) - {"reset"})))
                opts = obj["reset"]
                if not isinstance(opts, dict) or set(opts) - {"seed"}:
                    raise ValueError('expected {"reset": {"seed": S}} (or {"reset": {}}), found '
                                     f"{_short(opts)}")
                seed = _seed(opts.get("seed", seed))
                started, k = False, 0
                explorer.last = None  # the maps of the last session are not this one's
                reply = {"reset": True, "seed": seed}
            else:
                shape = explorer.scenario.shape
                axes = ("ix", "iy", "iz")[:len(shape)]
                missing = [key for key in ("cell", "texture", "compliance") if key not in obj]
                if missing:
                    raise ValueError(f"missing {', '.join(missing)}: expected "
                                     f'{{"cell": [{", ".join(axes)}], "texture": e, '
                                     '"compliance": c}')
                cell = obj["cell"]
                if (not isinstance(cell, list) or len(cell) != len(shape)
                        or not all(isinstance(i, int) and not isinstance(i, bool) for i in cell)):
                    raise ValueError(f"expected 'cell' as {len(shape)} integers "
                                     f"[{', '.join(axes)}], found {_short(cell)}")
                if not all(0 <= i < n for i, n in zip(cell, shape, strict=True)):
                    raise ValueError(f"cell {_short(cell)} is outside the "
                                     f"{' x '.join(map(str, shape))} grid")
                texture, compliance = _reading(obj, "texture"), _reading(obj, "compliance")
                if not started:
                    explorer.reset(start=cell, seed=seed)
                    started = True
                extra = set(obj) - {"cell", "texture", "compliance", "maps"}
                if extra:
                    raise ValueError(f"unknown key(s) {', '.join(sorted(extra))}: expected cell, "
                                     "texture, compliance and maybe maps")
                if "maps" in obj and obj["maps"] is not True and obj["maps"] is not False:
                    raise ValueError(f"expected 'maps' true or false, found {_short(obj['maps'])}")
                nxt = explorer.observe(cell, texture, compliance)
                reply = {"k": k, "next": list(nxt), "probed": session.probed(cell),
                         "chosen": session.chosen(), "shape": session.shape()}
                if obj.get("maps"):
                    reply["maps"] = session.maps()
                k += 1
                answered += 1
        except (ValueError, BayesprogError) as exc:
            reply = {"error": f"line {line_no}: {exc}"}
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()
    return answered
