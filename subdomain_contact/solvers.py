"""PETSc solver presets, as named read-only option sets, and KSP construction with a prefix."""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from types import MappingProxyType
from typing import ClassVar

from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["DIRECT", "Reaper", "destroy", "make_ksp"]

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


class Reaper:
    """Destroys factorisations collectively, at points where every rank is, never in ``__del__``.

    Destroying a MUMPS factorisation is collective (MUMPS duplicates a communicator). The
    garbage collector frees objects caught in reference cycles (an exception's traceback, say)
    at different moments on different ranks, so a destroy from ``__del__`` can deadlock.
    Owners ``register`` a factorisation when they make it and ``release`` it from ``__del__``;
    ``collect`` then destroys, in creation order, those that every holding rank has released.
    """

    _tickets = itertools.count()
    _held: ClassVar[dict[int, PETSc.Object]] = {}
    _released: ClassVar[set[int]] = set()

    @classmethod
    def register(cls, obj: PETSc.Object) -> int:
        """Ticket for ``obj``; tickets agree across ranks when objects are made in step."""
        ticket = next(cls._tickets)
        cls._held[ticket] = obj
        return ticket

    @classmethod
    def release(cls, ticket: int) -> None:
        """Mark as unused; safe from ``__del__`` (no PETSc or MPI call)."""
        cls._released.add(ticket)

    @classmethod
    def collect(cls, comm: MPI.Comm) -> None:
        """Destroy what every rank of ``comm`` holding it has released (collective on comm).

        Only objects whose communicator lies within ``comm`` are considered.
        """
        within = {t for t, obj in cls._held.items() if _inside(obj.getComm().tompi4py(), comm)}
        views = comm.allgather((within, cls._released & within))
        ready = set().union(*(released for _, released in views))
        for held, released in views:
            ready -= held - released
        for ticket in sorted(ready & within):
            cls._held.pop(ticket).destroy()
            cls._released.discard(ticket)


def _inside(inner: MPI.Comm, outer: MPI.Comm) -> bool:
    """Whether every rank of ``inner`` belongs to ``outer``."""
    inner_group, outer_group = inner.Get_group(), outer.Get_group()
    ranks = MPI.Group.Translate_ranks(inner_group, list(range(inner.size)), outer_group)
    inner_group.Free()
    outer_group.Free()
    return MPI.UNDEFINED not in ranks
