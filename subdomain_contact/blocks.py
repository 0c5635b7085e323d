"""One body's slave/master blocks, assembled from its dolfinx forms, and its solves.

For body α with half-links of coefficient h̄_k on its interfaces k (METHOD.md §2):

    (K^S + Σ_k h̄_k M_k) U = F + Σ_k h̄_k M_k P_k U_m,k

where ``P_k`` puts master values on the slave DOFs of interface k. The matrix does not depend
on the master values: it is factorised once. The master residual of interface k is computed
from the solid's own reaction on its slave DOFs (the numerically stable form of METHOD.md §4):

    r_k = P_kᵀ (K^S U − F + Σ_{j≠k} h̄_j M_j (U − P_j U_m,j))
"""

from __future__ import annotations

from collections.abc import Mapping

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.interfaces import MasterLayer, slave_map
from subdomain_contact.schur import CondensedFactor
from subdomain_contact.solvers import DIRECT, Reaper, destroy, make_ksp
from subdomain_contact.thermal import BodyForms

__all__ = ["BodyBlocks"]

MasterValues = Mapping[str, npt.NDArray[np.float64]]
Matrix = npt.NDArray[np.float64]


class BodyBlocks:
    """Assembled blocks of one body, its factorised matrix, and its slave maps.

    Args:
        name: Body name (used in PETSc option prefixes and messages).
        forms: The body's forms.
        facet_tags: Facet tags of the body mesh.
        layers: Master layer of each interface the body touches.
        half_links: Interface name -> h̄ = 2h [W/(m^2 K)].
        factorise: Factorise the body matrix now (not needed when the blocks only feed the
            monolithic solve).
        condense: For a body held by one rank, factorise the solid alone with its slave DOFs
            left as a dense Schur block (:class:`CondensedFactor`), which gives the condensed
            stiffness K̂ of every interface at the cost of that one factorisation; the
            half-links are then added to the dense block. Elsewhere K̂ costs one solve per
            slave DOF.
    """

    def __init__(
        self,
        name: str,
        forms: BodyForms,
        facet_tags: dolfinx.mesh.MeshTags,
        layers: Mapping[str, MasterLayer],
        half_links: Mapping[str, float],
        *,
        factorise: bool = True,
        condense: bool = False,
    ) -> None:
        self.name, self.forms, self.V = name, forms, forms.V
        self.comm: MPI.Comm = self.V.mesh.comm
        self.layers = dict(layers)
        self.half_links = {k: float(half_links[k]) for k in layers}
        self.slaves = {k: slave_map(layer, self.V, facet_tags) for k, layer in layers.items()}
        self.a_body = dolfinx.fem.form(self._solid_plus_links(list(layers)))
        self.K_free = _assemble(dolfinx.fem.form(forms.solid), [])
        load = dolfinx.fem.form(forms.load)
        self.F_free = dolfinx.fem.petsc.assemble_vector(load)
        self.F_free.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        self.b0 = dolfinx.fem.petsc.assemble_vector(load)
        dolfinx.fem.petsc.apply_lifting(self.b0, [self.a_body], bcs=[forms.bcs])
        self.b0.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(self.b0, forms.bcs)
        mass = {k: dolfinx.fem.form(forms.contact_mass[k]) for k in layers}
        self.M_free = {k: _assemble(mass[k], []) for k in layers}
        # The coupling to the masters, with the rows of fixed DOFs removed (their equation is
        # the condition); a fixed slave keeps its master coupling in the residual (link form).
        fixed = self._fixed_dofs()
        start = self.V.dofmap.index_map.local_range[0]
        self.M_rows = {}
        for k in layers:
            self.M_rows[k] = self.M_free[k].copy()
            self.M_rows[k].zeroRows((start + fixed).astype(PETSc.IntType), diag=0.0)
        self._fixed_slaves = {
            k: np.flatnonzero(np.isin(self.slaves[k].local_dofs, fixed)) for k in layers
        }
        stiffness = self.K_free.norm(PETSc.NormType.INFINITY)
        self._soft = {
            k: self.half_links[k] * self.M_free[k].norm(PETSc.NormType.INFINITY) < stiffness
            for k in layers
        }
        # the link form is needed for soft links, for fixed slaves, and where contacts meet
        self._link_used = {
            k: self._soft[k]
            or len(layers) > 1
            or self.comm.allreduce(self._fixed_slaves[k].size, op=MPI.SUM) > 0
            for k in layers
        }
        self.T = dolfinx.fem.Function(self.V, name="temperature [K]")
        self._rhs, self._tmp, self._slave, self._reaction, self._gap = (
            self.K_free.createVecLeft() for _ in range(5)
        )
        self._links = {k: self.K_free.createVecLeft() for k in layers}
        self.factor: CondensedFactor | None = None
        self.ksp: PETSc.KSP | None = None
        self._A: PETSc.Mat | None = None
        prefix = f"sc_body_{name}_"
        if factorise and condense and self.comm.size == 1 and layers:
            self.kept = np.unique(np.concatenate([m.local_dofs for m in self.slaves.values()]))
            self._kept_links = self._links_on_kept()
            H = np.zeros((len(self.kept),) * 2)
            for at, link in self._kept_links.values():
                H[np.ix_(at, at)] += link
            K = self.K_free.copy()  # the solid with its temperature conditions, as assembled
            K.zeroRowsColumns(self._fixed_dofs().astype(PETSc.IntType), diag=1.0)
            self.factor = CondensedFactor(K, self.kept, H, prefix)
            K.destroy()
        else:
            self.ksp = make_ksp(self.A, prefix, DIRECT, setup=factorise)
            self._ticket = Reaper.register(self.ksp)

    def __del__(self) -> None:
        """Destroy the PETSc objects now; the factorisation is left to :class:`Reaper`.

        Left to the garbage collector, parallel PETSc objects wait on a garbage list and hold
        MPI communicators: a long sweep then runs out of communicators.
        """
        if "_A" not in self.__dict__:  # __init__ failed: petsc4py's own garbage handles it
            return
        if self.ksp is not None:
            Reaper.release(self._ticket)
        destroy(
            self._A, self.K_free, self.F_free, self.b0, *self.M_rows.values(),
            *self.M_free.values(), self._rhs, self._tmp, self._slave, self._reaction,
            self._gap, *self._links.values(),
        )  # fmt: skip

    @property
    def A(self) -> PETSc.Mat:
        """``K^S + Σ_k h̄_k M_k`` with the temperature conditions (assembled at first use)."""
        if self._A is None:
            self._A = _assemble(self.a_body, self.forms.bcs)
        return self._A

    def _solid_plus_links(self, interfaces: list[str]) -> ufl.Form:
        """The solid's form plus the half-links of ``interfaces``."""
        form = self.forms.solid
        for k in interfaces:
            form = form + self.half_links[k] * self.forms.contact_mass[k]
        return form

    def _fixed_dofs(self) -> npt.NDArray[np.int32]:
        """Owned DOFs fixed by temperature conditions (local indices)."""
        size = self.V.dofmap.index_map.size_local
        fixed = [bc.dof_indices()[0] for bc in self.forms.bcs]
        every = np.unique(np.concatenate(fixed)) if fixed else np.zeros(0, np.int32)
        return every[every < size].astype(np.int32)

    # -- solves ---------------------------------------------------------------------------
    def _on_slaves(self, k: str, master: npt.NDArray[np.float64]) -> PETSc.Vec:
        """``P_k U_m,k``: master values on the slave DOFs of interface k, zero elsewhere."""
        self._slave.zeroEntries()
        self.slaves[k].scatter(master, self._slave.array)
        return self._slave

    def solve(
        self,
        master: MasterValues,
        *,
        homogeneous: bool = False,
        loads: MasterValues | None = None,
    ) -> dolfinx.fem.Function:
        """Temperature [K] of the body for given master values [K] of its interfaces.

        ``homogeneous``: without the body's own loads and conditions, so that the residuals
        that follow are the interface stiffness applied to ``master`` (``S^α U_m``).
        ``loads``: interface name -> nodal heat [W] put into the body at its slave DOFs, in
        master order (a Neumann datum of a partitioned coupling); none at fixed DOFs.
        """
        b = self._rhs
        if homogeneous:
            b.zeroEntries()
        else:
            self.b0.copy(b)
        for k, hbar in self.half_links.items():
            self.M_rows[k].mult(self._on_slaves(k, master[k]), self._tmp)
            b.axpy(hbar, self._tmp)
        for k, load in (loads or {}).items():
            nodal = self._on_slaves(k, load)
            nodal.array[self.slaves[k].local_dofs[self._fixed_slaves[k]]] = 0.0
            b.axpy(1.0, nodal)
        if self.factor is not None:
            self.factor.solve(b, self.T.x.petsc_vec)
        else:
            self.ksp.solve(b, self.T.x.petsc_vec)
            if self.ksp.getConvergedReason() < 0:
                reason = self.ksp.getConvergedReason()
                raise RuntimeError(f"body '{self.name}': linear solve failed (reason {reason})")
        self.T.x.scatter_forward()
        return self.T

    def solid_reaction(self, *, homogeneous: bool = False) -> PETSc.Vec:
        """``K^S U − F`` [W] of the last solve: fluxes the solid takes from supports and links."""
        self.K_free.mult(self.T.x.petsc_vec, self._reaction)
        if not homogeneous:
            self._reaction.axpy(-1.0, self.F_free)
        return self._reaction

    def residuals(
        self, master: MasterValues, *, homogeneous: bool = False
    ) -> dict[str, npt.NDArray[np.float64]]:
        """Master residual r_k [W] of each interface, replicated, from the last solve.

        Two equal forms, each exact where the other loses digits: for a stiff link
        (h̄M larger than the solid's stiffness) the solid's reaction on the slaves; for a soft
        link ``−h̄_k M_k (U − P_k U_m,k)``, whose round-off scales with h̄ instead of k.
        """
        for k, hbar in self.half_links.items():
            if not self._link_used[k]:
                continue
            self.T.x.petsc_vec.copy(self._gap)
            self._gap.axpy(-1.0, self._on_slaves(k, master[k]))
            self.M_free[k].mult(self._gap, self._links[k])
            self._links[k].scale(hbar)
        reaction = self.solid_reaction(homogeneous=homogeneous)
        result = {}
        for k, layer in self.layers.items():
            if self._soft[k]:
                r = -self._links[k].array
            else:  # other half-links count where two contacts share slave DOFs
                r = reaction.array.copy()
                for j, link in self._links.items():
                    if j != k:
                        r += link.array
                # a fixed slave's reaction includes its support's: take its link there
                fixed = self.slaves[k].local_dofs[self._fixed_slaves[k]]
                r[fixed] = -self._links[k].array[fixed]
            result[k] = self.slaves[k].gather(r, layer.size, self.comm)
        return result

    # -- condensed operators (dense, master order, replicated) ----------------------------
    def apply_stiffness(self, master: MasterValues) -> dict[str, npt.NDArray[np.float64]]:
        """``S^α U_m`` [W]: the body's interface stiffness applied by one homogeneous solve."""
        self.solve(master, homogeneous=True)
        return self.residuals(master, homogeneous=True)

    def stiffness(self) -> npt.NDArray[np.float64]:
        """Dense ``S^α`` [W/K] over all the body's masters (interfaces in ``layers`` order).

        One homogeneous solve per master DOF, each residual in its stable form.
        """
        sizes = [layer.size for layer in self.layers.values()]
        S = np.zeros((sum(sizes), sum(sizes)))
        unit = np.zeros(sum(sizes))
        for column in range(sum(sizes)):
            unit[:] = 0.0
            unit[column] = 1.0
            parts = np.split(unit, np.cumsum(sizes)[:-1])
            response = self.apply_stiffness(dict(zip(self.layers, parts, strict=True)))
            S[:, column] = np.concatenate([response[k] for k in self.layers])
        return 0.5 * (S + S.T)

    def mass(self, k: str) -> npt.NDArray[np.float64]:
        """Interface mass matrix M of interface k [m^(d-1)], dense, in master order."""
        slaves = self._slave_is(k)
        block = self.M_free[k].createSubMatrix(slaves, slaves)
        result = self._gather_dense(block, k)
        destroy(slaves, block)
        return result

    def condensed_stiffness(self, k: str) -> npt.NDArray[np.float64]:
        """``K̂_ee = K_ee − K_ei K_ii⁻¹ K_ie`` [W/K] of interface k, dense, in master order.

        The solid condensed on the slaves of k, contact term of k excluded, other interfaces'
        half-links included (METHOD.md §3). From the Schur block of the factorisation where
        there is one, else by one solve per slave DOF (:meth:`condensed`).
        """
        if self.factor is None:
            K_ee, coupling = self.condensed(k)
            return self.clamp_fixed(k, K_ee - coupling)
        block = self.factor.sigma.copy()
        for j, (at, H) in self._kept_links.items():
            if j != k:
                block[np.ix_(at, at)] += H
        at = self._kept_links[k][0]
        other = np.setdiff1d(np.arange(len(self.kept)), at)
        K_hat = block[np.ix_(at, at)]
        if other.size:
            K_hat = K_hat - block[np.ix_(at, other)] @ np.linalg.solve(
                block[np.ix_(other, other)], block[np.ix_(other, at)]
            )
        return self.clamp_fixed(k, self._to_master_order(K_hat, k))

    def condensed(
        self, k: str, interior: npt.NDArray[np.int32] | None = None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """The solid's slave blocks on interface k: ``K_ee`` and ``K_ei K_ii⁻¹ K_ie`` [W/K].

        Contact term of k excluded, other interfaces' half-links included (METHOD.md §3), so
        ``K̂_ee = K_ee − K_ei K_ii⁻¹ K_ie``. Both are dense, in master order; one solve per
        slave DOF. Fixed slaves keep their unit rows (see :meth:`clamp_fixed`).

        Args:
            k: Interface.
            interior: Owned local DOFs to condense (default: every DOF not a slave of k);
                the others are clamped.
        """
        B = _assemble(
            dolfinx.fem.form(self._solid_plus_links([j for j in self.layers if j != k])),
            self.forms.bcs,
        )
        slaves = self.slaves[k].local_dofs
        if interior is None:
            owned = np.arange(self.V.dofmap.index_map.size_local, dtype=np.int32)
            interior = np.setdiff1d(owned, slaves).astype(np.int32)
        e, i = self._slave_is(k), self._is(interior)
        K_ee, K_ie_sparse, K_ii = (B.createSubMatrix(*p) for p in [(e, e), (i, e), (i, i)])
        K_ie = K_ie_sparse.convert("dense", out=PETSc.Mat())
        ksp = make_ksp(K_ii, f"sc_body_{self.name}_condense_", DIRECT)
        X = K_ie.duplicate()
        ksp.getPC().getFactorMatrix().matSolve(K_ie, X)
        # K_ei X = K_ieᵀ X (B is symmetric): local rows, summed over ranks. (PETSc's
        # MPIAIJ × MPIDense product crashed here when a rank owns none of the slaves.)
        local = K_ie.getDenseArray(readonly=True).T @ X.getDenseArray(readonly=True)
        coupling = self._to_master_order(self.comm.allreduce(local, op=MPI.SUM), k)
        K_ee_dense = self._gather_dense(K_ee, k)
        destroy(B, e, i, K_ee, K_ie_sparse, K_ii, K_ie, ksp, X)
        return K_ee_dense, coupling

    def clamp_fixed(self, k: str, stiffness: Matrix) -> Matrix:
        """``stiffness`` (master order) with the fixed slaves of k made infinitely stiff.

        A slave fixed by a temperature condition is infinitely stiff, not the unit row the
        condition leaves in the matrix: its row and column are zeroed and its diagonal set
        to 1e8 times the largest one.
        """
        fixed = np.concatenate(
            self.comm.allgather(self.slaves[k].master_index[self._fixed_slaves[k]])
        )
        if fixed.size:
            stiff = 1e8 * float(np.abs(np.diag(stiffness)).max())
            stiffness = stiffness.copy()
            stiffness[fixed, :] = 0.0
            stiffness[:, fixed] = 0.0
            stiffness[fixed, fixed] = stiff
        return stiffness

    def _links_on_kept(self) -> dict[str, tuple[npt.NDArray[np.intp], Matrix]]:
        """Interface -> positions of its slaves in ``kept``, and its ``h̄_k M_k`` there.

        Rows and columns of fixed DOFs are zero, as in the assembled body matrix.
        """
        fixed = np.isin(self.kept, self._fixed_dofs())
        result = {}
        for k, hbar in self.half_links.items():
            at = np.searchsorted(self.kept, self.slaves[k].local_dofs)
            order = self.slaves[k].master_index  # slave i is master order[i]
            link = hbar * self.mass(k)[np.ix_(order, order)]
            link[fixed[at], :] = 0.0
            link[:, fixed[at]] = 0.0
            result[k] = (at, link)
        return result

    def _is(self, local: npt.NDArray[np.int32]) -> PETSc.IS:
        start = self.V.dofmap.index_map.local_range[0]
        return PETSc.IS().createGeneral((start + local).astype(PETSc.IntType), comm=self.comm)

    def _slave_is(self, k: str) -> PETSc.IS:
        return self._is(self.slaves[k].local_dofs)

    def _gather_dense(self, A: PETSc.Mat, k: str) -> npt.NDArray[np.float64]:
        """A square matrix on the slaves of k (slave numbering) as a replicated dense array."""
        dense = A.convert("dense", out=PETSc.Mat())
        rows = np.concatenate(self.comm.allgather(dense.getDenseArray(readonly=True).copy()))
        dense.destroy()
        return self._to_master_order(rows, k)

    def _to_master_order(self, matrix: npt.NDArray[np.float64], k: str) -> np.ndarray:
        """Reorder a matrix on the slaves of k from slave numbering to master numbering."""
        order = self.slaves[k].gathered_master_index
        result = np.empty_like(matrix)
        result[np.ix_(order, order)] = matrix
        return result


def _assemble(form: dolfinx.fem.Form, bcs, *, diagonal: float = 1.0) -> PETSc.Mat:
    A = dolfinx.fem.petsc.assemble_matrix(form, bcs=bcs, diag=diagonal)
    A.assemble()
    return A


def dofs_within_layers(
    V: dolfinx.fem.FunctionSpace, seeds: npt.NDArray[np.int32], layers: int
) -> npt.NDArray[np.int32]:
    """Owned DOFs of ``V`` within ``layers`` element layers of the DOFs ``seeds`` (seeds included).

    A layer is every cell that has a marked DOF; its DOFs are marked for the next layer.
    Parallel-safe: marks cross process boundaries through the index map.
    """
    marker = dolfinx.la.vector(V.dofmap.index_map, dtype=np.int32)
    marker.array[seeds] = 1
    marker.scatter_forward()
    cells = V.dofmap.list
    for _ in range(layers):
        hit = cells[marker.array[cells].max(axis=1) > 0]
        marker.array[hit.ravel()] = 1
        marker.scatter_reverse(dolfinx.la.InsertMode.add)
        marker.scatter_forward()
    owned = marker.array[: V.dofmap.index_map.size_local]
    return np.flatnonzero(owned).astype(np.int32)
