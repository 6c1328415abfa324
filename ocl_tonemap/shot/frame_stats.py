"""A frame's statistics in a shot's store: to and from JSON (exactly), and read
ahead of the pass that needs them (``passes.py``: integrate steps the state over
them, apply maps frames from them)."""

from __future__ import annotations

import os

import numpy as np

from ..models.photometry import RepairCounts
from ..operators.base import FrameStats
from .store import ShotStore


# -- statistics to and from JSON (exact) ----------------------------------------------------
def encode_value(v):
    """``v`` as JSON that :func:`decode_value` gives back exactly (numpy arrays and
    scalars with their dtype)."""
    if isinstance(v, np.ndarray):
        return {"__ndarray__": v.ravel().tolist(), "dtype": str(v.dtype), "shape": list(v.shape)}
    if isinstance(v, np.generic):
        return {"__npscalar__": v.item(), "dtype": str(v.dtype)}
    if isinstance(v, dict):
        return {str(k): encode_value(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [encode_value(x) for x in v]
    return v


def decode_value(v):
    if isinstance(v, dict):
        if "__ndarray__" in v:
            return np.array(v["__ndarray__"], dtype=v["dtype"]).reshape(v["shape"])
        if "__npscalar__" in v:
            return np.dtype(v["dtype"]).type(v["__npscalar__"])
        return {k: decode_value(x) for k, x in v.items()}
    if isinstance(v, list):
        return [decode_value(x) for x in v]
    return v


def stats_document(stats: FrameStats, illuminant, hint, t: float, held: bool, inp: str) -> dict:
    """What integrate needs of one frame's statistics (JSON; floats exact)."""
    return {"time_s": float(t), "held": bool(held), "input": os.path.basename(inp),
            "width": int(stats.width), "height": int(stats.height),
            "G_rod": float(stats.G_rod), "G_cone": float(stats.G_cone),
            "scene_goal": None if stats.scene_goal is None else [float(g) for g in
                                                                   stats.scene_goal],
            "scene_max_Y": stats.scene_max_Y, "scene_max_Ys": stats.scene_max_Ys,
            "scene_repairs": None if stats.scene_repairs is None else
            stats.scene_repairs.as_dict(),
            "repairs": stats.repairs.as_dict(), "values": encode_value(dict(stats.values)),
            "illuminant": encode_value(illuminant), "illuminant_hint": encode_value(hint)}


def stats_from_document(doc: dict, planes, schedule) -> tuple[FrameStats, object]:
    """(FrameStats ready for ``Tonemapper.integrate``, the frame's illuminant hint);
    a document whose parts do not decode is refused (ValueError)."""
    try:
        return _stats_from_document(doc, planes, schedule)
    except (KeyError, TypeError, AttributeError, IndexError) as exc:
        raise ValueError(f"frame {doc.get('frame')}'s statistics are damaged ({exc!r}); "
                         "measure it again") from None


def _stats_from_document(doc: dict, planes, schedule) -> tuple[FrameStats, object]:
    illum = decode_value(doc.get("illuminant"))
    goal = doc.get("scene_goal")
    max_Y, scene_rep = doc.get("scene_max_Y"), doc.get("scene_repairs")
    max_Ys = doc.get("scene_max_Ys")
    stats = FrameStats(int(doc["width"]), int(doc["height"]), float(doc["G_rod"]),
                       float(doc["G_cone"]), RepairCounts(**doc.get("repairs", {})),
                       (lambda: illum) if illum is not None else None,
                       decode_value(doc.get("values") or {}),
                       scene_goal=None if goal is None else (float(goal[0]), float(goal[1])),
                       scene_max_Y=None if max_Y is None else float(max_Y),
                       scene_repairs=None if scene_rep is None else RepairCounts(**scene_rep),
                       scene_max_Ys=None if max_Ys is None else float(max_Ys))
    if planes is not None:
        stats = schedule.stats_from_planes(stats, planes)
    return stats, decode_value(doc.get("illuminant_hint"))


#: Frames whose statistics are read ahead of the state step (their planes
#: decompress on threads while the device steps: OIIO releases the GIL).
READ_AHEAD = 2


def stats_ahead(store: ShotStore, frames: list[int], depth: int = READ_AHEAD):
    """``get(k)``: frame ``frames[k]``'s (document, planes), read on a thread
    ``depth`` frames ahead of the caller (in order; at most ``depth + 1`` frames'
    planes in memory). Statistics without planes (global operators) are read
    where they are asked for: a small JSON is not worth a thread."""
    from concurrent.futures import ThreadPoolExecutor
    if not frames or not store.stats_document(frames[0]).get("planes"):
        return lambda k: store.read_stats(frames[k])
    threads = max(1, min(depth, (os.cpu_count() or 2) - 1))
    pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="ocltm-stats")
    pending: dict = {}

    def get(k: int):
        for j in range(k, min(k + depth + 1, len(frames))):
            if j not in pending:
                pending[j] = pool.submit(store.read_stats, frames[j])
        for j in [j for j in pending if j < k]:
            pending.pop(j).cancel()
        try:
            return pending.pop(k).result()
        finally:
            if k + 1 >= len(frames) or not pending:
                pool.shutdown(wait=False, cancel_futures=True)
    return get


def stored_stats(store: ShotStore, frames: list[int], docs: dict):
    """``get(frame, schedule)``: the frame's statistics from the store as the apply
    pass maps from them, for the run's schedule, once each: its document from
    ``docs`` (the frames' documents, already read), its planes read ahead on a
    thread where it has them."""
    index = {f: k for k, f in enumerate(frames)}
    ahead = stats_ahead(store, frames) if frames and docs[frames[0]].get("planes") else None

    def get(frame, schedule):
        k = index.get(frame)
        if k is None:
            return None
        doc, planes = ahead(k) if ahead is not None else (docs[frame], None)
        return stats_from_document(doc, planes, schedule)[0]
    return get
