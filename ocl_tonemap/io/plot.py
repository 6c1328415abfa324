"""Plots like the graphs under Pattanaik 2000, Figure 7.

Top: adaptation goal and state over time (log10 cd/m^2; the dashed verticals mark
the frames of the mapping curves, in their colours) and the bleaching factors.
Bottom: the scene-to-display mapping of neutral luminances at chosen frames (log10
scene cd/m^2 -> log10 display cd/m^2), from the float64
reference of the operator with each frame's state.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..base import safeio
from ..mechanisms.planner import mechanisms
from ..models.ferwerda1996 import log_threshold_rod
from ..effects.visibility import trace

#: The PNG text key that holds each panel's legend (``{panel: [label, ...]}``): what
#: the plot shows, readable without looking at it.
LEGENDS_KEY = "ocltm:legends"



def mapping_curve(op, state, display, L: np.ndarray) -> np.ndarray | None:
    """Display luminance (cd/m^2) of neutral scene luminances ``L`` for one state
    of an operator (``op``: the operator instance), None where there is no single
    curve (local adaptation)."""
    out = op.plot_curves(state, L)
    return None if out is None else display.from_signal(out[:, 1])


def default_plot_frames(infos, count: int = 6) -> list[int]:
    """Indices where the goal changes most, plus first and last."""
    if len(infos) <= count:
        return list(range(len(infos)))
    g = np.log10(np.maximum([i.G_cone for i in infos], 1e-6))
    jumps = np.argsort(-np.abs(np.diff(g)))[: count // 2]
    picks = {0, len(infos) - 1}
    for j in jumps:
        picks.add(min(int(j) + 1, len(infos) - 1))
        picks.add(min(int(j) + 8, len(infos) - 1))
    return sorted(picks)[:count]


def adapted_levels(tm, infos) -> tuple | None:
    """The adapted cone and rod levels over the shot, cd/m^2, where the state holds
    them in other terms (durand00: the filtered inverse thresholds 1/eps_C, 1/eps_R;
    its ``L_wa``, ``L_waR`` are the frame's goals): the luminances whose Eq. 2 and
    Eq. 1 thresholds they are (``observer_level``; the rods' Eq. 1 inverted on its
    rising branch); None for states that hold their levels (``A_cone``) or none."""
    values = infos[0].state.values
    if "A_cone" in values or "inv_eps_cone" not in values or tm.op.observer_per_pixel:
        return None
    cone = np.array([tm.op.observer_level(tm.op.observer_of(i.state)) for i in infos])
    x = np.linspace(-3.94, 8.0, 4000)          # log10 L_aR: Eq. 1 beyond its flat foot
    y = np.maximum.accumulate(log_threshold_rod(10.0 ** x))
    le = -np.log10(np.maximum([i.state.values["inv_eps_rod"] for i in infos], 1e-300))
    return cone, 10.0 ** np.interp(le, y, x)


def plot_adaptation(path: str, infos, tm, frames: list[int] | None = None) -> dict:
    """The adaptation plot (the module's), written to ``path``; returns each panel's
    legend, ``{panel: [label, ...]}``, also kept in a PNG's text (:data:`LEGENDS_KEY`)."""
    plt = _pyplot()
    if not infos:
        raise RuntimeError("nothing to plot")
    t = np.array([i.time_s for i in infos])
    val = lambda k: np.array([i.state.values[k] for i in infos])  # noqa: E731
    lg = lambda x: np.log10(np.maximum(x, 1e-7))  # noqa: E731
    plans = [i.plan.get("weights") for i in infos if i.plan]
    target = [i for i in infos if getattr(i, "visibility", None)]
    n = 3 + bool(plans) + bool(target)
    fig, axes = plt.subplots(n, 1, figsize=(9, 10 + 2 * (n - 3)),
                             gridspec_kw={"height_ratios": [2, 1, 2, 1, 1][:n]})
    if plans:
        _plot_plan(axes[3], infos)
    if target:
        _plot_target(axes[n - 1], target)
    ax = axes[0]
    ax.plot(t, lg([i.G_cone for i in infos]), "k:", label="G_cone (goal)")
    ax.plot(t, lg([i.G_rod for i in infos]), "b:", label="G_rod (goal, scotopic)")
    if "A_cone" in infos[0].state.values:
        ax.plot(t, lg(val("A_cone")), "k-", label="A_cone")
        ax.plot(t, lg(val("A_rod")), "b-", label="A_rod")
    levels = adapted_levels(tm, infos)
    if levels is not None:
        ax.plot(t, lg(levels[0]), "k-", label="L_a cone (adapted: Eq. 2 at the filtered eps_C)")
        ax.plot(t, lg(levels[1]), "b-", label="L_a rod (adapted: Eq. 1 at the filtered eps_R)")
    ax.set_ylabel("log10 cd/m^2")
    ax.set_title(f"{tm.operator_name}: adaptation over time")
    ax.grid(alpha=0.3)
    ax = axes[1]
    pig = [(getattr(i.state, "extra", None) or {}).get("pigment") for i in infos]
    linear = all(isinstance(p, dict) for p in pig)
    if linear:          # the default mode's slow course: the shared pigment model's
        for k, c, lab in (("Bb_cone", "k", "cones' pigment bleached"),
                          ("Bb_rod", "b", "rods' pigment bleached")):
            ax.plot(t, [p[k] for p in pig], c, label=lab)
        ax.set_ylabel("fraction bleached\n(shared pigment course)")
        ax.set_ylim(0.0, 1.02)
    elif "B_cone" in infos[0].state.values:
        for k, c in (("B_cone", "k"), ("B_rod", "b")):
            ax.plot(t, val(k), c, label=k)
        ax.set_ylabel("bleaching B")
    elif "m_cone" in infos[0].params:                  # durand00: threshold-mapping factors
        for k, c in (("m_cone", "k"), ("m_rod", "b")):
            ax.plot(t, [i.params[k] for i in infos], c, label=k)
        ax.set_ylabel("scale factor m")
    else:
        ax.text(0.5, 0.5, "per-pixel state (see the state's .pixels.exr)", ha="center",
                transform=ax.transAxes)
    if ax.lines:
        if not linear:
            ax.set_yscale("log")
        ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3)
    ax = axes[2]
    picks = frames if frames else default_plot_frames(infos)
    L = np.logspace(-4, 6, 241)
    if tm.op.plot_curves(infos[0].state, L[:1]) is None:   # each pixel has its own curve
        picks = []
        ax.text(0.5, 0.5, "local operator: the mapping differs per pixel", ha="center",
                transform=ax.transAxes)
    for k, idx in enumerate(picks):
        idx = min(max(int(idx), 0), len(infos) - 1)
        inf = infos[idx]
        Ld = mapping_curve(tm.op, inf.state, tm.display, L)
        lab = f"t={inf.time_s:.2f}s" + (f" (frame {inf.frame})" if inf.frame is not None else "")
        line, = ax.plot(np.log10(L), lg(Ld), label=lab)
        # the curve's time above, in its colour
        axes[0].axvline(inf.time_s, color=line.get_color(), lw=0.9, ls="--", alpha=0.6,
                        label="frames of the mapping curves below, in their colours"
                        if k == 0 else None)
    ax.axhline(np.log10(tm.display.white_cd), color="0.6", ls="--", lw=0.8)
    ax.axhline(np.log10(tm.display.black_cd), color="0.6", ls="--", lw=0.8)
    ax.set_xlabel("scene luminance, log10 cd/m^2")
    ax.set_ylabel("display luminance, log10 cd/m^2")
    ax.set_title("scene-to-display mapping (dashed: display white and black)")
    if picks:
        ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    legends = {_panel(a, k): [x.get_text() for x in a.get_legend().get_texts()]
               for k, a in enumerate(axes) if a.get_legend() is not None}
    save_figure(fig, path, {LEGENDS_KEY: json.dumps(legends)})
    return legends


def _panel(ax, k: int) -> str:
    """A panel's name: its title without the operator's name or what follows "(" or
    ":" ("adaptation over time", "scene-to-display mapping"), else its y label."""
    title = ax.get_title()
    if title.endswith("adaptation over time"):
        return "adaptation over time"
    return title.split(" (")[0].split(":")[0] or ax.get_ylabel() or f"panel {k + 1}"


def _plot_target(ax, infos) -> None:
    """VL of the tracked target over the shot (``run --target``), threshold marked."""
    t = [i.time_s for i in infos]
    v0 = infos[0].visibility
    ax.plot(t, [max(i.visibility["VL"], 1e-3) for i in infos], "k-",
            label=f"VL at ({v0['x']:g}, {v0['y']:g}), {v0['size_arcmin']:g} arcmin")
    ax.axhline(1.0, color="r", ls="--", lw=1, label="threshold (VL 1)")
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("visibility level")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3, which="both")


def _plot_plan(ax, infos, model: str | None = None) -> None:
    """The mechanism plan's weights over time (``mechanisms/``), one line each,
    offset a little so that lines on top of each other stay visible; the title says
    what the plan did over the shot (:func:`plan_summary`)."""
    rows = [(i.time_s, i.plan["weights"]) for i in infos if i.plan]
    t = np.array([r[0] for r in rows])
    present = [m for m in mechanisms() if any(m in w for _, w in rows)]
    for k, m in enumerate(present):
        w = np.array([r[1].get(m, np.nan) for r in rows])
        ax.step(t, w + 0.02 * k, where="post", label=m)
    ax.set_ylim(-0.1, 1.25)
    ax.set_ylabel("weight")
    ax.set_xlabel("time (s)")
    ax.set_title(plan_title([r[1] for r in rows], model), fontsize=9)
    ax.legend(loc="center right", fontsize=7, ncol=2)
    ax.grid(alpha=0.3)


def plan_summary(weights: list[dict]) -> dict:
    """What a shot's mechanism plan did, from its frames' weights (mechanism -> 0..1,
    in frame order): ``{"applied": [...], "skipped": [...], "partial": [...],
    "switched": {mechanism: (frames on, frames, changes)}}`` -- applied: weight 1 on
    every frame; skipped: 0 on every frame; partial: one weight between 0 and 1 on
    every frame; switched: the weight changed over the shot (on: weight above 0)."""
    order = [m for m in mechanisms() if any(m in w for w in weights)]
    order += sorted({m for w in weights for m in w} - set(order))
    out = {"applied": [], "skipped": [], "partial": [], "switched": {}}
    for m in order:
        vals = [float(w[m]) for w in weights if m in w]
        if len(set(vals)) > 1:
            changes = sum(1 for a, b in zip(vals, vals[1:]) if a != b)
            out["switched"][m] = (sum(1 for v in vals if v > 0), len(vals), changes)
        elif vals[0] >= 1.0:
            out["applied"].append(m)
        elif vals[0] <= 0.0:
            out["skipped"].append(m)
        else:
            out["partial"].append(f"{m} {vals[0]:g}")
    return out


def plan_title(weights: list[dict], model: str | None = None) -> str:
    """The plan's title: what it applied, skipped and switched on and off over the
    shot (:func:`plan_summary`), wrapped to the plot's width."""
    import textwrap
    s = plan_summary(weights)
    parts = []
    if s["applied"]:
        parts.append("applied throughout: " + ", ".join(s["applied"]))
    if s["partial"]:
        parts.append("in part throughout: " + ", ".join(s["partial"]))
    if s["switched"]:
        parts.append("switched on/off: " + ", ".join(
            f"{m} (on in {on} of {n} frames, {c} change{'s' if c != 1 else ''})"
            for m, (on, n, c) in s["switched"].items()))
    if s["skipped"]:
        parts.append("skipped throughout: " + ", ".join(s["skipped"]))
    head = f"mechanism plan (--model {model})" if model else "mechanism plan"
    n = len(weights)
    text = f"{head} over {n} frame{'s' if n != 1 else ''}: " + ("; ".join(parts) or "empty")
    return "\n".join(textwrap.wrap(text, 110))


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise RuntimeError("--plot needs matplotlib: pip install 'ocl-tonemap[plot]'") from exc
    return plt


def save_figure(fig, path: str, text: dict | None = None) -> None:
    """Write a figure through a temporary file, verified (safeio); ``text``: a PNG's
    text entries (other formats keep only their standard keys)."""
    import matplotlib.pyplot as plt
    tmp = safeio.temp_path(path)
    try:
        safeio.claim_temp(tmp, path)
    except safeio.WriteFailed:
        plt.close(fig)
        raise
    try:
        fmt = os.path.splitext(path)[1][1:].lower() or "png"
        fig.savefig(tmp, dpi=110, format=fmt, metadata=text if text and fmt == "png" else None)
        safeio.commit(tmp, path)
    except OSError as exc:
        raise safeio.WriteFailed(path, safeio.reason(exc), exc.errno) from None
    finally:
        safeio.remove(tmp)
        plt.close(fig)


def plot_visibility_step(path: str, ops, L_from: float, seconds, L_s: float, view,
                         polarity: str = "positive", t_max: float = 30.0,
                         L_veil: float = 0.0) -> None:
    """dL_th (Adrian 1989 x each operator's transient factor) over the seconds after a
    step of the surround from ``L_from`` to ``L_s`` (with the veil ``L_veil`` over it:
    L_b = L_s + Lveil, the run's symbols); ``ops``: an operator or a list of them."""
    plt = _pyplot()
    ops = ops if isinstance(ops, (list, tuple)) else [ops]
    t = np.concatenate([[0.0], np.logspace(-2, np.log10(max(t_max, 0.02)), 160)])
    fig, ax = plt.subplots(figsize=(8, 5))
    for op in ops:
        pts = trace(op, L_from, seconds, L_s, t, view, polarity, L_veil=L_veil)
        ax.plot(t[1:], [p.dL_th for p in pts[1:]], label=op.name)
    steady = float(view.steady(L_s + L_veil, polarity))
    ax.axhline(steady, color="0.4", ls="--", lw=1,
               label=f"steady at L_b {L_s + L_veil:g} cd/m^2" +
               (f" (L_s {L_s:g} + Lveil {L_veil:g})" if L_veil else ""))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds after the step")
    ax.set_ylabel("threshold dL_th, cd/m^2")
    pre = "fully" if seconds is None else f"{seconds:g} s"
    ax.set_title(f"L_s {L_from:g} -> {L_s:g} cd/m^2 (adapted {pre}); {view.size_arcmin:g}', "
                 f"{view.age:g} y, t_obs {view.time_s:g} s, {polarity}")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
