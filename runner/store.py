"""Results that survive: one file per (task, configuration, chunk of runs), written atomically.

``DIR/experiment.json`` records the experiment, its seed and start cells, the text of every
program and scenario file it resolved, and a hash of all of it. Running again in the same folder
skips the chunks already written; a different configuration is refused, never mixed in.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bayesprog.errors import BayesprogError
from bayesprog.files import atomic_write


class StoreError(BayesprogError):
    """An output folder that cannot take these results."""


@dataclass(frozen=True)
class Unit:
    """One piece of work: some runs of one task under one configuration."""

    task: str
    configuration: str
    chunk: int
    runs: tuple[int, ...]

    @property
    def name(self) -> str:
        return f"{self.task}/{self.configuration}/runs_{self.runs[0]:04d}-{self.runs[-1]:04d}.npz"


def config_hash(manifest: dict) -> str:
    payload = {k: manifest[k] for k in ("experiment", "start_cells", "files")}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


class ResultStore:
    def __init__(self, out: Path):
        self.out = Path(out)

    @property
    def manifest_path(self) -> Path:
        return self.out / "experiment.json"

    def manifest(self) -> dict:
        try:
            return json.loads(self.manifest_path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise StoreError(f"{self.out}: no experiment.json: not an experiment's output "
                             "folder") from None

    def open(self, manifest: dict) -> None:
        """Start or resume: refuse a folder that holds another configuration's results."""
        manifest = dict(manifest, hash=config_hash(manifest))
        if self.manifest_path.exists():
            old = self.manifest()
            if old.get("hash") != manifest["hash"]:
                raise StoreError(
                    f"{self.out} holds results of another configuration (hash "
                    f"{old.get('hash')}, this one {manifest['hash']}): choose another --out "
                    "folder, or remove this one to start again"
                )
            return
        self.out.mkdir(parents=True, exist_ok=True)
        atomic_write(self.manifest_path, json.dumps(manifest, indent=1).encode())

    def path(self, unit: Unit) -> Path:
        return self.out / "chunks" / unit.name

    def done(self, unit: Unit) -> bool:
        return self.path(unit).exists()

    def save(self, unit: Unit, result: dict[str, np.ndarray]) -> None:
        buffer = io.BytesIO()
        np.savez(buffer, runs=np.asarray(unit.runs), **result)
        atomic_write(self.path(unit), buffer.getvalue())

    def load(self, task: str, configuration: str, units: list[Unit]) -> dict[str, np.ndarray]:
        """Every run of (task, configuration), in run order."""
        parts = []
        for unit in units:
            if unit.task != task or unit.configuration != configuration:
                continue
            path = self.path(unit)
            if not path.exists():
                raise StoreError(f"{self.out}: results of {unit.name} are missing: run the "
                                 "experiment again to finish it")
            with np.load(path) as data:
                parts.append({k: data[k] for k in data.files})
        if not parts:
            raise StoreError(f"{self.out}: no results for {task}/{configuration}")
        keys = list(dict.fromkeys(k for p in parts for k in p))
        # a field that earlier versions did not store: NaN for their runs
        return {k: np.concatenate([p[k] if k in p else np.full(p["gamma"].shape, np.nan)
                                   for p in parts]) for k in keys}
