"""Seconds as well as minutes (issue 66, item 4): a fixed target at a tunnel entrance lit
by CIE 88:2004's transition curve against a sudden step, and light adaptation on a
dark-adapted eye (Baker 1949), by each operator's own observer. One command:

    python -m benchmarks.tunnel_entrance [--out-dir DIR | --out FILE]

Writes tunnel_entrance.md and, beside it, tunnel_entrance.png into DIR (default
./benchmark-results; the committed table: ``--out-dir benchmarks/results``; the rule:
``benchmarks/lib/outdir.py``). The experiment: ``benchmarks/lib/human/tunnel.py``.
Pure float64, a few seconds.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

try:
    from benchmarks.lib.human import tunnel as T
    from benchmarks.lib.outdir import add_out_args, link, out_path
except ModuleNotFoundError:     # run as a file: its own folder is first on the path
    from lib.human import tunnel as T
    from lib.outdir import add_out_args, link, out_path

#: The seconds after the entrance the drive's table shows.
DRIVE_TABLE_S = (0.0, 1.0, 2.0, 3.0, 4.5, 6.0, 8.0, 12.0, 16.0, 21.2, 30.0, 40.0)
#: ... and after the sudden step.
STEP_TABLE_S = (0.0, 0.1, 0.2, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 30.0, 60.0)
#: "Near its threshold-zone value": the least VL on the curve and in the interior at
#: least this share of the entrance's; "some seconds": VL < 1 at least this long.
NEAR = 0.8
SOME_S = 1.0
BAKER_TABLE_S = (0.0, 0.01, 0.05, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0)


def _at(t_arr, v_arr, t):
    return float(v_arr[int(np.argmin(np.abs(np.asarray(t_arr) - t)))])


def curve_holds(d) -> bool:
    return d.vl_min_curve >= NEAR * d.VL_threshold_zone and d.vl_min_curve >= 1.0


def step_holds(d) -> bool:
    return d.step_below1_s >= SOME_S


def report(drives, onsets, failed, out: str) -> list[str]:
    D = T.threshold_zone_s()
    L = ["# The tunnel entrance and light adaptation (issue 66, item 4)", "",
         "`python -m benchmarks.tunnel_entrance`; the experiment: "
         "`benchmarks/lib/human/tunnel.py`; what it means: "
         f"[docs/validation.md]({link(out, 'docs/validation.md')}) (\"The tunnel entrance "
         "and light adaptation (issue 66)\").", "",
         "## A. A fixed target along CIE 88's transition curve and after a sudden step", "",
         f"Access zone L20 = {T.L20:g} cd/m^2, the driver adapted to it for good. "
         f"{T.SPEED_KMH:g} km/h, stopping distance {T.STOPPING_M:g} m: the threshold zone "
         f"lasts {D:.2f} s, at L_th = k L20 = {T.K_TH:g} x {T.L20:g} = {T.L_TH:g} cd/m^2 for "
         f"its first half, linear to {T.THRESHOLD_END:g} L_th over its second; then "
         f"L_tr = L_th (1.9 + t)^-1.4 (t from the transition zone's start) down to the "
         f"interior's {T.L_INTERIOR:g} cd/m^2, reached {T.transition_end_s():.1f} s into "
         f"the transition zone ({D + T.transition_end_s():.1f} s after the entrance). The "
         f"sudden step: L20 to {T.L_INTERIOR:g} cd/m^2 at the entrance. The target: "
         f"{T.TARGET_M * 100:g} cm at {T.STOPPING_M:g} m ({T.target_arcmin():.2f} arcmin), "
         f"{T.CONTRAST:g} below the road luminance of each moment (negative contrast); "
         "Adrian 1989, 25 years, 0.2 s look, k = 2.6, no veil; dL_th x the transient factor "
         f"of the operator's own state (`visibility.seen` on the drive, {T.DT_S:g} s steps; "
         "`visibility.trace` for the step).", "",
         "Expected: VL stays near its threshold-zone value along the curve (here: its least "
         f"on the curve and in the interior at least {NEAR:g} x the entrance's, and >= 1) "
         f"and falls below 1 for some seconds (here: >= {SOME_S:g} s) after the sudden "
         "step.", "",
         "| operator | VL at the entrance (eye at L20) | VL adapted to L_th | least VL of the "
         "drive (at s) | least VL on the curve + interior (/ entrance) | s VL < 1 on the "
         "drive | s VL < 1 after the step (last) | VL adapted to the interior | curve holds "
         "| step holds |", "|---|---|---|---|---|---|---|---|---|---|"]
    for n, d in drives.items():
        last = d.step_last_below1_s
        L.append(f"| {n} | {d.VL_threshold_zone:.3f} | {d.VL_adapted_th:.3f} | "
                 f"{d.vl_min:.3f} ({d.vl_min_t:.2f}) | {d.vl_min_curve:.3f} "
                 f"({d.vl_min_curve / d.VL_threshold_zone:.2f}) | {d.below1_drive_s:.2f} | "
                 f"{d.step_below1_s:.2f} ({'—' if last is None else f'{last:.2f}'}) | "
                 f"{d.step_VL_adapted:.3f} | {'yes' if curve_holds(d) else 'no'} | "
                 f"{'yes' if step_holds(d) else 'no'} |")
    for n, e in failed.items():
        L.append(f"| {n} | failed: {e} |" + " |" * 9)
    ops = list(drives)
    L += ["", "VL on the drive (the eye's cone level La, cd/m^2, in brackets):", "",
          "| t after the entrance (s) | road cd/m^2 | " + " | ".join(ops) + " |",
          "|---|---|" + "---|" * len(ops)]
    first = drives[ops[0]]
    for t in DRIVE_TABLE_S:
        L.append(f"| {t:g} | {_at(first.t, first.L_road, t):.4g} | " + " | ".join(
            f"{_at(d.t, d.VL, t):.3f} ({_at(d.t, d.L_a, t):.4g})" for d in drives.values())
            + " |")
    L += ["", f"VL after the sudden step to {T.L_INTERIOR:g} cd/m^2:", "",
          "| t after the step (s) | " + " | ".join(ops) + " |", "|---|" + "---|" * len(ops)]
    for t in STEP_TABLE_S:
        L.append(f"| {t:g} | " + " | ".join(f"{_at(d.step_t, d.step_VL, t):.3f}"
                                          for d in drives.values()) + " |")
    L += ["", "## B. Light adaptation on a dark-adapted eye (Baker 1949)", "",
          "The observer dark-adapted for good (the tool's darkest field, 1e-6 cd/m^2); a "
          "uniform field switched on at t = 0 (t = 0: the field on, the state still the "
          "dark one). The same target's threshold dL_th (positive contrast) over its steady "
          "value (TAF, clipped to >= 1 as the model has it), and in brackets the unclipped "
          "gain ratio s_steady / s_now (< 1: more sensitive than adapted). Baker: at the "
          "onset the threshold jumps well above its steady value and falls to it within "
          "seconds to tens of seconds.", "",
          "| operator | field cd/m^2 | steady dL_th | " +
          " | ".join(f"{t:g} s" for t in BAKER_TABLE_S) + " | above 1.01 x steady until (s) |",
          "|---|---|---|" + "---|" * len(BAKER_TABLE_S) + "---|"]
    for n, by in onsets.items():
        for Lf, o in by.items():
            u = o.above_steady_until
            L.append(f"| {n} | {Lf:g} | {o.steady:.4g} | " + " | ".join(
                f"{o.over_steady_at(t):.3g} ({o.ratio[o.t.index(t)]:.3g})"
                for t in BAKER_TABLE_S) + f" | {'never' if u is None else f'{u:g}'} |")
    return L + [""]


def plot(drives, onsets, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    colours = {"pattanaik00": "#1b9e77", "durand00": "#d95f02", "kirk11": "#7570b3",
               "ledda04": "#e7298a"}
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8))
    first = next(iter(drives.values()))
    ax[0].semilogy(first.t, first.L_road, "k-", lw=2, label="road (CIE 88 curve)")
    for n, d in drives.items():
        ax[0].semilogy(d.t, d.L_a, color=colours.get(n), lw=1, label=f"{n} La")
    ax[0].axvline(T.threshold_zone_s(), color="0.6", ls=":")
    ax[0].set(xlabel="s after the entrance", ylabel="cd/m^2",
              title="The drive: road luminance and the eye's level")
    ax[0].legend(fontsize=7)
    for n, d in drives.items():
        ax[1].semilogy(d.t, d.VL, color=colours.get(n), lw=1.5, label=f"{n}, curve")
        ax[1].semilogy(d.step_t, d.step_VL, color=colours.get(n), lw=1, ls="--",
                       label=f"{n}, step")
    ax[1].axhline(1.0, color="k", lw=0.8)
    ax[1].set(xlabel="s after the entrance", ylabel="VL", xlim=(0, T.DRIVE_S),
              title=f"VL of a {T.target_arcmin():.1f}' target, contrast -{T.CONTRAST:g}")
    ax[1].legend(fontsize=7, ncol=2)
    Lf = max(T.BAKER_FIELDS)
    for n, by in onsets.items():
        o = by[Lf]
        t = np.asarray(o.t) + 0.005
        ax[2].loglog(t, o.dL_th / o.steady, color=colours.get(n), lw=1.5, label=n)
        ax[2].loglog(t, o.ratio, color=colours.get(n), lw=0.8, ls=":")
    ax[2].axhline(1.0, color="k", lw=0.8)
    ax[2].set(xlabel="s after the onset (+0.005)", ylabel="dL_th / steady",
              title=f"Dark-adapted eye, {Lf:g} cd/m^2 on (dotted: unclipped)")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "tunnel_entrance.md")
    a = ap.parse_args(argv)
    out = out_path(a, "tunnel_entrance.md")
    drives, onsets, failed = T.run_all()
    png = os.path.join(os.path.dirname(os.path.abspath(out)), "tunnel_entrance.png")
    lines = report(drives, onsets, failed, out)
    try:
        plot(drives, onsets, png)
        lines += [f"![The drive, VL, and the dark-adapted eye]({os.path.basename(png)})", ""]
    except ImportError:
        lines += ["(no figure: matplotlib missing)", ""]
    with open(out, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    print(f"wrote {out}" + (f" and {png}" if os.path.exists(png) else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
