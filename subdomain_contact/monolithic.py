"""The monolithic reference: the whole Jacobian, bodies and master layers merged, solved at once.

The merged matrix (:mod:`~subdomain_contact.merged`) is the same discrete system as the
subdomain iteration, with the master layers merged, so Newton with either linear solver
follows the same path.

The merged matrix is assembled (AIJ) for MUMPS or an iterative solve, or left unassembled
(PETSc's MATIS, one subdomain per rank: its bodies and the masters they touch) for PETSc's
balancing domain decomposition, PCBDDC, whose interface is then the master layers.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.merged import merged_matrix, same_pattern, unassembled_matrix
from subdomain_contact.solvers import DIRECT, destroy, make_ksp, ordered
from subdomain_contact.subdomain import InterfaceResult, Tolerance
from subdomain_contact.system import System

__all__ = ["BDDC", "CG_GAMG", "Monolithic"]

Vector = npt.NDArray[np.float64]

#: Conjugate gradients preconditioned by smoothed-aggregation algebraic multigrid (PETSc's
#: GAMG), to a relative residual of 1e-12: the monolithic iterative solve.
CG_GAMG: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": "1e-12", "ksp_max_it": "5000"}
)

#: PETSc's balancing domain decomposition by constraints on the unassembled matrix (one
#: subdomain per rank, the master layers its interface), deluxe scaling, MUMPS for the local
#: and coarse problems (ordered by :func:`~subdomain_contact.solvers.ordering`); GMRES to a
#: relative residual of 1e-12 (CG broke down, PETSc reason −8, on the two plates at h = 1e6,
#: where GMRES takes 1 to 2 iterations). Every rank must hold whole bodies
#: (``placement="groups"`` with no more ranks than bodies).
BDDC: Mapping[str, str] = MappingProxyType(
    {
        "ksp_type": "gmres",
        "ksp_rtol": "1e-12",
        "ksp_max_it": "1000",
        "pc_type": "bddc",
        "pc_bddc_use_deluxe_scaling": "true",
        "pc_bddc_dirichlet_pc_factor_mat_solver_type": "mumps",
        "pc_bddc_neumann_pc_factor_mat_solver_type": "mumps",
        "pc_bddc_coarse_pc_factor_mat_solver_type": "mumps",
        "sub_schurs_mat_solver_type": "mumps",  # deluxe: each subdomain's one factorisation
    }
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

    def _bddc(self) -> bool:
        """Whether the solve is PCBDDC (given in ``options`` or on the command line)."""
        database, key = PETSc.Options(), self.prefix + "pc_type"
        given = database.getString(key) if database.hasName(key) else self.options.get("pc_type")
        return given == "bddc"

    def check(self, system: System) -> None:
        """Refuse BDDC on a rank that holds part of a body (the merged matrix takes any)."""
        if self._bddc() and system.comm.allreduce(
            system.problem.scene.group_comm.size > 1, op=MPI.LOR
        ):
            raise ValueError(
                f"{system.problem.scene.source}: BDDC needs every body on one rank: load the "
                "scene with placement='groups' on no more ranks than bodies"
            )

    def setup(self, system: System) -> None:
        """Merge the assembled blocks into one matrix and set its solve up (factorise it)."""
        self.check(system)
        self.system = system
        bddc = self._bddc()
        if bddc:  # a new preconditioner for every new matrix
            self.destroy()
        merged = unassembled_matrix(system) if bddc else merged_matrix(system)
        failed = self.ksp is not None and self.ksp.getPC().getFailedReason() != 0
        if self.K is not None and not failed and same_pattern(merged, self.K):
            # the same sparsity (a new Newton step): MUMPS keeps its analysis
            merged.copy(self.K, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            merged.destroy()
            self.ksp.setOperators(self.K)
            self.ksp.setUp()
            self.factorisations += 1
            return
        self.destroy()
        self.K = merged
        dim, rows = system.problem.scene.dim, self.K.getSize()[0]
        options = ordered(self.options, dim, rows, again=not system.is_linear)
        self.ksp = make_ksp(self.K, self.prefix, options)
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
