"""The nonlinear coupled system: every body and master layer, its residual and Jacobian blocks.

Unknowns: each body's fields ``U^α`` and each interface's master fields ``U_m,k`` (one
*channel* per scalar master field: T, φ, and the displacement components that carry a law).
Residual and Jacobian blocks come from the UFL forms of :mod:`multiphysics` by
``ufl.derivative``, contact-law derivatives included:

    A^α   = ∂F^α/∂U^α        B^α_k = ∂F^α/∂U_m,k
    C^α_k = ∂r^α_k/∂U^α      D^α_k = ∂r^α_k/∂U_m,k

with ``F^α`` the body residual and ``r^α_k`` its share of the master residual of Γ_k. The
master equations are ``Σ_α r^α_k = 0`` (paper eq. 3). ``B``, ``C``, ``D`` are kept as matrices
of the body's space; the slave maps ``P_k`` move values between them and master vectors.

Global vectors (for SNES) hold, on each rank, the owned DOFs of every body in scene order, then
on rank 0 every master value. Master vectors are replicated on every rank, as in
:mod:`interfaces`.
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

from subdomain_contact.geometry import gather_rows, match_points
from subdomain_contact.interfaces import MasterLayer, SlaveMap, master_layer
from subdomain_contact.multiphysics import FIELDS, BodyPhysics, CoupledProblem, body_physics
from subdomain_contact.solvers import DIRECT, Reaper, destroy, make_ksp

__all__ = ["Channel", "CoupledBody", "CoupledSystem"]

Channel = tuple[str, int | None]  # (field, displacement component or None)


class CoupledBody:
    """One body's forms, Jacobian blocks, factorised ``A`` and slave maps.

    Args:
        physics: The body's fields and forms.
        layers: Master layer of each interface the body touches.
        channels: Interface name -> its master channels.
        facet_tags: Facet tags of the body mesh.
    """

    def __init__(
        self,
        physics: BodyPhysics,
        layers: dict[str, MasterLayer],
        channels: dict[str, list[Channel]],
        facet_tags: dolfinx.mesh.MeshTags,
    ) -> None:
        self.physics, self.name, self.U = physics, physics.name, physics.U
        W = physics.W
        self.comm: MPI.Comm = W.mesh.comm
        index_map, bs = W.dofmap.index_map, W.dofmap.index_map_bs
        self.size = index_map.size_local * bs
        self.start = index_map.local_range[0] * bs
        self.slaves = {
            k: _slave_map(physics, layers[k], channels[k], facet_tags) for k in physics.masters
        }
        U, res = physics.U, physics.residual
        self.F = dolfinx.fem.form(res)
        self.a_A = dolfinx.fem.form(ufl.derivative(res, U))
        self.r, self.a_B, self.a_C, self.a_D = {}, {}, {}, {}
        for k, Um in physics.masters.items():
            rk = physics.master_residuals[k]
            self.r[k] = dolfinx.fem.form(rk)
            self.a_B[k] = dolfinx.fem.form(ufl.derivative(res, Um))
            self.a_C[k] = dolfinx.fem.form(ufl.derivative(rk, U))
            self.a_D[k] = dolfinx.fem.form(ufl.derivative(rk, Um))
        self.A = dolfinx.fem.petsc.create_matrix(self.a_A)
        self.B = {k: dolfinx.fem.petsc.create_matrix(a) for k, a in self.a_B.items()}
        self.C = {k: dolfinx.fem.petsc.create_matrix(a) for k, a in self.a_C.items()}
        self.D = {k: dolfinx.fem.petsc.create_matrix(a) for k, a in self.a_D.items()}
        self.ksp = make_ksp(self.A, f"sc_coupled_{self.name}_", DIRECT, setup=False)
        self._ticket = Reaper.register(self.ksp)
        fixed = [bc.dof_indices() for bc in physics.bcs]
        self.fixed = np.unique(np.concatenate([d[:n] for d, n in fixed] or [np.zeros(0)]))
        self.fixed = self.fixed.astype(np.int32)
        self.vectors = [self.A.createVecRight() for _ in range(4)]

    def __del__(self) -> None:
        """Destroy the PETSc objects now; the factorisation is left to :class:`Reaper`."""
        if "vectors" not in self.__dict__:
            return
        Reaper.release(self._ticket)
        destroy(self.A, *self.B.values(), *self.C.values(), *self.D.values(), *self.vectors)

    def assemble(self) -> None:
        """Assemble the Jacobian blocks at the current state."""
        bcs = self.physics.bcs
        self.A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.A, self.a_A, bcs=bcs)
        self.A.assemble()
        rows = (self.start + self.fixed).astype(PETSc.IntType)
        for mats, forms in [(self.B, self.a_B), (self.C, self.a_C), (self.D, self.a_D)]:
            for k, M in mats.items():
                M.zeroEntries()
                dolfinx.fem.petsc.assemble_matrix(M, forms[k])
                M.assemble()
        for B in self.B.values():  # the rows of fixed DOFs are their conditions alone
            B.zeroRows(rows, diag=0.0)

    def factorise(self) -> None:
        """Factorise the assembled ``A`` (for :meth:`solve`)."""
        self.ksp.setOperators(self.A)
        self.ksp.setUp()

    def residual(self) -> npt.NDArray[np.float64]:
        """Owned body residual at the current state; rows of fixed DOFs hold U − g."""
        b = dolfinx.fem.petsc.assemble_vector(self.F)
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(b, self.physics.bcs, x0=self.U.x.petsc_vec, alpha=-1.0)
        values = b.array.copy()
        b.destroy()
        return values

    def master_residual(self, k: str, size: int) -> npt.NDArray[np.float64]:
        """This body's share ``r^α_k`` of the master residual, replicated."""
        b = dolfinx.fem.petsc.assemble_vector(self.r[k])
        b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
        values = self.slaves[k].gather(b.array, size, self.comm)
        b.destroy()
        return values

    def nodal(
        self, field: str, component: int | None = None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Coordinates [m] and values of one field (or component) at this rank's owned nodes."""
        V, parent_of = self.physics.collapsed(field, component)
        owned = V.dofmap.index_map.size_local
        points = V.tabulate_dof_coordinates()[:owned]
        if V.dofmap.index_map_bs > 1:
            raise ValueError(f"nodal('{field}'): give the component of a vector field")
        return points, self.U.x.array[parent_of[:owned]]

    def contact_integral(self, k: str, quantity: str) -> float:
        """``∫_Γk q ds`` of a half-link quantity over the interface (collective).

        ``quantity``: ``"pressure"`` [Pa], ``"current density"`` [A/m^2] or ``"heat flux"``
        [W/m^2] (see :class:`BodyPhysics`); the integral is in that unit times m^(d-1).
        """
        physics = self.physics
        form = dolfinx.fem.form(physics.contact[k][quantity] * physics.ds(physics.tags[k]))
        local = dolfinx.fem.assemble_scalar(form)
        return self.comm.allreduce(local, op=MPI.SUM)

    def set_masters(self, masters: dict[str, npt.NDArray[np.float64]]) -> None:
        """Write replicated master vectors into the body's master Functions."""
        for k, Um in self.physics.masters.items():
            Um.x.array[:] = 0.0
            self.slaves[k].scatter(masters[k], Um.x.array)
            Um.x.scatter_forward()

    def solve(self, rhs: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``A⁻¹ rhs`` on owned DOFs."""
        b, x = self.vectors[0], self.vectors[1]
        b.array[:] = rhs
        self.ksp.solve(b, x)
        if self.ksp.getConvergedReason() < 0:
            raise RuntimeError(f"body '{self.name}': linear solve failed")
        return x.array.copy()

    def couple(self, masters: dict[str, np.ndarray]) -> npt.NDArray[np.float64]:
        """``Σ_k B_k P_k m_k`` on owned DOFs, over the interfaces of ``masters`` it touches."""
        out = np.zeros(self.size)
        s, y = self.vectors[2], self.vectors[3]
        # in the order of ``masters`` on every rank: a set's order follows the string hashes,
        # which differ between processes, and the products are collective
        for k in (k for k in masters if k in self.B):
            s.array[:] = 0.0
            self.slaves[k].scatter(masters[k], s.array)
            self.B[k].mult(s, y)
            out += y.array
        return out

    def apply_C(self, k: str, x: npt.NDArray[np.float64], size: int) -> np.ndarray:
        """``P_kᵀ C_k x``, replicated."""
        s, y = self.vectors[2], self.vectors[3]
        s.array[:] = x
        self.C[k].mult(s, y)
        return self.slaves[k].gather(y.array, size, self.comm)

    def apply_D(self, k: str, m: npt.NDArray[np.float64]) -> np.ndarray:
        """``P_kᵀ D_k P_k m``, replicated."""
        s, y = self.vectors[2], self.vectors[3]
        s.array[:] = 0.0
        self.slaves[k].scatter(m, s.array)
        self.D[k].mult(s, y)
        return self.slaves[k].gather(y.array, len(m), self.comm)


def _slave_map(
    physics: BodyPhysics,
    layer: MasterLayer,
    channels: list[Channel],
    tags: dolfinx.mesh.MeshTags,
) -> SlaveMap:
    """Slave DOFs of every channel of one interface, matched to the master nodes."""
    fdim = physics.W.mesh.topology.dim - 1
    n_owned = physics.W.dofmap.index_map.size_local * physics.W.dofmap.index_map_bs
    local, index, gathered = [], [], []
    for c, (field, component) in enumerate(channels):
        V, parent_of = physics.collapsed(field, component)
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, tags.find(layer.interface.tag))
        dofs = dofs[dofs < V.dofmap.index_map.size_local]
        parent = parent_of[dofs]
        if np.any(parent >= n_owned):
            raise RuntimeError(f"body '{physics.name}': owned sub-space DOF not owned in W")
        points = gather_rows(physics.W.mesh.comm, V.tabulate_dof_coordinates()[dofs])
        what = f"interface '{layer.interface.name}' ({field} DOFs of '{physics.name}')"
        matched = match_points(layer.coordinates, points, what=what) + c * layer.size
        start = physics.W.mesh.comm.exscan(len(dofs)) or 0
        local.append(parent.astype(np.int32))
        index.append(matched[start : start + len(dofs)])
        gathered.append(matched)
    return SlaveMap(np.concatenate(local), np.concatenate(index), np.concatenate(gathered))


def channels_of(problem: CoupledProblem, k: str, layer: MasterLayer) -> list[Channel]:
    """Master channels of interface ``k``: T, φ, and u_n alone (free) or every u_i (stuck).

    Raises:
        ValueError: Free sliding on an interface that is not a plane normal to an axis.
    """
    channels: list[Channel] = []
    for field in problem.fields:
        if field != "displacement":
            channels.append((field, None))
            continue
        dim = problem.scene.bodies[layer.interface.bodies[0]].mesh.geometry.dim
        if problem.contacts[k].tangential == "stuck":
            channels += [("displacement", c) for c in range(dim)]
            continue
        spread = np.ptp(layer.coordinates[:, :dim], axis=0)
        flat = np.flatnonzero(spread <= 1e-10 * max(spread.max(), 1e-300))
        if len(flat) != 1:
            raise ValueError(
                f"interface '{k}': free sliding needs a flat contact normal to x, y or z "
                f"(coordinate spread {spread}); use tangential='stuck' or split the contact"
            )
        channels.append(("displacement", int(flat[0])))
    return channels


class CoupledSystem:
    """Every body and master layer of a :class:`CoupledProblem`, as one nonlinear system.

    Args:
        problem: The problem.

    Raises:
        ValueError: The scene was loaded with ``placement="groups"`` (not supported here yet).
    """

    def __init__(self, problem: CoupledProblem) -> None:
        scene = problem.scene
        if not scene.shared:
            raise ValueError(
                f"{scene.source}: the coupled Newton solver needs placement='shared' "
                "(every body spread over all ranks)"
            )
        self.problem, self.comm = problem, scene.comm
        self.layers = {k: master_layer(i) for k, i in scene.interfaces.items()}
        self.channels = {k: channels_of(problem, k, layer) for k, layer in self.layers.items()}
        self.sizes = {k: len(self.channels[k]) * self.layers[k].size for k in self.layers}
        self.bodies = {}
        for name, body in scene.bodies.items():
            physics = body_physics(problem, body)
            layers = {k: self.layers[k] for k in physics.masters}
            channels = {k: self.channels[k] for k in physics.masters}
            self.bodies[name] = CoupledBody(physics, layers, channels, body.facet_tags)
        self.masters = {k: np.zeros(n) for k, n in self.sizes.items()}
        offsets = np.cumsum([0] + [b.size for b in self.bodies.values()])
        self.slices = {
            name: slice(int(a), int(b))
            for name, a, b in zip(self.bodies, offsets[:-1], offsets[1:], strict=True)
        }
        master_total = sum(self.sizes.values()) if self.comm.rank == 0 else 0
        self.local_size = int(offsets[-1]) + master_total
        self.master_slice = slice(int(offsets[-1]), self.local_size)
        self.master_fields = {
            k: np.repeat([FIELDS.index(f) for f, _ in self.channels[k]], self.layers[k].size)
            for k in self.sizes
        }
        self.field_of = self._field_index()

    def bodies_on(self, k: str) -> list[CoupledBody]:
        """The bodies that touch interface ``k``."""
        return [b for b in self.bodies.values() if k in b.slaves]

    def num_dofs(self) -> dict[str, int]:
        """Global number of DOFs per body, and of master DOFs (``"masters"``); collective."""
        counts = {n: self.comm.allreduce(b.size, op=MPI.SUM) for n, b in self.bodies.items()}
        counts["masters"] = sum(self.sizes.values())
        return counts

    def create_vector(self) -> PETSc.Vec:
        """A global vector with this system's layout."""
        vec = PETSc.Vec().createMPI((self.local_size, PETSc.DETERMINE), comm=self.comm)
        vec.setUp()
        return vec

    def split_masters(self, flat: npt.NDArray[np.float64]) -> dict[str, np.ndarray]:
        """Replicated master vectors from rank 0's master part of a global vector."""
        flat = self.comm.bcast(np.asarray(flat) if self.comm.rank == 0 else None, root=0)
        ends = np.cumsum(list(self.sizes.values()))
        return dict(zip(self.sizes, np.split(flat, ends[:-1]), strict=True))

    def join_masters(self, masters: dict[str, np.ndarray]) -> np.ndarray:
        """Rank 0's master part of a global vector (empty on other ranks)."""
        if self.comm.rank != 0:
            return np.zeros(0)
        return np.concatenate([masters[k] for k in self.sizes]) if self.sizes else np.zeros(0)

    def reset(self, initial: Mapping[str, float] | None = None) -> None:
        """Set every body and master value to a uniform initial guess (zero by default).

        Args:
            initial: Field name -> uniform value (e.g. ``{"temperature": 300.0}``).
        """
        initial = dict(initial or {})
        for body in self.bodies.values():
            body.U.x.array[:] = 0.0
            for field, value in initial.items():
                dofs = body.physics.collapsed(field)[1]
                body.U.x.array[dofs] = value
        self.masters = {}
        for k in self.sizes:
            values = [initial.get(f, 0.0) for f, _ in self.channels[k]]
            self.masters[k] = np.repeat(values, self.layers[k].size).astype(float)
        for body in self.bodies.values():
            body.set_masters(self.masters)

    def state(self) -> PETSc.Vec:
        """The current state as a new global vector."""
        x = self.create_vector()
        self.get_state(x)
        return x

    def difference(self, a: PETSc.Vec, b: PETSc.Vec) -> dict[str, float]:
        """Per field, ``max |a − b| / max |b|`` over every body and master value (collective)."""
        out = {}
        for field in self.problem.fields:
            mask = self.field_of == FIELDS.index(field)
            local = np.abs(a.array_r - b.array_r)[mask].max(initial=0.0)
            diff = self.comm.allreduce(local, op=MPI.MAX)
            scale = self.comm.allreduce(np.abs(b.array_r)[mask].max(initial=0.0), op=MPI.MAX)
            out[field] = float(diff / scale) if scale > 0 else float(diff)
        return out

    def apply_conditions(self) -> None:
        """Set every body's fixed DOFs to their prescribed values."""
        for body in self.bodies.values():
            for bc in body.physics.bcs:
                bc.set(body.U.x.array)
            body.U.x.scatter_forward()

    def get_state(self, x: PETSc.Vec) -> None:
        """Copy the current state into global vector ``x``."""
        for name, body in self.bodies.items():
            x.array[self.slices[name]] = body.U.x.array[: body.size]
        x.array[self.master_slice] = self.join_masters(self.masters)

    def set_state(self, x: PETSc.Vec) -> None:
        """Take the state from global vector ``x``."""
        array = x.array_r
        for name, body in self.bodies.items():
            body.U.x.array[: body.size] = array[self.slices[name]]
            body.U.x.scatter_forward()
        self.masters = self.split_masters(array[self.master_slice])
        for body in self.bodies.values():
            body.set_masters(self.masters)

    def residual(self, f: PETSc.Vec) -> None:
        """Residual of every body and master equation at the current state, into ``f``."""
        out = f.array
        for name, body in self.bodies.items():
            out[self.slices[name]] = body.residual()
        masters = {
            k: sum(b.master_residual(k, n) for b in self.bodies_on(k))
            for k, n in self.sizes.items()
        }
        out[self.master_slice] = self.join_masters(masters)

    def assemble_jacobian(self) -> None:
        """Assemble every body's Jacobian blocks at the current state."""
        for body in self.bodies.values():
            body.assemble()

    def mult(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """``y = J x`` with the assembled blocks."""
        array, out = x.array_r, y.array
        masters = self.split_masters(array[self.master_slice])
        result = {k: np.zeros(n) for k, n in self.sizes.items()}
        for name, body in self.bodies.items():
            xb = array[self.slices[name]]
            s, t = body.vectors[0], body.vectors[1]
            s.array[:] = xb
            body.A.mult(s, t)
            out[self.slices[name]] = t.array + body.couple(masters)
            for k in body.slaves:
                result[k] += body.apply_C(k, xb, self.sizes[k]) + body.apply_D(k, masters[k])
        out[self.master_slice] = self.join_masters(result)

    def _field_index(self) -> npt.NDArray[np.int32]:
        """Index in :data:`FIELDS` of the field of every local entry of a global vector."""
        index = np.zeros(self.local_size, dtype=np.int32)
        for name, body in self.bodies.items():
            part = np.zeros(body.size, dtype=np.int32)
            for field in self.problem.fields:
                dofs = body.physics.collapsed(field)[1]
                part[dofs[dofs < body.size]] = FIELDS.index(field)
            index[self.slices[name]] = part
        index[self.master_slice] = self.join_masters(self.master_fields)
        return index

    def field_norms(self, f: PETSc.Vec) -> dict[str, float]:
        """2-norm of each field's part of global vector ``f`` (collective)."""
        squares = np.array(
            [np.sum(f.array_r[self.field_of == FIELDS.index(n)] ** 2) for n in self.problem.fields]
        )
        totals = self.comm.allreduce(squares, op=MPI.SUM)
        return {n: float(np.sqrt(s)) for n, s in zip(self.problem.fields, totals, strict=True)}
