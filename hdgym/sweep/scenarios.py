"""Scenario registry: name → ``function(params, job) → {metric: float}``.

A scenario runs one job on one (possibly randomized) drive and returns flat
metrics (SI units, the unit in the docstring). It draws randomness only from
``job.run_rng()`` / ``job.run_seed()`` so a job is reproducible from its
inputs. Where scenarios come from:

* built-in open-loop scenarios that need only the simulator
  (``current_steps``, ``locked_random``);
* the packages built on hdgym, through the entry-point group
  ``hdgym.sweep_scenarios`` (:mod:`hdgym.plugins`): ``controllers`` adds
  ``controllers:tracking``, ``controllers:load_step`` and
  ``controllers:point_to_point`` (:mod:`controllers.sweep`, run once per
  ``[[controllers]]`` config through :func:`register_controller_scenario`),
  ``agents`` adds ``rl_train`` (:mod:`agents.sweep`, once per
  ``[[agents]]`` config). hdgym imports neither;
* ``package.module:function`` -- any importable function ``(params, job) ->
  metrics``; imported lazily in the workers, so it works on a process pool
  and on Ray nodes (a function registered only in ``__main__`` would not);
* scenarios registered with :func:`register` (in-process, or in a module the
  workers import).

Register your own::

    from hdgym.sweep.scenarios import register

    @register("my_scenario", options={"duration": 1.0})
    def my_scenario(params, job):
        ...
        return {"metric": value}
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hdgym import plugins
from hdgym.params import JointParams

__all__ = ["OptionError", "Scenario", "check_options", "get_scenario", "register",
           "register_controller_scenario", "scenario_names"]

ScenarioFn = Callable[[JointParams, Any], Mapping[str, float]]


class OptionError(ValueError):
    """A bad scenario option; ``key`` names it (for the spec's line number)."""

    def __init__(self, msg: str, key: str | None = None):
        super().__init__(msg)
        self.key = key


@dataclass(frozen=True)
class Scenario:
    """A registered scenario.

    Attributes:
        name: the name specs use.
        fn: ``fn(params, job) -> {metric: float}``.
        needs: ``None`` (open loop), ``"controller"`` (run once per
            ``[[controllers]]``) or ``"agent"`` (once per ``[[agents]]``).
        options: allowed option names and their defaults (``None``: any
            option is passed through unchecked).
        check_slot: validates one controller/agent config before the sweep.
        task_digest: ``task_digest(slot) -> str`` names what a job's result
            depends on beyond the drive's physics (for ``rl_train``: the env's
            task code and the agent config), hashed into the job id so a
            resumed sweep reruns its jobs when that changes; ``None``: nothing.
    """

    name: str
    fn: ScenarioFn
    needs: str | None = None
    options: Mapping[str, Any] | None = None
    check_slot: Callable[[Mapping[str, Any]], None] | None = None
    doc: str = ""
    task_digest: Callable[[Mapping[str, Any] | None], str] | None = None

    def option(self, job: Any, key: str) -> Any:
        opts = self.options or {}
        return job.options.get(key, opts.get(key))


_REGISTRY: dict[str, Scenario] = {}


def register(name: str, *, needs: str | None = None, options: Mapping[str, Any] | None = None,
             check_slot: Callable[[Mapping[str, Any]], None] | None = None,
             task_digest: Callable[[Mapping[str, Any] | None], str] | None = None
             ) -> Callable[[ScenarioFn], ScenarioFn]:
    """Decorator: register ``fn(params, job) -> metrics`` under ``name``
    (the keywords are :class:`Scenario`'s attributes)."""
    if needs not in (None, "controller", "agent"):
        raise ValueError(f"needs must be None, 'controller' or 'agent', got {needs!r}")

    def deco(fn: ScenarioFn) -> ScenarioFn:
        _REGISTRY[name] = Scenario(name, fn, needs, options, check_slot,
                                   (fn.__doc__ or "").strip().splitlines()[0] if fn.__doc__
                                   else "", task_digest)
        return fn

    return deco


def scenario_names() -> list[str]:
    """Registered names, those of the installed packages' entry points included."""
    plugins.load(plugins.SWEEP_SCENARIOS)
    return sorted(_REGISTRY)


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name`` (raises ValueError if unknown)."""
    if name in _REGISTRY:
        return _REGISTRY[name]
    failed = plugins.load(plugins.SWEEP_SCENARIOS)
    if name in _REGISTRY:
        return _REGISTRY[name]
    why = "".join(f"; entry point {ep!r}: {msg}" for ep, msg in failed.items())
    if ":" in name:
        return _imported_scenario(name, why)
    raise ValueError(f"unknown scenario {name!r}{why}")


def _imported_scenario(name: str, why: str = "") -> Scenario:
    """``package.module:function`` -- a scenario any worker (pool, Ray node) can import.

    The function takes ``(params, job)`` and returns metrics; its optional
    attribute ``needs`` (``"controller"``/``"agent"``) says what it runs per.
    A function registered with :func:`register` in that module is used as
    registered.
    """
    import importlib

    mod_name, _, fn_name = name.partition(":")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"unknown scenario {name!r} (cannot import {mod_name!r}: {exc}){why}"
                         ) from None
    fn = getattr(mod, fn_name, None)
    if not callable(fn):
        raise ValueError(f"unknown scenario {name!r} ({mod_name} has no function {fn_name!r})"
                         f"{why}")
    for sc in _REGISTRY.values():
        if sc.fn is fn:
            return Scenario(name, sc.fn, sc.needs, sc.options, sc.check_slot, sc.doc,
                            sc.task_digest)
    return Scenario(name, fn, getattr(fn, "needs", None), None, None,
                    (fn.__doc__ or "").strip())


def check_options(name: str, options: Mapping[str, Any]) -> None:
    """Raise :class:`OptionError` for unknown options or options of the wrong type."""
    sc = get_scenario(name)
    if sc.options is None:
        return
    for key, value in options.items():
        if key not in sc.options:
            raise OptionError(f"unknown option {key!r} for scenario {name!r}; known: "
                              f"{', '.join(sorted(sc.options)) or '(none)'}", key)
        default = sc.options[key]
        if isinstance(default, bool) != isinstance(value, bool):
            raise OptionError(f"option {key!r} of {name!r} must be "
                              f"{type(default).__name__}, got {value!r}", key)
        if isinstance(default, (int, float)) and not isinstance(value, (int, float)):
            raise OptionError(f"option {key!r} of {name!r} must be a number, got {value!r}", key)
        if isinstance(default, list) or (default is None and isinstance(value, list)):
            if not isinstance(value, list) or not value or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                raise OptionError(f"option {key!r} of {name!r} must be a non-empty list of "
                                  f"numbers, got {value!r}", key)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and key in (
                "duration", "quick_duration", "cutoff_hz", "amplitude") and value <= 0:
            raise OptionError(f"option {key!r} of {name!r} must be > 0, got {value!r}", key)


# ----------------------------------------------------------- open-loop, built in


def _duration(sc: Scenario, job: Any) -> float:
    return float(sc.option(job, "quick_duration") if job.quick else sc.option(job, "duration"))


@register("current_steps", options={"currents": None, "fractions": [0.1, 0.2, 0.4],
                                    "duration": 1.0, "quick_duration": 0.3, "settle": 0.5})
def current_steps(params: JointParams, job: Any) -> dict[str, float]:
    """Mean motor (input) speed, rad/s, in the last part of a current step, per step current.

    Free output, true states. ``currents`` (A) or ``fractions`` of the
    amplifier current limit; metrics ``speed_at_<I>A`` (or
    ``speed_at_<f>Imax``) average the motor speed over the last ``settle``
    fraction of ``duration`` s.
    """
    from hdgym.sim import Simulator

    sc = get_scenario("current_steps")
    duration = _duration(sc, job)
    settle = float(sc.option(job, "settle"))
    currents = sc.option(job, "currents")
    if currents is not None:
        steps = [(float(i), f"speed_at_{float(i):g}A") for i in currents]
    else:
        steps = [(f * params.amplifier.current_limit, f"speed_at_{float(f):g}Imax")
                 for f in sc.option(job, "fractions")]
    sim = Simulator(params, sensors=False)
    seed = job.run_seed()
    out: dict[str, float] = {}
    for amps, name in steps:
        rec = sim.run(np.full(sim.time(duration).size, amps), seed=seed)
        w = rec.columns["motor_velocity"]
        k0 = min(int(len(w) * (1.0 - settle)), len(w) - 1)
        out[name] = float(np.mean(w[k0:]))
    return out


@register("locked_random", options={"amplitude": 0.3, "cutoff_hz": 20.0, "duration": 1.0,
                                    "quick_duration": 0.3})
def locked_random(params: JointParams, job: Any) -> dict[str, float]:
    """Locked output, band-limited random current: torque and current RMS.

    ``amplitude`` is a fraction of the amplifier current limit, ``cutoff_hz``
    the band edge (Hz). Metrics: ``torque_rms`` (N m, flexspline torque),
    ``torque_peak`` (N m), ``current_rms`` (A), ``torque_per_amp`` (N m/A,
    RMS ratio: torque constant x ratio less friction and windup losses).
    """
    from hdgym.sim import Simulator

    sc = get_scenario("locked_random")
    duration = _duration(sc, job)
    amps = float(sc.option(job, "amplitude")) * params.amplifier.current_limit
    cutoff = float(sc.option(job, "cutoff_hz"))
    sim = Simulator(params, locked_output=True, sensors=False)
    rec = sim.run(f"random:{amps!r}:{cutoff!r}", duration, seed=job.run_seed())
    tq = rec.columns["output_torque"]
    cur = rec.columns["motor_current"]
    t_rms = float(np.sqrt(np.mean(tq**2)))
    c_rms = float(np.sqrt(np.mean(cur**2)))
    return {"torque_rms": t_rms, "torque_peak": float(np.max(np.abs(tq))), "current_rms": c_rms,
            "torque_per_amp": t_rms / c_rms if c_rms > 0 else float("nan")}


# ------------------------------------------------ one run per controller config
#
# A controller scenario runs one ``[[controllers]]`` config of the spec per
# job. Its function is called with the keyword arguments it accepts of:
# ``params`` (the job's randomized drive), ``nominal`` (the preset at the grid
# point, no spreads: what a controller is designed on), ``controller`` (the
# config), ``seed``, ``rng``, ``quick``, ``options`` and each scenario option
# by name. Its keyword parameters other than those are the scenario's options
# (defaults checked by type); a function taking ``**kwargs`` gets any option
# unchecked.

_PASSED = ("params", "nominal", "controller", "seed", "rng", "quick", "options")


def _call(fn: Callable[..., Any], kwargs: Mapping[str, Any]) -> Any:
    """Call ``fn`` with the keyword arguments it accepts."""
    sig = inspect.signature(fn)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return fn(**kwargs)
    return fn(**{k: v for k, v in kwargs.items() if k in sig.parameters})


def _signature_options(fn: Callable[..., Any]) -> dict[str, Any] | None:
    """Options of a controller scenario: its keyword parameters with defaults, not passed."""
    sig = inspect.signature(fn)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return None
    return {n: p.default for n, p in sig.parameters.items()
            if n not in _PASSED and p.default is not inspect.Parameter.empty
            and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def _nominal(job: Any) -> JointParams:
    p = job.base_params()
    for path in sorted(job.grid):
        v = job.grid[path]
        p = p.set(path, tuple(v) if isinstance(v, list) else v)
    return p


def register_controller_scenario(name: str, fn: Callable[..., Mapping[str, float]],
                                 check_config: Callable[[dict[str, Any]], None] | None = None
                                 ) -> Scenario:
    """Register ``fn`` under ``name``, run once per ``[[controllers]]`` config.

    ``fn`` takes the keyword arguments described above and returns metrics;
    ``check_config(config)`` raises ValueError for a bad controller config
    before the sweep starts (its ``key`` attribute, if any, names the
    offending key for the spec's line number).
    """
    options = _signature_options(fn)

    def run(params: JointParams, job: Any) -> Mapping[str, float]:
        config = dict(job.controller or {})
        opts = {**(options or {}), **dict(job.options)}
        metrics = _call(fn, {"params": params, "nominal": _nominal(job), "controller": config,
                             "seed": job.run_seed(), "rng": job.run_rng(), "quick": job.quick,
                             "options": dict(job.options), **opts})
        return {k: float(v) for k, v in dict(metrics).items()}

    run.__doc__ = fn.__doc__  # the summary quotes it

    def check_slot(config: Mapping[str, Any]) -> None:
        if check_config is not None:
            check_config(dict(config))

    sc = Scenario(name, run, needs="controller", options=options, check_slot=check_slot,
                  doc=(fn.__doc__ or "").strip())
    _REGISTRY[name] = sc
    return sc
