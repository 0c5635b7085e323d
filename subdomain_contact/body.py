"""One body: its Jacobian blocks over its fields, its factorisation, and its interface response.

Linearised at the current state, body α with master increments ``y_k`` on its interfaces k
solves (METHOD.md §3, Newton form)

    A y = b − Σ_k B_k P_k y_k,        A = A_bulk + Σ_k L_k,

with ``L_k`` the half-link's block on the body (slave rows and columns only) and ``B_k`` its
coupling to the masters. Its share of the master residual of interface k is
``r_k = P_kᵀ (C_k y + D_k P_k y_k)``. The half-link's fluxes appear in both with opposite
signs, so ``C_k = −L_k + C̃_k`` and ``D_k = −B_k + D̃_k`` where the remainders C̃, D̃ (the
contact's Joule heat, and at an open contact the master's tie less the body's) are small;
likewise ``B_k P_k = (−L_k + B̃_k) P_k`` with ``B̃_k`` the
coupling at a fixed jump (:class:`~subdomain_contact.physics.BodyForms`).

Every one of these blocks lives on the *contact DOFs* (every field on the contact facets), a
small block. The master residual of a DOF is taken in its stable form (docs/METHOD.md §4, §7):
where the link is stiffer than the bulk, from the body's own equation,
``L_k y + B_k P_k y_k = b − A_bulk y − Σ_{j≠k} (L_j y + B_j P_j y_j)`` on its free contact rows,
which never subtracts two h̄-sized numbers; where it is softer, or the slave is fixed by a
Dirichlet condition, from the link itself.

A body held by one rank factorises ``A_bulk`` with MUMPS, leaving the contact DOFs as a dense
Schur block Σ (:class:`~subdomain_contact.schur.CondensedFactor`): solves with ``A`` then
replace that block by ``Σ + L``, the interface operator of the body is dense algebra on Σ, and
a change of the contact laws alone (a Newton step whose bulk is linear) costs a new dense block,
never a new sparse factorisation. A body spread over several ranks is factorised whole
(MUMPS, distributed) and gets its interface operator from solves, a block of columns at a time.
A body solved *iteratively* (a large 3D body, where a sparse factorisation grows far faster
than the mesh) solves ``A`` by CG (GMRES where ``A`` is not symmetric) preconditioned by
smoothed-aggregation AMG (PETSc's GAMG) with its kernel modes as the near-null space; its
interface operator is only ever applied, one solve per application. A large 3D body of T or φ
and of u is solved that way too, by FGMRES on one sweep over its (T, φ) and u blocks, each
factorised (:data:`FACTORISED_SWEEP`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from types import MappingProxyType

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import numpy.typing as npt
import scipy.sparse
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.masters import MasterLayer, SlaveMap, contact_dofs, slave_map
from subdomain_contact.modes import Mode, centre, modes, span
from subdomain_contact.physics import BodyForms, Problem, body_forms
from subdomain_contact.scene import Body as SceneBody
from subdomain_contact.schur import CondensedFactor, condensation
from subdomain_contact.solvers import (
    BLOCK_LOW_RANK,
    DIRECT,
    THERMOELECTRIC_MECHANICAL,
    RowScaledKrylov,
    columns_apply,
    columns_mult,
    destroy,
    factorise,
    fgmres_columns,
    fits_freed,
    make_ksp,
    ordered,
    ordering,
    refactorisation_shortfall,
    refuse_refactorisation,
    set_up,
    set_up_relaxed,
    sweepable,
)

__all__ = [
    "FACTORISED_SWEEP",
    "FACTORISED_SWEEP_DOUBLE",
    "ITERATIVE",
    "SOLVERS",
    "SPLIT",
    "SPLIT_FIELD",
    "Body",
]

#: A body solved iteratively: CG (``ksp_type`` becomes GMRES for a body whose matrix is not
#: symmetric) preconditioned by PETSc's smoothed-aggregation AMG, to the relative
#: (preconditioned) residual that the interface solver sets (:meth:`Body.set_rtol`).
#: GAMG estimates the largest eigenvalue of each level for its Chebyshev smoother by CG
#: (``pc_gamg_esteig_ksp_type``; PETSc's default GMRES is kept for a GMRES body): with the
#: GMRES estimate, block 0 of the two 3D blocks at 939,678 DOFs (467,437 DOFs, h = 1e10)
#: stopped after 3 CG iterations on an indefinite preconditioner (PETSc reason -8) and was
#: factorised instead (6.96 GB); with CG's, 22 iterations to 1e-12.
ITERATIVE: Mapping[str, str] = MappingProxyType(
    {
        "ksp_type": "cg",
        "pc_type": "gamg",
        "pc_gamg_threshold": "0.02",
        "pc_gamg_esteig_ksp_type": "cg",
        "ksp_rtol": "1e-12",
        "ksp_max_it": "1000",
    }
)

#: A body of several fields solved iteratively: GMRES preconditioned by one block Gauss-Seidel
#: sweep over its fields in the problem's order (PETSc's multiplicative ``fieldsplit``), each
#: field's block by one V-cycle of GAMG with that field's near-null space (the constant of T
#: or φ, the rigid motions of u). One GAMG on the whole coupled matrix aggregates rows of
#: conductances (W/(m K)) with rows of stiffnesses (Pa): on four 3D blocks of 1.5k DOFs each
#: (T, φ, u, ``cases.squeezed_row``) the interface Krylov then stalled 3e-3 off and Newton
#: failed; with the split it takes the monolithic Newton's 13 steps.
SPLIT: Mapping[str, str] = MappingProxyType(
    {
        "ksp_type": "gmres",
        "ksp_gmres_restart": "100",
        "pc_type": "fieldsplit",
        "pc_fieldsplit_type": "multiplicative",
        "ksp_rtol": "1e-12",
        "ksp_max_it": "1000",
    }
)

#: Each field's block of :data:`SPLIT` (under ``fieldsplit_<field>_``).
SPLIT_FIELD: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "gamg", "pc_gamg_threshold": "0.02"}
)

#: A body of T or φ and of u solved by FGMRES on one block Gauss-Seidel sweep over (T, φ), then u
#: (:data:`~subdomain_contact.solvers.THERMOELECTRIC_MECHANICAL`), each split's block factorised by
#: MUMPS in single precision with block low-rank factors (``pc_precision``,
#: :data:`~subdomain_contact.solvers.BLOCK_LOW_RANK`): the monolithic Newton's ``FIELDSPLIT_SINGLE``
#: on one body, its rows weighed by each field's scale
#: (:class:`~subdomain_contact.solvers.RowScaledKrylov`). The sweep is exact but for the
#: contacts' dependence on u, and FGMRES makes up for it and for the precision (each field's true
#: residual checked after, :meth:`Body._solve_whole`), so a solve is a few pairs of triangular
#: solves on two factorisations of 2 and 3 unknowns a node, which fit where one of 5 does not. Where
#: a 3D body of several fields is too large to factorise whole, this replaces GAMG per field, whose
#: Krylov solves (10-25 iterations each, tens of them per Newton step) kept the collector bar slot
#: at 1.07M DOFs from converging in two hours (docs/collector_bar_slot.md).
FACTORISED_SWEEP: Mapping[str, str] = MappingProxyType(
    SPLIT
    | {"ksp_type": "fgmres"}
    | {
        f"fieldsplit_{split}_{k}": v
        for split in THERMOELECTRIC_MECHANICAL
        for k, v in (DIRECT | {"pc_precision": "single"} | BLOCK_LOW_RANK).items()
    }
)

#: :data:`FACTORISED_SWEEP` with its splits factorised in double precision (block low-rank
#: kept): a body whose solve by the single-precision sweep stays short of a field's
#: tolerance after :data:`FIELD_REFINEMENTS` is factorised again so, and keeps it. Single
#: precision's ε (6e-8) leaves little of a split whose condition number nears 1e7: on the
#: row of four 3D blocks (``cases.squeezed_row``, the inner two floating, held in u by their
#: contacts alone) the floating block 1's solves ended 282, 676 and 2,670 times short at
#: 10,460, 18,495 and 31,420 DOFs (the other bodies' within theirs, refined), and
#: from 18,495 DOFs the interface Krylov failed at the first Newton step (true residual 7e6
#: and 1.6e20 times its tolerance), and Newton with it; block 1 in double: 13 Newton steps,
#: as the monolithic Newton, the others kept single. Those shortfalls were GMRES's, whose
#: residual estimate drifts by single precision's round-off; by FGMRES
#: (:class:`~subdomain_contact.solvers.RowScaledKrylov`, 2026-12-07) no sweep of the row ends
#: short, and this stays the way out for one that does.
FACTORISED_SWEEP_DOUBLE: Mapping[str, str] = MappingProxyType(
    FACTORISED_SWEEP
    | {f"fieldsplit_{split}_pc_precision": "double" for split in THERMOELECTRIC_MECHANICAL}
)

#: How a body is solved: factorised whole (``direct``), by Krylov + AMG (``iterative``), or
#: by FGMRES on the factorised sweep over its fields (``split``, :data:`FACTORISED_SWEEP`).
SOLVERS = ("direct", "iterative", "split")

#: A body whose Krylov solve failed on this many matrices in a row (a solve of each, the
#: others on it may have converged) is factorised by MUMPS for the next ``2^(n-1)``
#: matrices after its n-th such matrix before it tries again (a back-off:
#: :meth:`Body._krylov`). One failure is a wild iterate (the row of four 3D blocks at 1.01M
#: DOFs: a step that moved a field by 22 times its largest value broke GAMG down once); two
#: in a row a solver that does not suit the body (the collector bar slot's cast iron, swept
#: by option: its first solves on each Jacobian took 8-9 FGMRES iterations, a later one
#: stopped at 1,000, and MUMPS solved the rest, at every Jacobian).
FAILURES_IN_A_ROW = 2

#: Refinements of an iterative solve of a body of several fields, at most, while one
#: field's residual is above the tolerance relative to its own scale.
FIELD_REFINEMENTS = 3

#: Memory of the right-hand sides that a body's multi-column solve holds at once [bytes].
COLUMN_BYTES = 64 * 2**20

#: Fewest iterations between restarts of a split body's FGMRES on several columns at once
#: (:meth:`Body._column_budget`), and the restarts after which a column goes on alone.
COLUMN_RESTART = 10
COLUMN_CYCLES = 4

#: A master DOF whose half-link's row sum is below this fraction of the bulk's takes the
#: link form of its residual even where its interface's other DOFs take the reaction form
#: (:meth:`Body._soft_or_fixed`): an open contact's tie, at most 1e-3 of the body's E/h,
#: whose reaction-form round-off ``K ε`` its error weight ``K/κ`` made unreachable (the
#: collector bar slot's pressure setup with an iterative block stalled 1.4 times above its
#: target). Below 1 and far from the ties' 1e-3: one form per DOF wherever the link is
#: near the bulk moved the row of four blocks' inner rounds between rank groups and serial
#: (3 against 2 at one step).
WEAK_LINK = 1e-2

#: A mode solves a body (:meth:`Body.respond_by`) where its residual is at most this much
#: of each field's scale (``‖b_f‖∞ + ‖A_f‖∞ ‖y_f‖∞``): the 1e3 eps a factorised solve
#: reaches (:meth:`Body._polluted`), so the product is as exact as a direct solve.
KERNEL_RESIDUAL = 1e3 * np.finfo(float).eps

Matrix = npt.NDArray[np.float64]
Vector = npt.NDArray[np.float64]
MasterValues = dict[str, npt.NDArray[np.float64]]


def _depends_on(form: ufl.Form, functions: list[dolfinx.fem.Function]) -> bool:
    """Whether a form, its derivatives expanded, has any of ``functions`` as coefficients."""
    coefficients = set(ufl.algorithms.expand_derivatives(form).coefficients())
    return any(f in coefficients for f in functions)


class Body:
    """A body's forms, blocks, factorisation and slave maps, for any set of fields.

    Args:
        problem: The problem.
        body: The scene's body (held by this rank's group).
        layers: Master layer of each interface the body touches, in scene order.
        prefix: PETSc options prefix of the body's factorisation (``<prefix>mat_mumps_*``).
        schur: Condense the body on its contact DOFs where it is on one rank: a dense
            Schur block, or for a thin body its ``S^α`` by multi-column solves
            (:func:`~subdomain_contact.schur.condensation`); otherwise the whole body matrix
            is factorised and ``S^α`` applied by body solves.
        solver: One of :data:`SOLVERS`: ``"direct"`` (a factorisation), ``"iterative"``
            (Krylov + AMG, :data:`ITERATIVE` or :data:`SPLIT`) or ``"split"`` (FGMRES on the
            factorised sweep, :data:`FACTORISED_SWEEP`, for a body of T or φ and of u);
            options under ``prefix`` win.

    Call :meth:`destroy` (collectively) when done.
    """

    def __init__(
        self,
        problem: Problem,
        body: SceneBody,
        layers: dict[str, MasterLayer],
        *,
        prefix: str,
        schur: bool = True,
        solver: str = "direct",
    ) -> None:
        self.forms: BodyForms = body_forms(problem, body)
        self.name, self.U, W = body.name, self.forms.U, self.forms.W
        self.scene_body = body  # the mesh, its tags and its file node numbers
        self.comm: MPI.Comm = W.mesh.comm
        self.dim = W.mesh.topology.dim
        self.prefix = prefix
        self.layers = layers
        bs = W.dofmap.index_map_bs
        self.size = W.dofmap.index_map.size_local * bs
        self.start = W.dofmap.index_map.local_range[0] * bs
        self.slaves: dict[str, SlaveMap] = {
            k: slave_map(self.forms, layer, body.facet_tags) for k, layer in layers.items()
        }
        self._index_contact_dofs(contact_dofs(self.forms, body.facet_tags, list(layers)))
        self._index_fields()
        self._compile()
        if solver not in SOLVERS:
            raise ValueError(f"solver='{solver}' of body '{self.name}': give one of {SOLVERS}")
        if solver == "split" and not sweepable(problem.fields):
            raise ValueError(
                f"-{prefix}solver split: body '{self.name}' has the fields "
                f"{', '.join(problem.fields)}; the sweep needs T or φ, and u (use direct or "
                "iterative)"
            )
        #: Solved by a Krylov method (AMG, or the factorised sweep), not one factorisation.
        self.iterative = solver != "direct"
        #: Solved by FGMRES on the factorised sweep (:data:`FACTORISED_SWEEP`).
        self.split = solver == "split"
        #: The sweep's options: single precision until a solve falls short (:meth:`_solve_whole`).
        self.sweep = FACTORISED_SWEEP
        self._may_double = self.split  # a short sweep may be factorised again in double
        contact = len(self.kept)
        alone = schur and not self.iterative and self.comm.size == 1 and 0 < contact
        how = condensation(contact, self.size, self.dim) if alone else ""
        self.schur = how == "block"
        #: A thin body: factorised whole, its ``S^α`` formed densely by multi-column solves.
        self.columns = how == "columns"
        #: Whether ``S^α`` is held dense, from a Schur block or from multi-column solves.
        self.condensed = self.schur or self.columns
        self.factor: CondensedFactor | None = None
        self.ksp: PETSc.KSP | None = None
        #: The sweep's flexible Krylov solve on rows weighed by field (a split body's).
        self._scaled_krylov: RowScaledKrylov | None = None
        #: Each field's scale of the split body's last FGMRES solve (:meth:`_weigh`).
        self._solved_scales = np.zeros(0)
        #: MUMPS on the body's matrix where its Krylov solve failed, until the matrix changes.
        self._direct: PETSc.KSP | None = None
        #: Matrices on which the Krylov solve failed and MUMPS took over (:meth:`_krylov`) or
        #: that MUMPS took at once after failures in a row (:data:`FAILURES_IN_A_ROW`), and
        #: sweeps factorised again in double precision (:meth:`_sweep_in_double`).
        self.fallbacks = 0
        #: Matrices in a row on which a Krylov solve failed (those MUMPS took at once between
        #: them not counted), and the matrices MUMPS takes next at once.
        self.failures_in_a_row, self._skip = 0, 0
        self._near_null: list[PETSc.Object] = []
        #: A split body's (T, φ) and u index sets, among ``_near_null`` (:meth:`_sweep_splits`).
        self._splits: list[tuple[str, PETSc.IS]] = []
        #: Krylov iterations of the body's iterative solves, summed.
        self.solve_iterations = 0
        self._A: PETSc.Mat | None = None
        self._scaled: PETSc.Mat | None = None
        self.factorisations = 0
        # Jacobian assemblies, and the one the bulk (and whole) matrix was assembled at
        self._step, self._bulk_step, self._whole_step = 0, -1, -1
        self._stiffness: Matrix | None = None
        self._compiled: dict[Hashable, dolfinx.fem.Form] = {}  # forms of :meth:`compiled`
        self._vectors = [self.A_bulk.createVecRight() for _ in range(3)]

    # -- set-up ---------------------------------------------------------------------------
    def _index_contact_dofs(self, kept_local: npt.NDArray[np.int32]) -> None:
        """Contact DOFs: local, global, and each master DOF's position among them."""
        self.kept_local = kept_local
        counts = self.comm.allgather(len(kept_local))
        offset = int(np.sum(counts[: self.comm.rank]))
        self.kept_slice = slice(offset, offset + len(kept_local))
        self.kept = np.concatenate(self.comm.allgather(self.start + kept_local))
        fixed = self._fixed_local()
        self.fixed_local = fixed
        on_fixed = np.isin(kept_local, fixed).astype(float)
        self.fixed_kept = np.flatnonzero(self._gather_kept(on_fixed) > 0)
        self.free_kept = np.setdiff1d(np.arange(len(self.kept)), self.fixed_kept)
        self.position: dict[str, npt.NDArray[np.int64]] = {}
        for k, layer in self.layers.items():
            slaves = self.slaves[k]
            local = np.zeros(layer.size)
            local[slaves.master_index] = offset + np.searchsorted(kept_local, slaves.local_dofs)
            positions = self.comm.allreduce(local, op=MPI.SUM) if self.comm.size > 1 else local
            self.position[k] = positions.astype(np.int64)

    def _fixed_local(self) -> npt.NDArray[np.int32]:
        """Owned DOFs fixed by Dirichlet conditions (local indices)."""
        fixed = [bc.dof_indices()[0][: bc.dof_indices()[1]] for bc in self.forms.bcs]
        every = np.unique(np.concatenate(fixed)) if fixed else np.zeros(0, np.int32)
        return every[every < self.size].astype(np.int32)

    def _compile(self) -> None:
        """Forms of the residuals and Jacobian blocks, and the matrices they fill."""
        f, U = self.forms, self.forms.U
        trial = ufl.TrialFunction(f.W)
        self.F_bulk = dolfinx.fem.form(f.bulk)
        self.F_links = {k: dolfinx.fem.form(f.links[k]) for k in self.layers}
        self.F_fluxes = {k: dolfinx.fem.form(f.fluxes[k]) for k in self.layers}
        a_bulk = ufl.derivative(f.bulk, U, trial)
        self.a_bulk = dolfinx.fem.form(a_bulk)
        self.A_bulk = dolfinx.fem.petsc.create_matrix(self.a_bulk)
        unknowns = [U, *f.masters.values()]
        self.bulk_is_linear = not _depends_on(a_bulk, [U])
        #: The form coefficients the bulk matrix holds: when one changes (a time step's
        #: data, a switched convection), the matrix is assembled and factorised again.
        self.matrix_constants = set(ufl.algorithms.expand_derivatives(a_bulk).constants())
        blocks: dict[str, dict[str, ufl.Form]] = {}
        self._linearised = {  # the links as the Jacobian sees them: with the open ties
            k: f.links[k] if f.ties[k] is None else f.links[k] + f.ties[k] for k in self.layers
        }
        for k in self.layers:
            Um = f.masters[k]
            blocks[k] = {
                "L": ufl.derivative(self._linearised[k], U, trial),
                "B": ufl.derivative(self._linearised[k], Um, trial),
            }
            if f.master_only[k] is not None:
                blocks[k]["Ct"] = ufl.derivative(f.master_only[k], U, trial)
                blocks[k]["Dt"] = ufl.derivative(f.master_only[k], Um, trial)
        self.links_are_linear = not any(
            _depends_on(form, unknowns) for forms in blocks.values() for form in forms.values()
        )
        self.a_blocks = {
            k: {name: dolfinx.fem.form(form) for name, form in forms.items()}
            for k, forms in blocks.items()
        }
        self.block_matrices = {
            k: {name: dolfinx.fem.petsc.create_matrix(a) for name, a in forms.items()}
            for k, forms in self.a_blocks.items()
        }
        self._kept_is = PETSc.IS().createGeneral(
            (self.start + self.kept_local).astype(PETSc.IntType), comm=self.comm
        )

    @property
    def is_linear(self) -> bool:
        """Whether the body's Jacobian does not depend on the state (bulk and contact laws)."""
        return self.bulk_is_linear and self.links_are_linear

    def destroy(self) -> None:
        """Free the body's PETSc objects (collective on its communicator)."""
        if self.factor is not None:
            self.factor.destroy()
        mats = [m for forms in self.block_matrices.values() for m in forms.values()]
        self._drop_scaled_krylov()
        destroy(self.ksp, self._direct, self.A_bulk, self._A, self._scaled, self._kept_is)
        destroy(*mats, *self._vectors, *self._near_null)
        self.factor, self.ksp, self._direct, self._A = None, None, None, None
        self._near_null, self._splits = [], []

    # -- assembly and factorisation ------------------------------------------------------
    def assemble(self) -> None:
        """Jacobian blocks of the contact at the current state.

        The bulk matrix waits for :meth:`bulk_matrix` (a factorisation asks for it, the
        monolithic reference does not).
        """
        self._step += 1
        self.blocks = {k: self._contact_blocks(k) for k in self.layers}
        self._rows = {  # every link's blocks on the slave rows of each interface
            k: {
                name: {j: self.blocks[j][name][at].tocsr() for j in self.layers}
                for name in ("L", "BP")
            }
            for k, at in self.position.items()
        }
        self._stiffness = None
        free = scipy.sparse.diags(np.isin(np.arange(len(self.kept)), self.free_kept) * 1.0)
        self.L = sum((b["L"] for b in self.blocks.values()), scipy.sparse.csr_matrix(
            (len(self.kept),) * 2))  # fmt: skip
        self.L_bc = (free @ self.L @ free).tocsr()

    def bulk_changed(self) -> None:
        """The bulk's data changed (a new time step): assemble and factorise it again."""
        self._bulk_step = -1

    def bulk_matrix(self) -> PETSc.Mat:
        """``A_bulk`` with the Dirichlet conditions at the current state.

        Assembled again only when it depends on the state; returns whether it changed in
        ``self._bulk_changed``.
        """
        self._bulk_changed = self._bulk_step < 0 or (
            not self.bulk_is_linear and self._bulk_step != self._step
        )
        if self._bulk_changed:
            self.A_bulk.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(self.A_bulk, self.a_bulk, bcs=self.forms.bcs)
            self.A_bulk.assemble()
            if self._bulk_step < 0:  # new data, not a new Newton state: see _bulk_norms_by_field
                self._bulk_norms_by_field()
        self._bulk_step = self._step
        return self.A_bulk

    def factorise(self) -> None:
        """The body's factorisation for the assembled blocks.

        The sparse factorisation is made again only when the bulk matrix changed; with the
        Schur block, changed contact blocks cost a new dense block.
        """
        self.bulk_matrix()
        self.use_link = self._soft_or_fixed()
        if self.schur:
            if self._bulk_changed or self.factor is None:
                self._factorise_scaled()
            d = self.scale[self.kept_local]
            scaled = d[:, None] * self.L_bc.toarray() * d[None, :]
            self.factor.update(scaled)
        elif self._bulk_changed or not self.links_are_linear or self.ksp is None:
            self._factorise_whole()

    def _factorise_scaled(self) -> None:
        """MUMPS with the Schur block, of ``D A_bulk D``, ``D = |diag A_bulk|^(-1/2)``.

        The symmetric scaling puts every field on the same footing (a stiffness of 1e11 Pa
        beside a conductivity of 45 W/(m K)), so that the dense factorisation of the
        Schur block, which pivots by size, does not mix their round-off.
        """
        diagonal = self.A_bulk.getDiagonal()
        magnitude = np.abs(diagonal.array)
        diagonal.destroy()
        self.scale = 1.0 / np.sqrt(np.where(magnitude > 0, magnitude, 1.0))
        D = self.A_bulk.createVecLeft()
        D.array[:] = self.scale
        if self.factor is None:  # the contact's block follows in :meth:`factorise`
            self._scaled = self.A_bulk.copy()
            self._scaled.diagonalScale(D, D)
            self.factor = CondensedFactor(
                self._scaled,
                self.kept_local,
                None,
                self.prefix,
                ordering(self.dim, self._scaled.getSize()[0], again=not self.bulk_is_linear),
            )
        else:  # the same sparsity: MUMPS keeps its analysis (ordering, symbolic phase)
            self.A_bulk.copy(self._scaled, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
            self._scaled.diagonalScale(D, D)
            self.factor.refactor(self._scaled, None)
        d = self.scale[self.kept_local]
        self.sigma = self.factor.sigma / d[:, None] / d[None, :]
        D.destroy()
        self.factorisations += 1

    def _index_fields(self) -> None:
        """The field of every owned DOF and of every contact DOF (once: it is structure)."""
        field_of = np.zeros(self.size, dtype=np.int32)
        for f, name in enumerate(self.forms.fields):
            dofs = self.forms.collapsed(name)[1]
            field_of[dofs[dofs < self.size]] = f
        count = len(self.forms.fields)
        self._field_dofs = [np.flatnonzero(field_of == f) for f in range(count)]
        kept_field = self._gather_kept(field_of[self.kept_local].astype(float)).astype(int)
        self._kept_field = kept_field
        self._kept_field_dofs = [np.flatnonzero(kept_field == f) for f in range(count)]

    def _bulk_norms_by_field(self) -> None:
        """The bulk matrix's largest row sum on the rows of each field (on every rank).

        Scales that choose between two exact forms of the master residual (and bound the
        round-off of a solve): orders of magnitude matter, not the few per cent a state
        dependent bulk changes from one Newton step to the next. So they are computed when
        the bulk's data change (the first assembly, a new time step), not at every Newton
        step, which would copy the whole matrix each time.
        """
        indptr, _, data = self.A_bulk.getValuesCSR()
        rows = np.add.reduceat(np.abs(data), indptr[:-1]) if data.size else np.zeros(0)
        rows[indptr[:-1] == indptr[1:]] = 0.0
        bulk = np.array([rows[dofs].max(initial=0.0) for dofs in self._field_dofs])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, bulk, op=MPI.MAX)
        self._bulk_norms = bulk

    def master_stiffness(self, k: str) -> tuple[Vector, Vector]:
        """Per master DOF of k: the half-link's stiffness at it, and the bulk's at its slave.

        Orders of magnitude (row sums), [W/K], [S] or [N/m], replicated. The link's is the
        row sum of its master block ``P_kᵀ D_k P_k`` (at an open contact the master's own
        tie, ``physics.MASTER_TIE``); for a displacement, the smallest eigenvalue of the
        node's lumped block over the components, given to each of them: an open contact
        ties the normal alone where a stuck one's slip spring holds the tangents. The bulk's
        is the largest row sum on the slave's field (:meth:`_bulk_norms_by_field`).
        """
        layer, D = self.layers[k], self._master_block(k)
        link = np.abs(D).sum(axis=1).A1
        nodes = layer.nodes
        u = [c for c, (f, _) in enumerate(layer.channels) if f == "displacement"]
        if u:
            rows = [np.arange(c * nodes, (c + 1) * nodes) for c in u]
            lumped = np.zeros((nodes, len(u), len(u)))
            for b, columns in enumerate(rows):
                ones = np.zeros(D.shape[1])
                ones[columns] = 1.0
                summed = D @ ones
                for a, at in enumerate(rows):
                    lumped[:, a, b] = summed[at]
            smallest = np.linalg.eigvalsh(0.5 * (lumped + lumped.transpose(0, 2, 1)))[:, 0]
            for c in u:
                link[c * nodes : (c + 1) * nodes] = np.maximum(smallest, 0.0)
        return link, self._bulk_norms[self._kept_field[self.position[k]]]

    def _link_rows(self, k: str) -> Vector:
        """Row sums of ``|L_k|`` on the contact DOFs: the half-link's stiffness [W/K, S, N/m]."""
        return np.abs(self.blocks[k]["L"]).sum(axis=1).A1

    def _soft_or_fixed(self) -> dict[str, npt.NDArray[np.bool_]]:
        """Per master DOF of each interface: take the link form (soft link or fixed slave).

        A link is soft for a field when its block's largest row sum is below the bulk's, on
        the rows of that field; and at a DOF whose row sum is below :data:`WEAK_LINK` times
        the bulk's (an open contact's tie), whatever its neighbours.
        """
        out = {}
        for k, position in self.position.items():
            link_rows = self._link_rows(k)
            fields = self._kept_field[position]
            soft = np.zeros(len(position), dtype=bool)
            for f, bulk in enumerate(self._bulk_norms):
                on = fields == f
                rows = link_rows[position[on]]
                soft[on] = (rows.max(initial=0.0) < bulk) | (rows < WEAK_LINK * bulk)
            out[k] = soft | np.isin(position, self.fixed_kept)
        return out

    def _contact_blocks(self, k: str) -> dict[str, scipy.sparse.csr_matrix]:
        """The blocks of interface k on the contact DOFs (no conditions), sparse, replicated.

        ``L`` (contact DOFs²), ``BP = B_k P_k`` (contact DOFs × masters of k) and, with the
        contact's Joule heat, ``CtP = P_kᵀ C̃_k`` and ``DtP = P_kᵀ D̃_k P_k``.
        """
        dense = {}
        for name, a in self.a_blocks[k].items():
            M = self.block_matrices[k][name]
            M.zeroEntries()
            dolfinx.fem.petsc.assemble_matrix(M, a)
            M.assemble()
            dense[name] = self._gather_sparse(M)
        at = self.position[k]
        out = {"L": dense["L"], "BP": dense["B"][:, at].tocsr()}
        if "Ct" in dense:
            out["CtP"] = dense["Ct"][at, :].tocsr()
            out["DtP"] = dense["Dt"][at, :][:, at].tocsr()
        return out

    def _gather_sparse(self, M: PETSc.Mat) -> scipy.sparse.csr_matrix:
        """A matrix's contact-DOF block, sparse, on every rank of the body."""
        sub = M.createSubMatrix(self._kept_is, self._kept_is)
        indptr, indices, data = sub.getValuesCSR()
        sub.destroy()
        rows = scipy.sparse.csr_matrix(
            (data.copy(), indices.copy(), indptr.copy()), shape=(len(indptr) - 1, len(self.kept))
        )
        if self.comm.size == 1:
            return rows
        return scipy.sparse.vstack(self.comm.allgather(rows)).tocsr()

    def whole_matrix(self) -> PETSc.Mat:
        """``A = A_bulk + Σ_k L_k`` with the Dirichlet conditions, at the current state.

        A copy of the bulk matrix with the links added on the contact rows (their entries
        lie in the bulk's pattern: a facet's DOFs are its cell's), not a second assembly of
        the bulk form (one 3D coupled Jacobian: 4.2 of 44 s of the row of four blocks with
        iterative bodies). The body keeps (and frees) the matrix.
        """
        bulk = self.bulk_matrix()
        if self._A is not None and self._whole_step == self._step:
            return self._A
        if self._A is None:
            self._A = bulk.duplicate(copy=True)
        else:
            bulk.copy(self._A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        owned = self.L_bc[self.kept_slice].tocsr()
        self._A.setValuesIJV(
            owned.indptr.astype(PETSc.IntType),
            self.kept[owned.indices].astype(PETSc.IntType),
            owned.data,
            addv=PETSc.InsertMode.ADD_VALUES,
            rowmap=(self.start + self.kept_local).astype(PETSc.IntType),
        )
        self._A.assemble()
        self._whole_step = self._step
        return self._A

    def apply_jacobian(
        self, x: Vector, masters: dict[str, Vector]
    ) -> tuple[Vector, dict[str, Vector]]:
        """The body's rows of ``J [x; y_m]`` (owned) and its shares ``C_k x + D_k P_k y_k``.

        ``A x`` by :meth:`_apply_A`, the masters' coupling added on the contact rows.
        """
        columns = {k: v[:, None] for k, v in masters.items()}
        x_s = self._gather_kept(x[self.kept_local])[:, None]
        rows = self._apply_A(x, x_s[:, 0])
        rows[self.kept_local] += self.coupling(columns)[self.kept_slice, 0]
        shares = {}
        for k, rows_k in self._rows.items():  # the link's own blocks on its slave rows
            blocks = self.blocks[k]
            r = -(rows_k["L"][k] @ x_s + rows_k["BP"][k] @ columns[k])[:, 0]
            if "CtP" in blocks:
                r = r + (blocks["CtP"] @ x_s + blocks["DtP"] @ columns[k])[:, 0]
            shares[k] = r
        return rows, shares

    def _factorise_whole(self) -> None:
        """``A`` as one sparse matrix, factorised by MUMPS (distributed), or its AMG set up.

        Raises:
            MemoryError: A direct body's factorising again would not fit in a node's memory
                left; said before ``A`` takes new values (the kept factors still solve the
                old ones). A split body makes room instead (:meth:`_room_for_sweep`).
        """
        rtol = None if self.ksp is None else self.ksp.getTolerances()[0]  # an iterative one's
        if self._direct is None:  # the last matrix solved by its Krylov solve throughout
            self.failures_in_a_row = 0
        destroy(self._direct)  # a matrix of other values: the Krylov solve is tried again
        self._direct = None
        self._drop_scaled_krylov()  # made again on the new matrix at the next solve
        if self._skip:  # after failures in a row: MUMPS at once, the Krylov's set-up left
            self._skip -= 1
            self.whole_matrix()
            self._fall_back(
                f"its Krylov solve failed at {self.failures_in_a_row} matrices in a row; "
                f"MUMPS for {self._skip + 1} more before it tries again"
            )
            return
        if self.ksp is not None and self.split:
            self._room_for_sweep()
        elif self.ksp is not None and not self.iterative:
            what = f"body '{self.name}' ({self._A.getSize()[0]} DOFs)"
            advice = (
                f"the body solved iteratively (-{self.prefix}solver split or iterative), "
                f"block low-rank factors (-{self.prefix}mat_mumps_icntl_35 2 "
                f"-{self.prefix}mat_mumps_cntl_7 1e-5), or fewer ranks per node"
            )
            refuse_refactorisation(self.ksp, self.comm, what, advice)
        self.whole_matrix()
        if self.split:  # made, or factorised again, with a short workspace relaxed
            if self.ksp is None:
                self._splits = self._sweep_splits()
            ksp, self.ksp = self.ksp, None  # one made again is destroyed by set_up_relaxed
            self.ksp, _ = set_up_relaxed(self._A, self.prefix, self.sweep, ksp, splits=self._splits)
        elif self.ksp is None and self.iterative and len(self.forms.fields) > 1:
            options = dict(SPLIT)
            for name in self.forms.fields:
                options |= {f"fieldsplit_{name}_{k}": v for k, v in SPLIT_FIELD.items()}
            self.ksp = make_ksp(self._A, self.prefix, options, splits=self._field_splits())
        elif self.ksp is None and self.iterative:
            self._A.setNearNullSpace(self._near_null_space())
            options = dict(ITERATIVE)
            if not self.is_linear:  # a Jacobian that is not symmetric
                options["ksp_type"] = "gmres"
                del options["pc_gamg_esteig_ksp_type"]
            self.ksp = make_ksp(self._A, self.prefix, options)
        elif self.iterative:
            self.ksp.setOperators(self._A)
            set_up(self.ksp)  # the fields' splits set up now, not at the first solve
        else:
            what = f"body '{self.name}'"
            again = not self.is_linear
            self.ksp = factorise(self._A, self.prefix, what, self.ksp, dim=self.dim, again=again)
        if rtol is not None:
            self.set_rtol(rtol)  # where the KSP was made anew
        self.factorisations += 1

    def _drop_ksp(self) -> None:
        """Free the body's KSP (its factors) and the index sets it was made with."""
        self._drop_scaled_krylov()
        destroy(self.ksp, *self._near_null)
        self.ksp, self._near_null, self._splits = None, [], []

    def _drop_scaled_krylov(self) -> None:
        if self._scaled_krylov is not None:
            self._scaled_krylov.destroy()
            self._scaled_krylov = None

    def _room_for_sweep(self) -> None:
        """Make room to factorise the sweep's splits again (collective).

        MUMPS factorises new values beside the old factors
        (:func:`~subdomain_contact.solvers.refactorisation_shortfall`). Where the node has not
        that room, the old factors are freed first; where even then the new ones would not
        fit (:func:`~subdomain_contact.solvers.fits_freed`), the body is solved by AMG
        (:data:`SPLIT`) for its life.
        The row of four 3D blocks at 1.01M DOFs (2 ranks, 23 GB node, every block by the
        sweep) stopped at its second Jacobian: block 0 asked 1.79 GB beside its factors with
        1.47 GB left.
        """
        if refactorisation_shortfall(self.ksp, self.comm) is None:
            return
        fits = fits_freed(self.ksp, self.comm)
        self._drop_ksp()
        if not fits:
            self.split = self._may_double = False
            self.fallbacks += 1

    def _field_splits(self) -> list[tuple[str, PETSc.IS]]:
        """Each field's owned DOFs (global, ascending) for :data:`SPLIT`.

        The displacement's set is blocked by node (block size = the mesh's dimension) and
        carries its rigid motions as the near-null space that PCFIELDSPLIT hands to its
        block; T and φ keep GAMG's default, the constant.
        """
        splits = []
        for name in self.forms.fields:
            V, parent_of = self.forms.collapsed(name)
            bs = V.dofmap.index_map_bs
            nodes = parent_of[: V.dofmap.index_map.size_local * bs].reshape(-1, bs)
            order = np.argsort(nodes[:, 0])
            iset = PETSc.IS().createGeneral(nodes[order].ravel() + self.start, comm=self.comm)
            self._near_null.append(iset)
            if name == "displacement":
                iset.setBlockSize(bs)
                points = V.tabulate_dof_coordinates()[: len(nodes)][order, :bs]
                coordinates = PETSc.Vec().createWithArray(
                    (points - centre(points, self.comm)).ravel(), bsize=bs, comm=self.comm
                )
                space = PETSc.NullSpace().createRigidBody(coordinates)
                coordinates.destroy()
                iset.compose("nearnullspace", space)
                self._near_null.append(space)
            splits.append((name, iset))
        return splits

    def _sweep_splits(self) -> list[tuple[str, PETSc.IS]]:
        """The owned DOFs (global, ascending) of (T, φ) and of u, for :data:`FACTORISED_SWEEP`."""
        splits = []
        for split, names in THERMOELECTRIC_MECHANICAL.items():
            rows = []
            for name in (n for n in names if n in self.forms.fields):
                V, parent_of = self.forms.collapsed(name)
                rows.append(parent_of[: V.dofmap.index_map.size_local * V.dofmap.index_map_bs])
            indices = np.sort(np.concatenate(rows)) + self.start
            iset = PETSc.IS().createGeneral(indices.astype(PETSc.IntType), comm=self.comm)
            self._near_null.append(iset)
            splits.append((split, iset))
        return splits

    def _near_null_space(self) -> PETSc.NullSpace:
        """The body's kernel modes on its DOFs, orthonormal (the near-null space of AMG)."""
        fields, dim = self.forms.fields, self.forms.W.mesh.geometry.dim
        V, _ = self.forms.collapsed(fields[0], 0 if fields[0] == "displacement" else None)
        owned = V.dofmap.index_map.size_local
        middle = centre(V.tabulate_dof_coordinates()[:owned], self.comm)
        vectors: list[PETSc.Vec] = []
        for mode in modes(fields, dim):
            v = self.A_bulk.createVecRight()
            v.array[:] = self.mode_values(mode, middle)
            vectors.append(v)
        space = span(vectors, self.comm)
        self._near_null = [space]
        return space

    def set_rtol(self, rtol: float) -> None:
        """Relative (preconditioned) residual of an iterative body solve.

        The option ``-<prefix>ksp_rtol`` wins.
        """
        if self.iterative and self.ksp is not None:
            if not PETSc.Options().hasName(self.prefix + "ksp_rtol"):
                self.ksp.setTolerances(rtol=rtol)

    # -- solves -----------------------------------------------------------------------------
    def _gather_kept(self, values: Vector) -> Vector:
        """Owned contact-DOF values -> every contact DOF, on every rank."""
        return np.concatenate(self.comm.allgather(values)) if self.comm.size > 1 else values

    def solve(self, rhs: Vector) -> Vector:
        """``A⁻¹ rhs`` on owned DOFs.

        With several fields, one step of iterative refinement: the dense factorisation of
        the Schur block pivots across fields (a Joule coupling can outweigh a conductivity by
        1e6), which leaves a small field the round-off of a large one; the residual of the
        first solve, computed with the sparse matrix, takes it back out.
        """
        if self.factor is None:
            return self._solve_whole(rhs)
        y = self._solve_schur(rhs)
        if len(self.forms.fields) > 1:
            residual = rhs - self._apply_A(y)
            if self._polluted(residual, rhs, y):
                y += self._solve_schur(residual)
        return y

    def _polluted(self, residual: Matrix, rhs: Matrix, y: Matrix, *, kept: bool = False) -> bool:
        """Whether some field's residual is above 1e3 eps of its own scale.

        The scale is that of :meth:`_field_residual`, which a solve that kept the fields
        apart reaches to a few eps.
        """
        return self._field_residual(residual, rhs, y, kept=kept) > 1e3 * np.finfo(float).eps

    def _field_residual(
        self, residual: Matrix, rhs: Matrix, y: Matrix, *, kept: bool = False
    ) -> float:
        """The largest over fields of ``‖r_f‖∞ / (‖b_f‖∞ + ‖A_f‖∞ ‖y_f‖∞)`` (every rank).

        The scale of field f: its right-hand side, and its rows' largest sum times its own
        unknowns. ``kept``: the arrays are on the contact DOFs (rows), not on the owned DOFs.
        """
        dofs_of = self._kept_field_dofs if kept else self._field_dofs
        return self._scaled_residual(residual, self._local_scales(rhs, y, dofs_of), dofs_of)

    def _local_scales(self, rhs: Matrix, y: Matrix, dofs_of: list) -> Vector:
        """Each field's ``‖b_f‖∞ + ‖A_f‖∞ ‖y_f‖∞`` on this rank's ``dofs_of`` (fields × columns)."""
        return np.array(
            [
                np.abs(rhs[dofs]).max(axis=0, initial=0.0)
                + self._bulk_norms[f] * np.abs(y[dofs]).max(axis=0, initial=0.0)
                for f, dofs in enumerate(dofs_of)
            ]
        )

    def _solve_schur(self, rhs: Vector) -> Vector:
        b, x = self._vectors[0], self._vectors[1]
        b.array[:] = self.scale * rhs
        self.factor.solve(b, x)
        return self.scale * x.array

    def _apply_A(self, y: Vector, y_s: Vector | None = None) -> Vector:
        """``A y = A_bulk y + Σ_k L_k y`` (conditions included) on owned DOFs.

        By the whole matrix where it is built for this state, else by the bulk matrix and
        the links' block (``y_s``: y on every contact DOF, where the caller has gathered it).
        """
        x, Ay = self._vectors[0], self._vectors[2]
        x.array[:] = y
        if self._A is not None and self._whole_step == self._step:
            self._A.mult(x, Ay)
            return Ay.array.copy()
        self.bulk_matrix().mult(x, Ay)
        out = Ay.array.copy()
        y_s = self._gather_kept(y[self.kept_local]) if y_s is None else y_s
        out[self.kept_local] += (self.L_bc @ y_s)[self.kept_slice]
        return out

    def _solve_whole(self, rhs: Vector) -> Vector:
        if self.split:
            return self._solve_split(rhs[:, None])[:, 0]
        y = self._krylov(rhs)
        if self.iterative and len(self.forms.fields) > 1:
            # The Krylov test's norm mixes fields of units K, V and m: a field of small
            # values can stop far short of its own relative tolerance (four 3D blocks, T, φ,
            # u: u up to 1e8 times short), and the interface then stalls. Each field's residual is
            # measured against its own scale, and a short solve is refined (A δ = r), to
            # a tenth of the shortfall only: a refinement to the full tolerance repeated
            # the whole reduction on the residual (the row of four blocks at 31k DOFs: 36,
            # 26 and 14 iterations per refinement where 9, 7 and 7 suffice, the same count
            # of refinements; body Krylov 32.8 s → 27.1 s, 13 Newton steps both).
            target = self._target()
            for _ in range(FIELD_REFINEMENTS):
                residual = rhs - self._apply_A(y)
                shortfall = self._field_residual(residual, rhs, y) / target
                if shortfall <= 1.0:
                    break
                y += self._krylov(residual, max(target, 0.1 / shortfall))
        return y

    def _target(self) -> float:
        """Each field's tolerance of an iterative solve, relative to its scale."""
        return max(self.ksp.getTolerances()[0], 1e3 * np.finfo(float).eps)

    def _solve_split(self, rhs: Matrix) -> Matrix:
        """A split body's solves of ``A Y = rhs`` (owned rows × columns), every column at once.

        Each field's residual is measured against its own scale and a short column refined,
        as :meth:`_solve_whole`'s; a field is measured against the larger of its own scale and
        the one its column's FGMRES weighed it by (:meth:`_weigh`). A sweep in single
        precision still short after :data:`FIELD_REFINEMENTS` is factorised again in double
        (:meth:`_sweep_in_double`) and every column solved again.
        """
        target = self._target()
        y, solved = self._sweep_columns(rhs, np.full(rhs.shape[1], None), None)
        for refinement in range(FIELD_REFINEMENTS + 1):
            residual = rhs - self._apply_columns(y)
            scales = np.maximum(self._field_scales(rhs, y), solved)
            shortfall = self._scaled_residual(residual, scales) / target
            short = shortfall > 1.0
            if not short.any() or refinement == FIELD_REFINEMENTS:
                break
            rtol = np.maximum(target, 0.1 / shortfall[short])
            dy, solved[:, short] = self._sweep_columns(residual[:, short], rtol, scales[:, short])
            y[:, short] += dy
        if short.any() and self._may_double and self._sweep_in_double():
            return self._solve_split(rhs)
        return y

    def _apply_columns(self, y: Matrix) -> Matrix:
        """``A y`` for columns on the owned DOFs (:meth:`_apply_A`).

        By one product where the whole matrix is built for this state.
        """
        if y.shape[1] > 1 and self._A is not None and self._whole_step == self._step:
            return columns_mult(self._A, y)
        return np.column_stack([self._apply_A(column) for column in y.T])

    def _sweep_columns(
        self, rhs: Matrix, rtol: Sequence[float | None], scales: Matrix | None
    ) -> tuple[Matrix, Matrix]:
        """A split body's FGMRES on every column of ``rhs``, its rows weighed by field.

        ``rtol``: each column's (None: the body's); ``scales``: each field's (rows) scale
        per column, or None for the fields' scales of ``rhs`` and one sweep on it
        (:meth:`_weigh`). Several columns go together (:func:`~subdomain_contact.solvers.
        fgmres_columns`) while the sweep solves, one by one by :meth:`_krylov` once MUMPS
        has taken the body; a column that does not meet its tolerance together is solved
        again alone, by :meth:`_krylov` and its ways out. Returns the solutions and the scales
        each column was weighed by.
        """
        m = rhs.shape[1]
        y, solved = np.empty_like(rhs), np.empty((len(self._field_dofs), m))

        def alone(j: int) -> None:
            y[:, j] = self._krylov(rhs[:, j], rtol[j], None if scales is None else scales[:, j])
            solved[:, j] = self._solved_scales

        if m == 1 or self._direct is not None:
            for j in range(m):
                alone(j)
            return y, solved
        pc = self.ksp.getPC()
        first = columns_apply(pc, rhs)
        weights = np.empty_like(rhs)
        for j in range(m):
            column = None if scales is None else scales[:, j]
            weights[:, j] = self._weigh(rhs[:, j], first[:, j], column)
            solved[:, j] = self._solved_scales
        own = self.ksp.getTolerances()[0]
        tolerances = np.array([own if r is None else r for r in rtol], dtype=float)
        restart, max_it = self._column_budget(m)
        together, iterations, met = fgmres_columns(
            self._A, pc, rhs, weights, tolerances, restart, max_it, first
        )
        y[:] = together  # the columns solved alone below are written into y
        self.solve_iterations += int(iterations.sum())
        for j in np.flatnonzero(~met):
            alone(j)
        return y, solved

    def _column_budget(self, columns: int) -> tuple[int, int]:
        """Restart and iteration cap of FGMRES on ``columns`` at once (:meth:`_sweep_columns`).

        The restart is the body's (``-<prefix>ksp_gmres_restart``) shared among the columns,
        so that they hold as many vectors as one solve at its restart, but at least
        :data:`COLUMN_RESTART`; a column still short after :data:`COLUMN_CYCLES` restarts is
        solved again alone.
        """
        key = self.prefix + "ksp_gmres_restart"
        restart = PETSc.Options().getInt(key, int(self.sweep["ksp_gmres_restart"]))
        restart = max(COLUMN_RESTART, restart // columns)
        return restart, min(self.ksp.getTolerances()[3], COLUMN_CYCLES * restart)

    def _sweep_in_double(self) -> bool:
        """Factorise the sweep's splits again in double precision, for the body's life.

        Where the double-precision factors (about twice the single ones) would not fit in the
        node's memory left once the single ones are freed, the single ones stay, for good:
        the interface solve checks its true residual and says so if it fails (collective).

        Returns: Whether the splits are now factorised in double precision.
        """
        self._may_double = False
        if not fits_freed(self.ksp, self.comm, 2.0):
            return False
        rtol = self.ksp.getTolerances()[0]
        self._drop_ksp()
        self.sweep = FACTORISED_SWEEP_DOUBLE
        self._splits = self._sweep_splits()
        self.ksp, _ = set_up_relaxed(self._A, self.prefix, self.sweep, splits=self._splits)
        self.set_rtol(rtol)
        self.factorisations += 1
        self.fallbacks += 1
        return True

    def _krylov(
        self, rhs: Vector, rtol: float | None = None, scales: Vector | None = None
    ) -> Vector:
        """One Krylov solve (or solve by the factorisation) of ``A y = rhs``.

        Where an iterative body's Krylov solve fails (GMRES + GAMG broke down, PETSc reason
        -5, at a state far from the solution: the row of four 3D blocks at 1.01M DOFs, a
        step that moved a field by 22 times its largest value), the body's matrix is
        factorised by MUMPS (options under ``-<prefix>direct_``) and solves by it until the
        matrix changes; the next matrix tries the Krylov solve again, but after the n-th
        failure in a row (n ≥ :data:`FAILURES_IN_A_ROW`) MUMPS takes the next ``2^(n-1)``
        matrices first, without the Krylov's set-up. A sweep still in single
        precision is first factorised again in double (:meth:`_sweep_in_double`), as a short
        one is, and solves again. Where MUMPS's analysis
        says those factors would not fit in the node's memory left, a ``MemoryError`` says so
        and what to try (:func:`~subdomain_contact.solvers.refuse_factorisation`).
        A split body solves by FGMRES on its rows weighed by ``1 / scales`` of their field
        (:class:`~subdomain_contact.solvers.RowScaledKrylov`): by default each field's scale
        for ``rhs`` and one sweep on it (:meth:`_field_scales`), the scales then kept in
        ``_solved_scales``.
        """
        b, x = self._vectors[0], self._vectors[1]
        b.array[:] = rhs
        if self._direct is not None:
            self._direct.solve(b, x)
            return self._checked(self._direct, x)
        ksp = self.ksp
        if self.split:
            if self._scaled_krylov is None:
                key = self.prefix + "ksp_gmres_restart"
                restart = PETSc.Options().getInt(key, int(self.sweep["ksp_gmres_restart"]))
                self._scaled_krylov = RowScaledKrylov(self.ksp, self._A, restart)
            ksp = self._scaled_krylov.ksp
            rtol = self.ksp.getTolerances()[0] if rtol is None else rtol
            x = self._scaled_krylov.solve(
                b, lambda b, y: self._weigh(b.array_r, y.array_r, scales), rtol
            )
        else:
            if rtol is not None:
                kept = ksp.getTolerances()[0]
                ksp.setTolerances(rtol=rtol)
            ksp.solve(b, x)
            if rtol is not None:
                ksp.setTolerances(rtol=kept)
        reason, iterations = ksp.getConvergedReason(), ksp.getIterationNumber()
        self.solve_iterations += iterations if self.iterative else 0
        if reason < 0 and self.iterative and self._may_double and self._sweep_in_double():
            # a sweep in single precision that stagnates is doubled before MUMPS takes the
            # body whole (the row at 18,495 DOFs: block 0's GMRES broke down at its restart
            # of 100 iterations, stuck at 4e-5 of its start, on a coarse column at step 12)
            return self._krylov(rhs, rtol, scales)
        if reason < 0 and self.iterative:
            kind = f"{ksp.getType().upper()} + {self.ksp.getPC().getType().upper()}"
            self.failures_in_a_row += 1
            if self.failures_in_a_row >= FAILURES_IN_A_ROW:
                self._skip = 2 ** (self.failures_in_a_row - 1)
            self._fall_back(
                f"{kind} stopped with PETSc reason {reason} after {iterations} iterations; "
                "MUMPS instead"
            )
            return self._krylov(rhs)
        return self._checked(ksp, x)

    def _fall_back(self, why: str) -> None:
        """MUMPS on the body's matrix (options under ``-<prefix>direct_``) until it changes.

        ``why`` names the cause in the error raised where the factors would not fit.
        """
        advice = (
            f"a larger Krylov budget (-{self.prefix}ksp_max_it, "
            f"-{self.prefix}ksp_gmres_restart), shorter Newton steps (a smaller "
            "max_temperature_step of sc.solve), or fewer ranks per node"
        )
        self._direct = factorise(
            self._A,
            self.prefix + "direct_",
            f"body '{self.name}' ({why})",
            dim=self.dim,
            again=False,
            advice=advice,
        )
        self.factorisations += 1
        self.fallbacks += 1

    def _field_scales(self, rhs: Matrix, y: Matrix) -> Matrix:
        """Each field's scale ``‖b_f‖∞ + ‖A_f‖∞ ‖y_f‖∞`` (:meth:`_field_residual`), all ranks.

        One per field, or fields × columns for columns.
        """
        scales = self._local_scales(rhs, y, self._field_dofs)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, scales, op=MPI.MAX)
        return scales

    def _scaled_residual(
        self, residual: Matrix, scales: Matrix, dofs_of: list | None = None
    ) -> float | Vector:
        """The largest over fields of ``‖r_f‖∞ / scale_f`` (every rank).

        Per column for columns (``scales``: fields × columns).
        """
        dofs_of = self._field_dofs if dofs_of is None else dofs_of
        largest = np.array([np.abs(residual[dofs]).max(axis=0, initial=0.0) for dofs in dofs_of])
        worst = np.atleast_1d((largest / np.maximum(scales, 1e-300)).max(axis=0))
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, worst, op=MPI.MAX)
        return worst if residual.ndim > 1 else float(worst[0])

    def _weigh(self, rhs: Vector, y: Vector, scales: Vector | None) -> Vector:
        """Each owned row's weight in a split body's FGMRES: ``1 / scale`` of its field.

        ``scales`` where given, else :meth:`_field_scales` with ``y`` an estimate of the
        solution (one sweep on ``rhs``). A field of zero scale takes the largest weight of
        the others (1 where every scale is zero). The scales are kept (``_solved_scales``) for
        the solve's own test (:meth:`_solve_split`): a field whose solution is the round-off
        of the others (the potential of a column with no current, 1e-17 where its sweep gave
        1e-3) is measured against the scale it was solved to, not its own, which FGMRES
        drives down with it (the row at 218,790 DOFs: 2.5e10 times short by its own, its
        refinements 2,211 iterations, then the sweep doubled and MUMPS).
        """
        if scales is None:
            scales = self._field_scales(rhs, y)
        weights = np.divide(1.0, scales, out=np.zeros_like(scales), where=scales > 0)
        weights[scales == 0] = weights.max(initial=0.0) or 1.0
        self._solved_scales = 1.0 / weights
        out = np.empty(self.size)
        for f, dofs in enumerate(self._field_dofs):
            out[dofs] = weights[f]
        return out

    def _checked(self, ksp: PETSc.KSP, x: PETSc.Vec) -> Vector:
        """The solution ``x`` of ``ksp``, or an error naming the body."""
        reason = ksp.getConvergedReason()
        if reason < 0:
            raise RuntimeError(f"body '{self.name}': linear solve failed (reason {reason})")
        return x.array.copy()

    def coupling(self, masters: dict[str, Matrix]) -> Matrix:
        """``Σ_k B_k P_k Y_k`` on the contact DOFs for columns Y, rows of fixed DOFs zeroed."""
        out = np.zeros((len(self.kept), next(iter(masters.values())).shape[1]))
        for k in self.layers:
            out += self.blocks[k]["BP"] @ masters[k]
        out[self.fixed_kept] = 0.0
        return out

    def round(self, b: Vector | None, masters: MasterValues) -> tuple[Vector, MasterValues]:
        """Solve the body for master increments; its share of every master residual.

        Args:
            b: Right-hand side on owned DOFs, zero on fixed DOFs; None for zero.
            masters: Interface name -> master values (replicated).

        Returns:
            The body's solution on owned DOFs, and interface name -> ``r_k`` (replicated).
        """
        columns = {k: v[:, None] for k, v in masters.items()}
        rhs = np.zeros(self.size) if b is None else b.copy()
        rhs[self.kept_local] -= self.coupling(columns)[self.kept_slice, 0]
        y = self.solve(rhs)
        x, Ay = self._vectors[0], self._vectors[2]
        x.array[:] = y
        self.A_bulk.mult(x, Ay)
        kept = self.kept_local
        b_s = self._gather_kept(np.zeros(len(kept)) if b is None else b[kept])
        y_s, Ay_s = self._gather_kept(y[kept]), self._gather_kept(Ay.array[kept])
        residuals = self._master_residuals(
            lambda at: b_s[at, None] - Ay_s[at, None], y_s[:, None], columns
        )
        return y, {k: r[:, 0] for k, r in residuals.items()}

    def _master_residuals(
        self,
        unbalanced: Callable[[npt.NDArray[np.intp]], Matrix],
        y_s: Matrix,
        masters: dict[str, Matrix],
    ) -> dict[str, Matrix]:
        """``r_k`` for columns of contact-DOF solutions ``y_s``.

        ``unbalanced(at)``: the right-hand side minus ``A_bulk y`` on the contact DOFs
        ``at``. Two equal forms, each exact where the other loses digits: for a stiff link
        (its block larger than the bulk's, field by field) the reaction form, the body's own
        equation without the link; for a soft link, and at fixed slaves, the link itself,
        whose round-off scales with the link instead of the bulk. The reaction form is
        evaluated on the rows that take it only: with the Schur block its ``A_bulk y`` is a
        dense product as costly as the solve.
        """
        out = {}
        for k, rows in self._rows.items():
            r = -(rows["L"][k] @ y_s + rows["BP"][k] @ masters[k])
            stiff = np.flatnonzero(~self.use_link[k])
            if stiff.size:
                share = unbalanced(self.position[k][stiff])
                for j in self.layers:
                    if j != k:
                        share = share - (rows["L"][j] @ y_s + rows["BP"][j] @ masters[j])[stiff]
                r[stiff] = -share
            blocks = self.blocks[k]
            if "CtP" in blocks:
                r = r + blocks["CtP"] @ y_s + blocks["DtP"] @ masters[k]
            out[k] = r
        return out

    # -- interface operators ---------------------------------------------------------------
    def master_sizes(self) -> list[int]:
        """Master DOFs of each of the body's interfaces, in ``layers`` order."""
        return [layer.size for layer in self.layers.values()]

    def master_slices(self) -> dict[str, slice]:
        """Where each interface's masters sit in the body's concatenated master vector."""
        ends = np.cumsum([0, *self.master_sizes()])
        pairs = zip(self.layers, ends[:-1], ends[1:], strict=True)
        return {k: slice(int(a), int(b)) for k, a, b in pairs}

    def interface_stiffness(self) -> Matrix:
        """Dense ``S^α`` over all the body's masters (interfaces in ``layers`` order).

        The body's response to each unit master value, its master residuals in the reaction
        form: with the Schur block ``y_s = (Σ + L)⁻¹ rhs_s`` and ``A_bulk y = Σ y_s`` on the
        contact DOFs, dense algebra; otherwise one body solve per master DOF. Kept until the
        next :meth:`assemble`.
        """
        if self._stiffness is None:
            self._stiffness = self._form_stiffness()
        return self._stiffness

    def _form_stiffness(self) -> Matrix:
        sizes = self.master_sizes()
        unit = np.eye(sum(sizes))
        masters = dict(zip(self.layers, np.split(unit, np.cumsum(sizes)[:-1]), strict=True))
        response = self.respond(masters)
        return np.concatenate([response[k] for k in self.layers])

    def respond(self, masters: dict[str, Matrix]) -> dict[str, Matrix]:
        """``S^α`` applied to columns of master values: the homogeneous master residuals."""
        rhs_s = -self.coupling(masters)
        if self.schur:
            y_s = self._solve_kept(rhs_s)
            if len(self.forms.fields) > 1:  # iterative refinement, as in :meth:`solve`
                # probed on one combination of the columns (cheap), refined on all
                z = np.random.default_rng(0).standard_normal(y_s.shape[1])
                yz, bz = y_s @ z, rhs_s @ z
                if self._polluted(bz - self.sigma @ yz - self.L_bc @ yz, bz, yz, kept=True):
                    y_s += self._solve_kept(rhs_s - self.sigma @ y_s - self.L_bc @ y_s)
            return self._master_residuals(lambda at: -(self.sigma[at] @ y_s), y_s, masters)
        y_s, Ay_s = self._solve_columns(rhs_s)
        return self._master_residuals(lambda at: -Ay_s[at], y_s, masters)

    def mode_values(self, mode: Mode, middle: npt.NDArray[np.float64]) -> Vector:
        """A kernel mode (:func:`~subdomain_contact.modes.modes`) on the owned DOFs.

        Rotations are about ``middle`` [m]. From the DOFs' nodes, made once
        (:meth:`~subdomain_contact.physics.BodyForms.nodes`), not tabulated at each call: the
        kernels are looked for at every Jacobian, 1.2 s a Newton step on the row of four 3D
        blocks at 1.01M DOFs, and tabulating was about half of it (74,580 DOFs, 2 ranks: 1.17
        → 0.65 s over 13 Jacobians).
        """
        nodes = self.forms.nodes()
        x = nodes.points[nodes.node[: self.size]] - middle
        component = nodes.component[: self.size]
        out = np.zeros(self.size)
        for c, (name, d) in enumerate(nodes.parts):
            at = component == c
            out[at] = mode(name, d, x[at])
        return out

    def respond_by(self, y: Vector, masters: dict[str, Vector]) -> dict[str, Vector] | None:
        """``S^α`` of master values that ``y`` (owned DOFs) solves the body for, without a solve.

        A body's own constant or rigid motion, its trace on the masters, solves the body
        where the body's conditions and laws do not see it (a floating body's translation):
        its response is then the master residuals at ``y``, a product, where a solve would
        compute it as the small difference of two large terms. None where ``y`` leaves a
        residual above :data:`KERNEL_RESIDUAL` of some field's scale (collective).
        """
        columns = {k: v[:, None] for k, v in masters.items()}
        rhs = np.zeros(self.size)
        rhs[self.kept_local] -= self.coupling(columns)[self.kept_slice, 0]
        if self._field_residual(rhs - self._apply_A(y), rhs, y) > KERNEL_RESIDUAL:
            return None
        x, Ay = self._vectors[0], self._vectors[2]
        x.array[:] = y
        self.A_bulk.mult(x, Ay)
        kept = self.kept_local
        y_s, Ay_s = self._gather_kept(y[kept]), self._gather_kept(Ay.array[kept])
        out = self._master_residuals(lambda at: -Ay_s[at, None], y_s[:, None], columns)
        return {k: r[:, 0] for k, r in out.items()}

    def _solve_kept(self, rhs_s: Matrix) -> Matrix:
        """``(Σ + L)⁻¹ rhs_s`` by the scaled dense factorisation of the Schur block."""
        d = self.scale[self.kept_local][:, None]
        return d * self.factor.solve_block(d * rhs_s)

    def _solve_columns(self, rhs_s: Matrix) -> tuple[Matrix, Matrix]:
        """Body solves for right-hand sides on the contact DOFs: ``y_s`` and ``(A_bulk y)_s``.

        A body factorised on one rank solves many columns at once (``MatMatSolve``, in
        blocks of :data:`COLUMN_BYTES`), a split body by FGMRES on every column at once
        (:meth:`_solve_split`); otherwise one solve per column.
        """
        if self.split and rhs_s.shape[1] > 1:
            rhs = np.zeros((self.size, rhs_s.shape[1]))
            rhs[self.kept_local] = rhs_s[self.kept_slice]
            y = self._solve_split(rhs)
            Ay = columns_mult(self.A_bulk, y)
            return self._gather_kept(y[self.kept_local]), self._gather_kept(Ay[self.kept_local])
        if self.iterative or self.comm.size > 1 or rhs_s.shape[1] == 1:
            return self._solve_each_column(rhs_s)
        y_s, Ay_s = np.empty_like(rhs_s), np.empty_like(rhs_s)
        width = max(1, COLUMN_BYTES // (8 * self.size))
        for first in range(0, rhs_s.shape[1], width):
            block = slice(first, min(first + width, rhs_s.shape[1]))
            rhs = np.zeros((self.size, block.stop - block.start))
            rhs[self.kept_local] = rhs_s[:, block]
            y = columns_apply(self.ksp.getPC(), rhs)  # the factorisation's MatMatSolve
            y_s[:, block] = y[self.kept_local]
            Ay_s[:, block] = columns_mult(self.A_bulk, y)[self.kept_local]
        return y_s, Ay_s

    def _solve_each_column(self, rhs_s: Matrix) -> tuple[Matrix, Matrix]:
        """:meth:`_solve_columns` by one body solve per column (iterative or spread bodies)."""
        y_s, Ay_s = np.zeros_like(rhs_s), np.zeros_like(rhs_s)
        rhs = np.zeros(self.size)
        x, Ay = self._vectors[0], self._vectors[2]
        for j in range(rhs_s.shape[1]):
            rhs[self.kept_local] = rhs_s[self.kept_slice, j]
            x.array[:] = self.solve(rhs)
            self.A_bulk.mult(x, Ay)
            y_s[:, j] = self._gather_kept(x.array[self.kept_local])
            Ay_s[:, j] = self._gather_kept(Ay.array[self.kept_local])
        return y_s, Ay_s

    def condensed_stiffness(self, k: str) -> Matrix:
        """``K̂`` of interface k: the solid with its other half-links, condensed on k's masters.

        Contact term of k excluded (METHOD.md §3); dense, in master order. From the Schur
        block where there is one, else by one solve per master DOF. Slaves fixed by a
        Dirichlet condition are made infinitely stiff (1e8 times the largest diagonal).
        """
        if not self.schur:
            owned = np.arange(self.size, dtype=np.int32)
            interior = np.setdiff1d(owned, self.slaves[k].local_dofs).astype(np.int32)
            K_ee, coupling = self.condense(k, interior)
            return self.clamp_fixed(k, K_ee - coupling)
        free = scipy.sparse.diags(np.isin(np.arange(len(self.kept)), self.free_kept) * 1.0)
        block = self.sigma + (free @ (self.L - self.blocks[k]["L"]) @ free).toarray()
        at = self.position[k]
        other = np.setdiff1d(np.arange(len(self.kept)), at)
        K_hat = block[np.ix_(at, at)]
        if other.size:
            K_hat = K_hat - block[np.ix_(at, other)] @ np.linalg.solve(
                block[np.ix_(other, other)], block[np.ix_(other, at)]
            )
        return self.clamp_fixed(k, K_hat)

    def condense(self, k: str, interior: npt.NDArray[np.int32]) -> tuple[Matrix, Matrix]:
        """The solid's blocks on the master channels e of k: ``K_ee`` and ``K_ei K_ii⁻¹ K_ie``.

        The solid with its other half-links and its conditions; the owned DOFs ``interior``
        are condensed, the others clamped. Both dense, in master order.
        """
        forms, U = self.forms, self.forms.U
        others = [j for j in self.layers if j != k]
        if others:
            solid = forms.bulk
            for j in others:
                solid = solid + self._linearised[j]
            a = dolfinx.fem.form(ufl.derivative(solid, U, ufl.TrialFunction(forms.W)))
            K = dolfinx.fem.petsc.assemble_matrix(a, bcs=forms.bcs)
            K.assemble()
        else:  # the solid is the bulk, assembled already
            K = self.bulk_matrix()
        Kt = K.transpose(PETSc.Mat())
        e, i = (
            PETSc.IS().createGeneral((self.start + d).astype(PETSc.IntType), comm=self.comm)
            for d in (self.slaves[k].local_dofs, interior)
        )
        K_ee, K_ie_sparse, K_ii, K_eiT = (
            M.createSubMatrix(*p) for M, p in [(K, (e, e)), (K, (i, e)), (K, (i, i)), (Kt, (i, e))]
        )
        K_ie = K_ie_sparse.convert("dense", out=PETSc.Mat())
        options = ordered(DIRECT, self.dim, K_ii.getSize()[0], again=False)
        ksp = make_ksp(K_ii, f"{self.prefix}condense_", options)
        X = K_ie.duplicate()
        ksp.getPC().getFactorMatrix().matSolve(K_ie, X)
        # K_ei X from the rows each rank owns, summed (PETSc's MPIAIJ × MPIDense product
        # crashed here when a rank owns none of the slaves)
        eiT = K_eiT.convert("dense", out=PETSc.Mat())
        local = eiT.getDenseArray(readonly=True).T @ X.getDenseArray(readonly=True)
        coupling = self.comm.allreduce(local, op=MPI.SUM) if self.comm.size > 1 else local
        dense = K_ee.convert("dense", out=PETSc.Mat())
        rows = dense.getDenseArray(readonly=True).copy()
        rows = np.concatenate(self.comm.allgather(rows)) if self.comm.size > 1 else rows
        order = self.slaves[k].gathered_master_index
        result = []
        for matrix in (rows, coupling):
            reordered = np.empty_like(matrix)
            reordered[np.ix_(order, order)] = matrix
            result.append(reordered)
        destroy(K if others else None, Kt, e, i, K_ee, K_ie_sparse, K_ii, K_eiT, K_ie, ksp, X)
        destroy(eiT, dense)
        return result[0], result[1]

    def clamp_fixed(self, k: str, stiffness: Matrix) -> Matrix:
        """``stiffness`` (master order) with the fixed slaves of k made infinitely stiff."""
        fixed = np.flatnonzero(np.isin(self.position[k], self.fixed_kept))
        if fixed.size:
            stiff = 1e8 * float(np.abs(np.diag(stiffness)).max())
            stiffness = stiffness.copy()
            stiffness[fixed, :] = 0.0
            stiffness[:, fixed] = 0.0
            stiffness[fixed, fixed] = stiff
        return stiffness

    def link_stiffness(self, k: str) -> Matrix:
        """The half-link's own master block ``P_kᵀ D_k P_k`` (the paper's K_mm = h̄M), dense."""
        return self._master_block(k).toarray()

    def _master_block(self, k: str) -> scipy.sparse.csr_matrix:
        """``P_kᵀ D_k P_k`` (masters of k², sparse): ``−B_k P_k`` on the slave rows, plus D̃."""
        D = -self.blocks[k]["BP"][self.position[k], :]
        return D + self.blocks[k]["DtP"] if "DtP" in self.blocks[k] else D

    # -- residuals ------------------------------------------------------------------------
    def residual(self, *, conditions: bool = True) -> Vector:
        """Owned body residual at the current state.

        With ``conditions`` the rows of fixed DOFs hold U − g; without, every row holds the
        assembled residual, which at a fixed DOF is its reaction [W, A, N].
        """
        b = dolfinx.fem.petsc.assemble_vector(self.F_bulk)
        for form in self.F_links.values():
            dolfinx.fem.petsc.assemble_vector(b, form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        if conditions:
            dolfinx.fem.petsc.set_bc(b, self.forms.bcs, x0=self.U.x.petsc_vec, alpha=-1.0)
        values = b.array.copy()
        b.destroy()
        return values

    def compiled(self, key: Hashable, form: ufl.Form) -> dolfinx.fem.Form:
        """``form`` compiled on first use and kept under ``key`` (later forms are not read).

        For the integrals a report asks for at every step (means, flows, balances): a form
        compiled again costs its UFL processing and a look-up of the JIT cache each time
        (about 9 ms per form on the preheat slice, more than its assembly).
        """
        if key not in self._compiled:
            self._compiled[key] = dolfinx.fem.form(form)
        return self._compiled[key]

    def master_residual(self, k: str) -> Vector:
        """This body's share ``r_k`` of the master residual of k at the current state."""
        return -self.assembled_at_slaves(self.F_fluxes[k], k)

    def assembled_at_slaves(self, form: dolfinx.fem.Form, k: str) -> Vector:
        """A vector form assembled on the body, at the slave DOFs of k in master order."""
        b = dolfinx.fem.petsc.assemble_vector(form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        values = self.slaves[k].gather(b.array, self.layers[k].size, self.comm)
        b.destroy()
        return values

    def contact_outflow(self, k: str, load: Vector | None = None) -> Vector:
        """What leaves the body into interface k per master DOF [W, A, N]: its half-link.

        The link's nodal terms at the slaves (heat conducted minus the contact's Joule heat
        deposited on this side, current, contact force), in the stable form of each DOF:
        for a stiff link the reaction of the bulk and the other links (minus ``load``,
        nodal values in master order put into the body at the slaves), for a soft one or a
        fixed slave the link itself. The state must satisfy the body's equation.
        """
        if not hasattr(self, "blocks"):
            self.assemble()
        self.bulk_matrix()
        use_link = self._soft_or_fixed()[k]
        b = dolfinx.fem.petsc.assemble_vector(self.F_bulk)
        for j, form in self.F_links.items():
            if j != k:
                dolfinx.fem.petsc.assemble_vector(b, form)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        rest = self.slaves[k].gather(b.array, self.layers[k].size, self.comm)
        b.destroy()
        if load is not None:
            rest = rest - load
        return np.where(use_link, self.assembled_at_slaves(self.F_links[k], k), -rest)

    def set_masters(self, masters: MasterValues) -> None:
        """Write replicated master vectors into the body's master Functions."""
        for k, Um in self.forms.masters.items():
            Um.x.array[:] = 0.0
            self.slaves[k].scatter(masters[k], Um.x.array)
            Um.x.scatter_forward()

    def apply_conditions(self) -> None:
        """Set the fixed DOFs to their prescribed values."""
        for bc in self.forms.bcs:
            bc.set(self.U.x.array)
        self.U.x.scatter_forward()

    def failing_law(self) -> str | None:
        """The first conductivity or conductance that is negative or NaN at the current state.

        Named with a point [m] where it fails, or None (collective on the body).
        """
        laws = {  # a constant's value was checked with the problem's data
            name: (law, dm)
            for name, (law, dm) in self.forms.laws.items()
            if not isinstance(law, dolfinx.fem.Constant)
        }
        if not laws:
            return None
        field = self.forms.fields[0]  # temperature or potential: the laws' fields come first
        V, parent_of = self.forms.collapsed(field)
        if not hasattr(self, "_law_checks"):
            v = ufl.TestFunction(self.forms.W)
            v = v if len(self.forms.fields) == 1 else ufl.split(v)[0]
            self._law_checks = [
                (name, dolfinx.fem.form(ufl.conditional(ufl.ge(law, 0.0), 0.0, 1.0) * v * dm))
                for name, (law, dm) in laws.items()
            ]
        owned = V.dofmap.index_map.size_local
        for name, form in self._law_checks:
            b = dolfinx.fem.petsc.assemble_vector(form)
            b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
            bad = np.flatnonzero(b.array[parent_of[:owned]] > 0)
            b.destroy()
            point = V.tabulate_dof_coordinates()[bad[0]] if bad.size else None
            found = [x for x in self.comm.allgather(point) if x is not None]
            if found:
                where = ", ".join(f"{c:.4g}" for c in found[0])
                return f"{name} is negative or not a number near x = ({where})"
        return None

    def nodal(self, field: str, component: int | None = None) -> tuple[Matrix, Vector]:
        """Coordinates [m] and values of one field (or component) at this rank's owned nodes."""
        V, parent_of = self.forms.collapsed(field, component)
        if V.dofmap.index_map_bs > 1:
            raise ValueError(f"nodal('{field}'): give the component of a vector field")
        owned = V.dofmap.index_map.size_local
        return V.tabulate_dof_coordinates()[:owned], self.U.x.array[parent_of[:owned]]
