"""The resident set of this process, for the benchmarks' memory figures (Linux)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["resident"]


def resident(what: str = "VmRSS") -> int:
    """This process's resident set [KiB] (``VmHWM``: its peak); reading VmRSS resets the peak.

    The peak is reset through ``/proc/self/clear_refs``, so ``resident("VmHWM") - resident()``
    taken around a step is that step's peak above the set before it.
    """
    status = Path("/proc/self/status").read_text()
    value = int(next(line.split()[1] for line in status.splitlines() if line.startswith(what)))
    if what == "VmRSS":
        Path("/proc/self/clear_refs").write_text("5")
    return value
