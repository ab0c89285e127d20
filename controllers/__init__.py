"""Controllers for hdgym joints: they see only what the hardware measures.

Every controller is a callable ``controller(t, measurement) -> current`` (A)
with a ``reset()`` method, as :meth:`hdgym.sim.Simulator.run_closed_loop`
expects. ``measurement`` carries the channels of
:data:`hdgym.hardware.CHANNELS` (``motor_angle``, ``output_angle`` in rad,
``motor_velocity``, ``output_velocity`` in rad/s, ``output_torque`` in N m,
``motor_current`` in A) plus ``time`` (s) and ``reference`` (output rad).

Modules, one job each:

* :mod:`controllers.pid` -- discrete PID with anti-windup, filtered
  derivative, limits and bumpless reset; position loops and :class:`Cascade`.
* :mod:`controllers.ke_feedforward` -- kinematic-error model identified from
  a record, and the feedforward that corrects the motor reference.
* :mod:`controllers.repetitive` -- Fourier-series repetitive control indexed
  by the WG angle.
* :mod:`controllers.dob` -- disturbance observer (nominal inverse + Q-filter).
* :mod:`controllers.tuning` -- linear two-inertia model and PID design with
  python-control.
* :mod:`controllers.adapter` -- run a controller as a policy on the envs.
* :mod:`controllers.scenarios` -- closed-loop runs with the true states beside
  the measured ones, references, the benchmark's PID design, metrics.
* :mod:`controllers.experiments` -- the benchmark's four experiments and
  what they run on.
* :mod:`controllers.benchmark` -- ``hdgym controllers``: runs them, then
  :mod:`controllers.figures` draws and :mod:`controllers.report` writes the page.
* :mod:`controllers.sweep` -- ``hdgym sweep`` scenarios ``controllers:NAME``
  (one controller config per run), found through an entry point.
"""

from controllers.base import Controller, Measurement
from controllers.dob import DisturbanceObserver
from controllers.ke_feedforward import KEFeedforward, KEModel, identify_ke
from controllers.pid import PID, Cascade, PositionPID
from controllers.repetitive import RepetitiveController

__all__ = [
    "PID", "Cascade", "Controller", "DisturbanceObserver", "KEFeedforward", "KEModel",
    "Measurement", "PositionPID", "RepetitiveController", "identify_ke",
]
