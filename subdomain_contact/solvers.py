"""PETSc solver presets, as named read-only option sets, and KSP construction with a prefix."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from petsc4py import PETSc

__all__ = ["DIRECT", "destroy", "factorise", "make_ksp"]

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


def factorise(A: PETSc.Mat, prefix: str, what: str, ksp: PETSc.KSP | None = None) -> PETSc.KSP:
    """A MUMPS factorisation of ``A``: a new KSP, or ``ksp`` factorised again on A's values.

    While MUMPS's workspace estimate falls short (INFOG(1) = −9, PETSc's FACTOR_OUTMEMORY),
    it factorises again with the relaxation ICNTL(14) doubled, up to 1600 %: numerical
    pivoting at a stiff or opening contact delays pivots beyond the analysis's estimate (two
    3D blocks at h = 1e10 on 2 ranks: 20 % fails, 200 % factorises). ICNTL(14) is set on the
    factor matrix: options given to :func:`make_ksp` are gone from the database before the
    PC creates it.

    Raises:
        RuntimeError: The factorisation failed otherwise, naming ``what`` and the reason.
    """
    if ksp is None:
        ksp = make_ksp(A, prefix, DIRECT)
    else:
        ksp.setOperators(A)
        ksp.setUp()
    relaxation = 20  # MUMPS's default, in percent
    while ksp.getPC().getFailedReason() == PETSc.PC.FailedReason.FACTOR_OUTMEMORY:
        if relaxation >= 1600:
            break
        relaxation *= 2
        ksp.destroy()
        ksp = make_ksp(A, prefix, DIRECT, setup=False)
        pc = ksp.getPC()
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(14, relaxation)
        ksp.setUp()
    reason = ksp.getPC().getFailedReason()
    if reason != 0:
        ksp.destroy()
        raise RuntimeError(
            f"{what}: factorisation failed (PETSc PC reason {reason}, MUMPS workspace relaxed "
            f"to {relaxation} %)"
        )
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
