"""Partitioned Robin-Robin couplings: the same discrete problem, and where they go wrong."""

import numpy as np
import pytest
from helpers import linear_solve, snapshot

import subdomain_contact as sc
from subdomain_contact.partitioned import (
    robin_robin_map,
    solve_dirichlet_neumann,
    solve_robin_robin,
)
from verification.cases import two_plates, two_plates_scene
from verification.nodal import relative_nodal_error


@pytest.fixture(scope="module")
def plates(comm):
    """conftest's plates spread over every rank: a coupling needs both bodies on each."""
    return two_plates_scene(4, 4, comm=comm, placement="shared")


def error(result, reference):
    spaces = {n: T.function_space for n, T in result.temperatures.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    return relative_nodal_error(spaces, values, reference)


@pytest.mark.parametrize("acceleration", ["aitken", "iqn-ils"])
def test_accelerated_robin_robin_reaches_the_exact_solution(plates, acceleration):
    case = two_plates(plates, h=1.0, k_a=2.0, source_a=3.0)
    result = solve_robin_robin(case.problem, acceleration=acceleration)
    # uniform data: the interface error is one scalar mode, which the first secant (iteration
    # 2) removes exactly; iteration 3 checks it
    assert result.converged and result.iterations == 3
    # round-off only (measured 4.1e-14; 1e-12 leaves 24 times that)
    assert error(result, case.exact_by_body) < 1e-12


def test_constant_relaxation_converges_at_small_h_and_stalls_at_large_h(plates):
    small = two_plates(plates, h=1e-2)
    result = solve_robin_robin(small.problem, acceleration="constant", relaxation=0.5)
    # at small h the Robin-Robin map barely depends on its input: the relaxed iteration
    # contracts by 1 − ω = 0.5 a step (measured), so the error is about the last change
    # (≤ 1e-10) times the last contraction; the run ends far below (measured 6.9e-15)
    assert result.converged and error(result, small.exact_by_body) < 1e-12
    large = two_plates(plates, h=1e4)
    result = solve_robin_robin(large.problem, acceleration="constant", max_iterations=50)
    # at h = 1e4 the map's dominant eigenvalue is λ = 0.96: the relaxed iteration contracts
    # by 1 − ω(1 − λ) = 0.98 a step (measured), and 50 steps leave the change at about
    # 0.98⁵⁰ of its start (measured 3.9e-2, 400 times the bound)
    assert not result.converged and result.history[-1] > 1e-4


def test_iqn_ils_beats_aitken_when_the_data_vary_along_the_contact(plates):
    base = two_plates(plates, h=1e4).problem
    cooled = sc.Problem(
        plates, base.materials, base.contacts, [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    )
    # The Robin-Robin map is affine, x̃ = M x + c: its fixed point x* and ‖(I − M)⁻¹‖ from
    # five probes. Robin-Robin stops on the change ‖x̃ − x‖/‖x̃‖ ≤ rtol, and
    # x − x* = (I − M)⁻¹ (x − x̃) exactly: the error of its data is bounded by
    # ‖(I − M)⁻¹‖ ‖x̃ − x‖ (1 + 1e-6 for round-off). At h = 1e4 the eigenvalues of M are
    # 0.9957 to 0.9997 and ‖(I − M)⁻¹‖ ≈ 3.4e3: a change of 1e-10 allows errors of 1e-6,
    # which is why a fixed bound (1e-9) held here and failed on other BLAS kernels.
    iterate = robin_robin_map(cooled)
    c = iterate(np.zeros(5))
    M = np.column_stack([iterate(e) - c for e in np.eye(5)])
    inverse = np.linalg.inv(np.eye(5) - M)
    exact = inverse @ c
    runs = {a: solve_robin_robin(cooled, acceleration=a) for a in ("aitken", "iqn-ils")}
    for run in runs.values():
        assert run.converged
        bound = np.linalg.norm(inverse, 2) * np.linalg.norm(run.output - run.data)
        assert np.linalg.norm(run.data - exact) <= (1 + 1e-6) * bound
    # x* is B's interface temperature of the same discrete problem: the subdomain solve's
    # (cond(I − M) eps ≈ 1e-12 apart; 1e-10 leaves 100 times that)
    system, _ = linear_solve(cooled, rtol=1e-12)
    body = system.bodies["plate_B"]
    on_b = body.slaves["contact"].gather(body.U.x.array, 5, body.comm)
    assert np.abs(on_b - exact).max() <= 1e-10
    assert runs["iqn-ils"].iterations < runs["aitken"].iterations


def test_robin_robin_refuses_more_than_two_bodies():
    from verification.cases import stack, stack_scene

    problem = stack(stack_scene(3, 2, 2), h=1.0)
    with pytest.raises(ValueError, match="two bodies, one interface, heat alone"):
        solve_robin_robin(problem)


def cooled(scene, h):
    base = two_plates(scene, h=h).problem
    extra = [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    problem = sc.Problem(scene, base.materials, base.contacts, extra)
    system, _ = linear_solve(problem, rtol=1e-12)
    return problem, snapshot(system)[0]


@pytest.mark.parametrize("acceleration", ["aitken", "iqn-ils"])
def test_dirichlet_neumann_reaches_the_exact_solution(plates, acceleration):
    case = two_plates(plates, h=1.0, k_a=2.0, source_a=3.0)
    result = solve_dirichlet_neumann(case.problem, acceleration=acceleration)
    # one scalar mode, as for Robin-Robin above: a secant, then the check
    assert result.converged and result.iterations == 3
    assert error(result, case.exact_by_body) < 1e-12  # round-off: measured 4.1e-14


def test_dirichlet_neumann_stays_exact_at_a_stiff_contact_where_robin_robin_is_refused(plates):
    problem, reference = cooled(plates, 1e10)
    dn = solve_dirichlet_neumann(problem, acceleration="aitken")
    # Mirror-image plates: the Dirichlet-Neumann iteration matrix is −I (eigenvalue −1, the
    # two Schur complements equal), which the first relaxation ω = ½ solves exactly; h =
    # 1e10 perturbs it by k/(hL): measured 3 iterations, one more allowed for round-off
    assert dn.converged and dn.iterations <= 4
    assert error(dn, reference) < 1e-12  # exchanging heat, DN stays at round-off: 5e-16
    rr = solve_robin_robin(problem, acceleration="aitken", max_iterations=60)
    # Its interface temperatures stop changing at round-off (measured 1e-15), but a round-off
    # δT leaves a heat imbalance h δT / q ≈ 1e10 · eps · |T| / q ≈ 1e-5 (measured 4.3e-5):
    # above the 1e-6 the coupling requires, so it must not call itself converged
    assert min(rr.history) < 1e-12 and rr.balance > 1e-6 and not rr.converged


def test_a_diverging_coupling_stops_and_says_so():
    scene = two_plates_scene(4, 4, placement="shared")
    problem = two_plates(scene, h=1e3, k_b=10.0).problem  # DN unrelaxed-ish: B stiffer than A
    result = solve_dirichlet_neumann(problem, acceleration="constant", relaxation=1.0)
    # the iteration matrix has eigenvalues near −k_B/k_A = −10: it grows 10-fold a step, so
    # the 1e8 growth rule stops it after about 8 steps past the first five (measured 14)
    assert result.diverged and not result.converged and result.iterations < 200
