"""The interface problem as a whole: CG with per-interface correctors and a coarse space."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
from helpers import (
    interface_operator,
    linear_solve,
    monolithic,
    preconditioned_condition,
    release,
    snapshot,
)
from mpi4py import MPI
from petsc4py import PETSc

import subdomain_contact as sc
from subdomain_contact import correctors, solvers
from subdomain_contact.correctors import dofs_within_layers
from subdomain_contact.merged import merged_matrix
from subdomain_contact.scene import gather_rows, match_points
from subdomain_contact.solvers import destroy
from verification.cases import (
    GEO,
    bars_scene,
    blocks3d_scene,
    heated_blocks,
    squeezed_joule_bars,
    stack,
    stack_scene,
    two_plates,
    two_plates_scene,
)
from verification.nodal import field_values, relative_nodal_error

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def chain(comm):
    return stack_scene(8, 2, 2, comm=comm)


def difference_from_monolithic(system):
    values, _ = snapshot(system)
    monolithic(system)
    spaces, reference = field_values(system)
    return relative_nodal_error(spaces, values, reference, comm=system.comm)


@pytest.mark.parametrize("h", [1e-4, 1.0, 1e4, 1e8])
def test_cg_on_floating_chain_equals_monolithic(chain, h):
    solver = sc.Subdomains()
    system, result = linear_solve(stack(chain, h=h), rtol=1e-10, solver=solver)
    assert result.krylov_iterations  # floating bodies: Krylov by default
    assert result.history[-1] <= 1e-10  # the stopping rule, checked on the true residual
    # CG ends, in exact arithmetic, within as many iterations as the interface problem has
    # unknowns (7 interfaces × 3 masters); measured 3 to 7 per solve (additive coarse
    # correction: 5 to 13)
    masters = sum(system.sizes.values())
    assert max(result.krylov_iterations) <= masters == 21
    # The answer is as exact as its stopping rule: its relative error is at most cond(S)
    # times its relative residual (history[-1]). The merged reference is a direct solve
    # whose condition grows with h̄ (in units of the bodies' k/L = 1): it differs from
    # over-solved answers by 2e-15, 4e-14, 4e-12, 8e-8 at h = 1e-4 … 1e8, at most 8 eps h
    # above h = 1, bounded here by 1e-12 + 100 eps h. Measured 3e-15, 1.5e-12, 4e-12, 8e-8.
    S = interface_operator(solver)
    stopped = np.linalg.cond(S[np.ix_(solver.active, solver.active)]) * result.history[-1]
    assert difference_from_monolithic(system) <= stopped + 1e-12 + 100 * EPS * h
    # the coarse correction is balanced: the preconditioner inverts S on the coarse space,
    # P S Z = Z (a sum G S Z + Z would not), to the round-off of solving with E = Zᵀ S Z
    Z = solver.coarse_basis
    assert Z.shape[1] == 7  # 8 bodies' constants on 7 interfaces: their span
    PSZ = np.column_stack([solver.precondition(S @ z) for z in Z.T])
    assert np.abs(PSZ - Z).max() <= 100 * EPS * np.linalg.cond(solver.coarse_matrix)
    solver.destroy()


def test_cg_is_exact_against_the_1d_chain(chain):
    """No top cooling: a 1D chain of resistances, nodal-exact with P1 (h = 1e10)."""
    h = 1e10
    problem = stack(chain, h=h, cooled=False)
    problem = sc.Problem(
        chain,
        {n: sc.Material(conductivity=m.conductivity) for n, m in problem.materials.items()},
        problem.contacts,
        problem.conditions,
    )
    system, _ = linear_solve(problem, rtol=1e-12)
    k = [problem.materials[f"body_{i}"].conductivity for i in range(8)]
    resistance = sum(1 / ki for ki in k) + 7 / h + 1 / 2.0
    q = 1.0 / resistance

    def exact(i):
        drop_before = sum(1 / k[j] for j in range(i)) * q + i * q / h
        return lambda x: 1.0 - drop_before - q * (x[:, 0] - i) / k[i]

    spaces, values = field_values(system)
    reference = {f"body_{i}": exact(i) for i in range(8)}
    # nodally exact P1 in 1D, solved to rtol 1e-12: measured 1.9e-14 (3.0e-14 on 2 ranks),
    # 1e-9 leaves 3e4 times that at h = 1e10
    assert relative_nodal_error(spaces, values, reference) <= 1e-9


def test_iterations_barely_grow_with_the_mesh(comm):
    """Refining 4 times (2 → 8 layers per body) adds at most 2 CG iterations.

    Balancing domain decomposition bounds the condition number by C (1 + log(H/h))²,
    independent of the mesh but for the logarithm; measured: the same counts (6, 12, 13) on
    both meshes. The 2 iterations allow for CG's stopping test falling either side of its
    tolerance on another machine.
    """
    counts = {}
    for refinement in (1, 4):
        scene = stack_scene(8, 2 * refinement, 2 * refinement, comm=comm)
        for h in (1e-4, 1.0, 1e10):
            _, result = linear_solve(stack(scene, h=h))
            counts[refinement, h] = sum(result.krylov_iterations)
    for h in (1e-4, 1.0, 1e10):
        assert counts[4, h] <= counts[1, h] + 2


def test_matrix_free_equals_dense(chain):
    problem = stack(chain, h=30.0)
    dense_system, dense = linear_solve(problem, dense_limit=10_000)
    free_system, free = linear_solve(problem, dense_limit=0)
    assert dense.applications == 0 and free.applications > 0
    # the same operator to round-off: the same CG, whose answers differ by round-off
    # amplified by the interface problem's condition
    assert free.krylov_iterations == dense.krylov_iterations
    difference = max(
        np.abs(free_system.masters[k] - values).max() / np.abs(values).max()
        for k, values in dense_system.masters.items()
    )
    assert difference < 1e-10  # measured 9.8e-15 (4.9e-15 on 2 ranks): 1e4 of margin


def dense_strip_part(body, k: str, layers: int) -> np.ndarray:
    """``S̃^α = D − C (K̂ + L)⁻¹ B`` on the slaves of k, dense: the body condensed on its strip
    of ``layers`` element layers, clamped beyond (the strip corrector's definition)."""
    slaves = body.slaves[k].local_dofs
    strip = dofs_within_layers(body.forms.W, slaves, layers)
    K_ee, coupling = body.condense(k, np.setdiff1d(strip, slaves).astype(np.int32))
    K_hat = body.clamp_fixed(k, K_ee - coupling)
    at, blocks = body.position[k], body.blocks[k]
    L = blocks["L"][at][:, at].toarray()
    C = -L if "CtP" not in blocks else -L + blocks["CtP"][:, at].toarray()
    return body.link_stiffness(k) - C @ np.linalg.solve(K_hat + L, blocks["BP"][at].toarray())


@pytest.mark.parametrize("h", [1.0, 1e3, 1e8])
def test_sparse_strip_is_the_dense_strip_corrector_on_one_interface(comm, h):
    """One interface: eliminating the strips from the sparse strip matrix leaves S̃^A + S̃^B,
    computed here dense from each body's condensation, so both give the same G r (two 3D
    blocks, 31 masters; the coupled Joule bars with T, φ and u).

    The strip of T, φ and u solved by one sweep over (T, φ), then u (``split``): the same
    where no contact law sees the pressure (the Jacobian is then block lower triangular in
    that order, the sweep its inverse); with the bars' laws of p the whole strip is solved.
    """
    layers = 2
    problems = [(heated_blocks(blocks3d_scene(0.05, comm=comm), h=h), True)]
    if h == 1.0:
        bars = squeezed_joule_bars(bars_scene(8, comm=comm))
        constant = dataclasses.replace(
            bars.contacts["contact"], conductance=5e3, electrical_conductance=1e4
        )
        problems += [
            (bars, False),
            (dataclasses.replace(bars, contacts={"contact": constant}), True),
        ]
    for problem, split in problems:
        with sc.System(problem, solver="direct") as system:
            system.reset({"temperature": 300.0})
            system.assemble_jacobian()
            strip = sc.SparseStrip(layers=layers, split=split, cut="clamped")
            sparse = sc.Subdomains(strip, krylov=True, coarse=False)
            sparse.setup(system)
            (k,) = system.layers
            parts = system.everywhere(
                {name: dense_strip_part(body, k, layers) for name, body in system.bodies.items()}
            )
            active = system.active[k]
            S = sum(parts.values())[np.ix_(active, active)]
            r = np.random.default_rng(1).standard_normal(active.size) * active
            a = np.linalg.solve(S, r[active])
            b = sparse.precondition(r)[active]
            sparse.destroy()
            # S̃ = Σ (D − C (K̂ + L)⁻¹ B) loses ε ‖D‖ to cancellation (D, the half-link's
            # block, grows with h): the two differ by round-off ε ‖D‖ / ‖S̃‖ times cond(S̃);
            # measured 3e-16 to 1.4e-10 (h = 1e8)
            singular = np.linalg.svd(S, compute_uv=False)
            link = max(np.linalg.norm(body.link_stiffness(k), 2) for body in system.bodies.values())
            link = system.comm.allreduce(link, op=MPI.MAX)
            loss = max(1.0, link / singular[0])
            condition = singular[0] / singular[-1]
            assert np.linalg.norm(a - b) <= 10 * EPS * loss * condition * np.linalg.norm(a)


def test_a_sweep_that_leaves_the_interface_krylov_short_is_replaced_by_the_whole_strip(
    comm, monkeypatch
):
    """A strip swept over its fields (``split``) is exact but for the contact laws' dependence
    on u; where the interface Krylov stops short on it, this Jacobian's strip is factorised
    whole and the solve goes on from its iterate; the next set-up sweeps again. The coupled
    Joule bars (T, φ, u), both bars whole in the ten-layer strip, so the whole strip is the
    merged matrix and its Krylov solve takes 1 iteration. The sweep is made inexact on purpose
    (``pc_fieldsplit_type additive``: the u split without T's load, 2 iterations) and held to
    the whole strip's 1: it stops, falls back, and ends at the whole strip's solution."""
    problem = squeezed_joule_bars(bars_scene(8, comm=comm))
    reference_system, reference = linear_solve(problem, sc.SparseStrip(split=False), krylov=True)
    assert reference.krylov_iterations == [1]
    options = PETSc.Options()
    options.setValue("sc_strip_pc_fieldsplit_type", "additive")
    try:
        solver = sc.Subdomains(sc.SparseStrip(split=True), krylov=True)
        _, swept = linear_solve(problem, solver=solver)
        assert solver.strip.fallbacks == 0
        assert swept.krylov_iterations[-1] > 1  # the additive sweep alone: short of 1
        solver.destroy()
        solver = sc.Subdomains(sc.SparseStrip(split=True), krylov=True, max_rounds=1)
        system, result = linear_solve(problem, solver=solver)
    finally:
        options.delValue("sc_strip_pc_fieldsplit_type")
    strip = solver.strip
    assert strip.whole == {"plate_A", "plate_B"}
    assert strip.fallbacks == 1 and not strip.swept
    assert result.krylov_iterations == [1, 1]  # stopped at the limit, then the exact strip
    x, x_ref = system.state().array_r, reference_system.state().array_r
    for f in np.unique(system.field_of[: system.local_size]):
        at = system.field_of[: system.local_size] == f
        difference = comm.allreduce(np.abs(x[at] - x_ref[at]).max(initial=0.0), op=MPI.MAX)
        scale = comm.allreduce(np.abs(x_ref[at]).max(initial=0.0), op=MPI.MAX)
        # both solves end at the merged system's solution, the whole strip being its exact
        # inverse: apart by round-off (measured 5.6e-15 of u's largest value), far below the
        # stopping rule's 1e-10, which bounds what a solve stopped by it would leave
        assert difference <= 1e-10 * scale
    system.assemble_jacobian()
    solver.setup(system)  # the next Jacobian: swept again
    assert strip.swept and solver.strip.ksp.getPC().getType() == "fieldsplit"
    solver.destroy()

    # where the whole strip would not fit (the sweep's factors said to take 1 TB, 1 GB
    # left: INFO(22) of these bars is below MUMPS's 1 MB unit), the stall is said, and why
    # no fallback came, before any factorisation
    def short(ksp, comm, times):
        with monkeypatch.context() as patch:
            patch.setattr(solvers, "refactorisation_memory", lambda ksp, comm: (1e12, 1e9))
            return solvers.fits_freed(ksp, comm, times)

    monkeypatch.setattr(correctors, "fits_freed", short)
    options.setValue("sc_strip_pc_fieldsplit_type", "additive")
    try:
        solver = sc.Subdomains(sc.SparseStrip(split=True), krylov=True, max_rounds=1)
        with pytest.raises(sc.SubdomainConvergenceError, match="would not fit"):
            linear_solve(problem, solver=solver)
        assert solver.strip.fallbacks == 0
        solver.destroy()
    finally:
        options.delValue("sc_strip_pc_fieldsplit_type")


@pytest.mark.parametrize("h", [1e3, 1e6])
def test_a_robin_cut_brings_the_strip_corrector_closer_to_the_interface_operator(comm, h):
    """Clamped at its cut, a strip of width w answers a mode cos(ξ s) along the contact by
    k ξ coth(ξ w) where the whole block answers k ξ: too stiff for the modes smooth along the
    contact, which the coarse space (the constant) leaves to it, the more so as w shrinks
    against the face (a fixed count of layers on a finer mesh). The Robin cut of reach D/π
    answers the lowest mode as the block does. Two 3D blocks, 0.2 m faces, 97 master DOFs,
    strips of 2 layers (5 cm: coth(π/4) = 1.52), G S on the complement of the constant:
    clamped κ 1.224 (h = 1e3) and 1.246 (1e6), Robin 1.050 and 1.056; the test asks the Robin
    cut to take at least half of the clamp's excess off (it takes 77 %). G stays symmetric
    (the interface CG's preconditioner).
    """
    with sc.System(heated_blocks(blocks3d_scene(0.025, comm=comm), h=h), solver="direct") as s:
        s.reset()
        s.assemble_jacobian()
        exact = sc.Subdomains(krylov=True, coarse=False, dense_limit=10**9)
        exact.setup(s)
        S = interface_operator(exact)
        complement = scipy.linalg.null_space(np.ones((1, exact.size)))
        excess = {}
        for cut in ("clamped", "robin"):
            strip = sc.Subdomains(sc.SparseStrip(layers=2, cut=cut), krylov=True, coarse=False)
            strip.setup(s)
            G = np.column_stack([strip.correct(e) for e in np.eye(strip.size)])
            strip.destroy()
            # G is S̃⁻¹ from a sparse LU: symmetric to its round-off, ε cond(S̃) ‖G‖
            assert np.abs(G - G.T).max() <= 1e3 * EPS * np.linalg.cond(G) * np.abs(G).max()
            inverse = complement.T @ np.linalg.inv(0.5 * (G + G.T)) @ complement
            eigenvalues = scipy.linalg.eigvalsh(complement.T @ S @ complement, inverse)
            excess[cut] = eigenvalues.max() / eigenvalues.min() - 1.0
    assert excess["clamped"] > 0.1  # the clamp's error is there to take off (measured 0.22)
    assert excess["robin"] <= 0.5 * excess["clamped"]


def test_a_robin_cut_at_an_infinite_reach_keeps_the_rows_constant_by_component(comm):
    """The Robin cut lumps a dropped column's entry on the row's node, at the column's field
    component: a vector constant in each component (T, φ, u_x, u_y at 1, 2, 3, 5) then meets
    the strip's rows as the whole merged matrix's, whatever the fields' couplings (the coupled
    Joule bars with T, φ and u, 2 layers), where the clamped strip loses the dropped part.
    The rows of a node with a DOF fixed by a condition are left out: an entry that would land
    on that DOF is dropped, the fixed DOF's row staying its condition alone."""
    problem = squeezed_joule_bars(bars_scene(8, comm=comm))
    with sc.System(problem, solver="direct") as system:
        system.reset({"temperature": 300.0})
        system.assemble_jacobian()
        solver = sc.Subdomains(sc.SparseStrip(layers=2), krylov=True, coarse=False)
        solver.setup(system)
        kept = solver.strip.rows  # this rank's rows of the merged matrix, global
        rows = kept - (system.comm.exscan(system.local_size) or 0)
        solver.destroy()
        dim = problem.scene.dim
        parts = [(f, c) for f in problem.fields
                 for c in (range(dim) if f == "displacement" else [None])]  # fmt: skip
        values = np.array([1.0, 2.0, 3.0, 5.0])[: len(parts)]
        t = np.zeros(system.local_size)
        held = np.zeros(system.local_size, dtype=bool)  # a node with a DOF fixed: clamped
        for name, body in system.bodies.items():
            nodes = body.forms.nodes()
            t[system.slices[name]] = values[nodes.component[: body.size]]
            fixed = np.isin(nodes.dof_at, body.fixed_local).any(axis=1)
            held[system.slices[name]] = fixed[nodes.node[: body.size]]
        masters = [
            np.repeat([values[parts.index(channel)] for channel in layer.channels], layer.nodes)
            for layer in system.layers.values()
        ]
        t[system.master_slice] = system.join_masters(dict(zip(system.layers, masters, strict=True)))
        whole = merged_matrix(system)
        x, y = whole.createVecs()
        x.array[:] = t
        whole.mult(x, y)
        expected = y.array[rows]
        absolute = np.add.reduceat(np.abs(whole.getValuesCSR()[2]), whole.getValuesCSR()[0][:-1])
        scale = system.comm.allreduce(5.0 * absolute.max(), op=MPI.MAX)
        destroy(whole, x, y)
        gaps = {}
        for cut, reach in (("robin", dict.fromkeys(problem.scene.bodies, np.inf)),
                           ("clamped", None)):  # fmt: skip
            K = merged_matrix(system, kept, reach)
            x, y = K.createVecs()
            x.array[:] = t[rows]
            K.mult(x, y)
            gap = np.abs(y.array - expected)[~held[rows]]
            gaps[cut] = system.comm.allreduce(gap.max(initial=0.0), op=MPI.MAX)
            destroy(K, x, y)
    # the same sums in another order: round-off of the rows' absolute sums
    assert gaps["robin"] <= 100 * EPS * scale
    assert gaps["clamped"] > 1e-3 * scale  # what the test would see of a dropped part


@pytest.mark.parametrize("shape", [(), (3,)])
def test_a_strip_of_n_layers_is_n_node_planes_of_a_box(comm, shape):
    """A box of 8 × 5 × 4 hexahedra, each cut into six tetrahedra: every tetrahedron spans
    two neighbouring node planes, so n layers grown from the face x = 1 hold the n + 1
    planes nearest to it, (n + 1) · 6 · 5 nodes (all 9 planes from n = 8 on), times the
    block size. Serial and on 2 ranks, where the layers cross the ranks' boundaries."""
    import basix.ufl
    import dolfinx

    mesh = dolfinx.mesh.create_box(
        comm, [[0.0, 0.0, 0.0], [1.0, 0.5, 0.4]], [8, 5, 4], dolfinx.mesh.CellType.tetrahedron
    )
    element = basix.ufl.element("Lagrange", "tetrahedron", 1, shape=shape)
    W = dolfinx.fem.functionspace(mesh, element)
    bs = W.dofmap.index_map_bs
    face = dolfinx.fem.locate_dofs_geometrical(W, lambda x: np.isclose(x[0], 1.0))
    face = face[face < W.dofmap.index_map.size_local]
    seeds = (bs * face[:, None] + np.arange(bs)).ravel().astype(np.int32)
    for n in (0, 1, 2, 5, 8, 12):
        strip = dofs_within_layers(W, seeds, n)
        assert comm.allreduce(strip.size) == bs * min(n + 1, 9) * 6 * 5, n
        planes = np.unique(np.round(W.tabulate_dof_coordinates()[strip // bs, 0] * 8))
        assert np.all(planes >= 8 - n)  # none beyond the n-th plane


def test_a_strip_limited_to_a_share_of_the_body_stops_at_a_whole_layer(comm):
    """``most`` keeps the most layers (at least one, at most ``layers``) whose DOFs are not
    more than ``most``: the unlimited strips of 1, 2, … layers are the truth (a 3D block, P1
    vectors, seeded on its contact face; serial and on 2 ranks, counted over the ranks)."""
    import basix.ufl
    import dolfinx

    mesh = blocks3d_scene(0.05, comm=comm, placement="shared").bodies["block_A"].mesh
    W = dolfinx.fem.functionspace(mesh, basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
    x_max = comm.allreduce(mesh.geometry.x[:, 0].max(), op=MPI.MAX)
    face = dolfinx.fem.locate_dofs_geometrical(W, lambda x: np.isclose(x[0], x_max))
    seeds = (3 * face[:, None] + np.arange(3)).ravel().astype(np.int32)
    seeds = seeds[seeds < 3 * W.dofmap.index_map.size_local]
    total = 3 * W.dofmap.index_map.size_global

    def count(dofs):
        return comm.allreduce(dofs.size)

    unlimited = [count(dofs_within_layers(W, seeds, n)) for n in range(1, 9)]
    assert np.all(np.diff(unlimited) > 0)  # it grows
    assert unlimited[-1] < total  # eight layers do not reach the far face
    for share in (1e-3, 0.2, 0.5, 1.0):
        most = share * total
        kept = max([n for n, c in enumerate(unlimited, 1) if c <= most], default=1)
        limited = dofs_within_layers(W, seeds, 8, most)
        assert count(limited) == unlimited[kept - 1], (share, kept)
        assert np.array_equal(limited, dofs_within_layers(W, seeds, kept))


@pytest.mark.parametrize("h", [1.0, 1e4, 1e8])
def test_a_strip_that_holds_every_body_whole_is_the_exact_corrector(chain, h):
    """Bodies two cells across, 10 element layers: every body lies whole in its strip, the
    strip's matrix is the whole merged system, and its corrector is ``S⁻¹``. No body then
    brings coarse modes (an additive correction would correct them twice), and the Krylov
    solve ends in one or two iterations, on the monolithic solution. With one layer the end
    bodies keep a cell outside the strip, and their modes."""
    bodies = set(chain.bodies)
    solver = sc.Subdomains(sc.SparseStrip(layers=10), krylov=True)
    system, result = linear_solve(stack(chain, h=h), solver=solver)
    assert solver.strip.whole == bodies and solver.coarse_matrix is None
    S = interface_operator(solver)
    PS = np.column_stack([solver.precondition(c) for c in S.T])
    # P S = I but for the round-off of applying S, ε ‖D‖ / ‖S‖ (D, the half-link's block,
    # grows with h) times cond(S), as in the test of the strip against its dense form;
    # measured 2.5e-15, 4.2e-12 and 2.9e-8 for h = 1, 1e4, 1e8
    singular = np.linalg.svd(S, compute_uv=False)
    link = max(
        np.linalg.norm(body.link_stiffness(k), 2)
        for body in system.bodies.values()
        for k in body.layers
    )
    loss = max(1.0, system.comm.allreduce(link, op=MPI.MAX) / singular[0])
    defect = np.abs(PS - np.eye(solver.size)).max()
    assert defect <= 10 * EPS * loss * singular[0] / singular[-1]
    # one iteration leaves that defect of the residual, a second its square, below the
    # tolerance 1e-10 since defect < 1e-5; measured [1], [2], [2]
    assert defect < 1e-5 and sum(result.krylov_iterations) <= 2 and result.converged
    # the merged reference loses digits as h grows: the bound of the CG test above
    assert difference_from_monolithic(system) <= 1e-12 + 100 * EPS * h
    solver.destroy()
    release(system.comm)
    solver = sc.Subdomains(sc.SparseStrip(layers=1), krylov=True)
    system, result = linear_solve(stack(chain, h=h), solver=solver)
    ends = {"body_0", f"body_{len(bodies) - 1}"}
    assert solver.strip.whole == bodies - ends and solver.coarse_basis.shape[1] > 0
    assert result.converged
    solver.destroy()
    release(system.comm)


def test_coarse_space_keeps_a_long_floating_chain_fast(comm):
    """Chains of 8 and 32 bodies, all floating but the first: the coarse correction keeps the
    preconditioned condition number independent of the chain's length.

    Without it, a chain of n floating bodies is a 1D diffusion over the bodies, whose
    condition grows like n² (theory: 16 times from 8 to 32 bodies; measured 262 → 5170,
    19.7 times); with it, balancing domain decomposition bounds it by C (1 + log(H/h))², the
    same for both (measured 1.066 → 1.067; 3.09 → 3.10 with the coarse correction added to
    the correctors instead of balanced). Eigenvalues are round-off free to many digits,
    so the bounds carry margins: 8 (half the theory) and 10 % of growth.
    """
    kappa, iterations = {}, {}
    for n in (8, 32):
        problem = stack(stack_scene(n, 2, 2, comm=comm), h=1e4, cooled=False)
        for coarse in (True, False):
            kappa[n, coarse] = preconditioned_condition(problem, coarse=coarse)
            _, result = linear_solve(problem, coarse=coarse)
            iterations[n, coarse] = sum(result.krylov_iterations)
            release(comm)  # 32 bodies hold ~300 of MPI's 2048 communicators per system
    assert kappa[32, True] <= 1.1 * kappa[8, True]
    assert kappa[32, False] >= 8 * kappa[8, False]
    # and CG feels it: measured 1 iteration with the coarse space (the uncooled chain's
    # solution is uniform along each contact: in the coarse space) against 37 without
    assert iterations[32, True] < iterations[32, False]


def test_paper_fixed_point_stalls_where_cg_converges(chain):
    problem = stack(chain, h=1e4)
    with pytest.raises(sc.SubdomainConvergenceError, match="use krylov=True"):
        linear_solve(problem, rtol=1e-10, krylov=False, max_rounds=100)
    _, result = linear_solve(problem, rtol=1e-10)
    assert result.history[-1] <= 1e-10  # its stopping rule


def test_distributed_equals_serial(comm):
    """Every body spread over every rank (placement="shared"): the same CG as serially."""
    solutions = {}
    for label, c in [("world", comm), ("self", MPI.COMM_SELF)]:
        scene = stack_scene(8, 3, 3, comm=c, placement="shared")
        solutions[label] = linear_solve(stack(scene, h=100.0), rtol=1e-12)
    (world, r_world), (serial, r_serial) = solutions["world"], solutions["self"]
    assert r_world.krylov_iterations == r_serial.krylov_iterations
    for name in world.bodies:
        V_w, u_w = field_values(world)[0][name], world.bodies[name].U.x.array
        V_s, u_s = field_values(serial)[0][name], serial.bodies[name].U.x.array
        n_w = V_w.dofmap.index_map.size_local
        x_w = gather_rows(comm, V_w.tabulate_dof_coordinates()[:n_w])
        u_w = gather_rows(comm, u_w[:n_w])
        order = match_points(V_s.tabulate_dof_coordinates(), x_w, what=name)
        # the same CG on the same operator; the distributed body solves sum in another
        # order: round-off only (measured ≤ 1e-14 relative on 2 ranks, 0 serially)
        assert np.abs(u_w - u_s[order]).max() <= 1e-12 * np.abs(u_s).max()


@pytest.fixture(scope="module")
def junction(comm):
    return sc.load_scene(
        GEO / "junction.geo",
        bodies=["base", "left", "middle", "right"],
        interfaces=["base_left", "base_middle", "base_right", "left_middle", "middle_right"],
        parameters={"cells": 4},
        comm=comm,
    )


@pytest.mark.parametrize("h", [1e-2, 1.0, 1e4])
def test_body_touching_three_others_and_triple_points(junction, h):
    """ "middle" touches base, left and right; three bodies meet at two points; the held
    top of "middle" fixes slave nodes of two contacts; "left" and "right" float."""
    conductivities = {"base": 1.0, "left": 5.0, "middle": 0.2, "right": 1.0}
    problem = sc.Problem(
        junction,
        {b: sc.Material(conductivity=k) for b, k in conductivities.items()},
        {k: sc.Contact(conductance=h) for k in junction.interfaces},
        [
            sc.Temperature("floor", 0.0),
            sc.Temperature("middle_top", 1.0),
            sc.Convection("left_top", 1.0, 0.5),
            sc.HeatFlux("right_top", 2.0),
        ],
    )
    system, result = linear_solve(problem, rtol=1e-10)
    assert result.history[-1] <= 1e-10  # its stopping rule
    # measured ≤ 1.5e-12 (at h = 1e4, the reference's own round-off; 1.1e-13 below):
    # 1e-10 leaves 65 times that
    assert difference_from_monolithic(system) <= 1e-10


def test_bodies_on_rank_groups_equal_serial(comm):
    """placement="groups": each body solved by its own rank group; same numbers as serial."""
    grouped = stack_scene(8, 3, 3, comm=comm, placement="groups")
    assert len(grouped.group_roots) == min(comm.size, 8)
    system, result = linear_solve(stack(grouped, h=100.0), rtol=1e-12)
    serial, expected = linear_solve(stack(stack_scene(8, 3, 3, comm=MPI.COMM_SELF), h=100.0),
                                    rtol=1e-12)  # fmt: skip
    assert result.krylov_iterations == expected.krylov_iterations
    worst = 0.0
    for name, body in system.bodies.items():
        V = field_values(system)[0][name]
        n = V.dofmap.index_map.size_local
        x = gather_rows(V.mesh.comm, V.tabulate_dof_coordinates()[:n])
        u = gather_rows(V.mesh.comm, body.U.x.array[:n])
        V_s = field_values(serial)[0][name]
        order = match_points(V_s.tabulate_dof_coordinates(), x, what=name)
        worst = max(worst, float(np.abs(u - serial.bodies[name].U.x.array[order]).max()))
    # round-off of the same solves summed in another order (measured 1.6e-15 on 2 ranks, on
    # temperatures of order 1 K)
    assert comm.allreduce(worst, op=MPI.MAX) <= 1e-12
    for k, values in system.masters.items():
        assert np.abs(values - serial.masters[k]).max() <= 1e-12
    # the monolithic reference merges the groups' bodies into one matrix over every rank: the
    # same solution, to the subdomain solve's stopping rule (relative master residual 1e-12;
    # measured 6.8e-14, 1.5e-13, 1.7e-13 K on 1, 2, 3 ranks: the bound leaves 500x for the
    # round-off of other BLAS kernels)
    subdomain = {n: b.U.x.array.copy() for n, b in system.bodies.items()}
    monolithic(system)
    gap = max(float(np.abs(b.U.x.array - subdomain[n]).max()) for n, b in system.bodies.items())
    assert comm.allreduce(gap, op=MPI.MAX) <= 1e-10


def test_bddc_solves_the_same_system(comm):
    """PETSc's BDDC on the unassembled matrix (the master layers its interface) == series."""
    problem = stack(stack_scene(8, 3, 3, comm=comm), h=100.0)  # groups under mpiexec
    system, _ = linear_solve(problem, rtol=1e-12)
    series = {n: b.U.x.array.copy() for n, b in system.bodies.items()}
    system.reset()
    bddc = sc.Monolithic(sc.BDDC)
    result = sc.solve(system, bddc)
    # one subdomain (one rank) is a direct solve: 1 iteration; two subdomains of four bodies
    # each: 6 measured. The bound allows twice that for the round-off of other BLAS kernels
    # near the stopping test (relative residual 1e-12)
    assert result.inner[-1].rounds <= (1 if comm.size == 1 else 12)
    gap = max(float(np.abs(b.U.x.array - series[n]).max()) for n, b in system.bodies.items())
    # both stop at 1e-12 (measured 9.9e-14 on 1 rank, 3.5e-14 on 2; temperatures of order 1 K)
    assert comm.allreduce(gap, op=MPI.MAX) <= 1e-10
    bddc.destroy()


def test_a_spread_body_is_applied_matrix_free_by_default(comm):
    """A body factorised whole (as one spread over ranks) never costs a solve per master DOF.

    Its exact corrector would: the default is then the interface Krylov with that body's
    ``S^α`` applied by one body solve per iteration, preconditioned by the exact corrector
    on a strip of element layers.
    """
    scene = two_plates_scene(64, 64, comm=comm, placement="shared")  # 65 master DOFs
    base = two_plates(scene, h=1.0, k_b=10.0).problem  # top cooled: T varies along the contact
    problem = sc.Problem(
        scene, base.materials, base.contacts, [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    )
    with sc.System(problem, schur=False) as system:
        solver = sc.Subdomains()
        inner = sc.solve(system, solver, rtol=1e-12).inner[-1]
        assert solver.corrector.name == "sparse strip" and solver.use_krylov
        # the exact corrector would solve each body once per master DOF (2 × 65); one body
        # solve per body and CG iteration: measured 16 (8 iterations; 8 too for 2 × 129
        # masters on 128 × 128 elements, 19 at h = 1e3: the count follows the spectrum of the
        # strip's error, not the interface's size)
        assert inner.applications < 2 * system.sizes["contact"]
        solver.destroy()
        values, _ = snapshot(system)
        system.reset()
        sc.solve(system, sc.Monolithic())
        reference, _ = snapshot(system)
    # both stop at 1e-12 (temperatures of order 1 K): round-off of the two solves
    gap = max(float(np.abs(values[n] - reference[n]).max(initial=0.0)) for n in values)
    assert comm.allreduce(gap, op=MPI.MAX) <= 1e-10


@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="a body shared by ranks needs several")
def test_bddc_refuses_a_body_shared_by_ranks(comm):
    problem = stack(stack_scene(2, 2, 2, comm=comm, placement="shared"), h=1.0)
    with sc.System(problem) as system, pytest.raises(ValueError, match="placement='groups'"):
        sc.solve(system, sc.Monolithic(sc.BDDC))
