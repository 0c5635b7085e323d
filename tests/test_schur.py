"""The condensed stiffness from MUMPS's Schur block against dense algebra and against solves."""

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import pytest
import ufl
from mpi4py import MPI

import subdomain_contact as sc
from subdomain_contact.cases import stack, stack_scene, two_plates, two_plates_scene
from subdomain_contact.schur import CondensedFactor


def test_schur_block_and_solves_match_dense_algebra():
    """Σ = K_ss − K_si K_ii⁻¹ K_is of a Poisson matrix, and solves with K + H, to 1e-12."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 12, 9)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    fixed = dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(0.0, fixed, V)
    form = dolfinx.fem.form((1 + 5 * ufl.SpatialCoordinate(mesh)[1]) * ufl.dot(
        ufl.grad(u), ufl.grad(v)
    ) * ufl.dx)  # fmt: skip
    K = dolfinx.fem.petsc.assemble_matrix(form, bcs=[bc])
    K.assemble()
    kept = np.sort(dolfinx.fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[0], 1.0)))
    rng = np.random.default_rng(3)
    H = rng.random((kept.size, kept.size))
    H = 40.0 * (H + H.T)
    factor = CondensedFactor(K, kept, H, "test_schur_")

    dense = K.convert("dense").getDenseArray().copy()
    inner = np.setdiff1d(np.arange(dense.shape[0]), kept)
    sigma = dense[np.ix_(kept, kept)] - dense[np.ix_(kept, inner)] @ np.linalg.solve(
        dense[np.ix_(inner, inner)], dense[np.ix_(inner, kept)]
    )
    # two direct eliminations of a 130-DOF matrix of condition ~1e3: measured 2.3e-16 relative
    assert np.abs(factor.sigma - sigma).max() <= 1e-12 * np.abs(sigma).max()
    dense[np.ix_(kept, kept)] += H
    b, x = K.createVecLeft(), K.createVecLeft()
    b.array[:] = rng.random(b.getSize())
    expected = np.linalg.solve(dense, b.array)
    for _ in range(2):  # the factorisation is reused
        factor.solve(b, x)
        assert np.abs(x.array - expected).max() <= 1e-12 * np.abs(expected).max()  # 9e-16
    with pytest.raises(ValueError, match="finite square matrix"):
        CondensedFactor(K, kept, np.full_like(H, np.nan), "test_schur_nan_")


def _fixed_slaves(scene):
    """Fixed temperatures on top reach the contact's end nodes (fixed slaves)."""
    base = two_plates(scene, h=1e2, k_b=3.0).problem
    top = sc.Temperature("top", 2.0)
    return sc.ThermalProblem(scene, base.materials, base.contacts, [*base.conditions, top])


@pytest.mark.parametrize(
    ("scene", "problem"),
    [
        (lambda: two_plates_scene(6, 5, quads=False, placement="groups"), _fixed_slaves),
        (lambda: stack_scene(4, 3, 3, placement="groups"), lambda s: stack(s, h=5.0)),
    ],
    ids=["fixed slaves", "stack: two interfaces, floating"],
)
def test_condensed_stiffness_from_schur_equals_solves(scene, problem):
    """K̂ of every body and interface: the Schur block and one solve per slave DOF agree."""
    problem = problem(scene())
    _, condensed = sc.body_blocks(problem, condense=True)
    _, solved = sc.body_blocks(problem, condense=False)
    for name, block in condensed.items():
        assert block.factor is not None  # each body is held by one rank
        assert solved[name].factor is None
        for k in block.layers:
            schur = block.condensed_stiffness(k)
            reference = solved[name].condensed_stiffness(k)
            # two direct computations of the same matrix; the fixed slaves' 1e8-stiff
            # diagonal sets the scale: measured ≤ 2.5e-16 relative
            assert np.abs(schur - reference).max() <= 1e-10 * np.abs(reference).max()
