"""Parameters of a harmonic-drive joint, as frozen, validated dataclasses.

One dataclass per physical part. All values are SI: rad, rad/s, N m, A, V,
s, kg m^2. Torques and stiffnesses of the transmission (compliance,
hysteresis, output friction, kinematic error, load) are *output-referred*;
motor and input-friction values are *motor-referred* (WG side).

Presets are TOML files in ``hdgym/presets/``; every number in a preset has an
entry in its ``[sources]`` table (paper and section, or the observation it
was chosen to reproduce). :func:`load` / :func:`save` read and write them.

The package is split by job; everything is re-exported here:

- :mod:`~hdgym.params.validation`: limits and the field checks;
- :mod:`~hdgym.params.parts`: one dataclass per part (``Motor`` ... ``Integration``);
- :mod:`~hdgym.params.joint`: :class:`JointParams`, dotted-path get/set, :func:`numeric_paths`;
- :mod:`~hdgym.params.toml_io`: TOML in/out (:func:`load`, :func:`save`, ...);
- :mod:`~hdgym.params.bundled`: the shipped presets (:func:`preset`);
- :mod:`~hdgym.params.randomize`: :func:`perturb` (domain randomization).
"""

from hdgym.params.bundled import preset, preset_names
from hdgym.params.joint import JointParams, numeric_paths
from hdgym.params.parts import (
    PARTS,
    Amplifier,
    Compliance,
    Friction,
    FrictionSide,
    Harmonic,
    Hysteresis,
    Integration,
    KinematicError,
    Load,
    Motor,
    Ripple,
    Sensors,
    Transmission,
)
from hdgym.params.randomize import perturb
from hdgym.params.toml_io import (
    atomic_write_text,
    dumps,
    from_dict,
    load,
    loads,
    save,
    to_dict,
)
from hdgym.params.validation import (
    COMPLIANCE_MODELS,
    FRICTION_PLACEMENTS,
    GROUNDED,
    HYSTERESIS_MODELS,
    MAX_HARMONICS,
    MAX_RIPPLES,
    MAX_SLIP_ELEMENTS,
)

__all__ = [
    "COMPLIANCE_MODELS", "FRICTION_PLACEMENTS", "GROUNDED", "HYSTERESIS_MODELS", "MAX_HARMONICS",
    "MAX_RIPPLES", "MAX_SLIP_ELEMENTS", "PARTS", "Amplifier", "Compliance", "Friction",
    "FrictionSide", "Harmonic", "Hysteresis", "Integration", "JointParams", "KinematicError",
    "Load", "Motor", "Ripple", "Sensors", "Transmission", "atomic_write_text", "dumps",
    "from_dict", "load", "loads", "numeric_paths", "perturb", "preset", "preset_names", "save",
    "to_dict",
]
