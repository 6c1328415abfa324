"""The operators held against measurements of people (issue 34): dark adaptation
(Hecht, Haig & Chase 1937), acuity (Shlaer 1937), increment thresholds (Ferwerda et al.
1996's TVI) and the Purkinje peak (CIE 1924 V, CIE 1951 V'), with each operator's rod
weight against CIE 191:2010's mesopic m. Every experiment runs the tool through its
public API or its command line (``benchmarks/lib/human/``); docs/validation.md says how
each threshold is derived and why a model departs where it does.

One command (matplotlib: ``pip install "ocl-tonemap[plot]"``):
    python benchmarks/psychophysics.py [--out-dir DIR | --out FILE]

Writes psychophysics.md into DIR (default ./benchmark-results; the committed table:
``--out-dir benchmarks/results``; the rule: ``benchmarks/lib/outdir.py``) and, beside
it, psychophysics_dark.png (the README's plot), psychophysics_acuity.png,
psychophysics_tvi.png and psychophysics_purkinje.png.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

try:
    from benchmarks.lib.human import acuity, dark, purkinje, tvi
    from benchmarks.lib.human.data import HECHT_TD, load_hecht1937
    from benchmarks.lib.outdir import add_out_args, link, out_path
except ModuleNotFoundError:     # run as a file: its own folder is first on the path
    from lib.human import acuity, dark, purkinje, tvi
    from lib.human.data import HECHT_TD, load_hecht1937
    from lib.outdir import add_out_args, link, out_path

TD_COLOURS = {263.0: "#1b9e77", 3800.0: "#d95f02", 19500.0: "#7570b3", 38900.0: "#e7298a",
              400000.0: "#333333"}


def _f(v, fmt="{:.2f}"):
    return "—" if v is None or (isinstance(v, float) and not np.isfinite(v)) else fmt.format(v)


def dark_section(res, crit) -> list:
    L = ["## 1. Dark adaptation after a bright field (Hecht, Haig & Chase 1937)", "",
         f"Pre-adaptation {dark.PREADAPT_S:.0f} s through the natural pupil (Moon & Spencer); "
         f"test light {dark.TEST_NM:.0f} nm (L'/L = "
         f"{dark.scotopic_photopic_ratio(dark.TEST_NM):.1f}); thresholds in log "
         "micro-micro-lamberts. RMS median: against the median of the three observers "
         "(each interpolated on a 15 s grid; the target is 0.5 log units, the observers "
         "differ by 0.3-0.5); RMS points: over every observer's points; shape: RMS after "
         "removing the mean offset. The shared pigment model (models/bleaching.py) was fitted "
         f"on {', '.join(f'{t:g}' for t in dark.FIT_TD)} td; "
         f"{', '.join(f'{t:g}' for t in dark.HELD_OUT_TD)} td are held out. Criterion: "
         "(rods', cones') response increments, factors on Ferwerda's thresholds for "
         "durand00 (docs/validation.md). Data: the rod-cone break at 12-14 min after "
         "400 000 td, 5-7 min after 19 500 td.", "",
         "| operator | criterion | trolands | set | field cd/m^2 | RMS median | shape | offset "
         "| RMS points | break min | cone plateau | drop (model / data) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for op, d in res.items():
        c = crit[op]
        ctext = ", ".join(f"{x:.3g}" for x in c) if isinstance(c, tuple) else _f(c, "{:.3g}")
        for td, (cv, sc) in d.items():
            L.append(f"| {op} | {ctext} | {td:g} | "
                     f"{'held out' if td in dark.HELD_OUT_TD else 'fit'} | {cv.L_pre:.3g} | "
                     f"{sc.rms_median:.2f} | {sc.shape_median:.2f} | {sc.offset_median:+.2f} | "
                     f"{sc.rms:.2f} | "
                     f"{_f(sc.break_min, '{:.1f}') if sc.break_min is not None else 'none'} | "
                     f"{_f(sc.plateau)} | {sc.drop:.2f} / {sc.data_drop:.2f} |")
    return L + [""]


def acuity_section(res) -> list:
    ops = list(res)
    L = ["## 2. Acuity against luminance (Shlaer 1937)", "",
         f"Sine gratings, {acuity.FOV_DEG:g} degrees over {acuity.WIDTH} px, "
         "`--acuity on` against `off` (each operator, `--model none` otherwise); cut-off "
         "where the transfer falls through 10^-0.395 (Eq. 10). Shlaer: Table 1 at the "
         "field's photopic luminance; Ward: Ward Larson et al. 1997's fit; omega: the "
         "model's own cut-off. Measured c/deg, and / Shlaer in brackets.", "",
         "| La cd/m^2 | Shlaer | Ward's fit | omega | " + " | ".join(ops) + " |",
         "|---|---|---|---|" + "---|" * len(ops)]
    for k, (La, _, s, w, om) in enumerate(res[ops[0]]):
        cells = []
        for op in ops:
            m = res[op][k][1]
            cells.append("—" if m is None else f"{m:.2f} ({m / s:.3f})")
        L.append(f"| {La:.3g} | {s:.2f} | {w:.2f} | {om:.2f} | " + " | ".join(cells) + " |")
    return L + [""]


def tvi_section(res) -> list:
    L = ["## 3. Increment thresholds against Ferwerda et al. 1996", "",
         "A disk on a uniform field at steady state; the world increment that is one "
         "just noticeable difference on the display (Delta E ITP = 1 in display light) over "
         "Ferwerda's threshold at La (ratio 1: one world threshold is one display "
         "threshold); the second ratio takes the display threshold as Durand & Dorsey do "
         "(Ferwerda's cone threshold at the display observer's adaptation).", "",
         "| operator | " + " | ".join(f"{La:.0e}" for La in tvi.LEVELS) + " |",
         "|---|" + "---|" * len(tvi.LEVELS)]
    for op, rows in res.items():
        L.append(f"| {op} (Delta E ITP) | " + " | ".join(f"{r[3]:.3g}" for r in rows) + " |")
        L.append(f"| {op} (Ferwerda display) | " + " | ".join(f"{r[4]:.3g}" for r in rows) +
                 " |")
    return L + [""]


def purkinje_section(peaks, mes) -> list:
    L = ["## 4. The Purkinje peak (kirk11's spectral path) and the mesopic rod weight", "",
         "The wavelength shown brightest from equal spectral radiance in 5 nm bands (CIE "
         "1924 V peaks at 555 nm, CIE 1951 V' at 507 nm):", "",
         "| mean L cd/m^2 | " + " | ".join(f"{L_:.0e}" for L_, _ in peaks) + " |",
         "|---|" + "---|" * len(peaks),
         "| peak nm | " + " | ".join(f"{p:.1f}" for _, p in peaks) + " |", "",
         "Rod weight for a neutral field (1 - m of CIE 191:2010, from its own equations):",
         "", "| L cd/m^2 | CIE 191 (1 - m) | " + " | ".join(mes[0][2]) + " |",
         "|---|---|" + "---|" * len(mes[0][2])]
    for L_, cie, ops in mes:
        L.append(f"| {L_:.3g} | {cie:.3f} | " + " | ".join(f"{v:.3f}" for v in ops.values()) +
                 " |")
    return L + [""]


def _axes(ax, xlabel: str, ylabel: str, logy: bool = False) -> None:
    """Log x (luminance), labels, grid and legend, as every plot here has them."""
    ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _save(fig, out_dir: str, name: str, paths: list) -> None:
    import matplotlib.pyplot as plt
    fig.tight_layout()
    paths.append(os.path.join(out_dir, name))
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)


def plots(out_dir, res_dark, acu, res_tvi, peaks, mes) -> list:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ocl_tonemap.models.shaler1937 import SHALER_LOG_L, SHALER_OMEGA
    paths: list = []
    pts = load_hecht1937()
    fig, axs = plt.subplots(1, len(res_dark), figsize=(5 * len(res_dark), 4.2), sharey=True)
    for ax, (op, d) in zip(np.atleast_1d(axs), res_dark.items()):
        for td in sorted(HECHT_TD.values()):
            c = TD_COLOURS[td]
            p = [q for q in pts if q.td == td]
            ax.scatter([q.minutes for q in p], [q.log_uuL for q in p], s=9, color=c, alpha=0.6,
                       label=f"{td:g} td")
            cv = d[td][0]
            ax.plot(cv.minutes, cv.log_uuL, color=c, lw=1.6)
        ax.set_title(op)
        ax.set_xlabel("minutes in the dark")
        ax.set_xlim(0, 45)
        ax.grid(alpha=0.3)
    np.atleast_1d(axs)[0].set_ylabel("log threshold, micro-micro-lamberts")
    np.atleast_1d(axs)[0].legend(fontsize=8, title="Hecht et al. 1937 (points)")
    fig.suptitle("Dark adaptation: Hecht, Haig & Chase 1937 (points) and each operator (lines)")
    _save(fig, out_dir, "psychophysics_dark.png", paths)

    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot(10.0 ** SHALER_LOG_L, SHALER_OMEGA, "ko", ms=4, label="Shlaer 1937 (Table 1)")
    xs = np.logspace(-3.5, 3, 100)
    ax.plot(xs, acuity.ward_fit(xs), "k:", label="Ward Larson et al. 1997 fit")
    for op, rows in acu.items():
        ax.plot([r[0] for r in rows], [np.nan if r[1] is None else r[1] for r in rows],
                "s-", ms=4, alpha=0.8, label=f"{op} through the CLI (--acuity on)")
    _axes(ax, "field luminance, cd/m^2", "cut-off, cycles/degree")
    _save(fig, out_dir, "psychophysics_acuity.png", paths)

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for op, rows in res_tvi.items():
        line, = ax.plot([r[0] for r in rows], [r[3] for r in rows], "o-", label=f"{op}")
        ax.plot([r[0] for r in rows], [r[4] for r in rows], "s--", color=line.get_color(),
                alpha=0.6)
    ax.axhspan(0.5, 2.0, color="0.9")
    ax.set_title("solid: Delta E ITP = 1; dashed: Ferwerda display threshold", fontsize=9)
    _axes(ax, "adapting luminance La, cd/m^2", "display-JND increment / Ferwerda threshold",
          logy=True)
    _save(fig, out_dir, "psychophysics_tvi.png", paths)

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    a1.plot([p[0] for p in peaks], [p[1] for p in peaks], "o-", color="#7570b3",
            label="kirk11 (spectral EXR through the CLI)")
    a1.axhline(555, color="k", ls=":", lw=1)
    a1.axhline(507, color="k", ls="--", lw=1)
    a1.text(2e-4, 556.5, "V (555 nm)", fontsize=8)
    a1.text(2e-4, 508.5, "V' (507 nm)", fontsize=8)
    _axes(a1, "mean photopic luminance, cd/m^2", "brightest wavelength, nm")
    Ls = [m[0] for m in mes]
    a2.plot(Ls, [m[1] for m in mes], "k-", lw=2.5, label="CIE 191:2010 (1 - m)")
    for op in mes[0][2]:
        a2.plot(Ls, [m[2][op] for m in mes], "o-", ms=3, label=op)
    _axes(a2, "neutral field, cd/m^2", "rod weight")
    _save(fig, out_dir, "psychophysics_purkinje.png", paths)
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "psychophysics.md")
    a = ap.parse_args(argv)
    out = out_path(a, "psychophysics.md")
    t0 = time.perf_counter()
    res_dark, crit = dark.run_all()
    print(f"dark adaptation: {time.perf_counter() - t0:.0f} s", flush=True)
    acu = {op: acuity.run_all(operator=op) for op in tvi.OPERATORS}
    print(f"acuity: {time.perf_counter() - t0:.0f} s", flush=True)
    res_tvi = tvi.run_all()
    print(f"thresholds: {time.perf_counter() - t0:.0f} s", flush=True)
    peaks = purkinje.purkinje_peaks()
    mes = purkinje.mesopic_table()
    print(f"Purkinje: {time.perf_counter() - t0:.0f} s", flush=True)
    out_dir = os.path.dirname(os.path.abspath(out))
    names = [os.path.basename(p) for p in plots(out_dir, res_dark, acu, res_tvi, peaks, mes)]
    L = ["# The operators against measurements of people", "",
         "- command `python benchmarks/psychophysics.py`; this machine (2 cores, PoCL CPU "
         f"OpenCL); {time.perf_counter() - t0:.0f} s; what each experiment derives and why "
         "a model departs: [docs/validation.md]"
         f"({link(out, 'docs/validation.md')})",
         "- plots: " + ", ".join(f"[{n}]({n})" for n in names), ""]
    L += dark_section(res_dark, crit) + acuity_section(acu) + tvi_section(res_tvi) + \
        purkinje_section(peaks, mes)
    with open(out, "w") as fh:
        fh.write("\n".join(L) + "\n")
    print(f"wrote {out} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
