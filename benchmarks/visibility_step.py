"""The threshold after a step down, by each operator's time course (issue 48): one command.

    python -m benchmarks.visibility_step [--out-dir DIR]

An observer fully adapted to 5000 cd/m^2 (a sunlit tunnel approach) looks at a
background that steps to L_b at t = 0. Adrian 1989's dL_th (10 arcmin, positive
contrast, age 25, 2 s look, k = 2.6) times each operator's transient factor
(``ocl_tonemap/effects/visibility.py``): the table at 0.5, 2, 10 and 60 s after the step,
for L_b = 5 cd/m^2 and for CIE 88's threshold zone (L_th = k L20, k = 0.05), and
the operators' adaptation luminance against CIE 88's transition-zone design curve
L_tr(t) = L_th (1.9 + t)^-1.4. Pure float64, seconds. Writes
``visibility_step.md`` and ``visibility_step.png``.
"""

from __future__ import annotations

import argparse
import os
import sys

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import write_markdown
from ocl_tonemap.operators import get_operator
from ocl_tonemap.effects.visibility import Viewing, trace

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")
L_APPROACH = 5000.0
#: CIE 88:2004's k for the threshold zone (symmetrical lighting, 60 m stopping distance).
K_CIE88 = 0.05
TIMES = (0.0, 0.5, 2.0, 10.0, 60.0)


def cie88_transition(L_th: float, t: float) -> float:
    """CIE 88's transition-zone luminance t seconds into the tunnel, cd/m^2."""
    return L_th * (1.9 + t) ** -1.4


def table(L_b: float, view: Viewing) -> list[str]:
    steady = float(view.steady(L_b))
    lines = [f"### {L_APPROACH:g} -> {L_b:g} cd/m^2 (steady dL_th at {L_b:g}: {steady:.4g} "
             "cd/m^2)", "",
             "| operator | " + " | ".join(f"dL_th at {t:g} s (TAF; La)" for t in TIMES) +
             " | falls monotonically |", "|---|" + "---|" * (len(TIMES) + 1)]
    for name in OPERATORS:
        op = get_operator(name)({})
        pts = trace(op, L_APPROACH, None, L_b, TIMES, view)
        dense = trace(op, L_APPROACH, None, L_b, [0.05 * i for i in range(1201)], view)
        mono = all(b.dL_th <= a.dL_th for a, b in zip(dense, dense[1:]))
        above = all(p.dL_th > steady for p in pts if 0 < p.t <= 10)
        lines.append(f"| {name} | " + " | ".join(
            f"{p.dL_th:.4g} ({p.TAF:.4g}; {p.L_a:.3g})" for p in pts) +
            f" | {'yes' if mono else 'no'}{'' if above else ', at steady by 10 s'} |")
    return lines + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "visibility_step.md")
    a = ap.parse_args(argv)
    view = Viewing(10.0, 25.0, 2.0)
    L_th = K_CIE88 * L_APPROACH
    lines = ["# The threshold after a step down, by each operator's time course", "",
             "`python -m benchmarks.visibility_step`. Adrian 1989's dL_th (10 arcmin, "
             "positive contrast, 25 years, 2 s look, k = 2.6) times the transient factor "
             "of each operator's own state (TAF: its response gain at L_b when adapted "
             "there over its gain now; docs/models.md, \"Transient adaptation\"); La is "
             "the operator's cone adaptation luminance. The observer was fully adapted to "
             f"{L_APPROACH:g} cd/m^2.", ""]
    lines += table(5.0, view)
    lines += table(L_th, view)
    lines += [f"### Adaptation against CIE 88's transition curve (L_th = {K_CIE88:g} x "
              f"{L_APPROACH:g} = {L_th:g} cd/m^2, the background held at L_th)", "",
              "CIE 88 lowers the tunnel's luminance after the threshold zone as "
              "L_th (1.9 + t)^-1.4: its assumption of how fast a driver's adaptation may "
              "follow. The operators' La over the same seconds (the eye held at L_th):", "",
              "| t (s) | CIE 88 L_tr | " + " | ".join(OPERATORS) + " |",
              "|---|---|" + "---|" * len(OPERATORS)]
    ts = (0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
    las = {n: trace(get_operator(n)({}), L_APPROACH, None, L_th, ts, view)
           for n in OPERATORS}
    for i, t in enumerate(ts):
        lines.append(f"| {t:g} | {cie88_transition(L_th, t):.4g} | " +
                     " | ".join(f"{las[n][i].L_a:.4g}" for n in OPERATORS) + " |")
    out = out_path(a, "visibility_step.md")
    png = os.path.splitext(out)[0] + ".png"
    from ocl_tonemap.io.plot import plot_visibility_step
    plot_visibility_step(png, [get_operator(n)({}) for n in OPERATORS], L_APPROACH, None,
                         5.0, view, t_max=600.0)
    lines += ["", f"![dL_th after the step to 5 cd/m^2]({os.path.basename(png)})"]
    write_markdown(out, lines, [])
    print(f"wrote {out} and {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
