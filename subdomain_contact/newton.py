"""Newton outside (PETSc SNES), the subdomain iteration inside, and the monolithic reference.

SNES drives Newton's method on the whole coupled system of :mod:`coupled`, with its line
search (full steps by default, backtracking on request) and its function and
Jacobian callbacks. Each linearised system ``J Δ = F`` is solved by a Python preconditioner
under ``ksp_type preonly``: either the subdomain iteration (bodies solved with the masters
fixed, masters corrected) or a direct solve of the merged matrix (the monolithic Newton). Both
run the same Newton on the same discrete problem, so their results agree to solver precision.

The subdomain iteration stops when each field's master residual is below ``η ‖F_f‖``, with
the forcing term ``η = min(1e-4, max_f ‖F_f‖/scale_f)`` (the slowest field sets it): tight
enough that the inexact steps follow the exact Newton path, and tighter near the solution,
which keeps Newton's quadratic convergence.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import scipy.linalg
from petsc4py import PETSc

from subdomain_contact.coupled import CoupledBody, CoupledSystem
from subdomain_contact.multiphysics import FIELDS
from subdomain_contact.solvers import DIRECT, destroy, make_ksp

__all__ = [
    "InnerConvergenceError",
    "MonolithicLinearSolver",
    "NewtonConvergenceError",
    "NewtonResult",
    "NewtonStep",
    "SubdomainLinearSolver",
    "solve_newton",
]

_REASONS = {
    getattr(PETSc.SNES.ConvergedReason, n): n
    for n in dir(PETSc.SNES.ConvergedReason)
    if n.isupper()
}


class InnerConvergenceError(RuntimeError):
    """The subdomain iteration of one Newton step did not reach its tolerance."""


class SubdomainLinearSolver:
    """``J Δ = b`` by the subdomain iteration (METHOD.md §3) on the linearised blocks.

    Each round solves every body with the master increments fixed, forms the master residual
    ``R_k = Σ_α (C_k Δ^α + D_k Δ_m,k) − b_m,k`` and corrects ``Δ_m,k −= K_C,k⁻¹ R_k``.

    Args:
        system: The coupled system (its Jacobian assembled before :meth:`setup`).
        corrector: ``"exact"``: ``K_C = Σ_α S^α_k``, each body's exact condensed Jacobian on
            interface k, ``S = D − C A⁻¹ B`` (one correction suffices for one interface).
            ``"method1"``: ``K_C = Σ_α D^α_k``, the half-links alone (paper's method 1).
        max_rounds: Rounds (or GMRES iterations) allowed per linear solve.
        krylov: Accelerate by GMRES on the interface problem, preconditioned by the
            correctors (a round per iteration): what several interfaces per body need. Without
            it the correctors act as block Jacobi across interfaces (the paper's fixed point).
    """

    def __init__(
        self,
        system: CoupledSystem,
        *,
        corrector: str = "exact",
        max_rounds: int = 100,
        krylov: bool = False,
    ) -> None:
        if corrector not in ("exact", "method1"):
            raise ValueError(f"corrector = {corrector!r}: 'exact' or 'method1'")
        self.system, self.corrector, self.max_rounds = system, corrector, max_rounds
        self.krylov = krylov
        self.factors: dict[str, tuple] = {}

    def setup(self) -> None:
        """Factorise the bodies, then build and factorise each interface's corrector."""
        for body in self.system.bodies.values():
            body.factorise()
        for k, m in self.system.sizes.items():
            total = np.zeros((m, m))
            for body in self.system.bodies_on(k):
                total += self._condensed(body, k, m)
            self.factors[k] = scipy.linalg.lu_factor(total)

    def _condensed(self, body: CoupledBody, k: str, m: int) -> npt.NDArray[np.float64]:
        """Dense ``P_kᵀ (D − C A⁻¹ B) P_k`` (exact) or ``P_kᵀ D P_k`` (method 1)."""
        S = np.zeros((m, m))
        for j in range(m):
            unit = np.zeros(m)
            unit[j] = 1.0
            S[:, j] = body.apply_D(k, unit)
            if self.corrector == "exact":
                y = body.solve(body.couple({k: unit}))
                S[:, j] -= body.apply_C(k, y, m)
        return S

    def solve(
        self, b: npt.NDArray[np.float64], tolerance: dict[str, float]
    ) -> tuple[npt.NDArray[np.float64], int]:
        """Solve until each field's master residual is below its tolerance; (Δ, rounds)."""
        if self.krylov:
            return self._solve_krylov(b, tolerance)
        system = self.system
        dm = {k: np.zeros(n) for k, n in system.sizes.items()}
        first = None
        for rounds in range(1, self.max_rounds + 1):
            out, R = self._round(b, dm)
            norms = self._field_norms(R)
            first = norms if first is None else first
            if all(norms[f] <= tolerance[f] for f in norms):
                return out, rounds
            if not all(
                np.isfinite(v) and v <= 1e8 * max(first[f], tolerance[f]) for f, v in norms.items()
            ):
                break
            for k in dm:
                dm[k] -= scipy.linalg.lu_solve(self.factors[k], R[k])
        raise InnerConvergenceError(
            f"subdomain iteration ({self.corrector} corrector): master residual {_fmt(norms)} "
            f"after {rounds} rounds, tolerance {_fmt(tolerance)} (first round {_fmt(first)})"
        )

    def _round(
        self, b: npt.NDArray[np.float64] | None, dm: dict[str, np.ndarray]
    ) -> tuple[npt.NDArray[np.float64], dict[str, np.ndarray]]:
        """Solve every body with master increments ``dm``; (Δ, master residual per interface).

        With ``b = None`` the right-hand side is zero: ``R`` is then the interface operator
        ``Σ_α (D − C A⁻¹ B) dm`` applied to ``dm``.
        """
        system = self.system
        out = np.zeros(system.local_size)
        masters = system.split_masters(b[system.master_slice]) if b is not None else None
        R = {k: -masters[k] if b is not None else np.zeros(n) for k, n in system.sizes.items()}
        for name, body in system.bodies.items():
            rhs = -body.couple(dm)
            if b is not None:
                rhs += b[system.slices[name]]
            xb = body.solve(rhs)
            out[system.slices[name]] = xb
            for k in body.slaves:
                R[k] += body.apply_C(k, xb, system.sizes[k]) + body.apply_D(k, dm[k])
        out[system.master_slice] = system.join_masters(dm)
        return out, R

    def _solve_krylov(
        self, b: npt.NDArray[np.float64], tolerance: dict[str, float]
    ) -> tuple[npt.NDArray[np.float64], int]:
        """GMRES on the interface problem ``S dm = −R(0)``, preconditioned by the correctors.

        Rows are scaled by each field's tolerance, so that ``‖W r‖ ≤ 1`` bounds every field's
        master residual by its own tolerance (W, A and N never share one norm).
        """
        system = self.system
        zero = {k: np.zeros(n) for k, n in system.sizes.items()}
        out, R0 = self._round(b, zero)
        weights = {
            k: 1.0 / np.array([tolerance[FIELDS[f]] for f in system.master_fields[k]])
            for k in system.sizes
        }
        if all(np.linalg.norm(weights[k] * R0[k]) <= 1.0 for k in R0):
            return out, 1
        shell = _InterfaceShell(self, weights)
        local = system.local_size - system.master_slice.start
        S = PETSc.Mat().createPython(
            ((local, None), (local, None)), context=shell, comm=system.comm
        )
        S.setUp()
        ksp = PETSc.KSP().create(system.comm)
        ksp.setOptionsPrefix("sc_newton_interface_")
        ksp.setOperators(S)
        ksp.setType("gmres")
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(shell)
        ksp.setTolerances(rtol=0.0, atol=1.0, max_it=self.max_rounds)
        ksp.setFromOptions()
        rhs, x = S.createVecs()
        rhs.array[:] = system.join_masters({k: -weights[k] * R0[k] for k in R0})
        ksp.solve(rhs, x)
        reason, iterations = ksp.getConvergedReason(), ksp.getIterationNumber()
        dm = system.split_masters(x.array_r)
        destroy(ksp, S, rhs, x)
        out, R = self._round(b, dm)
        norms = self._field_norms(R)
        if reason < 0 or not all(norms[f] <= 1.01 * tolerance[f] for f in norms):
            raise InnerConvergenceError(
                f"interface GMRES ({self.corrector} corrector): master residual {_fmt(norms)} "
                f"after {iterations} iterations (reason {reason}), tolerance {_fmt(tolerance)}"
            )
        return out, iterations + 2

    def _field_norms(self, R: dict[str, np.ndarray]) -> dict[str, float]:
        """2-norm of each field's part of replicated master vectors."""
        fields = self.system.problem.fields
        norms = dict.fromkeys(fields, 0.0)
        for k, r in R.items():
            for f in fields:
                norms[f] += float(np.sum(r[self.system.master_fields[k] == FIELDS.index(f)] ** 2))
        return {f: float(np.sqrt(v)) for f, v in norms.items()}


def _fmt(values: dict[str, float]) -> str:
    return ", ".join(f"{f} {v:.3e}" for f, v in values.items())


class _InterfaceShell:
    """Python context: the scaled interface operator ``W S`` and its preconditioner."""

    def __init__(self, solver: SubdomainLinearSolver, weights: dict[str, np.ndarray]) -> None:
        self.solver, self.weights = solver, weights

    def mult(self, mat, x, y) -> None:
        system = self.solver.system
        dm = system.split_masters(x.array_r)
        _, R = self.solver._round(None, dm)
        y.array[:] = system.join_masters({k: self.weights[k] * R[k] for k in R})

    def apply(self, pc, x, y) -> None:
        system = self.solver.system
        r = system.split_masters(x.array_r)
        factors = self.solver.factors
        y.array[:] = system.join_masters(
            {k: scipy.linalg.lu_solve(factors[k], r[k] / self.weights[k]) for k in r}
        )


class MonolithicLinearSolver:
    """``J Δ = b`` by a solve of the merged matrix: the reference (MUMPS by default).

    Args:
        system: The coupled system (its Jacobian assembled before :meth:`setup`).
        options: PETSc options of the solve (an iterative one stops at its own ``ksp_rtol``).
    """

    def __init__(self, system: CoupledSystem, options: Mapping[str, str] = DIRECT) -> None:
        self.system, self.options = system, options
        self.K: PETSc.Mat | None = None
        self.ksp: PETSc.KSP | None = None

    def setup(self) -> None:
        """Merge the blocks into one AIJ matrix and factorise it."""
        system = self.system
        names, interfaces = list(system.bodies), list(system.sizes)
        n = len(names) + len(interfaces)
        blocks: list[list[PETSc.Mat | None]] = [[None] * n for _ in range(n)]
        made = []
        for a, name in enumerate(names):
            body = system.bodies[name]
            blocks[a][a] = body.A
            for m, k in enumerate(interfaces, start=len(names)):
                if k not in body.slaves:
                    continue
                P = self._prolongation(body, k)
                BP, PtC, PtDP = (
                    body.B[k].matMult(P),
                    P.transposeMatMult(body.C[k]),
                    body.D[k].PtAP(P),
                )
                blocks[a][m], blocks[m][a] = BP, PtC
                if blocks[m][m] is None:
                    blocks[m][m] = PtDP
                else:
                    blocks[m][m].axpy(1.0, PtDP, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                    made.append(PtDP)
                made += [P, BP, PtC]
        made += [blocks[m][m] for m in range(len(names), n)]
        nest = PETSc.Mat().createNest(blocks, comm=system.comm)
        destroy(self.K, self.ksp)
        self.K = nest.convert("aij", out=PETSc.Mat())
        self.ksp = make_ksp(self.K, "sc_coupled_monolithic_", self.options)
        destroy(nest, *made)

    def _prolongation(self, body: CoupledBody, k: str) -> PETSc.Mat:
        """``P_k``: body rows × master columns (all owned by rank 0), 1 at slave DOFs."""
        m = self.system.sizes[k]
        local = m if self.system.comm.rank == 0 else 0
        P = PETSc.Mat().createAIJ(
            ((body.size, PETSc.DETERMINE), (local, m)), nnz=(1, 1), comm=self.system.comm
        )
        slaves = body.slaves[k]
        for dof, master in zip(slaves.local_dofs, slaves.master_index, strict=True):
            P.setValue(body.start + int(dof), int(master), 1.0)
        P.assemble()
        return P

    def solve(
        self, b: npt.NDArray[np.float64], tolerance: dict[str, float]
    ) -> tuple[npt.NDArray[np.float64], int]:
        """Direct solve; returns (Δ, 1)."""
        rhs, x = self.K.createVecs()
        rhs.array[:] = b
        self.ksp.solve(rhs, x)
        if self.ksp.getConvergedReason() < 0:
            raise InnerConvergenceError(
                f"monolithic linear solve failed (PETSc reason {self.ksp.getConvergedReason()}"
                f" after {self.ksp.getIterationNumber()} iterations)"
            )
        out = x.array.copy()
        destroy(rhs, x)
        return out, max(1, self.ksp.getIterationNumber())

    def __del__(self) -> None:
        """Destroy the merged matrix and its factorisation."""
        destroy(self.__dict__.get("K"), self.__dict__.get("ksp"))


@dataclass
class NewtonStep:
    """One Newton iterate: its residual and the inner solve that led to it.

    Attributes:
        iteration: Newton iteration (0: the initial state).
        residual: 2-norm of the whole residual.
        fields: 2-norm of each field's residual [W, A, N].
        inner_rounds: Subdomain rounds of the linear solve that produced this iterate (0 at
            iteration 0; 1 for the monolithic direct solve).
    """

    iteration: int
    residual: float
    fields: dict[str, float]
    inner_rounds: int


@dataclass
class NewtonResult:
    """Outcome of a Newton solve: the history, the reason and the wall time [s].

    ``scale`` holds each field's residual scale [W, A, N] that the convergence test used.
    """

    history: list[NewtonStep] = field(default_factory=list)
    reason: str = ""
    seconds: float = 0.0
    scale: dict[str, float] = field(default_factory=dict)

    @property
    def iterations(self) -> int:
        """Newton iterations taken."""
        return self.history[-1].iteration if self.history else 0

    def relative_residuals(self) -> npt.NDArray[np.float64]:
        """Newton's own measure per iterate: ``max_f ‖F_f‖ / scale_f`` (fields never mix)."""
        fields = [f for f, value in self.scale.items() if value > 0]
        return np.array([max(s.fields[f] / self.scale[f] for f in fields) for s in self.history])

    def order(self, floor: float = 1e-10) -> float:
        """Convergence order from the last three iterates whose relative residual is > floor.

        For ``ρ_{k+1} = C ρ_k²`` this is ``2 + ln(C_k/C_{k−1}) / ln(ρ_k/ρ_{k−1})``; a linear
        rate gives about 1. Below ``floor`` the residual is round-off, not Newton: choose it
        above the relative residual the converged state itself leaves.

        Raises:
            ValueError: Fewer than three iterates above ``floor``.
        """
        rho = self.relative_residuals()
        above = rho[rho > floor][-3:]
        if len(above) < 3:
            raise ValueError(f"order: fewer than three relative residuals above {floor:g}: {rho}")
        return float(np.log(above[2] / above[1]) / np.log(above[1] / above[0]))

    def table(self) -> str:
        """The history as text lines, one per iterate."""
        return "\n".join(
            f"  {s.iteration:3d}  |F| = {s.residual:.3e}  "
            + "  ".join(f"{n} {v:.2e}" for n, v in s.fields.items())
            + f"  inner rounds {s.inner_rounds}"
            for s in self.history
        )


class NewtonConvergenceError(RuntimeError):
    """Newton did not converge; ``result`` holds its history."""

    def __init__(self, message: str, result: NewtonResult) -> None:
        super().__init__(message)
        self.result = result


class _Callbacks:
    """SNES callbacks: residual and Jacobian; product and inner solve as Python contexts.

    The object is the Python context of the shell Jacobian (``mult``) and of the
    preconditioner that runs the inner solve (``apply``).
    """

    def __init__(self, system, linear, rtol: float, max_it: int, monitor=None) -> None:
        self.system, self.linear, self.rtol, self.max_it = system, linear, rtol, max_it
        self.monitor = monitor
        self.result = NewtonResult()
        self.scale: dict[str, float] = {}
        self.eta = 1e-4
        self.pending_rounds = 0
        self.failure: Exception | None = None

    def function(self, snes, x, f) -> None:
        self._guard(lambda: (self.system.set_state(x), self.system.residual(f)))

    def jacobian(self, snes, x, J, P) -> None:
        def assemble():
            self.system.set_state(x)
            self.system.assemble_jacobian()
            self.linear.setup()

        self._guard(assemble)

    def mult(self, mat, x, y) -> None:
        self._guard(lambda: self.system.mult(x, y))

    def apply(self, pc, b, y) -> None:
        def inner():
            norms = self.system.field_norms(b)
            tolerance = {
                f: max(self.eta * v, 1e-3 * self.rtol * self.scale[f]) for f, v in norms.items()
            }
            delta, rounds = self.linear.solve(b.array_r, tolerance)
            y.array[:] = delta
            self.pending_rounds += rounds

        self._guard(inner)

    def converged(self, snes, it, norms) -> int:
        reasons = PETSc.SNES.ConvergedReason
        f = snes.getFunction()[0]
        fields = self.system.field_norms(f)
        total = float(np.sqrt(sum(v**2 for v in fields.values())))
        self.result.history.append(NewtonStep(it, total, fields, self.pending_rounds))
        self.pending_rounds = 0
        if self.monitor is not None:
            self.system.set_state(snes.getSolution())
            self.monitor(it)
        if not np.isfinite(total):
            return reasons.DIVERGED_FNORM_NAN
        for name, value in fields.items():
            self.scale[name] = max(self.scale.get(name, 0.0), value)
        progress = [v / self.scale[n] for n, v in fields.items() if self.scale[n] > 0]
        self.eta = min(1e-4, max(progress, default=1e-4))  # the slowest field sets the pace
        if all(v <= self.rtol * self.scale[n] for n, v in fields.items()):
            return reasons.CONVERGED_FNORM_RELATIVE

        if it >= self.max_it:
            return reasons.DIVERGED_MAX_IT
        return reasons.ITERATING

    def _guard(self, action) -> None:
        """Run a callback; keep its exception for the error message (SNES only sees a code)."""
        try:
            action()
        except Exception as error:
            self.failure = error
            raise


def solve_newton(
    system: CoupledSystem,
    *,
    linear: str = "subdomain",
    corrector: str = "exact",
    rtol: float = 1e-10,
    max_it: int = 30,
    line_search: str = "basic",
    max_rounds: int = 100,
    krylov: bool | None = None,
    linear_options: Mapping[str, str] | None = None,
    monitor: Callable[[int], None] | None = None,
) -> NewtonResult:
    """Newton's method on the coupled system, from its current state.

    Converged when every field's residual is below ``rtol`` times its scale: the largest of
    the residuals it has had and of its residual at the *cold state* (every unknown zero but
    the Dirichlet values), which measures the loads the field can see. A field that starts
    at rest (a mechanical state at T_ref) is then judged against its loads, not against its
    own round-off.

    Args:
        system: The coupled system; its state is the initial guess and receives the solution.
        linear: ``"subdomain"`` (the subdomain iteration inside) or ``"monolithic"`` (a
            direct solve of the merged Jacobian: the reference).
        corrector: Corrector of the subdomain iteration: ``"exact"`` or ``"method1"``.
        rtol: Relative tolerance per field.
        max_it: Newton iterations allowed.
        line_search: SNES line search: ``"basic"`` (full steps: the semi-smooth Newton of
            unilateral contact, which finds the contact status in a few steps) or ``"bt"``
            (backtracking on ‖F‖², which mixes W, A and N and can creep when a step changes
            the contact status).
        max_rounds: Subdomain rounds allowed per linear solve.
        krylov: GMRES on the interface problem (see :class:`SubdomainLinearSolver`); by
            default where some body touches several interfaces.
        linear_options: PETSc options of the monolithic linear solve (default: MUMPS).
        monitor: Called with the iteration number at every iterate, the system holding it
            (its time is the caller's to exclude).

    Raises:
        NewtonConvergenceError: Newton (or an inner solve) failed; the error holds the history.
    """
    start = time.perf_counter()
    if linear == "subdomain":
        if krylov is None:
            krylov = any(len(body.slaves) > 1 for body in system.bodies.values())
        solver = SubdomainLinearSolver(
            system, corrector=corrector, max_rounds=max_rounds, krylov=krylov
        )
    elif linear == "monolithic":
        solver = MonolithicLinearSolver(system, linear_options or DIRECT)
    else:
        raise ValueError(f"linear = {linear!r}: 'subdomain' or 'monolithic'")
    callbacks = _Callbacks(system, solver, rtol, max_it, monitor)
    x, f = system.create_vector(), system.create_vector()
    system.get_state(x)
    callbacks.scale = _cold_residuals(system, f)
    system.set_state(x)
    system.apply_conditions()
    system.get_state(x)
    sizes = (x.getLocalSize(), x.getSize())
    J = PETSc.Mat().createPython((sizes, sizes), context=callbacks, comm=system.comm)
    J.setUp()
    snes = PETSc.SNES().create(system.comm)
    snes.setOptionsPrefix("sc_newton_")
    snes.setType("newtonls")
    snes.getLineSearch().setType(line_search)
    snes.setFunction(callbacks.function, f)
    snes.setJacobian(callbacks.jacobian, J, J)
    snes.setConvergenceTest(callbacks.converged)
    snes.setTolerances(max_it=max_it + 1)
    ksp = snes.getKSP()
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(callbacks)
    snes.setFromOptions()
    result = callbacks.result
    try:
        snes.solve(None, x)
        reason = snes.getConvergedReason()
    except PETSc.Error as error:
        reason = None
        cause = callbacks.failure or error
    system.set_state(x)
    result.seconds, result.scale = time.perf_counter() - start, dict(callbacks.scale)
    destroy(snes, J, x, f)
    if reason is None or reason < 0:
        result.reason = _REASONS.get(reason, "error in a callback")
        why = f"{cause}" if reason is None else result.reason
        raise NewtonConvergenceError(
            f"Newton ({linear}) failed after {result.iterations} iterations: {why}\n"
            f"{result.table()}",
            result,
        ) from (cause if reason is None else None)
    result.reason = _REASONS[reason]
    return result


def _cold_residuals(system: CoupledSystem, f: PETSc.Vec) -> dict[str, float]:
    """Each field's residual norm with every unknown zero but the Dirichlet values."""
    system.reset()
    system.apply_conditions()
    system.residual(f)
    return system.field_norms(f)
