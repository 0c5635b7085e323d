"""Partitioned Robin-Robin couplings: the same discrete problem, and where they go wrong."""

import pytest

import subdomain_contact as sc
from subdomain_contact.cases import two_plates
from subdomain_contact.partitioned import solve_dirichlet_neumann, solve_robin_robin
from subdomain_contact.verification import relative_nodal_error


def error(result, reference):
    spaces = {n: T.function_space for n, T in result.temperatures.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    return relative_nodal_error(spaces, values, reference)


@pytest.mark.parametrize("acceleration", ["aitken", "iqn-ils"])
def test_accelerated_robin_robin_reaches_the_exact_solution(plates, acceleration):
    case = two_plates(plates, h=1.0, k_a=2.0, source_a=3.0)
    result = solve_robin_robin(case.problem, acceleration=acceleration)
    assert result.converged and result.iterations == 3  # a scalar interface mode: 2 secants
    assert error(result, case.exact_by_body) < 1e-12


def test_constant_relaxation_converges_at_small_h_and_stalls_at_large_h(plates):
    small = two_plates(plates, h=1e-2)
    result = solve_robin_robin(small.problem, acceleration="constant", relaxation=0.5)
    assert result.converged and error(result, small.exact_by_body) < 1e-12
    large = two_plates(plates, h=1e4)
    result = solve_robin_robin(large.problem, acceleration="constant", max_iterations=50)
    assert not result.converged and result.history[-1] > 1e-4


def test_iqn_ils_beats_aitken_when_the_data_vary_along_the_contact(plates):
    base = two_plates(plates, h=1e4).problem
    cooled = sc.ThermalProblem(
        plates, base.materials, base.contacts, [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    )
    series = sc.ThermalSubdomains(cooled).solve(rtol=1e-12)
    reference = {n: T.x.array.copy() for n, T in series.temperatures.items()}
    assert series.rounds <= 3
    runs = {a: solve_robin_robin(cooled, acceleration=a) for a in ("aitken", "iqn-ils")}
    assert runs["iqn-ils"].converged and error(runs["iqn-ils"], reference) < 1e-9
    assert runs["iqn-ils"].iterations < runs["aitken"].iterations


def test_robin_robin_refuses_more_than_two_bodies():
    from subdomain_contact.cases import stack, stack_scene

    problem = stack(stack_scene(3, 2, 2), h=1.0)
    with pytest.raises(ValueError, match="two bodies, one interface"):
        solve_robin_robin(problem)


def cooled(scene, h):
    base = two_plates(scene, h=h).problem
    extra = [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    problem = sc.ThermalProblem(scene, base.materials, base.contacts, extra)
    series = sc.ThermalSubdomains(problem).solve(rtol=1e-12)
    return problem, {n: T.x.array.copy() for n, T in series.temperatures.items()}


@pytest.mark.parametrize("acceleration", ["aitken", "iqn-ils"])
def test_dirichlet_neumann_reaches_the_exact_solution(plates, acceleration):
    case = two_plates(plates, h=1.0, k_a=2.0, source_a=3.0)
    result = solve_dirichlet_neumann(case.problem, acceleration=acceleration)
    assert result.converged and result.iterations == 3
    assert error(result, case.exact_by_body) < 1e-12


def test_dirichlet_neumann_stays_exact_at_a_stiff_contact_where_robin_robin_is_refused(plates):
    problem, reference = cooled(plates, 1e10)
    dn = solve_dirichlet_neumann(problem, acceleration="aitken")
    assert dn.converged and dn.iterations <= 4 and error(dn, reference) < 1e-12
    rr = solve_robin_robin(problem, acceleration="aitken", max_iterations=60)
    # its interface temperatures stop changing, but the heat balance says it is wrong
    assert min(rr.history) < 1e-12 and rr.balance > 1e-6 and not rr.converged


def test_a_diverging_coupling_stops_and_says_so():
    from subdomain_contact.cases import two_plates_scene

    scene = two_plates_scene(4, 4)
    problem = two_plates(scene, h=1e3, k_b=10.0).problem  # DN unrelaxed-ish: B stiffer than A
    result = solve_dirichlet_neumann(problem, acceleration="constant", relaxation=1.0)
    assert result.diverged and not result.converged and result.iterations < 200
