"""``python -m ocl_tonemap`` and the ``ocl-tonemap`` command (``entry``): the command
line with its signals handled from the first moment (``interrupts.py``): SIGINT
exits 130, SIGTERM 143, in one line, never a traceback."""

import sys


def entry() -> int:
    try:
        from .interrupts import install
        install()
        from .cli import main
        return main()
    except BaseException as exc:          # noqa: BLE001 - only the two signals end here
        from .interrupts import Terminated, exit_code
        if not isinstance(exc, (KeyboardInterrupt, Terminated)):
            raise
        print("ocl-tonemap: interrupted" if isinstance(exc, KeyboardInterrupt)
              else "ocl-tonemap: terminated", file=sys.stderr)
        return exit_code(exc)


if __name__ == "__main__":
    raise SystemExit(entry())
