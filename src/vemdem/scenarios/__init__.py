"""Ready-made scenarios: each has a config schema and a run function (see registry.py)."""
