"""Which of a file's channels a frame uses: R, G, B (and alpha) by name, by
``--channels``, or by position; the wavelength-named channels of a spectral image;
runs of adjacent channels for reads that skip the others (a thousand AOVs)."""

from __future__ import annotations

import re


def select_channels(spec, channels: list[str] | None = None) -> tuple[list[int], str | None]:
    """(indices of R, G, B [, alpha], note) for a file's channels.

    R, G, B by name (``layer.R`` too) when the file has them; ``channels`` (names
    or numbers, 1 or 3 of them; ``--channels``) otherwise or to override; one
    channel is luminance (grey); three or more unnamed channels are taken in
    order. Two channels (R, G without B; a UV map) are refused: there is no
    honest way to make light of them. The note says what was assumed."""
    names = list(spec.channelnames)
    short = [n.split(".")[-1].upper() for n in names]
    alpha = spec.alpha_channel if spec.alpha_channel >= 0 else (short.index("A") if "A" in short else -1)
    note = None

    def find(c):
        if c.isdigit() and int(c) < len(names):
            return int(c)
        for i, n in enumerate(names):
            if n == c or short[i] == c.upper():
                return i
        raise ValueError(f"--channels: the file has no channel {c!r} (it has {', '.join(names)})")

    if channels:
        idx = [find(c) for c in channels]
        if len(idx) == 1:
            idx = idx * 3
        elif len(idx) != 3:
            raise ValueError("--channels takes one name (luminance) or three (R,G,B)")
        note = f"channels {', '.join(names[i] for i in dict.fromkeys(idx))} used as R, G, B"
    elif all(c in short for c in "RGB"):
        idx = [short.index(c) for c in "RGB"]
    elif spec.nchannels == 1 or (len(short) >= 1 and short[0] == "Y" and "Y" in short
                                 and spec.nchannels - (alpha >= 0) == 1):
        idx = [short.index("Y") if "Y" in short else 0] * 3
        note = f"1 channel ({names[idx[0]]}): taken as luminance"
    elif spec.nchannels - (alpha >= 0) == 2 or spec.nchannels == 2:
        raise ValueError(f"2 channels ({', '.join(names)}) are not a colour image; give the "
                         "channels to use with --channels (one name for luminance, or R,G,B)")
    else:
        idx = [i for i in range(spec.nchannels) if i != alpha][:3]
        note = f"no R, G, B channels: {', '.join(names[i] for i in idx)} used as R, G, B"
    if alpha >= 0 and alpha not in idx:
        idx.append(alpha)
    return idx, note


_SPECTRAL_CHANNEL = re.compile(r"^(?:S0\.)?(\d+(?:[.,]\d*)?)\s*nm$|^(\d{3}(?:[.,]\d*)?)$",
                               re.IGNORECASE)
#: Fewest wavelength-named channels that make a file spectral.
MIN_SPECTRAL_CHANNELS = 4


def spectral_channels(names) -> list[tuple[int, float]]:
    """(index, wavelength nm) of the channels named by wavelength: the spectral
    OpenEXR convention ``S0.<wl>nm`` (Fichet et al. 2021; a comma may stand for
    the decimal point) or plain ``<wl>nm`` / ``<wl>`` names, sorted by wavelength."""
    out = []
    for i, n in enumerate(names):
        m = _SPECTRAL_CHANNEL.match(n.strip())
        if m:
            out.append((i, float((m.group(1) or m.group(2)).replace(",", "."))))
    return sorted(out, key=lambda t: t[1]) if len(out) >= MIN_SPECTRAL_CHANNELS else []


def channel_runs(idx) -> list[tuple[int, int]]:
    """[chbegin, chend) runs of adjacent channels covering ``idx``."""
    runs: list[list[int]] = []
    for c in sorted(set(int(i) for i in idx)):
        if runs and c == runs[-1][1]:
            runs[-1][1] = c + 1
        else:
            runs.append([c, c + 1])
    return [(a, b) for a, b in runs]
