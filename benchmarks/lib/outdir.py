"""Where a benchmark writes (issue 45): the one rule every script in ``benchmarks/`` follows.

* ``--out-dir DIR``: the folder to write into (made if missing);
* without it: ``benchmark-results/`` under the current working directory (ignored by git),
  so that running a benchmark never rewrites the committed results;
* ``--out FILE`` (where a benchmark has it): names its main file exactly and wins over
  ``--out-dir``; what the benchmark writes beside that file goes beside it.

To refresh the committed results a maintainer names them: ``--out-dir benchmarks/results``.

In a script's ``main``::

    add_out_args(ap, "psychophysics.md")
    a = ap.parse_args(argv)
    out = out_path(a, "psychophysics.md")
"""

from __future__ import annotations

import argparse
import os

#: The folder a benchmark writes into when it is given neither --out-dir nor --out,
#: relative to the current working directory.
DEFAULT_DIR = "benchmark-results"
#: The repository's root (links written into a report are made relative to it).
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def add_out_args(ap: argparse.ArgumentParser, filename: str | None = None) -> None:
    """Add ``--out-dir DIR`` and, when ``filename`` is given, ``--out FILE`` (the path of
    that one file, which wins over ``--out-dir``)."""
    ap.add_argument("--out-dir", metavar="DIR", default=None,
                    help=f"folder to write into (default: ./{DEFAULT_DIR}; to refresh the "
                    "committed results: --out-dir benchmarks/results)")
    if filename:
        ap.add_argument("--out", metavar="FILE", default=None,
                        help=f"write {filename} to this file exactly (wins over --out-dir; "
                        "anything written beside it goes to its folder)")


def out_dir(args: argparse.Namespace) -> str:
    """The folder named by ``--out-dir``, else ``./benchmark-results``; made if missing."""
    d = getattr(args, "out_dir", None) or DEFAULT_DIR
    os.makedirs(d, exist_ok=True)
    return d


def out_path(args: argparse.Namespace, filename: str) -> str:
    """The path to write ``filename`` to: ``--out`` when given, else ``filename`` in
    :func:`out_dir`. Its folder is made."""
    p = getattr(args, "out", None)
    if not p:
        return os.path.join(out_dir(args), filename)
    os.makedirs(os.path.dirname(os.path.abspath(p)) or ".", exist_ok=True)
    return p


def link(from_file: str, repo_path: str) -> str:
    """A Markdown link target to ``repo_path`` (relative to the repository's root) from a
    report written to ``from_file``: ``../../docs/validation.md`` from
    ``benchmarks/results/``, whatever folder the report was written to."""
    target = os.path.join(ROOT, repo_path)
    try:
        rel = os.path.relpath(target, os.path.dirname(os.path.abspath(from_file)))
    except ValueError:      # another drive (Windows)
        return target.replace(os.sep, "/")
    return rel.replace(os.sep, "/")


def repo_relative(path: str) -> str:
    """``path`` relative to the repository's root when it is inside it, else absolute
    (for the paths a report names in its text)."""
    p = os.path.abspath(path)
    try:
        rel = os.path.relpath(p, ROOT)
    except ValueError:
        return p
    return p if rel.startswith("..") else rel
