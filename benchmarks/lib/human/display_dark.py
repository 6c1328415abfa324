"""Dark adaptation seen on the display (Ledda, Santos & Chalmers 2004, Sec. 6.1's method;
issue 66): when does each target of a chart first show on the screen, against when a
person (Hecht, Haig & Chase 1937) would first see it?

Where ``dark.py`` reads each operator's *state* (a threshold derived from it), this
experiment looks only at the *pictures*, as Ledda's participants did: a chart of uniform
neutral square targets on black (:data:`TARGETS_CD`, log-spaced 1e-6 .. 1 cd/m^2) goes
through the public API with the default settings (``Tonemapper(op, preadapt=(L, 120))``:
``model="auto"``, effects on ``auto``, ``logmean`` metering, the sRGB display), frames at
:data:`TIMES_MIN` after the bright field goes off at t = 0.

**The display's criterion** (Ledda's paper has none: its participants "said at which
frame they started seeing the target"): a target is visible on the display when the
light the display emits for it and for the black around it differ by one just noticeable
difference, Delta E ITP >= :data:`JND` (ITU-R BT.2124). The emitted light is the
display's own: an sRGB display of white 100 and black 0.1 cd/m^2
(``DisplaySpec.from_signal``: black + (white - black) x the display-linear value,
clipped to 0..1 as the display does). The target's colour is the mean of its central
half, the surround's the mean of a ring :data:`RING_PX` outside its edge (the flare and
the acuity blur of the target's own light included, as a viewer sees them). A second
reading takes a display with no black (emitted = white x value, as ``tvi.py`` does).

**The observer's course**: Hecht's median (``dark.median_curve``) is a violet test light
(``dark.TEST_NM``: L'/L = 29.8), the chart's targets neutral (L'/L = 2.57). Stated
simplification: above the cones' plateau (``dark.data_cone_plateau()``, the median after
400 000 td at 5-12 min, taken as the cones' dark-adapted threshold after every field)
the cones see the test light, and a neutral of the same photopic luminance is seen
alike; below it the rods see the violet, and a neutral needs 29.8 / 2.57 = 11.6x its
photopic luminance for the same rod signal, or the cones' plateau, whichever is less:
neutral(t) = T(t) where T >= P, else min(P, 11.6 T(t)).

**The comparison** (the issue's: the time at which each target first shows on the
display, against the time at which the observers' threshold falls below it): for each
target the minute it first reaches :data:`JND` for good (interpolated in log Delta E
between frames), and the observers' minute for it (``hecht_first_visible``). Both sets
of (minute, target) points are read as a course the same way (``course_from_first``:
the log10 luminance just visible at each time, linear in time between the minutes at
which successive targets came into view), so that both are sampled on the same
ladder of targets, 0.125 log units a rung. Each course is taken relative to its value
at the end (the last time of Hecht's median, 29.5-39 min) and compared at the frames
within the data's range: RMS and largest absolute difference (the shape), and the
offset at the end (display minus observer: the two JNDs may differ by a factor).
Times where the display course leaves the chart (every target visible, or none) are
left out and counted. (Reading the display's course off Delta E at each time instead,
interpolated between targets, fails once the display shows a target from its
threshold on: Delta E then jumps from 0 to tens between two targets and the reading
snaps to the ladder.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import dark
from .data import HECHT_TD, log_uuL_to_cd, scotopic_photopic_ratio, trolands_to_cd

OPERATORS = ("pattanaik00", "durand00", "kirk11", "ledda04")
#: The targets, cd/m^2 (neutral): 49, 0.125 log units apart, 1e-6 .. 1 (each alone in
#: its frame; the ladder's rung is the resolution of both courses).
TARGETS_CD = 10.0 ** np.linspace(-6.0, 0.0, 49)
#: The chart's: every fourth, 0.5 log units apart (13 in one frame).
CHART_TARGETS_CD = TARGETS_CD[::4]
#: The chart: targets of TARGET_PX on a grid of COLS columns with GAP_PX of black between
#: them and around (10 px of a 170 px chart are 2.9 degrees at the default 50-degree
#: field of view: Hecht's 3-degree test field).
TARGET_PX, GAP_PX, COLS = 10, 20, 5
#: The chart's field of view, degrees (the tool's default).
CHART_FOV_DEG = 50.0
#: The surround ring: from RING_PX[0] to RING_PX[1] px outside the target's edge.
RING_PX = (5, 10)
#: One just noticeable difference on the display (BT.2124).
JND = 1.0
PREADAPT_S = dark.PREADAPT_S
#: Minutes after the field goes off (frames at these instants).
TIMES_MIN = np.unique(np.r_[np.geomspace(0.05, 1.0, 10), np.arange(1.5, 40.01, 0.5)])
#: The issue's target for the shape, log units at each time.
SHAPE_TARGET = 0.75


def chart(targets=CHART_TARGETS_CD, size=TARGET_PX, gap=GAP_PX, cols=COLS):
    """(H x W x 3 float32 frame, list of (y0, x0) corners of each target)."""
    n = len(targets)
    rows = -(-n // cols)
    H, W = rows * size + (rows + 1) * gap, cols * size + (cols + 1) * gap
    f = np.zeros((H, W, 3), np.float32)
    boxes = []
    for k, L in enumerate(targets):
        y0 = gap + (k // cols) * (size + gap)
        x0 = gap + (k % cols) * (size + gap)
        f[y0:y0 + size, x0:x0 + size] = L
        boxes.append((y0, x0))
    return f, boxes


def _masks(shape, boxes, size=TARGET_PX, ring=RING_PX):
    """Per target: (centre mask, surround ring mask)."""
    H, W = shape[:2]
    yy, xx = np.mgrid[:H, :W]
    out = []
    q = size // 4
    for y0, x0 in boxes:
        cy, cx = y0 + (size - 1) / 2.0, x0 + (size - 1) / 2.0
        d = np.maximum(np.abs(yy - cy), np.abs(xx - cx)) - (size - 1) / 2.0  # px outside
        centre = (yy >= y0 + q) & (yy < y0 + size - q) & (xx >= x0 + q) & (xx < x0 + size - q)
        out.append((centre, (d >= ring[0]) & (d <= ring[1])))
    return out


def emitted(display, v, black: bool = True) -> np.ndarray:
    """The light (cd/m^2) the display emits for display-linear ``v`` (clipped to 0..1,
    an SDR display's range): with its black (``from_signal``) or without (white x v)."""
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    return display.from_signal(v) if black else v * display.white_cd


def delta_e(display, out, masks, black: bool = True) -> np.ndarray:
    """Delta E ITP of each target's displayed colour against its surround's."""
    from ocl_tonemap.models.ictcp import delta_e_itp, rgb709_to_ictcp
    rgb = np.asarray(out, np.float64)[..., :3]
    de = []
    for centre, ring in masks:
        a = emitted(display, rgb[centre].mean(axis=0), black)
        b = emitted(display, rgb[ring].mean(axis=0), black)
        de.append(float(delta_e_itp(rgb709_to_ictcp(a), rgb709_to_ictcp(b))))
    return np.asarray(de)


def visible_from(vis) -> int | None:
    """The index from which ``vis`` holds to its end (None: its last is False)."""
    if not vis[-1]:
        return None
    k = len(vis) - 1
    while k > 0 and vis[k - 1]:
        k -= 1
    return k


def first_visible(minutes, de_col, jnd=JND) -> float:
    """Minutes at which one target first reaches ``jnd`` for good (interpolated in log
    Delta E between the frames around it); 0: from the first frame; inf: never."""
    k = visible_from(de_col >= jnd)
    if k is None:
        return np.inf
    if k == 0:
        return 0.0
    a, b = max(de_col[k - 1], 1e-12), de_col[k]
    f = (np.log10(jnd) - np.log10(a)) / (np.log10(b) - np.log10(a))
    return float(minutes[k - 1] + f * (minutes[k] - minutes[k - 1]))


def course_from_first(minutes, first, targets=TARGETS_CD) -> np.ndarray:
    """log10 cd/m^2 just visible at each of ``minutes``, from the minutes at which each
    target (ascending) first shows for good (``first``: 0 from the start, inf never):
    the dimmest target from which every brighter one is in view, linear in time toward
    the next dimmer one until it comes into view; -inf: every target in view, +inf:
    none. The time a target's rung is reached is the latest of its own and every
    brighter target's first minute, so the course never rises."""
    logL = np.log10(np.asarray(targets, float))
    reach = np.maximum.accumulate(np.asarray(first, float)[::-1])[::-1]   # all >= k seen
    out = []
    for t in np.atleast_1d(np.asarray(minutes, float)):
        k = int(np.searchsorted(-reach, -t, side="left"))     # first k with reach[k] <= t
        if k >= len(logL):
            out.append(np.inf)
        elif k == 0:
            out.append(-np.inf)
        elif not np.isfinite(reach[k - 1]):
            out.append(float(logL[k]))
        else:
            f = (t - reach[k]) / (reach[k - 1] - reach[k])
            out.append(float(logL[k] + f * (logL[k - 1] - logL[k])))
    return np.asarray(out)


# -- the observers ---------------------------------------------------------------------

def neutral_factor() -> float:
    """A neutral's photopic luminance over the violet's for the same rod signal."""
    from ocl_tonemap.models.photometry import neutral_scotopic_ratio
    return scotopic_photopic_ratio(dark.TEST_NM) / float(neutral_scotopic_ratio())


def hecht_course(td: float):
    """(minutes, log10 cd/m^2): the observers' median threshold for a neutral target
    (module docstring: the violet's above the cones' plateau, min(plateau, 11.6x) below)."""
    t, y = dark.median_curve(td)
    T = log_uuL_to_cd(y)
    P = dark.data_cone_plateau()
    n = np.where(T >= P, T, np.minimum(P, neutral_factor() * T))
    return t, np.log10(n)


def hecht_first_visible(td: float, targets=TARGETS_CD):
    """Minutes at which the observers' neutral threshold falls below each target for good
    (0: below it from the first point; inf: never within the data)."""
    t, y = hecht_course(td)
    out = []
    for L in np.log10(targets):
        k = visible_from(y <= L)
        if k is None or k == 0:
            out.append(np.inf if k is None else 0.0)
            continue
        f = (y[k - 1] - L) / (y[k - 1] - y[k])
        out.append(float(t[k - 1] + f * (t[k] - t[k - 1])))
    return np.array(out)


# -- the experiment --------------------------------------------------------------------

@dataclass
class Run:
    """One operator after one field: Delta E ITP of each target at each time."""

    op: str
    td: float
    L_pre: float
    minutes: np.ndarray
    de: np.ndarray                          # times x targets (display black)
    de_noblack: np.ndarray                  # the same without the display's black
    level: list = field(default_factory=list)   # the frame's mean display luminance
    targets: np.ndarray = field(default_factory=lambda: TARGETS_CD)

    def course(self, black: bool = True) -> np.ndarray:
        """The display's course at its frames (``course_from_first``)."""
        return self.course_at(self.minutes, black)

    def course_at(self, minutes, black: bool = True) -> np.ndarray:
        return course_from_first(minutes, self.first_visible(black), self.targets)

    def first_visible(self, black: bool = True) -> np.ndarray:
        d = self.de if black else self.de_noblack
        return np.array([first_visible(self.minutes, d[:, j]) for j in range(d.shape[1])])


#: The two layouts: each target ``alone`` in its own frame (Hecht's method, one test
#: field at a time: the primary reading), or all of them in one ``chart`` (the
#: brighter targets' veil then lies over the dimmer ones).
LAYOUTS = ("alone", "chart")
#: A lone target's frame, px (the target at its centre, at the chart's degrees a pixel).
ALONE_PX = 40


def _frames(targets, layout: str):
    """[(frame, masks, fov_deg, [target indices])]: the frames one run of ``layout``
    shows, each with its targets' masks and its field of view (the chart's degrees a
    pixel: a target is ~2.9 degrees either way)."""
    if layout == "chart":
        f, boxes = chart(targets)
        return [(f, _masks(f.shape, boxes), CHART_FOV_DEG, list(range(len(targets))))]
    out = []
    y0 = (ALONE_PX - TARGET_PX) // 2
    for k, L in enumerate(targets):
        f = np.zeros((ALONE_PX, ALONE_PX, 3), np.float32)
        f[y0:y0 + TARGET_PX, y0:y0 + TARGET_PX] = L
        out.append((f, _masks(f.shape, [(y0, y0)]),
                    CHART_FOV_DEG * ALONE_PX / chart(targets)[0].shape[1], [k]))
    return out


def simulate(op: str, td: float, times_min=TIMES_MIN, backend=None, targets=None,
             preadapt_s: float = PREADAPT_S, layout: str = "alone", **kw) -> Run:
    """The targets seen by ``op``'s default observer after ``td`` trolands for
    ``preadapt_s`` (the field goes off at t = 0), in ``layout`` (:data:`LAYOUTS`;
    ``targets`` by default :data:`TARGETS_CD` alone, :data:`CHART_TARGETS_CD` in the
    chart)."""
    from ocl_tonemap import Tonemapper
    if targets is None:
        targets = CHART_TARGETS_CD if layout == "chart" else TARGETS_CD
    targets = np.asarray(targets, float)
    L = trolands_to_cd(td)
    n = len(targets)
    de = np.zeros((len(times_min), n))
    de0 = np.zeros_like(de)
    lev = []
    for f, masks, fov, idx in _frames(targets, layout):
        tm = Tonemapper(op, backend=backend, preadapt=(L, preadapt_s), fov_deg=fov, **kw)
        tm.process(f, time_s=0.0)
        for i, t in enumerate(times_min):
            out = tm.process(f, time_s=float(t) * 60.0)
            de[i, idx] = delta_e(tm.display, out, masks, True)
            de0[i, idx] = delta_e(tm.display, out, masks, False)
            if layout == "chart":
                lev.append(float(np.mean(np.clip(out[..., :3], 0, 1)
                                         @ np.array([0.2126, 0.7152, 0.0722]))
                                 * tm.display.white_cd))
    return Run(op, td, L, np.asarray(times_min, float), de, de0, lev, targets)


@dataclass
class Score:
    """A display course against the observers' (log10 cd/m^2, relative to the end)."""

    rms_shape: float
    max_dev: float            # the largest |difference| of the relative courses
    offset: float             # display - observers at the end, log units
    n: int                    # times compared
    censored: int             # times where the display course left the chart
    end_min: float            # the minute both are taken relative to
    within: bool              # max_dev <= SHAPE_TARGET


def hecht_sampled(td: float, minutes, targets=TARGETS_CD) -> np.ndarray:
    """The observers' course read as the display's is (``course_from_first`` on their
    first minutes for the same targets)."""
    return course_from_first(minutes, hecht_first_visible(td, targets), targets)


def compare(run: Run, black: bool = True) -> tuple[Score, np.ndarray, np.ndarray, np.ndarray]:
    """(score, minutes, display relative course, observers' relative course) on the
    times of the run within the data's range, both read off their first minutes on
    the same ladder of targets."""
    t, _ = hecht_course(run.td)
    end = float(t[-1])
    m = run.minutes
    sel = (m >= t[0]) & (m <= end)
    d_at = run.course(black)[sel]
    d_end = float(run.course_at([end], black)[0])
    h_at = hecht_sampled(run.td, m[sel], run.targets)
    h_end = float(hecht_sampled(run.td, [end], run.targets)[0])
    ok = np.isfinite(d_at) & np.isfinite(h_at)
    if not (np.isfinite(d_end) and np.isfinite(h_end)):
        return (Score(np.nan, np.nan, np.nan, 0, int(sel.sum()), end, False), m[sel],
                d_at - np.nan, h_at - h_end)
    rel_d, rel_h = d_at - d_end, h_at - h_end
    diff = (rel_d - rel_h)[ok]
    sc = Score(float(np.sqrt(np.mean(diff ** 2))) if ok.any() else np.nan,
               float(np.max(np.abs(diff))) if ok.any() else np.nan,
               float(d_end - h_end), int(ok.sum()), int((~ok).sum()), end,
               bool(ok.any() and np.max(np.abs(diff)) <= SHAPE_TARGET))
    return sc, m[sel], rel_d, rel_h


def run_all(operators=OPERATORS, tds=None, times_min=TIMES_MIN, backend=None,
            layout: str = "alone"):
    """{op: {td: Run}}."""
    tds = sorted(HECHT_TD.values()) if tds is None else tds
    return {op: {td: simulate(op, td, times_min, backend, layout=layout) for td in tds}
            for op in operators}
