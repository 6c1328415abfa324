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


# --- the shared receptor scheduler (Pattanaik et al. 2000, Sec. 4.1.2) -------------
#
# Four signals per observer: neural adaptation levels A (cd/m^2, fast, symmetric)
# and pigment bleaching B (0..1, slow, asymmetric: bleaching in light, regeneration
# over minutes in the dark) for rods and cones. pattanaik00 uses them directly;
# kirk11 and the Purkinje effect take their adaptation level from A and the rods'
# dark adaptation from B (:func:`rod_sensitivity`).

#: Neural time constants t0, s.
T0_ROD, T0_CONE = 0.150, 0.080
#: Pigment regeneration time constants tau, s.
TAU_ROD, TAU_CONE = 400.0, 110.0
#: Bleaching half-rate constants of Eq. 7 (J = T*B*G/k), cd/m^2.
K_ROD, K_CONE = 16.0, 2.2e8
#: Floor on adaptation luminance (cd/m^2) of a fully dark-adapted observer.
A_FLOOR = 1.0e-10


def bleach_static(G, k_half: float, tau: float):
    """Hunt's static bleaching factor (Pattanaik Eq. 6), k/(k + tau G): 0.04/(0.04 + A)
    for rods, 2e6/(2e6 + A) for cones; the steady state of Eq. 7."""
    G = np.maximum(np.asarray(G, np.float64), 0.0)
    return (k_half / tau) / (k_half / tau + G)


def receptor_levels_steady(G_rod: float, G_cone: float) -> dict:
    """Fully adapted to the goals: A = G, B = Eq. 6."""
    return {"A_rod": float(G_rod), "A_cone": float(G_cone),
            "B_rod": float(bleach_static(G_rod, K_ROD, TAU_ROD)),
            "B_cone": float(bleach_static(G_cone, K_CONE, TAU_CONE))}


def receptor_levels_advance(values: dict, G_rod: float, G_cone: float, dt: float) -> dict:
    """Advance A (exact exponential filters, t0 150/80 ms) and B (Eq. 7's kinetics,
    solved exactly) by ``dt`` seconds toward the goals."""
    return {
        "A_rod": exponential_step(values["A_rod"], G_rod, dt, T0_ROD),
        "A_cone": exponential_step(values["A_cone"], G_cone, dt, T0_CONE),
        "B_rod": bleaching_step(values["B_rod"], G_rod, dt, K_ROD, TAU_ROD),
        "B_cone": bleaching_step(values["B_cone"], G_cone, dt, K_CONE, TAU_CONE),
    }


def receptor_levels_preadapted(L_rod: float, L_cone: float, seconds: float | None) -> dict:
    """After a neutral field (rods see ``L_rod``, cones ``L_cone``): fully adapted
    to it, or from full dark adaptation exposed to it for ``seconds``."""
    if seconds is None:
        return receptor_levels_steady(L_rod, L_cone)
    dark = {"A_rod": A_FLOOR, "A_cone": A_FLOOR, "B_rod": 1.0, "B_cone": 1.0}
    return receptor_levels_advance(dark, L_rod, L_cone, seconds)


def rod_sensitivity(values: dict) -> float:
    """How far the rods' dark adaptation has come: B_rod over its steady value at the
    current level A_rod, in [0, 1]. 1 when adapted; right after a bright field
    (rhodopsin bleached) near 0, recovering over minutes (tau 400 s)."""
    b_inf = float(bleach_static(values["A_rod"], K_ROD, TAU_ROD))
    return float(min(1.0, max(0.0, values["B_rod"] / b_inf))) if b_inf > 0 else 0.0


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
        try:
            vals = {str(k): float(v) for k, v in dict(doc.get("values") or {}).items()}
            op = str(doc["operator"])
            t = doc.get("time_s")
            t = None if t is None else float(t)
            frame = doc.get("frame")
            frame = None if frame is None else int(frame)
            extra = dict(doc.get("extra") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"malformed adaptation state ({exc!r})") from None
        for k, v in vals.items():
            if not math.isfinite(v):
                raise ValueError(f"state value {k} is not finite ({v})")
        if t is not None and not math.isfinite(t):
            raise ValueError(f"state time {t} is not finite")
        return cls(op, vals, t, frame, extra)

    def save(self, path: str | os.PathLike, checkpoint: bool = False) -> None:
        """Write atomically (temp file in the same folder, then rename); per-pixel
        state goes first to a side file beside it, named in ``extra``:
        ``<stem>.pixels.exr``, or with ``checkpoint`` ``<stem>.pixels.<n>.exr``, a new
        name each time, so that the JSON and its planes always belong together
        whenever the writer is killed; older side files are removed after the
        JSON is replaced."""
        path = Path(path)
        doc = self.to_json()
        stem = path.name[:-len(path.suffix)] if path.suffix else path.name
        if self.pixels is not None:
            if checkpoint:
                n = 0
                while path.with_name(f"{stem}.pixels.{n}.exr").exists():
                    n += 1
                side = path.with_name(f"{stem}.pixels.{n}.exr")
            else:
                side = path.with_name(stem + ".pixels.exr")
            _write_planes(side, self.pixels)
            doc["extra"] = dict(doc["extra"], pixel_state=side.name)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        tmp.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, path)
        keep = doc["extra"].get("pixel_state")
        for old in path.parent.glob(f"{glob_escape(stem)}.pixels.*.exr"):
            if old.name != keep:
                try:
                    old.unlink()
                except OSError:
                    pass

    @classmethod
    def load(cls, path: str | os.PathLike) -> "AdaptationState":
        """From a state JSON (with its per-pixel side file), or from an output frame
        of ocl-tonemap, whose ``ocltm:state`` attribute holds the scalar state."""
        p = Path(path)
        try:
            raw = p.read_bytes()
        except OSError as exc:
            raise ValueError(f"cannot read adaptation state {path}: {exc.strerror or exc}") from None
        try:
            doc = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            doc = _state_from_image(p)
        if not isinstance(doc, dict):
            raise ValueError(f"{path} is not an ocl-tonemap adaptation state")
        st = cls.from_json(doc)
        side = st.extra.pop("pixel_state", None)    # (it names a file beside *this* JSON)
        if side:
            st.pixels = _read_planes(p.with_name(side))
        return st


def glob_escape(text: str) -> str:
    import glob
    return glob.escape(text)


def _state_from_image(path: Path) -> dict:
    """The ``ocltm:state`` attribute of an image ocl-tonemap wrote."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"{path} is neither a state JSON nor an image with ocltm:state")
    try:
        v = inp.spec().getattribute("ocltm:state")
    finally:
        inp.close()
    if not v:
        raise ValueError(f"{path} has no ocltm:state attribute (not an ocl-tonemap output?)")
    try:
        return json.loads(v)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: its ocltm:state is not JSON ({exc})") from None


def _write_planes(path: Path, planes: dict) -> None:
    """Float32 EXR, one channel per plane, written atomically."""
    import OpenImageIO as oiio
    names = list(planes)
    h, w = np.shape(planes[names[0]])
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    # uncompressed: a checkpoint is written after every frame, and zip took
    # longer than the frame (1080p ledda04: 0.4 s of a 0.9 s frame)
    spec.attribute("compression", "none")
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
