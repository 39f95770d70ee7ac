"""Local worker processes shared by the sweep and the regression suite."""
from __future__ import annotations

__all__ = ["process_context"]


def process_context():
    """Start method for local worker processes.

    ``fork`` when available and this process runs no other thread (workers start at
    once, with the simulator already imported and compiled); otherwise ``forkserver``
    with the simulator preloaded, or ``spawn`` where neither exists.  A process that has
    imported PyTorch (a learned policy was loaded) does not fork: PyTorch's native thread
    pool, which ``threading`` does not count, leaves a forked child deadlocked at its first
    network evaluation.
    """
    import multiprocessing
    import sys
    import threading
    methods = multiprocessing.get_all_start_methods()
    if "fork" in methods and threading.active_count() == 1 and "torch" not in sys.modules:
        return multiprocessing.get_context("fork")
    if "forkserver" in methods:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["ebraille_sim.scenarios.runner", "ebraille_sim.tools.sweep", "controllers"])
        return ctx
    return multiprocessing.get_context("spawn")
