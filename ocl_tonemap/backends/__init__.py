"""Backends: where and how a frame's stages run.

``reference``  float64 NumPy, straight from the equations (``models/``): the ground
               truth, and a backend like the other.
``opencl``     float32 kernels (``kernels/*.cl``) on an OpenCL device, in row bands
               when a frame does not fit (``bands.py``).

A backend gives each operator a *schedule* (:meth:`schedule`): the object that
runs the operator's measure / integrate / apply phases on this backend. Operators
whose only per-pixel stage is pointwise share the backend's pointwise schedule;
the others name theirs (``Operator.schedules``), which lets a plugin bring its own.

Which backend a run gets: ``select.py`` (``make_backend``, ``resolve_backend``); the
protocols they keep: ``base.py``; ``--quality``'s tiers: ``quality.py``.
"""
