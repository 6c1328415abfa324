"""A shot on many machines: measure -> integrate -> apply (``passes.py``), the
per-shot statistics store (``store.py``), the Dask scheduler (``distributed.py``)
and render-farm job templates (``farm.py``)."""

from .passes import apply, default_store, integrate, measure  # noqa: F401
from .store import ShotStore  # noqa: F401
