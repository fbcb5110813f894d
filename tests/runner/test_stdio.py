"""The JSON-lines step interface (runner/robot/stdio.py) driven by scripted sessions, in process and
through the real ``bayesprog explore --stdio`` command."""

from __future__ import annotations

import functools
import io
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from runner.attention.explorer import Explorer
from runner.robot.stdio import serve
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
PAPER = ROOT / "models" / "scenarios" / "paper.yaml"
NX, NY = 30, 60

# readings at the proxy material means of models/pi_per.yaml (texture E, compliance C)
READINGS = {"silicone": (0.12, 0.35), "wood": (0.52, 0.08), "plush": (0.66, 0.62)}


@functools.cache
def scenario():
    return load_scenario(PAPER)


def explorer(task: str = "T2") -> Explorer:
    return Explorer(scenario(), task)


def probe(cell, material: str = "wood") -> str:
    e, c = READINGS[material]
    return json.dumps({"cell": list(cell), "texture": e, "compliance": c})


def session(lines: list[str], *, seed: int = 0, ex: Explorer | None = None) -> list[dict]:
    out = io.StringIO()
    serve(ex or explorer(), io.StringIO("".join(line + "\n" for line in lines)), out, seed=seed)
    return [json.loads(line) for line in out.getvalue().splitlines()]


# a walk across the rectangle's lower edge (silicone inside, wood outside)
WALK = [probe((10, 12), "silicone"), probe((11, 12), "silicone"), probe((11, 13), "wood"),
        probe((12, 13), "silicone"), probe((12, 14), "wood"), probe((13, 14), "silicone")]


def assert_step_replies(replies: list[dict], first_k: int = 0) -> None:
    for j, reply in enumerate(replies):
        assert set(reply) - {"warning"} == {"k", "next", "position", "probed", "chosen",
                                            "shape"}, reply
        # a walk that does not go where the replies say is flagged, and for nothing else here
        assert "not the cell asked for" in reply.get("warning", "not the cell asked for")
        assert reply["k"] == first_k + j
        ix, iy = reply["next"]
        assert isinstance(ix, int) and isinstance(iy, int)
        # the centre of that cell in metres, from the grid's corner (1 cm cells)
        assert reply["position"] == pytest.approx([(ix + 0.5) * 0.01, (iy + 0.5) * 0.01])
        assert 0 <= ix < NX and 0 <= iy < NY


def test_valid_probes_get_numbered_replies_in_order():
    out = io.StringIO()
    answered = serve(explorer(), io.StringIO("\n".join(WALK) + "\n"), out)
    replies = [json.loads(line) for line in out.getvalue().splitlines()]
    assert answered == len(WALK) == len(replies)
    assert_step_replies(replies)


def test_following_the_suggestions_like_a_robot():
    """A robot that probes the cell each reply suggests, with the readings of its true material;
    the input is produced lazily, after the previous reply was written."""
    sc = scenario()
    out = io.StringIO()
    probed = []

    def robot() -> Iterator[str]:
        cell = (15, 9)  # wood, below the rectangle
        for _ in range(12):
            probed.append(cell)
            yield probe(cell, sc.materials[sc.material_map[cell]]) + "\n"
            cell = tuple(json.loads(out.getvalue().splitlines()[-1])["next"])

    assert serve(explorer(), robot(), out) == 12
    replies = [json.loads(line) for line in out.getvalue().splitlines()]
    assert_step_replies(replies)
    assert not any("warning" in r for r in replies)  # every probe where it was asked for
    # each reply is the cell probed next
    assert [tuple(r["next"]) for r in replies[:-1]] == probed[1:]


BAD_LINES = {
    "not json": "this is not JSON",
    "no reading": json.dumps({"cell": [3, 4]}),
    "every reading null": json.dumps({"cell": [3, 4], "texture": None, "compliance": None}),
    "a reading misspelt": json.dumps({"cell": [3, 4], "readings": {"textur": 0.5}}),
    "outside the grid": json.dumps({"cell": [30, 4], "texture": 0.5, "compliance": 0.1}),
    "negative cell": json.dumps({"cell": [-1, 4], "texture": 0.5, "compliance": 0.1}),
    "texture not a number": json.dumps({"cell": [3, 4], "texture": "rough", "compliance": 0.1}),
    "texture infinite": '{"cell": [3, 4], "texture": Infinity, "compliance": 0.1}',
    "cell not integers": json.dumps({"cell": [3.0, 4], "texture": 0.5, "compliance": 0.1}),
    "not an object": "[1, 2, 3]",
}


@pytest.mark.parametrize("bad", list(BAD_LINES.values()), ids=list(BAD_LINES))
@pytest.mark.parametrize("where", [0, 3], ids=["first line", "mid-session"])
def test_malformed_line_gets_an_error_and_the_session_goes_on(bad, where):
    lines = WALK[:where] + [bad] + WALK[where:]
    replies = session(lines)
    assert len(replies) == len(lines)
    error = replies[where]
    assert set(error) == {"error"}
    assert f"line {where + 1}" in error["error"]
    # the other replies are exactly those of the session without the bad line
    clean = session(WALK)
    assert replies[:where] + replies[where + 1:] == clean
    assert_step_replies(clean)


def test_error_line_numbers_count_every_input_line():
    lines = [WALK[0], "", "oops", WALK[1], "   ", '{"cell": [1, 2]}', WALK[2]]
    replies = session(lines)
    # blank lines get no reply but are counted
    assert [r.get("k") for r in replies] == [0, None, 1, None, 2]
    assert "line 3" in replies[1]["error"]
    assert "line 6" in replies[3]["error"]
    assert "texture" in replies[3]["error"]


def test_reset_restarts_the_exploration():
    before = WALK[:3]
    after = [probe((10, 13), "wood"), probe((11, 13), "silicone"), probe((12, 12), "wood"),
             probe((12, 14), "silicone")]
    replies = session(before + [json.dumps({"reset": {"seed": 3}})] + after)
    assert replies[3] == {"reset": True, "task": "T2", "seed": 3, "workspace": {"cell_m": 0.01, "size": [30, 60], "frame": "workspace"}}
    assert_step_replies(replies[:3])
    assert_step_replies(replies[4:])  # k counts from 0 again
    # after the reset the session is a fresh one with seed 3: nothing of the first walk remains
    assert replies[4:] == session(after, seed=3)
    # (and this is not trivially so: without the reset, the first walk changes the answers)
    assert [r["next"] for r in session(before + after)[3:]] != [r["next"] for r in replies[4:]]


def test_same_script_twice_gives_the_same_replies():
    script = WALK[:2] + ["garbage"] + WALK[2:] + ['{"reset": {"seed": 3}}'] + WALK[:4]
    first = session(script)
    assert first == session(script)
    # also when the same explorer serves the script again
    ex = explorer()
    assert session(script, ex=ex) == first
    assert session(script, ex=ex) == first


def test_cli_explore_stdio_subprocess():
    bayesprog = Path(sys.executable).with_name("bayesprog")
    lines = WALK[:4] + ["{not json"] + WALK[4:]
    proc = subprocess.run(
        [str(bayesprog), "explore", "models/scenarios/paper.yaml", "--stdio", "--task", "T2"],
        input="".join(line + "\n" for line in lines), capture_output=True, text=True,
        cwd=ROOT, timeout=60, check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    replies = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(replies) == len(lines)
    assert "line 5" in replies[4]["error"]
    assert_step_replies(replies[:4] + replies[5:])
    # the command serves the same explorer as the in-process one (task T2, seed 0)
    assert replies == session(lines)


# --- lines that crashed the session at commit b2fab07 (fixed since in runner/robot/stdio.py) ---


def test_huge_cell_index_gets_an_error_reply():
    # was: OverflowError from np.asarray(cell, dtype=int) in Explorer.flat, not caught
    lines = [json.dumps({"cell": [10**30, 4], "texture": 0.5, "compliance": 0.1}), WALK[0]]
    replies = session(lines)
    assert "line 1" in replies[0]["error"]
    assert replies[1] == session(WALK[:1])[0]


def test_huge_integer_reading_gets_an_error_reply():
    # was: OverflowError from math.isfinite on an int too large for a float, not caught
    lines = ['{"cell": [3, 4], "texture": 1' + "0" * 400 + ', "compliance": 0.1}', WALK[0]]
    replies = session(lines)
    assert "line 1" in replies[0]["error"]
    assert len(replies[0]["error"]) < 200  # the 400-digit number is not echoed in full
    assert replies[1] == session(WALK[:1])[0]


@pytest.mark.parametrize("seed", ["null", "[1, 2]", '"three"'])
def test_reset_with_a_non_numeric_seed_gets_an_error_reply(seed):
    # was: TypeError from int(None) / int([1, 2]), not caught
    lines = [WALK[0], '{"reset": {"seed": ' + seed + "}}", WALK[1]]
    replies = session(lines)
    assert "line 2" in replies[1]["error"]
    assert replies[2] == session(WALK[:2])[1]  # the session goes on, unreset


def test_reset_with_a_negative_seed_is_refused_or_works():
    # was: acknowledged, then np.random.default_rng refused it at every following probe
    replies = session(['{"reset": {"seed": -1}}', WALK[0], WALK[1]])
    if "error" in replies[0]:
        assert "line 1" in replies[0]["error"]
    else:
        assert replies[0] == {"reset": True, "task": "T2", "seed": -1,
                              "workspace": {"cell_m": 0.01, "size": [30, 60], "frame": "workspace"}}
    assert_step_replies(replies[1:])


def test_reset_with_an_unknown_key_gets_an_error_reply():
    replies = session(['{"reset": {"begin": [3, 4]}}', WALK[0]])
    assert "line 1" in replies[0]["error"] and "begin" in replies[0]["error"]
    assert replies[1]["k"] == 0


def test_reset_sets_the_task_the_seed_and_the_start_cell():
    replies = session(['{"reset": {"task": "T1", "seed": 4, "start": [3, 40]}}', probe((3, 40)),
                       '{"reset": {"task": "T9"}}', '{"reset": {"start": [30, 0]}}'])
    assert replies[0] == {"reset": True, "task": "T1", "seed": 4, "next": [3, 40],
                          "position": [0.035, 0.405], "workspace": {"cell_m": 0.01, "size": [30, 60], "frame": "workspace"}}
    # decided for T1 (plush), as an explorer of T1 with that seed decides
    alone = Explorer(scenario(), "T1")
    alone.reset(start=[3, 40], seed=4)
    texture, compliance = READINGS["wood"]
    wood = {"texture": texture, "compliance": compliance}
    assert replies[1]["next"] == list(alone.observe([3, 40], wood))
    assert "unknown task 'T9': expected one of T1, T2, T3" in replies[2]["error"]
    assert "outside the 30 x 60 grid" in replies[3]["error"]


def test_a_reading_far_from_every_material_is_decided_on_with_a_warning():
    far = json.dumps({"cell": [10, 12], "texture": 0.5, "compliance": 5})
    replies = session([WALK[0], far])
    assert "warning" not in replies[0]
    assert "compliance 5 is" in replies[1]["warning"] and "standard deviations" in replies[1]["warning"]
    assert replies[1]["k"] == 1 and len(replies[1]["next"]) == 2


def test_replies_say_what_stood_behind_the_choice_and_the_maps_when_asked():
    ex = explorer("T2")
    lines = WALK[:5] + [WALK[5][:-1] + ', "maps": true}', json.dumps({"maps": True})]
    replies = session(lines, ex=ex)
    last = replies[5]
    # the probed cell: the material posterior there, from the explorer's perceptual map
    cell = last["probed"]["cell"]
    flat = cell[0] * NY + cell[1]
    belief = ex.posterior[0, flat]
    assert last["probed"]["material"] == ex.scenario.materials[int(np.argmax(belief))]
    assert last["probed"]["task_material"] == pytest.approx(belief[ex.target_material])
    # the chosen cell: its cues and posterior, which the maps hold at the same place
    ix, iy = last["next"]
    maps = last["maps"]
    assert last["chosen"]["inhibition"] == pytest.approx(maps["inhibition"][ix][iy])
    assert last["chosen"]["uncertainty"] == pytest.approx(maps["uncertainty"][ix][iy])
    assert last["chosen"]["probability"] == pytest.approx(maps["posterior"][ix][iy])
    assert last["chosen"]["probability"] == pytest.approx(max(max(r) for r in maps["posterior"]))
    assert len(maps["belief"]) == NX and len(maps["belief"][0]) == NY
    assert maps["belief"][0][0] is None  # a cell never probed
    assert maps["belief"][cell[0]][cell[1]] == pytest.approx(belief[ex.target_material])
    assert replies[6] == {"k": 5, "maps": maps}
    assert last["shape"] == {"in_force": False, "posterior": None}  # six probes: too few


def test_the_shape_posterior_is_pi_objs_once_the_cue_is_in_force():
    ex = explorer("T2")
    materials = ex.scenario.material_map
    border = np.argwhere(ex.scenario.border("T2"))
    order = np.argsort(np.arctan2(*(border - border.mean(0)).T[::-1]))
    lines = []
    for ix, iy in border[order][:20]:  # each border cell, and a wood cell beside it
        lines.append(probe((int(ix), int(iy)), "silicone"))
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            if ex.scenario.materials[materials[ix + dx, iy + dy]] == "wood":
                lines.append(probe((int(ix + dx), int(iy + dy)), "wood"))
                break
    replies = session(lines, ex=ex)
    assert replies[-1]["shape"]["in_force"]
    posterior = replies[-1]["shape"]["posterior"]
    d = ex.last
    # pi_obj (eq. 8): P(R = r | L) is proportional to Beta(1, 4.5) at the error against r
    density = stats.beta(1.0, 4.5).pdf(d.shape_error[0])
    expected = density / density.sum()
    assert posterior == pytest.approx(dict(zip(("rectangle", "triangle"), expected.tolist(),
                                               strict=True)), rel=1e-12)
    assert sum(posterior.values()) == pytest.approx(1.0)


def test_maps_after_a_reset_and_malformed_maps_requests_get_errors():
    lines = [WALK[0], json.dumps({"reset": {"seed": 2}}), json.dumps({"maps": True}),
             json.dumps({"cell": [10, 12], "texture": 0.1, "compliance": 0.3, "maps": 1}),
             json.dumps({"reset": {}, "maps": True}), WALK[1]]
    replies = session(lines)
    assert replies[1] == {"reset": True, "task": "T2", "seed": 2, "workspace": {"cell_m": 0.01, "size": [30, 60], "frame": "workspace"}}
    assert "no decision yet" in replies[2]["error"]
    assert "'maps' true or false" in replies[3]["error"]
    assert "alone" in replies[4]["error"]
    assert replies[5]["k"] == 0


@pytest.mark.parametrize("line", [
    '{"cell": [3, 4], "compliance": 0.1}',
    '{"cell": [3, 4], "texture": NaN, "compliance": 0.1}',
    '{"cell": [3, 4], "texture": null, "compliance": 0.1}',
    '{"cell": [3, 4], "readings": {"compliance": 0.1}}',
])
def test_a_missing_reading_is_summed_out_and_named(line):
    import bayesprog

    out = io.StringIO()
    serve(explorer(), io.StringIO(line + "\n"), out)
    reply = json.loads(out.getvalue())
    assert reply["missing"] == ["texture"] and reply["k"] == 0
    # the cell's material is then P(M | C) alone, the texture summed out (pi_per's Normals)
    program = bayesprog.load(ROOT / "models" / "pi_per.yaml")
    alone = program.ask("P(M | C)", {"C": 0.1}).probabilities
    assert reply["probed"]["probability"] == pytest.approx(alone.max(), rel=1e-12)
