"""Reference values with their provenance (tests/data/reference_values.json)."""

import json
import os

_PATH = os.path.join(os.path.dirname(__file__), "data", "reference_values.json")

with open(_PATH) as fh:
    VALUES = {k: v for k, v in json.load(fh).items() if not k.startswith("_")}


def ref(name):
    """(value, relative tolerance) of a reference value."""
    e = VALUES[name]
    return e["value"], e["rel"]
