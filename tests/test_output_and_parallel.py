"""VTK output reads back; a distributed solve equals the serial one."""

import dolfinx
import numpy as np
import pytest
import pyvista
from helpers import linear_solve, make_system
from mpi4py import MPI

import subdomain_contact as sc
from subdomain_contact.scene import gather_rows, match_points
from verification.cases import (
    bars_scene,
    blocks3d_scene,
    steel_blocks_between_walls,
    two_plates,
    two_plates_scene,
)
from verification.nodal import NodalReference, field_values


def test_vtk_reads_back_with_units(plates, shared_tmp, comm):
    case = two_plates(plates, h=3.0, source_a=2.0)
    system, _ = linear_solve(case.problem)
    files = sc.write_vtk(shared_tmp, system)
    names = ["plate_A.pvd", "plate_B.pvd", "master_contact.pvd", "scene.pvd"]
    assert [f.name for f in files] == names
    comm.barrier()
    if comm.rank == 0:
        for name, expected in [
            ("plate_A", case.exact.temperature_a),
            ("plate_B", case.exact.temperature_b),
        ]:
            grid = pyvista.get_reader(str(shared_tmp / f"{name}.pvd")).read().combine()
            values = grid.point_data["temperature [K]"]
            # nodally exact, round-off only (temperatures of order 1 K; as in
            # test_thermal_contact, measured ≤ 5e-14): VTK's ASCII keeps 17 digits
            assert np.allclose(values, expected(grid.points[:, 0]), rtol=0.0, atol=1e-10)
        master = pyvista.get_reader(str(shared_tmp / "master_contact.pvd")).read().combine()
        # the 5 master nodes, some written twice where the ranks' pieces meet
        assert len(np.unique(master.points, axis=0)) == 5
        jump = case.exact.temperature_a(1.0) - case.exact.flux / (2 * 3.0)  # q = h̄ (T_A − T_m)
        assert np.allclose(master.point_data["temperature [K]"], jump, rtol=0.0, atol=1e-10)


def test_2d_displacement_reads_back_as_vectors(shared_tmp, comm):
    """Steel blocks heated 50 K between walls, plane strain: u = (ε_xx x, ε_yy y, 0) per block,
    ε_yy = ((1 + ν) α ΔT − ν ε_xx) / (1 − ν) (σ_yy = 0, ε_zz = 0): both components, as
    ParaView reads them."""
    problem, exact = steel_blocks_between_walls(bars_scene(4, 2, comm=comm), 350.0)
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    sc.write_vtk(shared_tmp / "blocks", system)
    comm.barrier()
    if comm.rank != 0:
        return
    nu, alpha, heating = 0.3, 1.2e-5, 50.0
    for name, e_xx, u_x in zip(
        ("plate_A", "plate_B"), exact.strain(heating), exact.displacement_x(heating), strict=True
    ):
        path = shared_tmp / "blocks" / f"{name}_displacement.pvd"
        grid = pyvista.get_reader(str(path)).read().combine()
        u = grid.point_data["displacement [m]"]
        assert u.shape == (grid.n_points, 3)  # a vector per point, z = 0 in 2D
        e_yy = ((1 + nu) * alpha * heating - nu * e_xx) / (1 - nu)
        x, y = grid.points[:, 0], grid.points[:, 1]
        expected = np.column_stack([u_x(x), e_yy * y, np.zeros_like(x)])
        # uniform strains are exact for P1: round-off only, measured 4.8e-15 of the largest
        # component (4.3e-15 on 2 ranks); VTK's ASCII keeps 17 digits
        assert np.abs(u - expected).max() <= 1e-10 * np.abs(expected).max()


def gathered(V, values):
    n = V.dofmap.index_map.size_local
    comm = V.mesh.comm
    return gather_rows(comm, V.tabulate_dof_coordinates()[:n]), gather_rows(comm, values[:n])


@pytest.mark.parametrize("corrector", [sc.Exact(), sc.Method2(), sc.Method1()])
def test_distributed_equals_serial(comm, corrector):
    """Every body spread over all ranks gives the serial numbers to 1e-12."""
    h = 0.05 if corrector.name == "method1" else 1e4
    results = {}
    for label, c in [("world", comm), ("self", MPI.COMM_SELF)]:
        k_b = 7.0 if corrector.name == "exact" else 1.0  # β = ½ suits identical plates
        case = two_plates(
            two_plates_scene(6, 5, comm=c, placement="shared"), h=h, k_b=k_b, source_a=4.0
        )
        results[label] = linear_solve(case.problem, corrector, rtol=1e-12, krylov=False)
    (world, r_world), (serial, r_serial) = results["world"], results["self"]
    # the same iteration with the bodies' sums in another order: round-off only (measured
    # ≤ 3e-15 relative on 2 ranks), far from any stopping decision (rtol 1e-12)
    assert r_world.rounds == r_serial.rounds
    spaces_w, values_w = field_values(world)
    spaces_s, values_s = field_values(serial)
    for name in ("plate_A", "plate_B"):
        x_w, u_w = gathered(spaces_w[name], values_w[name])
        x_s, u_s = gathered(spaces_s[name], values_s[name])
        order = match_points(x_s, x_w, what=name)
        assert np.abs(u_w - u_s[order]).max() <= 1e-12 * np.abs(u_s).max()
    m_w, m_s = world.masters["contact"], serial.masters["contact"]
    order = match_points(
        serial.layers["contact"].coordinates, world.layers["contact"].coordinates, what="m"
    )
    assert np.abs(m_w - m_s[order]).max() <= 1e-12 * np.abs(m_s).max()


def test_a_nodal_reference_is_found_from_any_placement(comm):
    """A reference gathered from bodies on rank groups answers a scene spread over every rank.

    ``NodalReference`` gathers every body's nodes over all ranks: gathered over a body's own
    ranks only, a rank outside its group had no reference for it (``bench_3d_bodies.py
    --splits`` after the subdomain Newton on 2 ranks, each scene placed by its own solvers,
    raised ``KeyError``). The values, a linear function of the nodes, are found at them.
    """

    def linear(points):
        return points[:, 0] + 2 * points[:, 1] + 3 * points[:, 2]

    def spaces(scene):
        return {
            name: dolfinx.fem.functionspace(body.mesh, ("Lagrange", 1))
            for name, body in scene.bodies.items()
            if scene.is_local(name)
        }

    grouped = spaces(blocks3d_scene(0.05, comm=comm, placement="groups"))
    values = {n: linear(V.tabulate_dof_coordinates()) for n, V in grouped.items()}
    reference = NodalReference(grouped, values)
    spread = spaces(blocks3d_scene(0.05, comm=comm, placement="shared"))
    assert set(spread) == {"block_A", "block_B"}
    for name, found in reference.at(spread).items():
        owned = spread[name].dofmap.index_map.size_local
        exact = linear(spread[name].tabulate_dof_coordinates()[:owned])
        # the two meshes' node coordinates agree to their last bits: measured 4.4e-16 in
        # values of order 1 (a node found at another node would be 0.05 off)
        assert np.abs(found - exact).max(initial=0.0) <= 1e-12
