"""The command line (oiiotool's table of thin commands).

``table.py``     the table of sub-commands, the parser and :func:`main`;
``options.py``   the option groups: each flag declared once, turned into job options;
``commands.py``  the sub-commands, each a thin function over the job and shot layers;
``docs.py``      docs/cli.md from the parser (``python -m ocl_tonemap.cli.docs``).
"""

from .table import build_parser, main

__all__ = ["build_parser", "main"]
