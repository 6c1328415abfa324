"""Dark adaptation as the display shows it (Ledda, Santos & Chalmers 2004, Sec. 6.1's
method; issue 66): a chart of neutral targets on black, seen after Hecht, Haig & Chase
1937's pre-adapting fields through the public API with the default settings; the time
each target first shows on the display (Delta E ITP >= 1 against its black surround)
against the time the observers' median threshold falls below it, and the shape of the
two courses (``benchmarks/lib/human/display_dark.py`` says how each is derived).

One command (matplotlib: ``pip install "ocl-tonemap[plot]"``):
    python benchmarks/display_dark.py [--out-dir DIR | --out FILE]

Writes display_dark.md into DIR (default ./benchmark-results; the committed table:
``--out-dir benchmarks/results``; the rule: ``benchmarks/lib/outdir.py``) and, beside
it, display_dark.png.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

try:
    from benchmarks.lib.human import display_dark as D
    from benchmarks.lib.human.data import HECHT_TD
    from benchmarks.lib.outdir import add_out_args, link, out_path
except ModuleNotFoundError:     # run as a file: its own folder is first on the path
    from lib.human import display_dark as D
    from lib.human.data import HECHT_TD
    from lib.outdir import add_out_args, link, out_path

TD_COLOURS = {263.0: "#1b9e77", 3800.0: "#d95f02", 19500.0: "#7570b3", 38900.0: "#e7298a",
              400000.0: "#333333"}


def _f(v, fmt="{:.2f}"):
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "—"
    if isinstance(v, float) and np.isinf(v):
        return "never" if v > 0 else "all"
    return fmt.format(v)


def score_table(res) -> list:
    L = ["| operator | trolands | field cd/m^2 | shape RMS | max abs dev | within 0.75 | "
         "offset at end | times (left chart) | shape RMS, no display black | "
         "offset, no black |", "|---|---|---|---|---|---|---|---|---|---|"]
    for op, d in res.items():
        for td, run in d.items():
            s, _, _, _ = D.compare(run, True)
            s0, _, _, _ = D.compare(run, False)
            L.append(f"| {op} | {td:g} | {run.L_pre:.3g} | {_f(s.rms_shape)} | "
                     f"{_f(s.max_dev)} | {'yes' if s.within else 'no'} | "
                     f"{_f(s.offset, '{:+.2f}')} | {s.n} ({s.censored}) | "
                     f"{_f(s0.rms_shape)} | {_f(s0.offset, '{:+.2f}')} |")
    return L + [""]


#: The first-visible tables show every fourth target (0.5 log units apart).
TABLE_EVERY = 4


def first_table(res, td) -> list:
    k = TABLE_EVERY
    logs = np.log10(D.TARGETS_CD)[::k]
    L = [f"**{td:g} td** (minutes at which each target first shows, every {k}th "
         "target; 0: from the first frame, 0.05 min; never: not within 40 min)", "",
         "| | " + " | ".join(f"{x:.1f}" for x in logs) + " |",
         "|---|" + "---|" * len(logs),
         "| Hecht median (neutral) | " +
         " | ".join(_f(v, "{:.1f}") for v in D.hecht_first_visible(td)[::k]) + " |"]
    for op, d in res.items():
        L.append(f"| {op} | " + " | ".join(_f(v, "{:.1f}") for v in d[td].first_visible()[::k])
                 + " |")
    return L + [""]


def plot(res, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ops = list(res)
    fig, axs = plt.subplots(2, len(ops), figsize=(4.2 * len(ops), 7.4), sharey="row",
                            squeeze=False)
    for j, op in enumerate(ops):
        for td, run in res[op].items():
            c = TD_COLOURS.get(td, "k")
            _, m, rd, rh = D.compare(run)
            a = axs[0, j]
            a.plot(m, rd, color=c, lw=1.6, label=f"{td:g} td")
            a.plot(m, rh, color=c, lw=1.2, ls="--")
            th, yh = D.hecht_course(td)
            b = axs[1, j]
            cv = run.course()
            b.plot(run.minutes, np.where(np.isfinite(cv), cv, np.nan), color=c, lw=1.6,
                   label=f"{td:g} td")
            b.plot(th, yh, color=c, lw=1.2, ls="--")
        axs[0, j].set_title(op)
        axs[1, j].set_xlabel("minutes in the dark")
        for a in axs[:, j]:
            a.set_xlim(0, 40)
            a.grid(alpha=0.3)
    axs[0, 0].set_ylabel("log10 just-visible L, relative to the end")
    axs[1, 0].set_ylabel("log10 just-visible L, cd/m^2")
    axs[0, 0].legend(fontsize=8, title="display (solid), Hecht (dashed)")
    axs[1, 0].axhspan(np.log10(D.TARGETS_CD[0]) - 0.5, np.log10(D.TARGETS_CD[0]), color="0.9")
    fig.suptitle("Neutral targets on black, each alone, after Hecht's fields: display "
                 "(Delta E ITP >= 1) against the observers' median")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "display_dark.md")
    a = ap.parse_args(argv)
    out = out_path(a, "display_dark.md")
    t0 = time.perf_counter()
    res = D.run_all()                       # each target alone (the primary reading)
    chart_res = D.run_all(layout="chart")   # all of them in one chart
    dt = time.perf_counter() - t0
    png = os.path.join(os.path.dirname(os.path.abspath(out)), "display_dark.png")
    plot(res, png)
    f, _ = D.chart()
    L = ["# Dark adaptation on the display (Ledda et al. 2004, Sec. 6.1's method)", "",
         f"- command `python benchmarks/display_dark.py`; {dt:.0f} s on this machine; how "
         "each course is derived and what it shows: [docs/validation.md]"
         f"({link(out, 'docs/validation.md')}), section 'Dark adaptation on the display'",
         f"- plot: [{os.path.basename(png)}]({os.path.basename(png)})", "",
         f"Targets: {len(D.TARGETS_CD)} neutral squares of {D.TARGET_PX} px "
         f"({D.TARGET_PX / f.shape[1] * 50:.1f} degrees), "
         f"{D.TARGETS_CD[0]:g} to {D.TARGETS_CD[-1]:g} cd/m^2 in "
         f"{np.diff(np.log10(D.TARGETS_CD))[0]:g} log steps, on black: "
         f"each alone in a {D.ALONE_PX} x {D.ALONE_PX} px frame (Hecht's method, one test "
         "field at a time; the tables and the plot), and every fourth of them "
         f"({len(D.CHART_TARGETS_CD)}, 0.5 log apart) in one chart of "
         f"{f.shape[1]} x {f.shape[0]} px at the default 50-degree field (the last "
         "table: the brighter targets' veil lies over the dimmer ones). Pre-adaptation "
         f"{D.PREADAPT_S:.0f} s at each "
         "of Hecht's fields through the natural pupil; then frames at "
         f"{D.TIMES_MIN[0]:g}-{D.TIMES_MIN[-1]:g} min with the defaults "
         "(`Tonemapper(op, preadapt=(L, 120))`: `model=\"auto\"`, logmean metering, "
         "sRGB display of white 100 and black 0.1 cd/m^2). Visible on the display: "
         f"Delta E ITP >= {D.JND:g} between the light the display emits for the target's "
         "centre and for the ring of black 5-10 px around it. The observers' course: "
         "Hecht's median (violet test light) read for a neutral target (above the cones' "
         f"plateau, 10^{np.log10(D.dark.data_cone_plateau()):.2f} cd/m^2, as measured; "
         f"below it min(plateau, {D.neutral_factor():.1f} x the violet's photopic "
         "threshold)). Shape: both courses (the log10 luminance just visible at each time, "
         "each read off the minutes at which the targets first show, linear in time between "
         "them: the same ladder for both) relative to their value at the last time of the "
         "data's median (29.5-39 min), "
         "compared at the frames within the data's range; the issue's target: within "
         f"{D.SHAPE_TARGET} log units at each time (max abs dev). Offset: display minus "
         "observers at that end time (a constant factor between the two JNDs). Times "
         "where every target or none is visible are left out (counted in brackets).", "",
         "## The shape of the courses (each target alone)", ""]
    L += score_table(res)
    L += ["## When each target first shows (alone; log10 cd/m^2 across)", ""]
    for td in sorted(HECHT_TD.values()):
        L += first_table(res, td)
    L += ["## The shape of the courses, all targets in one chart", ""]
    L += score_table(chart_res)
    with open(out, "w") as fh:
        fh.write("\n".join(L) + "\n")
    print("\n".join(score_table(res)))
    print(f"wrote {out} and {png} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
