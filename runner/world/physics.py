"""Probes as physics (MuJoCo): a fingertip on a Cartesian stage presses each cell of a surface
to a set normal force, strokes it a few millimetres and lifts; the forces and the depth it
measures become the texture and compliance the explorer reads.

The scene is built from a scenario: the workspace's surface, each cell of its material; the
fingertip, a sphere on a Cartesian stage of three slide joints, x and y holding it through a
compliant force sensor, z force-controlled (the stage carries its weight, so gravity is left
out). Each material has a contact stiffness and damping (MuJoCo's soft contact, set so that a
press of F newtons indents the surface F / stiffness metres once settled), a friction
coefficient and a roughness. The contact under the fingertip takes each cell's properties in
proportion to its share of the contact disc, so a press on a border feels both materials. The
roughness is modelled by its equivalent along a stroke: a smooth random relief per material (a
few variants, each cell one of them) whose heights have the material's roughness as standard
deviation, bumps about a millimetre across; where the fingertip slides up a slope s of it, the
friction coefficient under it is raised by s (a sphere sliding up a bump of slope s feels about
F_n (mu + s) along its path), and lowered going down.

A probe (:meth:`Scene.probe`), all in simulated time steps of one millisecond:

1. approach: the fingertip starts 0.1 mm above the surface, over the cell's centre plus the
   hand's positioning error (``jitter``), and comes down at 2 mm/s;
2. press: it settles for ``press`` seconds; the depth is how far it moved from where it met
   the surface (the height at which the normal force starts to rise, from a line through the
   force against the height while it rises), the normal force the contact's;
3. stroke: the stage moves it ``stroke`` metres along x at ``speed``; the tangential force is
   what the x axis's force sensor reads, over the last three quarters of the stroke;
4. lift: the simulation of the probe ends (the next probe starts afresh).

Sensor noise (``noise_force`` newtons on every force sample, ``noise_depth`` metres on every
position sample) and the positioning error are drawn from the probe's own seed. The features
(:func:`features`): compliance is the depth per newton in units of ``compliance_scale``
(metres per newton); texture is the fluctuation of the tangential force while stroking
(its standard deviation around a straight line, per newton of normal force) in units of
``texture_scale``, plus ``friction_weight`` times the friction ratio (mean tangential over mean
normal force). The raw figures and the traces are kept with every probe (:class:`Probe`).

Not modelled: the fingertip's own deformation and its skin (it is a rigid sphere against a
compliant surface), Hertzian (non-linear) indentation, viscoelastic creep, vibration sensing
beyond the 1 kHz force samples, wear, temperature; volumes (a probe presses a surface).

MuJoCo is the ``physics`` extra: it is imported when a scene is built, never before.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

#: the optional dependency, its extra, and the option that asks for it
EXTRA = ("mujoco", "physics")

#: simulated time step (s)
TIMESTEP = 0.001
#: the stage's moving mass at the fingertip (kg): it sets the contact's time scale, not its
#: indentation
TIP_MASS = 0.2
#: the stage's x and y axes hold the fingertip through a compliant force sensor: its stiffness
#: (N/m) and damping (N s/m, critical for the moving mass)
STAGE_KP, STAGE_KV = 3000, 49
#: MuJoCo's constraint impedance for the surface contacts; with it, the soft contact's
#: reference stiffness that makes a press of F newtons indent F / K metres is K / (2 m)
IMPEDANCE = 0.5
#: the relief: samples 0.25 mm apart, bumps about 1 mm across, variants per material, and the
#: least friction a downhill slope leaves
RELIEF_SPACING = 0.00025
BUMP = 0.001
VARIANTS = 4
MIN_FRICTION = 0.02
#: first contact: a normal force above this share of the set force
ONSET = 0.02
#: the friction's own time constant and damping ratio (s, -): slip builds up over 20 ms,
#: critically damped, so that a stiff surface does not chatter at the time step
FRICTION_SOLREF = "0.02 1"
#: points spread over the unit disc: the contact patch's share of each cell
DISC = np.array([(u, v) for u in np.linspace(-0.8, 0.8, 5) for v in np.linspace(-0.8, 0.8, 5)
                 if u * u + v * v <= 0.8])
#: the approach: from this gap above the surface (m) at this speed (m/s); then the z axis's
#: own damping (N s/m)
APPROACH_GAP = 1e-4
APPROACH_SPEED = 0.002
Z_DAMPING = 5.0


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class MaterialPhysics(_Strict):
    """A material's contact properties, in SI units."""

    stiffness: float = Field(gt=0, le=1e7, description="contact stiffness against the "
                             "fingertip (N/m): a press of F newtons indents F / stiffness metres")
    damping: float = Field(ge=0, le=1e5, description="contact damping (N s/m)")
    friction: float = Field(gt=0, le=5, description="sliding friction coefficient against "
                            "the fingertip")
    roughness: float = Field(ge=0, le=0.005, description="standard deviation of the surface's "
                             "height (m)")
    variation: float = Field(0.1, ge=0, le=1, description="how much cells of the material "
                             "differ: the relative standard deviation of their stiffness and "
                             "friction (a log-normal factor per cell)")
    why: str = Field("", description="where the numbers come from")


class MaterialPhysicsPatch(_Strict):
    """A scenario's ``physics:`` entry for one material: any of the properties, the others
    taken from the bundled defaults (a material without defaults needs all four)."""

    stiffness: float | None = Field(None, gt=0, le=1e7)
    damping: float | None = Field(None, ge=0, le=1e5)
    friction: float | None = Field(None, gt=0, le=5)
    roughness: float | None = Field(None, ge=0, le=0.005)
    variation: float | None = Field(None, ge=0, le=1)
    why: str | None = None


def merged(defaults: Mapping[str, MaterialPhysics], patches: Mapping[str, MaterialPhysicsPatch]
           ) -> tuple[dict[str, MaterialPhysics], dict[str, list[str]]]:
    """The defaults with a scenario's entries laid over them, and per material the properties
    it lacks (a material that has no defaults and gives only some)."""
    out, lacking = dict(defaults), {}
    for name, patch in patches.items():
        given = patch.model_dump(exclude_none=True)
        if name in defaults:
            out[name] = defaults[name].model_copy(update=given)
            continue
        missing = [key for key in ("stiffness", "damping", "friction", "roughness")
                   if key not in given]
        if missing:
            lacking[name] = missing
        else:
            out[name] = MaterialPhysics(**given)
    return out, lacking


class ProbeSpec(_Strict):
    """How the fingertip probes, and how its signals become features (``sensor: {physics:}``)."""

    force: float = Field(1.0, gt=0, le=20, description="normal force of the press (N)")
    stroke: float = Field(0.004, gt=0, le=0.02, description="stroke length along x (m)")
    speed: float = Field(0.02, gt=0, le=0.5, description="stroke speed (m/s)")
    press: float = Field(0.25, ge=0.05, le=2.0, description="time the press settles (s)")
    radius: float = Field(0.006, ge=0.001, le=0.02, description="fingertip radius (m)")
    jitter: float = Field(0.001, ge=0, le=0.01, description="standard deviation of the hand's "
                          "positioning error around the cell's centre, per axis (m)")
    noise_force: float = Field(0.005, ge=0, le=1, description="standard deviation of the "
                               "force sensor's noise (N)")
    noise_depth: float = Field(2e-6, ge=0, le=1e-3, description="standard deviation of the "
                               "position sensor's noise (m)")
    compliance_scale: float = Field(0.004, gt=0, description="depth per newton (m/N) that "
                                    "reads as compliance 1")
    texture_scale: float = Field(0.2, gt=0, description="tangential-force fluctuation per "
                                 "newton of normal force that reads as texture 1")
    friction_weight: float = Field(0.2, ge=0, le=1, description="texture added per unit of "
                                   "friction ratio")
    seed: int = Field(0, ge=0, description="seed of the surfaces' relief")


def default_materials() -> dict[str, MaterialPhysics]:
    """The bundled defaults (``models/physics/materials.yaml``), each with its reasons (read
    once per process: every scenario's check and its properties use them)."""
    return dict(_bundled_materials())


@functools.cache
def _bundled_materials() -> dict[str, MaterialPhysics]:
    from bayesprog import bundled_root, load_document

    _, spec = load_document(bundled_root() / "physics" / "materials.yaml", MaterialsFile)
    return dict(spec.materials)


class MaterialsFile(_Strict):
    physics: int = Field(1, ge=1, le=1)
    description: str = ""
    materials: dict[str, MaterialPhysics]


def require(feature: str = "--physics") -> None:
    """MuJoCo, or the one-line error that names the extra (and ``feature``, what needs it)."""
    from bayesprog import require_extra

    require_extra(EXTRA[0], EXTRA[1], feature)


@dataclass
class Probe:
    """One press and stroke: the features, the raw figures, and the traces they come from."""

    texture: float
    compliance: float
    #: mean normal force while settled (N), depth from first contact (m), tangential force
    #: over normal force while stroking, the tangential force's fluctuation (N)
    force: float
    depth: float
    friction_ratio: float
    tangential_sd: float
    #: where the fingertip pressed (m), the positioning error included
    at: tuple[float, float]
    #: per time step: normal force (N), tangential force (N), the fingertip's height (m)
    traces: dict[str, np.ndarray] = field(repr=False, default_factory=dict)


def features(normal: np.ndarray, tangential: np.ndarray, height: np.ndarray, press_steps: int,
             spec: ProbeSpec) -> tuple[float, float, dict[str, float]]:
    """(texture, compliance, raw figures) of one probe's traces: ``normal``, ``tangential``
    forces and ``height`` per step, the first ``press_steps`` of them the press."""
    press_n, press_z = normal[:press_steps], height[:press_steps]
    settled = slice(max(press_steps - press_steps // 5, 1), press_steps)  # the last fifth
    force = float(press_n[settled].mean())
    depth = float(_contact_height(press_n, press_z, force) - press_z[settled].mean())
    stroke_n, stroke_t = normal[press_steps:], tangential[press_steps:]
    steady = slice(len(stroke_t) // 4, len(stroke_t))
    n, t = stroke_n[steady], stroke_t[steady]
    mean_n = max(float(n.mean()), 1e-9)
    ratio = float(t.mean()) / mean_n
    line = np.polyval(np.polyfit(np.arange(len(t)), t, 1), np.arange(len(t)))
    sd = float(np.std(t - line))
    compliance = depth / max(force, 1e-9) / spec.compliance_scale
    texture = sd / mean_n / spec.texture_scale + spec.friction_weight * ratio
    return texture, compliance, {"force": force, "depth": depth, "friction_ratio": ratio,
                                 "tangential_sd": sd}


def _contact_height(normal: np.ndarray, height: np.ndarray, force: float) -> float:
    """Where the surface was met: the height at which the normal force starts to rise, from a
    straight line through the force against the height while it rises to half the press's
    force (the first sample in contact when fewer than two lie there)."""
    rising = np.flatnonzero(normal > ONSET * force)
    if not rising.size:
        return float(height[-1])
    first = rising[0]
    end = first + int(np.argmax(normal[first:] >= 0.5 * force))
    if end - first < 2:
        return float(height[first])
    slope, intercept = np.polyfit(normal[first:end], height[first:end], 1)
    return float(intercept)


def _slopes(roughness: float, samples: int, spacing: float, rng: np.random.Generator
            ) -> np.ndarray:
    """The slope along x [samples, samples] of a smooth random relief whose heights have
    standard deviation ``roughness`` (m) and whose bumps are about ``BUMP`` across."""
    from scipy import ndimage

    noise = ndimage.gaussian_filter(rng.standard_normal((samples, samples)), BUMP / spacing / 2,
                                    mode="wrap")
    heights = roughness * (noise - noise.mean()) / noise.std()
    return np.gradient(heights, spacing, axis=0)


class Scene:
    """The MuJoCo model of a surface grid and its fingertip, built once; :meth:`probe` presses
    one cell. ``material_map`` [nx, ny] holds material indices into ``materials``."""

    def __init__(self, material_map: np.ndarray, cell: float, materials: Sequence[str],
                 properties: Mapping[str, MaterialPhysics], spec: ProbeSpec):
        from bayesprog import BayesprogError

        if np.ndim(material_map) != 2:
            raise BayesprogError("physics probes press a surface: a volume (a 3-D grid) is not "
                                 "modelled")
        self.material_map, self.cell = np.asarray(material_map), float(cell)
        self.materials, self.spec = tuple(materials), spec
        used = sorted({int(m) for m in np.unique(self.material_map)})
        missing = [self.materials[m] for m in used if self.materials[m] not in properties]
        if missing:
            raise BayesprogError(f"no physical properties for material(s) "
                                 f"{', '.join(missing)}: give them under physics: in the "
                                 "scenario")
        self.properties = {self.materials[m]: properties[self.materials[m]] for m in used}
        flat = self.material_map.ravel()

        def per_cell(key: str) -> np.ndarray:
            table = np.array([getattr(properties[name], key) if i in used else np.nan
                              for i, name in enumerate(self.materials)])
            return table[flat]

        # each cell of a material a little unlike the others (seeded by the scene)
        spread = per_cell("variation")
        z = np.random.default_rng([spec.seed, 0x7A7]).standard_normal((2, flat.size))
        factor = np.exp(spread * z - spread**2 / 2)
        self.cell_stiffness = per_cell("stiffness") * factor[0]
        self.cell_damping = per_cell("damping") * np.sqrt(factor[0])
        self.cell_friction = per_cell("friction") * factor[1]
        self.cell_contact = np.stack([self.cell_stiffness, self.cell_damping,
                                      self.cell_friction], axis=1)
        # the relief's slopes: a few variants per material, each cell one of them
        rng = np.random.default_rng([spec.seed, 0x5EED])
        self.samples = int(round(self.cell / RELIEF_SPACING))
        self.slopes = {name: np.stack([_slopes(p.roughness, self.samples, RELIEF_SPACING, rng)
                                       for _ in range(VARIANTS)])
                       for name, p in self.properties.items()}
        self.variant = np.random.default_rng([spec.seed, 0xCE11]).integers(
            VARIANTS, size=self.material_map.size)

    @cached_property
    def model(self) -> Any:
        import mujoco

        return mujoco.MjModel.from_xml_string(self.xml())

    @cached_property
    def data(self) -> Any:
        import mujoco

        return mujoco.MjData(self.model)

    def xml(self, tiles: bool = False) -> str:
        """The scene as MuJoCo's XML; with ``tiles``, each cell drawn in its material's colour
        (for a viewer: they take no part in the contact, and slow every step)."""
        nx, ny = self.material_map.shape
        half = self.cell / 2
        colours = {name: f"{0.3 + 0.6 * i / max(len(self.properties) - 1, 1):.3f} 0.5 0.4 1"
                   for i, name in enumerate(self.properties)}
        # the regions as the eye sees them; the fingertip touches one surface whose contact
        # follows the cells under it (:meth:`contact`)
        drawn = "".join(
            f'<geom type="box" size="{half} {half} 0.001" contype="0" conaffinity="0" '
            f'rgba="{colours[self.materials[int(self.material_map[ix, iy])]]}" '
            f'pos="{(ix + 0.5) * self.cell:.6g} {(iy + 0.5) * self.cell:.6g} -0.001"/>'
            for ix in range(nx) for iy in range(ny)) if tiles else ""
        r = self.spec.radius
        return f"""<mujoco model="bayesprog_surface">
  <option timestep="{TIMESTEP}" gravity="0 0 0" cone="elliptic"/>
  <worldbody>
    <geom name="surface" type="box" size="{nx * half:.6g} {ny * half:.6g} 0.01"
          pos="{nx * half:.6g} {ny * half:.6g} -0.01" contype="0" conaffinity="0"
          rgba="0.6 0.6 0.6 1"/>
    {drawn}
    <body name="fingertip" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <joint name="z" type="slide" axis="0 0 1" damping="{Z_DAMPING}"/>
      <geom name="fingertip" type="sphere" size="{r}" mass="{TIP_MASS}" rgba="0.9 0.8 0.2 1"/>
      <site name="fingertip" size="{r * 1.05:.6g}"/>
    </body>
  </worldbody>
  <contact>
    <pair name="touch" geom1="surface" geom2="fingertip" condim="3"
          solimp="{IMPEDANCE} {IMPEDANCE} 0.001" solreffriction="{FRICTION_SOLREF}"/>
  </contact>
  <actuator>
    <position name="x" joint="x" kp="{STAGE_KP}" kv="{STAGE_KV}"/>
    <position name="y" joint="y" kp="{STAGE_KP}" kv="{STAGE_KV}"/>
    <motor name="z" joint="z"/>
  </actuator>
  <sensor>
    <touch name="normal" site="fingertip"/>
    <actuatorfrc name="tangential" actuator="x"/>
    <framepos name="position" objtype="body" objname="fingertip"/>
  </sensor>
</mujoco>"""

    def contact(self, x: float, y: float, depth: float) -> tuple[float, float, float]:
        """(stiffness, damping, friction) of the surface under a fingertip at (x, y) pressed
        ``depth`` metres in: each cell's in proportion to its share of the contact disc
        (radius sqrt(R depth), at least a tenth of the fingertip's), the friction raised by the
        relief's slope along x under the centre (a sphere sliding up a bump of slope s feels
        about F_n (mu + s) along its path)."""
        nx, ny = self.material_map.shape
        radius = max(np.sqrt(self.spec.radius * max(depth, 0.0)), self.spec.radius / 10)
        px = np.minimum(np.maximum((x + radius * DISC[:, 0]) // self.cell, 0), nx - 1)
        py = np.minimum(np.maximum((y + radius * DISC[:, 1]) // self.cell, 0), ny - 1)
        k, b, mu = self.cell_contact[(px * ny + py).astype(np.intp)].mean(axis=0)
        centre = self._cell_at(x, y)
        return float(k), float(b), max(float(mu) + self._slope(centre, x, y), MIN_FRICTION)

    def _cell_at(self, x: float, y: float) -> int:
        nx, ny = self.material_map.shape
        ix = min(max(int(x // self.cell), 0), nx - 1)
        iy = min(max(int(y // self.cell), 0), ny - 1)
        return ix * ny + iy

    def _slope(self, cell: int, x: float, y: float) -> float:
        """The relief's slope along x under the fingertip's centre, on cell ``cell``."""
        name = self.materials[int(self.material_map.ravel()[cell])]
        ix, iy = np.unravel_index(cell, self.material_map.shape)
        u = int((x - ix * self.cell) / RELIEF_SPACING) % self.samples
        v = int((y - iy * self.cell) / RELIEF_SPACING) % self.samples
        return float(self.slopes[name][self.variant[cell], u, v])

    def probe(self, flat: int, rng: np.random.Generator) -> Probe:
        """Press, stroke and lift at cell ``flat``; ``rng`` draws the positioning error and the
        sensor noise."""
        import mujoco

        model, data, spec = self.model, self.data, self.spec
        ix, iy = np.unravel_index(int(flat), self.material_map.shape)
        error = rng.standard_normal(2) * spec.jitter
        x0 = (ix + 0.5) * self.cell + error[0] - spec.stroke / 2
        y0 = (iy + 0.5) * self.cell + error[1]
        mujoco.mj_resetData(model, data)
        data.qpos[:] = (x0, y0, spec.radius + APPROACH_GAP)
        # the approach at a slow, steady speed (the z axis damped); once in contact, the press
        model.dof_damping[2] = spec.force / APPROACH_SPEED
        data.ctrl[:] = (x0, y0, -spec.force)
        press_steps = int(round(spec.press / TIMESTEP))
        stroke_steps = max(int(round(spec.stroke / spec.speed / TIMESTEP)), 8)
        steps = press_steps + stroke_steps
        sensed = np.empty((steps, 3))
        xs = x0 + np.concatenate([np.zeros(press_steps),
                                  np.linspace(0, spec.stroke, stroke_steps)])
        qpos, ctrl, sensordata = data.qpos, data.ctrl, data.sensordata
        at = (np.inf, np.inf, np.inf)  # where the contact was last set
        touching = False
        for k in range(steps):
            x, y, z = qpos
            if not touching and sensordata[0] > 0:
                model.dof_damping[2], touching = Z_DAMPING, True
            depth = spec.radius - z
            if abs(x - at[0]) > RELIEF_SPACING / 2 or abs(depth - at[2]) > 0.05 * abs(at[2]) \
                    + 1e-5:
                stiffness, damping, friction = self.contact(x, y, depth)
                # MuJoCo's soft contact: with impedance d, a reference stiffness of K / (2 m)
                # settles a press of F newtons at F / K metres (elliptic cones)
                model.pair_solref[0] = (-stiffness / (2 * TIP_MASS), -damping / (2 * TIP_MASS))
                model.pair_friction[0, :2] = friction
                at = (x, y, depth)
            ctrl[0] = xs[k]
            mujoco.mj_step(model, data)
            sensed[k] = sensordata[0], sensordata[1], sensordata[4]
        noise = rng.standard_normal((steps, 3)) * (spec.noise_force, spec.noise_force,
                                                   spec.noise_depth)
        normal, tangential, height = (sensed + noise).T
        texture, compliance, raw = features(normal, tangential, height, press_steps, spec)
        return Probe(texture=texture, compliance=compliance, at=(x0 + spec.stroke / 2, y0),
                     traces={"normal": normal, "tangential": tangential, "height": height},
                     **raw)


def press_cells(material_map: np.ndarray, presses: int, seed: int
                ) -> list[tuple[int, np.ndarray]]:
    """Per material of a map (by index): its index and the ``presses`` cells (flat) its
    presses land on, drawn among its cells from (``seed``, the material's index)."""
    flat = np.asarray(material_map).ravel()
    out = []
    for m in sorted({int(v) for v in np.unique(flat)}):
        cells = np.flatnonzero(flat == m)
        rng = np.random.default_rng([seed, m])
        out.append((m, cells[rng.integers(len(cells), size=presses)]))
    return out


def probe_seed(seed: Sequence[int] | int, step: int) -> list[int]:
    """The seed of a probe: its run's reading seed and its step."""
    base = [int(seed)] if isinstance(seed, (int, np.integer)) else [int(s) for s in seed]
    return [*base, int(step)]


class PhysicsSensor:
    """A haptic sensor whose readings come from :class:`Scene` probes: run r's probe at step k
    is seeded by (its reading seed, k), so a run's readings depend on nothing else."""

    def __init__(self, scene: Scene, seeds: Sequence[int | tuple[int, ...]]):
        self.scene = scene
        self.seeds = list(seeds)
        self.steps = [0] * len(self.seeds)
        self.last: list[Probe] = []

    def probe(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.last = []
        for r, cell in enumerate(np.asarray(cells).ravel()):
            rng = np.random.default_rng(probe_seed(self.seeds[r], self.steps[r]))
            self.last.append(self.scene.probe(int(cell), rng))
            self.steps[r] += 1
        return (np.array([p.texture for p in self.last]),
                np.array([p.compliance for p in self.last]))
