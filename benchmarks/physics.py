"""What physics probes cost (not a test): one press and stroke of the simulated fingertip
against the bare MuJoCo steps it is made of, and a 100-step ``bayesprog robot --physics``
closed loop as a whole command against the same loop whose readings are drawn from the
perception program's Normals, with where the physics loop's time goes.

Each figure is the median of ``--repeats``; the two commands are timed interleaved in fresh
processes. Reported to standard output and, as JSON, to ``--out``.

    python benchmarks/physics.py [--repeats 5] [--out results/benchmarks/physics.json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

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
    computed), and the bare MuJoCo steps of as many presses (``mj_step`` called as often, in C,
    without reading; the electrodes' distance sensors included)."""
    import mujoco

    from runner.world.scenario import load_scenario

    scene = load_scenario(ROOT / "models" / "scenarios" / "paper_physics.yaml").physics_scene()
    start = time.perf_counter()
    scene.model  # noqa: B018  (built once per scenario and process)
    build = time.perf_counter() - start
    cells = np.random.default_rng(0).integers(scene.material_map.size, size=60)
    steps = int(round(scene.spec.press / 0.001)) + int(round(scene.spec.stroke / scene.spec.speed
                                                              / 0.001))
    ours, bare = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        for i, c in enumerate(cells):
            scene.probe(int(c), np.random.default_rng(i))
        ours.append((time.perf_counter() - start) / len(cells))
        data = mujoco.MjData(scene.model)
        start = time.perf_counter()
        for _ in cells:
            mujoco.mj_resetData(scene.model, data)
            data.qpos[2] = scene.spec.radius
            mujoco.mj_step(scene.model, data, nstep=steps)
        bare.append((time.perf_counter() - start) / len(cells))
    return {"scene_build_s": build, "probe_ms": 1000 * float(np.median(ours)),
            "bare_mujoco_steps_ms": 1000 * float(np.median(bare)),
            "ratio": float(np.median(ours) / np.median(bare)), "steps_per_probe": steps}


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
    args = parser.parse_args()
    result = {"per_probe": per_probe(args.repeats), "closed_loop": closed_loop(args.repeats),
              "breakdown_100_steps": breakdown()}
    print(json.dumps(result, indent=2))
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
