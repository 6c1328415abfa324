"""The grain of night vision, as an ocl-tonemap plugin effect (an example).

Scotopic vision is photon-limited: few quanta reach each rod in an integration time,
and a night scene looks grainy (Hecht, Shlaer & Pirenne 1942; simulated as noise in
the rods' share of the signal by Wanat & Mantiuk 2014). This example adds a
luminance grain to the display-linear output, its strength rising from nothing at a
cone level of 0.1 cd/m^2 to ``--night-noise-amount`` (relative, one standard
deviation) at 0.001 cd/m^2 and below. It is an illustration of the effect protocol,
not a fitted model.

What it shows of the protocol (``ocl_tonemap/effects/base.py``):

* ``name`` -> the ``--night-noise on|off|auto`` flag, the ``night_noise`` API keyword
  and settings field, and the plan's gate (``gated``: ``predict`` gives its p99
  Delta E ITP, and ``--model auto`` leaves it off where that is below one JND);
* ``options`` -> ``--night-noise-amount`` / ``night_noise_amount``;
* ``slot = "display"``: it works on display-linear frames, after the operator;
* capabilities ``host`` (whole frames) and ``banded`` (frames in row bands): the
  grain of a row depends only on the frame and the row, so a frame made in bands,
  a shot split across machines and one run give the same pixels.
"""

from __future__ import annotations

import math

import numpy as np

from ocl_tonemap.effects import Effect, EffectOption
from ocl_tonemap.base.quantities import Quantity
from ocl_tonemap.mechanisms.predict import display_ictcp, p99, sampled

#: Cone levels (cd/m^2) where the grain starts and where it is full.
GRAIN_START, GRAIN_FULL = 0.1, 0.001
#: The grain's own seed, beside the frame's number and the row.
SEED = 0x6E6F6973


def strength(G_cone: float, amount: float) -> float:
    """The grain's relative standard deviation at the cone level ``G_cone``."""
    if not (G_cone > 0.0 and math.isfinite(G_cone)):
        return amount if G_cone == 0.0 else 0.0
    t = (math.log10(GRAIN_START) - math.log10(G_cone)) / \
        (math.log10(GRAIN_START) - math.log10(GRAIN_FULL))
    return amount * min(1.0, max(0.0, t))


def frame_key(frame: int | None, time_s: float) -> int:
    """The frame's part of the seed: its number, else its time in milliseconds."""
    key = frame if frame is not None else int(round(time_s * 1000.0))
    return int(key) % 2**32


def grain(key: int, y0: int, y1: int, w: int) -> np.ndarray:
    """Unit normal grain of rows [y0, y1) (one value a pixel, float32): each row
    from its own seed, so any split into bands gives the same grain."""
    return np.stack([np.random.default_rng([SEED, key, y]).standard_normal(w, np.float32)
                     for y in range(y0, y1)]) if y1 > y0 else np.zeros((0, w), np.float32)


def apply_grain(rows: np.ndarray, y0: int, key: int, s: float) -> np.ndarray:
    """Display-linear ``rows`` (starting at row ``y0``) with the grain of strength
    ``s``: a luminance factor 1 + s n, never below 0 (black stays black)."""
    n = grain(key, y0, y0 + rows.shape[0], rows.shape[1])
    f = np.maximum(1.0 + np.float32(s) * n, 0.0)[..., None]
    out = np.array(rows, np.float32, copy=True)
    out[..., :3] *= f
    return out


class NightNoise(Effect):
    name = "night_noise"
    slot = "display"
    help = "the grain of night vision (example plugin: examples/night_noise_effect)"
    gated = True
    blends = True                     # the plan's weight scales the grain itself
    capabilities = frozenset({"host", "banded"})
    options = (EffectOption("night_noise_amount", "--night-noise-amount",
                            "relative grain (one standard deviation) at 0.001 cd/m^2 and "
                            "below (default 0.1)", metavar="A", value=0.1,
                            decl=Quantity("relative grain", "", 0.0, 10.0, above=True)),)

    def _strength(self, ctx) -> float:
        return strength(ctx.G_cone, self.fx.s.night_noise_amount) * self.fx.weight(self.name)

    def host(self, ctx, out):
        s = self._strength(ctx)
        if s <= 0.0:
            return None, {"ran": False, "strength": 0.0}
        key = frame_key(ctx.frame, ctx.time_s)
        return apply_grain(np.asarray(out, np.float32), 0, key, s), {"ran": True, "strength": s}

    def banded(self, ctx, sink, shape, block_pixels=None):
        s = self._strength(ctx)
        if s <= 0.0:
            return sink, {"ran": False, "strength": 0.0}
        key = frame_key(ctx.frame, ctx.time_s)

        def grained(y0, band):
            sink(y0, apply_grain(band, y0, key, s))
        return grained, {"ran": True, "strength": s}

    @classmethod
    def predict(cls, an, response, settings) -> float:
        """p99 Delta E ITP of the grain on the frame's sampled pixels as the operator
        shows them (a fixed grain: the same frame gets the same prediction)."""
        s = strength(an.G_cone, settings.night_noise_amount)
        if s <= 0.0:
            return 0.0
        shown = response.display_linear(sampled(an.proxy))
        n = np.random.default_rng(SEED).standard_normal(len(shown))[:, None]
        grained = shown * np.maximum(1.0 + s * n, 0.0)
        return p99(display_ictcp(shown, response.display), display_ictcp(grained, response.display))
