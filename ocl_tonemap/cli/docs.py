"""The command-line reference, ``docs/cli.md``, written from the parser itself.

``python -m ocl_tonemap.cli.docs`` writes it (``--out PATH`` elsewhere);
``python -m ocl_tonemap.cli.docs --check`` exits 1 when the file differs from what the
parser gives now. Everything comes from :func:`ocl_tonemap.cli.table.build_parser`: the
sub-commands (its ``_SubParsersAction``), each one's usage, and each argument group's
title and options with their flags, metavar, choices, default and help, in the order
``--help`` shows them. Options a sub-command accepts without listing them (the run
options of the shot passes) are left out there, as its help leaves them out.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
from pathlib import Path

from .table import build_parser

#: Where the reference lives, from the repository root.
DEFAULT_PATH = Path("docs") / "cli.md"
#: The width usage lines are wrapped at (fixed: the file must not depend on a terminal).
WIDTH = 88
GENERATOR = "python -m ocl_tonemap.cli.docs"


def _shown(action: argparse.Action) -> bool:
    return action.help is not argparse.SUPPRESS and not isinstance(
        action, (argparse._HelpAction, argparse._SubParsersAction))


def _formatter(prog: str) -> argparse.HelpFormatter:
    """argparse's formatter at the fixed width, never coloured (Python 3.14 colours help
    on a terminal)."""
    try:
        return argparse.HelpFormatter(prog=prog, width=WIDTH, color=False)
    except TypeError:                     # before Python 3.14: no colour argument
        return argparse.HelpFormatter(prog=prog, width=WIDTH)


def _help_text(action: argparse.Action, prog: str) -> str:
    """The help string as ``--help`` prints it (``%(default)s`` expanded, ``%%`` one
    ``%``), on one line."""
    text = action.help or ""
    if text:
        try:
            text = _formatter(prog)._expand_help(action)
        except (KeyError, TypeError, ValueError):
            pass
    return " ".join(text.split())


def _md(text: str) -> str:
    """Plain text safe in Markdown prose."""
    text = text.replace("\\", "\\\\").replace("&", "&amp;").replace("<", "&lt;")
    text = text.replace(">", "&gt;")
    return re.sub(r"([*_`\[\]|])", r"\\\1", text)


def _value(action: argparse.Action) -> str:
    """What follows the flag: the choices, else the metavar, else the dest in capitals."""
    if action.nargs == 0:
        return ""
    if action.choices is not None:
        return "|".join(map(str, action.choices))
    if action.metavar is not None:
        return action.metavar if isinstance(action.metavar, str) else " ".join(action.metavar)
    return action.dest.upper() if action.option_strings else action.dest


def _invocation(action: argparse.Action) -> str:
    value = _value(action)
    if not action.option_strings:
        return f"`{value}`"
    flags = [f"`{o}`" for o in action.option_strings]
    if value:
        flags[-1] = f"`{action.option_strings[-1]} {value}`"
    return ", ".join(flags)


def _default(action: argparse.Action) -> str | None:
    d = action.default
    if action.nargs == 0 or d is None or d is argparse.SUPPRESS or not action.option_strings:
        return None
    if not isinstance(d, (str, int, float)):
        return None        # a parsed value (a size's tuple): its help says it as typed
    return str(d)


def _item(action: argparse.Action, prog: str) -> str:
    notes = []
    if getattr(action, "required", False) and action.option_strings:
        notes.append("required")
    d = _default(action)
    if d is not None:
        notes.append(f"default `{d}`")
    head = _invocation(action) + (f" ({'; '.join(notes)})" if notes else "")
    text = _md(_help_text(action, prog))
    return f"- {head}" + (f": {text}" if text else "")


def _usage(p: argparse.ArgumentParser) -> str:
    fmt = _formatter(p.prog)
    fmt.add_usage(p.usage, p._actions, p._mutually_exclusive_groups)
    return "\n".join(line.rstrip() for line in fmt.format_help().strip().splitlines())


def _groups(p: argparse.ArgumentParser) -> list[str]:
    out = []
    for g in p._action_groups:
        actions = [a for a in g._group_actions if _shown(a)]
        if actions:
            out += ["", f"**{_md(g.title or 'options')}**", ""]
            out += [_item(a, p.prog) for a in actions]
    return out


def _command(name: str, p: argparse.ArgumentParser, summary: str) -> list[str]:
    text = summary
    if p.description and p.description.startswith(summary):
        text = p.description                      # the summary and what it adds
    elif p.description:
        text = f"{summary}\n\n{p.description}" if summary else p.description
    out = ["", f"## `{p.prog}`", ""]
    out += [_md(" ".join(par.split())) for par in text.split("\n\n")]
    out += ["", "```text", _usage(p), "```"]
    return out + _groups(p)


@contextlib.contextmanager
def _builtin_only():
    """The parser with the built-in operators and effects only: the plugins an
    installation happens to have (entry points) left out, the registries' caches
    cleared before and after so the process sees its plugins again."""
    import importlib.metadata as md
    # lazy: the registries, imported where the parser is built with built-ins only
    from ..effects import settings
    from ..operators import ENTRY_POINT_GROUP, registry  # lazy: as above

    plugin_groups = {ENTRY_POINT_GROUP, "ocl_tonemap.effects"}
    real = md.entry_points

    def entry_points(**kw):
        if kw.get("group") in plugin_groups:
            return md.EntryPoints(())
        return real(**kw)

    caches = [registry, settings.registry, settings.options]
    for c in caches:
        c.cache_clear()
    md.entry_points = entry_points
    try:
        yield
    finally:
        md.entry_points = real
        for c in caches:
            c.cache_clear()


def render(parser: argparse.ArgumentParser | None = None) -> str:
    """docs/cli.md for ``parser`` (default: the whole command line)."""
    if parser is None:
        with _builtin_only():
            return render(build_parser())
    ap = parser
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    summaries = {c.dest: c.help or "" for c in sub._choices_actions}
    out = ["# Command-line reference", "",
           f"<!-- Written by `{GENERATOR}` from the parser; do not edit by hand. "
           f"`{GENERATOR} --check` exits 1 when this file is stale. -->", "",
           f"Every sub-command of `{ap.prog}`, its usage and its options in the groups its "
           "`--help` shows, each with its value (the choices, or what to give), its "
           f"default and its help. Generated from the parser by `{GENERATOR}`; the "
           "[README](../README.md) has examples, the [guide](guide.md) the meaning.", "",
           _md(ap.description or ""), "", "```text", _usage(ap), "```"]
    out += _groups(ap)
    out += ["", "| sub-command | what it does |", "|---|---|"]
    for name, p in sub.choices.items():
        anchor = re.sub(r"[^\w\- ]", "", p.prog.lower()).replace(" ", "-")
        out.append(f"| [`{name}`](#{anchor}) | {_md(summaries.get(name, ''))} |")
    for name, p in sub.choices.items():
        out += _command(name, p, summaries.get(name, ""))
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=GENERATOR, description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_PATH,
                    help=f"the file to write or check (default {DEFAULT_PATH})")
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 when the file is not what the parser gives")
    a = ap.parse_args(argv)
    text = render()
    if a.check:
        current = a.out.read_text(encoding="utf-8") if a.out.is_file() else None
        if current != text:
            print(f"{a.out} is stale: run {GENERATOR}", file=sys.stderr)
            return 1
        return 0
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
