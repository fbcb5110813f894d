"""A step interface for a real robot: JSON lines in, JSON lines out.

Each input line reports one probe, ``{"cell": [ix, iy], "texture": e, "compliance": c}``; the
reply is ``{"k": k, "next": [ix, iy]}``, the cell to probe next. ``{"reset": {"seed": s}}``
starts a new exploration. A malformed line gets ``{"error": "..."}`` and the session goes on.
"""

from __future__ import annotations

import json
import math
from typing import IO

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


def serve(explorer: Explorer, stdin: IO[str], stdout: IO[str], seed: int = 0) -> int:
    """Answer probes until end of input. Returns the number of probes answered."""
    k = 0
    started = False
    answered = 0
    for line_no, line in enumerate(stdin, 1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
            if not isinstance(obj, dict):
                raise ValueError("expected a JSON object")
            if "reset" in obj:
                opts = obj["reset"]
                if not isinstance(opts, dict) or set(opts) - {"seed"}:
                    raise ValueError('expected {"reset": {"seed": S}} (or {"reset": {}}), found '
                                     f"{_short(opts)}")
                seed = _seed(opts.get("seed", seed))
                started, k = False, 0
                reply: dict = {"reset": True, "seed": seed}
            else:
                missing = [key for key in ("cell", "texture", "compliance") if key not in obj]
                if missing:
                    raise ValueError(f"missing {', '.join(missing)}: expected "
                                     '{"cell": [ix, iy], "texture": e, "compliance": c}')
                cell = obj["cell"]
                nx, ny = explorer.scenario.shape
                if (not isinstance(cell, list) or len(cell) != 2
                        or not all(isinstance(i, int) and not isinstance(i, bool) for i in cell)):
                    raise ValueError(f"expected 'cell' as two integers [ix, iy], found "
                                     f"{_short(cell)}")
                if not (0 <= cell[0] < nx and 0 <= cell[1] < ny):
                    raise ValueError(f"cell {_short(cell)} is outside the {nx} x {ny} grid")
                texture, compliance = _reading(obj, "texture"), _reading(obj, "compliance")
                if not started:
                    explorer.reset(start=cell, seed=seed)
                    started = True
                nxt = explorer.observe(cell, texture, compliance)
                reply = {"k": k, "next": list(nxt)}
                k += 1
                answered += 1
        except (ValueError, BayesprogError) as exc:
            reply = {"error": f"line {line_no}: {exc}"}
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()
    return answered
