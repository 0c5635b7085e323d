"""The monolithic reference: the whole Jacobian, bodies and master layers merged, solved at once.

Unknowns ``[y^α ..., y_m,k ...]``; blocks ``A^α`` (each body's whole matrix), ``B^α_k P_k``
between a body and a master layer, ``P_kᵀ C^α_k`` back, and ``Σ_α P_kᵀ D^α_k P_k`` on each
master layer. It is the same discrete system as the subdomain iteration, with the master
layers merged, so Newton with either linear solver follows the same path. Masters of an
insulating contact have no equation: they are held at 0.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
import scipy.sparse
from petsc4py import PETSc

from subdomain_contact.body import Body
from subdomain_contact.solvers import DIRECT, destroy, make_ksp
from subdomain_contact.subdomain import InterfaceResult, Tolerance
from subdomain_contact.system import System

__all__ = ["CG_GAMG", "Monolithic"]

Vector = npt.NDArray[np.float64]

#: Conjugate gradients preconditioned by smoothed-aggregation algebraic multigrid (PETSc's
#: GAMG), to a relative residual of 1e-12: the monolithic iterative solve.
CG_GAMG: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": "1e-12", "ksp_max_it": "5000"}
)


class Monolithic:
    """``J y = b`` by one solve of the merged matrix (MUMPS by default): the reference.

    Args:
        options: PETSc options of the solve (an iterative one stops at its own ``ksp_rtol``).
        prefix: Options prefix of the solve (``-<prefix>ksp_*``, ``-<prefix>pc_*``).
        monitor: Called after every iteration of an iterative solve with its number and a
            function returning the iterate (global-vector layout).
        refine: Steps of iterative refinement after each solve (``y += K⁻¹ (b − K y)``): a
            reference polished beyond the direct solve's round-off.

    Call :meth:`destroy` (collectively) when done.
    """

    def __init__(
        self,
        options: Mapping[str, str] = DIRECT,
        *,
        prefix: str = "sc_monolithic_",
        monitor: Callable[[int, Callable[[], Vector]], None] | None = None,
        refine: int = 0,
    ) -> None:
        self.options, self.prefix, self.monitor = options, prefix, monitor
        self.refine = refine
        self.K: PETSc.Mat | None = None
        self.ksp: PETSc.KSP | None = None
        #: Set-ups of the merged matrix's solve: factorisations, for a direct one.
        self.factorisations = 0

    def check(self, system: System) -> None:
        """Refuse a system this solver cannot solve (bodies on different rank groups)."""
        if not system.problem.scene.shared:
            raise ValueError(
                f"{system.problem.scene.source}: the monolithic solve needs every body on the "
                "same ranks: load the scene with placement='shared' (or run on one rank)"
            )

    def setup(self, system: System) -> None:
        """Merge the assembled blocks into one AIJ matrix and factorise it."""
        self.check(system)
        self.system = system
        names, interfaces = list(system.bodies), list(system.sizes)
        n = len(names) + len(interfaces)
        blocks: list[list[PETSc.Mat | None]] = [[None] * n for _ in range(n)]
        made: list[PETSc.Mat] = []
        for a, name in enumerate(names):
            body = system.bodies[name]
            blocks[a][a] = body.whole_matrix()
            for m, k in enumerate(interfaces, start=len(names)):
                if k in body.layers:
                    B, C = _coupling(body, k, system)
                    blocks[a][m], blocks[m][a] = B, C
                    made += [B, C]
        for m, k in enumerate(interfaces, start=len(names)):
            blocks[m][m] = _master_block(system, k)
            made.append(blocks[m][m])
        nest = PETSc.Mat().createNest(blocks, comm=system.comm)
        merged = nest.convert("aij", out=PETSc.Mat())
        destroy(nest, *made)
        if self.K is not None and merged.getInfo()["nz_used"] == self.K.getInfo()["nz_used"]:
            # the same sparsity (a new Newton step): MUMPS keeps its analysis
            merged.copy(self.K, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            merged.destroy()
            self.ksp.setOperators(self.K)
            self.ksp.setUp()
            self.factorisations += 1
            return
        self.destroy()
        self.K = merged
        self.ksp = make_ksp(self.K, self.prefix, self.options)
        self.factorisations += 1
        if self.monitor is not None:

            def watch(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
                def iterate() -> Vector:
                    built = ksp.buildSolution()
                    values = built.array.copy()
                    built.destroy()
                    return values

                self.monitor(iteration, iterate)

            self.ksp.setMonitor(watch)

    def solve(self, b: Vector | None, tolerance: Tolerance) -> tuple[Vector, InterfaceResult]:
        """One solve; its result counts the iterations of an iterative solve as rounds."""
        rhs, x = self.K.createVecs()
        rhs.array[:] = 0.0 if b is None else b
        self.ksp.solve(rhs, x)
        reason = self.ksp.getConvergedReason()
        iterations = self.ksp.getIterationNumber()
        residual, correction = self.K.createVecs()
        for _ in range(self.refine):
            self.K.mult(x, residual)
            residual.aypx(-1.0, rhs)
            self.ksp.solve(residual, correction)
            x.axpy(1.0, correction)
        out = x.array.copy()
        destroy(rhs, x, residual, correction)
        if reason < 0:
            raise RuntimeError(
                f"monolithic linear solve failed (PETSc reason {reason} after {iterations} "
                "iterations)"
            )
        return out, InterfaceResult(rounds=max(1, iterations), converged=True)

    def destroy(self) -> None:
        """Free the merged matrix and its factorisation (collective)."""
        destroy(self.K, self.ksp)
        self.K, self.ksp = None, None


def _coupling(body: Body, k: str, system: System) -> tuple[PETSc.Mat, PETSc.Mat]:
    """``B_k P_k`` (body rows × masters of k) and ``P_kᵀ C_k`` (masters × body columns).

    Every stored entry is inserted, zeros included, so that the merged matrix keeps one
    sparsity pattern from one Newton step to the next.
    """
    m = system.sizes[k]
    local_m = m if system.comm.rank == 0 else 0
    blocks = body.blocks[k]
    free = np.setdiff1d(np.arange(body.kept_slice.start, body.kept_slice.stop), body.fixed_kept)
    B = _from_sparse(  # the rows of fixed DOFs are their conditions alone
        [(blocks["BP"][free], body.kept[free], np.arange(m))], (body.size, local_m), system
    )
    rows = np.arange(m) if system.comm.rank == 0 else np.zeros(0, dtype=int)
    parts = [(-blocks["L"][body.position[k][rows]], rows, body.kept)]
    if "CtP" in blocks:
        parts.append((blocks["CtP"][rows], rows, body.kept))
    return B, _from_sparse(parts, (local_m, body.size), system)


def _master_block(system: System, k: str) -> PETSc.Mat:
    """``Σ_α P_kᵀ D^α_k P_k``, identity on the masters of an insulating channel (dense)."""
    local = np.zeros((system.sizes[k],) * 2)
    for body in system.bodies_of(k):
        local += body.link_stiffness(k)
    D = system.total({k: local})[k]
    inactive = ~system.active[k]
    D[inactive, :] = 0.0
    D[:, inactive] = 0.0
    D[inactive, inactive] = 1.0
    m = system.sizes[k]
    local_m = m if system.comm.rank == 0 else 0
    rows = np.arange(m) if system.comm.rank == 0 else np.zeros(0, dtype=int)
    dense = scipy.sparse.csr_matrix(np.ones((len(rows), m)))
    dense.data[:] = D[rows].ravel()  # every entry stored, zeros included
    return _from_sparse([(dense, rows, np.arange(m))], (local_m, local_m), system)


def _from_sparse(
    parts: list[tuple[scipy.sparse.csr_matrix, npt.NDArray, npt.NDArray]],
    local: tuple[int, int],
    system: System,
) -> PETSc.Mat:
    """A PETSc AIJ matrix of local size ``local``: the sum of this rank's ``parts``.

    Each part is ``(rows_csr, rows, columns)``: row i of ``rows_csr`` is global row
    ``rows[i]``, its column j global column ``columns[j]``. Every stored entry is added,
    zeros included.
    """
    M = PETSc.Mat().createAIJ(
        ((local[0], PETSc.DETERMINE), (local[1], PETSc.DETERMINE)), comm=system.comm
    )
    widest = max((int(np.diff(csr.indptr).max(initial=0)) for csr, _, _ in parts), default=0)
    M.setPreallocationNNZ((widest * len(parts), widest * len(parts)))
    M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    for csr, rows, columns in parts:
        for i, row in enumerate(rows):
            span = slice(csr.indptr[i], csr.indptr[i + 1])
            at = columns[csr.indices[span]].astype(PETSc.IntType)
            M.setValues([int(row)], at, csr.data[span], addv=PETSc.InsertMode.ADD_VALUES)
    M.assemble()
    return M
