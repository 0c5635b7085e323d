"""PETSc solver presets, as named read-only option sets, and KSP construction with a prefix."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from petsc4py import PETSc

__all__ = ["DIRECT", "destroy", "make_ksp"]

#: Sparse direct solve by MUMPS (the factorisation is kept and reused).
DIRECT: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
)


def make_ksp(
    A: PETSc.Mat, prefix: str, options: Mapping[str, str], *, setup: bool = True
) -> PETSc.KSP:
    """KSP on ``A`` configured from ``options`` under its own ``prefix``; set up (factorised).

    With ``setup=False`` the factorisation waits for the first ``setUp`` or solve (for a
    matrix not assembled yet).

    Options already in the PETSc database under ``prefix`` (from the command line) win;
    ``options`` are removed from the database once read, so that the next KSP of the same
    prefix gets its own.
    """
    database = PETSc.Options()
    added = [prefix + key for key in options if not database.hasName(prefix + key)]
    for key, value in options.items():
        if prefix + key in added:
            database.setValue(prefix + key, value)
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    for name in added:
        database.delValue(name)
    if setup:
        ksp.setUp()
    return ksp


def destroy(*objects: PETSc.Object | None) -> None:
    """Destroy PETSc objects at once (collective on their communicators).

    Does nothing once PETSc is finalised (at interpreter exit), when petsc4py frees them.
    """
    if PETSc.Sys.isFinalized():
        return
    for obj in objects:
        if obj is not None:
            obj.destroy()
