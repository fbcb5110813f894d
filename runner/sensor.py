"""Haptic sensors: the interface the explorer reads, and a synthetic sensor for simulation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from bayesprog import Program
from bayesprog.forms import ParamValue


class HapticSensor(Protocol):
    """What the explorer needs from a sensor: texture and compliance of probed cells.

    A real robot implements ``probe`` by moving the hand to each cell (one per run) and
    extracting the two haptic features; the simulator draws them from the true material.
    """

    def probe(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``cells`` [runs] flat cell indices -> (texture [runs], compliance [runs])."""
        ...


def material_normals(perception: Program) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Mean and sigma per material of the perception program's ``P(E | M)`` and ``P(C | M)``."""
    out = {}
    card = perception.variables["M"].card  # type: ignore[union-attr]
    for feature in ("E", "C"):
        term = perception.term(f"P({feature} | M)")
        values = []
        for name in ("mean", "sigma"):
            p = term.params[name]
            assert isinstance(p, ParamValue), f"P({feature} | M) {name} must be a literal"
            values.append(np.broadcast_to(p.array, (card,)).astype(float))
        out[feature] = (values[0], values[1])
    return out


class SyntheticSensor:
    """Draws (texture, compliance) from the true material's Normals, plus optional white noise.

    Each run has its own generator, so a run's readings do not depend on the other runs.
    """

    def __init__(self, material_map: np.ndarray, perception: Program, seeds: Sequence[int | np.random.SeedSequence],
                 extra_noise: float = 0.0):
        self.materials = material_map.ravel()
        self.normals = material_normals(perception)
        self.extra_noise = extra_noise
        self.rngs = [np.random.default_rng(s) for s in seeds]

    def probe(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.materials[np.asarray(cells)]
        out = []
        for feature in ("E", "C"):
            mean, sigma = self.normals[feature]
            z = np.array([rng.standard_normal(2) for rng in self.rngs])
            noise = z[:, 1] * self.extra_noise
            out.append(mean[m] + sigma[m] * z[:, 0] + noise)
        return out[0], out[1]
