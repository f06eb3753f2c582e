"""Threads of the runtime that yield the cores to the model: :func:`lower_priority`, and
:func:`check_nice` for every setting that asks for it."""

from __future__ import annotations

import os
import threading

NICE_RANGE = (0, 19)      # steps below the caller's priority a thread may take (Linux's nice range)


def check_nice(nice: int, name: str = "nice") -> None:
    """``ValueError`` naming the setting when ``nice`` is outside :data:`NICE_RANGE`."""
    lo, hi = NICE_RANGE
    if not lo <= nice <= hi:
        raise ValueError(f"{name} must be within {lo}..{hi}, got {nice}")


def lower_priority(nice: int) -> bool:
    """Lower the calling thread's scheduling priority by ``nice`` (Linux, where a thread is a task of
    its own); False where that is not possible (other systems, a sandbox that forbids it)."""
    if not nice or not hasattr(os, "setpriority") or not hasattr(threading, "get_native_id"):
        return False
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))
    except OSError:
        return False
    return True
