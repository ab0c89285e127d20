"""An RGB frame of one joint (matplotlib Agg, no window).

Two dials (WG angle, output angle with the reference when there is one),
bars for the flexspline torque (torsion) and the motor current, and text.
"""

from __future__ import annotations

import math

import numpy as np


def render_frame(state: np.ndarray, aux: np.ndarray, task: str, time: float,
                 torque_scale: float, current_limit: float, speed_scale: float,
                 width: int = 480, height: int = 360) -> np.ndarray:
    """Draw one frame; returns ``(height, width, 3)`` uint8.

    Args:
        state: true states in :data:`hdgym.envs.common.INFO_STATES` order.
        aux: the task's two extra values (reference and error, or target
            speed and torque oscillation).
        task: ``"tracking"`` or ``"resonance"``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    th_m, w_m, th_o, w_o, cur, tk = (float(v) for v in state)
    dpi = 100
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="white")
    canvas = FigureCanvasAgg(fig)

    def dial(ax, angles: list[tuple[float, str, str]], title: str) -> None:
        ax.set_xlim(-1.25, 1.25)
        ax.set_ylim(-1.25, 1.25)
        ax.set_aspect("equal")
        ax.axis("off")
        t = np.linspace(0, 2 * np.pi, 100)
        ax.plot(np.cos(t), np.sin(t), color="0.3", lw=1.5)
        for k in range(12):
            a = k * np.pi / 6
            ax.plot([0.9 * math.cos(a), math.cos(a)], [0.9 * math.sin(a), math.sin(a)],
                    color="0.5", lw=1)
        for ang, color, style in angles:
            if math.isfinite(ang):
                ax.plot([0, 0.95 * math.cos(ang)], [0, 0.95 * math.sin(ang)], color=color,
                        lw=3, ls=style)
        ax.set_title(title, fontsize=9)

    ax1 = fig.add_axes((0.02, 0.40, 0.46, 0.50))
    dial(ax1, [(th_m, "tab:red", "-")], f"WG angle {math.degrees(th_m) % 360:.1f}°")
    ax2 = fig.add_axes((0.52, 0.40, 0.46, 0.50))
    pointers = [(th_o, "tab:blue", "-")]
    if task == "tracking":
        pointers.append((float(aux[0]), "tab:green", "--"))
        title = f"output {math.degrees(th_o):.2f}° (reference dashed)"
    else:
        title = f"output {math.degrees(th_o) % 360:.1f}°"
    dial(ax2, pointers, title)

    bars = [("torsion T_k", tk / torque_scale, f"{tk:.1f} N m"),
            ("current", cur / current_limit, f"{cur:.2f} A")]
    if task == "resonance":
        bars.append(("WG speed", w_m / float(aux[0]),
                     f"{math.degrees(w_m):.0f} / {math.degrees(float(aux[0])):.0f} °/s"))
    else:
        bars.append(("error", float(aux[1]) / 1e-3 / 10.0,
                     f"{math.degrees(float(aux[1])) * 1e3:.1f} m°"))
    ax3 = fig.add_axes((0.2, 0.1, 0.42, 0.25))
    names = [b[0] for b in bars]
    vals = [float(np.clip(np.nan_to_num(b[1]), -1.5, 1.5)) for b in bars]
    colors = ["tab:purple", "tab:orange", "tab:green"]
    ax3.barh(range(len(bars)), vals, color=colors[:len(bars)])
    ax3.set_xlim(-1.5, 1.5)
    ax3.axvline(0, color="0.3", lw=0.8)
    ax3.set_yticks(range(len(bars)), names, fontsize=8)
    ax3.tick_params(axis="x", labelsize=7)
    ax3.invert_yaxis()
    for k, b in enumerate(bars):
        ax3.text(1.6, k, b[2], va="center", fontsize=8, clip_on=False)
    fig.text(0.01, 0.96, f"t = {time:.3f} s", fontsize=8)
    canvas.draw()
    frame = np.asarray(canvas.buffer_rgba())[..., :3]
    return np.ascontiguousarray(frame, dtype=np.uint8)
