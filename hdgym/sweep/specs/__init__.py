"""Ready-made sweep specs (package data): run with ``hdgym sweep hdgym/sweep/specs/NAME.toml``."""
