"""What a user reads back: integrals by group, contact fields, balances and the VTK files."""

import numpy as np
import pytest
import pyvista
from helpers import make_system
from mpi4py import MPI

import subdomain_contact as sc
from verification.analytic import BlocksBetweenWalls
from verification.cases import (
    bars_scene,
    blocks3d_scene,
    cathode_slot,
    cathode_slot_scene,
    joule_bars,
)


@pytest.mark.parametrize("placement", ["shared", "groups"])
def test_joule_bars_integrals_and_contact_fields_match_the_closed_form(comm, placement):
    """Current, heat, voltage drop and every contact field of the Joule bars (0.1 m high).

    1D problems on P1 are nodally exact and so are their reactions (the residual at a held
    DOF integrates the same sources as the closed form): round-off only, measured ≤ 2e-15
    for the currents, 1.6e-13 for the conducted heat and 1.1e-12 for the temperature jump
    (0.27 K out of 300 K: ε × 300 / 0.27 ≈ 2.5e-13 per nodal value); 1e-10 leaves 90 times
    the worst for other machines and for Newton's rtol (1e-12).
    """
    problem, exact = joule_bars(bars_scene(4, 2, comm=comm, placement=placement))
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    j, thermal, height = exact.current_density, exact.thermal, 0.1
    q, joule = thermal.flux, j**2 / exact.g  # conducted across, released in the contact

    def close(value, truth):
        return value == pytest.approx(truth, rel=1e-10, abs=1e-10 * abs(j * height))

    assert close(sc.current(system, "left"), j * height)
    assert close(sc.current(system, "contact"), j * height)
    assert close(sc.current(system, "right"), -j * height)
    # into bar A at x = 0: k_A T_A'(0) out of it; into bar B at its far end: k_B T_B'(1)
    slope_a = (thermal.temperature_a(1e-6) - thermal.temperature_a(0.0)) / 1e-6
    in_left = -(thermal.source_a * 0.5 - q + joule / 2) * height  # −k_A T_A'(0) × height
    assert abs(10.0 * slope_a * height + in_left) < 1e-3 * abs(in_left)  # the formula itself
    assert sc.heat(system, "left") == pytest.approx(in_left, rel=1e-10)
    assert sc.heat(system, "contact") == pytest.approx(q * height, rel=1e-10)
    assert sc.voltage_drop(system, "left", "right") == pytest.approx(0.5, rel=1e-12)
    assert sc.average(system, "right", "temperature") == pytest.approx(320.0, rel=1e-14)
    fields = sc.contact_fields(system)["contact"]
    truth = {
        "current density": j,
        "potential jump": j / exact.g,
        "heat flux": q,
        "temperature jump": q / exact.h,
        "contact Joule heat": joule,
    }
    for name, value in truth.items():
        assert fields[name] == pytest.approx(np.full(3, value), rel=1e-10), name
    assert fields["area"].sum() == pytest.approx(height, rel=1e-14)
    budget = sc.balance(system)
    generated = (j**2 / 1e4 * 0.5 + j**2 / 3e4 * 0.5 + joule) * height
    assert budget["heat"]["generated"] == pytest.approx(generated, rel=1e-10)
    # what Newton leaves (rtol 1e-12 of each field's scale, in 2-norm over < 50 DOFs):
    # measured 1.5e-16 (heat) and 1.4e-16 (current)
    assert budget["heat"]["relative"] < 1e-10
    assert budget["current"]["relative"] < 1e-10


@pytest.mark.parametrize("mechanics", [False, True])
def test_balances_close_on_the_cathode_slot(comm, mechanics):
    """Three bodies, four contacts with laws of p and T, convection on three groups: the heat
    and the current balance to Newton's tolerance, the supports' forces sum to zero."""
    system = make_system(
        cathode_slot(cathode_slot_scene(0.06, 0.03, comm=comm), mechanics=mechanics)
    )
    system.reset({"temperature": 300.0})
    result = sc.solve(system, rtol=1e-10)
    budget = sc.balance(system)
    # The imbalance is the sum of the residual Newton leaves at the free DOFs and masters,
    # below rtol 1e-10 of each field's scale in 2-norm; over n ~ 1e3 DOFs a sum can reach
    # √n times that. Measured ≤ 6.9e-15 (heat), 2.6e-14 (current), 4.7e-15 (force); 1e-8
    # holds √n · rtol with a margin of 3.
    assert result.reason.startswith("CONVERGED")
    assert budget["heat"]["relative"] < 1e-8
    assert budget["current"]["relative"] < 1e-8
    assert budget["current"]["in"] > 0 and budget["heat"]["generated"] > 0
    assert sc.current(system, "top") == pytest.approx(-sc.current(system, "bar_bottom"), rel=1e-8)
    if mechanics:
        assert budget["force"]["relative"] < 1e-8
        pressure = sc.contact_fields(system)["slot_side"]["pressure"]
        assert pressure.max() > 0  # the hot bar and cast iron press on the carbon


def test_3d_scene_reads_back_from_one_file_with_vectors(shared_tmp, comm):
    """Steel blocks heated 50 K between walls in 3D (rollers on y = 0, z = 0): ``scene.pvd``
    opens the two bodies, their displacements and the contact; u against the closed form of
    uniaxial stress (ε_yy = ε_zz = ν p / E + α ΔT), the contact's pressure and gap too."""
    steel = sc.Material(
        conductivity=45.0, young=200e9, poisson=0.3, expansion=1.2e-5, reference_temperature=300.0
    )
    problem = sc.Problem(
        blocks3d_scene(0.1, comm=comm),
        {"block_A": steel, "block_B": steel},
        {"contact": sc.Contact(conductance=1e4, normal=sc.Penalty(1e13), gap=1e-4)},
        [
            sc.Temperature("left", 350.0),
            sc.Temperature("right", 350.0),
            sc.Displacement("left", 0, 0.0),
            sc.Displacement("right", 0, 0.0),
            sc.Displacement("front", 1, 0.0),
            sc.Displacement("bottom", 2, 0.0),
        ],
    )
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    files = sc.write_vtk(shared_tmp / "blocks3d", system)
    assert files[-1].name == "scene.pvd"
    exact = BlocksBetweenWalls(
        (0.5, 0.5), (200e9,) * 2, (0.3,) * 2, (1.2e-5,) * 2, 1e-4, 1e13, plane_strain=False
    )
    p = exact.pressure(50.0)
    if comm.rank != 0:
        return
    reader = pyvista.get_reader(str(files[-1]))
    parts = reader.read()
    names = [files[dataset.part].stem for dataset in reader.active_datasets]  # one per file
    assert sorted(names) == sorted(
        ["block_A", "block_A_displacement", "block_B", "block_B_displacement", "master_contact"]
    )
    lateral = 0.3 * p / 200e9 + 1.2e-5 * 50.0
    for name, u_x in zip(("block_A", "block_B"), exact.displacement_x(50.0), strict=True):
        grid = parts[names.index(f"{name}_displacement")]
        u = grid.point_data["displacement [m]"]
        assert u.shape == (grid.n_points, 3)
        x, y, z = grid.points.T
        expected = np.column_stack([u_x(x), lateral * y, lateral * z])
        # uniform strains, exact on P1 tetrahedra: round-off, measured 3.7e-15 of the largest
        assert np.abs(u - expected).max() <= 1e-10 * np.abs(expected).max()
        temperature = parts[names.index(name)].point_data["temperature [K]"]
        assert np.allclose(temperature, 350.0, rtol=1e-13)
    master = parts[names.index("master_contact")]
    # the nodal reactions over the nodal areas, uniform here: measured 1.3e-14 (pressure),
    # 1.7e-14 (gap, a difference of displacements 1e3 times larger)
    assert master.point_data["pressure [Pa]"] == pytest.approx(p, rel=1e-9)
    assert master.point_data["gap [m]"] == pytest.approx(exact.gap_width(50.0), rel=1e-9)


def test_unknown_group_is_named(comm):
    problem, _ = joule_bars(bars_scene(4, 2, comm=comm))
    system = make_system(problem)
    with pytest.raises(ValueError, match="no boundary group or interface named 'lft'"):
        sc.current(system, "lft")
    with pytest.raises(ValueError, match="'lft'"):
        sc.average(system, "lft", "temperature")
    assert MPI.COMM_WORLD.allreduce(1) == comm.size


def test_a_node_at_closure_to_round_off_is_closed_whatever_its_sign():
    """The open share counts a node open by its gap, above 1e-9 of the face's largest |gap|:
    gaps of ±1e-20 m beside openings and penetrations of 1e-5 m are the displacements'
    round-off, and the two Newton routes, equal to 1e-15, must read the same share (they
    read 17.2 % and 17.0 % of the slot sides at 204k DOFs by the sign of the pressure)."""
    area = np.array([1.0, 2.0, 3.0, 4.0, 10.0])
    for noise in (1e-20, -1e-20):
        gap = np.array([2e-5, -1e-5, noise, -noise, 0.0])
        assert sc.open_share(gap, area) == 1.0 / 20.0
    assert sc.open_share(np.zeros(3), np.ones(3)) == 0.0  # closed, exactly at closure
    assert sc.open_share(np.full(3, 1e-9), np.ones(3)) == 1.0  # every node open by 1 nm
