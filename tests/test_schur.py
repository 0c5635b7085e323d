"""The Schur-block factorisation against dense algebra, and against whole-body solves."""

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import pytest
import scipy.sparse
import ufl
from helpers import make_system
from mpi4py import MPI
from petsc4py import PETSc

import subdomain_contact as sc
from subdomain_contact import schur as schur_module
from subdomain_contact import solvers
from subdomain_contact.schur import CondensedFactor
from verification.cases import (
    bars_scene,
    cathode_slot,
    cathode_slot_scene,
    squeezed_joule_bars,
    stack,
    stack_scene,
    two_plates,
    two_plates_scene,
)


def test_schur_block_and_solves_match_dense_algebra():
    """Σ = K_ss − K_si K_ii⁻¹ K_is of an unsymmetric vector problem; solves with K + H for
    two H, the second without a new sparse factorisation, to 1e-12."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 12, 9)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    wind = ufl.as_vector((3.0, 1.0))
    a = ufl.inner(ufl.grad(u), ufl.grad(v)) + ufl.inner(ufl.dot(ufl.grad(u), wind), v)
    fixed = dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(np.zeros(2), fixed, V)
    K = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form((a + 0.3 * u[0] * v[1]) * ufl.dx),
                                          bcs=[bc])  # fmt: skip
    K.assemble()
    nodes = dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 1.0))
    kept = np.sort(np.concatenate([2 * nodes, 2 * nodes + 1]))
    rng = np.random.default_rng(3)
    H = [40.0 * rng.random((kept.size, kept.size)) for _ in range(2)]
    factor = CondensedFactor(K, kept, H[0], "test_schur_")
    dense = K.convert("dense").getDenseArray().copy()
    inner = np.setdiff1d(np.arange(dense.shape[0]), kept)
    sigma = dense[np.ix_(kept, kept)] - dense[np.ix_(kept, inner)] @ np.linalg.solve(
        dense[np.ix_(inner, inner)], dense[np.ix_(inner, kept)]
    )
    # two direct eliminations of a 260-DOF matrix of condition ~1e3: measured 2e-16 relative
    assert np.abs(factor.sigma - sigma).max() <= 1e-12 * np.abs(sigma).max()
    b, x = K.createVecLeft(), K.createVecLeft()
    b.array[:] = rng.random(b.getSize())
    for added in H:
        factor.update(added)
        matrix = dense.copy()
        matrix[np.ix_(kept, kept)] += added
        expected = np.linalg.solve(matrix, b.array)
        for _ in range(2):  # the factorisation is reused
            factor.solve(b, x)
            assert np.abs(x.array - expected).max() <= 1e-12 * np.abs(expected).max()  # 1e-15
    with pytest.raises(ValueError, match="finite square matrix"):
        factor.update(np.full_like(H[0], np.nan))
    factor.destroy()


def _fixed_slaves(scene):
    """Fixed temperatures on top reach the contact's end nodes (fixed slaves)."""
    base = two_plates(scene, h=1e2, k_b=3.0).problem
    top = sc.Temperature("top", 2.0)
    return sc.Problem(scene, base.materials, base.contacts, [*base.conditions, top])


@pytest.mark.parametrize(
    ("scene", "problem"),
    [
        (lambda: two_plates_scene(6, 5, quads=False, placement="groups"), _fixed_slaves),
        (lambda: stack_scene(4, 3, 3, placement="groups"), lambda s: stack(s, h=5.0)),
        (lambda: bars_scene(4, 2, placement="groups"), squeezed_joule_bars),
    ],
    ids=["fixed slaves", "stack: two interfaces, floating", "coupled T, φ, u"],
)
def test_interface_operators_from_schur_equal_whole_body_solves(scene, problem):
    """S^α and K̂ of every body: from the Schur block (dense algebra) and from solves with the
    whole body matrix agree. The coupled bars are taken at a state with the contact closed,
    its laws varying with p and T (unsymmetric, mixed fields)."""
    problem = problem(scene())
    operators = {}
    for schur in (True, False):
        with sc.System(problem, schur=schur) as system:
            system.reset({"temperature": 300.0} if len(problem.fields) > 1 else None)
            if len(problem.fields) > 1:
                sc.solve(system, max_it=3, rtol=0.5)  # a state away from the cold one
            system.assemble_jacobian()
            for name, body in system.bodies.items():
                body.factorise()
                assert body.schur == schur
                operators[schur, name] = body.interface_stiffness()
                for k in body.layers:
                    operators[schur, name, k] = body.condensed_stiffness(k)
    for key, value in operators.items():
        if key[0]:
            reference = operators[(False, *key[1:])]
            # two direct computations of the same matrix; the fixed slaves' 1e8-stiff
            # diagonal sets the scale of K̂ there: measured ≤ 1e-13 relative
            assert np.abs(value - reference).max() <= 1e-10 * np.abs(reference).max(), key


@pytest.mark.parametrize(
    ("scene", "problem"),
    [
        (lambda: two_plates_scene(6, 5, quads=False, placement="groups"), _fixed_slaves),
        (lambda: bars_scene(4, 2, placement="groups"), squeezed_joule_bars),
    ],
    ids=["fixed slaves", "coupled T, φ, u"],
)
def test_the_whole_matrix_is_the_whole_form_assembled(scene, problem):
    """``A = A_bulk + Σ_k L_k``, built from the bulk matrix and the links' block on the
    contact rows, equals the Jacobian of the bulk and link forms assembled at once, with the
    Dirichlet conditions; for the coupled bars away from the cold state (laws of p and T,
    unsymmetric, mixed fields)."""
    problem = problem(scene())
    system = make_system(problem)
    system.reset({"temperature": 300.0} if len(problem.fields) > 1 else None)
    if len(problem.fields) > 1:
        sc.solve(system, max_it=3, rtol=0.5)  # a state away from the cold one
    system.assemble_jacobian()
    for body in system.bodies.values():
        forms = body.forms
        whole = forms.bulk + sum(body._linearised[k] for k in body.layers)
        a = dolfinx.fem.form(ufl.derivative(whole, forms.U, ufl.TrialFunction(forms.W)))
        expected = dolfinx.fem.petsc.assemble_matrix(a, bcs=forms.bcs)
        expected.assemble()
        built = body.whole_matrix()
        scale = expected.norm(PETSc.NormType.INFINITY)
        expected.axpy(-1.0, built, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        # the same entries summed in another order: a few eps of the largest row sum
        assert expected.norm(PETSc.NormType.INFINITY) <= 1e-13 * scale, body.name
        expected.destroy()


def test_a_thin_body_condensed_by_columns_equals_its_schur_block(monkeypatch):
    """The cast iron of the cathode slot (T, φ, u; most of its DOFs on contacts) is thin: its
    S^α from one multi-column solve of its whole factorisation equals the one from its
    Schur block, and the one from a solve per column (the fields mixed: conductances in
    W/(m² K) and S/m², stiffnesses in Pa/m)."""
    problem = cathode_slot(cathode_slot_scene(0.06, 0.03, comm=MPI.COMM_SELF))
    operators = {}
    for share in (schur_module.THIN_SHARE, np.inf):  # thin, then kept as a Schur block
        monkeypatch.setattr(schur_module, "THIN_SHARE", share)
        with sc.System(problem) as system:
            system.reset({"temperature": 300.0})
            system.assemble_jacobian()
            body = system.bodies["cast_iron"]
            body.factorise()
            assert (body.columns, body.schur) == ((True, False) if share < 1 else (False, True))
            operators[share] = body.interface_stiffness()
            if body.columns:  # the same columns one body solve at a time
                rhs_s = -body.coupling(dict(zip(body.layers, np.split(
                    np.eye(sum(body.master_sizes())), np.cumsum(body.master_sizes())[:-1]
                ), strict=True)))  # fmt: skip
                for one, many in zip(body._solve_each_column(rhs_s), body._solve_columns(rhs_s),
                                     strict=True):  # fmt: skip
                    # the same solves, many columns at once: measured ≤ 1.7e-15
                    assert np.abs(one - many).max() <= 1e-12 * np.abs(one).max()
    reference = operators[np.inf]
    # two direct computations of the same matrix (one scaled, one not): measured ≤ 1e-15
    assert (
        np.abs(operators[schur_module.THIN_SHARE] - reference).max()
        <= 1e-10 * np.abs(reference).max()
    )


def test_the_ordering_follows_the_mesh_and_the_factorisations(comm, plates, monkeypatch):
    """MUMPS orders a 2D body and the merged matrix by AMD (``solvers.ordering``); a 2D matrix
    above ``AMD_ROWS`` that is factorised again keeps MUMPS's choice; an option wins.

    INFOG(7) is the ordering MUMPS used (0: AMD, 5: METIS); ICNTL(7) = 7 is its automatic
    choice.
    """
    problem = two_plates(plates, h=10.0).problem

    def orderings(**options):
        system = make_system(problem, **options)
        sc.solve(system)
        return {b.name: (b.factor.F.getMumpsIcntl(7), b.factor.F.getMumpsInfog(7))
                for b in system.bodies.values()}  # fmt: skip

    assert set(orderings().values()) == {(0, 0)}  # linear: factorised once, by AMD
    materials = {**problem.materials, "plate_A": sc.Material(conductivity=lambda p, T: 1 + T / 1e3)}
    nonlinear = sc.Problem(plates, materials, problem.contacts, problem.conditions)
    monkeypatch.setattr(solvers, "AMD_ROWS", 0)
    system = make_system(nonlinear)
    sc.solve(system)
    chosen = {b.name: b.factor.F.getMumpsIcntl(7) for b in system.bodies.values()}
    assert chosen.get("plate_A", 7) == 7 and chosen.get("plate_B", 0) == 0  # B stays linear
    monkeypatch.undo()
    database = PETSc.Options()
    database["sc_body_plate_A_mat_mumps_icntl_7"] = 5
    try:
        used = orderings()
    finally:
        database.delValue("sc_body_plate_A_mat_mumps_icntl_7")
    assert used.get("plate_A", (5, 5)) == (5, 5) and used.get("plate_B", (0, 0)) == (0, 0)
    monolithic = sc.Monolithic()
    sc.solve(make_system(problem), monolithic)
    assert monolithic.ksp.getPC().getFactorMatrix().getMumpsInfog(7) == 0
    monolithic.destroy()


def _delaying(n: int) -> scipy.sparse.csr_matrix:
    """Central differences of a convection with a diffusion 1e-4 of it (n² rows): without
    MUMPS's scaling and column permutation (ICNTL(6) = ICNTL(8) = 0) most diagonal pivots
    fail the threshold test and are delayed beyond the analysis's workspace estimate
    (n = 50: 751–889 of 2,500 delayed, INFOG(13); short at ICNTL(14) = 20 and 40 %, serially
    and on 2 ranks, whole at 80 %)."""
    eye = scipy.sparse.identity(n)
    second = scipy.sparse.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (n, n))
    first = scipy.sparse.diags([1.0, -1.0], [1, -1], (n, n))
    diffusion = scipy.sparse.kron(eye, second) + scipy.sparse.kron(second, eye)
    convection = scipy.sparse.kron(eye, first) + scipy.sparse.kron(first, eye)
    return (1e-3 * diffusion + 10.0 * convection).tocsr()


def _petsc(matrix: scipy.sparse.csr_matrix, comm: MPI.Comm) -> PETSc.Mat:
    A = PETSc.Mat().createAIJ(matrix.shape, comm=comm)
    A.setUp()
    first, last = A.getOwnershipRange()
    for row in range(first, last):
        span = slice(matrix.indptr[row], matrix.indptr[row + 1])
        A.setValues(row, matrix.indices[span], matrix.data[span])
    A.assemble()
    return A


def test_a_factorisation_whose_workspace_falls_short_is_made_again_relaxed(comm):
    """MUMPS's workspace estimate short (PETSc's FACTOR_OUTMEMORY) at the default ICNTL(14) =
    20 %: ``factorise`` and a field split's sweep (the sparse strip corrector's) factorise
    again with it doubled, the short split alone; the solves are then right."""
    hard = _delaying(50)
    m = hard.shape[0]
    database = PETSc.Options()
    unscaled = {"mat_mumps_icntl_6": "0", "mat_mumps_icntl_8": "0"}
    for key, value in unscaled.items():  # a user's options: they win over the code's
        database[f"relax_whole_{key}"] = value
    try:
        A = _petsc(hard, comm)
        plain = solvers.make_ksp(A, "relax_whole_", solvers.DIRECT)
        short = plain.getPC().getFailedReason()
        plain.destroy()
        ksp = solvers.factorise(A, "relax_whole_", "the test matrix")
    finally:
        for key in unscaled:
            database.delValue(f"relax_whole_{key}")
    assert short == PETSc.PC.FailedReason.FACTOR_OUTMEMORY  # what the retry is for
    relaxed = ksp.getPC().getFactorMatrix().getMumpsIcntl(14)
    assert relaxed in {*(20 * 2**k for k in range(1, 7)), 1600}  # doubled from 20, up to 1600
    checks = [(A, ksp)]

    whole = scipy.sparse.block_diag([hard, scipy.sparse.identity(m)]).tocsr()
    B = _petsc(whole, comm)
    first, last = B.getOwnershipRange()
    sets = [
        (
            name,
            PETSc.IS().createGeneral(
                np.arange(max(first, lo), min(last, hi), dtype=PETSc.IntType), comm=comm
            ),
        )
        for name, (lo, hi) in (("hard", (0, m)), ("easy", (m, 2 * m)))
    ]
    options = {"ksp_type": "preonly", "pc_type": "fieldsplit", "pc_fieldsplit_type": "additive"}
    options |= {f"fieldsplit_{n}_{k}": v for n, _ in sets for k, v in solvers.DIRECT.items()}
    options |= {f"fieldsplit_hard_{k}": v for k, v in unscaled.items()}
    plain = solvers.make_ksp(B, "relax_split_", options, splits=sets)
    short = [sub.getPC().getFailedReason() for sub in plain.getPC().getFieldSplitSubKSP()]
    plain.destroy()
    assert short == [PETSc.PC.FailedReason.FACTOR_OUTMEMORY, 0]
    swept, relaxation = solvers.set_up_relaxed(B, "relax_split_", options, splits=sets)
    subs = swept.getPC().getFieldSplitSubKSP()
    assert [sub.getPC().getFailedReason() for sub in subs] == [0, 0]
    assert relaxation["hard"] > 20 and relaxation["easy"] == 20  # the short split alone
    assert [s.getPC().getFactorMatrix().getMumpsIcntl(14) for s in subs] == [
        relaxation["hard"],
        20,
    ]
    checks.append((B, swept))
    for matrix, solver in checks:
        b, x = matrix.createVecs()
        b.array[:] = np.random.default_rng(5).random(b.local_size)
        solver.solve(b, x)
        residual = b.duplicate()
        matrix.mult(x, residual)
        residual.axpy(-1.0, b)
        # LU with threshold pivoting (CNTL(1) = 0.01: growth up to 100 a delayed pivot) at
        # condition 1e4: measured 1.1e-10 to 1.9e-10, serially and on 2 ranks; a failed factor
        # leaves x = 0, a residual of 1. The bound leaves 50 times that to other BLAS kernels.
        assert residual.norm() <= 1e-8 * b.norm()
        solvers.destroy(b, x, residual, solver, matrix)
    solvers.destroy(*(iset for _, iset in sets))
