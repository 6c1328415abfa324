"""Operator registry: ``--operator NAME`` -> the module implementing it.

An operator module provides, in the papers' terms:

``steady_state(G_rod, G_cone)``   state values fully adapted to a goal;
``advance(values, G_rod, G_cone, dt)``   exact time step of the state;
``preadapted(L_cd, seconds)``   state after pre-adaptation to a neutral field;
``frame_params(state, display)``   per-frame scalars for the per-pixel pass;
``map_reference(rgb, Y, Ys, params)``   float64 per-pixel pass;
``map_opencl(rt, rgb, Y, Ys, out, n, params)``   the same on the device.

A global operator may take options (``OPTIONS``, a tuple of names), passed
as keywords to ``frame_params``.

A *local* operator (``LOCAL = True``) keeps per-pixel state instead and
provides ``make_observer(options, display, preadapt)``, an object with
``process_reference`` / ``process_opencl`` (one frame), ``pixel_state()`` and
``set_pixel_state()``.
"""

from __future__ import annotations

import importlib

#: name -> (module, one-line description). Later papers add to this.
REGISTRY = {
    "pattanaik00": ("ocl_tonemap.pattanaik00",
                    "Pattanaik, Tumblin, Yee & Greenberg 2000: time-dependent global adaptation"),
    "ledda04": ("ocl_tonemap.ledda04",
                "Ledda, Santos & Chalmers 2004: local (bilateral) adaptation, dark/light time course"),
    "durand00": ("ocl_tonemap.durand00",
                 "Durand & Dorsey 2000: Ferwerda threshold mapping, mesopic blue shift, "
                 "light and chromatic adaptation"),
    "kirk11": ("ocl_tonemap.kirk11",
               "Kirk & O'Brien 2011: Purkinje colour shift (rods in the cone pathways), "
               "bilateral range reduction, mesopic dimming"),
}


def get_operator(name: str):
    try:
        modname, _ = REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown operator {name!r}; available: {', '.join(sorted(REGISTRY))}") from None
    return importlib.import_module(modname)
