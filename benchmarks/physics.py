"""What physics probes cost (not a test): one press and stroke of the simulated fingertip
against the bare MuJoCo steps it is made of, and a 100-step ``bayesprog robot --physics``
closed loop as a whole command against the same loop whose readings are drawn from the
perception program's Normals, with where the physics loop's time goes.

Each figure is the median of ``--repeats``; the two commands are timed interleaved in fresh
processes. Reported to standard output and, as JSON, to ``--out``.

    python benchmarks/physics.py [--repeats 5] [--only-probes] [--compare 2000]
                                 [--out results/benchmarks/physics.json]

``--compare N`` also checks that the presses side by side give the features of the presses
driven step by step, in distribution (N presses per material).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).parents[1]
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))

#: the same closed loop, its readings from pi_per's Normals (the reference of the command)
TABLE_LOOP = """
import json
from runner.robot.closed import closed_loop
from runner.world.scenario import load_scenario
scenario = load_scenario("{scenario}")
print(json.dumps(closed_loop(scenario, "T2", 100)["gamma_m"]))
"""


def per_probe(repeats: int) -> dict[str, float]:
    """Milliseconds per probe on the paper's layout (60 presses at random cells, every feature
    computed): side by side as one step of 60 runs makes them (on one thread, and on two), one
    at a time as ``robot --physics`` makes them, and driven from Python step by step (the
    reference); against the bare MuJoCo steps of as many presses (``mj_step`` called as often,
    in C, without reading, a fingertip resting on the surface; the electrodes' distance sensors
    included), and against the same presses' own steps (the same start and controls, the
    contact left as it is, rolled by ``mujoco.rollout``: what MuJoCo alone costs for them)."""
    import mujoco

    from runner.world.scenario import load_scenario

    scene = load_scenario(ROOT / "models" / "scenarios" / "paper_physics.yaml").physics_scene()
    start = time.perf_counter()
    scene.model  # noqa: B018  (built once per scenario and process)
    build = time.perf_counter() - start
    cells = np.random.default_rng(0).integers(scene.material_map.size, size=60)
    steps = int(round(scene.spec.press / 0.001)) + int(round(scene.spec.stroke / scene.spec.speed
                                                              / 0.001))

    def rngs() -> list[np.random.Generator]:
        return [np.random.default_rng(i) for i in range(len(cells))]

    def batched(threads: int) -> None:
        scene.probes(cells, rngs(), threads=threads)

    def alone() -> None:
        for c, rng in zip(cells, rngs(), strict=True):
            scene.probes(np.array([c]), [rng], threads=1)

    def stepwise() -> None:
        for c, rng in zip(cells, rngs(), strict=True):
            scene.probe_stepwise(int(c), rng)

    data = mujoco.MjData(scene.model)

    def bare() -> None:
        for _ in cells:
            mujoco.mj_resetData(scene.model, data)
            data.qpos[2] = scene.spec.radius
            mujoco.mj_step(scene.model, data, nstep=steps)

    # the same presses' own steps: from the same start, under the same controls (the stage
    # along the stroke, the press's force), the contact left as it is, rolled by MuJoCo in C
    from mujoco import rollout

    spec, model = scene.spec, scene.model
    kind = mujoco.mjtState.mjSTATE_FULLPHYSICS
    ix, iy = np.unravel_index(cells, scene.material_map.shape)
    x0, y0 = (ix + 0.5) * scene.cell - spec.stroke / 2, (iy + 0.5) * scene.cell
    start_states = np.empty((len(cells), mujoco.mj_stateSize(model, kind)))
    for i in range(len(cells)):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = (x0[i], y0[i], spec.radius + 1e-4)
        mujoco.mj_getState(model, data, start_states[i], kind)
    press = int(round(spec.press / 0.001))
    path = np.concatenate([np.zeros(press), np.linspace(0, spec.stroke, steps - press)])
    controls = np.stack([x0[:, None] + path, np.repeat(y0[:, None], steps, axis=1),
                         np.full((len(cells), steps), -spec.force)], axis=2)

    def same_press() -> None:
        rollout.rollout([model] * len(cells), [data], start_states, controls, nstep=steps,
                        skip_checks=True)

    ways = {"batched_1_thread": lambda: batched(1), "batched_2_threads": lambda: batched(2),
            "one_at_a_time": alone, "stepwise": stepwise, "bare": bare,
            "bare_same_press": same_press}
    times: dict[str, list[float]] = {name: [] for name in ways}
    batched(1)  # (the models' copies made once)
    for _ in range(repeats):  # interleaved: each repeat times every way once
        for name, way in ways.items():
            start = time.perf_counter()
            way()
            times[name].append((time.perf_counter() - start) / len(cells))
    ms = {name: 1000 * float(np.median(t)) for name, t in times.items()}
    out = {"scene_build_s": build, "steps_per_probe": steps, "bare_mujoco_steps_ms": ms["bare"],
           "bare_same_press_ms": ms["bare_same_press"]}
    for name in ("batched_1_thread", "batched_2_threads", "one_at_a_time", "stepwise"):
        out[f"{name}_ms"] = ms[name]
        out[f"{name}_ratio"] = ms[name] / ms["bare"]
        out[f"{name}_ratio_same_press"] = ms[name] / ms["bare_same_press"]
    return out


def compare(presses: int, seed: int = 11) -> dict[str, Any]:
    """The features of ``presses`` presses per material of the paper's layout, batched against
    stepwise: each press's largest difference (in standard deviations of the feature), and a
    two-sample Kolmogorov-Smirnov test per material and feature on independent presses (the
    batched presses of seeds (S, m, i), the stepwise of (S + 1, m, i)), its p-values adjusted
    for the number of tests by Holm's method."""
    from scipy import stats
    from statsmodels.stats.multitest import multipletests

    from runner.world.physics import press_cells
    from runner.world.scenario import load_scenario

    scenario = load_scenario(ROOT / "models" / "scenarios" / "paper_physics.yaml")
    scene = scenario.physics_scene()
    rows = []
    for m, cells in press_cells(scenario.material_map, presses, seed):
        batched = scene.probes(cells, [np.random.default_rng([seed, m, i])
                                       for i in range(presses)])
        same = [scene.probe_stepwise(int(c), np.random.default_rng([seed, m, i]))
                for i, c in enumerate(cells)]
        _, other = press_cells(scenario.material_map, presses, seed + 1)[
            [k for k, _ in press_cells(scenario.material_map, 1, seed + 1)].index(m)]
        independent = [scene.probe_stepwise(int(c), np.random.default_rng([seed + 1, m, i]))
                       for i, c in enumerate(other)]
        for name in batched[0].features:
            a = np.array([p.features[name] for p in batched])
            b = np.array([p.features[name] for p in same])
            c = np.array([p.features[name] for p in independent])
            if not np.isfinite(a).any():
                continue  # a feature the material cannot give
            spread = float(np.std(b)) or 1.0
            rows.append({"material": scenario.materials[m], "feature": name,
                         "largest_difference_sd": float(np.max(np.abs(a - b)) / spread),
                         "mean_batched": float(np.mean(a)), "mean_stepwise": float(np.mean(c)),
                         "ks_p": float(stats.ks_2samp(a, c).pvalue)})
    adjusted = multipletests([r["ks_p"] for r in rows], method="holm")[1]
    for row, p in zip(rows, adjusted, strict=True):
        row["ks_p_holm"] = float(p)
    return {"presses_per_material": presses, "tests": len(rows),
            "differ_at_1_percent": [f"{r['material']} {r['feature']}" for r in rows
                                    if r["ks_p_holm"] < 0.01], "features": rows}


def closed_loop(repeats: int) -> dict[str, float]:
    """The 100-step command against the same loop on table readings, whole processes."""
    physics = [BAYESPROG, "robot", "paper_physics", "--physics", "--task", "T2", "--steps",
               "100", "--json"]
    table = [sys.executable, "-c",
             TABLE_LOOP.format(scenario=ROOT / "models" / "scenarios" / "paper.yaml")]
    times: dict[str, list[float]] = {"physics": [], "table": []}
    for _ in range(repeats):
        for name, command in (("physics", physics), ("table", table)):
            start = time.perf_counter()
            subprocess.run(command, check=True, capture_output=True, cwd=ROOT)
            times[name].append(time.perf_counter() - start)
    medians = {k: float(np.median(v)) for k, v in times.items()}
    return {"robot_physics_100_s": medians["physics"], "table_loop_100_s": medians["table"],
            "ratio": medians["physics"] / medians["table"]}


def breakdown() -> dict[str, float]:
    """Where a 100-step physics loop's time goes, in this process: loading the scenario, the
    scene, the probes, and the explorer's decisions (the rest of each step)."""
    from runner.attention.explorer import Explorer
    from runner.experiments.loop import decision_seed, make_sensor, reading_seed, start_cell
    from runner.world.scenario import load_scenario

    start = time.perf_counter()
    scenario = load_scenario(ROOT / "models" / "scenarios" / "paper_physics.yaml")
    loaded = time.perf_counter()
    explorer = Explorer(scenario, "T2")
    explorer.reset(start_cell(scenario.shape, 0, 0)[None], seed=[decision_seed(0, 0)])
    sensor = make_sensor(scenario, [reading_seed(0, 0)])
    scenario.physics_scene().model  # noqa: B018
    built = time.perf_counter()
    probing = deciding = 0.0
    cells = explorer.expected
    for _ in range(100):
        t0 = time.perf_counter()
        readings = sensor.probe(cells)
        t1 = time.perf_counter()
        cells = explorer.step(cells, readings)
        probing += t1 - t0
        deciding += time.perf_counter() - t1
    return {"load_scenario_s": loaded - start, "explorer_and_scene_s": built - loaded,
            "probes_s": probing, "decisions_s": deciding}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--compare", type=int, default=0, metavar="N",
                        help="also compare N batched and stepwise presses per material (2000)")
    parser.add_argument("--only-probes", action="store_true",
                        help="time the probes only (not the closed loop)")
    args = parser.parse_args()
    result: dict[str, Any] = {"per_probe": per_probe(args.repeats)}
    if not args.only_probes:
        result["closed_loop"] = closed_loop(args.repeats)
        result["breakdown_100_steps"] = breakdown()
    if args.compare:
        result["batched_against_stepwise"] = compare(args.compare)
    print(json.dumps(result, indent=2))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
