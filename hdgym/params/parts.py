"""The parts of a joint, one frozen dataclass each (SI units; see :mod:`hdgym.params`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from hdgym.params.validation import (
    COMPLIANCE_MODELS,
    FRICTION_PLACEMENTS,
    GROUNDED,
    HYSTERESIS_MODELS,
    MAX_HARMONICS,
    MAX_RIPPLES,
    MAX_SLIP_ELEMENTS,
    finite,
    require,
)


@dataclass(frozen=True)
class Motor:
    """Motor and wave generator, motor-referred.

    Attributes:
        inertia: rotor + wave generator inertia, kg m^2 (> 0).
        torque_constant: K_t, N m/A (> 0).
        back_emf_constant: K_b, V s/rad (>= 0).
        resistance: winding resistance R, ohm (> 0).
    """

    inertia: float
    torque_constant: float
    back_emf_constant: float = 0.0
    resistance: float = 1.0

    def __post_init__(self) -> None:
        finite(self, "motor")
        require(self.inertia > 0, "motor.inertia", "> 0 kg m^2", self.inertia)
        require(self.torque_constant > 0, "motor.torque_constant", "> 0 N m/A",
                self.torque_constant)
        require(self.back_emf_constant >= 0, "motor.back_emf_constant", ">= 0 V s/rad",
                self.back_emf_constant)
        require(self.resistance > 0, "motor.resistance", "> 0 ohm", self.resistance)


@dataclass(frozen=True)
class Transmission:
    """Gear geometry and which port is grounded.

    Attributes:
        n: catalogue ratio N (flexspline teeth / tooth difference), > 1.
        grounded: ``"flexspline"`` (output on the circular spline, ratio N+1,
            same direction) or ``"circular_spline"`` (output on the
            flexspline, ratio N, opposite direction; the sign is folded into
            ``output_angle`` so the ideal output is ``motor_angle/ratio``).
    """

    n: float
    grounded: str = "circular_spline"

    def __post_init__(self) -> None:
        finite(self, "transmission")
        require(self.n > 1, "transmission.n", "> 1 (a reduction)", self.n)
        require(self.grounded in GROUNDED, "transmission.grounded", f"one of {GROUNDED}",
                self.grounded)

    @property
    def ratio(self) -> float:
        """Motor (WG) angle per output angle."""
        return self.n + 1.0 if self.grounded == "flexspline" else self.n

    def port_factor(self, port: str) -> float:
        """WG turns relative to ``port`` per WG turn relative to ground.

        Tooth errors of a port are sampled by the WG lobes at its angle
        relative to that port, so the split kinematic-error lines of the two
        splines sit at different orders of the (grounded-frame) WG angle.
        """
        if port == self.grounded:
            return 1.0
        # output port turns with +1/ratio (FS grounded) or -1/ratio physically
        sign = 1.0 if self.grounded == "flexspline" else -1.0
        return 1.0 - sign / self.ratio


@dataclass(frozen=True)
class Compliance:
    """Flexspline torsional stiffness, output-referred.

    ``model`` picks the spring when ``nonlinear_stiffness`` is on; with it
    off the spring is linear with ``stiffness``.

    Attributes:
        model: ``linear``, ``cubic`` (T = k1 x + k3 x^3), ``two_segment``
            (slope k1 inside +-knee, k1 + extra_stiffness outside) or
            ``three_segment`` (catalogue K1 to T1, K2 to T2, K3 above).
        stiffness: k1 / K1, N m/rad (> 0).
        cubic: k3, N m/rad^3 (>= 0).
        knee: theta0 of the two-segment spring, rad.
        extra_stiffness: k0 of the two-segment spring, N m/rad.
        segment_torques: (T1, T2) of the three-segment spring, N m.
        segment_stiffness: (K2, K3) of the three-segment spring, N m/rad.
        damping: structural damping across the spring, N m s/rad (>= 0).
    """

    stiffness: float
    model: str = "cubic"
    cubic: float = 0.0
    knee: float = 0.0
    extra_stiffness: float = 0.0
    segment_torques: tuple[float, float] = (0.0, 0.0)
    segment_stiffness: tuple[float, float] = (0.0, 0.0)
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "segment_torques", tuple(float(v) for v in self.segment_torques))
        object.__setattr__(self, "segment_stiffness",
                           tuple(float(v) for v in self.segment_stiffness))
        finite(self, "compliance")
        require(self.model in COMPLIANCE_MODELS, "compliance.model",
                f"one of {COMPLIANCE_MODELS}", self.model)
        require(self.stiffness > 0, "compliance.stiffness", "> 0 N m/rad", self.stiffness)
        require(self.cubic >= 0, "compliance.cubic", ">= 0 N m/rad^3", self.cubic)
        require(self.knee >= 0, "compliance.knee", ">= 0 rad", self.knee)
        require(self.extra_stiffness >= 0, "compliance.extra_stiffness", ">= 0 N m/rad",
                self.extra_stiffness)
        require(self.damping >= 0, "compliance.damping", ">= 0 N m s/rad", self.damping)
        require(len(self.segment_torques) == 2, "compliance.segment_torques", "two values",
                self.segment_torques)
        require(len(self.segment_stiffness) == 2, "compliance.segment_stiffness", "two values",
                self.segment_stiffness)
        if self.model == "three_segment":
            t1, t2 = self.segment_torques
            require(0 < t1 < t2, "compliance.segment_torques", "0 < T1 < T2", self.segment_torques)
            require(min(self.segment_stiffness) > 0, "compliance.segment_stiffness", "> 0",
                     self.segment_stiffness)


@dataclass(frozen=True)
class Hysteresis:
    """Hysteresis in the flexspline torsion, output-referred.

    Attributes:
        model: ``maxwell`` (n Maxwell-slip elements) or ``tanh`` (Seyfferth's
            element with last-reversal memory).
        element_stiffness: kappa_i of the Maxwell-slip elements, N m/rad (>= 0).
        element_strength: slip strength W_i, N m (>= 0).
        width: B_f of the tanh element at no load history, N m (>= 0).
        shape: gamma of the tanh element at no load history, 1/rad (>= 0).
        width_slope: growth of B_f per N m of load history (>= 0): the tanh
            element uses ``B_f = width + width_slope * L`` where ``L`` is
            |transmitted torque| at the last torsion reversal (Seyfferth
            figs 9b, 15b).
        shape_slope: change of gamma per N m of load history, 1/(rad N m)
            (any sign; gamma is held >= 0; Seyfferth figs 9a, 15a).
        startup_slope: growth of the input side's Coulomb (startup) torque
            per N m of load history, motor N m per output N m (>= 0;
            Seyfferth figs 10, 16); switched by ``load_dependent_friction``.
            The load history is the tanh element's reversal memory, so the
            three slopes need the ``tanh`` model.
    """

    model: str = "maxwell"
    element_stiffness: tuple[float, ...] = ()
    element_strength: tuple[float, ...] = ()
    width: float = 0.0
    shape: float = 0.0
    width_slope: float = 0.0
    shape_slope: float = 0.0
    startup_slope: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "element_stiffness",
                           tuple(float(v) for v in self.element_stiffness))
        object.__setattr__(self, "element_strength", tuple(float(v) for v in self.element_strength))
        finite(self, "hysteresis")
        require(self.model in HYSTERESIS_MODELS, "hysteresis.model",
                f"one of {HYSTERESIS_MODELS}", self.model)
        require(len(self.element_stiffness) == len(self.element_strength),
                "hysteresis.element_strength", "as long as element_stiffness",
                self.element_strength)
        require(len(self.element_stiffness) <= MAX_SLIP_ELEMENTS, "hysteresis.element_stiffness",
                f"at most {MAX_SLIP_ELEMENTS} elements", self.element_stiffness)
        for k, v in enumerate(self.element_stiffness):
            require(v >= 0, f"hysteresis.element_stiffness[{k}]", ">= 0 N m/rad", v)
        for k, v in enumerate(self.element_strength):
            require(v >= 0, f"hysteresis.element_strength[{k}]", ">= 0 N m (W)", v)
        require(self.width >= 0, "hysteresis.width", ">= 0 N m", self.width)
        require(self.shape >= 0, "hysteresis.shape", ">= 0 1/rad", self.shape)
        require(self.width_slope >= 0, "hysteresis.width_slope", ">= 0 N m per N m",
                self.width_slope)
        require(self.startup_slope >= 0, "hysteresis.startup_slope", ">= 0 N m per N m",
                self.startup_slope)
        for name in ("width_slope", "shape_slope", "startup_slope"):
            v = getattr(self, name)
            require(v == 0 or self.model == "tanh", f"hysteresis.{name}",
                    "0 unless model = 'tanh' (the load history is the tanh element's memory)", v)


@dataclass(frozen=True)
class Ripple:
    """One position-dependent friction harmonic ``amplitude * sin(order * angle + phase)``.

    Attributes:
        order: cycles per revolution of ``frame`` (> 0).
        frame: ``input`` (WG revolution) or ``output`` (output revolution).
        amplitude: N m, referred to the side the ripple belongs to (>= 0).
        phase: rad.
    """

    order: float
    amplitude: float
    frame: str = "input"
    phase: float = 0.0

    def __post_init__(self) -> None:
        finite(self, "ripple")
        require(self.order > 0, "ripple.order", "> 0", self.order)
        require(self.amplitude >= 0, "ripple.amplitude", ">= 0 N m", self.amplitude)
        require(self.frame in ("input", "output"), "ripple.frame", "'input' or 'output'",
                self.frame)


@dataclass(frozen=True)
class FrictionSide:
    """Friction on one side of the gear.

    Running friction at speed w (each term switched by its effect):
    ``[Fc + sum_k A_k sin(order_k angle + phase_k) + (Fs - Fc) exp(-(w/ws)^2)] sgn(w)
    + b1 w + b2 w^3`` with the cubic clamped beyond its peak so viscous
    friction never falls. While stuck it holds up to ``breakaway``.

    Attributes:
        coulomb: Fc, N m (>= 0).
        breakaway: Fs, static friction, N m (>= coulomb).
        stribeck_velocity: ws, rad/s (> 0 when breakaway > coulomb).
        viscous: b1, N m s/rad (>= 0).
        cubic: b2, N m s^3/rad^3 (<= 0, Tuttle eq 3.22; clamped).
        ripple: position-dependent harmonics; amplitudes sum to at most Fc.
    """

    coulomb: float = 0.0
    breakaway: float = 0.0
    stribeck_velocity: float = 1.0
    viscous: float = 0.0
    cubic: float = 0.0
    ripple: tuple[Ripple, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "ripple", tuple(
            r if isinstance(r, Ripple) else Ripple(**r) for r in self.ripple))
        finite(self, "friction")
        require(self.coulomb >= 0, "friction.coulomb", ">= 0 N m", self.coulomb)
        require(self.breakaway >= self.coulomb, "friction.breakaway", ">= coulomb",
                self.breakaway)
        require(self.stribeck_velocity > 0, "friction.stribeck_velocity", "> 0 rad/s",
                self.stribeck_velocity)
        require(self.viscous >= 0, "friction.viscous", ">= 0 N m s/rad", self.viscous)
        require(self.cubic <= 0 or self.viscous == 0 and self.cubic >= 0, "friction.cubic",
                "<= 0 (a falling cubic, Tuttle eq 3.22) or >= 0 with viscous 0", self.cubic)
        require(len(self.ripple) <= MAX_RIPPLES, "friction.ripple",
                f"at most {MAX_RIPPLES} harmonics", len(self.ripple))
        total = sum(r.amplitude for r in self.ripple)
        require(total <= self.coulomb + 1e-12, "friction.ripple",
                "amplitudes summing to at most coulomb (friction never negative)", total)


@dataclass(frozen=True)
class Friction:
    """Friction of the joint.

    Attributes:
        input: wave-generator bearing and motor, motor-referred N m.
        output: the transmission's friction, output-referred N m, with the
            load-dependent tooth term ``mu' |T_k|``. Where it acts is
            ``placement``.
        tooth_mu: Coulomb coefficient at the gear teeth (Tuttle model 5).
        tooth_angle: gear-tooth pressure angle, rad (Tuttle: 30 deg).
        placement: ``output``: the output side's friction acts between the
            output and ground, at the output speed (the flexspline torque
            then carries it); ``mesh``: it acts in the tooth mesh between
            flexspline and circular spline, at the mesh's relative speed
            ``motor_velocity (1/ratio - ke')`` and reflected to the wave
            generator by the same factor (Tuttle §3 models 2 and 5, p. 113:
            the flexspline torque sensor is blind to it); ``splines``: between
            the splines on the output side of the compliance (Tuttle's models 4
            and 5): the motion of ``output``, with the state's torque (the
            sensor) the grounded spline's, ``J_o dw_o/dt + T_load``, blind to the
            friction. docs/physics.md eq. (8).
    """

    input: FrictionSide = field(default_factory=FrictionSide)
    output: FrictionSide = field(default_factory=FrictionSide)
    tooth_mu: float = 0.0
    tooth_angle: float = math.radians(30.0)
    placement: str = "output"

    def __post_init__(self) -> None:
        for side in ("input", "output"):
            v = getattr(self, side)
            if isinstance(v, Mapping):
                object.__setattr__(self, side, FrictionSide(**v))
        finite(self, "friction")
        require(self.tooth_mu >= 0, "friction.tooth_mu", ">= 0", self.tooth_mu)
        require(0 < self.tooth_angle < math.pi / 2, "friction.tooth_angle", "in (0, pi/2) rad",
                self.tooth_angle)
        require(self.placement in FRICTION_PLACEMENTS, "friction.placement",
                f"one of {FRICTION_PLACEMENTS}", self.placement)

    @property
    def load_coefficient(self) -> float:
        """mu' = mu / (sin(alpha) cos(alpha)): output-referred tooth friction torque per
        N m transmitted (docs/physics.md eq. 7).

        The normal force on a tooth flank at pressure angle alpha carries the
        tangential load T/r as T/(r cos alpha); the flank slides 1/sin(alpha)
        times as fast as the circular spline turns at the pitch radius (Tuttle
        1992 eq. 3.81: tooth-surface speed = B x WG speed, B = 1/((N+1) sin alpha)),
        so friction mu F_N does the work of mu T/(sin alpha cos alpha) at the output.
        """
        return self.tooth_mu / (math.sin(self.tooth_angle) * math.cos(self.tooth_angle))


@dataclass(frozen=True)
class Harmonic:
    """One kinematic-error harmonic ``amplitude * sin(order * angle + phase)``.

    Attributes:
        order: cycles per WG revolution relative to ``port`` (> 0).
        amplitude: output rad (>= 0).
        phase: rad.
        port: whose tooth errors make the line: ``circular_spline`` or
            ``flexspline``; the grounded port's line sits at ``order`` of the
            WG angle, the other's at ``order * (1 -+ 1/ratio)``.
    """

    order: float
    amplitude: float
    phase: float = 0.0
    port: str = "circular_spline"

    def __post_init__(self) -> None:
        finite(self, "kinematic_error")
        require(self.order > 0, "kinematic_error.order", "> 0", self.order)
        require(self.amplitude >= 0, "kinematic_error.amplitude", ">= 0 rad", self.amplitude)
        require(self.port in GROUNDED, "kinematic_error.port", f"one of {GROUNDED}", self.port)


@dataclass(frozen=True)
class KinematicError:
    """Kinematic error as a harmonic series in WG angle (output rad)."""

    harmonics: tuple[Harmonic, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "harmonics", tuple(
            h if isinstance(h, Harmonic) else Harmonic(**h) for h in self.harmonics))
        require(len(self.harmonics) <= MAX_HARMONICS, "kinematic_error.harmonics",
                f"at most {MAX_HARMONICS}", len(self.harmonics))


@dataclass(frozen=True)
class Load:
    """What the output drives.

    Attributes:
        inertia: output-side inertia (output port + load), kg m^2 (> 0).
        torque: constant external torque opposing positive motion, N m.
        gravity: m g l of an arm, N m; adds ``gravity * sin(output_angle)``.
    """

    inertia: float
    torque: float = 0.0
    gravity: float = 0.0

    def __post_init__(self) -> None:
        finite(self, "load")
        require(self.inertia > 0, "load.inertia", "> 0 kg m^2", self.inertia)


@dataclass(frozen=True)
class Amplifier:
    """Current amplifier (Tuttle App. C).

    Attributes:
        current_limit: I_max, A (> 0); commands are clipped to +-I_max.
        voltage_limit: supply V, V (> 0); current in
            [(-V - K_b w)/R, (V - K_b w)/R].
        bandwidth: current-loop bandwidth, Hz (> 0; first order).
    """

    current_limit: float
    voltage_limit: float
    bandwidth: float = 1000.0

    def __post_init__(self) -> None:
        finite(self, "amplifier")
        require(self.current_limit > 0, "amplifier.current_limit", "> 0 A", self.current_limit)
        require(self.voltage_limit > 0, "amplifier.voltage_limit", "> 0 V", self.voltage_limit)
        require(self.bandwidth > 0, "amplifier.bandwidth", "> 0 Hz", self.bandwidth)


@dataclass(frozen=True)
class Sensors:
    """Encoders and torque sensor.

    Attributes:
        motor_counts: input encoder counts per WG revolution after decoding (>= 1).
        output_counts: output encoder counts per output revolution (>= 1).
        torque_sensor: whether a flexspline torque sensor is fitted.
        torque_noise: torque-sensor noise standard deviation, N m (>= 0).
        current_noise: current-measurement noise standard deviation, A (>= 0).
        delay: samples of measurement delay, 0 or 1.
    """

    motor_counts: int = 4096
    output_counts: int = 80000
    torque_sensor: bool = True
    torque_noise: float = 0.0
    current_noise: float = 0.0
    delay: int = 0

    def __post_init__(self) -> None:
        finite(self, "sensors")
        require(int(self.motor_counts) == self.motor_counts and self.motor_counts >= 1,
                "sensors.motor_counts", "a whole number >= 1", self.motor_counts)
        require(int(self.output_counts) == self.output_counts and self.output_counts >= 1,
                "sensors.output_counts", "a whole number >= 1", self.output_counts)
        require(self.torque_noise >= 0, "sensors.torque_noise", ">= 0 N m", self.torque_noise)
        require(self.current_noise >= 0, "sensors.current_noise", ">= 0 A", self.current_noise)
        require(self.delay in (0, 1), "sensors.delay", "0 or 1 samples", self.delay)


@dataclass(frozen=True)
class Integration:
    """Fixed-step integration.

    Attributes:
        ctrl_dt: control (sample) period, s (> 0).
        n_substeps: physics substeps per control period (>= 1).
    """

    ctrl_dt: float = 1e-3
    n_substeps: int = 10

    def __post_init__(self) -> None:
        finite(self, "integration")
        require(self.ctrl_dt > 0, "integration.ctrl_dt", "> 0 s", self.ctrl_dt)
        require(int(self.n_substeps) == self.n_substeps and self.n_substeps >= 1,
                "integration.n_substeps", "a whole number >= 1", self.n_substeps)

    @property
    def dt(self) -> float:
        """Substep, s."""
        return self.ctrl_dt / self.n_substeps


PARTS: dict[str, type] = {
    "motor": Motor,
    "transmission": Transmission,
    "compliance": Compliance,
    "hysteresis": Hysteresis,
    "friction": Friction,
    "kinematic_error": KinematicError,
    "load": Load,
    "amplifier": Amplifier,
    "sensors": Sensors,
    "integration": Integration,
}
