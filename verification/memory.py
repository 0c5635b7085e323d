"""The benchmarks' memory figures: this process's resident set (Linux), MUMPS's estimate."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from subdomain_contact import System

__all__ = ["mumps_estimate", "resident"]


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


def mumps_estimate(system: System) -> str:
    """MUMPS's own estimate of the monolithic factorisation of ``system``'s assembled Jacobian.

    MUMPS analyses the merged matrix, then refuses the factorisation (ICNTL(23) = 1 MB:
    INFOG(1) = -19), so nothing of its size is allocated. Returns a line: rows, ranks, the
    estimate on the largest rank and in all [GiB] (INFOG(16), INFOG(17): 10⁶ bytes).
    """
    import subdomain_contact as sc

    monolithic = sc.Monolithic({**sc.DIRECT, "mat_mumps_icntl_23": "1"})
    try:
        monolithic.setup(system)
        factor = monolithic.ksp.getPC().getFactorMatrix()
        status, largest, total = (factor.getMumpsInfog(i) for i in (1, 16, 17))
        rows = monolithic.K.getSize()[0]
    finally:
        monolithic.destroy()
    gib = 1e6 / 2**30
    return (
        f"{rows} rows, {system.comm.size} ranks: MUMPS estimates {largest * gib:.2f} GiB on its"
        f" largest rank, {total * gib:.2f} GiB in all (INFOG(1) = {status})"
    )
