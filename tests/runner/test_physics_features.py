"""The physics fingertip's named features: texture and compliance as they were, the static
pressure, the vibration power, the electrodes' spread and the temperature drop each against
what the physics says, the scenario's mapping of readings to features and the features its
materials cannot give."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from bayesprog import BayesprogError
from runner.world.physics import (
    FEATURES,
    NEEDS,
    MaterialPhysics,
    MaterialPhysicsPatch,
    PhysicsSensor,
    ProbeSpec,
    Scene,
    default_materials,
    electrode_positions,
    feature_problems,
    merged,
    press_features,
    vibration_power,
)
from runner.world.readings import Readings
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
#: no noise and no positioning error: each feature is the physics alone
QUIET = ProbeSpec(jitter=0.0, noise_force=0.0, noise_depth=0.0, noise_electrode=0.0,
                  noise_temperature=0.0)
RIGID = MaterialPhysics(stiffness=1e5, damping=280, friction=0.5, roughness=0.0)


def uniform(material: MaterialPhysics, spec: ProbeSpec = QUIET) -> Scene:
    """A 3 x 3 surface of one material, every cell alike."""
    flat = material.model_copy(update={"variation": 0.0})
    return Scene(np.zeros((3, 3), int), 0.01, ("m",), {"m": flat}, spec)


def soft(stiffness: float, **more: float) -> MaterialPhysics:
    return MaterialPhysics(stiffness=stiffness, damping=2 * np.sqrt(stiffness * 0.2),
                           friction=0.5, roughness=0.0, **more)


@pytest.fixture(scope="module")
def paper_physics():
    return load_scenario(ROOT / "models" / "scenarios" / "paper_physics.yaml")


# main's values (commit 0ee59bf, before the features beyond texture and compliance) of these
# probes of paper_physics's scene: cell, seed of the probe's rng -> texture, compliance
MAIN_PROBES = {
    (940, (11, 940, 0)): (1.481683036135748, 1.010877498080318),  # plush
    (940, (11, 940, 1)): (1.1282894966216779, 1.0161973181378112),
    (912, (11, 912, 0)): (0.22212383039526895, 0.09951619627960677),  # silicone
    (912, (11, 912, 1)): (0.22298554400547113, 0.09911638700299315),
    (896, (11, 896, 0)): (0.5524512858280038, 0.0023899145212900107),  # wood
    (896, (11, 896, 1)): (0.2735349704727886, 0.0028198374654217298),
    (400, (5, 0)): (0.9674367247264973, 0.21391095780144478),  # plush by a border
    (1250, (5, 1)): (0.23038336787292502, 0.002991510640634891),  # wood
}
# and the raw figures of the last two: force, depth, friction ratio, tangential sd
MAIN_RAW = {
    400: (1.0145568396100362, 0.0008680993012199585, 0.6343515674725968,
          0.15917103790854203),
    1250: (0.9987481828148742, 1.1951063264821829e-05, 0.43551644664297623,
           0.028662890724243998),
}


#: how close a press here is to the values above, recorded on another machine: MuJoCo's
#: contact solver and the maths library take other instructions on another processor or under
#: another MuJoCo release (seen: 3e-16 apart, relative, under MuJoCo 4.0, 4e-14 under 3.17),
#: and nothing else may move them. Bit for bit is asserted where it holds, between the presses
#: of one machine (the batched presses and the stepwise ones, below).
MACHINES = 1e-10


def test_texture_and_compliance_are_what_they_were(paper_physics):
    """The press driven step by step (the reference the batched presses are checked against)
    gives what it gave before the features beyond texture and compliance, to the last bits a
    processor may change."""
    scene = paper_physics.physics_scene()
    for (cell, seed), (texture, compliance) in MAIN_PROBES.items():
        probe = scene.probe_stepwise(cell, np.random.default_rng(list(seed)))
        np.testing.assert_allclose((probe.texture, probe.compliance), (texture, compliance),
                                   rtol=MACHINES, atol=0, err_msg=str((cell, seed)))
        assert (probe.features["texture"], probe.features["compliance"]) == (
            probe.texture, probe.compliance)
        if cell in MAIN_RAW:
            raw = (probe.force, probe.depth, probe.friction_ratio, probe.tangential_sd)
            np.testing.assert_allclose(raw, MAIN_RAW[cell], rtol=MACHINES, atol=0)
            assert tuple(probe.features[k] for k in ("force", "depth", "friction_ratio",
                                                     "tangential_sd")) == raw


def test_every_feature_is_declared_with_its_unit_and_computed_in_that_order():
    probe = uniform(soft(3000.0, effusivity=500.0), ProbeSpec()).probe(4,
                                                                        np.random.default_rng(0))
    assert list(probe.features) == list(FEATURES)
    assert all(np.isfinite(v) for v in probe.features.values())
    units = {name: text.split(":")[0] for name, text in FEATURES.items()}
    assert units == {"texture": "1", "compliance": "1", "force": "N", "depth": "m",
                     "friction_ratio": "1", "tangential_sd": "N", "pressure": "Pa",
                     "vibration_power": "N^2", "electrode_spread": "1",
                     "temperature_drop": "K"}
    assert set(NEEDS) <= set(FEATURES)
    # the features are those of the traces kept with the probe
    again = press_features(probe.traces, 250, ProbeSpec())
    assert again == probe.features


def test_static_pressure_is_the_force_over_the_hertz_contact_area():
    pressures = []
    for stiffness in (250.0, 3000.0, 1e5):
        probe = uniform(soft(stiffness)).probe(4, np.random.default_rng(0))
        area = np.pi * 0.006 * probe.depth  # pi a^2, a = sqrt(R d)
        assert probe.features["pressure"] == pytest.approx(probe.force / area, rel=1e-12)
        pressures.append(probe.features["pressure"])
    # the same newton on a stiffer surface: a smaller contact, a higher pressure
    assert pressures[0] < pressures[1] < pressures[2]
    # 1 N on 3,000 N/m: d = 1/3 mm, a = 1.41 mm, 159 kPa
    assert pressures[1] == pytest.approx(1 / (np.pi * 0.006 / 3000), rel=0.03)


@pytest.mark.parametrize("size", [4, 5, 63, 64, 65, 150, 151, 400])
def test_the_vibration_power_is_welchs_estimate_over_the_band(size):
    rng = np.random.default_rng(size)
    x = 0.6 + np.cumsum(rng.standard_normal(size)) * 0.01 + rng.standard_normal(size) * 0.02
    frequency, density = signal.welch(x, fs=1000, nperseg=min(64, size), detrend="linear")
    for band in ((20, 400), (0, 500), (100, 120)):
        inside = (frequency >= band[0]) & (frequency <= band[1])
        expected = density[inside].sum() * (frequency[1] - frequency[0])
        assert vibration_power(x, band) == pytest.approx(expected, rel=1e-10, abs=1e-300)
    assert np.isnan(vibration_power(x[:3], (20, 400)))


def test_a_rougher_surface_vibrates_more_in_the_band():
    powers = []
    for roughness in (0.0, 5e-5, 3e-4):
        scene = uniform(RIGID.model_copy(update={"roughness": roughness}), ProbeSpec())
        probes = [scene.probe(c, np.random.default_rng([2, c])) for c in range(0, 9, 2)]
        powers.append(np.mean([p.features["vibration_power"] for p in probes]))
    assert powers[0] < powers[1] < powers[2]
    assert powers[2] > 30 * powers[0]
    # a flat surface: the force sensor's white noise alone, its variance times the band's
    # share of the 500 Hz (within the spread of five estimates)
    assert powers[0] == pytest.approx(0.005**2 * 380 / 500, rel=0.3)


def test_the_electrodes_read_the_fingertips_depth_below_the_surface_at_each():
    positions = electrode_positions(19, 0.006, 50.0)
    assert np.allclose(np.linalg.norm(positions, axis=1), 0.006)
    assert positions[0].tolist() == [0.0, 0.0, -0.006]
    polar = np.degrees(np.arccos(-positions[:, 2] / 0.006))
    assert polar.max() == pytest.approx(50.0) and np.all(np.diff(polar) > 0)
    probe = uniform(soft(250.0)).probe(4, np.random.default_rng(0))
    # MuJoCo's distance to the plane of the surface, against the geometry: how far each
    # electrode lies below the surface (the fingertip's centre at the height)
    below = -(probe.traces["height"][:, None] + positions[:, 2])
    np.testing.assert_allclose(probe.traces["electrodes"], np.maximum(below, 0), atol=1e-12)


def test_the_electrodes_spread_less_on_a_softer_surface():
    spreads = {k: uniform(soft(k)).probe(4, np.random.default_rng(0)).features[
        "electrode_spread"] for k in (1e5, 3000.0, 250.0)}
    # rigid: the pole alone touches, the coefficient of variation of one in 19 is sqrt(18)
    assert spreads[1e5] == pytest.approx(np.sqrt(18), rel=1e-9)
    assert spreads[1e5] > spreads[3000.0] > spreads[250.0]
    assert spreads[250.0] < 0.5  # 4 mm deep: every electrode of the cap pressed


def test_the_temperature_drop_is_the_first_order_contact_model():
    spec = QUIET
    drops = {}
    for name, effusivity in (("copper", 37000.0), ("wood", 400.0), ("foam", 60.0)):
        probe = uniform(RIGID.model_copy(update={"effusivity": effusivity}), spec).probe(
            4, np.random.default_rng(0))
        # the closed form: two half-spaces meet at the effusivity-weighted mean; the sensor
        # follows it with a lag of 1 s over the time in contact
        contact = np.count_nonzero(probe.traces["normal"] > 0) * 0.001
        assert 0.35 < contact < 0.45  # 450 ms of press and stroke, less the approach
        t_c = (1100.0 * 33.0 + effusivity * 22.0) / (1100.0 + effusivity)
        expected = (33.0 - t_c) * (1 - np.exp(-contact / 1.0))
        assert probe.features["temperature_drop"] == pytest.approx(expected, rel=1e-9)
        drops[name] = probe.features["temperature_drop"]
    assert drops["copper"] > drops["wood"] > drops["foam"] > 0
    assert drops["copper"] > 10 * drops["foam"]
    # the drop follows the temperatures and the time constant given
    warm = spec.model_copy(update={"surface_temperature": 30.0, "thermal_time_constant": 0.2})
    probe = uniform(RIGID.model_copy(update={"effusivity": 37000.0}), warm).probe(
        4, np.random.default_rng(0))
    contact = np.count_nonzero(probe.traces["normal"] > 0) * 0.001
    t_c = (1100.0 * 33.0 + 37000.0 * 30.0) / 38100.0
    assert probe.features["temperature_drop"] == pytest.approx(
        (33.0 - t_c) * (1 - np.exp(-contact / 0.2)), rel=1e-9)


def test_a_material_without_effusivity_gives_no_temperature_drop():
    probe = uniform(RIGID, ProbeSpec()).probe(4, np.random.default_rng(0))
    assert np.isnan(probe.features["temperature_drop"])
    assert all(np.isfinite(v) for k, v in probe.features.items() if k != "temperature_drop")


def test_a_press_on_a_border_feels_both_materials_effusivities():
    rigid = RIGID.model_copy(update={"variation": 0.0})
    materials = {"copper": rigid.model_copy(update={"effusivity": 37000.0}),
                 "foam": rigid.model_copy(update={"effusivity": 60.0})}
    scene = Scene(np.array([[0, 1]]), 0.01, ("copper", "foam"), materials, QUIET)
    assert scene.effusivity_at(0.005, 0.005, 1e-4) == 37000.0
    assert scene.effusivity_at(0.005, 0.015, 1e-4) == 60.0
    assert 60.0 < scene.effusivity_at(0.005, 0.010, 1e-4) < 37000.0


def test_the_bundled_materials_carry_their_effusivity():
    known = default_materials()
    assert all(m.effusivity is not None and "effusivity" in m.why for m in known.values())
    e = {name: m.effusivity for name, m in known.items()}
    assert e["copper"] > e["steel"] > e["brick"] > e["wood"] > e["cork"] > e["soft_foam"]
    # a scenario's entry overrides it; a material of its own may leave it out
    patched, lacking = merged(known, {"wood": MaterialPhysicsPatch(effusivity=500.0),
                                      "basalt": MaterialPhysicsPatch(
                                          stiffness=1e5, damping=280, friction=0.6,
                                          roughness=1e-5)})
    assert patched["wood"].effusivity == 500.0 and patched["wood"].stiffness == 1e5
    assert patched["basalt"].effusivity is None and not lacking


def test_feature_problems_name_the_reading_the_feature_and_the_fix():
    known = default_materials()
    basalt = MaterialPhysics(stiffness=1e5, damping=280, friction=0.6, roughness=1e-5)
    properties = {**known, "basalt": basalt}
    assert feature_problems(ProbeSpec(), properties, ["wood", "basalt"]) == []
    every = ProbeSpec(readings={name: name for name in FEATURES})
    assert feature_problems(every, properties, ["wood", "plush", "silicone"]) == []
    # a material that is not laid does not count
    assert feature_problems(every, properties, ["wood"]) == []
    problems = feature_problems(
        ProbeSpec(readings={"texture": "texture", "vib": "vibraton_power",
                            "heat": "temperature_drop"}), properties, ["wood", "basalt"])
    assert [where for where, _ in problems] == [("readings", "vib"), ("readings", "heat")]
    unknown, lacking = (message for _, message in problems)
    assert "unknown feature 'vibraton_power': did you mean 'vibration_power'?" in unknown
    assert "temperature_drop" in unknown and "electrode_spread" in unknown  # the choices
    assert "temperature_drop needs each laid material's effusivity" in lacking
    assert "basalt has none" in lacking and "wood" not in lacking
    assert "physics: (basalt: {effusivity: ...})" in lacking


def test_the_sensor_reads_the_features_its_readings_name(paper_physics):
    scene = paper_physics.physics_scene()
    default = PhysicsSensor(scene, [(5, 0), (5, 1)]).probe(np.array([400, 1250]))
    assert isinstance(default, Readings) and default.names == ("texture", "compliance")
    alone = [scene.probe(c, np.random.default_rng([5, r, 0])) for r, c in enumerate((400, 1250))]
    assert default.values.tolist() == [[p.texture, p.compliance] for p in alone]
    spec = scene.spec.model_copy(update={"readings": {
        "grip": "friction_ratio", "heat": "temperature_drop", "E": "texture",
        "pdc": "pressure"}})
    sensor = PhysicsSensor(paper_physics.physics_scene(spec), [(5, 0), (5, 1)])
    readings = sensor.probe(np.array([400, 1250]))
    assert readings.names == ("grip", "heat", "E", "pdc") and readings.values.shape == (2, 4)
    for r, probe in enumerate(sensor.last):
        assert readings.values[r].tolist() == [probe.features[f] for f in (
            "friction_ratio", "temperature_drop", "texture", "pressure")]
    # the same seeds: the features that were there read as they did
    assert readings["E"].tolist() == default["texture"].tolist()
    assert sensor.probe(np.array([400, 1250])).runs == 2 and sensor.steps == [2, 2]


def test_a_sensor_that_asks_what_its_surface_cannot_give_is_refused():
    spec = QUIET.model_copy(update={"readings": {"heat": "temperature_drop"}})
    with pytest.raises(BayesprogError, match="basalt has none"):
        PhysicsSensor(Scene(np.zeros((2, 2), int), 0.01, ("basalt",), {"basalt": RIGID},
                            spec), [0])
    spec = QUIET.model_copy(update={"readings": {"x": "hardness"}})
    with pytest.raises(BayesprogError, match="unknown feature 'hardness'"):
        PhysicsSensor(uniform(RIGID, spec), [0])


@pytest.mark.parametrize("band", [(300.0, 600.0), (200.0, 100.0), (-1.0, 100.0)])
def test_a_vibration_band_outside_the_samples_is_refused(band):
    with pytest.raises(ValueError, match="vibration_band"):
        ProbeSpec(vibration_band=band)


def test_the_sensor_reads_probes_made_elsewhere(paper_physics):
    scene = paper_physics.physics_scene()
    probes = [scene.probe_stepwise(940, np.random.default_rng([11, 940, s])) for s in (0, 1)]
    readings = PhysicsSensor(scene, []).readings(probes)
    assert readings.names == ("texture", "compliance")
    assert readings.values.tolist() == [[p.texture, p.compliance] for p in probes]
    np.testing.assert_allclose(readings.values, [MAIN_PROBES[940, (11, 940, s)] for s in (0, 1)],
                               rtol=MACHINES, atol=0)
    assert PhysicsSensor(scene, []).readings([]).values.shape == (0, 2)


@pytest.mark.parametrize("threads", [1, 2])
def test_presses_in_a_batch_are_the_stepwise_presses_bit_for_bit(paper_physics, threads):
    """The compiled loop steps each press of a batch as probe_stepwise does from Python (the
    contact set again at every step it is due, MuJoCo's own steps): the same traces and
    features to the last bit, on one thread or two."""
    scene = paper_physics.physics_scene()
    cells = [940, 912, 896, 400, 1250]
    batched = scene.probes(np.array(cells), [np.random.default_rng([3, c]) for c in cells],
                           threads=threads)
    for cell, probe in zip(cells, batched, strict=True):
        stepwise = scene.probe_stepwise(cell, np.random.default_rng([3, cell]))
        assert probe.features == stepwise.features, cell
        assert probe.at == stepwise.at
        for key, trace in stepwise.traces.items():
            np.testing.assert_array_equal(probe.traces[key], trace)


def test_batched_texture_and_compliance_are_what_the_stepwise_presses_gave(paper_physics):
    scene = paper_physics.physics_scene()
    keys = list(MAIN_PROBES)
    probes = scene.probes(np.array([cell for cell, _ in keys]),
                          [np.random.default_rng(list(seed)) for _, seed in keys])
    for key, probe in zip(keys, probes, strict=True):
        stepwise = scene.probe_stepwise(key[0], np.random.default_rng(list(key[1])))
        assert (probe.texture, probe.compliance) == (stepwise.texture, stepwise.compliance), key
        np.testing.assert_allclose((probe.texture, probe.compliance), MAIN_PROBES[key],
                                   rtol=MACHINES, atol=0, err_msg=str(key))


def test_a_press_is_the_same_whatever_shares_its_batch(paper_physics):
    from runner.world.physics import BATCH

    scene = paper_physics.physics_scene()
    cells = np.random.default_rng(4).integers(paper_physics.material_map.size, size=BATCH + 3)

    def rngs(idx):
        return [np.random.default_rng([9, int(i)]) for i in idx]

    wide = scene.probes(cells, rngs(range(len(cells))), threads=2)
    for i in (0, 7, BATCH + 1):  # alone, among a few others, and past the first batch
        for probe in (scene.probes(cells[i:i + 1], rngs([i]), threads=1)[0],
                      scene.probes(cells[i:i + 4], rngs(range(i, min(i + 4, len(cells)))),
                                   threads=1)[0]):
            assert probe.features == wide[i].features
            for key, trace in probe.traces.items():
                np.testing.assert_array_equal(trace, wide[i].traces[key])


def test_a_scene_sent_to_another_process_presses_the_same(paper_physics):
    """A scene pickled (as for a worker) leaves MuJoCo's model, its copies and its lock
    behind, builds them again, and presses as the original does."""
    import pickle

    scene = paper_physics.physics_scene()
    cells = np.array([940, 912])
    here = scene.probes(cells, [np.random.default_rng([6, c]) for c in cells])
    sent = pickle.dumps(scene)
    assert b"_press_workers" not in sent
    there = pickle.loads(sent).probes(cells, [np.random.default_rng([6, c]) for c in cells])
    assert [p.features for p in there] == [p.features for p in here]
