"""Appearance metrics of a tone-mapped still (NumPy, plus colour-science for CIELAB).

Inputs are float arrays: ``out`` the operator's display-linear output (H x W x 3,
linear Rec.709, 1.0 = display white), ``scene_Y`` / ``scene_rgb`` the scene in
cd/m^2. Luminance is Y = 0.2126 R + 0.7152 G + 0.0722 B. CIELAB uses the sRGB
(D65) white. Sections 3-4 take it after normalising each image so that its
log-average (geometric mean over Y > 0) is 0.18 (exposure does not count; unlike
the arithmetic mean it is not dominated by a light source); section 6 (magenta,
warm turned cool, hue shift against the input) takes the output as the display
shows it (clipped to 0..1, relative to display white). Used by
``benchmarks/appearance.py``; importable by tests.
"""

from __future__ import annotations

import warnings

import numpy as np

Y_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
#: Linear Rec.709 / sRGB -> CIE XYZ (D65), IEC 61966-2-1.
RGB709_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805],
                          [0.2126, 0.7152, 0.0722],
                          [0.0193, 0.1192, 0.9505]])

MAGENTA_HUES = ((300.0, 360.0), (0.0, 30.0))   #: hue angle ranges counted as "magenta/red-purple"
BLUE_HUES = (180.0, 300.0)                      #: expected scotopic hue range (blue-green to blue)


def luminance(rgb) -> np.ndarray:
    """Photopic luminance Y of linear Rec.709 RGB (float64, shape H x W)."""
    return np.asarray(rgb, np.float64)[..., :3] @ Y_WEIGHTS


def _colour():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour  # noqa: PLC0415 -- slow import, only when needed
    return colour


def to_lab(rgb, mean_Y: float = 0.18, norm: str | None = "logavg") -> np.ndarray:
    """CIELAB (D65 white, Y_white = 1) of linear Rec.709 ``rgb`` (negatives as 0)
    scaled so that its log-average luminance (``norm="logavg"``) or its mean
    (``"mean"``) is ``mean_Y`` (an all-black image stays black); ``norm=None``:
    as given (a display image: 1.0 = display white)."""
    a = np.maximum(np.asarray(rgb, np.float64)[..., :3], 0.0)
    Y = luminance(a)
    if norm is None:
        m = 0.0
    elif norm == "mean":
        m = float(Y.mean())
    else:
        pos = Y[Y > 0]
        m = float(np.exp(np.mean(np.log(pos)))) if pos.size else 0.0
    if m > 0:
        a = a * (mean_Y / m)
    colour = _colour()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cs = colour.RGB_COLOURSPACES["sRGB"]
        XYZ = colour.RGB_to_XYZ(a, cs, apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(XYZ, cs.whitepoint)


def chroma_hue(lab) -> tuple[np.ndarray, np.ndarray]:
    """(C*ab, h_ab in degrees 0..360) of CIELAB."""
    lab = np.asarray(lab)
    C = np.hypot(lab[..., 1], lab[..., 2])
    h = np.degrees(np.arctan2(lab[..., 2], lab[..., 1])) % 360.0
    return C, h


def hue_delta(h1, h2) -> np.ndarray:
    """Absolute hue difference in degrees, wrapped to 0..180."""
    d = np.abs(np.asarray(h1) - np.asarray(h2)) % 360.0
    return np.minimum(d, 360.0 - d)


def circular_median(h) -> float:
    """Median of hue angles (degrees): the angles are unwrapped around their
    circular mean before the median is taken. NaN for no angles."""
    h = np.asarray(h, np.float64).ravel()
    if h.size == 0:
        return float("nan")
    r = np.radians(h)
    centre = np.degrees(np.arctan2(np.sin(r).mean(), np.cos(r).mean()))
    rel = (h - centre + 180.0) % 360.0 - 180.0
    v = float((np.median(rel) + centre) % 360.0)
    return 0.0 if v > 360.0 - 1e-9 else v


# --- 1. brightness order ----------------------------------------------------------

def brightness_means(outputs, mask=None) -> tuple[list[float], bool]:
    """Mean output luminance of each output (ordered by increasing scene level) and
    whether it strictly increases with the level; over the pixels where ``mask``
    (e.g. not a light source) when given. ``None`` entries (an operator that
    failed) give NaN and ``False``."""
    m = None if mask is None else np.asarray(mask, bool)

    def mean(o):
        Y = luminance(o)
        return float(Y.mean() if m is None or not m.any() else Y[m].mean())
    means = [float("nan") if o is None else mean(o) for o in outputs]
    ok = all(np.isfinite(means)) and all(b > a for a, b in zip(means, means[1:]))
    return means, bool(ok)


# --- 2. clipping -------------------------------------------------------------------

def light_source_mask(scene_Y, logavg: float, factor: float = 30.0) -> np.ndarray:
    """Pixels whose scene luminance is over ``factor`` x the frame's log-average."""
    return np.asarray(scene_Y) > factor * logavg


def srgb_encode(lin) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of display-linear values in 0..1."""
    x = np.clip(np.asarray(lin, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def code_values_8bit(out) -> np.ndarray:
    """The 8-bit sRGB code values (0..255, float) a display is sent for the
    display-linear ``out`` (clipped to 0..1, encoded, rounded)."""
    return np.round(255.0 * srgb_encode(np.asarray(out)[..., :3]))


def clip_fraction(out, scene_Y, logavg: float, threshold: float = 0.999,
                  source_factor: float = 30.0, channels: str = "all",
                  eight_bit: bool = True) -> float:
    """Share of pixels at display white, among the pixels that are not light
    sources (scene Y <= ``source_factor`` x the log-average ``logavg``).

    At white: ``channels="all"`` three (``"any"``: any one) channels whose 8-bit
    sRGB code value / 255 is >= ``threshold`` (0.999: code 255, i.e. display-linear
    >= 0.9956); ``eight_bit=False`` compares the display-linear value itself.
    Target: < 2%."""
    o = np.asarray(out)[..., :3]
    keep = ~light_source_mask(scene_Y, logavg, source_factor)
    n = int(keep.sum())
    if n == 0:
        return 0.0
    v = code_values_8bit(o) / 255.0 if eight_bit else o
    at = v >= threshold
    clipped = (np.all(at, axis=-1) if channels == "all" else np.any(at, axis=-1)) & keep
    return float(clipped.sum()) / n


# --- 3. photopic hue ----------------------------------------------------------------

def hue_difference_deg(out, ref, min_chroma: float = 10.0, mask=None) -> float:
    """Median absolute CIELAB hue difference (degrees, wrapped) between ``out`` and
    the reference rendering ``ref`` (both display-linear Rec.709, each normalised to
    log-average Y 0.18), over the pixels whose reference chroma C*ab > ``min_chroma``
    (and where ``mask``, e.g. not a light source, when given). NaN when no pixel
    is that colourful. Target (photopic levels): < 5 degrees."""
    C_ref, h_ref = chroma_hue(to_lab(ref))
    _, h_out = chroma_hue(to_lab(out))
    m = C_ref > min_chroma
    if mask is not None:
        m &= np.asarray(mask, bool)
    if not m.any():
        return float("nan")
    return float(np.median(hue_delta(h_out[m], h_ref[m])))


# --- 4. scotopic colour ---------------------------------------------------------------

def _in_ranges(h, ranges) -> np.ndarray:
    h = np.asarray(h)
    m = np.zeros(h.shape, bool)
    for lo, hi in ranges:
        m |= (h >= lo) & (h < hi)
    return m


def scotopic_colour(out, out_day, scene_rgb, neutral_chroma: float = 5.0,
                    min_out_chroma: float = 2.0, magenta_chroma: float = 5.0,
                    min_share: float = 0.01) -> dict:
    """Colour of a dark (scotopic) rendering ``out`` against the same operator's
    rendering of the same scene at a photopic level, ``out_day``.

    Returns a dict:
      ``chroma`` / ``chroma_day`` / ``chroma_scene``: median C*ab of ``out`` /
      ``out_day`` / the scene itself (each normalised to log-average Y 0.18);
      ``chroma_lower``: ``chroma < chroma_day`` (colour fades at night);
      ``neutral_hue``: circular median hue of ``out`` over the scene's near-neutral
      pixels (scene C* < ``neutral_chroma``) where the output has C* > ``min_out_chroma``
      (NaN when they are under ``min_share`` of the image), ``neutral_n`` their share
      of all pixels, ``neutral_blue``:
      the hue lies in 180..300 degrees (blue-green to blue, the expected night tint);
      ``magenta_share``: share of all pixels whose output hue is in 300..360 or
      0..30 degrees with C* > ``magenta_chroma`` although the scene's hue there was
      not (or the scene pixel was near-neutral).
    """
    C, h = chroma_hue(to_lab(out))
    C_day, _ = chroma_hue(to_lab(out_day))
    C_s, h_s = chroma_hue(to_lab(scene_rgb))
    neutral = (C_s < neutral_chroma) & (C > min_out_chroma)
    nh = circular_median(h[neutral]) if neutral.mean() >= min_share else float("nan")
    scene_mag = _in_ranges(h_s, MAGENTA_HUES) & (C_s >= neutral_chroma)
    pushed = _in_ranges(h, MAGENTA_HUES) & (C > magenta_chroma) & ~scene_mag
    res = {
        "chroma": float(np.median(C)),
        "chroma_day": float(np.median(C_day)),
        "chroma_scene": float(np.median(C_s)),
        "neutral_hue": nh,
        "neutral_n": float(neutral.mean()),
        "magenta_share": float(pushed.mean()),
    }
    res["chroma_lower"] = bool(res["chroma"] < res["chroma_day"])
    res["neutral_blue"] = bool(np.isfinite(nh) and BLUE_HUES[0] <= nh <= BLUE_HUES[1])
    return res


# --- 5. artefacts -----------------------------------------------------------------------

def log_luminance(Y, rel_floor: float = 1e-4) -> np.ndarray:
    """log10(Y + floor), the floor ``rel_floor`` x the image's geometric-mean
    luminance (so that black and noise do not make gradients; scale-free)."""
    Y = np.maximum(np.asarray(Y, np.float64), 0.0)
    pos = Y[Y > 0]
    g = float(np.exp(np.mean(np.log(pos)))) if pos.size else 1.0
    return np.log10(Y + rel_floor * g)


def gradient_reversal(scene_Y, out_Y, scales=(1, 4, 16), min_grad: float = 0.05,
                      out_tol: float = 1e-3, rel_floor: float = 1e-4) -> dict:
    """Gradient reversal (halo) share between scene and output luminance.

    Log-luminance differences between pixels ``s`` apart horizontally and
    vertically, for each ``s`` in ``scales``; among the pairs whose scene
    difference exceeds ``min_grad`` decades, the share where the output goes the
    other way (opposite sign and more than ``out_tol`` decades; a flat output is
    lost detail, not a reversal). Returns ``{"all": share over all scales,
    s: share at scale s}``. Target: < 1%.
    """
    ls, lo = log_luminance(scene_Y, rel_floor), log_luminance(out_Y, rel_floor)
    res, tot_n, tot_r = {}, 0, 0
    for s in scales:
        n = r = 0
        for ds, do in ((ls[:, s:] - ls[:, :-s], lo[:, s:] - lo[:, :-s]),
                       (ls[s:, :] - ls[:-s, :], lo[s:, :] - lo[:-s, :])):
            m = np.abs(ds) > min_grad
            n += int(m.sum())
            r += int((m & (np.sign(ds) * do < -out_tol)).sum())
        res[s] = r / n if n else 0.0
        tot_n += n
        tot_r += r
    res["all"] = tot_r / tot_n if tot_n else 0.0
    return res


def _ranks(x) -> np.ndarray:
    """Ranks 1..n with ties given their average rank."""
    x = np.asarray(x).ravel()
    _, inv, counts = np.unique(x, return_inverse=True, return_counts=True)
    ends = np.cumsum(counts)
    avg = ends - (counts - 1) / 2.0
    return avg[inv]


def spearman(scene_Y, out_Y) -> float:
    """Spearman rank correlation of scene and output luminance over all pixels
    (ties ranked by their average). Target: >= 0.9 for local operators."""
    a, b = _ranks(scene_Y), _ranks(out_Y)
    a = a - a.mean()
    b = b - b.mean()
    d = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / d) if d > 0 else float("nan")


#: CIE 191:2010 MES2 constants: m = a + b log10(L_mes); V'(lambda_0) = 683/1699.
MES2_A, MES2_B, V_PRIME_0 = 0.7670, 0.3334, 683.0 / 1699.0


def mesopic_weight(L_p: float, L_s: float, iterations: int = 50) -> float:
    """The CIE 191:2010 (MES2) mesopic adaptation coefficient m of a visual field
    with photopic luminance ``L_p`` and scotopic ``L_s`` (cd/m^2): 1 when photopic
    (L_mes >= 5), 0 when scotopic (<= 0.005), iterated between."""
    m = 0.5
    for _ in range(iterations):
        L_mes = (m * L_p + (1.0 - m) * L_s * V_PRIME_0) / (m + (1.0 - m) * V_PRIME_0)
        m_new = float(np.clip(MES2_A + MES2_B * np.log10(max(L_mes, 1e-30)), 0.0, 1.0))
        if abs(m_new - m) < 1e-9:
            break
        m = m_new
    return m


def mesopic_luminance(rgb_cd, m: float | None = None) -> np.ndarray:
    """Per-pixel CIE 191 mesopic luminance of scene RGB (cd/m^2, linear Rec.709),
    with the field's m (default: from the image's log-average photopic and scotopic
    luminances). At night pixels are ordered by V' (the Purkinje shift a person
    sees), by day by V: the luminance whose order a tone mapper should keep."""
    from ocl_tonemap.models.photometry import scotopic_luminance
    rgb = np.maximum(np.asarray(rgb_cd, np.float64)[..., :3], 0.0)
    Y, Ys = luminance(rgb), scotopic_luminance(rgb)
    if m is None:
        def la(x):
            pos = x[x > 0]
            return float(np.exp(np.mean(np.log(pos)))) if pos.size else 0.0
        m = mesopic_weight(la(Y), la(Ys))
    return (m * Y + (1.0 - m) * Ys * V_PRIME_0) / (m + (1.0 - m) * V_PRIME_0)


# --- 6. colour on the display (the measures) -------------------------------------
#
# ``out`` is what the display is sent: display-linear Rec.709, 1.0 = display white,
# taken as shown (clipped to 0..1); CIELAB relative to display white (no exposure
# normalisation: a dim night rendering has little chroma, as a person sees it).
# ``keep``: the pixels measured (not light sources: scene Y <= 30 x log-average).

MAGENTA_RANGE = (290.0, 350.0)        #: CIELAB hue angles counted as magenta
MAGENTA_CHROMA = 15.0                 #: ... with C*ab above this


def shown(out) -> np.ndarray:
    """The display-linear image as the display shows it: clipped to 0..1."""
    return np.clip(np.asarray(out, np.float64)[..., :3], 0.0, 1.0)


def _keep(shape, keep) -> np.ndarray:
    return np.ones(shape, bool) if keep is None else np.asarray(keep, bool)


def hue_preserving_render(scene_rgb) -> np.ndarray:
    """A plain, hue-preserving rendering of the scene: scaled so that its log-average
    luminance is 0.18, then the global curve Y/(1+Y) on luminance with the RGB
    ratios kept (``rgb / (1 + Y)``); display-linear, may exceed 1 where saturated."""
    a = np.maximum(np.asarray(scene_rgb, np.float64)[..., :3], 0.0)
    Y = luminance(a)
    pos = Y[Y > 0]
    if pos.size:
        a = a * (0.18 / float(np.exp(np.mean(np.log(pos)))))
    return a / (1.0 + luminance(a))[..., None]


def magenta_share(display_rgb, keep=None, hues=MAGENTA_RANGE,
                  min_chroma: float = MAGENTA_CHROMA) -> float:
    """Share of the ``keep`` pixels of a display image (as shown) whose CIELAB hue
    lies in ``hues`` (290-350 degrees) with chroma C*ab > ``min_chroma`` (15).

    CIELAB's hue of a saturated deep blue lies in that range too (the Rec.709 blue
    primary: 306 degrees; (0.1, 0.1, 0.5): 298): :func:`magenta_excess` subtracts
    the photograph's own share for that reason."""
    C, h = chroma_hue(to_lab(shown(display_rgb), norm=None))
    k = _keep(C.shape, keep)
    n = int(k.sum())
    if n == 0:
        return 0.0
    mag = (h >= hues[0]) & (h <= hues[1]) & (C > min_chroma) & k
    return float(mag.sum()) / n


def magenta_excess(out, scene_rgb, keep=None) -> dict:
    """Magenta the operator adds: :func:`magenta_share` of ``out`` minus that of
    :func:`hue_preserving_render` of the scene (the photograph's own magenta), over
    the ``keep`` pixels. Returns ``{"excess", "share", "ref_share"}``; target:
    excess <= 1%."""
    share = magenta_share(out, keep)
    ref = magenta_share(hue_preserving_render(scene_rgb), keep)
    return {"excess": share - ref, "share": share, "ref_share": ref}


def warm_to_cool(out, scene_rgb, keep=None, warm: float = 1.3, cool: float = 1.15) -> dict:
    """Warm scene pixels shown cool: share of the ``keep`` pixels whose scene has
    R > ``warm`` x B (1.3) and whose output (as shown) has B > ``cool`` x R (1.15).
    Returns ``{"share"`` (of the kept pixels; target < 5% at >= 10 cd/m^2),
    ``"of_warm"`` (of the kept warm pixels), ``"warm"`` (the warm pixels' share)}."""
    s = np.maximum(np.asarray(scene_rgb, np.float64)[..., :3], 0.0)
    o = shown(out)
    k = _keep(s.shape[:-1], keep)
    n = int(k.sum())
    w = (s[..., 0] > warm * s[..., 2]) & k
    turned = w & (o[..., 2] > cool * o[..., 0])
    nw = int(w.sum())
    return {"share": float(turned.sum()) / n if n else 0.0,
            "of_warm": float(turned.sum()) / nw if nw else 0.0,
            "warm": float(nw) / n if n else 0.0}


def hue_shift_deg(out, scene_rgb, keep=None, min_in_chroma: float = 8.0,
                  min_out_chroma: float = 4.0, pct: float = 99.0) -> float:
    """Median CIELAB hue difference (degrees, wrapped to 0..180) between the output
    (as shown, relative to display white) and the input scene scaled so that the
    ``pct`` (99th) percentile of its luminance over the ``keep`` pixels is 1, over
    the ``keep`` pixels with input C*ab > ``min_in_chroma`` (8) and output C*ab >
    ``min_out_chroma`` (4). NaN when no pixel qualifies. Target: <= 15 degrees at
    >= 100 cd/m^2."""
    s = np.maximum(np.asarray(scene_rgb, np.float64)[..., :3], 0.0)
    k = _keep(s.shape[:-1], keep)
    Y = luminance(s)
    top = float(np.percentile(Y[k], pct)) if k.any() else 0.0
    if top > 0:
        s = s / top
    C_in, h_in = chroma_hue(to_lab(s, norm=None))
    C_out, h_out = chroma_hue(to_lab(shown(out), norm=None))
    m = k & (C_in > min_in_chroma) & (C_out > min_out_chroma)
    if not m.any():
        return float("nan")
    return float(np.median(hue_delta(h_out[m], h_in[m])))


def _line_steps(g, k: float, floor: float):
    """Where a neighbour difference along rows (and, transposed, columns) is at least
    ``k`` x the median of the 9 differences around it (and at least ``k`` x ``floor``):
    a step on otherwise smooth ground. (row mask, column mask)."""
    from numpy.lib.stride_tricks import sliding_window_view
    out = []
    for axis in (1, 0):
        d = np.abs(np.diff(g, axis=axis))
        dd = d if axis == 1 else d.T
        m = np.median(sliding_window_view(np.pad(dd, ((0, 0), (4, 4)), mode="edge"), 9,
                                          axis=1), axis=-1)
        s = dd >= k * np.maximum(m, floor)
        out.append(s if axis == 1 else s.T)
    return out


def step_artefacts(codes, scene_rgb) -> float:
    """The share of pixels where the display shows a step the scene does not have:
    8-bit code values (H x W x 3) stepping by at least 3 codes where the 9 steps around
    are at most a code, more than 2 pixels from any step of the scene's log luminance
    (its own edges). The stepped rings and halos of a time course restarted pixel by
    pixel on a smooth field (docs/models.md, ledda04's time course)."""
    from numpy.lib.stride_tricks import sliding_window_view
    g = np.asarray(codes, np.float64)[..., :3].mean(axis=2)
    L = np.log10(np.maximum(luminance(scene_rgb), 1e-6))
    sx, sy = _line_steps(g, 3.0, 1.0)
    ex, ey = _line_steps(L, 3.0, 0.01)
    edge = np.zeros(g.shape, bool)
    edge[:, 1:] |= ex
    edge[:, :-1] |= ex
    edge[1:] |= ey
    edge[:-1] |= ey
    near = sliding_window_view(np.pad(edge, 2), (5, 5)).any(axis=(-1, -2))
    art = np.zeros(g.shape, bool)
    art[:, 1:] |= sx & ~near[:, 1:]
    art[1:] |= sy & ~near[1:]
    return float(art.mean())


# --- 7. saturation kept (issue 67) ----------------------------------------------------------

def rgb_saturation(rgb) -> np.ndarray:
    """Saturation s = 1 - min/max of linear RGB (negatives as 0; 0 where max is 0):
    0 for a grey, 1 for a primary; unchanged by scaling, so a hue- and
    ratio-preserving rendering keeps it."""
    a = np.maximum(np.asarray(rgb, np.float64)[..., :3], 0.0)
    mx, mn = a.max(axis=-1), a.min(axis=-1)
    return np.where(mx > 0, 1.0 - mn / np.where(mx > 0, mx, 1.0), 0.0)


def saturation_ratio(out, scene_rgb, logavg: float, lo: float = 0.25, hi: float = 4.0,
                     min_sat: float = 0.15, source_factor: float = 30.0) -> dict:
    """How much of the scene's colour saturation the output keeps, on coloured mid-tones.

    Over the pixels whose scene luminance is ``lo``..``hi`` (0.25-4) x the frame's
    log-average ``logavg`` (so no light source: those are > 30 x), whose scene
    saturation :func:`rgb_saturation` is > ``min_sat`` (0.15) and whose output has no
    channel at 8-bit code 255 (not clipped), the median of s_out / s_scene, s taken on
    linear light of the output (display-linear, negatives as 0) and of the scene.
    A rendering that keeps the RGB ratios (any exposure, hue-preserving curve on
    luminance) gives 1; a map that pulls colours to grey < 1, one that boosts them > 1.
    Target: 0.5-1.6 at daylight (5000) and interior (30) levels; lower at dusk and
    night, where the rods take over. Returns ``{"ratio"`` (NaN when no pixel
    qualifies), ``"n"`` (share of all pixels measured)}."""
    s_in = np.asarray(scene_rgb, np.float64)[..., :3]
    o = np.asarray(out, np.float64)[..., :3]
    Y = luminance(s_in)
    src = light_source_mask(Y, logavg, source_factor)
    ss = rgb_saturation(s_in)
    not_clipped = ~np.any(code_values_8bit(o) >= 255.0, axis=-1)
    m = ((Y >= lo * logavg) & (Y <= hi * logavg) & (ss > min_sat) & not_clipped & ~src
         & (np.maximum(o, 0.0).max(axis=-1) > 0))
    if not m.any():
        return {"ratio": float("nan"), "n": 0.0}
    return {"ratio": float(np.median(rgb_saturation(o[m]) / ss[m])), "n": float(m.mean())}
