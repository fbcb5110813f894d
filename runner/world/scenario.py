"""Scenarios: a grid of materials made of polygons, the tasks, the templates and the sensor knobs.

A scenario is a YAML file (see ``models/scenarios/paper.yaml``): users describe other workspaces
(polygons of any material, placed templates) without code.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    field_validator,
    model_validator,
)

import bayesprog
from bayesprog import SpecError, did_you_mean, limit, load_document, reference_problem
from runner.world.physics import (
    FEATURES,
    MaterialPhysics,
    MaterialPhysicsPatch,
    ProbeSpec,
    Scene,
    default_materials,
    feature_problems,
    merged,
)
from runner.world.readings import Perception, ReadingError, perception_problems, reading_pairs
from runner.world.sensor import (
    MODEL_READINGS,
    Pooled,
    ProgramNormals,
    SensorModel,
    load_sensor_model,
)
from runner.world.solids import (
    SOLID_KEYS,
    SolidSpec,
    check_outline,
    farthest_points,
    inside,
    outline_points,
    yaw,
)

#: points of a solid's surface its templates are registered against (3-D workspaces); also
#: the most template points a scenario may ask for
SURFACE_SAMPLES = 1500


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class GridSpec(_Strict):
    shape: list[int] = Field(min_length=2, max_length=3, description="cells along x, y (a "
                             "surface) or x, y, z (a volume)")
    cell: float = Field(gt=0)

    @model_validator(mode="after")
    def _size(self) -> GridSpec:
        if any(n < 1 for n in self.shape):
            raise ValueError(f"expected sizes >= 1, found {self.shape}")
        cells, cap = int(np.prod(self.shape)), limit("states")
        if cells > cap:
            raise ValueError(f"a grid of {' x '.join(map(str, self.shape))} has {cells:,} cells, "
                             f"more than the limit of {cap:,} (raise it with the environment "
                             "variable BAYESPROG_MAX_STATES)")
        return self


def _polygon(points: list[list[float]]) -> list[list[float]]:
    check_outline(points, "polygon")
    return points


class CurveSpec(_Strict):
    """A template given as a curve: an ellipse of semi-axes ``ellipse: [a, b]`` or a circle of
    radius ``circle: r`` (metres), centred, its outline a polygon of ``vertices`` corners."""

    ellipse: list[float] | None = None
    circle: float | None = None
    vertices: int = Field(48, ge=8, le=1000)

    @model_validator(mode="after")
    def _one_curve(self) -> CurveSpec:
        if (self.ellipse is None) == (self.circle is None):
            raise ValueError("expected exactly one of 'ellipse: [a, b]' or 'circle: r'")
        if self.ellipse is not None and not (
                len(self.ellipse) == 2 and all(np.isfinite(v) and v > 0 for v in self.ellipse)):
            raise ValueError(f"ellipse: expected two positive semi-axes [a, b] (metres), found "
                             f"{self.ellipse}")
        if self.circle is not None and not (np.isfinite(self.circle) and self.circle > 0):
            raise ValueError(f"circle: expected a positive radius (metres), found {self.circle}")
        return self

    def polygon(self) -> np.ndarray:
        a, b = self.ellipse if self.ellipse is not None else (self.circle, self.circle)
        t = 2 * np.pi * np.arange(self.vertices) / self.vertices
        return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)


def template_polygon(template: list[list[float]] | CurveSpec | SolidSpec) -> np.ndarray:
    """A template's outline as a polygon [V, 2] (a curve's corners, or the points given)."""
    if isinstance(template, SolidSpec):
        raise ValueError("a solid has no outline polygon: it is a template of a 3-D workspace")
    if isinstance(template, CurveSpec):
        return template.polygon()
    return np.asarray(template, float)


def _template_kind(value: Any) -> str:
    if isinstance(value, Mapping):
        return "<solid>" if any(k in value for k in SOLID_KEYS) else "<curve>"
    return "<polygon>"


class ObjectSpec(_Strict):
    material: str
    template: str | None = None
    at: list[float] | None = Field(None, min_length=2, max_length=3,
                                   description="[x, y] (or [x, y, z] in a volume), metres")
    rotation: float = Field(0.0, description="degrees, counter-clockwise (about z in a volume)")
    polygon: list[list[float]] | None = None

    @model_validator(mode="after")
    def _one_shape(self) -> ObjectSpec:
        if (self.template is None) == (self.polygon is None):
            raise ValueError("expected exactly one of 'template' (with 'at') or 'polygon'")
        if self.template is not None and self.at is None:
            raise ValueError("an object placed from a template needs 'at: [x, y]' ('at: [x, y, "
                             "z]' in a volume)")
        if self.polygon is not None:
            check_outline(self.polygon, "polygon")
        return self


#: the column of a lab's recordings that holds the material pressed, when no column is named as
#: the material variable itself
MATERIAL_COLUMN = "material"

#: what a scenario's ``readings:`` may be: the variables read, or reading names and the
#: variable each observes
ReadingNames = list[str] | dict[str, str]


def perception_template() -> Path:
    """The perception program whose forms a lab's recordings are learned into, by default: the
    bundled ``pi_per``."""
    from bayesprog import bundled_root

    return bundled_root() / "pi_per.yaml"


class PerceptionSpec(_Strict):
    """The perception program, the material it perceives and the readings it reads."""

    program: str = Field(description="the perception program (relative to the scenario)")
    material: str = Field("M", description="its variable of the probed cell's material")
    readings: ReadingNames | None = Field(
        None, description="the readings: a list of its variables, or {name: variable} to name "
        "a reading otherwise on the lines and in the columns; by default every variable but "
        "the material, named by its variable (the paper's E and C: texture and compliance)")


class RecordingsSpec(_Strict):
    """A perception program learned from a lab's recordings, at load."""

    recordings: str = Field(description="a CSV or Parquet file of probes (relative to the "
                            "scenario): one row per probe, its material and its readings")
    program: str | None = Field(None, description="the program whose forms are learned (by "
                                "default the runner's pi_per.yaml: a Normal per material and "
                                "feature)")
    material: str = Field("M", description="the program's variable of the material")
    readings: ReadingNames | None = Field(None, description="as for a perception program")
    columns: dict[str, str] = Field(default_factory=dict, description="the variable a column "
                                    "holds, for a column named neither as its reading nor as "
                                    "its variable (the material's column may be named "
                                    "'material')")
    on_bad_lines: Literal["error", "warn", "skip"] = Field(
        "error", description="a bad row (of the wrong number of fields, a value that is not "
        "a number, a state not declared) refuses the file at its line (error), or is set "
        "aside and named in a warning (warn, skip), as bayesprog learn --on-bad-lines does")


class ProgramsSpec(_Strict):
    perception: str | PerceptionSpec | RecordingsSpec
    shape: str
    target: str

    @property
    def perceived(self) -> PerceptionSpec | RecordingsSpec | None:
        """The perception's entry when it is a mapping (None: a program's file alone)."""
        return None if isinstance(self.perception, str) else self.perception

    @property
    def material(self) -> str:
        return self.perceived.material if self.perceived is not None else "M"

    @property
    def readings(self) -> ReadingNames | None:
        return self.perceived.readings if self.perceived is not None else None


class SensorSpec(_Strict):
    model: str | None = Field(None, description="a sensor model file (relative to the "
                              "scenario) the simulated probes are drawn from; by default the "
                              "perception program's own Normals")
    recordings: str | None = Field(None, description="draw the simulated probes from a sensor "
                                   "model fitted to these recordings (per material, a "
                                   "skew-normal per feature and their correlation; the paper's "
                                   "two readings, texture and compliance)")
    resample: str | None = Field(None, description="draw each simulated probe from these "
                                 "recordings: a row of the probed cell's material, chosen by "
                                 "the run's random stream (any readings, missing ones kept)")
    physics: ProbeSpec | None = Field(None, description="every reading from a simulated "
                                      "fingertip pressing and stroking the surface (MuJoCo, "
                                      "the physics extra): how it probes, its noise, how its "
                                      "signals become features; {} or true for the defaults")
    extra_noise: float = Field(0.0, ge=0)
    on_bad_lines: Literal["error", "warn", "skip"] = Field(
        "error", description="for its recordings (recordings:, resample:), as for the "
        "perception's")

    @field_validator("physics", mode="before")
    @classmethod
    def _physics_switch(cls, value: Any) -> Any:
        return {} if value is True else (None if value is False else value)

    @model_validator(mode="after")
    def _one_source(self) -> SensorSpec:
        given = [name for name in ("model", "recordings", "resample", "physics")
                 if getattr(self, name) is not None]
        if len(given) > 1:
            raise ValueError(f"expected one source of readings, found {' and '.join(given)}")
        return self


class ScenarioSpec(_Strict):
    scenario: int = Field(1, ge=1, le=1)
    name: str
    description: str = ""
    programs: ProgramsSpec
    grid: GridSpec
    background: str
    templates: dict[str, Annotated[
        Annotated[list[list[float]], AfterValidator(_polygon), Tag("<polygon>")]
        | Annotated[CurveSpec, Tag("<curve>")]
        | Annotated[SolidSpec, Tag("<solid>")],
        Discriminator(_template_kind)]] = Field(
        min_length=1, description="shapes by name. On a 2-D grid, outlines: a polygon "
        "[[x, y], ...] (any shape, concave ones included) or a curve {ellipse: [a, b]} / "
        "{circle: r}. On a 3-D grid, solids: {box: [lx, ly, lz]}, {ellipsoid: [a, b, c]}, "
        "{sphere: r} or {prism: {polygon: [[x, y], ...], height: h}}")
    template_points: int = Field(50, ge=3, le=SURFACE_SAMPLES, description="points spread "
                                 "along each template's "
                                 "outline (over its surface on a 3-D grid): the shape cue's "
                                 "Gaussian centres")
    shape_matcher: Literal["icp", "chamfer"] = Field(
        "icp", description="how the templates are registered onto the followed border: the "
        "paper's ICP, or a chamfer search over a grid of poses (runner/attention/shape.py)")
    objects: list[ObjectSpec] = Field(default_factory=list)
    tasks: dict[str, str] = Field(min_length=1)
    sensor: SensorSpec = Field(default_factory=SensorSpec)
    physics: dict[str, MaterialPhysicsPatch] = Field(
        default_factory=dict, description="physical properties of materials, for physics "
        "probes (sensor: {physics: ...}): per material any of stiffness (N/m), damping "
        "(N s/m), friction, roughness (m); the others from the bundled defaults "
        "(models/physics/materials.yaml)")


@dataclass
class Scenario:
    """A loaded scenario: the material of every cell, tasks, templates and programs."""

    spec: ScenarioSpec
    path: Path
    materials: tuple[str, ...]
    #: pi_per and pi_tar as used on this workspace (pi_tar's grid O set by the scenario's grid)
    perception: bayesprog.Program
    target: bayesprog.Program
    #: the readings and how they are perceived (pi_per's material and readings)
    readings: Perception = field(default=None)  # type: ignore[assignment]
    #: the model simulated probes are drawn from (None: the perception program)
    sensor_model: SensorModel | Pooled | None = None
    #: what the scenario does that is allowed but may not be meant (an object clipped by the
    #: grid's edge), at its place in the file: the commands print them
    warnings: list = field(default_factory=list)
    _scenes: dict[str, Scene] = field(default_factory=dict, repr=False)
    _pools: dict[str, Pooled] = field(default_factory=dict, repr=False)

    @property
    def name(self) -> str:
        return self.spec.name

    def program_sensor(self, perception: Perception | None = None) -> ProgramNormals | Pooled:
        """Simulated probes drawn from a perception program (by default the scenario's) given
        the cell's material: its own Normals when every reading is a Normal given the
        material alone (the paper's), else draws of the program per material (made once per
        program, from a fixed seed)."""
        perception = perception or self.readings
        if perception.naive_normals:
            return ProgramNormals(perception)
        key = f"pool:{id(perception.program)}"
        if key not in self._pools:
            self._pools[key] = Pooled.from_program(perception)
        return self._pools[key]

    @cached_property
    def physics(self) -> dict[str, MaterialPhysics]:
        """Each material's physical properties: the bundled defaults, the scenario's over them."""
        return merged(default_materials(), self.spec.physics)[0]

    def physics_scene(self, probe: ProbeSpec | None = None) -> Scene:
        """The MuJoCo scene of this surface, probed as ``probe`` says (by default the
        scenario's ``sensor: {physics:}``, else the defaults); built once per probe settings.
        Needs the physics extra (the error names it)."""
        from runner.world.physics import require

        require(f"the sensor: {{physics:}} of {self.path.name}")
        probe = probe or self.spec.sensor.physics or ProbeSpec()
        key = probe.model_dump_json()
        if key not in self._scenes:
            self._scenes[key] = Scene(self.material_map, self.cell, self.materials,
                                      self.physics, probe)
        return self._scenes[key]

    @property
    def shape(self) -> tuple[int, ...]:
        """Cells along each axis: (nx, ny), or (nx, ny, nz) for a volume."""
        return tuple(self.spec.grid.shape)

    @property
    def dims(self) -> int:
        """2 for a surface of cells, 3 for a volume."""
        return len(self.spec.grid.shape)

    @property
    def cell(self) -> float:
        return self.spec.grid.cell

    @cached_property
    def centres(self) -> np.ndarray:
        """Cell centres [cells, dims] in row-major order (the state order of a grid variable)."""
        index = np.meshgrid(*[np.arange(n) for n in self.shape], indexing="ij")
        return (np.stack([i.ravel() for i in index], axis=1) + 0.5) * self.cell

    def polygons(self) -> list[tuple[str, np.ndarray]]:
        """The objects of a 2-D workspace: (material, polygon [V, 2] in metres)."""
        out = []
        for obj in self.spec.objects:
            if obj.polygon is not None:
                out.append((obj.material, np.asarray(obj.polygon, float)))
            else:
                base = template_polygon(self.spec.templates[obj.template])  # type: ignore[index]
                turn = yaw(obj.rotation)[:2, :2]
                out.append((obj.material, base @ turn.T + np.asarray(obj.at)))
        return out

    def object_cells(self) -> list[tuple[str, np.ndarray]]:
        """Per object: its material and which cells (flat) have their centre inside it."""
        if self.dims == 2:
            return [(m, inside(self.centres, poly)) for m, poly in self.polygons()]
        out = []
        for obj in self.spec.objects:
            solid = self.spec.templates[obj.template]  # type: ignore[index]
            assert isinstance(solid, SolidSpec)
            # into the solid's frame: undo the shift, then the rotation about z
            local = (self.centres - np.asarray(obj.at)) @ yaw(obj.rotation)
            out.append((obj.material, solid.inside(local)))
        return out

    @cached_property
    def material_map(self) -> np.ndarray:
        """Index of each cell's true material, shape ``grid shape`` (later objects on top)."""
        flat = np.full(len(self.centres), self.materials.index(self.spec.background))
        for material, cells in self.object_cells():
            flat[cells] = self.materials.index(material)
        return flat.reshape(self.shape)

    def task_material(self, task: str) -> int:
        return self.materials.index(self.spec.tasks[task])

    def counter_materials(self, task: str) -> list[int]:
        """The other side of a task's discontinuity (the paper's Material_b): the remaining
        materials of the workspace, those of its background and objects but the task's."""
        present = [self.spec.background] + [o.material for o in self.spec.objects]
        own = self.spec.tasks[task]
        return sorted({self.materials.index(m) for m in present if m != own})

    def border(self, task: str) -> np.ndarray:
        """Ground-truth border of a task: cells of its material that share a side (a face in a
        volume: 4-adjacency on a surface, 6 in a volume) with a cell of another material."""
        m = self.material_map
        target = m == self.task_material(task)
        padded = np.pad(m, 1, mode="edge")
        other = np.zeros_like(target)
        for axis in range(m.ndim):
            for step in (1, -1):
                window = tuple(slice(1 + (step if a == axis else 0),
                                     1 + (step if a == axis else 0) + m.shape[a])
                               for a in range(m.ndim))
                other |= padded[window] != m
        return target & other

    @cached_property
    def templates(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per template: what it is registered against and ``template_points`` points spread
        evenly over it, in the template frame. On a 2-D grid: the outline polygon [V, 2] and
        points along it (by arc length), centred on the centroid of the points; on a 3-D grid:
        a dense sample of the solid's surface [M, 3] and points spread over it, centred on the
        centroid of the sample."""
        out = {}
        for name, shape in self.spec.templates.items():
            try:
                if isinstance(shape, SolidSpec):
                    dense = shape.surface(SURFACE_SAMPLES)
                    pts = farthest_points(dense, self.spec.template_points)
                    centre = dense.mean(axis=0)
                    out[name] = (dense - centre, pts - centre)
                    continue
                poly_arr = template_polygon(shape)
                pts = outline_points(poly_arr, self.spec.template_points)
                centre = pts.mean(axis=0)
                out[name] = (poly_arr - centre, pts - centre)
            except ValueError as exc:
                raise _TemplateProblem(name, str(exc)) from None
        return out

    def program_path(self, which: str) -> Path:
        named = getattr(self.spec.programs, which)
        if isinstance(named, RecordingsSpec):  # the program its recordings are learned into
            return ((self.path.parent / named.program).resolve() if named.program
                    else perception_template())
        if isinstance(named, PerceptionSpec):
            return (self.path.parent / named.program).resolve()
        return (self.path.parent / named).resolve()

    def recordings_paths(self) -> dict[str, Path]:
        """The recordings the scenario learns from: for its perception, for its sensor."""
        out = {}
        if isinstance(self.spec.programs.perception, RecordingsSpec):
            out["perception_recordings"] = (self.path.parent
                                            / self.spec.programs.perception.recordings).resolve()
        for key in ("recordings", "resample"):
            if getattr(self.spec.sensor, key) is not None:
                out[f"sensor_{'recordings' if key == 'recordings' else 'resampled'}"] = (
                    self.path.parent / getattr(self.spec.sensor, key)).resolve()
        return out

    def load_target(self, terms: Mapping[str, Mapping[str, Any]] | None = None
                    ) -> bayesprog.Program:
        """pi_tar on this workspace's grid, with ``terms``' parameters set (see
        :func:`bayesprog.load`)."""
        return _load_target(self.program_path("target"), self.spec, terms)

    def load_shape(self) -> bayesprog.Program:
        """pi_obj over this workspace's templates."""
        return bayesprog.load(self.program_path("shape"), variables={"R": _shapes(self.spec)})


def _load_target(path: Path, spec: ScenarioSpec,
                 terms: Mapping[str, Mapping[str, Any]] | None = None) -> bayesprog.Program:
    """pi_tar as the scenario ``spec`` sets it: its grid O, its shapes R (the templates) and
    its tasks T (the scenario's, named as it names them)."""
    return bayesprog.load(path, variables={"O": _grid(spec), "R": _shapes(spec),
                                           "T": _tasks(spec)}, terms=terms)


def _tasks(spec: ScenarioSpec) -> dict:
    return {"states": list(spec.tasks),
            "description": "task: the border to follow (the scenario's tasks)"}


def _shapes(spec: ScenarioSpec) -> dict:
    return {"states": list(spec.templates),
            "description": "shape category of the discontinuity (the scenario's templates)"}


def _grid(spec: ScenarioSpec) -> dict:
    """The declaration of pi_tar's O for a scenario: the workspace sets the grid, so one program
    serves every grid size."""
    return {"grid": {"shape": list(spec.grid.shape), "cell": spec.grid.cell},
            "description": "next cell to probe (the scenario's grid)"}


def load_scenario(path: str | Path) -> Scenario:
    """Load and check a scenario file; problems are reported as ``FILE:LINE:COL: message``."""
    path = Path(path)
    located, spec = load_document(path, ScenarioSpec)
    files = {"shape": spec.programs.shape, "target": spec.programs.target}
    recordings = spec.programs.perception if isinstance(spec.programs.perception,
                                                        RecordingsSpec) else None
    perceived = spec.programs.perceived
    if isinstance(spec.programs.perception, str):
        files["perception"] = spec.programs.perception
    elif isinstance(perceived, PerceptionSpec) or (recordings is not None
                                                   and recordings.program is not None):
        files["perception"] = perceived.program  # type: ignore[union-attr,assignment]
    unread = [located.diagnostic(_program_key(spec, which), f"{which} program {name!r}: "
                                 f"{problem}")
              for which, name in files.items()
              if (problem := reference_problem((path.parent / name).resolve(), "program", name))]
    if unread:
        raise SpecError(unread)
    set_aside: list = []
    if recordings is None:
        perception = bayesprog.load((path.parent / files["perception"]).resolve())
        _check_perception(perception, spec, located)
    else:
        perception, set_aside = _learned_perception(path, recordings, located)
    readings = Perception(perception, spec.programs.material, spec.programs.readings)
    materials = readings.materials
    target = _load_target((path.parent / spec.programs.target).resolve(), spec)
    diags = []
    laid = {spec.background, *(o.material for o in spec.objects)}
    for task, material in spec.tasks.items():
        if material in materials and material not in laid:
            diags.append(located.diagnostic(("tasks", task), f"task {task!r} follows the border "
                                            f"of {material!r}, which is in no object of this "
                                            "layout and is not its background: expected one of "
                                            f"{', '.join(sorted(laid))}"))
    named = [("background",), *[("objects", i, "material") for i in range(len(spec.objects))],
             *[("tasks", t) for t in spec.tasks]]
    values = [spec.background, *[o.material for o in spec.objects], *spec.tasks.values()]
    for where, value in zip(named, values, strict=True):
        if value not in materials:
            diags.append(located.diagnostic(where, f"unknown material {value!r}: expected one of "
                                            f"{', '.join(materials)}"))
    dims = len(spec.grid.shape)
    if dims == 3 and spec.shape_matcher != "icp":
        diags.append(located.diagnostic(("shape_matcher",), f"shape matcher "
                                        f"{spec.shape_matcher!r} registers 2-D outlines: a 3-D "
                                        "grid takes 'icp'"))
    for name, shape in spec.templates.items():
        if (dims == 3) != isinstance(shape, SolidSpec):
            diags.append(located.diagnostic(("templates", name), f"template {name!r}: a "
                                            f"{dims}-D grid takes "
                                            + ("solids (box, ellipsoid, sphere or prism)"
                                               if dims == 3 else "outlines (a polygon, "
                                               "an ellipse or a circle)")
                                            + f", found {'a solid' if dims == 2 else 'an outline'}",
                                            at_key=True))
    for i, obj in enumerate(spec.objects):
        if obj.at is not None and len(obj.at) != dims:
            diags.append(located.diagnostic(("objects", i, "at"), f"expected {dims} coordinates "
                                            f"on a {dims}-D grid, found {len(obj.at)}"))
        if obj.polygon is not None and dims == 3:
            diags.append(located.diagnostic(("objects", i, "polygon"), "a 3-D grid takes "
                                            "objects placed from solid templates ('template' "
                                            "with 'at: [x, y, z]'), found a polygon"))
        if obj.template is not None and obj.template not in spec.templates:
            diags.append(located.diagnostic(("objects", i, "template"), f"unknown template "
                                            f"{obj.template!r}: expected one of "
                                            f"{', '.join(spec.templates)}"))
    sensor_model: SensorModel | Pooled | None = None
    diags += _sensor_problems(spec, located, readings)
    if spec.sensor.recordings is not None and not diags:
        sensor_model, more = _fitted_sensor(path, spec, located, readings)
        set_aside += more
    if spec.sensor.resample is not None and not diags:
        sensor_model, more = _resampled_sensor(path, spec, located, readings)
        set_aside += more
    if spec.sensor.model is not None:
        model_path = (path.parent / spec.sensor.model).resolve()
        problem = reference_problem(model_path, "sensor model", spec.sensor.model)
        if problem:
            diags.append(located.diagnostic(("sensor", "model"), f"sensor model "
                                            f"{spec.sensor.model!r}: {problem}"))
        elif not diags:
            sensor_model = load_sensor_model(model_path, materials)
    diags += _physics_problems(spec, located, materials, readings)
    if diags:
        raise SpecError(diags)
    scenario = Scenario(spec, path, materials, perception, target, readings, sensor_model)
    try:  # built once, here, where a problem can say where its template is written
        scenario.templates  # noqa: B018
    except _TemplateProblem as problem:
        raise SpecError([located.diagnostic(("templates", problem.name), f"template "
                                            f"{problem.name!r}: {problem.message}",
                                            at_key=True)]) from None
    empty = [located.diagnostic(("objects", i), f"this object ({obj.material}) holds no "
                                "cell's centre: it lies outside the grid or is thinner than a "
                                f"cell (the grid spans {_extent(spec)} metres)")
             for i, ((_, cells), obj) in enumerate(zip(scenario.object_cells(), spec.objects,
                                                       strict=True)) if not cells.any()]
    if empty:
        raise SpecError(empty)
    scenario.warnings = (set_aside + _physics_warnings(spec, located, readings)
                         + _clipped(scenario, located))
    return scenario


def _clipped(scenario: Scenario, located: Any) -> list:
    """Objects that reach past the grid's edge (they are clipped to it), each named at its
    place in the file: a polygon's corners, or points spread over a solid's surface."""
    low = np.zeros(scenario.dims)
    high = np.asarray(scenario.spec.grid.shape, float) * scenario.spec.grid.cell
    if scenario.dims == 2:
        shapes = [(material, polygon, "corners") for material, polygon in scenario.polygons()]
    else:
        shapes = []
        for obj in scenario.spec.objects:
            solid = scenario.spec.templates[obj.template]  # type: ignore[index]
            assert isinstance(solid, SolidSpec)
            points = solid.surface(200) @ yaw(obj.rotation).T + np.asarray(obj.at)
            shapes.append((obj.material, points, "surface points"))
    out = []
    for i, (material, points, what) in enumerate(shapes):
        outside = np.any((points < low - 1e-12) | (points > high + 1e-12), axis=1)
        if outside.any():
            out.append(located.diagnostic(
                ("objects", i), f"warning: object {i + 1} ({material}) reaches past the edge of "
                f"the grid ({_extent(scenario.spec)} metres): {int(outside.sum())} of its "
                f"{len(points)} {what} are outside; it is clipped to the grid"))
    return out


def _program_key(spec: ScenarioSpec, which: str) -> tuple:
    """Where a scenario names its ``which`` program's file."""
    if which == "perception" and spec.programs.perceived is not None:
        return ("programs", "perception", "program")
    return ("programs", which)


def _check_perception(program: bayesprog.Program, spec: ScenarioSpec, located: Any,
                      where: tuple = ("programs", "perception")) -> None:
    """The perception program declares the material and every reading, each problem at the
    scenario's key that names it."""
    perceived = spec.programs.perceived
    diags = []
    for key, message in perception_problems(program, spec.programs.material,
                                            spec.programs.readings):
        at = where
        if perceived is not None and key in perceived.model_fields_set:
            at = ("programs", "perception", key)
        diags.append(located.diagnostic(at, f"perception program {program.name!r}: {message}"))
    if diags:
        raise SpecError(diags)


def _recordings_frame(path: Path, name: str, columns: Mapping[str, str],
                      needed: Sequence[tuple[str, str]], located: Any, where: tuple,
                      variables: Mapping[str, Any], states_from_data: Sequence[str] = (),
                      on_bad_lines: str = "error") -> tuple[Path, Any, dict[str, str], list]:
    """The recordings ``name`` (relative to the scenario at ``path``) as a DataFrame whose
    columns are named as the variables ``needed`` (pairs of a reading or the material's
    column name and its variable), each checked against the program's ``variables``; the
    columns it read under another name; and the bad rows set aside (``on_bad_lines``, as
    ``bayesprog learn`` takes it: by default the first is refused). Read as ``bayesprog
    learn`` reads data (its delimiter by the suffix, a byte-order mark and spaces after the
    delimiters skipped). A problem is at ``where``. A column is found by the name ``columns``
    gives it, else by its reading's name (the material's: 'material'), else by its
    variable's."""
    file = (path.parent / name).resolve()
    problem = reference_problem(file, "recordings", name) if not file.is_file() else None
    if problem:
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: {problem}")])
    mode = "skip" if on_bad_lines != "error" else "error"  # warned here, at the scenario's line
    hint = "" if on_bad_lines != "error" else " (on_bad_lines: skip sets bad rows aside)"
    try:  # its columns as the reader names them, to find the readings' among them
        header = [str(c) for c in bayesprog.read_data(file, on_bad_lines="skip")[0].columns]
    except bayesprog.BayesprogError as exc:
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: cannot read it as "
                                            f"CSV or Parquet: {exc}")]) from None
    rename = {c: v for c, v in columns.items() if c in header and c != v}
    for column, variable in needed:
        if variable not in header and variable not in rename.values() \
                and column in header and column != variable:
            rename[column] = variable
    found = [rename.get(c, c) for c in header]
    missing = [(c, v) for c, v in needed if v not in found]
    if missing:
        spare = [c for c in header if c not in rename]
        told = [f"{c!r}" + (f" (for {v})" if v != c else "") + did_you_mean(c, spare).replace(
            ": did you mean", ", did you mean") for c, v in missing]
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: no column "
                                            f"{', '.join(told)} (columns: "
                                            f"{', '.join(map(str, header))}; name the "
                                            "columns with columns: {COLUMN: VARIABLE})")])
    try:
        frame, set_aside = bayesprog.read_data(
            file, {v: variables[v] for _, v in needed}, columns=rename or None,
            states_from_data=states_from_data, on_bad_lines=mode)
    except bayesprog.BayesprogError as exc:
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: {exc}{hint}")]
                        ) from None
    return file, frame, rename, list(set_aside)


def _set_aside(located: Any, where: tuple, name: str, rows: Sequence[Any]) -> list:
    """The bad rows of recordings set aside, as a warning at the key that names them."""
    if not rows:
        return []
    listed = "; ".join(str(r) for r in rows[:5]) + (f"; and {len(rows) - 5} more"
                                                    if len(rows) > 5 else "")
    return [located.diagnostic(where, f"warning: recordings {name!r}: {len(rows)} bad row(s) "
                               f"set aside: {listed}")]


def _needed_columns(material: str, pairs: Sequence[tuple[str, str]]) -> list[tuple[str, str]]:
    """The recordings' columns a perception reads: (column name, variable), the material's
    first."""
    return [(MATERIAL_COLUMN, material), *pairs]


def _learned_perception(path: Path, spec: RecordingsSpec, located: Any
                        ) -> tuple[bayesprog.Program, list]:
    """The perception program learned from a lab's recordings: the template's forms, the
    materials of the recordings (as written), its terms fitted by maximum likelihood (as
    ``bayesprog learn --states-from-data M`` does); and the warnings of the bad rows set
    aside (``on_bad_lines``)."""
    where = ("programs", "perception", "recordings")
    template_path = ((path.parent / spec.program).resolve() if spec.program
                     else perception_template())
    template = bayesprog.load(template_path)
    problems = perception_problems(template, spec.material, spec.readings)
    if problems:
        raise SpecError([located.diagnostic(
            ("programs", "perception", key) if key in spec.model_fields_set else where,
            f"perception program {template.name!r}: {message}") for key, message in problems])
    pairs = reading_pairs(template, spec.material, spec.readings)
    needed = _needed_columns(spec.material, pairs)
    file, frame, rename, bad = _recordings_frame(
        path, spec.recordings, spec.columns, needed, located, where, template.variables,
        [spec.material], spec.on_bad_lines)
    try:  # the file itself, so that its learned: record names it; its other columns read past
        fitted = template.fit(str(file), columns=rename or None, states_from_data=[
            spec.material], on_bad_lines="skip" if bad else "error",
            other_columns="ignore").program
    except bayesprog.BayesprogError as exc:
        raise SpecError([located.diagnostic(where, f"recordings {spec.recordings!r}: "
                                            f"{exc}")]) from None
    return fitted, _set_aside(located, where, spec.recordings, bad)


def _sensor_columns(spec: ScenarioSpec) -> dict[str, str]:
    perceived = spec.programs.perceived
    return perceived.columns if isinstance(perceived, RecordingsSpec) else {}


def _sensor_problems(spec: ScenarioSpec, located: Any, readings: Perception) -> list:
    """A sensor that cannot give the readings the perception program reads: a sensor model or
    recordings fitted as one give the paper's texture and compliance only."""
    out = []
    for key, what in (("model", "a sensor model"), ("recordings", "a sensor model fitted to "
                                                    "recordings")):
        if getattr(spec.sensor, key) is not None and set(readings.names) != set(MODEL_READINGS):
            out.append(located.diagnostic(
                ("sensor", key), f"{what} gives the readings {', '.join(MODEL_READINGS)} (the "
                f"paper's), but the perception program reads {', '.join(readings.names)}: "
                "resample the lab's recordings (sensor: {resample: FILE}), or leave sensor: "
                "out to draw the probes from the perception program"))
    return out


def _fitted_sensor(path: Path, spec: ScenarioSpec, located: Any, readings: Perception
                   ) -> tuple[SensorModel, list]:
    """A sensor model of the paper's two readings fitted to the recordings the sensor names,
    and the warnings of the bad rows set aside."""
    where = ("sensor", "recordings")
    name = spec.sensor.recordings
    assert name is not None
    needed = [(MATERIAL_COLUMN, readings.material),
              *[(n, readings.reading(n).variable) for n in MODEL_READINGS]]
    file, frame, _, bad = _recordings_frame(path, name, _sensor_columns(spec), needed,
                                            located, where, readings.program.variables,
                                            on_bad_lines=spec.sensor.on_bad_lines)
    frame = frame.rename(columns={v: k for k, (_, v) in zip(("M", "E", "C"), needed,
                                                             strict=True) if k != v})
    found = sorted({str(m) for m in frame["M"].dropna()})
    lacking = [m for m in readings.materials if m not in found]
    if lacking:
        raise SpecError([located.diagnostic(where, f"recordings {name!r} hold no probe of "
                                            f"{', '.join(lacking)}: the simulated sensor needs "
                                            "each material of the perception program")])
    try:
        return (SensorModel.from_recordings(frame, readings.materials, file),
                _set_aside(located, where, name, bad))
    except ValueError as exc:
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: {exc}")]) from None


def _resampled_sensor(path: Path, spec: ScenarioSpec, located: Any, readings: Perception
                      ) -> tuple[Pooled, list]:
    """Probes resampled per material from the recordings the sensor names, and the warnings
    of the bad rows set aside."""
    where = ("sensor", "resample")
    name = spec.sensor.resample
    assert name is not None
    needed = _needed_columns(readings.material, [(r.name, r.variable)
                                                 for r in readings.readings])
    file, frame, _, bad = _recordings_frame(path, name, _sensor_columns(spec), needed, located,
                                            where, readings.program.variables,
                                            on_bad_lines=spec.sensor.on_bad_lines)
    laid = {spec.background, *(o.material for o in spec.objects)}
    try:
        pooled = Pooled.from_recordings(frame, readings, readings.material,
                                        f"recordings {name}", file)
    except (ValueError, ReadingError) as exc:
        raise SpecError([located.diagnostic(where, f"recordings {name!r}: {exc}")]) from None
    lacking = [m for m, pool in zip(readings.materials, pooled.pools, strict=True)
               if m in laid and np.isnan(pool).all()]
    if lacking:
        raise SpecError([located.diagnostic(where, f"recordings {name!r} hold no probe of "
                                            f"{', '.join(lacking)} with a reading: the "
                                            "simulated sensor resamples each material the "
                                            "layout lays")])
    return pooled, _set_aside(located, where, name, bad)


def _physics_problems(spec: ScenarioSpec, located: Any, materials: tuple[str, ...],
                      readings: Perception) -> list:
    """A physics entry for a material the perception program does not know, one that lacks
    properties, and (with physics probes) a laid material that has none, or a volume."""
    diags = [located.diagnostic(("physics", name), f"unknown material {name!r}: expected one "
                                f"of {', '.join(materials)}", at_key=True)
             for name in spec.physics if name not in materials]
    defaults = default_materials()
    properties, lacking = merged(defaults, spec.physics)
    diags += [located.diagnostic(("physics", name), f"{name} has no bundled physical "
                                 f"properties: give {', '.join(missing)} too", at_key=True)
              for name, missing in lacking.items()]
    if spec.sensor.physics is not None:
        if len(spec.grid.shape) != 2:
            diags.append(located.diagnostic(("sensor", "physics"), "physics probes press a "
                                            "surface: a volume (a 3-D grid) is not modelled",
                                            at_key=True))
        laid = {spec.background, *(o.material for o in spec.objects)}
        diags += [located.diagnostic(("sensor", "physics"), f"material {name!r} has no "
                                     "physical properties: give them under physics:",
                                     at_key=True)
                  for name in sorted(laid) if name in materials and name not in properties
                  and name not in lacking]
        probe = spec.sensor.physics
        diags += [located.diagnostic(("sensor", "physics", *where), message, at_key=True)
                  for where, message in feature_problems(probe, properties, laid)]
        diags += [located.diagnostic(("sensor", "physics", "readings", name), f"reading "
                                     f"{name!r} is discrete (states {', '.join(r.states)}): "
                                     "the fingertip's features are numbers", at_key=True)
                  for name in probe.readings
                  if name in readings.names and (r := readings.reading(name)).states]
        given, read = list(probe.readings), list(readings.names)
        unknown = [n for n in given if n not in read]
        diags += [located.diagnostic(("sensor", "physics", "readings", name), f"reading "
                                     f"{name!r}: the perception program reads no such reading"
                                     + did_you_mean(name, read)
                                     + f" (its readings: {', '.join(read)})", at_key=True)
                  for name in unknown]
        if not unknown and not set(given) & set(read):
            diags.append(located.diagnostic(("sensor", "physics"), "the fingertip gives none "
                                            f"of the readings {', '.join(read)}", at_key=True))
    return diags


def _physics_warnings(spec: ScenarioSpec, located: Any, readings: Perception) -> list:
    """The readings a physics fingertip does not give: missing on every probe (summed out)."""
    if spec.sensor.physics is None:
        return []
    given = set(spec.sensor.physics.readings)
    lacking = [n for n in readings.names if n not in given]
    if not lacking or not given & set(readings.names):
        return []
    return [located.diagnostic(("sensor", "physics"), f"warning: the fingertip gives no "
                               f"{', '.join(lacking)} (map a reading to a feature under "
                               "sensor: physics: readings: {READING: FEATURE}; features: "
                               + ", ".join(FEATURES) + "): missing on every probe, summed out",
                               at_key=True)]


def _extent(spec: ScenarioSpec) -> str:
    return " x ".join(f"{n * spec.grid.cell:g}" for n in spec.grid.shape)


class _TemplateProblem(ValueError):
    """A template whose points cannot be built."""

    def __init__(self, name: str, message: str):
        super().__init__(f"template {name!r}: {message}")
        self.name, self.message = name, message
