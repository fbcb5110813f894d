"""Haptic sensors: the interface the explorer reads, and the simulated sensors: a sensor model of
the paper's two readings, the perception program's own Normals, draws from any perception
program given the material, or a lab's recordings resampled per material."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bayesprog import Program, SpecError, load_document
from runner.world.readings import Perception, Readings, normal_of

#: the readings a sensor model of the paper's kind gives (models/sensors/*.yaml)
MODEL_READINGS = ("texture", "compliance")


class HapticSensor(Protocol):
    """What the explorer needs from a sensor: the readings of the probed cells.

    A real robot implements ``probe`` by moving the hand to each cell (one per run) and
    extracting its features; the simulator draws them from the true material.
    """

    def probe(self, cells: np.ndarray) -> Readings:
        """``cells`` [runs] flat cell indices -> the readings of each run's probe."""
        ...


def material_normals(perception: Program) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Mean and sigma per material of the perception program's ``P(E | M)`` and ``P(C | M)``."""
    out = {}
    for feature in ("E", "C"):
        normal = normal_of(perception, feature, "M")
        if normal is None:
            raise ValueError(f"P({feature} | M) must be a Normal of literal parameters")
        out[feature] = normal
    return out


# A haptic sensor model that is not pi_per ---------------------------------------------------------
class FeatureSpec(BaseModel):
    """A skew-normal: ``loc + scale * (delta |u0| + sqrt(1 - delta^2) u1)``, delta from ``skew``."""

    model_config = ConfigDict(extra="forbid")
    loc: float
    scale: float = Field(gt=0)
    skew: float = Field(0.0, description="shape of the skew-normal (0: a Normal)")


class MaterialSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    texture: FeatureSpec
    compliance: FeatureSpec
    correlation: float = Field(0.0, gt=-1, lt=1, description="between the two features' "
                               "symmetric parts")
    why: str = ""


class SensorModelSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    sensor: int = Field(1, ge=1, le=1)
    name: str
    description: str = ""
    materials: dict[str, MaterialSpec] = Field(min_length=1)


class SensorModel:
    """Texture and compliance of each material, as a sensor reads them: per material a
    skew-normal for each feature, of its own spread, the two correlated. Draws for any list of
    materials from standard normals, so a caller controls the random stream."""

    def __init__(self, spec: SensorModelSpec, materials: Sequence[str], path: Path | None = None):
        self.spec, self.path = spec, path
        self.materials = tuple(materials)
        rows = [spec.materials[m] for m in self.materials]

        def column(feature: str, key: str) -> np.ndarray:
            return np.array([getattr(getattr(r, feature), key) for r in rows], float)

        self.loc = np.stack([column("texture", "loc"), column("compliance", "loc")], 1)
        self.scale = np.stack([column("texture", "scale"), column("compliance", "scale")], 1)
        skew = np.stack([column("texture", "skew"), column("compliance", "skew")], 1)
        self.delta = skew / np.sqrt(1 + skew**2)
        self.rho = np.array([r.correlation for r in rows])

    #: standard normals a simulated probe draws: four for the features, two for the noise
    normals_per_probe = 6

    #: the readings it gives
    names = MODEL_READINGS

    def readings(self, materials: np.ndarray, z: np.ndarray, extra_noise: float) -> Readings:
        """``materials`` [n], ``z`` [n, 6] -> texture and compliance [n], white noise of sd
        ``extra_noise`` added from ``z[:, 4:]``."""
        texture, compliance = self.draw(materials, z[:, :4])
        return Readings(self.names, np.stack([texture + extra_noise * z[:, 4],
                                              compliance + extra_noise * z[:, 5]], axis=1))

    def held_out(self, per_material: int, seed: int, extra_noise: float = 0.0
                 ) -> tuple[np.ndarray, Readings]:
        """``per_material`` probes of each material (see :meth:`record`): the materials'
        indices [n] and their readings."""
        data = self.record(per_material, seed, extra_noise)
        truth = np.repeat(np.arange(len(self.materials)), per_material)
        return truth, Readings.of(self.names, {"texture": data["E"], "compliance": data["C"]})

    def draw(self, materials: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``materials`` [n] indices, ``z`` [n, 4] standard normals -> (texture, compliance)."""
        m = np.asarray(materials)
        rho = self.rho[m]
        sym = np.stack([z[:, 0], rho * z[:, 0] + np.sqrt(1 - rho**2) * z[:, 1]], 1)
        d = self.delta[m]
        x = self.loc[m] + self.scale[m] * (d * np.abs(z[:, 2:4]) + np.sqrt(1 - d**2) * sym)
        return x[:, 0], x[:, 1]

    @classmethod
    def from_program(cls, perception: Perception) -> SensorModel:
        """The perception program's own Normals of the paper's two readings as a sensor model
        (no skew, no correlation)."""
        normals = {name: perception.normal(name) for name in MODEL_READINGS}
        if any(n is None for n in normals.values()):
            raise ValueError("a sensor model of the perception program needs its texture and "
                             "compliance each a Normal given the material")
        texture, compliance = normals["texture"], normals["compliance"]
        assert texture is not None and compliance is not None
        spec = SensorModelSpec(name=f"{perception.program.name} Normals", materials={
            m: MaterialSpec(texture=FeatureSpec(loc=texture[0][i], scale=texture[1][i]),
                            compliance=FeatureSpec(loc=compliance[0][i], scale=compliance[1][i]))
            for i, m in enumerate(perception.materials)})
        return cls(spec, perception.materials)

    @classmethod
    def from_recordings(cls, frame: Any, materials: Sequence[str],
                        path: Path | None = None) -> SensorModel:
        """A sensor model fitted to a lab's recordings (a DataFrame of columns M, E, C): per
        material, each feature's skew-normal by maximum likelihood (``scipy.stats.skewnorm.fit``:
        its shape is this model's ``skew``, its location and scale ``loc`` and ``scale``), and
        the correlation of the two features' symmetric parts: the features' correlation (from
        their ranks, Spearman's turned into the Normal's, ``2 sin(pi rho_s / 6)``) divided by
        what the skewed parts take from it (each feature's variance is ``scale^2 (1 - 2
        delta^2 / pi)``, of which the symmetric part carries ``scale^2 (1 - delta^2)``).
        Raises ValueError for a material with too few probes."""
        from scipy import stats

        specs = {}
        for material in materials:
            rows = frame[frame["M"].astype(str) == material]
            if len(rows) < 10:
                raise ValueError(f"{len(rows)} probe(s) of {material}: expected at least 10 "
                                 "to fit its readings")
            features = {}
            for name, column in (("texture", "E"), ("compliance", "C")):
                x = np.asarray(rows[column], float)
                x = x[np.isfinite(x)]
                if len(x) < 10 or np.std(x) == 0:
                    raise ValueError(f"the {name} of {material}: expected at least 10 probes "
                                     "that differ")
                shape, loc, scale = stats.skewnorm.fit(x)
                features[name] = FeatureSpec(loc=float(loc), scale=float(scale),
                                             skew=float(shape))
            both = rows[["E", "C"]].astype(float).dropna()
            rho_s = float(stats.spearmanr(both["E"], both["C"]).statistic)
            observed = 2 * np.sin(np.pi * rho_s / 6)
            delta2 = [(f.skew ** 2) / (1 + f.skew ** 2) for f in features.values()]
            carried = np.sqrt(np.prod([(1 - d) / (1 - 2 * d / np.pi) for d in delta2]))
            rho = float(np.clip(observed / carried, -0.99, 0.99))
            specs[material] = MaterialSpec(texture=features["texture"],
                                           compliance=features["compliance"],
                                           correlation=0.0 if not np.isfinite(rho) else rho,
                                           why="fitted to the recordings")
        name = path.name if path is not None else "recordings"
        spec = SensorModelSpec(name=f"fitted to {name}", materials=specs,
                               description="per material, a skew-normal per feature fitted by "
                               "maximum likelihood, and their rank correlation")
        return cls(spec, materials)  # its file is the recordings, kept with the scenario's

    def record(self, per_material: int, seed: int, extra_noise: float = 0.0) -> dict[str, list]:
        """A training set: ``per_material`` probes of each material, each material from its own
        seeded stream (columns M, E, C), plus optional white noise."""
        out: dict[str, list] = {"M": [], "E": [], "C": []}
        for i, name in enumerate(self.materials):
            rng = np.random.default_rng([seed, i])
            z = rng.standard_normal((per_material, 4))
            e, c = self.draw(np.full(per_material, i), z)
            if extra_noise:
                noise = rng.standard_normal((per_material, 2)) * extra_noise
                e, c = e + noise[:, 0], c + noise[:, 1]
            out["M"] += [name] * per_material
            out["E"] += [float(f"{v:.6g}") for v in e]
            out["C"] += [float(f"{v:.6g}") for v in c]
        return out


def load_sensor_model(path: str | Path, materials: Sequence[str] | None = None) -> SensorModel:
    """Load a sensor model file; every material of ``materials`` must be described (by default
    the file's materials, in its order)."""
    path = Path(path)
    located, spec = load_document(path, SensorModelSpec)
    materials = tuple(spec.materials) if materials is None else materials
    missing = [m for m in materials if m not in spec.materials]
    if missing:
        raise SpecError([located.diagnostic(("materials",), f"no model for material(s) "
                                            f"{', '.join(missing)}: expected every material of "
                                            "the perception program", at_key=True)])
    return SensorModel(spec, materials, path)


class ProgramNormals:
    """The perception program's own Normals, as a simulated sensor draws from them, for a
    program whose readings are each a Normal given the material alone: per probe two standard
    normals per reading, ``[z, noise]`` in the readings' order (for the paper's program
    ``[z_E, noise_E, z_C, noise_C]``, the draw order of its experiments, kept so that they
    repeat)."""

    def __init__(self, perception: Perception):
        self.names = perception.names
        self.normals = [perception.normal(name) for name in self.names]
        if any(n is None for n in self.normals):
            raise ValueError("ProgramNormals needs every reading a Normal given the material")
        self.normals_per_probe = 2 * len(self.names)
        self.materials = perception.materials

    def readings(self, materials: np.ndarray, z: np.ndarray, extra_noise: float) -> Readings:
        """``materials`` [n], ``z`` [n, 2 x readings] -> the readings [n]."""
        out = np.empty((len(materials), len(self.names)))
        for i, normal in enumerate(self.normals):
            assert normal is not None
            mean, sigma = normal
            out[:, i] = (mean[materials] + sigma[materials] * z[:, 2 * i]
                         + z[:, 2 * i + 1] * extra_noise)
        return Readings(self.names, out)

    def held_out(self, per_material: int, seed: int, extra_noise: float = 0.0
                 ) -> tuple[np.ndarray, Readings]:
        """``per_material`` probes of each material, each material from its own seeded
        stream: the materials' indices [n] and their readings."""
        return _held_out(self, per_material, seed, extra_noise)


#: draws per material a program's pool holds (see :class:`Pooled`)
POOL = 20_000


class Pooled:
    """Readings resampled per material from a pool of probes: a lab's recordings (its rows of
    each material, missing readings kept missing), or draws of the perception program given
    each material (any structure: features that depend on each other, mixtures, discrete
    readings), :data:`POOL` per material, drawn once from the scenario's seed. A probe of
    material m takes one row of m's pool, chosen by one standard normal of its run's stream
    (through the normal CDF), plus white noise on its real readings."""

    def __init__(self, names: Sequence[str], pools: Sequence[np.ndarray],
                 discrete: Sequence[bool], materials: Sequence[str], source: str):
        self.names = tuple(names)
        self.pools = [np.asarray(p, float).reshape(-1, len(self.names)) for p in pools]
        self.real = ~np.asarray(discrete, bool)
        #: each reading's support, that white noise keeps to (None: unbounded)
        self.supports: list[tuple[float, float]] = [(-np.inf, np.inf)] * len(self.names)
        self.source = source
        #: the file the pool was read from, if any (kept with an experiment's files)
        self.path: Path | None = None
        self.normals_per_probe = 1 + len(self.names)
        self.materials = tuple(materials)

    @classmethod
    def from_program(cls, perception: Perception, seed: int = 0, size: int = POOL) -> Pooled:
        """Draws of the perception program's readings given each material (forward draws kept
        where they are of that material: the material's prior only sets how many are drawn)."""
        program, material = perception.program, perception.material
        pools = []
        for i, name in enumerate(perception.materials):
            draws = program.sample(size, {material: name}, rng=np.random.default_rng(
                [seed, 0x5A3, i]), method="rejection")
            columns = []
            for r in perception.readings:
                column = draws[r.variable]
                columns.append(np.array([r.states.index(str(v)) for v in column], float)
                               if r.states is not None else np.asarray(column, float))
            pools.append(np.stack(columns, axis=1))
        pooled = cls(perception.names, pools, [r.discrete for r in perception.readings],
                     perception.materials, f"draws of {program.name} given each material")
        pooled.supports = [r.support for r in perception.readings]
        return pooled

    @classmethod
    def from_recordings(cls, frame: Any, perception: Perception, material_column: str,
                        source: str, path: Path | None = None) -> Pooled:
        """The rows of each material of a recordings frame (its columns named as the
        readings' variables) that hold at least one reading; a material without such rows
        draws nothing (it must not be laid)."""
        pools = []
        for name in perception.materials:
            rows = frame[frame[material_column].astype(str) == name]
            columns = [np.array([r.value(_plain(v)) for v in rows[r.variable]], float)
                       for r in perception.readings]
            pool = np.stack(columns, axis=1) if len(rows) else np.empty((0, len(columns)))
            pool = pool[~np.isnan(pool).all(axis=1)]  # a press with no reading: nothing drawn
            pools.append(pool if len(pool) else np.full((1, len(columns)), np.nan))
        pooled = cls(perception.names, pools, [r.discrete for r in perception.readings],
                     perception.materials, source)
        pooled.path, pooled.supports = path, [r.support for r in perception.readings]
        return pooled

    def readings(self, materials: np.ndarray, z: np.ndarray, extra_noise: float) -> Readings:
        from scipy.special import ndtr

        materials = np.asarray(materials)
        out = np.empty((len(materials), len(self.names)))
        u = ndtr(z[:, 0])
        for m in np.unique(materials):
            rows = np.flatnonzero(materials == m)
            pool = self.pools[int(m)]
            pick = np.minimum((u[rows] * len(pool)).astype(np.int64), len(pool) - 1)
            out[rows] = pool[pick]
        if extra_noise:  # kept within each reading's support, as a sensor's range is
            out[:, self.real] += extra_noise * z[:, 1:][:, self.real]
            low, high = np.array(self.supports, float).T
            out = np.clip(out, low, high)
        return Readings(self.names, out)

    def held_out(self, per_material: int, seed: int, extra_noise: float = 0.0
                 ) -> tuple[np.ndarray, Readings]:
        return _held_out(self, per_material, seed, extra_noise)


def _plain(value: Any) -> Any:
    """A frame's cell as a reading is sent: NaN and None missing, numpy scalars as Python's."""
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return None
    return value.item() if hasattr(value, "item") else value


def _held_out(model: Any, per_material: int, seed: int, extra_noise: float
              ) -> tuple[np.ndarray, Readings]:
    """``per_material`` probes of each material of ``model`` (its readings from standard
    normals), each material from its own seeded stream."""
    parts, truth = [], []
    for i in range(len(model.materials)):
        rng = np.random.default_rng([seed, i])
        z = rng.standard_normal((per_material, model.normals_per_probe))
        parts.append(model.readings(np.full(per_material, i), z, extra_noise))
        truth.append(np.full(per_material, i))
    return np.concatenate(truth), Readings.stack(parts)


class SimulatedSensor:
    """Simulated probes: the readings of the true material of each probed cell, drawn from
    ``model`` (a :class:`SensorModel`, the perception program's :class:`ProgramNormals`, or a
    :class:`Pooled` program or recordings), plus optional white noise. Each run has its own
    generator, so a run's readings do not depend on the other runs."""

    def __init__(self, material_map: np.ndarray, model: SensorModel | ProgramNormals | Pooled,
                 seeds: Sequence[int | tuple[int, ...] | np.random.SeedSequence],
                 extra_noise: float = 0.0):
        self.materials = material_map.ravel()
        self.model = model
        self.extra_noise = extra_noise
        self.rngs = [np.random.default_rng(s) for s in seeds]

    def probe(self, cells: np.ndarray) -> Readings:
        z = np.array([rng.standard_normal(self.model.normals_per_probe) for rng in self.rngs])
        return self.model.readings(self.materials[np.asarray(cells)], z, self.extra_noise)


def confusion(perception: Perception | Program, model: SensorModel | ProgramNormals | Pooled,
              per_material: int, seed: int, extra_noise: float = 0.0) -> np.ndarray:
    """Single-probe confusion of ``perception`` (a program: through its default readings) on
    held-out probes of ``model``: row = true material, column = the MAP material, each row
    sums to one."""
    if isinstance(perception, Program):
        perception = Perception(perception)
    truth, readings = model.held_out(per_material, seed, extra_noise)
    post = perception.posterior(readings)
    k = len(perception.materials)
    out = np.zeros((k, k))
    np.add.at(out, (truth, post.argmax(-1)), 1.0)
    return out / per_material


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m runner.sensor MODEL.yaml --per-material N --seed S -o PROBES.csv``: record a
    training set of probes from a sensor model (for ``bayesprog learn``)."""
    import argparse
    import sys

    import pandas as pd

    from bayesprog import BayesprogError, atomic_write

    parser = argparse.ArgumentParser(prog="python -m runner.sensor",
                                     description="record probes of every material from a "
                                     "sensor model (columns M, E, C)")
    parser.add_argument("model", metavar="MODEL.yaml")
    parser.add_argument("--perception", default=None, metavar="PI_PER.yaml",
                        help="the program whose materials are recorded, in its order (default: "
                        "the sensor model's order)")
    parser.add_argument("--per-material", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-o", "--output", required=True, metavar="PROBES.csv")
    args = parser.parse_args(argv)
    try:
        if args.per_material < 1:
            raise BayesprogError(f"--per-material: expected at least 1, found {args.per_material}")
        materials = None
        if args.perception:
            import bayesprog

            materials = bayesprog.load(args.perception).variables["M"].states  # type: ignore[union-attr]
        model = load_sensor_model(args.model, materials)
        frame = pd.DataFrame(model.record(args.per_material, args.seed))
        atomic_write(Path(args.output), frame.to_csv(index=False).encode(), parents=False)
    except SpecError as exc:
        for d in exc.diagnostics:
            print(d, file=sys.stderr)
        return 2
    except (BayesprogError, OSError) as exc:
        print(f"runner.sensor: {exc}", file=sys.stderr)
        return 2
    print(f"{args.output}: {args.per_material} probes of each of {len(model.materials)} materials "
          f"(seed {args.seed})")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
