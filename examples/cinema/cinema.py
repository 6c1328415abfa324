"""Pattanaik's cinema (Pattanaik et al. 2000's opening example; issue 66): from a sunny
street into a dark cinema and out again, seen by the default observer.

A person walks out of a sunny street (~1e4 cd/m^2) into a cinema: a room of ~0.1 cd/m^2
with a bright screen (~50 cd/m^2) and popcorn on the floor under the seats (~1e-3 cd/m^2).
At first only the screen is there and the room is black; the popcorn shows after tens
of minutes, as the rods' pigment grows back. Back outside, the street is white at first
and normal within seconds.

Both scenes are built here as HDR images in cd/m^2 (linear BT.709, 320 x 180) and go
through the public API with the default settings (``Tonemapper(op)``: the observer fully
adapted to the first frame, ``model="auto"``, the sRGB display of white 100 and black
0.1 cd/m^2), for pattanaik00 and durand00: the street for 2 minutes, the cinema at 1 s,
10 s, 1, 5, 10, 20 and 30 min, the street again at 0.1, 1, 5 and 30 s. Each claim is
measured on the display's light (display-linear values through the display: black +
(white - black) x value) and printed:

* the room: Delta E ITP (BT.2124: 1 = one just noticeable difference) of the room's wall
  against the display's black; the screen's mean display luminance;
* the popcorn: Delta E ITP of its displayed colour against the floor around it under the
  seats, and the minute it first reaches 1;
* back outside: the frame's mean display luminance, its share of white pixels (>= 90 %
  of display white) and its median Delta E ITP against the street's last frame before
  the cinema.

    python examples/cinema/cinema.py [--out PNG] [--operators pattanaik00,durand00]
                                     [--flare on|off|auto]

Needs matplotlib (``pip install "ocl-tonemap[plot]"``).
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from ocl_tonemap import Tonemapper
from ocl_tonemap.models.ictcp import delta_e_itp, rgb709_to_ictcp

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
W, H = 320, 180
Y709 = np.array([0.2126, 0.7152, 0.0722])

#: The observer's day: seconds outside, then inside, then outside again (frame times).
OUTSIDE_S = (0.0, 60.0, 120.0)
INSIDE_S = (1.0, 10.0, 60.0, 300.0, 600.0, 1200.0, 1800.0)
BACK_S = (0.1, 1.0, 5.0, 30.0)
#: A pixel shows white when its largest display-linear channel is at least this.
WHITE = 0.9


def _colour(rgb, L):
    """A colour of chromaticity ``rgb`` (linear BT.709) scaled to luminance ``L``."""
    c = np.asarray(rgb, np.float64)
    return c * (L / float(c @ Y709))


def street() -> np.ndarray:
    """A sunny street, cd/m^2: sky, a sunlit facade and a shaded one with windows, the
    road with its markings (log mean ~6e3 cd/m^2)."""
    f = np.zeros((H, W, 3))
    yy, xx = np.mgrid[:H, :W]
    f[:] = _colour((0.55, 0.75, 1.0), 1.0e4)                       # sky
    f[yy < 60] *= (1.0 + 0.3 * (60 - yy[yy < 60]) / 60.0)[:, None]
    left = (xx < 120) & (yy >= 20 + xx // 6) & (yy < 120)          # sunlit facade
    f[left] = _colour((1.0, 0.9, 0.75), 2.0e4)
    right = (xx >= 200) & (yy >= 30 + (W - xx) // 6) & (yy < 120)  # shaded facade
    f[right] = _colour((0.8, 0.85, 1.0), 1.5e3)
    for x0 in range(10, 110, 25):                                   # windows
        for y0 in (50, 85):
            f[y0:y0 + 14, x0:x0 + 12] = _colour((0.7, 0.75, 0.8), 4.0e2)
    for x0 in range(215, 315, 25):
        for y0 in (55, 88):
            f[y0:y0 + 14, x0:x0 + 12] = _colour((0.9, 0.8, 0.6), 1.5e2)
    road = yy >= 120
    f[road] = _colour((1.0, 1.0, 1.0), 5.0e3)
    f[(yy >= 120) & (xx > 140) & (xx < 180) & ((yy // 8) % 2 == 0)] = _colour((1, 1, 1), 1.5e4)
    f[(yy >= 120) & (xx >= 200)] = _colour((0.85, 0.9, 1.0), 1.2e3)  # the building's shadow
    return f.astype(np.float32)


#: Where the popcorn lies (rows, columns) and the floor around it that it is seen against.
POPCORN = (slice(158, 166), slice(146, 170))
FLOOR_RING = 4            # px of floor around the popcorn


def cinema() -> np.ndarray:
    """The cinema, cd/m^2: a room of ~0.1, the screen ~50 (a picture: sky, hills, a
    figure), rows of seats ~0.02, the floor under them ~3e-4 and popcorn there ~1e-3."""
    f = np.zeros((H, W, 3))
    yy, xx = np.mgrid[:H, :W]
    f[:] = _colour((1.0, 0.85, 0.7), 0.1)                           # the room
    scr = (yy >= 15) & (yy < 85) & (xx >= 60) & (xx < 260)
    f[scr] = _colour((0.6, 0.8, 1.0), 60.0)                         # the film: sky
    hills = scr & (yy > 60 + 8 * np.sin(xx / 17.0))
    f[hills] = _colour((0.4, 0.8, 0.3), 25.0)
    f[(yy >= 40) & (yy < 70) & (xx >= 150) & (xx < 162)] = _colour((0.9, 0.5, 0.4), 35.0)
    for k, y0 in enumerate(range(100, 175, 19)):                    # rows of seats
        backs = (yy >= y0) & (yy < y0 + 10) & ((xx + 7 * k) % 22 < 19)
        f[backs] = _colour((0.8, 0.15, 0.15), 0.02)
        f[(yy >= y0 + 10) & (yy < y0 + 19)] = _colour((1.0, 0.9, 0.8), 3.0e-4)  # under
    f[POPCORN] = _colour((1.0, 0.95, 0.75), 3.0e-4)
    ky, kx = np.mgrid[POPCORN]
    kernels = ((ky * 7 + kx * 3) % 5 < 3)                           # kernels, a pile
    pop = f[POPCORN]
    pop[kernels] = _colour((1.0, 0.95, 0.75), 1.5e-3)
    f[POPCORN] = pop
    return f.astype(np.float32)


def _masks():
    yy, xx = np.mgrid[:H, :W]
    pr, pc = POPCORN
    pop = np.zeros((H, W), bool)
    pop[POPCORN] = True
    ring = ((yy >= pr.start - FLOOR_RING) & (yy < pr.stop + FLOOR_RING) &
            (xx >= pc.start - FLOOR_RING) & (xx < pc.stop + FLOOR_RING) & ~pop)
    floor = cinema()[..., 1] < 1e-3
    wall = (yy < 10) | ((yy < 95) & ((xx < 50) | (xx >= 270)))
    screen = (yy >= 15) & (yy < 85) & (xx >= 60) & (xx < 260)
    return {"popcorn": pop, "floor": ring & floor, "wall": wall, "screen": screen}


def light(display, v) -> np.ndarray:
    """cd/m^2 the display emits for display-linear ``v`` (clipped to its 0..1)."""
    return display.from_signal(np.clip(np.asarray(v, np.float64), 0.0, 1.0))


def delta_e(display, a, b) -> float:
    """Delta E ITP between two display-linear colours as the display shows them."""
    return float(delta_e_itp(rgb709_to_ictcp(light(display, a)),
                             rgb709_to_ictcp(light(display, b))))


def srgb(v) -> np.ndarray:
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def run(op: str, **settings):
    """[(label, seconds since the door, scene name, display-linear frame, measurements)];
    ``settings``: Tonemapper keywords over the defaults (none by default)."""
    tm = Tonemapper(op, **settings)
    s, c, m = street(), cinema(), _masks()
    d = tm.display
    rows = []
    out = None
    for t in OUTSIDE_S:
        out = tm.process(s, time_s=t)
    ref = np.asarray(out, np.float64)[..., :3]
    ref_mean = float(np.mean(light(d, ref) @ Y709))
    rows.append(("street, 2 min", -0.0, "street", ref,
                 {"mean_cd": ref_mean, "white": float(np.mean(ref.max(-1) >= WHITE))}))
    door = OUTSIDE_S[-1]
    for t in INSIDE_S:
        o = np.asarray(tm.process(c, time_s=door + t), np.float64)[..., :3]
        meas = {"popcorn_dE": delta_e(d, o[m["popcorn"]].mean(0), o[m["floor"]].mean(0)),
                "wall_dE": delta_e(d, o[m["wall"]].mean(0), np.zeros(3)),
                "wall_cd": float(light(d, o[m["wall"]].mean(0)) @ Y709),
                "screen_cd": float(np.mean(light(d, o[m["screen"]]) @ Y709)),
                "screen_white": float(np.mean(o[m["screen"]].max(-1) >= WHITE)),
                "popcorn_cd": float(light(d, o[m["popcorn"]].mean(0)) @ Y709)}
        rows.append((f"inside {_t(t)}", t, "cinema", o, meas))
    back = door + INSIDE_S[-1]
    for t in BACK_S:
        o = np.asarray(tm.process(s, time_s=back + t), np.float64)[..., :3]
        mean = float(np.mean(light(d, o) @ Y709))
        rows.append((f"outside {_t(t)}", t, "street", o,
                     {"mean_cd": mean, "mean_ratio": mean / ref_mean,
                      "white": float(np.mean(o.max(-1) >= WHITE)),
                      "dE_median": float(np.median(delta_e_itp(
                          rgb709_to_ictcp(light(d, o)), rgb709_to_ictcp(light(d, ref)))))}))
    return rows


def _t(s: float) -> str:
    return f"{s:g} s" if s < 60 else f"{s / 60:g} min"


def emerges_min(rows) -> float:
    """The minute the popcorn first reaches Delta E ITP 1 for good (log-interpolated)."""
    ins = [(r[1], r[4]["popcorn_dE"]) for r in rows if r[2] == "cinema"]
    t = np.array([a for a, _ in ins]) / 60.0
    de = np.array([b for _, b in ins])
    vis = de >= 1.0
    if not vis[-1]:
        return np.inf
    k = len(vis) - 1
    while k > 0 and vis[k - 1]:
        k -= 1
    if k == 0:
        return float(t[0])
    f = -np.log10(max(de[k - 1], 1e-12)) / (np.log10(de[k]) - np.log10(max(de[k - 1], 1e-12)))
    return float(t[k - 1] + f * (t[k] - t[k - 1]))


def report(op: str, rows) -> list:
    L = [f"{op}:"]
    r0 = rows[0][4]
    L.append(f"  street after 2 min: mean display luminance {r0['mean_cd']:.1f} cd/m^2, "
             f"{100 * r0['white']:.1f} % of pixels white (>= 90 % of display white)")
    for lab, _, scene, _, m in rows[1:]:
        if scene == "cinema":
            L.append(f"  {lab:>14}: popcorn Delta E ITP vs the floor {m['popcorn_dE']:7.3f} "
                     f"(popcorn {m['popcorn_cd']:.4f} cd/m^2 on the display); room wall "
                     f"{m['wall_cd']:.3f} cd/m^2, {m['wall_dE']:6.2f} vs black; screen "
                     f"{m['screen_cd']:5.1f} cd/m^2, {100 * m['screen_white']:3.0f} % "
                     "white")
        else:
            L.append(f"  {lab:>14}: mean display luminance {m['mean_cd']:6.1f} cd/m^2 "
                     f"({m['mean_ratio']:.2f} x the street before), "
                     f"{100 * m['white']:5.1f} % white, median Delta E ITP vs the street "
                     f"before {m['dE_median']:.2f}")
    e = emerges_min(rows)
    when = f"{e:.1f} min" if np.isfinite(e) else "never (not within 30 min)"
    L.append(f"  the popcorn reaches Delta E ITP 1 at {when}")
    return L


def sheet(results: dict, path: str, note: str = "") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ops = list(results)
    n = len(results[ops[0]])
    pr, pc = POPCORN
    zoom = (slice(pr.start - 14, pr.stop + 10), slice(pc.start - 18, pc.stop + 18))
    cw = 1.6                                       # inches a column
    hi, hz = cw * H / W + 0.3, cw * 0.5 + 0.3      # an image row, a popcorn row
    fig = plt.figure(figsize=(cw * n, (hi + hz) * len(ops) + 2.9))
    gs = fig.add_gridspec(2 * len(ops) + 1, n, height_ratios=[hi, hz] * len(ops) + [2.4],
                          hspace=0.35, wspace=0.05)
    for i, op in enumerate(ops):
        for j, (lab, _, scene, o, m) in enumerate(results[op]):
            a = fig.add_subplot(gs[2 * i, j])
            a.imshow(srgb(o), interpolation="nearest")
            a.set_xticks([])
            a.set_yticks([])
            a.set_title(lab, fontsize=8)
            if j == 0:
                a.set_ylabel(op, fontsize=10)
            b = fig.add_subplot(gs[2 * i + 1, j])
            b.set_xticks([])
            b.set_yticks([])
            if scene == "cinema":
                b.imshow(srgb(o[zoom]), interpolation="nearest")
                b.set_xlabel(f"popcorn dE {m['popcorn_dE']:.2f}", fontsize=7, labelpad=1)
            else:
                b.axis("off")
                txt = f"mean {m['mean_cd']:.0f} cd/m^2\n{100 * m['white']:.0f} % white"
                if "dE_median" in m:
                    txt += f"\nmedian dE {m['dE_median']:.1f}"
                b.text(0.5, 0.5, txt, ha="center", va="center", fontsize=7,
                       transform=b.transAxes)
            if j == 1:
                b.set_ylabel("popcorn,\nenlarged", fontsize=7)
    sub = gs[-1, :].subgridspec(1, 2, wspace=0.25)
    a1, a2 = fig.add_subplot(sub[0]), fig.add_subplot(sub[1])
    for op in ops:
        rows = results[op]
        ins = [(r[1] / 60.0, r[4]["popcorn_dE"]) for r in rows if r[2] == "cinema"]
        a1.plot(*zip(*ins), "o-", label=op)
        back = [(r[1], r[4]["mean_ratio"]) for r in rows if r[2] == "street" and r[1] > 0]
        a2.plot(*zip(*back), "o-", label=op)
    a1.axhline(1.0, color="k", ls=":", lw=1)
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.set_xlabel("minutes in the cinema")
    a1.set_ylabel("popcorn vs floor, Delta E ITP")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.axhline(1.0, color="k", ls=":", lw=1)
    a2.set_xscale("log")
    a2.set_xlabel("seconds back outside")
    a2.set_ylabel("mean display L / before")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.suptitle("Pattanaik's cinema: a sunny street, 30 minutes in a cinema, the street "
                 "again (sRGB display, white 100, black 0.1 cd/m^2)" + note, fontsize=10)
    fig.subplots_adjust(left=0.045, right=0.99, top=0.93, bottom=0.07)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "sheets", "cinema.png"),
                    help="the contact sheet (PNG; default docs/sheets/cinema.png)")
    ap.add_argument("--operators", default="pattanaik00,durand00")
    ap.add_argument("--flare", default=None, choices=("on", "off", "auto"),
                    help="the flare effect (default: the default, auto); to see what the "
                    "screen's veiling glare does")
    a = ap.parse_args(argv)
    settings = {} if a.flare is None else {"flare": a.flare}
    results = {}
    for op in a.operators.split(","):
        results[op] = run(op, **settings)
        print("\n".join(report(op, results[op])), flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)) or ".", exist_ok=True)
    sheet(results, a.out, "" if a.flare is None else f"; --flare {a.flare}")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
