"""A MUMPS factorisation that stops short of a set of rows and hands back their Schur complement.

For a matrix ``K`` split into interior rows i and kept rows s, MUMPS eliminates i only and
returns the dense Schur complement ``Σ = K_ss − K_si K_ii⁻¹ K_is`` (MUMPS ICNTL(19), through
PETSc's ``MatFactorSetSchurIS``): the condensed stiffness costs one sparse factorisation,
where forming it column by column costs one solve per kept row. Replacing the Schur block
by ``Σ + H`` (dense, factorised by LAPACK) then makes every solve a solve with ``K + H``, for
any ``H`` that touches the kept rows only: a contact's half-links.

PETSc computes Schur complements of a matrix held by one rank only. petsc4py does not wrap
the Schur calls, so they go to the PETSc library through ``ctypes``.
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from subdomain_contact.solvers import Reaper

__all__ = ["CondensedFactor"]

Matrix = npt.NDArray[np.float64]
_UNFACTORED = 0  # MatFactorSchurStatus MAT_FACTOR_SCHUR_UNFACTORED


@functools.cache
def _petsc() -> ctypes.CDLL:
    """The PETSc library petsc4py has loaded (the same instance, found by its path)."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            if "libpetsc.so" in line:
                return ctypes.CDLL(line.split()[-1])
    raise RuntimeError("the PETSc library is not loaded: import petsc4py first")


def _call(name: str, *args: object) -> None:
    code = getattr(_petsc(), name)(*args)
    if code != 0:
        raise RuntimeError(f"PETSc {name} failed with error code {code}")


class CondensedFactor:
    """Solver of ``K + H`` from an LU of ``K`` by MUMPS whose ``kept`` rows are left dense.

    Args:
        K: Square matrix on a communicator of one rank.
        kept: Local indices of the kept rows (the order of ``sigma``'s rows and columns).
        added: ``H``, dense on the kept rows (zero: solves with K).
        prefix: PETSc options prefix of the factorisation (``-<prefix>mat_mumps_icntl_*``).

    Attributes:
        sigma: ``Σ = K_ss − K_si K_ii⁻¹ K_is``, dense, in the order of ``kept``.
    """

    def __init__(
        self,
        K: PETSc.Mat,
        kept: npt.NDArray[np.int32],
        added: npt.NDArray[np.float64],
        prefix: str,
    ) -> None:
        if K.getComm().getSize() != 1:
            raise ValueError(f"{prefix}: a Schur complement needs the matrix on one rank")
        self.size = len(kept)
        self.pc = PETSc.PC().create(K.getComm())
        self._ticket = Reaper.register(self.pc)
        self.pc.setOptionsPrefix(prefix)
        self.pc.setOperators(K)
        self.pc.setType("lu")
        self.pc.setFactorSolverType("mumps")
        self.pc.setFromOptions()
        self.pc.setFactorSetUpSolverType()
        self.F = self.pc.getFactorMatrix()
        rows = PETSc.IS().createGeneral(np.asarray(kept, dtype=PETSc.IntType), comm=K.getComm())
        _call("MatFactorSetSchurIS", ctypes.c_void_p(self.F.handle), ctypes.c_void_p(rows.handle))
        rows.destroy()
        self.pc.setUp()
        if self.pc.getFailedReason() != 0:
            raise RuntimeError(f"{prefix}: factorisation failed ({self.pc.getFailedReason()})")
        if added.shape != (self.size, self.size) or not np.all(np.isfinite(added)):
            raise ValueError(f"{prefix}: H must be a finite square matrix on the kept rows")
        self.sigma = self._add_to_schur(added)
        _call("MatFactorFactorizeSchurComplement", ctypes.c_void_p(self.F.handle))

    def __del__(self) -> None:
        if "_ticket" in self.__dict__:
            Reaper.release(self._ticket)

    def _add_to_schur(self, added: Matrix) -> Matrix:
        """Add ``added`` to the unfactored Schur block Σ in place; return a copy of Σ."""
        S, status = ctypes.c_void_p(), ctypes.c_int()
        F = ctypes.c_void_p(self.F.handle)
        _call("MatFactorGetSchurComplement", F, ctypes.byref(S), ctypes.byref(status))
        if status.value != _UNFACTORED:
            raise RuntimeError("the Schur block was factorised already")
        lead = np.zeros(1, dtype=PETSc.IntType)
        _call("MatDenseGetLDA", S, lead.ctypes.data_as(ctypes.c_void_p))
        values = ctypes.POINTER(ctypes.c_double)()
        _call("MatDenseGetArray", S, ctypes.byref(values))
        # column-major storage: row j of ``columns`` is column j of the block
        columns = np.ctypeslib.as_array(values, shape=(self.size, int(lead[0])))[:, : self.size]
        sigma = columns.T.copy()
        columns += added.T
        _call("MatDenseRestoreArray", S, ctypes.byref(values))
        _call("MatFactorRestoreSchurComplement", F, ctypes.byref(S), ctypes.c_int(_UNFACTORED))
        return sigma

    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """``x = (K + H)⁻¹ b``.

        Through the factor's own MatSolve: a KSPSolve over this factorisation returned
        ``inf`` on PETSc 3.25.5.
        """
        self.F.solve(b, x)
