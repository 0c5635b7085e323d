"""Correctors of the master iteration: ``ΔU_m = −G_k R_k`` on each interface, any field set.

The paper's correctors (eqs. 5–8) blend one correction per body with β:
``G = ½ [β K_C^A⁻¹ + (1 − β) K_C^B⁻¹]``, with K_C the half-link's own master block (method 1,
``h̄M`` for heat), the solid's condensed stiffness ``K̂`` on the interface (method 2), or its
partial condensation on a strip of element layers scaled by X (eqs. 9–10). The exact corrector
(METHOD.md §4) uses each body's whole interface response ``S^α`` (the series law
``((h̄M)⁻¹ + K̂⁻¹)⁻¹`` in the thermal case, the condensed Jacobian ``D − C A⁻¹ B`` for coupled
fields), ``G = (S^A + S^B)⁻¹``: one correction for a linear interface at any h.

Every part is a small dense matrix over the interface's master DOFs (all its channels),
computed where the body lives; ``combine`` runs everywhere. The exact corrector on a strip,
:class:`SparseStrip`, is the exception: it replaces each body by the element layers along its
contacts, clamped beyond, and solves those strips and every master layer together by one
sparse factorisation, storing nothing dense: the preconditioner of the interface Krylov where
``S^α`` is only applied (a body solved iteratively, spread over ranks, or thin).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import dolfinx
import numpy as np
import numpy.typing as npt
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.body import Body
from subdomain_contact.merged import Layout, MergePlan, RestrictedPlan, plan
from subdomain_contact.physics import FIELDS
from subdomain_contact.solvers import (
    SWEEP_DIRECT,
    THERMOELECTRIC_MECHANICAL,
    destroy,
    factorise,
    fits_freed,
    ordered,
    refactorisation_shortfall,
    refuse_refactorisation,
    set_up_relaxed,
    sweepable,
)
from subdomain_contact.system import System

__all__ = [
    "Corrector",
    "Exact",
    "Method1",
    "Method2",
    "PartialCondensation",
    "SparseStrip",
    "paper_factor",
]

Matrix = npt.NDArray[np.float64]

#: How the sparse strip is cut off where its body goes on: by a Robin condition
#: (:func:`~subdomain_contact.merged.merged_matrix`'s ``reach``), or clamped.
CUTS = ("robin", "clamped")


class Corrector(Protocol):
    """Builds the dense operator G of one interface from its two bodies' parts."""

    name: str

    def part(self, interface: str, body: Body) -> Matrix:
        """The body's share on the interface: its K_C^α, or its S^α (master order)."""
        ...

    def combine(
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        """G such that ΔU_m = −G R (master order)."""
        ...


def _inverse(K: Matrix, what: str) -> Matrix:
    """``K⁻¹``, refused where K is singular (its 1-norm condition above 1e15)."""
    try:
        inverse = np.linalg.inv(K) if np.all(np.isfinite(K)) else None
    except np.linalg.LinAlgError:
        inverse = None
    norm = np.abs(K).sum(axis=0).max(initial=0.0)
    if inverse is None or norm * np.abs(inverse).sum(axis=0).max(initial=0.0) > 1e15:
        raise ValueError(f"{what} is singular (a floating body?): use the exact corrector")
    return inverse


@dataclass(frozen=True, kw_only=True)
class _Paper:
    """Paper eqs. (5), (7), (8): G = ½ [β K_C^A⁻¹ + (1 − β) K_C^B⁻¹]."""

    beta: float = 0.5
    name: str = "paper"

    def combine(
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta = {self.beta}: must lie in [0, 1]")
        inverses = [
            _inverse(K, f"{self.name}: K_C of body '{b}' on '{interface}'")
            for K, b in zip(parts, bodies, strict=True)
        ]
        return 0.5 * (self.beta * inverses[0] + (1 - self.beta) * inverses[1])


@dataclass(frozen=True, kw_only=True)
class Method1(_Paper):
    """Paper method 1: K_C = K_mm, the half-link's master block (h̄M); for small h."""

    name: str = "method1"

    def part(self, interface: str, body: Body) -> Matrix:  # noqa: D102
        return body.link_stiffness(interface)


@dataclass(frozen=True, kw_only=True)
class Method2(_Paper):
    """Paper method 2: K_C = K̂, the solid condensed on the interface; for large h."""

    name: str = "method2"

    def part(self, interface: str, body: Body) -> Matrix:  # noqa: D102
        return body.condensed_stiffness(interface)


def paper_factor(refinement: int, layers: int = 1) -> float:
    """Paper eq. (10): X = 1 + Σ_{k=1..n} 1/(2^k N_i) for a mesh of step H/2^n, N_i layers."""
    return 1.0 + sum(1.0 / (2**k * layers) for k in range(1, refinement + 1))


@dataclass(frozen=True, kw_only=True)
class PartialCondensation(_Paper):
    """Paper §2: K̂(X) = K_ee − X K_ei K_ii,strip⁻¹ K_ie on ``layers`` element layers.

    DOFs beyond the strip are clamped. X corrects the interface mode that is uniform along
    the contact; it is exact for that mode in 1D when X = (1 − 1/m)(N + 1)/N (m elements).
    """

    layers: int = 1
    factor: float = 1.0
    name: str = "partial"

    def part(self, interface: str, body: Body) -> Matrix:  # noqa: D102
        if self.layers < 1 or not np.isfinite(self.factor) or self.factor <= 0:
            raise ValueError(f"partial condensation: layers = {self.layers}, X = {self.factor}")
        slaves = body.slaves[interface].local_dofs
        strip = dofs_within_layers(body.forms.W, slaves, self.layers)
        interior = np.setdiff1d(strip, slaves).astype(np.int32)
        K_ee, coupling = body.condense(interface, interior)
        return body.clamp_fixed(interface, K_ee - self.factor * coupling)


@dataclass(frozen=True, kw_only=True)
class Exact:
    """Exact corrector of METHOD.md §4: G = (S^A + S^B)⁻¹; one correction for any h."""

    name: str = "exact"

    def part(self, interface: str, body: Body) -> Matrix:  # noqa: D102
        S = body.interface_stiffness()
        at = body.master_slices()[interface]
        return S[at, at]

    def combine(  # noqa: D102
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        return _inverse(parts[0] + parts[1], f"S^A + S^B on '{interface}'")


@dataclass(frozen=True, kw_only=True)
class SparseStrip:
    """The exact corrector on a strip, for every interface at once, by a sparse solve.

    The merged matrix restricted to ``layers`` element layers of every body along its
    contacts and to every master layer. Eliminating the strips leaves ``Σ_α S̃^α`` on the
    masters, ``S̃^α = D − C (K̂ + L)⁻¹ B`` with K̂ the body cut to its strip: the series law
    ``((h̄M)⁻¹ + K̂⁻¹)⁻¹`` of the thermal case, exact where the link is soft. Where it is
    stiff, K̂ decides: clamped at its cut (``cut="clamped"``), a strip of width w answers a
    mode cos(ξ s) along the contact by k ξ coth(ξ w) where the body answers k ξ, too stiff
    for the modes smooth along the contact (the coarse space takes the constant), the more
    so as a fixed count of layers thins on a finer mesh. By default (``cut="robin"``) the
    cut carries a Robin condition that answers the lowest mode along each face as the body
    does (:func:`reach`, :func:`~subdomain_contact.merged.merged_matrix`): two 3D blocks
    (T, h = 1e6, 2 ranks, 939,678 DOFs) 10 interface CG iterations clamped, 7 with it. The
    interfaces are coupled through the bodies, not corrected one by one. Applied by one
    solve of that sparse matrix (MUMPS, options under ``-<prefix>``): nothing dense is
    stored, so it serves interfaces of any size and bodies whose contact DOFs are most of
    their DOFs.

    The strip of an iterative body stops growing before it covers more than ``share`` of the
    body's DOFs (at least one layer): it is factorised, where the body is solved iteratively
    so as not to be. Ten layers covered most of each block of the row of four 3D blocks
    (75k DOFs: peak memory 1.31 GiB against 0.92 GiB with three layers, 143 s against 137 s).

    Where the first factorisation of the strip would not fit again in the memory its nodes
    have left (:meth:`StripSolve.fits`), the strip is made again ``narrowest`` layers wide,
    once: a Newton step or a rebuilt preconditioner factorises it again. The collector bar
    slot at 1.07M DOFs on 2 ranks: ten layers 436,675 rows and 10.6 GB of factors, which a
    second factorisation would not fit beside; one layer 228,455 rows and 3.49 GB (at 174k
    DOFs one layer took the same Newton path as ten in 0.80 of the time).

    With ``split`` (the default), a strip of T or φ and u is solved by one sweep over (T, φ),
    then u, each factorised (:data:`~subdomain_contact.solvers.SWEEP_DIRECT`): exact but for
    the contacts' laws of the pressure, two factorisations of 2 and 3 unknowns a node in place
    of one of 5 (the collector bar slot, 2 ranks, nested: 0.64 of the subdomain Newton's time
    at 65.9k DOFs, 0.58 at 204k; at 1.07M DOFs 5.63 GB of factors where the whole strip takes
    10.6). Where the sweep leaves the interface Krylov short (the slot's cold climb, where the
    pressure law's contacts change state), that Jacobian's strip is factorised whole
    (:meth:`StripSolve.solve_whole`). A strip of one field, or of T and φ alone, is factorised
    whole; ``split=False`` factorises every strip whole.
    """

    layers: int = 10
    share: float = 0.25
    narrowest: int = 1
    split: bool = True
    cut: str = "robin"
    prefix: str = "sc_strip_"
    name: str = "sparse strip"

    def build(self, system: System, operator: StripSolve | None = None) -> StripSolve:
        """Its operator for the system's assembled blocks (``operator``: the last one, kept)."""
        if not 1 <= self.narrowest <= self.layers:
            raise ValueError(
                f"sparse strip corrector: layers = {self.layers}, narrowest = {self.narrowest}"
                " (1 ≤ narrowest ≤ layers)"
            )
        if not 0.0 < self.share <= 1.0:
            raise ValueError(f"sparse strip corrector: share = {self.share}, not in (0, 1]")
        if self.cut not in CUTS:
            raise ValueError(f"sparse strip corrector: cut = {self.cut!r}, not one of {CUTS}")
        if operator is None:
            operator = StripSolve(
                self.prefix, self.layers, self.share, self.split, self.cut == "robin"
            )
        operator.update(system)
        if operator.layers > self.narrowest and operator.factorisations == 1:
            if not operator.fits():  # its next factorisation would not fit: narrower, once
                operator.narrow(system, self.narrowest)
        return operator


#: The whole strip's MUMPS factors over its sweep's two: 10.6 against 5.63 GB on the collector
#: bar slot at 1.07M DOFs, 2 ranks (docs/iterative_bodies.md), 1.9, taken as 2.
WHOLE_OVER_SWEEP = 2.0


class StripSolve:
    """``G r``: the master part of the strips' merged matrix solved for ``r`` on the masters.

    Call :meth:`destroy` (collectively) when done.
    """

    def __init__(
        self,
        prefix: str,
        layers: int,
        share: float = 1.0,
        split: bool = False,
        robin: bool = True,
    ) -> None:
        self.prefix, self.split = prefix, split
        #: Body name -> the length of the Robin condition on its cut (:func:`reach`); None:
        #: every strip clamped at its cut
        self.reach: dict[str, float] | None = {} if robin else None
        #: The split's row sets, where the strip is solved by a sweep over its fields
        self.sets: list[tuple[str, PETSc.IS]] = []
        #: Element layers of each body's strip; ``share``: the largest part of an iterative
        #: body's DOFs in it
        self.layers, self.share = layers, share
        #: The layers of its first build where :meth:`narrow` made it narrower
        self.narrowed_from: int | None = None
        self.K: PETSc.Mat | None = None
        #: Where the merged matrix's entries go in ``K`` (:func:`~subdomain_contact.merged.plan`)
        self.plan: MergePlan | RestrictedPlan | None = None
        self.ksp: PETSc.KSP | None = None
        #: This rank's rows of the merged matrix in the strip (sorted global indices)
        self.rows: npt.NDArray[np.int64] | None = None
        #: Factorisations made
        self.factorisations = 0
        #: Jacobians at which the sweep left the interface Krylov short and the strip was
        #: factorised whole (:meth:`solve_whole`)
        self.fallbacks = 0
        self._whole_now = False  # this Jacobian's strip factorised whole after a sweep
        self.fields: tuple[str, ...] = ()  # the system's, at the last update
        #: Bodies every DOF of which lies in the strip (on every rank): the strip holds their
        #: whole ``S^α``, kernel modes included.
        self.whole: frozenset[str] = frozenset()

    def update(self, system: System) -> None:
        """Restrict the merged matrix to the strips and factorise (its analysis kept)."""
        layers, share = self.layers, self.share
        self.comm, self.fields = system.comm, system.problem.fields
        if self._whole_now:  # the last Jacobian's strip, factorised whole: sweep again
            destroy(self.ksp)
            self.ksp, self._whole_now = None, False
        if self.rows is None:
            layout = Layout(system)
            picked, whole = [], {}
            for name, body in system.bodies.items():
                seeds = np.unique(np.concatenate([s.local_dofs for s in body.slaves.values()]))
                most = share * body.comm.allreduce(body.size) if body.iterative else None
                strip = dofs_within_layers(body.forms.W, seeds.astype(np.int32), layers, most)
                picked.append(layout.body(name, body.start + strip))
                whole[name] = body.comm.allreduce(strip.size == body.size, op=MPI.LAND)
                if self.reach is not None:
                    self.reach[name] = reach(system, body)
            self.whole = frozenset(n for n, w in system.everywhere(whole).items() if w)
            self.masters = 0
            if self.comm.rank == 0:
                first = layout.mine + system.master_slice.start
                self.masters = system.local_size - system.master_slice.start
                picked.append(np.arange(first, first + self.masters))
            self.rows = np.sort(np.concatenate(picked)).astype(np.int64)
        if self.ksp is not None:  # the strip of the collector bar slot at 1.14M DOFs on 2
            refuse_refactorisation(  # ranks: killed at its second factorisation, 2026-11-27
                self.ksp,
                self.comm,
                f"sparse strip corrector ({self.K.getSize()[0]} rows)",
                "block low-rank factors (-sc_strip_mat_mumps_icntl_35 2 "
                "-sc_strip_mat_mumps_cntl_7 1e-5), the strip split by fields where it is not "
                "(SparseStrip(split=True), the default: about half the factors with T, φ and "
                "u), fewer ranks per node, or a narrower strip (SparseStrip(layers=..., "
                "share=...))",
            )
        data = None if self.plan is None else self.plan.values(system)
        if data is not None:  # the same entries: MUMPS keeps its analysis
            self.plan.write(self.K, data)
        else:  # the first, or contacts changed the pattern
            destroy(self.K, self.ksp, *(iset for _, iset in self.sets))
            self.plan = plan(system, self.rows, self.reach)
            self.K = self.plan.matrix(self.comm, self.plan.values(system))
            self.ksp, self.sets = None, []
        if self.swept:
            self._sweep(system)
        else:
            ksp, self.ksp = self.ksp, None  # a failed factorisation is destroyed by factorise
            dim, again = system.problem.scene.dim, not system.is_linear
            self.ksp = factorise(
                self.K, self.prefix, "sparse strip corrector", ksp, dim=dim, again=again
            )
        self.factorisations += 1

    @property
    def swept(self) -> bool:
        """Whether the strip is solved by the sweep over its fields at this Jacobian."""
        return self.split and sweepable(self.fields) and not self._whole_now

    def whole_fits(self) -> bool:
        """Whether the whole strip's factorisation fits where the sweep's two are freed.

        Its need is :data:`WHOLE_OVER_SWEEP` times the sweep's (MUMPS INFO(22), with the
        refactorisation margin), against the memory left plus what the sweep frees.
        Collective.
        """
        return fits_freed(self.ksp, self.comm, WHOLE_OVER_SWEEP)

    def solve_whole(self, system: System) -> None:
        """Factorise this Jacobian's strip whole, in place of the sweep, until the next update.

        The sweep is exact but for the contact laws' dependence on u; where the interface
        Krylov stalls on it (the collector bar slot's cold start at 17k DOFs: 100 GMRES
        iterations at 0.999 of the start), the whole strip is its exact operator. The next
        :meth:`update` sweeps again.
        """
        destroy(self.ksp, *(iset for _, iset in self.sets))
        self.ksp, self.sets, self._whole_now = None, [], True
        dim, again = system.problem.scene.dim, not system.is_linear
        self.ksp = factorise(self.K, self.prefix, "sparse strip corrector", dim=dim, again=again)
        self.factorisations += 1
        self.fallbacks += 1

    def _sweep(self, system: System) -> None:
        """Set up the strip's solve as one sweep over (T, φ), then u, each factorised.

        PETSc's ``fieldsplit`` (:data:`~subdomain_contact.solvers.SWEEP_DIRECT`): two
        factorisations of 2 and 3 unknowns a node in place of one of 5, exact but for the
        contacts' dependence on u (the interface Krylov takes the rest).
        """
        if self.ksp is None:
            mine = self.comm.exscan(system.local_size) or 0  # None on rank 0
            field = system.field_of[self.rows - mine]
            first = self.K.getOwnershipRange()[0]
            self.sets = []
            for name, fields in THERMOELECTRIC_MECHANICAL.items():  # SWEEP_DIRECT's splits
                rows = np.flatnonzero(np.isin(field, [FIELDS.index(f) for f in fields]))
                indices = (first + rows).astype(PETSc.IntType)
                self.sets.append((name, PETSc.IS().createGeneral(indices, comm=self.comm)))
        options = ordered(
            SWEEP_DIRECT, system.problem.scene.dim, self.K.getSize()[0], again=not system.is_linear
        )
        ksp, self.ksp = self.ksp, None  # a KSP made again is destroyed by set_up_relaxed
        self.ksp, relaxation = set_up_relaxed(self.K, self.prefix, options, ksp, splits=self.sets)
        subs = self.ksp.getPC().getFieldSplitSubKSP()
        for (name, _), sub in zip(self.sets, subs, strict=True):
            reason = sub.getPC().getFailedReason()
            if reason != 0:
                raise RuntimeError(
                    f"sparse strip corrector: factorisation of its {name} split failed (PETSc "
                    f"PC reason {reason}, MUMPS workspace relaxed to {relaxation[name]} %); "
                    "try SparseStrip(split=False)"
                )

    def narrow(self, system: System, layers: int) -> None:
        """Free the strip and its factorisation, and make it again ``layers`` wide."""
        self.narrowed_from = self.narrowed_from or self.layers
        self.destroy()
        self.layers = layers
        self.update(system)

    def fits(self) -> bool:
        """Whether factorising the strip again fits in the memory its nodes have left."""
        return refactorisation_shortfall(self.ksp, self.comm) is None

    def apply(self, r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``G r`` for concatenated master residuals r (replicated; the result too)."""
        rhs, x = self.K.createVecs()
        rhs.set(0.0)
        if self.comm.rank == 0:
            rhs.array[rhs.local_size - self.masters :] = r
        self.ksp.solve(rhs, x)
        if self.ksp.getConvergedReason() < 0:
            raise RuntimeError(
                f"sparse strip corrector: solve failed ({self.ksp.getConvergedReason()})"
            )
        z = x.array[x.local_size - self.masters :].copy() if self.comm.rank == 0 else None
        destroy(rhs, x)
        return self.comm.bcast(z, root=0)

    def destroy(self) -> None:
        """Free the matrix and its factorisation (collective)."""
        destroy(self.K, self.ksp, *(iset for _, iset in self.sets))
        self.K = self.ksp = self.rows = self.plan = None
        self.sets = []


def reach(system: System, body: Body) -> float:
    """The length [m] of the Robin condition on a body's cut: ``D / π``.

    D is the largest side of the bounding box of any of its contact faces: the Robin
    condition is then exact for the lowest mode along that face but its constant (which the
    coarse space takes), ``cos(π s / D)``, and nearly so for every higher one. Two 3D blocks
    (T, h = 1e6, 0.2 m faces, rtol 1e-12, 2 ranks, 939,678 DOFs): 10 interface CG
    iterations clamped, 7 with the Robin cut at 0.2 / π, 420 → 325 body CG iterations.
    """
    sides = [np.ptp(system.layers[k].coordinates, axis=0).max() for k in body.layers]
    return max(sides, default=0.0) / np.pi


def dofs_within_layers(
    W: dolfinx.fem.FunctionSpace,
    seeds: npt.NDArray[np.int32],
    layers: int,
    most: float | None = None,
) -> npt.NDArray[np.int32]:
    """Owned DOFs of ``W`` within ``layers`` element layers of the DOFs ``seeds`` (included).

    A layer is every cell that has a marked DOF; its DOFs are marked for the next layer.
    With ``most``, no layer is added beyond the first that would make the DOFs more than
    ``most`` (over every rank). Parallel-safe: marks cross process boundaries through the
    index map. Each layer visits only the cells of the nodes the last one marked (a
    block of 467k DOFs, ten layers: 1.2 s when every layer visited every cell).
    """
    bs = W.dofmap.index_map_bs
    owned = W.dofmap.index_map.size_local
    marker = dolfinx.la.vector(W.dofmap.index_map, dtype=np.int32)
    marker.array[np.asarray(seeds) // bs] = 1
    marker.scatter_forward()
    cells = W.dofmap.list
    per_cell = cells.shape[1]
    incidence = scipy.sparse.csr_matrix(
        (np.ones(cells.size, dtype=np.int8), cells.ravel(),
         np.arange(0, cells.size + 1, per_cell)),
        shape=(cells.shape[0], marker.array.size),
    )  # fmt: skip
    node_cells = incidence.T.tocsr()  # node -> the cells around it
    marked = marker.array > 0
    front = np.flatnonzero(marked)
    for layer in range(layers):
        before = marker.array.copy() if most is not None else None
        hit = np.unique(node_cells[front].indices)
        marker.array[cells[hit].ravel()] = 1
        marker.scatter_reverse(dolfinx.la.InsertMode.add)
        marker.scatter_forward()
        if most is not None and layer > 0:
            count = W.mesh.comm.allreduce(bs * np.count_nonzero(marker.array[:owned]))
            if count > most:
                marker.array[:] = before
                break
        now = marker.array > 0
        front, marked = np.flatnonzero(now & ~marked), now
    blocks = np.flatnonzero(marker.array[:owned])
    return (bs * blocks[:, None] + np.arange(bs)).ravel().astype(np.int32)
