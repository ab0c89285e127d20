"""Write a diagnosis as ``report.json`` + ``report.md`` + figures, atomically.

Everything is written into a temporary directory beside ``out`` and renamed
into place at the end, so an error never leaves a half-written report (an
existing report at ``out`` is replaced only when the new one is complete).
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from hdgym.files import umask_mode

from . import friction_events as FE
from . import residuals as R
from .diagnosis import Diagnosis

FIGURES = {
    "residual_time": "residual against time, before and after (per channel)",
    "order_spectrum": "order spectrum of the residual in the WG angle, before and after",
    "loops": "torque (or motor angle) against torsion: measured, before, after",
    "nmse_steps": "NMSE after each step (training and validation)",
}


def _r(x: float, n: int = 4) -> float | None:
    if x is None or not math.isfinite(x):
        return None
    return float(f"{x:.{n}g}")


def _nm(d: dict[str, float] | None) -> dict[str, float | None] | None:
    return None if d is None else {k: _r(v) for k, v in d.items()}


def to_json(diag: Diagnosis, notes: list[str] | None = None) -> dict:
    """The report.json content (what ``hdgym diagnose`` writes beside report.md)."""
    steps = []
    for s in diag.steps:
        steps.append({
            "name": s.name,
            "evidence": {**s.evidence, "candidates": [
                {k: c.get(k) for k in ("name", "score", "signature_explained",
                                       "sensitivity_explained", "relative_improvement",
                                       "trial_nmse", "feature_explained",
                                       "feature_judgement")} for c in s.candidates]},
            "fitted_parameters": {k: _r(v, 6) for k, v in s.values.items()},
            "nmse_after": _r(s.nmse_validation["mean"] if s.nmse_validation else s.nmse["mean"]),
            "nmse_after_training": _nm(s.nmse),
            "nmse_after_validation": _nm(s.nmse_validation),
            "relative_improvement": _r(s.relative_improvement),
        })
    return {
        "record": diag.source,
        "validation_record": diag.validation_source,
        "mode": diag.mode,
        "channels": list(diag.channels),
        "base_effects": list(diag.base_effects),
        "missing_effects": diag.missing_effects,
        "nmse_before": _r(diag.nmse_before),
        "nmse_after": _r(diag.nmse_after),
        "nmse_on": "validation" if diag.nmse_after_validation else "training",
        "nmse_definition": "100/(n sigma^2) sum (y_hat - y)^2 per channel (seed 002), "
                           "mean over channels; before = base model fitted to the record",
        "nmse_given_model": _nm(diag.nmse_given),
        "nmse_before_training": _nm(diag.before.nmse),
        "nmse_after_training": _nm(diag.after.nmse),
        "nmse_before_validation": _nm(diag.nmse_before_validation),
        "nmse_after_validation": _nm(diag.nmse_after_validation),
        "fit_window_s": diag.fit_window,
        "nmse_record_before": _nm(diag.nmse_record_before),
        "nmse_record_after": _nm(diag.nmse_record_after),
        "base_fit": {k: _r(v, 6) for k, v in diag.before.values.items()},
        "final_fit": {k: _r(v, 6) for k, v in diag.after.values.items()},
        "steps": steps,
        "where": diag.where_before,
        "where_after": diag.where_after,
        "remaining_candidates": [
            {k: c.get(k) for k in ("name", "score", "signature_explained",
                                   "sensitivity_explained", "relative_improvement")}
            for c in diag.final_candidates],
        "untestable_effects": diag.untestable,
        "untestable_why": dict(diag.untestable_why),
        "outcome": diag.outcome,
        "horizon_s": diag.horizon,
        "noise_nmse": _nm(diag.noise),
        "floor_nmse": None if diag.floor is None else _r(diag.floor, 4),
        "next_experiments": list(diag.next_experiments),
        "friction_features": diag.friction_features,
        "unexplained_channels": dict(diag.unexplained_channels),
        "compare": diag.compare,
        "conclusion": diag.conclusion,
        "notes": list(notes or []),
        "seconds": _r(diag.seconds, 3),
        "figures": {f"{k}.png": v for k, v in FIGURES.items()},
    }


def _figures(diag: Diagnosis, d: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pr = diag.problem
    made = []
    before = pr.residuals(diag.before.params)
    after = pr.residuals(diag.after.params)
    t = np.asarray(pr.record.time)
    tm = t if pr.mask is None else t[pr.mask]
    # residual against time
    n = len(pr.names)
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.2 * n), sharex=True, squeeze=False)
    for ax, ch in zip(axes[:, 0], pr.names, strict=True):
        ax.plot(tm, before[ch], lw=0.8, label="before (base model fitted)")
        ax.plot(tm, after[ch], lw=0.8, label="after")
        ax.set_ylabel(f"{ch}\n[{R.CHANNEL_UNITS[ch]}]", fontsize=8)
    axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title("residual (model - measurement), filtered")
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(d / "residual_time.png", dpi=90)
    plt.close(fig)
    made.append("residual_time.png")
    # order spectrum
    mctx = pr.masked_context()
    th, sp = mctx.theta_m, mctx.speed
    fig, ax = plt.subplots(figsize=(8, 3))
    drawn = False
    for ch in pr.names:
        for lab, res in (("before", before), ("after", after)):
            o, a = R.order_spectrum(res[ch] / math.sqrt(pr.sigma2[ch]), th, speed=sp)
            if o.size:
                ax.plot(o, a, lw=0.9, label=f"{ch} {lab}")
                drawn = True
    if drawn:
        ax.set_xlabel("order of the WG angle [cycles per WG revolution] (each direction "
                      "on its own, averaged)")
        ax.set_ylabel("amplitude / sigma of channel")
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "the WG turned less than two revolutions one way: no order spectrum",
                ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(d / "order_spectrum.png", dpi=90)
    plt.close(fig)
    made.append("order_spectrum.png")
    # loops
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    c = pr.context
    meas = pr.measured
    pb, pa = pr.predict(diag.before.params), pr.predict(diag.after.params)
    if pr.inverse:
        ang = np.degrees(np.mod(c.theta_m, 2 * math.pi))
        m = pr.mask
        sgn = np.sign(c.speed)
        y = "motor_current"
        for lab, arr, st in (("measured", meas[y], "."), ("before", pb[y], ","),
                             ("after", pa[y], ",")):
            ax.plot(ang[m], (arr * sgn)[m], st, ms=1.5, label=lab)
        ax.set_xlabel("WG (rotor) angle mod 360 [deg]")
        ax.set_ylabel("current x sign(speed) [A]")
        ax.set_title("friction current against rotor angle")
    elif c.torsion is not None:
        y = "output_torque" if "output_torque" in meas else pr.names[0]
        x = np.degrees(c.torsion)
        ax.plot(x, meas[y], lw=0.6, label="measured")
        ax.plot(x, pb[y], lw=0.6, label="before")
        ax.plot(x, pa[y], lw=0.6, label="after")
        ax.set_xlabel("torsion (from motor angle / ratio - output) [output deg]")
        ax.set_ylabel(f"{y} [{R.CHANNEL_UNITS[y]}]")
        ax.set_title("loops against torsion")
    else:
        y = pr.names[0]
        ax.plot(c.speed, meas[y], ".", ms=1, label="measured")
        ax.plot(c.speed, pb[y], ".", ms=1, label="before")
        ax.plot(c.speed, pa[y], ".", ms=1, label="after")
        ax.set_xlabel("motor speed [rad/s]")
        ax.set_ylabel(f"{y} [{R.CHANNEL_UNITS[y]}]")
        ax.set_title("no torsion measured: channel against speed")
    ax.legend(fontsize=8, markerscale=5)
    fig.tight_layout()
    fig.savefig(d / "loops.png", dpi=90)
    plt.close(fig)
    made.append("loops.png")
    # NMSE bars
    labels = ["base fitted"] + [f"+ {s.name}" for s in diag.steps]
    train = [diag.before.nmse["mean"]] + [s.nmse["mean"] for s in diag.steps]
    fig, ax = plt.subplots(figsize=(max(4, 1.6 * len(labels)), 3))
    xs = np.arange(len(labels))
    ax.bar(xs - 0.2, train, 0.4, label="training")
    if diag.nmse_before_validation:
        val = [diag.nmse_before_validation["mean"]] + [
            s.nmse_validation["mean"] for s in diag.steps]
        ax.bar(xs + 0.2, val, 0.4, label="validation")
    ax.set_xticks(xs, labels, fontsize=8)
    ax.set_ylabel("NMSE [%]")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(d / "nmse_steps.png", dpi=90)
    plt.close(fig)
    made.append("nmse_steps.png")
    return made


def _fmt_where(w: dict) -> list[str]:
    out = []
    if w.get("time_spans"):
        out.append("- time spans holding most of it: " + "; ".join(
            f"{s['t0']:.2f}-{s['t1']:.2f} s ({100 * s['share']:.0f} %)" for s in w["time_spans"]))
    if w.get("speed_bands"):
        out.append("- by |motor speed| [rad/s]: " + "; ".join(
            f"{b['lo']:.3g}-{b['hi']:.3g}: {100 * b['share']:.0f} %" for b in w["speed_bands"]))
    if w.get("orders"):
        out.append("- strongest orders of the WG angle: " + "; ".join(
            f"{o['order']:g} in {o['channel']} ({o['amplitude']:.3g} {o['unit']})"
            for o in w["orders"][:6]))
    if w.get("torsion_regions"):
        out.append("- by |torsion| [output rad]: " + "; ".join(
            f"{b['lo']:.3g}-{b['hi']:.3g}: {100 * b['share']:.0f} %"
            for b in w["torsion_regions"]))
    if w.get("channels"):
        out.append("- by channel: " + ", ".join(
            f"{k} {100 * v:.0f} %" for k, v in w["channels"].items()))
    return out


def to_markdown(js: dict, title: str | None = None, command: str | None = None) -> str:
    lines = [f"# {title or 'Discrepancy report'}", ""]
    if command:
        lines += [f"Generated by `{command}`.", ""]
    found = ", ".join(js["missing_effects"]) or "none"
    lines += [
        f"Record: `{js['record']}`" + (f"; validation: `{js['validation_record']}`"
                                       if js["validation_record"] else "") + ".",
        f"Comparison: {js['mode']} mode"
        + (f" (prediction horizon {js['horizon_s']:g} s)" if js.get("horizon_s") else "")
        + (" on the spring curve (motor angle over bins of the measured torque and its "
           "direction, one run)" if js.get("compare") == "spring" else
           " on the line channels (line amplitudes at orders of each run's own WG angle, "
           "window by window)" if js.get("compare") == "lines" else "")
        + f", channels {', '.join(js['channels'])}; base model "
        f"effects: {', '.join(js['base_effects']) or 'none'}.",
        "",
        f"**Outcome: {js.get('outcome') or '-'}. Missing effects, in the order found: "
        f"{found}.**",
        "",
        f"NMSE ({js['nmse_on']} record, mean over channels): {js['nmse_before']} % with the base "
        f"model fitted -> {js['nmse_after']} % after (measurement noise alone: "
        f"{(js.get('noise_nmse') or {}).get('mean')} %"
        + ("" if js.get("floor_nmse") is None else  # no floor for an inverse comparison
           f"; the final model on a record it made itself: {js['floor_nmse']} %")
        + f"). {js['conclusion']}.",
        "",
    ]
    if js.get("fit_window_s"):
        rb, ra = js["nmse_record_before"], js["nmse_record_after"]
        lines += [f"Fitted on the first {js['fit_window_s']:g} s of the record; on the whole "
                  f"record the NMSE goes from {rb['mean']} % to {ra['mean']} %.", ""]
    if js["steps"]:
        lines += ["## Steps", "", "| step | effect | evidence | NMSE after % | fitted parameters |",
                  "|---|---|---|---|---|"]
        for k, s in enumerate(js["steps"], 1):
            ev = s["evidence"]
            detail = ev.get("detail", {})
            orders = detail.get("orders")
            extra = ""
            if orders:
                top = sorted(orders.items(), key=lambda kv: -kv[1])[:3]
                extra = "; order lines " + ", ".join(f"{o} ({a:.2g})" for o, a in top)
            levels = [(side, v) for side, v in detail.items()
                      if isinstance(v, dict) and "static" in v]
            if levels:  # breakaway signature: static against running level per side
                extra += "; held while stuck vs running " + ", ".join(
                    f"{side} {v['static']:.3g} vs {v['running']:.3g} N m" for side, v in levels)
            evid = (f"linearized refit explains {100 * ev['sensitivity_explained']:.0f} %, "
                    f"signature ({ev['signature']}) {100 * ev['signature_explained']:.0f} %; "
                    f"trial refit cuts cost {100 * ev['relative_improvement']:.0f} %{extra}")
            pars = ", ".join(f"`{p}` = {v:.4g}" for p, v in s["fitted_parameters"].items())
            lines.append(f"| {k} | {s['name']} | {evid} | {s['nmse_after']} | {pars} |")
        lines.append("")
    lines += FE.markdown(js.get("friction_features"))
    lines += ["## Where the base model disagrees", ""] + _fmt_where(js["where"]) + [""]
    lines += ["## After", ""] + _fmt_where(js["where_after"]) + [""]
    if js["remaining_candidates"]:
        lines += ["## Candidates at the last step", "",
                  "| effect | linearized refit explains | signature explains | trial refit cut |",
                  "|---|---|---|---|"]
        for c in js["remaining_candidates"]:
            rel = c.get("relative_improvement")
            lines.append(f"| {c['name']} | {100 * c['sensitivity_explained']:.1f} % | "
                         f"{100 * c['signature_explained']:.1f} % | "
                         f"{'-' if rel is None else f'{100 * rel:.1f} %'} |")
        lines.append("")
    if js["untestable_effects"]:
        why = js.get("untestable_why", {})
        lines += ["## Not testable on this record", ""] + [
            f"- {n}: {why.get(n, '')}" for n in js["untestable_effects"]] + [""]
    if js.get("next_experiments"):
        lines += ["## Next experiment", "", "Records of these protocols would decide what this "
                  "one cannot:", ""] + [f"- `{c}`" for c in js["next_experiments"]] + [""]
    if js["notes"]:
        lines += ["## Notes", ""] + [f"- {n}" for n in js["notes"]] + [""]
    lines += ["## Figures", ""]
    for f, what in js["figures"].items():
        lines += [f"![{what}]({f})", "", f"*{f}: {what}.*", ""]
    return "\n".join(lines)


def write_report(diag: Diagnosis, out: Path, *, notes: list[str] | None = None,
                 title: str | None = None, command: str | None = None) -> dict:
    """Write ``out/report.json``, ``out/report.md`` and the figures; return the JSON dict."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))
    tmp.chmod(umask_mode(directory=True))  # mkdtemp's private 0700 would stay on the report
    try:
        js = to_json(diag, notes)
        _figures(diag, tmp)
        (tmp / "report.json").write_text(json.dumps(js, indent=1, default=_jsonable) + "\n")
        (tmp / "report.md").write_text(to_markdown(js, title, command))
        old = None
        if out.exists():
            old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.old-"))
            out.rename(old / "report")
        tmp.rename(out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return js


def _jsonable(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON: {type(x).__name__}")
