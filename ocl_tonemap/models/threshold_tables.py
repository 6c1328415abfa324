"""The threshold of the visibility planes as tables of log2 dL_th over log2 L_b, for a
device (``backends/opencl/visibility.py``, kernels/visibility.cl): Adrian's steady
threshold of both polarities, times a global observer's TAF, on nodes linear between
them in log-log, the nodes' segments split at Adrian's joins and at the steps of the
operator's steady gain, so that a lookup is exact there; within 5e-4 of the model
elsewhere (tests/models/test_visibility.py)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import adrian1989 as ad


#: The tables' L_b range (scene cd/m^2: a background is at least 1e-6 and at most the
#: scene ceiling 1e10), as log2, and their nodes an octave (linear in log2-log2 between
#: nodes: Adrian's smooth parts within ~2e-6, an operator's TAF kink within ~4e-4).
TABLE_LOG2 = (-20.0, 34.0)
TABLE_PER_OCTAVE = 256


@dataclass(frozen=True)
class Segments:
    """The tables' nodes: log2 L_b from TABLE_LOG2[0] to [1] in segments split at
    Adrian's joins (his fits' range edges, F_cp's), each segment's nodes uniform and
    its end nodes taken from inside it, so that a lookup is exact at a join (the fits
    step there by up to 1.6 %) and linear elsewhere. ``starts`` (log2, one per segment,
    ascending), ``steps`` (nodes per log2 unit), ``offsets`` (first node), ``nodes``
    (the log2 L_b of every node) and ``inside`` (L_b where each node is evaluated)."""

    starts: np.ndarray
    steps: np.ndarray
    offsets: np.ndarray
    nodes: np.ndarray
    inside: np.ndarray

    def as_buffer(self) -> np.ndarray:
        """float32 [n, starts..., steps..., offsets...] for a kernel."""
        return np.concatenate([[len(self.starts)], self.starts, self.steps,
                               self.offsets]).astype(np.float32)


#: A join of the tables: its log2 L_b, and the L_b just below and just above it where
#: the two segments' end nodes are evaluated (each side's value).
Join = tuple[float, float, float]


def adrian_joins(v: ad.Variant) -> tuple[Join, ...]:
    """Adrian's joins: his fits' range edges and F_cp's.

    >>> [round(2.0 ** j[0], 5) for j in adrian_joins(ad.ADRIAN_1989)]
    [0.004, 0.00418, 0.1, 0.6]
    """
    lo, hi = TABLE_LOG2
    out = {math.log2(x): (math.log2(x), float(np.nextafter(x, 0.0)), float(np.nextafter(x, np.inf)))
           for x in (ad.L_LOW, ad.L_HIGH, ad.FCP_C_SPLIT, v.fcp_low_L)
           if lo < math.log2(x) < hi}
    return tuple(out[k] for k in sorted(out))


@functools.lru_cache(maxsize=16)
def segments(joins: tuple[Join, ...]) -> Segments:
    """The tables' :class:`Segments` split at ``joins`` (ascending)."""
    lo, hi = TABLE_LOG2
    edges = [(lo, 2.0 ** lo, 2.0 ** lo), *joins, (hi, 2.0 ** hi, 2.0 ** hi)]
    starts, steps, offsets, nodes, inside = [], [], [], [], []
    for (a, _, a_right), (b, b_left, _) in zip(edges[:-1], edges[1:]):
        n = max(2, int(math.ceil((b - a) * TABLE_PER_OCTAVE)) + 1)
        x = a + (b - a) * np.arange(n) / (n - 1)
        L = 2.0 ** x
        L[0], L[-1] = a_right, b_left                 # each end from inside its segment
        starts.append(a)
        steps.append((n - 1) / (b - a))
        offsets.append(sum(len(q) for q in nodes))
        nodes.append(x)
        inside.append(L)
    return Segments(np.array(starts), np.array(steps), np.array(offsets, np.float64),
                    np.concatenate(nodes), np.concatenate(inside))


#: A cell whose midpoint its line misses by more than this (log2) holds a step.
STEP_LOG2 = 1.5e-3


def steps_of(f, seg: Segments, y: np.ndarray) -> tuple[Join, ...]:
    """The steps of ``f`` (log2 of a positive function of L_b, its values ``y`` on
    ``seg``'s nodes) as joins: each cell whose midpoint its line misses by more than
    :data:`STEP_LOG2` (a kink misses by at most ~5e-4) bisected to the step, to
    neighbouring floats of L_b."""
    x = seg.nodes
    cell = np.flatnonzero(np.diff(x) > 0)          # (the nodes a segment's end shares)
    mid = (x[cell] + x[cell + 1]) / 2
    off = np.abs(f(2.0 ** mid) - (y[cell] + y[cell + 1]) / 2) > STEP_LOG2
    out = []
    for c in cell[off]:
        a, b = 2.0 ** x[c], 2.0 ** x[c + 1]
        fa, fb = float(f(a)), float(f(b))
        while np.nextafter(a, np.inf) < b:
            m = float(np.sqrt(a) * np.sqrt(b))
            m = m if a < m < b else float(np.nextafter(a, np.inf))
            fm = float(f(m))
            if abs(fm - fa) < abs(fb - fm):
                a, fa = m, fm
            else:
                b, fb = m, fm
        out.append((math.log2(b), a, b))
    return tuple(out)


def table_lookup(table: np.ndarray, seg: Segments, Lb) -> np.ndarray:
    """What a kernel reads from ``table`` (on ``seg``'s nodes) at ``Lb``: the node's
    segment, then linear between its nodes (float64; the test of the tables)."""
    x = np.log2(np.asarray(Lb, np.float64))
    k = np.searchsorted(seg.starts, x, side="right") - 1
    k = np.clip(k, 0, len(seg.starts) - 1)
    u = (x - seg.starts[k]) * seg.steps[k]
    last = np.append(seg.offsets[1:], len(seg.nodes))[k] - 2 - seg.offsets[k]
    i = np.clip(np.floor(u), 0, last)
    f = np.clip(u - i, 0.0, 1.0)
    at = (seg.offsets[k] + i).astype(int)
    return table[at] * (1.0 - f) + table[at + 1] * f


@functools.lru_cache(maxsize=16)
def observer_segments(op, v: ad.Variant, gain: float):
    """(joins, segments, log2 of ``op``'s steady gain on their nodes x the media
    ``gain``): Adrian's joins and the steps of that gain (durand00's TVI joins step it
    by 3 %); the same every frame of a run (kept: a plugin's steady gain may be a loop)."""
    def f(L):
        return np.log2(np.maximum(op.observer_steady_slope(np.asarray(L) * gain), 1e-300))
    seg = segments(adrian_joins(v))
    joins = tuple(sorted(adrian_joins(v) + steps_of(f, seg, f(seg.inside))))
    seg = segments(joins)
    return joins, seg, f(seg.inside)


@functools.lru_cache(maxsize=16)
def _steady_rows(view, joins: tuple[Join, ...]) -> np.ndarray:
    """log2 of Adrian's steady dL_th on the nodes of ``joins``' segments, positive then
    negative: the same every frame of a run."""
    L = segments(joins).inside
    return np.stack([np.log2(view.steady(L, neg)) for neg in (False, True)])


def threshold_tables(op, obs: dict | None, view) -> tuple[Segments, np.ndarray]:
    """The device's tables of a frame on their segments (rows of the nodes, float32):
    log2 dL_th, positive then negative. ``obs`` a global observer: Adrian's steady
    threshold x TAF (clipped to 1 .. TAF_MAX at the nodes). None (a per-pixel
    observer): the steady threshold, and a third row, log2 of the operator's steady
    gain (the kernel divides by the gain now per pixel)."""
    g = view.media_gain
    joins, seg, ss = observer_segments(op, view.variant, float(g))
    st = _steady_rows(view, joins)
    if obs is None:
        return seg, np.vstack([st, ss[None]]).astype(np.float32)
    now = np.log2(np.maximum(op.observer_slope(obs, seg.inside * g), 1e-300))
    taf = np.clip(ss - now, 0.0, math.log2(ad.TAF_MAX))
    return seg, (st + taf[None]).astype(np.float32)
