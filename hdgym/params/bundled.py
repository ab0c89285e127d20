"""The presets shipped in ``hdgym/presets/`` (TOML files with a ``[sources]`` table)."""

from __future__ import annotations

from importlib import resources

from hdgym.params.joint import JointParams
from hdgym.params.toml_io import loads


def preset_names() -> list[str]:
    """Names of the bundled presets."""
    files = resources.files("hdgym.presets")
    return sorted(f.name[:-5] for f in files.iterdir() if f.name.endswith(".toml"))


def preset(name: str) -> JointParams:
    """Load a bundled preset by name (e.g. ``tuttle-joint1``)."""
    names = preset_names()
    if name not in names:
        raise ValueError(f"preset: unknown preset {name!r}; known presets are {', '.join(names)}")
    text = resources.files("hdgym.presets").joinpath(f"{name}.toml").read_text()
    return loads(text, f"preset {name}")
