"""Adaptation state and its time integration (the host scheduler).

The state is small and explicit: a dict of named float64 scalars per operator
plus the time (s) and number of the last frame shown. It serialises to a short
JSON document so a shot can be split into chunks and resumed; per-pixel state
(later operators) travels in a side file named in the JSON.

Integrators are *exact* for a goal held constant over the step (zero-order
hold of the frame's adaptation goal), so results do not depend on the frame
rate and stay bounded for any step from 1 ms to hours.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

STATE_FORMAT = "ocl-tonemap.adaptation-state/1"


def exponential_step(value: float, goal: float, dt: float, t0: float) -> float:
    """First-order low-pass toward ``goal`` over ``dt`` seconds, time constant ``t0``.

    Exact solution of dA/dt = (G - A)/t0 with G constant: the paper's filter
    with F = 1 - exp(-T/t0) (Pattanaik 2000, Sec. 4.1.2, Fig. 6).
    """
    if dt <= 0.0:
        return value
    f = -math.expm1(-dt / t0)  # 1 - exp(-dt/t0), accurate for dt << t0
    return value + f * (goal - value)


def bleaching_step(bleach: float, goal: float, dt: float, k_half: float, tau: float) -> float:
    """Exact pigment kinetics over ``dt`` seconds (Pattanaik 2000, Eq. 7 as an ODE).

    Eq. 7's discrete step B += K(B) - J(G, B) with J = T*B*G/k, K = T*(1-B)/tau
    is the explicit Euler step of
        dB/dt = -B*G/k + (1 - B)/tau,
    which is linear in B: with r = G/k + 1/tau and B_inf = (1/tau)/r,
        B(t + dt) = B_inf + (B(t) - B_inf) * exp(-r*dt).
    B_inf = k/(k + tau*G) is Hunt's static B (Eq. 6) for k/tau = 0.04 (rods)
    and 2e6 (cones). The result stays in [0, 1] for any G >= 0 and dt >= 0,
    where the explicit step goes negative once dt*G/k > 1.
    """
    goal = max(goal, 0.0)
    r = goal / k_half + 1.0 / tau
    b_inf = (1.0 / tau) / r
    if dt <= 0.0:
        return bleach
    return b_inf + (bleach - b_inf) * math.exp(-r * dt)


@dataclass
class AdaptationState:
    """Serialisable adaptation state of one observer.

    Attributes
    ----------
    operator : name of the operator that owns ``values`` (``pattanaik00`` ...).
    values : named scalars in the papers' terms (``A_rod`` cd/m^2, ``B_rod`` 0..1 ...).
    time_s : time of the last frame shown, seconds; None before the first frame.
    frame : number of the last frame shown, or None.
    extra : operator-specific JSON-able data (e.g. the path of per-pixel state).
    pixels : per-pixel state of local operators: name -> float32 (h, w) array,
        saved beside the JSON as ``<name>.pixels.exr`` (one channel per plane).
    """

    operator: str
    values: dict = field(default_factory=dict)
    time_s: float | None = None
    frame: int | None = None
    extra: dict = field(default_factory=dict)
    pixels: dict | None = None

    def copy(self) -> "AdaptationState":
        px = None if self.pixels is None else {k: np.array(v, copy=True)
                                              for k, v in self.pixels.items()}
        return AdaptationState(self.operator, dict(self.values), self.time_s, self.frame,
                               json.loads(json.dumps(self.extra)), px)

    def to_json(self) -> dict:
        return {"format": STATE_FORMAT, "operator": self.operator, "time_s": self.time_s,
                "frame": self.frame, "values": self.values, "extra": self.extra}

    @classmethod
    def from_json(cls, doc: dict) -> "AdaptationState":
        if doc.get("format") != STATE_FORMAT:
            raise ValueError(f"not an ocl-tonemap adaptation state (format {doc.get('format')!r}, "
                             f"expected {STATE_FORMAT!r})")
        vals = {k: float(v) for k, v in doc["values"].items()}
        for k, v in vals.items():
            if not math.isfinite(v):
                raise ValueError(f"state value {k} is not finite ({v})")
        return cls(doc["operator"], vals, doc.get("time_s"), doc.get("frame"), doc.get("extra") or {})

    def save(self, path: str | os.PathLike) -> None:
        """Write atomically (temp file in the same folder, then rename); per-pixel
        state goes first to ``<stem>.pixels.exr`` beside it, named in ``extra``."""
        path = Path(path)
        doc = self.to_json()
        if self.pixels is not None:
            side = path.with_name(path.stem + ".pixels.exr")
            _write_planes(side, self.pixels)
            doc["extra"] = dict(doc["extra"], pixel_state=side.name)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        tmp.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "AdaptationState":
        try:
            doc = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"cannot read adaptation state {path}: {exc}") from exc
        st = cls.from_json(doc)
        side = st.extra.get("pixel_state")
        if side:
            st.pixels = _read_planes(Path(path).with_name(side))
        return st


def _write_planes(path: Path, planes: dict) -> None:
    """Float32 EXR, one channel per plane, written atomically."""
    import OpenImageIO as oiio
    names = list(planes)
    h, w = np.shape(planes[names[0]])
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.attribute("compression", "zip")
    data = np.ascontiguousarray(np.stack([np.asarray(planes[k], np.float32) for k in names],
                                         axis=-1))
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.exr")
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), spec):
        raise OSError(f"cannot write per-pixel state {path}: {oiio.geterror()}")
    ok = out.write_image(data)
    out.close()
    if not ok:
        raise OSError(f"cannot write per-pixel state {path}: {out.geterror()}")
    os.replace(tmp, path)


def _read_planes(path: Path) -> dict:
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"cannot read per-pixel state {path}: {oiio.geterror()}")
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    inp.close()
    if data is None:
        raise ValueError(f"cannot read per-pixel state {path}")
    data = np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
    return {name: np.array(data[..., i]) for i, name in enumerate(spec.channelnames)}
