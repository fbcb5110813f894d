"""Probes as physics (MuJoCo): a fingertip on a Cartesian stage presses each cell of a surface
to a set normal force, strokes it a few millimetres and lifts; the forces, the depth, an array
of electrodes and a thermal sensor it carries become the named features a scenario maps to its
readings (by default the paper's texture and compliance).

The scene is built from a scenario: the workspace's surface, each cell of its material; the
fingertip, a sphere on a Cartesian stage of three slide joints, x and y holding it through a
compliant force sensor, z force-controlled (the stage carries its weight, so gravity is left
out). Each material has a contact stiffness and damping (MuJoCo's soft contact, set so that a
press of F newtons indents F / stiffness metres once settled), a friction coefficient, a
roughness and, for the thermal feature, a thermal effusivity. The contact under the fingertip
takes each cell's properties in proportion to its share of the contact disc, so a press on a
border feels both materials. The roughness is modelled by its equivalent along a stroke: a
smooth random relief per material (a few variants, each cell one of them) whose heights have
the material's roughness as standard deviation, bumps about a millimetre across; where the
fingertip slides up a slope s of it, the friction coefficient under it is raised by s (a sphere
sliding up a bump of slope s feels about F_n (mu + s) along its path), and lowered going down.

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
position sample, ``noise_electrode`` metres on every electrode sample, ``noise_temperature``
kelvin on every temperature sample) and the positioning error are drawn from the probe's own
seed, in that order (so a feature added later never changes the draws of those before it).

The features (:data:`FEATURES`, :func:`press_features`), one value each per probe in a fixed
unit, read while settled (the last fifth of the press) or while stroking (the last three
quarters of the stroke):

- ``texture`` (-): the tangential force's fluctuation while stroking (its standard deviation
  around a straight line, per newton of normal force) in units of ``texture_scale``, plus
  ``friction_weight`` times the friction ratio (the paper's E);
- ``compliance`` (-): the depth per newton in units of ``compliance_scale`` (metres per
  newton; the paper's C);
- ``force`` (N), ``depth`` (m): the mean normal force while settled and the depth from first
  contact; ``friction_ratio`` (-): mean tangential over mean normal force while stroking;
  ``tangential_sd`` (N): the tangential force's fluctuation while stroking;
- ``pressure`` (Pa): the static pressure, the settled normal force over the contact area of a
  sphere of radius R indenting a half-space by the depth d (Hertz: a = sqrt(R d), the area
  pi a^2, a kept within [R / 100, R]);
- ``vibration_power`` (N^2): the power of the tangential force's fluctuation in
  ``vibration_band`` while stroking (20-400 Hz by default: the tens to hundreds of hertz the
  skin's fast-adapting receptors feel, within the 500 Hz the 1 kHz samples hold): Welch's
  spectral density (segments of 64, a line taken out of each) summed over the band;
- ``electrode_spread`` (-): the coefficient of variation (standard deviation over mean)
  across ``electrodes`` electrodes of their compression while settled; the electrodes lie on
  the fingertip's lower cap (one at its pole, the others on a golden-angle spiral of equal
  areas out to ``electrode_angle`` degrees from it), each a MuJoCo distance sensor from a
  point of the fingertip's surface to the plane of the surface (its compression: how far it
  lies below). A rigid surface is met by the pole alone (spread sqrt(n - 1)); a soft one
  wraps the cap, loading the electrodes more evenly (a smaller spread). MuJoCo's touch
  sensors cannot serve as electrodes here: a sphere on a box makes one contact point, so a
  touch site reads the whole force or nothing;
- ``temperature_drop`` (K): how much a thermal sensor in the fingertip, at
  ``fingertip_temperature`` before the press, has cooled when the fingertip lifts, on a
  surface at ``surface_temperature``. Two semi-infinite bodies put in contact settle at once
  at the contact temperature T_c = (e_f T_f + e_s T_s) / (e_f + e_s), e = sqrt(k rho c) each
  body's thermal effusivity (:func:`contact_temperature`; ``fingertip_effusivity`` about
  human skin's); the sensor follows T_c as a first-order lag of time constant
  ``thermal_time_constant`` over the time in contact t (MuJoCo's normal force above zero),
  so the drop is (T_f - T_c)(1 - exp(-t / tau)). The surface's effusivity is its cells'
  shares of the contact disc under the press, as for the mechanics; a material without an
  effusivity gives no temperature drop (NaN: missing), and a scenario that reads one from it
  is refused (:func:`feature_problems`). Left out: the thermal contact resistance of the
  interface (roughness, pressure), the bodies' finite thickness (a thin sheet or a coating
  over another material), heat carried by the stroke onto fresh surface, heating of the
  surface by earlier presses and the fingertip's recovery between them, convection and
  radiation, and the sensor's depth below the skin (beyond its time constant).

A scenario maps its readings to features (``readings:`` of ``sensor: physics:``: reading
name -> feature, by default texture -> texture and compliance -> compliance);
:class:`PhysicsSensor` returns them as :class:`runner.world.readings.Readings`. The raw
figures, every feature and the traces are kept with every probe (:class:`Probe`).

Not modelled: the fingertip's own deformation and its skin (it is a rigid sphere against a
compliant surface), Hertzian (non-linear) indentation (the pressure uses Hertz's contact
radius, the force is linear in the depth), viscoelastic creep, vibration above the 1 kHz force
samples, the relief as geometry (the electrodes feel a flat surface), wear; volumes (a probe
presses a surface).

MuJoCo is the ``physics`` extra: it is imported when a scene is built, never before.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

if TYPE_CHECKING:
    from runner.world.readings import Readings

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
#: the most presses stepped in one batch (their readings per step are in memory together)
BATCH = 128
#: the most threads a batch of presses is stepped on (in a process of its own: one in an
#: experiment's worker process, whose cores the other workers take)
PRESS_THREADS = 2
APPROACH_SPEED = 0.002
Z_DAMPING = 5.0
#: an electrode: a sphere this small (m) centred on the fingertip's surface, massless and
#: touching nothing, whose distance to the plane of the surface MuJoCo reports when they
#: overlap (a cutoff of 0: one clear of it reads 0, and costs less)
ELECTRODE_RADIUS = 1e-4
#: Welch's segments for the vibration power (samples), at most
VIBRATION_SEGMENT = 64

#: every feature of a press: its unit ("1" for a pure number) and what it is, as
#: ``"UNIT: meaning"`` (``record --physics`` writes each as a column)
FEATURES: dict[str, str] = {
    "texture": "1: tangential-force fluctuation per newton of normal force in units of "
               "texture_scale, plus friction_weight times the friction ratio (the paper's E)",
    "compliance": "1: depth per newton in units of compliance_scale (the paper's C)",
    "force": "N: mean normal force while settled",
    "depth": "m: depth from first contact while settled",
    "friction_ratio": "1: mean tangential over mean normal force while stroking",
    "tangential_sd": "N: standard deviation of the tangential force around a straight line "
                     "while stroking",
    "pressure": "Pa: static pressure, the settled normal force over the Hertz contact area "
                "pi R depth",
    "vibration_power": "N^2: power of the tangential force's fluctuation in vibration_band "
                       "while stroking (Welch)",
    "electrode_spread": "1: coefficient of variation of the electrodes' compressions while "
                        "settled",
    "temperature_drop": "K: how much the fingertip's thermal sensor cooled over the contact "
                        "(two semi-infinite bodies, first-order sensor)",
}

#: the material properties a feature needs beyond the contact's four (stiffness, damping,
#: friction, roughness, which every material has): a laid material without them cannot give
#: the feature
NEEDS: dict[str, tuple[str, ...]] = {"temperature_drop": ("effusivity",)}

#: what such a property is, for the message that asks for it
_PROPERTY_MEANING = {"effusivity": "thermal effusivity sqrt(k rho c), W s^0.5 m^-2 K^-1"}

#: the readings of a physics sensor unless a scenario names them: reading -> feature
PAPER_READINGS = {"texture": "texture", "compliance": "compliance"}


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
    effusivity: float | None = Field(None, gt=0, le=1e5, description="thermal effusivity "
                                     "sqrt(k rho c) (W s^0.5 m^-2 K^-1), for the temperature "
                                     "drop; none: the material gives no temperature drop")
    why: str = Field("", description="where the numbers come from")


class MaterialPhysicsPatch(_Strict):
    """A scenario's ``physics:`` entry for one material: any of the properties, the others
    taken from the bundled defaults (a material without defaults needs the contact's four;
    without an effusivity it gives no temperature drop)."""

    stiffness: float | None = Field(None, gt=0, le=1e7)
    damping: float | None = Field(None, ge=0, le=1e5)
    friction: float | None = Field(None, gt=0, le=5)
    roughness: float | None = Field(None, ge=0, le=0.005)
    variation: float | None = Field(None, ge=0, le=1)
    effusivity: float | None = Field(None, gt=0, le=1e5)
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
    readings: dict[str, str] = Field(default_factory=lambda: dict(PAPER_READINGS),
                                     min_length=1, description="the readings the sensor "
                                     "reports, each a feature of the press: reading name -> "
                                     "feature (see FEATURES)")
    vibration_band: tuple[float, float] = Field((20.0, 400.0), description="the band of the "
                                                "vibration power (Hz), within the 500 Hz of "
                                                "the 1 kHz samples")
    electrodes: int = Field(19, ge=2, le=64, description="electrodes on the fingertip's lower "
                            "cap (a BioTac has 19)")
    electrode_angle: float = Field(50.0, gt=0, le=90, description="how far from the "
                                   "fingertip's pole the electrodes reach (degrees)")
    noise_electrode: float = Field(1e-6, ge=0, le=1e-3, description="standard deviation of "
                                   "an electrode's noise (m of compression)")
    fingertip_temperature: float = Field(33.0, ge=-50, le=150, description="the fingertip's "
                                         "temperature before a press (degrees C; skin is "
                                         "about 33)")
    surface_temperature: float = Field(22.0, ge=-50, le=150, description="the surface's "
                                       "temperature (degrees C; a room's)")
    fingertip_effusivity: float = Field(1100.0, gt=0, le=1e5, description="the fingertip's "
                                        "thermal effusivity (W s^0.5 m^-2 K^-1; human skin "
                                        "is about 1,100)")
    thermal_time_constant: float = Field(1.0, gt=0, le=100, description="the thermal "
                                         "sensor's first-order time constant (s)")
    noise_temperature: float = Field(0.01, ge=0, le=10, description="standard deviation of "
                                     "the thermal sensor's noise (K)")

    @field_validator("vibration_band")
    @classmethod
    def _band_within_the_samples(cls, band: tuple[float, float]) -> tuple[float, float]:
        low, high = band
        nyquist = 0.5 / TIMESTEP
        if not 0 <= low < high <= nyquist:
            raise ValueError(f"expected 0 <= low < high <= {nyquist:g} Hz (half the "
                             f"{1 / TIMESTEP:g} Hz samples), found [{low:g}, {high:g}]")
        return band


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
    #: per time step: normal force (N), tangential force (N), the fingertip's height (m), each
    #: electrode's compression (m) [steps, electrodes], the thermal sensor (degrees C)
    traces: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    #: every feature (:data:`FEATURES`, in its units), texture and compliance among them
    features: dict[str, float] = field(default_factory=dict)


def features(normal: np.ndarray, tangential: np.ndarray, height: np.ndarray, press_steps: int,
             spec: ProbeSpec) -> tuple[float, float, dict[str, float]]:
    """(texture, compliance, raw figures) of one probe's traces: ``normal``, ``tangential``
    forces and ``height`` per step, the first ``press_steps`` of them the press."""
    press_n, press_z = normal[:press_steps], height[:press_steps]
    settled = _settled(press_steps)
    force = float(press_n[settled].mean())
    depth = float(_contact_height(press_n, press_z, force) - press_z[settled].mean())
    stroke_n, stroke_t = normal[press_steps:], tangential[press_steps:]
    steady = _steady(len(stroke_t))
    n, t = stroke_n[steady], stroke_t[steady]
    mean_n = max(float(n.mean()), 1e-9)
    ratio = float(t.mean()) / mean_n
    line = np.polyval(np.polyfit(np.arange(len(t)), t, 1), np.arange(len(t)))
    sd = float(np.std(t - line))
    compliance = depth / max(force, 1e-9) / spec.compliance_scale
    texture = sd / mean_n / spec.texture_scale + spec.friction_weight * ratio
    return texture, compliance, {"force": force, "depth": depth, "friction_ratio": ratio,
                                 "tangential_sd": sd}


def press_features(traces: Mapping[str, np.ndarray], press_steps: int, spec: ProbeSpec
                   ) -> dict[str, float]:
    """Every feature of one probe (:data:`FEATURES`, in that order) from its traces
    (``normal``, ``tangential``, ``height`` per step, ``electrodes`` [steps, electrodes],
    ``temperature``), the first ``press_steps`` of them the press."""
    texture, compliance, raw = features(traces["normal"], traces["tangential"],
                                        traces["height"], press_steps, spec)
    stroking = traces["tangential"][press_steps:]
    out = {"texture": texture, "compliance": compliance, **raw,
           "pressure": static_pressure(raw["force"], raw["depth"], spec.radius),
           "vibration_power": vibration_power(stroking[_steady(len(stroking))],
                                              spec.vibration_band),
           "electrode_spread": electrode_spread(
               traces["electrodes"][_settled(press_steps)].mean(axis=0)),
           "temperature_drop": spec.fingertip_temperature - float(traces["temperature"][-1])}
    assert list(out) == list(FEATURES)
    return out


def _settled(press_steps: int) -> slice:
    """The press once settled: its last fifth."""
    return slice(max(press_steps - press_steps // 5, 1), press_steps)


def _steady(stroke_steps: int) -> slice:
    """The stroke once sliding: its last three quarters."""
    return slice(stroke_steps // 4, stroke_steps)


def static_pressure(force: float, depth: float, radius: float) -> float:
    """The mean pressure (Pa) of ``force`` newtons over the contact of a sphere of ``radius``
    metres indenting a half-space by ``depth``: F / (pi a^2), a = sqrt(R d) (Hertz), a kept
    within [R / 100, R] (a depth of zero or less, or deeper than the sphere's radius).

    >>> round(static_pressure(1.0, 1e-3, 0.006))  # a = 2.45 mm
    53052
    """
    a = min(max(np.sqrt(radius * max(depth, 0.0)), radius / 100), radius)
    return float(force / (np.pi * a * a))


def vibration_power(tangential: np.ndarray, band: tuple[float, float]) -> float:
    """The power (N^2) of the fluctuation of ``tangential`` (N, one sample per time step) in
    ``band`` (Hz): Welch's spectral density summed over the band's frequencies times their
    spacing (NaN for fewer than four samples).

    The estimate of ``scipy.signal.welch(x, 1 / TIMESTEP, nperseg=min(64, len(x)),
    detrend="linear")``, written out in numpy (that call took 1.7 ms a probe, more than every
    other feature together; the tests hold the two equal): segments of
    :data:`VIBRATION_SEGMENT` samples overlapping by half, a straight line taken out of each
    and a Hann window applied; their periodograms, scaled to a one-sided density, averaged.

    >>> t = np.arange(1000) * TIMESTEP  # a sine of amplitude 0.1 N: power 0.1^2 / 2
    >>> round(vibration_power(0.6 + 0.1 * np.sin(2 * np.pi * 100 * t), (20, 400)), 4)
    0.005
    """
    x = np.asarray(tangential, float)
    if x.size < 4:
        return float("nan")
    index, ramp, slope_scale, window, scale, inside, spacing = _welch_plan(
        x.size, (float(band[0]), float(band[1])))
    segments = x[index]
    segments = (segments - segments.mean(axis=1, keepdims=True)
                - np.outer(segments @ ramp / slope_scale, ramp))
    density = np.abs(np.fft.rfft(segments * window, axis=1)) ** 2 / scale
    size = window.size
    density[:, 1:(size + 1) // 2] *= 2  # one-sided: each frequency but 0 and fs / 2 twice
    density = density.mean(axis=0)
    return float(density[inside].sum() * spacing)


@functools.lru_cache(maxsize=16)
def _welch_plan(samples: int, band: tuple[float, float]) -> tuple:
    """What :func:`vibration_power` computes of ``samples`` samples before reading them (the
    segments' indices, the ramp a line is fitted on, the periodic Hann window, the density's
    scale, the band's frequencies and their spacing), once per length and band."""
    size = min(VIBRATION_SEGMENT, samples)
    step = size - size // 2
    starts = np.arange(0, samples - size + 1, step)
    index = starts[:, None] + np.arange(size)
    ramp = np.arange(size) - (size - 1) / 2
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(size) / size)  # periodic Hann
    fs = 1 / TIMESTEP
    frequency = np.fft.rfftfreq(size, TIMESTEP)
    inside = (frequency >= band[0]) & (frequency <= band[1])
    for kept in (index, ramp, window, inside):  # shared by every call: read only
        kept.flags.writeable = False
    return (index, ramp, ramp @ ramp, window, fs * (window @ window), inside,
            frequency[1] - frequency[0])


def electrode_spread(compressions: np.ndarray) -> float:
    """The coefficient of variation of the electrodes' ``compressions`` (m): their standard
    deviation over their mean (NaN when none is compressed).

    >>> round(electrode_spread(np.array([1e-5, 0, 0, 0, 0])), 6)  # the pole alone: sqrt(n - 1)
    2.0
    """
    mean = float(np.mean(compressions))
    return float(np.std(compressions) / mean) if mean > 0 else float("nan")


def electrode_positions(count: int, radius: float, angle: float) -> np.ndarray:
    """Where ``count`` electrodes lie on a fingertip of ``radius`` (metres, in its own frame,
    its pole at (0, 0, -radius)): one at the pole, the others on a golden-angle spiral out to
    ``angle`` degrees from it, each ring of the same area (steps of equal cos theta)."""
    i = np.arange(count)
    cos_theta = 1 - (1 - np.cos(np.radians(angle))) * i / (count - 1)
    sin_theta = np.sqrt(np.maximum(1 - cos_theta**2, 0))
    phi = i * np.pi * (3 - np.sqrt(5))
    return radius * np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), -cos_theta],
                             axis=1)


def contact_temperature(e_fingertip: float, t_fingertip: float, e_surface: float,
                        t_surface: float) -> float:
    """The temperature at which two semi-infinite bodies put in contact meet at once (degrees
    C): T_c = (e_f T_f + e_s T_s) / (e_f + e_s), each body's effusivity e = sqrt(k rho c)
    weighing its temperature: the heat equation's solution for two half-spaces, the model of
    the skin's contact temperature in studies of thermal touch (e.g. Ho and Jones, 2008).

    >>> round(contact_temperature(1100, 33, 37000, 22), 2)  # skin on copper
    22.32
    """
    return (e_fingertip * t_fingertip + e_surface * t_surface) / (e_fingertip + e_surface)


def thermal_trace(in_contact: np.ndarray, e_surface: float, spec: ProbeSpec) -> np.ndarray:
    """The thermal sensor's temperature (degrees C) per time step: ``fingertip_temperature``
    until the contact, then a first-order lag of ``thermal_time_constant`` towards the contact
    temperature, over the time in contact so far (``in_contact`` per step); NaN throughout for
    a surface of no effusivity (NaN)."""
    t_c = contact_temperature(spec.fingertip_effusivity, spec.fingertip_temperature,
                              e_surface, spec.surface_temperature)
    elapsed = np.cumsum(in_contact) * TIMESTEP
    lag = np.exp(-elapsed / spec.thermal_time_constant)
    return t_c + (spec.fingertip_temperature - t_c) * lag


def feature_problems(spec: ProbeSpec, properties: Mapping[str, MaterialPhysics],
                     laid: Iterable[str]) -> list[tuple[tuple, str]]:
    """What keeps ``spec``'s readings from being read on a surface of the materials ``laid``
    (of ``properties``; a laid material without properties is another check's): per problem,
    its path inside ``sensor: physics:`` and the message. A reading of an unknown feature, or
    of a feature that some laid material lacks a property for (:data:`NEEDS`).

    >>> basalt = MaterialPhysics(stiffness=1e5, damping=280, friction=0.6, roughness=1e-5)
    >>> spec = ProbeSpec(readings={"heat": "temperature_drop", "grip": "fricton_ratio"})
    >>> for where, message in feature_problems(spec, {"basalt": basalt}, ["basalt"]):
    ...     print(where, message)
    ('readings', 'heat') reading 'heat': temperature_drop needs each laid material's effusivity (thermal effusivity sqrt(k rho c), W s^0.5 m^-2 K^-1), and basalt has none: give it under physics: (basalt: {effusivity: ...}) or read another feature
    ('readings', 'grip') reading 'grip': unknown feature 'fricton_ratio': did you mean 'friction_ratio'? (expected one of texture, compliance, force, depth, friction_ratio, tangential_sd, pressure, vibration_power, electrode_spread, temperature_drop)
    """
    from bayesprog import did_you_mean

    laid = sorted(set(laid))
    problems: list[tuple[tuple, str]] = []
    for reading, feature in spec.readings.items():
        where = ("readings", reading)
        if feature not in FEATURES:
            problems.append((where, f"reading {reading!r}: unknown feature {feature!r}"
                             + did_you_mean(feature, FEATURES)
                             + f" (expected one of {', '.join(FEATURES)})"))
            continue
        for needed in NEEDS.get(feature, ()):
            lacking = [m for m in laid if m in properties
                       and getattr(properties[m], needed) is None]
            if lacking:
                problems.append((where, f"reading {reading!r}: {feature} needs each laid "
                                 f"material's {needed} ({_PROPERTY_MEANING[needed]}), and "
                                 f"{', '.join(lacking)} {'has' if len(lacking) == 1 else 'have'}"
                                 f" none: give it under physics: ({lacking[0]}: {{{needed}: "
                                 "...}) or read another feature"))
    return problems


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
        # NaN where the material has no effusivity: it gives no temperature drop
        self.cell_effusivity = np.array([
            np.nan if i not in used or properties[name].effusivity is None
            else properties[name].effusivity for i, name in enumerate(self.materials)])[flat]
        self.electrodes = electrode_positions(spec.electrodes, spec.radius,
                                              spec.electrode_angle)
        # the relief's slopes: a few variants per material, each cell one of them
        rng = np.random.default_rng([spec.seed, 0x5EED])
        self.samples = int(round(self.cell / RELIEF_SPACING))
        self.slopes = {name: np.stack([_slopes(p.roughness, self.samples, RELIEF_SPACING, rng)
                                       for _ in range(VARIANTS)])
                       for name, p in self.properties.items()}
        self.variant = np.random.default_rng([spec.seed, 0xCE11]).integers(
            VARIANTS, size=self.material_map.size)
        self._lock = threading.Lock()  # one batch of presses at a time on the scene's workers

    def __getstate__(self) -> dict[str, Any]:
        """The scene without what MuJoCo built for it (built again where it is unpickled) and
        without its lock."""
        state = self.__dict__.copy()
        for built in ("model", "data", "_press_workers", "_lock"):
            state.pop(built, None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

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
        # the electrodes: massless, touching nothing, each read as its distance to the plane
        # of the surface (after the scene's own sensors, so that theirs keep their places)
        electrodes = "".join(
            f'<geom name="electrode{i}" type="sphere" size="{ELECTRODE_RADIUS}" mass="0" '
            f'contype="0" conaffinity="0" group="4" pos="{x:.12g} {y:.12g} {z:.12g}"/>'
            for i, (x, y, z) in enumerate(self.electrodes))
        distances = "".join(
            f'<distance name="electrode{i}" geom1="electrode{i}" geom2="surface_plane" '
            'cutoff="0"/>' for i in range(len(self.electrodes)))
        return f"""<mujoco model="bayesprog_surface">
  <option timestep="{TIMESTEP}" gravity="0 0 0" cone="elliptic"/>
  <worldbody>
    <geom name="surface" type="box" size="{nx * half:.6g} {ny * half:.6g} 0.01"
          pos="{nx * half:.6g} {ny * half:.6g} -0.01" contype="0" conaffinity="0"
          rgba="0.6 0.6 0.6 1"/>
    <geom name="surface_plane" type="plane" size="0 0 1" contype="0" conaffinity="0"
          group="4" rgba="0 0 0 0"/>
    {drawn}
    <body name="fingertip" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <joint name="z" type="slide" axis="0 0 1" damping="{Z_DAMPING}"/>
      <geom name="fingertip" type="sphere" size="{r}" mass="{TIP_MASS}" rgba="0.9 0.8 0.2 1"/>
      <site name="fingertip" size="{r * 1.05:.6g}"/>
      {electrodes}
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
    {distances}
  </sensor>
</mujoco>"""

    def contact(self, x: float, y: float, depth: float) -> tuple[float, float, float]:
        """(stiffness, damping, friction) of the surface under a fingertip at (x, y) pressed
        ``depth`` metres in: each cell's in proportion to its share of the contact disc
        (radius sqrt(R depth), at least a tenth of the fingertip's), the friction raised by the
        relief's slope along x under the centre (a sphere sliding up a bump of slope s feels
        about F_n (mu + s) along its path)."""
        k, b, mu = self.cell_contact[self._under(x, y, depth)].mean(axis=0)
        centre = self._cell_at(x, y)
        return float(k), float(b), max(float(mu) + self._slope(centre, x, y), MIN_FRICTION)

    def effusivity_at(self, x: float, y: float, depth: float) -> float:
        """The thermal effusivity under a fingertip at (x, y) pressed ``depth`` metres in: each
        cell's in proportion to its share of the contact disc, as :meth:`contact`'s (NaN when
        a material under it has none)."""
        return float(self.cell_effusivity[self._under(x, y, depth)].mean())

    def _under(self, x: float, y: float, depth: float) -> np.ndarray:
        """The cells (flat) under the points of :data:`DISC` over the contact disc of a
        fingertip at (x, y) pressed ``depth`` metres in (radius sqrt(R depth), at least a
        tenth of the fingertip's)."""
        nx, ny = self.material_map.shape
        radius = max(np.sqrt(self.spec.radius * max(depth, 0.0)), self.spec.radius / 10)
        px = np.minimum(np.maximum((x + radius * DISC[:, 0]) // self.cell, 0), nx - 1)
        py = np.minimum(np.maximum((y + radius * DISC[:, 1]) // self.cell, 0), ny - 1)
        return (px * ny + py).astype(np.intp)

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
        sensor noise (forces and height, then the electrodes, then the thermal sensor)."""
        return self.probes(np.array([flat]), [rng])[0]

    def probes(self, cells: np.ndarray, rngs: Sequence[np.random.Generator],
               threads: int | None = None) -> list[Probe]:
        """One press, stroke and lift per cell of ``cells`` (flat), press i's positioning error
        and noise drawn from ``rngs[i]``: the presses of the batch are stepped in compiled code
        (MuJoCo's ``mj_step`` called from a loop with no Python between the steps), over
        ``threads`` threads (:func:`press_threads` unless given), each thread with its copy
        of the model and its data. Each press starts from MuJoCo's reset state and sets its
        contact at every step it is due, as :meth:`probe_stepwise` does, so that a press is
        the same whatever others share its batch or thread."""
        cells = np.asarray(cells, dtype=np.intp).ravel()
        n, spec = len(cells), self.spec
        if n > BATCH:  # a bounded batch at a time: its readings in memory
            return [probe for lo in range(0, n, BATCH)
                    for probe in self.probes(cells[lo:lo + BATCH], rngs[lo:lo + BATCH], threads)]
        if n == 0:
            return []
        ix, iy = np.unravel_index(cells, self.material_map.shape)
        error = np.stack([rng.standard_normal(2) for rng in rngs]) * spec.jitter
        x0 = (ix + 0.5) * self.cell + error[:, 0] - spec.stroke / 2
        y0 = (iy + 0.5) * self.cell + error[:, 1]
        press_steps = int(round(spec.press / TIMESTEP))
        stroke_steps = max(int(round(spec.stroke / spec.speed / TIMESTEP)), 8)
        path = np.concatenate([np.zeros(press_steps), np.linspace(0, spec.stroke, stroke_steps)])
        readings = np.empty((n, path.size, self.model.nsensordata))
        wanted = max(1, min(int(threads if threads is not None else press_threads()), n))
        chunks = np.array_split(np.arange(n), wanted)
        with self._lock:
            workers = self._workers(wanted)
            if wanted == 1:
                self._press(workers[0], x0, y0, path, readings)
            else:
                from concurrent.futures import ThreadPoolExecutor

                with ThreadPoolExecutor(wanted) as pool:  # the loop lets go of the GIL
                    list(pool.map(lambda w, part: self._press(w, x0[part], y0[part], path,
                                                              readings[part[0]:part[-1] + 1]),
                                  workers, chunks))
        return [self._probe_of(readings[i], rngs[i], float(x0[i]), float(y0[i]), press_steps)
                for i in range(n)]

    def _workers(self, count: int) -> list[tuple[Any, Any, np.ndarray]]:
        """``count`` copies of the model, each with a data and the addresses of the arrays the
        compiled loop reads and writes (kept: each press sets again what it changes)."""
        import copy

        import mujoco

        workers = self.__dict__.setdefault("_press_workers", [])
        while len(workers) < count:
            model = copy.copy(self.model)
            data = mujoco.MjData(model)
            fields = np.array([a.ctypes.data for a in (
                data.qpos, data.ctrl, data.sensordata, model.pair_solref, model.pair_friction,
                model.dof_damping)], dtype=np.int64)
            workers.append((model, data, fields))
        return workers[:count]

    def _press(self, worker: tuple[Any, Any, np.ndarray], x0: np.ndarray, y0: np.ndarray,
               path: np.ndarray, readings: np.ndarray) -> None:
        """The presses from (``x0``, ``y0``) on one worker (:meth:`_workers`), their sensors
        per step into ``readings``."""
        from runner.world._contact import mujoco_library, press_batch

        step, reset = mujoco_library()
        model, data, fields = worker
        spec = self.spec
        nx, ny = self.material_map.shape
        press_batch(step, reset, model._address, data._address, fields, model.nsensordata,
                    np.ascontiguousarray(x0), np.ascontiguousarray(y0),
                    spec.radius + APPROACH_GAP, spec.force / APPROACH_SPEED, Z_DAMPING,
                    spec.force, path, TIP_MASS, RELIEF_SPACING / 2, spec.radius, self.cell,
                    nx, ny, DISC, self.cell_contact, self._cell_material, self.variant,
                    self._slope_table, RELIEF_SPACING, self.samples, MIN_FRICTION, readings)

    @cached_property
    def _cell_material(self) -> np.ndarray:
        return np.ascontiguousarray(self.material_map.ravel(), dtype=np.intp)

    @cached_property
    def _slope_table(self) -> np.ndarray:
        """The relief's slopes by [material index, variant, u, v] (NaN for a material not
        laid)."""
        table = np.full((len(self.materials), VARIANTS, self.samples, self.samples), np.nan)
        for m, name in enumerate(self.materials):
            if name in self.slopes:
                table[m] = self.slopes[name]
        return table

    def _probe_of(self, readings: np.ndarray, rng: np.random.Generator, x0: float, y0: float,
                  press_steps: int) -> Probe:
        """A probe from its sensors' readings per step (after its positioning error was drawn
        from ``rng``): the noise drawn, the traces and the features."""
        spec, steps = self.spec, len(readings)
        sensed, distance = readings[:, [0, 1, 4]], readings[:, 5:]
        noise = rng.standard_normal((steps, 3)) * (spec.noise_force, spec.noise_force,
                                                   spec.noise_depth)
        normal, tangential, height = (sensed + noise).T
        # the draws of the features added since come after those above, so that a probe's
        # texture and compliance stay what they were
        compression = np.maximum(-(distance + ELECTRODE_RADIUS), 0.0)
        electrodes = compression + rng.standard_normal(compression.shape) * spec.noise_electrode
        pressed = spec.radius - float(sensed[press_steps - 1, 2])
        temperature = thermal_trace(sensed[:, 0] > 0, self.effusivity_at(x0, y0, pressed), spec)
        temperature = temperature + rng.standard_normal(steps) * spec.noise_temperature
        traces = {"normal": normal, "tangential": tangential, "height": height,
                  "electrodes": electrodes, "temperature": temperature}
        every = press_features(traces, press_steps, spec)
        raw = {key: every[key] for key in ("force", "depth", "friction_ratio", "tangential_sd")}
        return Probe(texture=every["texture"], compliance=every["compliance"],
                     at=(x0 + spec.stroke / 2, y0), traces=traces, features=every, **raw)

    def probe_stepwise(self, flat: int, rng: np.random.Generator) -> Probe:
        """:meth:`probe` driven from Python one step at a time, the contact set again at the
        step it is due (the reference the batched presses are measured and checked against,
        ``benchmarks/physics.py``)."""
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
        # per step, every sensor: the touch, the x axis's force, the position (three), then
        # the electrodes' distances
        readings = np.empty((steps, model.nsensordata))
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
            readings[k] = sensordata
        return self._probe_of(readings, rng, float(x0), float(y0), press_steps)


def press_threads() -> int:
    """The threads a batch of presses is stepped on: :data:`PRESS_THREADS` at most, as many as
    the process may use, and one in a worker process of an experiment (the workers share the
    cores)."""
    import multiprocessing
    import os

    if multiprocessing.parent_process() is not None:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(PRESS_THREADS, cores or 1))


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
    is seeded by (its reading seed, k), so a run's readings depend on nothing else. Its
    readings are the features its scene's ``readings:`` names (reading -> feature, in that
    order); raises BayesprogError when one is unknown or a laid material cannot give it
    (:func:`feature_problems`)."""

    def __init__(self, scene: Scene, seeds: Sequence[int | tuple[int, ...]]):
        from bayesprog import BayesprogError

        problems = feature_problems(scene.spec, scene.properties, scene.properties)
        if problems:
            raise BayesprogError("sensor: physics: " + "; ".join(m for _, m in problems))
        self.scene = scene
        self.seeds = list(seeds)
        self.steps = [0] * len(self.seeds)
        self.last: list[Probe] = []
        self.names = tuple(scene.spec.readings)
        self._features = [scene.spec.readings[name] for name in self.names]

    def probe(self, cells: np.ndarray) -> Readings:
        """The readings of one probe per run at ``cells`` [runs] (flat); the probes are kept
        in :attr:`last`."""
        flat = np.asarray(cells).ravel()
        rngs = [np.random.default_rng(probe_seed(self.seeds[r], self.steps[r]))
                for r in range(len(flat))]
        self.last = self.scene.probes(flat, rngs)
        for r in range(len(flat)):
            self.steps[r] += 1
        return self.readings(self.last)

    def readings(self, probes: Sequence[Probe]) -> Readings:
        """The readings of ``probes`` (one per run): the features the scene's readings name."""
        from runner.world.readings import Readings

        values = np.array([[p.features[f] for f in self._features] for p in probes],
                          dtype=float).reshape(len(probes), len(self.names))
        return Readings(self.names, values)
