"""The monolithic reference: every body and master layer in one system, solved directly.

Unknowns ``[U^α ..., U_m,k ...]``; blocks ``K^α`` (the body matrices of the subdomain solve),
``−h̄_k M_k P_k`` between a body and a master layer, and ``Σ_α h̄_k P_kᵀ M_k P_k`` on each
master layer. It is the same discrete system as the subdomain iteration, with the master
layers merged, so the two must agree to solver precision.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

from subdomain_contact.blocks import BodyBlocks
from subdomain_contact.solvers import DIRECT, destroy, make_ksp

__all__ = ["CG_GAMG", "Monitor", "MonolithicResult", "solve_monolithic"]


@dataclass
class MonolithicResult:
    """Solution of the merged system.

    Temperatures [K] per body, master values [K] per interface, the solve time [s], the
    system's size and the iterations of the solve (1 for a direct solve).
    """

    temperatures: dict[str, npt.NDArray[np.float64]]
    masters: dict[str, npt.NDArray[np.float64]]
    seconds: float
    num_dofs: int
    iterations: int = 1


def _prolongation(block: BodyBlocks, k: str) -> PETSc.Mat:
    """``P_k``: body rows × master columns, 1 where a slave DOF sits on a master DOF."""
    layer = block.layers[k]
    rows = block.V.dofmap.index_map
    cols = layer.V.dofmap.index_map
    P = PETSc.Mat().createAIJ(
        ((rows.size_local, rows.size_global), (cols.size_local, cols.size_global)),
        nnz=(1, 1),
        comm=block.comm,
    )
    slaves = block.slaves[k]
    start = rows.local_range[0]
    for dof, master in zip(slaves.local_dofs, slaves.master_index, strict=True):
        P.setValue(start + int(dof), int(master), 1.0)
    P.assemble()
    return P


#: Called after every iteration of an iterative solve with its number and body name ->
#: the owned temperatures [K] of the iterate.
Monitor = Callable[[int, dict[str, npt.NDArray[np.float64]]], None]

#: Conjugate gradients preconditioned by smoothed-aggregation algebraic multigrid (PETSc's
#: GAMG), to a relative residual of 1e-12: the monolithic iterative solve.
CG_GAMG: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": "1e-12", "ksp_max_it": "5000"}
)


def solve_monolithic(
    blocks: dict[str, BodyBlocks],
    options: Mapping[str, str] | None = None,
    *,
    refine: int = 0,
    monitor: Monitor | None = None,
) -> MonolithicResult:
    """Assemble the merged system from the bodies' blocks and solve it (MUMPS by default).

    Args:
        blocks: Every body's blocks (:func:`body_blocks`; no factorisation needed).
        options: PETSc options of the solve: :data:`DIRECT` (default) or :data:`CG_GAMG`.
        refine: Steps of iterative refinement after the solve (``x += K⁻¹ (b − K x)``).
        monitor: Called after every iteration of an iterative solve (its time is the
            caller's to exclude).
    """
    start = time.perf_counter()
    bodies = list(blocks)
    neighbours = {
        n for b in blocks.values() for layer in b.layers.values() for n in layer.interface.bodies
    }
    if not neighbours <= set(bodies):
        raise ValueError(
            "solve_monolithic: the bodies live on different rank groups; load the scene with "
            "placement='shared' (or on one rank) for the monolithic reference"
        )
    interfaces = sorted({k for b in blocks.values() for k in b.layers})
    n = len(bodies) + len(interfaces)
    rows: list[list[PETSc.Mat | None]] = [[None] * n for _ in range(n)]
    made: list[PETSc.Object] = []  # destroyed at the end, collectively
    lifted: dict[int, np.ndarray] = {}  # master right-hand sides from fixed slave DOFs
    for a, name in enumerate(bodies):
        rows[a][a] = blocks[name].A
    for m, k in enumerate(interfaces, start=len(bodies)):
        for a, name in enumerate(bodies):
            block = blocks[name]
            if k not in block.layers:
                continue
            P = _prolongation(block, k)
            coupling = block.M_rows[k].matMult(P)
            coupling.scale(-block.half_links[k])
            rows[a][m], rows[m][a] = coupling, coupling.transpose(PETSc.Mat())
            MP = block.M_free[k].matMult(P)
            diagonal = P.transposeMatMult(MP)
            # an insulating contact (h̄ = 0) leaves its masters free: they are set to 0
            diagonal.scale(block.half_links[k] or 1.0)
            made += [P, MP, coupling, rows[m][a], diagonal]
            lifted[m] = lifted.get(m, 0.0) + block.half_links[k] * _fixed_slave_flux(block, k, P)
            if rows[m][m] is None:
                rows[m][m] = diagonal
            else:
                rows[m][m].axpy(1.0, diagonal, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    nest = PETSc.Mat().createNest(rows, comm=blocks[bodies[0]].comm)
    K = nest.convert("aij", out=PETSc.Mat())
    ksp = make_ksp(K, "sc_monolithic_", options or DIRECT)
    b, x = K.createVecs()
    sizes = [blocks[name].V.dofmap.index_map.size_local for name in bodies]
    layer_sizes = []
    for k in interfaces:
        owner = next(blk for blk in blocks.values() if k in blk.layers)
        layer_sizes.append(owner.layers[k].V.dofmap.index_map.size_local)
    b.array[:] = np.concatenate(
        [blocks[name].b0.array[:s] for name, s in zip(bodies, sizes, strict=True)]
        + [
            np.asarray(lifted.get(m, np.zeros(s)))
            for m, s in enumerate(layer_sizes, start=len(bodies))
        ]
    )
    if monitor is not None:

        def watch(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
            built = ksp.buildSolution()
            parts = np.split(built.array, np.cumsum(sizes))
            monitor(iteration, dict(zip(bodies, parts, strict=False)))
            built.destroy()

        ksp.setMonitor(watch)
    ksp.solve(b, x)
    if ksp.getConvergedReason() < 0:
        reason = ksp.getConvergedReason()
        destroy(*made, nest, K, ksp, b, x)
        raise RuntimeError(f"monolithic solve failed (PETSc reason {reason})")
    residual, correction = K.createVecs()
    for _ in range(refine):
        K.mult(x, residual)
        residual.aypx(-1.0, b)
        ksp.solve(residual, correction)
        x.axpy(1.0, correction)
    size = K.getSize()[0]
    iterations = ksp.getIterationNumber()
    parts = np.split(x.array, np.cumsum(sizes + layer_sizes)[:-1])
    temperatures = dict(zip(bodies, parts[: len(bodies)], strict=True))
    temperatures = {name: part.copy() for name, part in temperatures.items()}
    masters = {}
    for k, part in zip(interfaces, parts[len(bodies) :], strict=True):
        owner = next(blk for blk in blocks.values() if k in blk.layers)
        masters[k] = _replicate(owner.layers[k].V, part)
    destroy(*made, nest, K, ksp, b, x, residual, correction)
    return MonolithicResult(temperatures, masters, time.perf_counter() - start, size, iterations)


def _fixed_slave_flux(block: BodyBlocks, k: str, P: PETSc.Mat) -> np.ndarray:
    """``P_kᵀ M_k g``: the master rows' share of slave DOFs fixed at g (owned part)."""
    fixed = block.A.createVecLeft()
    dolfinx.fem.petsc.set_bc(fixed, block.forms.bcs)
    on_gamma, result = block.A.createVecLeft(), P.createVecRight()
    block.M_free[k].mult(fixed, on_gamma)
    P.multTranspose(on_gamma, result)
    values = result.array.copy()
    destroy(fixed, on_gamma, result)
    return values


def _replicate(V: dolfinx.fem.FunctionSpace, owned: npt.NDArray[np.float64]) -> np.ndarray:
    """Owned values of a master space as a replicated vector in global DOF order."""
    return np.concatenate(V.mesh.comm.allgather(np.asarray(owned)))
