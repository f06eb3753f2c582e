"""Threads of the runtime that yield the cores to the model: :func:`lower_priority`."""

from __future__ import annotations

import os
import threading


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
