"""Every file an OCIO processor reads, checked before OCIO opens it (issue 65).

OCIO reads a config's LUTs (``FileTransform`` ``src``: .cube, .clf, .spi3d ...) inside
``Config.getProcessor``, holding the interpreter: a LUT that is a FIFO waits there for
a writer for ever, ``/dev/zero`` is read until memory runs out, and neither a signal
handler nor the watchdog thread (``interrupts.arm``) can run meanwhile. So every
processor the tool builds is made here (:func:`processor`, :func:`cpu_processor`):

1. the transforms it would use are walked (the colourspaces' to- and from-reference
   transforms, the view's view transform, colourspace and looks, each look's
   transforms and process space, named transforms, the default view transform
   between scene- and display-referred colourspaces, ``GroupTransform`` children,
   ``ColorSpaceTransform``, ``DisplayViewTransform`` and ``LookTransform``
   indirections, recursively; both directions: a broken file in either is refused);
2. each ``FileTransform``'s ``src`` is found as OCIO finds it
   (``Context.resolveFileLocation``: the context's variables, the search path, the
   config's working folder; it only ``stat``\\s, OCIO's ``FileExists`` being
   ``Platform::CreateFileContentHash``), and must be a regular file (links
   followed), readable, at most :data:`LUT_CAP` bytes, else :class:`LutFileError`:
   ``<config>: its view 'Raw' of display 'sRGB' (through colourspace 'out') reads LUT
   <path>: is a named pipe (FIFO), not a file``;
3. OCIO's own failure to build it (a LUT it cannot parse, whose message may not even
   be text) is one line naming the LUT that fails alone, when one does, and the
   config.

A LUT OCIO cannot locate is left to OCIO's own words (then as in 3): it may sit in a
direction of a colourspace the processor does not use. Built-in configs
(``ocio://``) have no files.
"""

from __future__ import annotations

import os
import re

import PyOpenColorIO as ocio

from ..base.safeio import file_kind
from .config import USE_DISPLAY_NAME, ColourError, config_source

#: Largest LUT file OCIO is let read: 256 MiB. The largest tables in use are 3D LUTs of
#: 65^3 to 129^3 nodes (a 65^3 .cube is ~9 MiB of text, 129^3 ~70 MiB; a CLF a little
#: more); a larger "LUT" is not one, and reading it (``/dev/zero`` has no end) would
#: take the memory inside OCIO, where no signal reaches.
LUT_CAP = 256 << 20


class LutFileError(ColourError):
    """A file a config's processor would read that is refused, or that OCIO cannot read:
    ``<config>: its <where> reads LUT <path>: <why>``."""

    def __init__(self, config: str, lut: str, why: str, where: str = ""):
        self.config, self.lut, self.why, self.where = config, str(lut), why, where
        super().__init__(f"{config}: {'its ' + where + ' ' if where else ''}reads LUT "
                         f"{self.lut}: {why}")


class _Walk:
    """The ``FileTransform``\\s a processor would use, each with where it was found."""

    def __init__(self, cfg, ctx):
        self.cfg, self.ctx = cfg, ctx
        self.seen: set = set()
        self.refs: set = set()              # reference space types met (scene, display)
        self.found: list = []               # (FileTransform, [labels from the top])

    def _name(self, name: str) -> str:
        try:
            return self.ctx.resolveStringVar(name) or name
        except Exception:  # noqa: BLE001 -- OCIO's own Exception: the name as written
            return name

    def _once(self, key) -> bool:
        if key in self.seen:
            return False
        self.seen.add(key)
        return True

    def space(self, name: str, chain: list) -> None:
        """A colourspace (a role, an alias) or a named transform, by name."""
        if not name:
            return
        name = self._name(name)
        cs = self.cfg.getColorSpace(name)
        if cs is not None:
            if self._once(("cs", cs.getName())):
                self.refs.add(cs.getReferenceSpaceType())
                c = chain + [f"colourspace {cs.getName()!r}"]
                for d in (ocio.COLORSPACE_DIR_TO_REFERENCE, ocio.COLORSPACE_DIR_FROM_REFERENCE):
                    self.transform(cs.getTransform(d), c)
            return
        get = getattr(self.cfg, "getNamedTransform", None)
        nt = get(name) if get is not None else None
        if nt is not None:
            self.named(nt, chain)

    def named(self, nt, chain: list) -> None:
        if self._once(("nt", nt.getName())):
            c = chain + [f"named transform {nt.getName()!r}"]
            for d in (ocio.TRANSFORM_DIR_FORWARD, ocio.TRANSFORM_DIR_INVERSE):
                self.transform(nt.getTransform(d), c)

    def view_transform(self, name: str, chain: list) -> None:
        vt = self.cfg.getViewTransform(name)
        if vt is None:
            get = getattr(self.cfg, "getNamedTransform", None)
            nt = get(name) if get is not None else None
            if nt is not None:
                self.named(nt, chain)
            return
        self._view_transform(vt, chain)

    def _view_transform(self, vt, chain: list) -> None:
        if self._once(("vt", vt.getName())):
            self.refs.add(vt.getReferenceSpaceType())
            c = chain + [f"view transform {vt.getName()!r}"]
            for d in (ocio.VIEWTRANSFORM_DIR_TO_REFERENCE, ocio.VIEWTRANSFORM_DIR_FROM_REFERENCE):
                self.transform(vt.getTransform(d), c)

    def looks(self, spec: str, chain: list) -> None:
        """A looks string (``+grade, -film|alt``): every look it names, alternatives too."""
        for token in re.split(r"[,:|]", spec or ""):
            name = token.strip().lstrip("+-").strip()
            look = self.cfg.getLook(name) if name else None
            if look is None or not self._once(("look", look.getName())):
                continue
            c = chain + [f"look {look.getName()!r}"]
            self.transform(look.getTransform(), c)
            self.transform(look.getInverseTransform(), c)
            self.space(look.getProcessSpace(), c)

    def display_view(self, src: str, display: str, view: str, chain: list,
                     looks: bool = True) -> None:
        self.space(src, chain)
        c = chain + [f"view {view!r} of display {display!r}"]
        vt = self.cfg.getDisplayViewTransformName(display, view)
        if vt:
            self.view_transform(vt, c)
        cs = self.cfg.getDisplayViewColorSpaceName(display, view)
        self.space(display if cs == USE_DISPLAY_NAME else cs, c)
        if looks:
            self.looks(self.cfg.getDisplayViewLooks(display, view), c)

    def transform(self, t, chain: list) -> None:
        if t is None:
            return
        if isinstance(t, ocio.GroupTransform):
            for child in t:
                self.transform(child, chain)
        elif isinstance(t, ocio.FileTransform):
            self.found.append((t, chain))
        elif isinstance(t, ocio.ColorSpaceTransform):
            self.space(t.getSrc(), chain)
            self.space(t.getDst(), chain)
        elif isinstance(t, ocio.DisplayViewTransform):
            self.display_view(t.getSrc(), t.getDisplay(), t.getView(), chain,
                              not t.getLooksBypass())
        elif isinstance(t, ocio.LookTransform):
            self.space(t.getSrc(), chain)
            self.space(t.getDst(), chain)
            self.looks(t.getLooks(), chain)

    def finish(self) -> None:
        """Between scene- and display-referred colourspaces OCIO goes through the
        config's default view transform."""
        if len(self.refs) > 1:
            vt = self.cfg.getDefaultSceneToDisplayViewTransform()
            if vt is not None:
                self._view_transform(vt, ["default view transform"])


def _where(chain: list) -> str:
    if not chain:
        return ""
    return chain[0] + (f" (through {', '.join(chain[1:])})" if len(chain) > 1 else "")


def _split(args: tuple):
    """(context or None, the arguments of ``getProcessor`` after it)."""
    if args and isinstance(args[0], ocio.Context):
        return args[0], args[1:]
    return None, args


def lut_files(cfg, *args) -> list:
    """(resolved path or None, FileTransform, where) of every file ``cfg.getProcessor(*args)``
    would read (the forms this package uses: ``(src, dst)`` colourspaces or named
    transforms, ``(src, display, view, direction)``, ``(transform[, direction])``, each
    with an optional leading ``Context``). None: OCIO cannot locate it."""
    ctx, rest = _split(args)
    ctx = ctx if ctx is not None else cfg.getCurrentContext()
    w = _Walk(cfg, ctx)
    if rest and isinstance(rest[0], ocio.Transform):
        w.transform(rest[0], [])
    elif len(rest) >= 3:
        w.display_view(rest[0], rest[1], rest[2], [])
    elif len(rest) == 2:
        w.space(rest[0], [])
        w.space(rest[1], [])
    w.finish()
    out, done = [], set()
    for ft, chain in w.found:
        try:
            # stat only: OCIO's FileExists is a stat (Platform::CreateFileContentHash)
            path = ctx.resolveFileLocation(ft.getSrc())
        except Exception:  # noqa: BLE001 -- not found: OCIO's own words, if it is used
            path = None
        key = path or ft.getSrc()
        if key not in done:
            done.add(key)
            out.append((path, ft, _where(chain)))
    return out


def check_lut_files(cfg, *args) -> list:
    """Refuse (:class:`LutFileError`) a file ``cfg.getProcessor(*args)`` would read that
    is not a regular file (a FIFO, a device, a folder; links followed), not readable
    or over :data:`LUT_CAP`; returns :func:`lut_files`."""
    files = lut_files(cfg, *args)
    for path, _, where in files:
        if path is None:
            continue
        try:
            st = os.stat(path)
        except OSError:                  # not on disk (an .ocioz archive's proxy): OCIO's
            continue
        kind = file_kind(st.st_mode)
        if kind is not None:
            real = os.path.realpath(path)
            raise LutFileError(config_source(cfg), path, f"is {kind}, not a file" if
                               real == os.path.abspath(path) else
                               f"a link to {real}, which is {kind}, not a file", where)
        if st.st_size > LUT_CAP:
            raise LutFileError(config_source(cfg), path, f"is {st.st_size} bytes, more than "
                               f"the {LUT_CAP >> 20} MiB a LUT can be", where)
        if not os.access(path, os.R_OK):
            raise LutFileError(config_source(cfg), path, "cannot be read (permission denied)",
                               where)
    return files


def ocio_reason(exc: BaseException) -> str:
    """OCIO's message as one line of text: its bytes decoded where Python could not
    (a LUT's bytes quoted in it: ``'utf-8' codec can't decode``), unprintable
    characters as ``?``, OCIO's preamble dropped, at most 300 characters."""
    binary = isinstance(exc, UnicodeDecodeError) and isinstance(exc.object, (bytes, bytearray))
    text = bytes(exc.object).decode("utf-8", "replace") if binary else \
        (str(exc) or type(exc).__name__)
    binary = binary or any(not (ch.isprintable() or ch.isspace()) for ch in text)
    text = " ".join(text.split())
    for preamble in (r"The specified transform file '[^']*' could not be loaded\. ",
                     r"All formats have been tried\. \(Enable debug log for errors from all "
                     r"formats\.\) ", r"The formats for the file's extension gave the "
                     r"errors: "):
        text = re.sub("^" + preamble, "", text)
    line = re.search(r"At line \(\d+\)", text)
    if binary and line:                  # the line OCIO quotes is a LUT's bytes, not text
        text = text[:line.end()] + ": not text"
    text = "".join(ch if ch.isprintable() and ch != "\ufffd" else "?" for ch in text)
    return text if len(text) <= 300 else text[:300] + " ..."


def _failure(cfg, ctx, files: list, exc: BaseException) -> ColourError:
    """OCIO's failure to build a processor, naming the file that fails alone."""
    for path, ft, where in files:
        try:
            cfg.getProcessor(ctx, ft, ocio.TRANSFORM_DIR_FORWARD)
        except Exception as one:  # noqa: BLE001 -- OCIO's own Exception (or a decode error)
            return LutFileError(config_source(cfg), path or ft.getSrc(),
                                f"OCIO cannot read it: {ocio_reason(one)}", where)
    return ColourError(f"{config_source(cfg)}: OCIO cannot make the transform: "
                       f"{ocio_reason(exc)}")


def processor(cfg, *args):
    """``cfg.getProcessor(*args)`` once every file it reads is checked
    (:func:`check_lut_files`); OCIO's failure in one line (:class:`ColourError`)."""
    files = check_lut_files(cfg, *args)
    try:
        return cfg.getProcessor(*args)
    except Exception as exc:  # noqa: BLE001 -- OCIO's own Exception (or a decode error)
        ctx, _ = _split(args)
        raise _failure(cfg, ctx or cfg.getCurrentContext(), files, exc) from None


def cpu_processor(cfg, *args):
    """:func:`processor`'s default CPU processor (its failure in one line too)."""
    proc = processor(cfg, *args)
    try:
        return proc.getDefaultCPUProcessor()
    except Exception as exc:  # noqa: BLE001 -- OCIO's own Exception
        raise ColourError(f"{config_source(cfg)}: OCIO cannot make the CPU processor: "
                          f"{ocio_reason(exc)}") from None
