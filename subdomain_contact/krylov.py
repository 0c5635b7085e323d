"""The interface problem as a whole: preconditioned CG on the masters of every interface.

With several interfaces per body, the bodies' interface stiffnesses ``S^α`` couple the
interfaces, and floating bodies make the per-interface fixed point stall on their constant
modes (METHOD.md §4). The master residual ``g(U_m) = Σ_α r^α(U_m)`` is affine with the
symmetric positive definite slope ``S = Σ_α S^α`` (the primal Schur complement of the whole
scene), so ``S ΔU_m = −g(0)`` is solved by PETSc's CG:

* the operator applies ``S^α`` body by body, never as a global matrix: a dense ``S^α`` where
  the body has at most ``dense_limit`` master DOFs, else one homogeneous body solve;
* the preconditioner adds the per-interface correctors ``(S^A_kk + S^B_kk)⁻¹`` and a coarse
  correction with one unknown per body (its constant temperature, shared half and half on
  each of its interfaces), as in balancing domain decomposition (Mandel 1993).

A final round of body solves checks the true residual; if the operator's round-off left it
above the tolerance, the correction is repeated (iterative refinement).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from subdomain_contact.subdomain import (
    SubdomainConvergenceError,
    SubdomainResult,
    ThermalSubdomains,
    relative_to_scale,
)

__all__ = ["KrylovResult", "solve_interface_krylov"]

Vector = npt.NDArray[np.float64]


@dataclass
class KrylovResult(SubdomainResult):
    """A subdomain result with the Krylov iterations of each refinement step.

    ``rounds`` counts the rounds of body solves that checked the true residual;
    ``applications`` the operator applications (one homogeneous round each where ``S^α`` is
    matrix-free); ``dense_bodies`` the bodies whose ``S^α`` was formed.
    """

    krylov_iterations: list[int] | None = None
    applications: int = 0
    dense_bodies: int = 0


class _InterfaceSystem:
    """``S = Σ_α S^α`` on the concatenated masters, and its two-level preconditioner."""

    def __init__(self, subdomains: ThermalSubdomains, dense_limit: int, coarse: bool) -> None:
        self.sub = subdomains
        names = list(subdomains.layers)
        sizes = [subdomains.layers[k].size for k in names]
        starts = np.concatenate([[0], np.cumsum(sizes)])
        self.slices = {k: slice(int(starts[i]), int(starts[i + 1])) for i, k in enumerate(names)}
        self.size = int(starts[-1])
        self.dense = {
            name: block.stiffness()
            for name, block in subdomains.blocks.items()
            if 0 < sum(layer.size for layer in block.layers.values()) <= dense_limit
        }
        self.applications = 0
        self.coarse_basis = self._coarse_basis() if coarse else np.zeros((self.size, 0))
        S_Z = np.column_stack([self.apply(z) for z in self.coarse_basis.T]) if coarse else None
        self.coarse_matrix = self.coarse_basis.T @ S_Z if coarse else None

    def split(self, v: Vector) -> dict[str, Vector]:
        return {k: v[s] for k, s in self.slices.items()}

    def apply(self, v: Vector) -> Vector:
        """``S v`` [W] for master values v [K]."""
        parts = self.split(v)
        local = {k: np.zeros(s.stop - s.start) for k, s in self.slices.items()}
        for name, block in self.sub.blocks.items():  # this rank's group's bodies
            own = list(block.layers)
            if name in self.dense:
                response = self.dense[name] @ np.concatenate([parts[k] for k in own])
                pieces = np.split(response, np.cumsum([len(parts[k]) for k in own])[:-1])
                for k, piece in zip(own, pieces, strict=True):
                    local[k] += piece
            else:
                for k, r in block.apply_stiffness({k: parts[k] for k in own}).items():
                    local[k] += r
        self.applications += 1
        total = self.sub.total(local)
        return np.concatenate([total[k] for k in self.slices])

    def _coarse_basis(self) -> npt.NDArray[np.float64]:
        """Orthonormal basis of the body constants: ½ on the masters of each body's interfaces.

        The body vectors are linearly dependent (a chain of n bodies has n − 1 interfaces),
        so the span is kept, not the vectors.
        """
        scene = self.sub.problem.scene
        Z = np.zeros((self.size, len(scene.bodies)))
        for j, body in enumerate(scene.bodies):
            for interface in scene.interfaces_of(body):
                Z[self.slices[interface.name], j] = 0.5
        U, sigma, _ = np.linalg.svd(Z, full_matrices=False)
        return U[:, sigma > 1e-10 * sigma.max()]

    def precondition(self, r: Vector) -> Vector:
        """Per-interface correctors plus the coarse correction (additive, symmetric)."""
        z = np.zeros(self.size)
        for k, s in self.slices.items():
            z[s] = self.sub.operators[k] @ r[s]
        if self.coarse_matrix is not None:
            Z = self.coarse_basis
            z += Z @ np.linalg.solve(self.coarse_matrix, Z.T @ r)
        return z


class _Shell:
    """PETSc shell context: replicated numpy in, the local part of a PETSc Vec out."""

    def __init__(self, function) -> None:
        self.function = function

    def _apply(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        start, end = x.getOwnershipRange()
        full = np.concatenate(x.getComm().tompi4py().allgather(x.getArray(readonly=True)))
        y.setArray(self.function(full)[start:end])

    def mult(self, mat: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self._apply(x, y)

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self._apply(x, y)


def solve_interface_krylov(
    subdomains: ThermalSubdomains,
    *,
    rtol: float = 1e-10,
    dense_limit: int = 32,
    coarse: bool = True,
    max_iterations: int = 500,
    max_refinements: int = 5,
    monitor: Callable[[int, dict[str, Vector]], None] | None = None,
) -> KrylovResult:
    """Solve the master problem of every interface at once by preconditioned CG.

    Args:
        subdomains: Bodies, master layers and per-interface correctors (their
            ``operators``; the default series corrector is the right one here).
        rtol: Tolerance on each interface's master residual relative to its flux scale,
            as in :meth:`ThermalSubdomains.solve`.
        dense_limit: A body with more master DOFs than this applies ``S^α`` by a body
            solve instead of a dense matrix (memory bound: ``dense_limit²`` per body).
            Forming ``S^α`` costs one body solve per master DOF, so it pays only when the
            body has fewer master DOFs than CG needs operator applications (about 20).
        coarse: Add the coarse correction (one unknown per body).
        max_iterations: CG iterations allowed per refinement step.
        max_refinements: Correction steps allowed (the first one usually suffices).
        monitor: Called after every CG iteration with the running count and the master
            values [K] of the iterate (its time is the caller's to exclude).

    Raises:
        SubdomainConvergenceError: CG failed or the true residual did not reach ``rtol``.
    """
    start = time.perf_counter()
    system = _InterfaceSystem(subdomains, dense_limit, coarse)
    comm = subdomains.problem.scene.comm
    masters = {k: np.zeros(layer.size) for k, layer in subdomains.layers.items()}
    result = KrylovResult(
        {n: b.T for n, b in subdomains.blocks.items()}, masters, 0, krylov_iterations=[]
    )
    operator = PETSc.Mat().createPython((system.size, system.size), _Shell(system.apply), comm=comm)
    operator.setUp()
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix("sc_interface_")
    ksp.setOperators(operator)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonContext(_Shell(system.precondition))
    ksp.setFromOptions()
    rhs, delta = operator.createVecs()
    if monitor is not None:

        def watch(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
            if iteration == 0:
                return
            built = ksp.buildSolution()
            step = np.concatenate(comm.allgather(built.getArray(readonly=True)))
            built.destroy()
            done = sum(result.krylov_iterations or [])
            monitor(done + iteration, {k: masters[k] + step[s] for k, s in system.slices.items()})

        ksp.setMonitor(watch)
    try:
        scales: dict[str, float] = {}
        for step in range(max_refinements + 1):
            residual = _round(subdomains, masters, scales)
            result.rounds += 1
            relative = max(
                relative_to_scale(float(np.linalg.norm(residual[s])), scales[k])
                for k, s in system.slices.items()
            )
            result.history.append(float(relative))
            if relative <= rtol:
                break
            if step == max_refinements:
                raise SubdomainConvergenceError(
                    f"interface CG: true residual {relative:.2e} above {rtol:g} after "
                    f"{max_refinements} refinements",
                    result,
                )
            lo, hi = rhs.getOwnershipRange()
            rhs.setArray(-residual[lo:hi])
            ksp.setTolerances(
                rtol=0.1 * rtol * _scale_ratio(scales, residual, system), max_it=max_iterations
            )
            delta.zeroEntries()
            ksp.solve(rhs, delta)
            result.krylov_iterations.append(ksp.getIterationNumber())
            if ksp.getConvergedReason() < 0:
                raise SubdomainConvergenceError(
                    f"interface CG failed (PETSc reason {ksp.getConvergedReason()}) after "
                    f"{ksp.getIterationNumber()} iterations",
                    result,
                )
            step_values = np.concatenate(comm.allgather(delta.getArray(readonly=True)))
            for k, s in system.slices.items():
                masters[k] += step_values[s]
    finally:
        for obj in (ksp, operator, rhs, delta):
            obj.destroy()
    result.applications, result.dense_bodies = system.applications, len(system.dense)
    result.seconds = time.perf_counter() - start
    return result


def _round(
    subdomains: ThermalSubdomains, masters: dict[str, Vector], scales: dict[str, float]
) -> Vector:
    """One round of body solves: the summed master residual (concatenated) [W]."""
    sums, pushed = subdomains.round(masters)
    if not scales:
        scales.update(pushed)
    return np.concatenate([sums[k] for k in subdomains.layers])


def _scale_ratio(scales: dict[str, float], residual: Vector, system: _InterfaceSystem) -> float:
    """Smallest interface flux scale over the residual norm: CG's tolerance in its own terms."""
    norm = float(np.linalg.norm(residual))
    smallest = min((s for s in scales.values() if s > 0), default=norm)
    return min(1.0, smallest / norm) if norm > 0 else 1.0
