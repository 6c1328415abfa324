"""The package's version (its own module: every layer names it, and the package's
``__init__`` is the top of the layers, ``docs/architecture.md``)."""

__version__ = "0.1.0"
