"""The import paths of the modules that moved into layer folders (issue 68), kept for
one release: ``import ocl_tonemap.imageio`` gives ``ocl_tonemap.io.imageio`` itself
(the same module object) with a DeprecationWarning naming the new path, and
``python -m ocl_tonemap.cli_docs`` runs ``ocl_tonemap.cli.docs``. Removed in 0.x+1
(docs/architecture.md, "Old import paths")."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: old module (under the package) -> its new place.
MOVED = {
    "resources": "base.resources", "interrupts": "base.interrupts", "safeio": "base.safeio",
    "quantities": "base.quantities", "reuse": "base.reuse",
    "visibility": "effects.visibility",
    "alpha": "pipeline.alpha", "state": "pipeline.state",
    "calibration": "colour.calibration",
    "imageio": "io.imageio", "imagewrite": "io.imagewrite", "channels": "io.channels",
    "patterns": "io.patterns", "radiance": "io.radiance", "state_files": "io.state_files",
    "sample": "io.sample", "plot": "io.plot",
    "cli_commands": "cli.commands", "cli_options": "cli.options", "cli_docs": "cli.docs",
}
PACKAGE = __name__.rpartition(".")[0]


def new_name(old: str) -> str | None:
    """The new full name of an old full module name, or None where it did not move."""
    head = PACKAGE + "."
    if not old.startswith(head):
        return None
    new = MOVED.get(old[len(head):])
    return None if new is None else head + new


def _message(old: str, new: str) -> str:
    return (f"{old} has moved to {new} (the package's layer folders); the old path "
            "works for this release only")


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame outside the import machinery and this
    module (where the DeprecationWarning should point: the importing line).
    ``warnings`` itself does not count importlib's bootstrap frames, so neither does
    this; ``importlib.import_module``'s own frame is passed over here."""
    f, level = sys._getframe(2), 2          # (1 is the create_module that warns)
    while f is not None:
        name = f.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            f = f.f_back                     # not counted by warnings
            continue
        if not (name == importlib.__file__ or name == __file__):
            return level
        f, level = f.f_back, level + 1
    return 2


class _OldPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path and loads the new module under it (no second copy)."""

    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        return None if new is None else importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new = new_name(spec.name)
        warnings.warn(_message(spec.name, new), DeprecationWarning, stacklevel=_caller_level())
        return importlib.import_module(new)

    def exec_module(self, module):
        """Nothing: the module is the new one, already run."""

    def get_code(self, fullname):
        """``python -m <old path>``: run the new module as ``__main__`` (its own
        package, so its relative imports hold), after the warning."""
        new = new_name(fullname)
        src = (f"import runpy, warnings\nwarnings.warn({_message(fullname, new)!r}, "
               f"DeprecationWarning, stacklevel=1)\n"
               f"runpy.run_module({new!r}, run_name='__main__', alter_sys=True)\n")
        return compile(src, f"<{fullname}: moved to {new}>", "exec")

    def is_package(self, fullname):
        return False


def install() -> None:
    """Add the finder once (``import ocl_tonemap`` does)."""
    if not any(isinstance(f, _OldPaths) for f in sys.meta_path):
        sys.meta_path.append(_OldPaths())
