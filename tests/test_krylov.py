"""The interface problem as a whole: CG with per-interface correctors and a coarse space."""

import numpy as np
import pytest
from mpi4py import MPI

import subdomain_contact as sc
from subdomain_contact.cases import stack, stack_scene
from subdomain_contact.geometry import gather_rows, match_points
from subdomain_contact.verification import relative_nodal_error


@pytest.fixture(scope="module")
def chain(comm):
    return stack_scene(8, 2, 2, comm=comm)


def difference_from_monolithic(solver, result):
    reference = sc.solve_monolithic(solver.blocks)
    spaces = {n: b.V for n, b in solver.blocks.items()}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    return relative_nodal_error(spaces, values, reference.temperatures)


@pytest.mark.parametrize("h", [1e-4, 1.0, 1e4, 1e8])
def test_cg_on_floating_chain_equals_monolithic(chain, h):
    solver = sc.ThermalSubdomains(stack(chain, h=h))
    result = sc.solve_interface_krylov(solver, rtol=1e-10)
    assert result.history[-1] <= 1e-10
    assert sum(result.krylov_iterations) <= 15
    assert difference_from_monolithic(solver, result) <= (1e-9 if h <= 1e4 else 1e-6)


def test_cg_is_exact_against_the_1d_chain(chain):
    """No top cooling: a 1D chain of resistances, nodal-exact with P1 (h = 1e10)."""
    h = 1e10
    problem = stack(chain, h=h, cooled=False)
    problem = sc.ThermalProblem(
        chain,
        {name: sc.ThermalMaterial(m.conductivity) for name, m in problem.materials.items()},
        problem.contacts,
        problem.conditions,
    )
    solver = sc.ThermalSubdomains(problem)
    result = sc.solve_interface_krylov(solver, rtol=1e-12)
    k = [problem.materials[f"body_{i}"].conductivity for i in range(8)]
    resistance = sum(1 / ki for ki in k) + 7 / h + 1 / 2.0
    q = 1.0 / resistance
    spaces = {n: b.V for n, b in solver.blocks.items()}

    def exact(i):
        drop_before = sum(1 / k[j] for j in range(i)) * q + i * q / h
        return lambda x: 1.0 - drop_before - q * (x[:, 0] - i) / k[i]

    reference = {f"body_{i}": exact(i) for i in range(8)}
    values = {n: T.x.array for n, T in result.temperatures.items()}
    assert relative_nodal_error(spaces, values, reference) <= 1e-9


def test_iterations_barely_grow_with_the_mesh(comm):
    """Refining 4 times (2 → 8 layers per body) adds at most 2 CG iterations."""
    counts = {}
    for refinement in (1, 4):
        scene = stack_scene(8, 2 * refinement, 2 * refinement, comm=comm)
        for h in (1e-4, 1.0, 1e10):
            solver = sc.ThermalSubdomains(stack(scene, h=h))
            counts[refinement, h] = sum(sc.solve_interface_krylov(solver).krylov_iterations)
    for h in (1e-4, 1.0, 1e10):
        assert counts[4, h] <= counts[1, h] + 2


def test_matrix_free_equals_dense(chain):
    solver = sc.ThermalSubdomains(stack(chain, h=30.0))
    dense = sc.solve_interface_krylov(solver, dense_limit=10_000)
    masters = {k: v.copy() for k, v in dense.masters.items()}
    free = sc.solve_interface_krylov(solver, dense_limit=0)
    assert dense.dense_bodies == 8 and free.dense_bodies == 0
    assert free.krylov_iterations == dense.krylov_iterations
    for k, values in masters.items():
        assert np.allclose(free.masters[k], values, rtol=1e-10, atol=1e-12)


def test_coarse_space_keeps_a_long_floating_chain_fast(comm):
    """32 bodies, 31 floating: the coarse correction halves the CG iterations (at 8 bodies,
    CG needs no help: the chain's 7 interfaces leave it few modes to find)."""
    solver = sc.ThermalSubdomains(stack(stack_scene(32, 2, 2, comm=comm), h=1e4, cooled=False))
    with_coarse = sum(sc.solve_interface_krylov(solver).krylov_iterations)
    without = sum(sc.solve_interface_krylov(solver, coarse=False).krylov_iterations)
    assert with_coarse <= 20 and without >= 2 * with_coarse


def test_paper_fixed_point_stalls_where_cg_converges(chain):
    solver = sc.ThermalSubdomains(stack(chain, h=1e4))
    with pytest.raises(sc.SubdomainConvergenceError, match="no convergence"):
        solver.solve(rtol=1e-10, max_rounds=100)
    assert sc.solve_interface_krylov(solver).history[-1] <= 1e-10


def test_distributed_equals_serial(comm):
    solutions = {}
    for label, c in [("world", comm), ("self", MPI.COMM_SELF)]:
        solver = sc.ThermalSubdomains(stack(stack_scene(8, 3, 3, comm=c), h=100.0))
        result = sc.solve_interface_krylov(solver, rtol=1e-12)
        solutions[label] = (solver, result)
    (world, r_world), (serial, r_serial) = solutions["world"], solutions["self"]
    assert r_world.krylov_iterations == r_serial.krylov_iterations
    for name in world.blocks:
        V_w, V_s = world.blocks[name].V, serial.blocks[name].V
        n_w = V_w.dofmap.index_map.size_local
        x_w = gather_rows(comm, V_w.tabulate_dof_coordinates()[:n_w])
        u_w = gather_rows(comm, r_world.temperatures[name].x.array[:n_w])
        x_s, u_s = V_s.tabulate_dof_coordinates(), r_serial.temperatures[name].x.array
        order = match_points(x_s, x_w, what=name)
        assert np.abs(u_w - u_s[order]).max() <= 1e-12 * np.abs(u_s).max()


@pytest.fixture(scope="module")
def junction(comm):
    return sc.load_scene(
        sc.cases.GEO / "junction.geo",
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
    problem = sc.ThermalProblem(
        junction,
        {b: sc.ThermalMaterial(k) for b, k in conductivities.items()},
        {k: sc.ThermalContact(h) for k in junction.interfaces},
        [
            sc.Temperature("floor", 0.0),
            sc.Temperature("middle_top", 1.0),
            sc.Convection("left_top", 1.0, 0.5),
            sc.HeatFlux("right_top", 2.0),
        ],
    )
    solver = sc.ThermalSubdomains(problem)
    result = sc.solve_interface_krylov(solver, rtol=1e-10)
    assert result.history[-1] <= 1e-10
    assert difference_from_monolithic(solver, result) <= 1e-10


def test_bodies_on_rank_groups_equal_serial(comm):
    """placement="groups": each body solved by its own rank group; same numbers as serial."""
    grouped = stack_scene(8, 3, 3, comm=comm)
    grouped = sc.load_scene(
        grouped.source,
        bodies=list(grouped.bodies),
        interfaces=list(grouped.interfaces),
        parameters={"bodies": 8, "layers": 3, "rows": 3},
        comm=comm,
        placement="groups",
    )
    assert len(grouped.group_roots) == min(comm.size, 8)
    solver = sc.ThermalSubdomains(stack(grouped, h=100.0))
    result = sc.solve_interface_krylov(solver, rtol=1e-12)
    serial = sc.ThermalSubdomains(stack(stack_scene(8, 3, 3, comm=MPI.COMM_SELF), h=100.0))
    expected = sc.solve_interface_krylov(serial, rtol=1e-12)
    assert result.krylov_iterations == expected.krylov_iterations
    worst = 0.0
    for name, T in result.temperatures.items():
        V = solver.blocks[name].V
        n = V.dofmap.index_map.size_local
        x = gather_rows(V.mesh.comm, V.tabulate_dof_coordinates()[:n])
        u = gather_rows(V.mesh.comm, T.x.array[:n])
        V_s = serial.blocks[name].V
        order = match_points(V_s.tabulate_dof_coordinates(), x, what=name)
        worst = max(worst, float(np.abs(u - expected.temperatures[name].x.array[order]).max()))
    assert comm.allreduce(worst, op=MPI.MAX) <= 1e-12
    for k, values in result.masters.items():
        assert np.abs(values - expected.masters[k]).max() <= 1e-12
    if comm.size > 1:
        with pytest.raises(ValueError, match="different rank groups"):
            sc.solve_monolithic(solver.blocks)
