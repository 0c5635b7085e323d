"""PETSc solver presets, as named read-only option sets, and KSP construction with a prefix."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from petsc4py import PETSc

__all__ = ["DIRECT", "make_ksp"]

#: Sparse direct solve by MUMPS (the factorisation is kept and reused).
DIRECT: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
)


def make_ksp(A: PETSc.Mat, prefix: str, options: Mapping[str, str]) -> PETSc.KSP:
    """KSP on ``A`` configured from ``options`` under its own ``prefix``; set up (factorised).

    Options already in the PETSc database under ``prefix`` (from the command line) win.
    """
    database = PETSc.Options()
    for key, value in options.items():
        if not database.hasName(prefix + key):
            database.setValue(prefix + key, value)
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    ksp.setUp()
    return ksp
