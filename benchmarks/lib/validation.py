"""Validation experiments that reproduce the papers' figures.

Ledda et al. 2004, Sec. 6.1 / Figure 11: ten targets of different luminance
on a dim background; the observer was light-adapted to a white field, the
light goes off, and we record the smallest target luminance that can be told
from the background at each instant of dark adaptation.

"Told from the background" is judged on the display, by the display viewer
the operator assumes (Sec. 4.4): adapted to the display adaptation level
L_d, so a luminance difference is visible when it reaches a Weber fraction
of L_d (2%, a textbook photopic Weber fraction):
    |L_target - L_background| >= 0.02 L_d    (display cd/m^2).

Run ``python -m benchmarks.lib.validation docs/ledda04_fig11.png`` to redraw the
figure shipped in docs/.
"""

from __future__ import annotations

import sys

import numpy as np

#: Figure 11 set-up (our choices; the paper gives none of the numbers).
BACKGROUND_CD = 0.003          # dim background, cd/m^2 (scotopic)
TARGETS_CD = np.logspace(-2.45, 0.7, 22)  # 0.0035 .. 5 cd/m^2
PREADAPT_CD = 200.0            # the white field, cd/m^2
CELL, TARGET = 16, 6           # px: each target is TARGET^2 in a CELL^2 tile


def target_scene(background: float = BACKGROUND_CD, targets=TARGETS_CD) -> np.ndarray:
    """Grey targets side by side on a grey background, cd/m^2 (H x W x 3)."""
    n = len(targets)
    img = np.full((CELL, CELL * n, 3), background, np.float32)
    a = (CELL - TARGET) // 2
    for k, L in enumerate(targets):
        img[a:a + TARGET, k * CELL + a:k * CELL + a + TARGET] = L
    return img


WEBER = 0.02


def visible_targets(out: np.ndarray, n: int, min_step: float) -> np.ndarray:
    """Which of the n targets differ from their background by >= ``min_step``
    (display-linear, green channel = luminance of a grey)."""
    g = np.asarray(out[..., 1], np.float64)
    c = CELL // 2
    tgt = g[c, [k * CELL + c for k in range(n)]]
    bg = g[1, [k * CELL + 1 for k in range(n)]]
    return np.abs(tgt - bg) >= min_step


def dark_adaptation_thresholds(preadapt_seconds: float, times_s, operator: str = "ledda04",
                               backend: str = "opencl", preadapt_cd: float = PREADAPT_CD,
                               background: float = BACKGROUND_CD, targets=TARGETS_CD,
                               options: dict | None = None) -> np.ndarray:
    """Minimum visible target luminance (cd/m^2; inf when none) at each time after
    the switch from ``preadapt_cd`` (held ``preadapt_seconds``; E = L x t, Eq. 16)."""
    from ocl_tonemap.pipeline import Tonemapper
    scene = target_scene(background, targets)
    tm = Tonemapper(operator, backend, preadapt=(preadapt_cd, preadapt_seconds), options=options,
                    model="none")
    tm.process(scene, time_s=0.0)
    L_d = tm.op.settings.display_adapt_cd or 0.4 * tm.display.white_cd
    min_step = WEBER * L_d / tm.display.unit_cd
    out = []
    t_now = 0.0
    for t in times_s:
        if t > t_now:
            tm.process(scene, time_s=float(t))
            t_now = float(t)
        vis = visible_targets(tm.last_output, len(targets), min_step)
        out.append(float(np.min(np.asarray(targets)[vis])) if vis.any() else np.inf)
    return np.array(out)


def plot_fig11(path: str, seconds=(5.0, 30.0, 120.0), backend: str = "opencl") -> dict:
    """Draw the Figure 11 trend for several pre-adaptation durations; returns the data."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    times = np.geomspace(0.5, 45 * 60.0, 120)
    data = {}
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for s in seconds:
        th = dark_adaptation_thresholds(s, times, backend=backend)
        data[s] = th
        E = PREADAPT_CD * s
        y = np.where(np.isfinite(th), th, np.nan)
        ax.step(times, y, where="post",
                label=f"{PREADAPT_CD:g} cd/m² for {s:g} s (E = {E:g} cd/m²·s)")
    ax.set_yscale("log")
    ax.set_xscale("log")
    ticks = [1, 10, 60, 600, 2400]
    ax.set_xticks(ticks, ["1 s", "10 s", "1 min", "10 min", "40 min"])
    ax.set_xlabel("time in the dark (log scale)")
    ax.set_ylabel("minimum visible target luminance (cd/m²)")
    ax.set_title("ledda04: dark adaptation thresholds (trend of Ledda et al. 2004, Fig. 11)")
    ax.axhline(BACKGROUND_CD, color="0.6", lw=0.8, ls=":")
    ax.text(1.0, BACKGROUND_CD * 1.15, "background", color="0.4", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return {"times_s": times, "thresholds": data}


if __name__ == "__main__":
    plot_fig11(sys.argv[1] if len(sys.argv) > 1 else "ledda04_fig11.png")
