"""The monolithic reference: the whole Jacobian, bodies and master layers merged, solved at once.

The merged matrix (:mod:`~subdomain_contact.merged`) is the same discrete system as the
subdomain iteration, with the master layers merged, so Newton with either linear solver
follows the same path.

The merged matrix is assembled (AIJ) for MUMPS or an iterative solve, or left unassembled
(PETSc's MATIS, one subdomain per rank: its bodies and the masters they touch) for PETSc's
balancing domain decomposition, PCBDDC, whose interface is then the master layers.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.merged import MergePlan, unassembled_matrix
from subdomain_contact.modes import centre, modes, span
from subdomain_contact.physics import FIELDS
from subdomain_contact.solvers import (
    DIRECT,
    FIELD_SWEEP,
    destroy,
    make_ksp,
    node_memory,
    ordered,
    set_up,
)
from subdomain_contact.subdomain import InterfaceResult, Tolerance
from subdomain_contact.system import System

__all__ = ["BDDC", "CG_GAMG", "FIELDSPLIT_GAMG", "Monolithic", "field_splits"]

Vector = npt.NDArray[np.float64]

#: Conjugate gradients preconditioned by smoothed-aggregation algebraic multigrid (PETSc's
#: GAMG), to a relative residual of 1e-12: the monolithic iterative solve. Each level's
#: largest eigenvalue (for the Chebyshev smoother) estimated by CG, not PETSc's default
#: GMRES: with the latter, the two 3D blocks at h = 1e10 stopped after 3 or 4 iterations on
#: an indefinite preconditioner (PETSc reason -8) at 5.5k and 107k DOFs; with CG's they
#: converge (488 and 1,216 iterations).
CG_GAMG: Mapping[str, str] = MappingProxyType(
    {
        "ksp_type": "cg",
        "pc_type": "gamg",
        "pc_gamg_esteig_ksp_type": "cg",
        "ksp_rtol": "1e-12",
        "ksp_max_it": "5000",
    }
)

#: The coupled problem's monolithic iterative solve: GMRES preconditioned by one block
#: Gauss-Seidel sweep over the fields (PETSc's multiplicative ``fieldsplit``, the fields in the
#: problem's order, :func:`field_splits`), each field's block by one V-cycle of GAMG with its
#: near-null space (the constant; for u the rigid motions of the whole). The bodies' own split
#: (``body.SPLIT``) on the merged matrix, contacts included.
FIELDSPLIT_GAMG: Mapping[str, str] = MappingProxyType(
    FIELD_SWEEP
    | {"ksp_max_it": "2000"}
    | {
        f"fieldsplit_{f}_{k}": v
        for f in ("temperature", "potential", "displacement")
        for k, v in {"ksp_type": "preonly", "pc_type": "gamg", "pc_gamg_threshold": "0.02"}.items()
    }
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
        inexact: An iterative solve stops where Newton's tolerance on every field's true
            residual is met (an inexact Newton), not at its ``ksp_rtol``.
        splits: For a ``fieldsplit`` preconditioner, the fields of each split by its name
            (its options under ``fieldsplit_<name>_``), in the order of the sweep, e.g.
            :data:`~subdomain_contact.solvers.THERMOELECTRIC_MECHANICAL`; fields the problem
            lacks are left out. Default: one split per field, named by it, in the problem's
            order.
        keep: Keep the factorisation across Newton steps as the preconditioner of the Krylov
            solve on each new Jacobian (not for ``ksp_type preonly``), and factorise again at
            the next Jacobian once the solves on it have cost, beyond the time of its first
            solve each, ``keep`` times the time of its factorisation (1: the ski-rental rule,
            within twice the cost of the best choice of steps in hindsight); at once where a
            solve on a kept factorisation fails. None: factorise every Jacobian. The times
            are wall-clock, the slowest rank's, so which steps factorise may differ between
            runs; each step is still solved to the Krylov tolerance. For Jacobians that move
            little from step to step: on the collector bar slot at 1.14M DOFs (the field
            split in single precision) four of five kept factorisations failed their budget
            and the fine level took 982 s against 736 s (docs/collector_bar_slot.md).

    Call :meth:`destroy` (collectively) when done.
    """

    def __init__(
        self,
        options: Mapping[str, str] = DIRECT,
        *,
        prefix: str = "sc_monolithic_",
        monitor: Callable[[int, Callable[[], Vector]], None] | None = None,
        refine: int = 0,
        inexact: bool = False,
        splits: Mapping[str, Sequence[str]] | None = None,
        keep: float | None = None,
    ) -> None:
        krylov = options.get("ksp_type", "preonly")
        if keep is not None and (not keep >= 0.0 or krylov == "preonly"):
            raise ValueError(
                f"Monolithic(keep={keep}): a kept factorisation needs a Krylov solve (options "
                f"give ksp_type {krylov}) and keep ≥ 0"
            )
        self.keep = keep
        self.options, self.prefix, self.monitor = options, prefix, monitor
        self.refine, self.inexact = refine, inexact
        self.groups = None if splits is None else {k: tuple(v) for k, v in splits.items()}
        self.system: System | None = None
        self.splits: list[tuple[str, PETSc.IS]] = []
        self.K: PETSc.Mat | None = None
        self.ksp: PETSc.KSP | None = None
        #: Set-ups of the merged matrix's solve: factorisations, for a direct one.
        self.factorisations = 0
        #: Solves on a factorisation kept from an earlier Jacobian that converged (``keep``).
        self.reuses = 0
        #: Krylov solves made again from their iterate, whose true residual was above their
        #: tolerance (:meth:`_krylov`).
        self.restarts = 0
        self._made: Mapping[str, str] = {}  # the options the KSP was made with
        self._shell: PETSc.Mat | None = None  # J applied by the assembled blocks
        self._plan: MergePlan | None = None  # K's pattern, and where the blocks go in it
        self._stale = False  # the operator has values the factorisation has not seen
        self._factorised = 0.0  # seconds of the last factorisation [s]
        self._first: float | None = None  # seconds of the first solve on it [s]
        self._first_iterations = 1  # its iterations
        self._excess = 0.0  # seconds of the later solves beyond the first's [s]

    def _bddc(self) -> bool:
        """Whether the solve is PCBDDC (given in ``options`` or on the command line)."""
        database, key = PETSc.Options(), self.prefix + "pc_type"
        given = database.getString(key) if database.hasName(key) else self.options.get("pc_type")
        return given == "bddc"

    def check(self, system: System) -> None:
        """Refuse what cannot be solved, before any assembly.

        BDDC on a rank that holds part of a body (the merged matrix takes any); a field split
        that leaves a field out or puts it twice, or whose options name no split.
        """
        if self.options.get("pc_type") == "fieldsplit":
            _groups(system.problem.fields, self.groups)  # each field in one split
            names = set(self.groups or FIELDS)  # a preset may name fields the problem lacks
            for key in self.options:
                if key.startswith("fieldsplit_") and not any(
                    key.startswith(f"fieldsplit_{name}_") for name in names
                ):
                    raise ValueError(
                        f"monolithic field split: option {key} names none of the splits "
                        f"{sorted(names)} (give them: Monolithic(splits=...))"
                    )
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
        failed = self.ksp is not None and self.ksp.getPC().getFailedReason() != 0
        if (
            self.ksp is not None
            and self.keep is not None
            and not failed
            and self._excess < self.keep * self._factorised
        ):
            # the factorisation of an earlier Jacobian preconditions GMRES on this one,
            # applied by the assembled blocks (``System.mult``): no merged matrix is made
            # (at 1.14M DOFs the merge beside the kept factors ran a node out of memory)
            self.ksp.setOperators(self._jacobian(), self.K)
            self._stale = True
            return
        self._merge(system)

    def _jacobian(self) -> PETSc.Mat:
        """``J`` applied by the system's assembled blocks (a shell matrix in K's layout)."""
        if self._shell is None:
            solve = self

            class Jacobian:
                def mult(self, mat: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
                    solve.system.mult(x, y)

            self._shell = PETSc.Mat().createPython(self.K.getSizes(), comm=self.K.getComm())
            self._shell.setPythonContext(Jacobian())
            self._shell.setUp()
        return self._shell

    def _merge(self, system: System) -> None:
        """Merge the blocks into ``K`` and factorise it (in place where the pattern is K's)."""
        failed = self.ksp is not None and self.ksp.getPC().getFailedReason() != 0
        if self._bddc():  # made anew each Newton step (``setup`` freed the last)
            self.destroy()
            self.K = unassembled_matrix(system)
        else:
            if self.K is not None and self._plan and merge_shortfall(self._plan, system.comm):
                self._free()  # the values would not fit beside K and its factors
            data = self._plan.values(system) if self._plan is not None else None
            if data is not None and self.K is not None and not failed:
                # the same sparsity (a new Newton step): the values written into K in
                # place, and MUMPS keeps its analysis and its workspace (a factorisation made
                # again in place took no memory beyond the first's, measured)
                self._plan.write(self.K, data)
                del data
                self._factorise()
                return
            self._free()  # a new matrix: a new analysis, the old factors freed first
            if data is None:  # a new pattern
                self._plan = None  # the old plan freed before the new one is made
                self._plan = MergePlan(system)
                data = self._plan.values(system)
            self.K = self._plan.matrix(system.comm, data)
            del data
        dim, rows = system.problem.scene.dim, self.K.getSize()[0]
        self._made = ordered(self.options, dim, rows, again=not system.is_linear)
        if self._made.get("pc_type") == "fieldsplit":
            self.splits = field_splits(system, self.groups)
        self._make()

    def _clock(self, work: Callable[[], None]) -> float:
        """Run ``work`` (collective); its wall-clock time on the slowest rank [s]."""
        start = time.perf_counter()
        work()
        return self.K.getComm().tompi4py().allreduce(time.perf_counter() - start, op=MPI.MAX)

    def _make(self) -> None:
        """A new KSP on ``K`` from the options it was made with (analysis and factorisation)."""

        def make() -> None:
            self.ksp = make_ksp(self.K, self.prefix, self._made, splits=self.splits)
            self.ksp.getPC().setReusePreconditioner(self.keep is not None)

        self._fresh(self._clock(make))
        if self.monitor is not None:

            def watch(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
                def iterate() -> Vector:
                    built = ksp.buildSolution()
                    values = built.array.copy()
                    built.destroy()
                    return values

                self.monitor(iteration, iterate)

            self.ksp.setMonitor(watch)

    def _factorise(self) -> None:
        """Factorise ``K``'s new values in place (MUMPS keeps its analysis)."""

        def factorise() -> None:
            pc = self.ksp.getPC()
            pc.setReusePreconditioner(False)
            self.ksp.setOperators(self.K)  # else a KSP set up once does not set up its PC again
            set_up(self.ksp)  # the splits too: their time is the set-up's
            pc.setReusePreconditioner(self.keep is not None)

        self._fresh(self._clock(factorise))

    def _fresh(self, seconds: float) -> None:
        """Count a factorisation that took ``seconds`` [s]; its solves start afresh."""
        self.factorisations += 1
        self._factorised, self._first, self._excess, self._stale = seconds, None, 0.0, False

    def _stale_limit(self, limit: int) -> int:
        """Iterations a solve on the kept factorisation may take (at most ``limit``).

        Its first solve's iterations, plus those that the rest of the budget (``keep``
        times the factorisation's time, less the excess so far) pays for at its first solve's
        time per iteration; beyond, factorising again is cheaper.
        """
        per_iteration = self._first / self._first_iterations
        budget = max(0.0, self.keep * self._factorised - self._excess)
        extra = budget / per_iteration if per_iteration > 0.0 else np.inf
        return int(min(limit, self._first_iterations + 1 + min(extra, limit)))

    def solve(self, b: Vector | None, tolerance: Tolerance) -> tuple[Vector, InterfaceResult]:
        """One solve; its result counts the iterations of an iterative solve as rounds.

        On a kept factorisation (``keep``) a failed solve factorises the matrix and solves
        again.
        """
        rhs, x = self.K.createVecs()
        rhs.array[:] = 0.0 if b is None else b
        if self.inexact and tolerance.atol is not None:
            self.ksp.setConvergenceTest(self._per_field(dict(tolerance.atol)))
        limit = self.ksp.getTolerances()[3]
        if self._stale:  # no more iterations than the rest of the budget pays for
            self.ksp.setTolerances(max_it=self._stale_limit(limit))
        seconds, counted = self._krylov(rhs, x)
        iterations = counted
        self.ksp.setTolerances(max_it=limit)
        reason = self.ksp.getConvergedReason()
        if reason >= 0 and self._stale:
            self.reuses += 1
        if reason < 0 and self._stale:  # this Jacobian merged and factorised after all
            self._merge(self.system)
            if self.inexact and tolerance.atol is not None:
                self.ksp.setConvergenceTest(self._per_field(dict(tolerance.atol)))
            seconds, counted = self._krylov(rhs, x)
            reason = self.ksp.getConvergedReason()
            iterations += counted
        if self._first is None:  # the time and iterations of the solve on this factorisation
            self._first, self._first_iterations = seconds, max(1, counted)
        else:
            self._excess += max(0.0, seconds - self._first)
        residual, correction = self.K.createVecs()
        for _ in range(self.refine):
            self.ksp.getOperators()[0].mult(x, residual)
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

    def _krylov(self, rhs: PETSc.Vec, x: PETSc.Vec) -> tuple[float, int]:
        """Solve into ``x``, a Krylov solve checked on its true residual: (seconds, iterations).

        A Krylov solve goes on from its iterate while ``‖b − J x‖`` exceeds
        :data:`TRUE_RESIDUAL_MARGIN` times its tolerance (at most
        :data:`TRUE_RESIDUAL_RESTARTS` times): GMRES's ``rtol ‖b‖`` or ``atol``, or the
        round-off floor of ``J x`` where that is larger. GMRES stops on the residual of its
        recurrence, which drifts from the true one by the round-off of the preconditioner's
        applications: with factors in single precision and block low-rank, the slot at 1.2M
        DOFs reached Newton's 1.1e-4 as with full-rank factors, then 1.4e-5 where they gave
        9.1e-8, and cycled at 8e-6 (docs/collector_bar_slot.md). The iterations count every solve.
        """
        ksp, iterations, restarts = self.ksp, 0, 0
        seconds = self._clock(lambda: ksp.solve(rhs, x))
        iterations += ksp.getIterationNumber()
        if ksp.getType() == "preonly" or self.inexact:  # the inexact test is on it already
            return seconds, iterations
        rtol, atol, _, _ = ksp.getTolerances()
        tolerance, floor = max(rtol * rhs.norm(), atol), None
        residual = rhs.duplicate()
        guess = ksp.getInitialGuessNonzero()
        while ksp.getConvergedReason() > 0 and restarts < TRUE_RESIDUAL_RESTARTS:
            ksp.getOperators()[0].mult(x, residual)
            residual.aypx(-1.0, rhs)
            norm = residual.norm()
            if norm <= TRUE_RESIDUAL_MARGIN * tolerance:
                break
            if floor is None:  # the product's round-off, ε ‖K‖_F (≥ ε ‖K‖₂), only where needed
                floor = np.finfo(float).eps * _frobenius_bound(self.K)
            if norm <= TRUE_RESIDUAL_MARGIN * floor * x.norm():
                break
            restarts += 1
            ksp.setInitialGuessNonzero(True)
            seconds += self._clock(lambda: ksp.solve(rhs, x))
            iterations += ksp.getIterationNumber()
        ksp.setInitialGuessNonzero(guess)
        residual.destroy()
        self.restarts += restarts
        return seconds, iterations

    def _per_field(self, atol: dict[str, float]) -> Callable:
        """A KSP convergence test: every field's true residual ‖r_f‖ ≤ ``atol[f]`` [W, A, N].

        One test of the whole residual would mix units: the displacement's rows (N) hide the
        potential's (A), and GMRES stagnates near round-off of the largest before the
        smallest is met (four 3D blocks, T, φ, u: a true relative residual of 3e-10).
        """
        reasons, max_it = PETSc.KSP.ConvergedReason, self.ksp.getTolerances()[3]

        def converged(ksp: PETSc.KSP, iteration: int, norm: float) -> int:
            r = ksp.buildResidual()
            norms = self.system.field_norms(r)
            r.destroy()
            if all(norms[f] <= atol[f] for f in atol):
                return reasons.CONVERGED_ATOL
            return reasons.DIVERGED_ITS if iteration >= max_it else reasons.ITERATING

        return converged

    def _free(self) -> None:
        """Free the merged matrix and its factorisation, the plan of its pattern kept."""
        destroy(self.K, self.ksp, self._shell, *(iset for _, iset in self.splits))
        self.K, self.ksp, self._shell, self.splits = None, None, None, []

    def destroy(self) -> None:
        """Free the merged matrix, its factorisation and its pattern's plan (collective)."""
        self._free()
        self._plan = None


#: How far a Krylov solve's true residual may exceed its tolerance before it is solved on
#: from its iterate: the recurrence's round-off (a few units of the tolerance), not its drift.
TRUE_RESIDUAL_MARGIN = 10.0
#: Solves on from the iterate at most, after the first (each converges by its recurrence).
TRUE_RESIDUAL_RESTARTS = 3


def _frobenius_bound(K: PETSc.Mat) -> float:
    """‖K‖_F, or for an unassembled (MATIS) matrix the sum of its local matrices' (≥ it)."""
    frobenius = PETSc.NormType.FROBENIUS
    if K.getType() != PETSc.Mat.Type.IS:
        return K.norm(frobenius)
    local = K.getISLocalMat().norm(frobenius)
    return K.getComm().tompi4py().allreduce(local)


def merge_shortfall(plan: MergePlan, comm: MPI.Comm) -> str | None:
    """Why the next state's values would not fit beside the matrix and its factors, or None.

    The plan's :attr:`~subdomain_contact.merged.MergePlan.values_bytes` against the memory
    the node shortest of it has left (collective).
    """
    need, available = node_memory(plan.values_bytes, comm)
    if available is None or need <= available:
        return None
    return (
        f"writing the next matrix's values needs about {need / 1e9:.3g} GB on a node where "
        f"{available / 1e9:.3g} GB is available"
    )


def _groups(
    fields: Sequence[str], splits: Mapping[str, Sequence[str]] | None
) -> dict[str, tuple[str, ...]]:
    """The splits' fields among ``fields`` (default one split per field); every field in one."""
    if splits is None:
        return {f: (f,) for f in fields}
    groups = {k: tuple(f for f in v if f in fields) for k, v in splits.items()}
    groups = {k: v for k, v in groups.items() if v}
    placed = [f for v in groups.values() for f in v]
    for f in fields:
        if placed.count(f) != 1:
            raise ValueError(
                f"monolithic field split: field {f!r} is in {placed.count(f)} of the splits "
                f"{dict(splits)} (each field in exactly one)"
            )
    return groups


def field_splits(
    system: System, splits: Mapping[str, Sequence[str]] | None = None
) -> list[tuple[str, PETSc.IS]]:
    """Each split's owned rows of the merged matrix (bodies', then masters'), ascending.

    ``splits``: the fields of each split by its name (default: one split per field, named by
    it). A split of the displacement alone carries the rigid motions of the whole as its
    near-null space, which PCFIELDSPLIT hands to its block's GAMG; row by row (a contact may
    carry the normal component alone, so the rows are not blocked by node). Destroy the sets
    when done.
    """
    comm, dim = system.comm, system.problem.scene.dim
    start = comm.exscan(system.local_size) or 0  # None on rank 0
    by_field = {}
    for field in system.problem.fields:
        rows, points, components = [np.zeros(0, int)], [np.zeros((0, 3))], [np.zeros(0, int)]
        for name, body in system.bodies.items():
            V, parent_of = body.forms.collapsed(field)
            bs, owned = V.dofmap.index_map_bs, V.dofmap.index_map.size_local
            rows.append(parent_of[: owned * bs] + start + system.slices[name].start)
            points.append(np.repeat(V.tabulate_dof_coordinates()[:owned], bs, axis=0))
            components.append(np.tile(np.arange(bs), owned))
        offset = start + system.master_slice.start
        for layer in system.layers.values() if comm.rank == 0 else ():
            for c, (f, component) in enumerate(layer.channels):
                if f == field:
                    rows.append(offset + c * layer.nodes + np.arange(layer.nodes))
                    points.append(layer.coordinates)
                    components.append(np.full(layer.nodes, component or 0))
            offset += layer.size
        by_field[field] = (np.concatenate(rows), np.concatenate(points), np.concatenate(components))
    made = []
    for name, fields in _groups(system.problem.fields, splits).items():
        rows = np.concatenate([by_field[f][0] for f in fields])
        order = np.argsort(rows)
        iset = PETSc.IS().createGeneral(rows[order].astype(PETSc.IntType), comm=comm)
        if fields == ("displacement",):
            at, of = by_field["displacement"][1][order], by_field["displacement"][2][order]
            space = _rigid_motions(comm, at, of, dim)
            iset.compose("nearnullspace", space)
            space.destroy()  # the set holds its reference
        made.append((name, iset))
    return made


def _rigid_motions(
    comm: MPI.Comm, points: npt.NDArray[np.float64], components: npt.NDArray, dim: int
) -> PETSc.NullSpace:
    """The rigid motions on rows of displacement component ``components`` at ``points``."""
    x = points - centre(points, comm)
    vectors = []
    for mode in modes(("displacement",), dim):
        v = PETSc.Vec().createMPI((len(x), PETSc.DETERMINE), comm=comm)
        v.array[:] = 0.0
        for c in range(dim):
            at = components == c
            v.array[at] = mode("displacement", c, x[at])
        vectors.append(v)
    return span(vectors, comm)
