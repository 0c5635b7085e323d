"""A MUMPS factorisation that stops short of a set of rows and hands back their Schur complement.

For a matrix ``K`` split into interior rows i and kept rows s, MUMPS eliminates i only and
returns the dense Schur complement ``Σ = K_ss − K_si K_ii⁻¹ K_is`` (MUMPS ICNTL(19), through
PETSc's ``MatFactorSetSchurIS``): the condensed stiffness costs one sparse factorisation,
where forming it column by column costs one solve per kept row. Replacing the Schur block
by ``Σ + H`` (dense, factorised by LAPACK) then makes every solve a solve with ``K + H``, for
any ``H`` that touches the kept rows only: a body's half-links. A new ``H`` (contact laws that
changed with the pressure or the temperature) needs no new sparse factorisation.

PETSc computes Schur complements of a matrix held by one rank only. petsc4py does not wrap
the Schur calls: they go to the PETSc library that petsc4py itself loaded, through ``ctypes``
with declared argument types.
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

__all__ = ["CondensedFactor", "condensation", "factorisation_work"]

Matrix = npt.NDArray[np.float64]

#: Contact DOFs up to which a body always keeps them as a dense Schur block (its dense
#: algebra costs less than 0.1 s).
SCHUR_SMALL = 1000

#: Above :data:`SCHUR_SMALL`, a body keeps its contact DOFs as a dense Schur block only while
#: they are at most this share of its DOFs (and at most :data:`SCHUR_LIMIT`); otherwise it is
#: factorised whole and its ``S^α`` applied by a body solve. The dense block's factorisation
#: and response grow as its size cubed, the sparse factorisation far slower. Measured, Newton
#: from 300 K, T, φ, u: the collector bar slot (contact shares 45, 95, 58 %; 2.3k, 4.2k, 1.8k
#: contact DOFs) 1 258 s with every body's Schur block, 4.7 s per step with the cast iron
#: alone whole, 11.4 s for 10 steps with every body whole (monolithic: 8.2 s); the row of
#: four 3D blocks (shares 6–12 %, up to 975 contact DOFs) 21.7 s with Schur blocks, 27.7 s
#: whole.
SCHUR_FRACTION = 0.25

#: Contact DOFs above which a body gets no Schur block: the block, its LU and the body's
#: ``S^α`` hold about 3 n² doubles, 1.5 GB at n = 8000.
SCHUR_LIMIT = 8000

#: Share of its DOFs above which a body with at most :data:`SCHUR_SMALL` contact DOFs is
#: thin: factorised whole, its ``S^α`` formed by solves of the sparse factorisation for
#: every master column at once. Its Schur block would be most of the body, and the dense
#: algebra on it (4.7 n³) costs more than the sparse solves: on the 2D preheat's coke bed
#: (624 of 942 DOFs) and cast iron (702 of 1,052), 12 time steps, CPU time of the
#: factorisations and ``S^α`` 1.08 and 1.46 s instead of 1.70 and 1.74 s.
THIN_SHARE = 0.5


def condensation(contact: int, size: int, dim: int) -> str:
    """How a body of ``size`` DOFs on one rank is condensed on its ``contact`` DOFs.

    ``"block"``: a dense Schur block (:class:`CondensedFactor`); ``"columns"``: a thin body,
    factorised whole, its ``S^α`` from multi-column solves; ``""``: not condensed, its
    ``S^α`` applied by one body solve per application.

    Above :data:`SCHUR_SMALL` contact DOFs, a 3D body keeps a Schur block only where its
    dense algebra costs at most its sparse factorisation (:func:`sparse_work`): the contact
    surface of a 3D body grows as its DOFs to the power 2/3, its dense block's algebra as
    their square, like the sparse factorisation, with a far larger constant. The collector
    bar slot at 34,510 DOFs: the block, 19,140 DOFs of which 2,620 on contacts (14 %, a
    Schur block by the share), 8.5e10 flops dense against 2.9e9 sparse; Newton from 300 K,
    one rank, 326 s with its Schur block, 176 s factorised whole (the monolithic Newton 124
    s; the same 19 steps and voltage drop; one run each, 2026-11-28, beside another run).
    2D is left as it was (not measured).
    """
    if contact <= SCHUR_SMALL:
        return "columns" if contact > THIN_SHARE * size else "block"
    if contact > min(SCHUR_FRACTION * size, SCHUR_LIMIT):
        return ""
    if dim == 3 and DENSE_BLOCK_WORK * float(contact) ** 3 > sparse_work(size, dim):
        return ""
    return "block"


#: The dense algebra on a Schur block of n contact DOFs at every update, ``DENSE_BLOCK_WORK
#: n³`` flops: its LU (2/3 n³), its solve for as many columns (2 n³) and the reaction ``Σ y``
#: (2 n³). A thin body's multi-column solves are counted as half that (measured at
#: 0.64–0.84 of its Schur block's time).
DENSE_BLOCK_WORK = 4.7


def sparse_work(size: int, dim: int) -> float:
    """Flops of the sparse LU of ``size`` unknowns by nested dissection.

    31 size^1.5 in 2D, 8 size² in 3D (MUMPS's count, RINFOG(3), for the 5- and 7-point
    Laplacians of 3.6k–27k unknowns).
    """
    return 31.0 * size**1.5 if dim == 2 else 8.0 * float(size) ** 2


def factorisation_work(size: int, contact: int, dim: int) -> float | None:
    """Floating-point operations of a body's factorisation and condensation, estimated.

    The sparse LU (:func:`sparse_work`); with a Schur block (:func:`condensation`) the dense
    algebra on it at every update (:data:`DENSE_BLOCK_WORK`), a thin body's multi-column
    solves half that. In 2D the block is the larger part: the cathode block of the 2D
    preheat, 3.4k nodes of which 347 on contacts, 6.1e6 sparse against 2.0e8 dense. None
    for a body that is not condensed: the work of its iterative interface (the sparse strip)
    is not in the estimate.
    """
    how = condensation(contact, size, dim)
    if not how:
        return None
    dense = DENSE_BLOCK_WORK if how == "block" else DENSE_BLOCK_WORK / 2
    return sparse_work(size, dim) + dense * float(contact) ** 3


_UNFACTORED = 0  # MatFactorSchurStatus MAT_FACTOR_SCHUR_UNFACTORED
_handle, _int = ctypes.c_void_p, ctypes.c_int
_SIGNATURES = {
    "MatFactorSetSchurIS": (_handle, _handle),
    "MatFactorGetSchurComplement": (_handle, ctypes.POINTER(_handle), ctypes.POINTER(_int)),
    "MatFactorRestoreSchurComplement": (_handle, ctypes.POINTER(_handle), _int),
    "MatFactorFactorizeSchurComplement": (_handle,),
    "MatDenseGetLDA": (_handle, ctypes.c_void_p),
    "MatDenseGetArray": (_handle, ctypes.POINTER(ctypes.POINTER(ctypes.c_double))),
    "MatDenseRestoreArray": (_handle, ctypes.POINTER(ctypes.POINTER(ctypes.c_double))),
    "MatMatSolve": (_handle, _handle, _handle),
}


@functools.cache
def _petsc() -> ctypes.CDLL:
    """petsc4py's extension module: its symbol lookup reaches the PETSc library it loaded."""
    library = ctypes.CDLL(PETSc.__file__)
    for name, arguments in _SIGNATURES.items():
        function = getattr(library, name)
        function.argtypes, function.restype = arguments, _int
    return library


def _call(name: str, *args: object) -> None:
    code = getattr(_petsc(), name)(*args)
    if code != 0:
        raise RuntimeError(f"PETSc {name} failed with error code {code}")


class CondensedFactor:
    """Solver of ``K + H`` from an LU of ``K`` by MUMPS whose ``kept`` rows are left dense.

    Call :meth:`destroy` (collectively) when done.

    Args:
        K: Square matrix on a communicator of one rank.
        kept: Local indices of the kept rows (the order of ``sigma``'s rows and columns).
        added: ``H``, dense on the kept rows (None: call :meth:`update` before solving).
        prefix: PETSc options prefix of the factorisation (``-<prefix>mat_mumps_icntl_*``).
        ordering: MUMPS's ordering ICNTL(7) (None: MUMPS's choice); ``-<prefix>mat_mumps_icntl_7``
            wins.

    Attributes:
        sigma: ``Σ = K_ss − K_si K_ii⁻¹ K_is``, dense, in the order of ``kept``.
    """

    def __init__(
        self,
        K: PETSc.Mat,
        kept: npt.NDArray[np.int32],
        added: Matrix | None,
        prefix: str,
        ordering: int | None = None,
    ) -> None:
        if K.getComm().getSize() != 1:
            raise ValueError(f"{prefix}: a Schur complement needs the matrix on one rank")
        self.size, self.prefix = len(kept), prefix
        given = PETSc.Options().hasName(prefix + "mat_mumps_icntl_7")
        self.ordering = None if given else ordering
        self.kept = np.asarray(kept, dtype=PETSc.IntType)
        self.pc: PETSc.PC | None = None
        self._build(K)
        if added is not None:
            self.update(added)

    def _build(self, K: PETSc.Mat) -> None:
        """A MUMPS LU of K with the Schur rows set, factorised.

        MUMPS estimates its workspace before it factorises, and a large Schur block can make
        the estimate too small (INFO(1) = −9, PETSc's "out of memory"): the factorisation is
        then made again with the workspace relaxation ICNTL(14) doubled, up to 1600 %.
        """
        relaxation = 20  # MUMPS's default, in percent
        while True:
            if self.pc is not None:
                self.pc.destroy()
            self.pc = PETSc.PC().create(K.getComm())
            self.pc.setOptionsPrefix(self.prefix)
            self.pc.setOperators(K)
            self.pc.setType("lu")
            self.pc.setFactorSolverType("mumps")
            self.pc.setFromOptions()
            self.pc.setFactorSetUpSolverType()
            self.F = self.pc.getFactorMatrix()
            if relaxation > 20:
                self.F.setMumpsIcntl(14, relaxation)
            if self.ordering is not None:
                self.F.setMumpsIcntl(7, self.ordering)
            rows = PETSc.IS().createGeneral(self.kept, comm=K.getComm())
            _call("MatFactorSetSchurIS", self.F.handle, rows.handle)
            rows.destroy()
            self.pc.setUp()
            reason = self.pc.getFailedReason()
            if reason != PETSc.PC.FailedReason.FACTOR_OUTMEMORY or relaxation >= 1600:
                break
            relaxation *= 2
        if reason != 0:
            raise RuntimeError(f"{self.prefix}: factorisation failed (PETSc reason {reason})")
        self.sigma = self._write_block(None)

    def refactor(self, K: PETSc.Mat, added: Matrix | None) -> None:
        """Factorise new values of the same sparsity pattern (MUMPS's analysis is kept).

        Solves need :meth:`update` next when ``added`` is None.
        """
        self.pc.setOperators(K)
        self.pc.setUp()
        if self.pc.getFailedReason() != 0:  # the workspace estimate fell short: start again
            self._build(K)
        else:
            self.sigma = self._write_block(None)
        if added is not None:
            self.update(added)

    def update(self, added: Matrix) -> None:
        """Make the dense block ``Σ + added`` and factorise it: solves are then with ``K + H``."""
        if added.shape != (self.size, self.size) or not np.all(np.isfinite(added)):
            raise ValueError(f"{self.prefix}: H must be a finite square matrix on the kept rows")
        self._write_block(self.sigma + added)
        _call("MatFactorFactorizeSchurComplement", self.F.handle)

    def _write_block(self, block: Matrix | None) -> Matrix:
        """Overwrite the Schur block with ``block`` (unfactored); return what it held."""
        S, status = _handle(), _int()
        _call("MatFactorGetSchurComplement", self.F.handle, ctypes.byref(S), ctypes.byref(status))
        lead = np.zeros(1, dtype=PETSc.IntType)
        _call("MatDenseGetLDA", S, lead.ctypes.data_as(ctypes.c_void_p))
        values = ctypes.POINTER(ctypes.c_double)()
        _call("MatDenseGetArray", S, ctypes.byref(values))
        # column-major storage: row j of ``columns`` is column j of the block
        columns = np.ctypeslib.as_array(values, shape=(self.size, int(lead[0])))[:, : self.size]
        held = columns.T.copy()
        if block is not None:
            columns[:] = block.T
        _call("MatDenseRestoreArray", S, ctypes.byref(values))
        _call("MatFactorRestoreSchurComplement", self.F.handle, ctypes.byref(S), _UNFACTORED)
        return held

    def solve_block(self, rhs: Matrix) -> Matrix:
        """``(Σ + H)⁻¹ rhs`` for columns on the kept rows, by the block's own factorisation.

        The LU that :meth:`update` made (LAPACK, inside PETSc) solves every column at once
        (``MatMatSolve``): the dense block is factorised once per update. Measured on the
        preheat's Schur blocks (624–702 rows, as many columns): with one BLAS thread, as fast
        as SciPy's ``lu_solve`` (18–25 ms), the second LU (7–10 ms) saved; with two threads
        SciPy's solve ran on both (10–12 ms) and PETSc's on one (15–23 ms), about even.
        """
        S, status = _handle(), _int()
        _call("MatFactorGetSchurComplement", self.F.handle, ctypes.byref(S), ctypes.byref(status))
        columns = rhs.shape[1]
        comm = PETSc.COMM_SELF
        B = PETSc.Mat().createDense((self.size, columns), array=np.asfortranarray(rhs), comm=comm)
        X = PETSc.Mat().createDense((self.size, columns), comm=comm)
        try:
            _call("MatMatSolve", S, B.handle, X.handle)
            return X.getDenseArray(readonly=True).copy()
        finally:
            _call("MatFactorRestoreSchurComplement", self.F.handle, ctypes.byref(S), status.value)
            B.destroy()
            X.destroy()

    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """``x = (K + H)⁻¹ b``.

        Through the factor's own MatSolve: a KSPSolve over this factorisation returned
        ``inf`` on PETSc 3.25.5.
        """
        self.F.solve(b, x)

    def destroy(self) -> None:
        """Free the factorisation (collective on its one rank)."""
        self.pc.destroy()
