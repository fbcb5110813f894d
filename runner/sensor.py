"""``python -m runner.sensor MODEL.yaml --per-material N --seed S -o PROBES.csv``: record a
training set of probes from a sensor model (:func:`runner.world.sensor.main`), at the address
the command has always had; the sensors themselves live in :mod:`runner.world.sensor`."""

from runner.world.sensor import main

if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
