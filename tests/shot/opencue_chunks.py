"""An OpenCue job's commands as its dispatcher runs them: each layer's range cut into
chunks of ``chunk`` frames, #FRAME_START# and #FRAME_END# filled in (the farm tests
run them here, from whatever folder they choose)."""

from __future__ import annotations

import shlex


def opencue_commands(layer) -> list[list[str]]:
    """The argv of every task of one ``<layer>`` element, in frame order."""
    a, _, b = layer.findtext("range").partition("-")
    fr = list(range(int(a), int(b or a) + 1))
    size = int(layer.findtext("chunk"))
    out = []
    for i in range(0, len(fr), size):
        part = fr[i:i + size]
        cmd = layer.findtext("cmd").replace("#FRAME_START#", str(part[0])) \
            .replace("#FRAME_END#", str(part[-1]))
        out.append(shlex.split(cmd))
    return out
