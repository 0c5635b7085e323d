"""The discrete nonlinear system of a problem: every body and master layer, state and residual.

Unknowns: each body's fields ``U^α`` and each interface's master channels ``U_m,k``. The body
residuals and the master residuals ``Σ_α r^α_k = 0`` (paper eq. 3) come from the forms of
:mod:`~subdomain_contact.physics`; the Jacobian blocks are each body's
(:class:`~subdomain_contact.body.Body`).

Global vectors (for SNES) hold, on each rank, the owned DOFs of the bodies its rank group
solves, in scene order, then on rank 0 every master value. Master vectors are replicated on
every rank. With ``placement="groups"`` a rank builds only its group's bodies, and the
master residuals are summed over the groups.
"""

from __future__ import annotations

import gc
from collections.abc import Mapping

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.body import SOLVERS, Body
from subdomain_contact.masters import MasterLayer, master_layer
from subdomain_contact.physics import FIELDS, Displacement, Problem
from subdomain_contact.solvers import sweepable

__all__ = ["LawRangeError", "System"]

Vector = npt.NDArray[np.float64]


class LawRangeError(ValueError):
    """A law is negative or NaN at a state.

    ``at_solution``: at a state Newton converged to (a spurious root, which a shorter time
    step may avoid), else at a given state.
    """

    def __init__(self, message: str, at_solution: bool) -> None:
        super().__init__(message)
        self.at_solution = at_solution


def _assign(body: Body, pairs) -> bool:
    """Give form coefficients of a body new values: ``(constant, value)`` pairs.

    A body whose bulk matrix holds a coefficient that changed is factorised again at the
    next Newton step. Returns whether any value changed.
    """
    pairs = list(pairs)
    changed = [c for c, value in pairs if float(c.value) != value]
    for c, value in pairs:
        c.value = value
    if any(c in body.matrix_constants for c in changed):
        body.bulk_changed()
    return bool(changed)


def _solver(problem: Problem, body, solver: str, prefix: str) -> str:
    """How a body is solved (:data:`~subdomain_contact.body.SOLVERS`).

    The option, else ``solver``, else the rule by the body's largest front
    (:meth:`~subdomain_contact.scene.Scene.solver_by_size`): a 3D body of T or φ and of u by
    the factorised sweep, floating or held (by FGMRES on weighed rows its single-precision splits
    reach the tolerance where a floating body's translation nears their reach:
    docs/iterative_bodies.md), any other large 3D one by AMG, the rest factorised.
    """
    options = PETSc.Options()
    if options.hasName(prefix + "solver"):
        solver = options.getString(prefix + "solver")
        if solver not in SOLVERS:
            raise ValueError(f"-{prefix}solver {solver}: give one of {', '.join(SOLVERS)}")
    if solver != "auto":
        return solver
    dim = body.mesh.geometry.dim
    per_node = sum(dim if f == "displacement" else 1 for f in problem.fields)
    return problem.scene.solver_by_size(body, per_node, sweepable(problem.fields))


def _covering_cells(V: dolfinx.fem.FunctionSpace) -> np.ndarray:
    """Owned cells of ``V``'s mesh that hold every DOF of its owned cells, each DOF's first.

    dolfinx's non-matching interpolation locates every cell's interpolation points: a P1
    node is shared by about 20 tetrahedra, and locating it in each dominated the nested
    iteration's step to a finer mesh. Each DOF's value is then taken at its own point once
    (a unit cube's P1 from 20³ to 60³ cells: 227k DOFs in 12.1 s from 227k of 1.30M cells,
    against 58.5 s, the same values to 1.1e-15; the collector bar slot from 49k to 221k DOFs
    on 2 ranks: its fine level's time outside Newton 2 s against 9 s).
    """
    local = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    dofs = V.dofmap.list[:local]
    _, first = np.unique(dofs.ravel(), return_index=True)
    return np.unique(first // dofs.shape[1]).astype(np.int32)


class System:
    """Every body of this rank's group and every master layer of a problem, with its state.

    Args:
        problem: The problem.
        prefix: Options prefix of the bodies' factorisations: ``<prefix>body_<name>_``.
        schur: Factorise a body held by one rank with its contact DOFs left as a dense Schur
            block (False: factorise every body whole, as a body on several ranks is).
        solver: How the bodies are solved: ``"direct"`` (MUMPS), ``"iterative"`` (Krylov +
            AMG, :data:`~subdomain_contact.body.ITERATIVE`), ``"split"`` (GMRES on the
            factorised sweep over (T, φ), then u, :data:`~subdomain_contact.body.FACTORISED_SWEEP`)
            or ``"auto"``: for a body meshed in 3D, split where the problem has T or φ and u
            and the body's largest front cubed over its DOFs exceeds ``scene.SWEEP_ABOVE``,
            iterative where it exceeds ``scene.FRONT_ABOVE``, direct otherwise
            (:meth:`~subdomain_contact.scene.Scene.solver_by_size`). The
            option ``-<prefix>body_<name>_solver direct|iterative|split`` wins for that body.

    Call :meth:`destroy` (collectively) when done, or use the system as a context manager.
    """

    def __init__(
        self, problem: Problem, *, prefix: str = "sc_", schur: bool = True, solver: str = "auto"
    ) -> None:
        if solver not in ("auto", *SOLVERS):
            raise ValueError(f"solver='{solver}': give 'auto' or one of {', '.join(SOLVERS)}")
        scene = problem.scene
        self.problem, self.comm, self.prefix = problem, scene.comm, prefix

        def solver_of(body) -> str:  # the same on every rank (a bad option raises on each)
            return _solver(problem, body, solver, f"{prefix}body_{body.name}_")

        scene.place(solver_of)  # a scene not yet placed: by its bodies' solvers
        solvers = {name: solver_of(body) for name, body in scene.bodies.items()}
        gc.collect()  # what earlier systems left: petsc4py hands it to PETSc's garbage,
        for name, body in scene.bodies.items():  # destroyed here, collectively on each comm
            if scene.is_local(name):
                PETSc.garbage_cleanup(body.mesh.comm)
        PETSc.garbage_cleanup(self.comm)
        self.layers: dict[str, MasterLayer] = {
            k: master_layer(problem, i) for k, i in scene.interfaces.items()
        }
        self.sizes = {k: layer.size for k, layer in self.layers.items()}
        if "displacement" in problem.fields:
            self._check_held_in_place()
        self.bodies: dict[str, Body] = {}
        failure: ValueError | None = None
        for name, body in scene.bodies.items():
            if scene.is_local(name):
                mine = {i.name: self.layers[i.name] for i in scene.interfaces_of(name)}
                try:  # bad data is refused on every rank of the body: tell the other groups
                    at = f"{prefix}body_{name}_"
                    self.bodies[name] = Body(
                        problem, body, mine, prefix=at, schur=schur, solver=solvers[name]
                    )
                except ValueError as error:
                    failure = error
                    break
        messages = [m for m in self.comm.allgather(failure and str(failure)) if m]
        if messages:
            self.destroy()
            raise failure or ValueError(messages[0])
        self.masters = {k: np.zeros(n) for k, n in self.sizes.items()}
        self.master_fields = {
            k: np.array([FIELDS.index(layer.channels[c][0]) for c in layer.field_index()])
            for k, layer in self.layers.items()
        }
        self.active = {  # an insulating contact's channel has no equation: its masters stay 0
            k: np.repeat(
                [not problem.insulating(k, f) for f, _ in layer.channels], layer.nodes
            ).astype(bool)
            for k, layer in self.layers.items()
        }
        offsets = np.cumsum([0] + [b.size for b in self.bodies.values()])
        self.slices = {
            name: slice(int(a), int(b))
            for name, a, b in zip(self.bodies, offsets[:-1], offsets[1:], strict=True)
        }
        master_total = sum(self.sizes.values()) if self.comm.rank == 0 else 0
        self.local_size = int(offsets[-1]) + master_total
        self.master_slice = slice(int(offsets[-1]), self.local_size)
        self.field_of = self._field_index()
        linear = self.comm.allreduce(all(b.is_linear for b in self.bodies.values()), op=MPI.LAND)
        self.is_linear = bool(linear)
        #: The Jacobian is symmetric: a linear problem of one field.
        self.symmetric = self.is_linear and len(problem.fields) == 1
        self.floating = self._everywhere({n: self._floats(b) for n, b in self.bodies.items()})

    def __enter__(self) -> System:
        return self

    def __exit__(self, *exc: object) -> None:
        self.destroy()

    def destroy(self) -> None:
        """Free every body's PETSc objects (collective)."""
        for body in self.bodies.values():
            body.destroy()

    def _check_held_in_place(self) -> None:
        """Refuse bodies whose displacement along an axis nothing holds, even through contacts.

        Along each axis, the bodies joined by contacts that carry that component (a freely
        sliding contact carries its normal one alone) need a Displacement condition on it
        somewhere; otherwise they may translate freely and every solver returns an arbitrary
        position. (Rotations are not checked.)
        """
        scene = self.problem.scene
        dim = next(iter(scene.bodies.values())).mesh.geometry.dim
        for component in range(dim):
            joining = [
                k
                for k, layer in self.layers.items()
                if ("displacement", component) in layer.channels
            ]
            held = {
                bc.boundary
                for bc in self.problem.conditions
                if isinstance(bc, Displacement) and bc.component == component
            }
            members = scene.unanchored(joining, held)
            if members is not None:
                raise ValueError(
                    f"{scene.source}: bodies {members} have no Displacement condition on "
                    f"component {component} ({'xyz'[component]}) and no contact carries it to "
                    "one: they may move freely along that axis (hold a point or a symmetry "
                    "plane, or make a contact stuck)"
                )

    # -- layout ---------------------------------------------------------------------------
    def _floats(self, body: Body) -> bool:
        """Whether some field of the body has no Dirichlet DOF (collective on the body)."""
        fixed = np.zeros(len(FIELDS), dtype=int)
        for f in self.problem.fields:
            dofs = body.forms.collapsed(f)[1]
            fixed[FIELDS.index(f)] = np.isin(body.fixed_local, dofs).sum()
        fixed = body.comm.allreduce(fixed, op=MPI.SUM)
        return any(fixed[FIELDS.index(f)] == 0 for f in self.problem.fields)

    def _everywhere(self, local: dict) -> dict:
        """Merge the groups' dictionaries (computed on their own bodies) on every rank."""
        scene = self.problem.scene
        if scene.shared:
            return dict(local)
        merged: dict = {}
        for part in self.comm.allgather(local if scene.group_comm.rank == 0 else {}):
            merged.update(part)
        return merged

    def everywhere(self, local: dict) -> dict:
        """Dictionaries computed by each rank group on its own bodies, merged on every rank."""
        return self._everywhere(local)

    def total(self, values: Mapping[str, Vector]) -> dict[str, Vector]:
        """Sum per-interface vectors of the local bodies over the groups (each counted once).

        Every rank passes the same keys and sizes: one ``MPI_Allreduce`` of their
        concatenation, not one pickled reduction per interface.
        """
        scene = self.problem.scene
        if scene.shared:
            return {k: np.asarray(v) for k, v in values.items()}
        arrays = {k: np.asarray(v, dtype=float) for k, v in values.items()}
        flat = np.concatenate([a.ravel() for a in arrays.values()]) if arrays else np.zeros(0)
        if scene.group_comm.rank != 0:
            flat[:] = 0.0
        summed = np.empty_like(flat)
        self.comm.Allreduce(flat, summed, op=MPI.SUM)
        ends = np.cumsum([0] + [a.size for a in arrays.values()])
        return {
            k: summed[ends[i] : ends[i + 1]].reshape(a.shape)
            for i, (k, a) in enumerate(arrays.items())
        }

    def bodies_of(self, k: str) -> list[Body]:
        """The local bodies that touch interface ``k``."""
        return [b for b in self.bodies.values() if k in b.layers]

    def num_dofs(self) -> dict[str, int]:
        """Global number of DOFs per body, and of master DOFs (``"masters"``); collective."""
        counts = self._everywhere(
            {n: b.comm.allreduce(b.size, op=MPI.SUM) for n, b in self.bodies.items()}
        )
        counts["masters"] = sum(self.sizes.values())
        return counts

    def create_vector(self) -> PETSc.Vec:
        """A global vector with this system's layout."""
        vec = PETSc.Vec().createMPI((self.local_size, PETSc.DETERMINE), comm=self.comm)
        vec.setUp()
        return vec

    def split_masters(self, flat: Vector) -> dict[str, Vector]:
        """Replicated master vectors from rank 0's master part of a global vector."""
        flat = self.comm.bcast(np.asarray(flat) if self.comm.rank == 0 else None, root=0)
        ends = np.cumsum(list(self.sizes.values()))
        return dict(zip(self.sizes, np.split(flat, ends[:-1]), strict=True))

    def join_masters(self, masters: Mapping[str, Vector]) -> Vector:
        """Rank 0's master part of a global vector (empty on other ranks)."""
        if self.comm.rank != 0 or not self.sizes:
            return np.zeros(0)
        return np.concatenate([masters[k] for k in self.sizes])

    def _field_index(self) -> npt.NDArray[np.int32]:
        """Index in :data:`FIELDS` of the field of every local entry of a global vector."""
        index = np.zeros(self.local_size, dtype=np.int32)
        for name, body in self.bodies.items():
            part = np.zeros(body.size, dtype=np.int32)
            for field in self.problem.fields:
                dofs = body.forms.collapsed(field)[1]
                part[dofs[dofs < body.size]] = FIELDS.index(field)
            index[self.slices[name]] = part
        index[self.master_slice] = self.join_masters(self.master_fields)
        return index

    # -- state ----------------------------------------------------------------------------
    def reset(self, initial: Mapping[str, float] | None = None) -> None:
        """Set every body and master value to a uniform initial guess (zero by default).

        Args:
            initial: Field name -> uniform value (e.g. ``{"temperature": 300.0}``).
        """
        initial = dict(initial or {})
        for body in self.bodies.values():
            body.U.x.array[:] = 0.0
            for field, value in initial.items():
                body.U.x.array[body.forms.collapsed(field)[1]] = value
        masters = {}
        for k, layer in self.layers.items():
            values = [initial.get(f, 0.0) for f, _ in layer.channels]
            masters[k] = np.repeat(values, layer.nodes).astype(float) * self.active[k]
        self.set_masters(masters)

    def interpolate(self, other: System) -> None:
        """Take the state of ``other``, the same problem on another mesh of the same geometry.

        Each body's fields are interpolated from ``other``'s body of the same name (dolfinx's
        non-matching interpolation), each master value is the mean of its two bodies' traces
        (where two half-links of equal stiffness balance). The initial guess of a nested
        iteration: solved on a coarse mesh from a cold start, a problem starts its fine-mesh
        Newton near the solution (collective on both systems).

        Raises:
            ValueError: ``other``'s bodies are placed on other rank groups than this
                system's (load one scene with ``placement=`` the other), or a node of
                a body lies outside ``other``'s mesh of it by more than its largest cell.
        """
        mine, theirs = self.problem.scene, other.problem.scene
        if dict(mine.owner) != dict(theirs.owner) or mine.group_roots != theirs.group_roots:
            raise ValueError(
                f"{mine.source}: interpolating from a system whose bodies lie on other rank "
                f"groups (body -> group {dict(theirs.owner)}, here {dict(mine.owner)}): load "
                "one scene with the other as its placement (load_scene(..., placement=scene))"
            )
        found, lost = {}, {}  # body -> the fine interpolation points in the coarse mesh
        for name, body in self.bodies.items():
            mesh = other.bodies[name].U.function_space.mesh
            tdim = mesh.topology.dim
            own = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
            reach = body.comm.allreduce(float(mesh.h(tdim, own).max(initial=0.0)), op=MPI.MAX)
            # every field is P1: the interpolation points of one serve all. Padded by
            # round-off first (by the largest cell, the search took 75 s at 66k DOFs, 27 times
            # as long); by that cell where nodes on a curved face fall outside its chords
            V, V0 = (
                b.forms.collapsed(self.problem.fields[0])[0] for b in (body, other.bodies[name])
            )
            cells = _covering_cells(V)
            for padding in (1e-6 * reach, reach):
                data = dolfinx.fem.create_interpolation_data(V, V0, cells, padding)
                outside = body.comm.allreduce(int((np.asarray(data.src_owner) < 0).sum()))
                if not outside:
                    break
            found[name], lost[name] = (cells, data), (outside, reach)
        for name, (count, reach) in self._everywhere(lost).items():
            if count:  # refused on every rank alike
                raise ValueError(
                    f"{mine.source}: {count} nodes of body '{name}' lie farther than "
                    f"{reach:.3g} m (its largest cell) outside the other mesh of it"
                )
        for name, body in self.bodies.items():
            source, (cells, data) = other.bodies[name], found[name]
            for field in self.problem.fields:
                V, dofs = body.forms.collapsed(field)
                V0, dofs0 = source.forms.collapsed(field)
                given, taken = dolfinx.fem.Function(V0), dolfinx.fem.Function(V)
                given.x.array[:] = source.U.x.array[dofs0]
                taken.interpolate_nonmatching(given, cells, data)
                taken.x.scatter_forward()
                body.U.x.array[dofs] = taken.x.array
        local = {k: np.zeros(n) for k, n in self.sizes.items()}
        for body in self.bodies.values():
            for k, slaves in body.slaves.items():
                local[k] += slaves.gather(body.U.x.array, self.sizes[k], body.comm)
        traces = self.total(local)
        self.set_masters({k: 0.5 * traces[k] * self.active[k] for k in self.layers})

    def set_masters(self, masters: Mapping[str, Vector]) -> None:
        """Take the master values (interface -> replicated vector; kept, not copied)."""
        self.masters = dict(masters)
        for body in self.bodies.values():
            body.set_masters(self.masters)

    def set_rates(self, rates: tuple[float, float]) -> None:
        """The time derivative's weights (r₀, r₁) [1/s] of the next step (0, 0: steady).

        A body whose bulk matrix holds a weight that changed is factorised again at the next
        Newton step, and kept while the weights stay the same (collective).
        """
        for body in self.bodies.values():
            _assign(body, zip(body.forms.rates, rates, strict=True))

    def set_time(self, time: float) -> None:
        """Data that follow a ``Schedule`` or a function ``(x, t)`` take their value at ``time``.

        A body whose bulk matrix holds one that changed (a switched convection coefficient)
        is factorised again at the next Newton step.
        """
        for body in self.bodies.values():
            pairs = [(c, schedule.at(time)) for c, schedule in body.forms.timed]
            if body.forms.time is not None:
                pairs.append((body.forms.time, time))
            if _assign(body, pairs) and body.forms.time is not None:
                for data, expression in body.forms.moving:  # Dirichlet data of (x, t)
                    data.interpolate(expression)

    def breakpoints(self) -> list[float]:
        """Every time [s] listed by a ``Schedule`` of the problem's conditions (collective)."""
        local = {t for b in self.bodies.values() for _, s in b.forms.timed for t in s.times}
        return sorted({t for part in self.comm.allgather(local) for t in part})

    def keep_previous(self) -> None:
        """The current state becomes the previous time's, and that one the time before."""
        for body in self.bodies.values():
            latest, older = body.forms.history
            older.x.array[:] = latest.x.array
            latest.x.array[:] = body.U.x.array

    def cold_residual(self, f: PETSc.Vec) -> None:
        """The residual into ``f`` at the cold state; the state is kept.

        Cold: every unknown zero but the Dirichlet values, the previous times' states too (so
        that it measures the loads, not the stored heat).
        """
        state = self.state()
        history = {n: [h.x.array.copy() for h in b.forms.history] for n, b in self.bodies.items()}
        try:
            self.reset()
            for body in self.bodies.values():
                for h in body.forms.history:
                    h.x.array[:] = 0.0
            self.apply_conditions()
            self.residual(f)
        finally:
            self.set_state(state)
            for name, body in self.bodies.items():
                for h, values in zip(body.forms.history, history[name], strict=True):
                    h.x.array[:] = values
            state.destroy()

    def apply_conditions(self) -> None:
        """Set every body's fixed DOFs to their prescribed values."""
        for body in self.bodies.values():
            body.apply_conditions()

    def state(self) -> PETSc.Vec:
        """The current state as a new global vector."""
        x = self.create_vector()
        self.get_state(x)
        return x

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
        self.set_masters(self.split_masters(array[self.master_slice]))

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

    # -- residual and Jacobian ------------------------------------------------------------
    def residual(self, f: PETSc.Vec) -> None:
        """Residual of every body and master equation at the current state, into ``f``."""
        out = f.array
        local = {k: np.zeros(n) for k, n in self.sizes.items()}
        for name, body in self.bodies.items():
            out[self.slices[name]] = body.residual()
            for k in body.layers:
                local[k] += body.master_residual(k)
        masters = self.total(local)
        out[self.master_slice] = self.join_masters(
            {k: np.where(self.active[k], r, self.masters[k]) for k, r in masters.items()}
        )

    def check_laws(self, when: str, *, at_solution: bool = False) -> None:
        """Refuse a state where a law is negative or NaN (collective), naming it and a point.

        Args:
            when: Which state, for the message (e.g. "at the initial state").
            at_solution: The state is one Newton converged to.

        Raises:
            LawRangeError: On every rank.
        """
        failing = self._everywhere({n: b.failing_law() for n, b in self.bodies.items()})
        found = [message for message in failing.values() if message is not None]
        if found:
            raise LawRangeError(
                f"{self.problem.scene.source}: {when}, {found[0]}: a conductivity or "
                "conductance must be >= 0 over the range of temperature and pressure the "
                "solution visits; check the law there, or start from a state inside its range "
                "(e.g. system.reset({'temperature': 300.0}))",
                at_solution,
            )

    def assemble_jacobian(self) -> None:
        """Every body's Jacobian blocks at the current state (the linear solver factorises)."""
        for body in self.bodies.values():
            body.assemble()

    def mult(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """``y = J x`` with the assembled blocks."""
        array, out = x.array_r, y.array
        masters = self.split_masters(array[self.master_slice])
        local = {k: np.zeros(n) for k, n in self.sizes.items()}
        for name, body in self.bodies.items():
            rows, shares = body.apply_jacobian(
                array[self.slices[name]], {k: masters[k] for k in body.layers}
            )
            out[self.slices[name]] = rows
            for k, r in shares.items():
                local[k] += r
        result = self.total(local)
        out[self.master_slice] = self.join_masters(
            {k: np.where(self.active[k], r, masters[k]) for k, r in result.items()}
        )

    def field_norms(self, f: PETSc.Vec) -> dict[str, float]:
        """2-norm of each field's part of global vector ``f`` (collective)."""
        squares = self._by_field(f, lambda part: np.sum(part**2), MPI.SUM)
        return {n: float(np.sqrt(v)) for n, v in squares.items()}

    def field_sums(self, f: PETSc.Vec) -> dict[str, float]:
        """1-norm of each field's part of global vector ``f`` (collective)."""
        return self._by_field(f, lambda part: np.abs(part).sum(), MPI.SUM)

    def field_max_norms(self, f: PETSc.Vec) -> dict[str, float]:
        """∞-norm of each field's part of global vector ``f`` (collective)."""
        return self._by_field(f, lambda part: np.abs(part).max(initial=0.0), MPI.MAX)

    def _by_field(self, f: PETSc.Vec, local, op: MPI.Op) -> dict[str, float]:
        """``local`` of each field's owned part of ``f``, reduced over the ranks by ``op``."""
        values = np.array(
            [local(f.array_r[self.field_of == FIELDS.index(n)]) for n in self.problem.fields]
        )
        totals = np.empty_like(values)  # the buffer form: MPI.MAX on pickled arrays is ambiguous
        self.comm.Allreduce(values, totals, op=op)
        return {n: float(v) for n, v in zip(self.problem.fields, totals, strict=True)}

    def master_field_norms(self, masters: Mapping[str, Vector]) -> dict[str, float]:
        """2-norm of each field's part of replicated master vectors (active DOFs)."""
        norms = dict.fromkeys(self.problem.fields, 0.0)
        for k, r in masters.items():
            for f in self.problem.fields:
                mask = (self.master_fields[k] == FIELDS.index(f)) & self.active[k]
                norms[f] += float(np.sum(r[mask] ** 2))
        return {f: float(np.sqrt(v)) for f, v in norms.items()}
