"""The subdomain solve against the closed-form two-plate solution and the monolithic solve."""

import numpy as np
import pytest

import subdomain_contact as sc
from subdomain_contact.cases import two_plates
from subdomain_contact.verification import relative_nodal_error


def errors(solver, result, case):
    spaces = {n: b.V for n, b in solver.blocks.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    return relative_nodal_error(spaces, values, case.exact_by_body)


@pytest.mark.parametrize("h", [10.0**e for e in range(-8, 13, 2)])
@pytest.mark.parametrize("contrast", [1e-6, 1.0, 1e6])
def test_series_corrector_is_nodal_exact_at_every_h(plates, h, contrast):
    """Two rounds (one correction and the check) and 1e-9 against the exact solution."""
    case = two_plates(plates, h=h, k_a=1.0, k_b=contrast, source_a=3.0, source_b=-2.0 * contrast)
    solver = sc.ThermalSubdomains(case.problem, sc.Series())
    result = solver.solve(rtol=1e-10)
    assert result.rounds <= 2
    assert errors(solver, result, case) <= 1e-9


@pytest.mark.parametrize("h", [1e-6, 1e-2, 1.0, 1e2, 1e6])
def test_subdomain_equals_monolithic(plates_fine, h):
    """Same discrete system: subdomain and merged-master solves agree (triangles)."""
    case = two_plates(plates_fine, h=h, k_a=2.0, k_b=50.0)
    solver = sc.ThermalSubdomains(case.problem)
    result = solver.solve(rtol=1e-12)
    reference = sc.solve_monolithic(solver.blocks)
    spaces = {n: b.V for n, b in solver.blocks.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    assert relative_nodal_error(spaces, values, reference.temperatures) <= 1e-9
    assert np.allclose(result.masters["contact"], reference.masters["contact"], rtol=1e-9)
    assert relative_nodal_error(spaces, reference.temperatures, case.exact_by_body) <= 1e-8


def test_monolithic_reference_is_exact_at_moderate_h(plates):
    case = two_plates(plates, h=10.0, k_a=1.0, k_b=4.0, source_b=5.0)
    solver = sc.ThermalSubdomains(case.problem)
    reference = sc.solve_monolithic(solver.blocks)
    spaces = {n: b.V for n, b in solver.blocks.items()}
    assert relative_nodal_error(spaces, reference.temperatures, case.exact_by_body) <= 1e-12
    assert reference.num_dofs == 2 * 25 + 5


@pytest.mark.parametrize(("layers", "X"), [(2, 1.0), (4, 1.5), (8, 1.75), (16, 1.875)])
def test_paper_table_1(comm, layers, X):
    """Partial condensation, one layer, h = 1e6: 2 rounds for every mesh (rtol 1e-6)."""
    n = int(np.log2(layers)) - 1
    assert sc.paper_factor(n, layers=1) == X == 2 - 2 / layers
    case = two_plates(sc.cases.two_plates_scene(layers, layers, comm=comm), h=1e6)
    solver = sc.ThermalSubdomains(case.problem, sc.PartialCondensation(layers=1, factor=X))
    result = solver.solve(rtol=1e-6)
    assert result.rounds == 2
    assert errors(solver, result, case) < 1e-6


@pytest.mark.parametrize("h", [0.01, 0.1, 1.0, 3.0])
def test_method1_contracts_by_hbar_over_one_plus_hbar(plates, h):
    """In units of the plate's own stiffness k/L = 1 W/(m^2 K): rate h̄/(1 + h̄)."""
    case = two_plates(plates, h=h)
    solver = sc.ThermalSubdomains(case.problem, sc.Method1())
    with pytest.raises(sc.SubdomainConvergenceError) as failure:
        solver.solve(rtol=1e-300, max_rounds=4)
    history = failure.value.result.history
    hbar = 2 * h
    assert history[2] / history[1] == pytest.approx(hbar / (1 + hbar), rel=1e-6)
    assert history[3] / history[2] == pytest.approx(hbar / (1 + hbar), rel=1e-6)


@pytest.mark.parametrize("h", [0.3, 1.0, 10.0, 1e3])
def test_method2_contracts_by_one_over_one_plus_hbar(plates, h):
    case = two_plates(plates, h=h)
    solver = sc.ThermalSubdomains(case.problem, sc.Method2())
    with pytest.raises(sc.SubdomainConvergenceError) as failure:
        solver.solve(rtol=1e-300, max_rounds=3)
    history = failure.value.result.history
    assert history[2] / history[1] == pytest.approx(1 / (1 + 2 * h), rel=1e-5)


def test_convection_and_flux_conditions(plates):
    """Heat flux in at x = 0, convection out at x = 2: a series of four resistances."""
    k_a, k_b, h, hc, ambient, q = 2.0, 0.5, 3.0, 4.0, 300.0, 50.0
    t_right = ambient + q / hc
    t_left = t_right + q * (1 / k_a + 1 / h + 1 / k_b)
    exact = sc.TwoPlates(1.0, 1.0, k_a, k_b, h, t_left, t_right)
    problem = sc.ThermalProblem(
        plates,
        {"plate_A": sc.ThermalMaterial(k_a), "plate_B": sc.ThermalMaterial(k_b)},
        {"contact": sc.ThermalContact(h)},
        [sc.HeatFlux("left", q), sc.Convection("right", hc, ambient), sc.HeatFlux("top", 0.0)],
    )
    solver = sc.ThermalSubdomains(problem)
    result = solver.solve()
    case = sc.cases.TwoPlatesCase(problem, exact)
    assert result.rounds <= 2
    assert errors(solver, result, case) <= 1e-10


def test_floating_bodies_with_series_corrector(plates):
    """No temperature condition at all: K̂ is singular, the series corrector still works."""
    problem = sc.ThermalProblem(
        plates,
        {"plate_A": sc.ThermalMaterial(1.0), "plate_B": sc.ThermalMaterial(1.0)},
        {"contact": sc.ThermalContact(5.0)},
        [sc.HeatFlux("left", 10.0), sc.Convection("right", 2.0, 20.0)],
    )
    result = sc.ThermalSubdomains(problem).solve()
    assert result.rounds <= 2
    # nothing fixes the level at all: refused before any solver sees a singular matrix
    with pytest.raises(ValueError, match="defined only up to a constant"):
        sc.ThermalProblem(
            plates,
            problem.materials,
            problem.contacts,
            [sc.HeatFlux("left", 10.0), sc.HeatFlux("right", -10.0)],
        )


def test_an_insulating_contact_separates_the_plates(plates):
    case = two_plates(plates, h=0.0, k_a=2.0, source_a=3.0)
    solver = sc.ThermalSubdomains(case.problem)
    result = solver.solve()
    spaces = {n: b.V for n, b in solver.blocks.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    assert result.rounds == 1  # nothing crosses: the first round is the answer
    assert relative_nodal_error(spaces, values, case.exact_by_body) < 1e-12
    reference = sc.solve_monolithic(solver.blocks)
    assert relative_nodal_error(spaces, reference.temperatures, case.exact_by_body) < 1e-12


def test_a_scene_that_nothing_holds_is_refused(plates):
    with pytest.raises(ValueError, match=r"\['plate_B'\] have no temperature"):
        sc.ThermalProblem(
            plates,
            {"plate_A": sc.ThermalMaterial(1.0), "plate_B": sc.ThermalMaterial(1.0)},
            {"contact": sc.ThermalContact(0.0)},  # insulating: B is on its own
            [sc.Temperature("left", 1.0), sc.HeatFlux("right", 2.0)],
        )
