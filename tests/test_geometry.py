"""The loader: bodies, master layers and boundary names from .geo files, and its refusals."""

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import linear_solve, make_system, monolithic, snapshot
from mpi4py import MPI

import subdomain_contact as sc
from subdomain_contact import scene as scene_module
from subdomain_contact.scene import gather_rows, match_points
from verification.analytic import TwoPlates
from verification.cases import GEO, blocks3d_scene, cathode_slot, cathode_slot_scene, two_plates
from verification.nodal import field_values, relative_nodal_error

DATA = Path(__file__).parent / "data"
SPLIT = DATA / "split_plates.geo"


def load_split(**parameters):
    return sc.load_scene(
        SPLIT, bodies=["left_plate", "right_plate"], interfaces=["contact"], parameters=parameters
    )


def test_two_plates_scene(plates):
    assert list(plates.bodies) == ["plate_A", "plate_B"]
    contact = plates.interfaces["contact"]
    assert contact.bodies == ("plate_A", "plate_B")
    assert contact.master_mesh.topology.index_map(0).size_global == 5
    assert contact.master_mesh.topology.index_map(1).size_global == 4
    assert set(plates.bodies["plate_A"].boundaries) == {"contact", "left", "top", "bottom"}
    assert set(plates.bodies["plate_B"].boundaries) == {"contact", "right", "top", "bottom"}
    for body in plates.bodies.values():
        assert body.mesh.topology.index_map(2).size_global == 16


def test_a_refined_scene_is_nested_with_eight_times_the_cells(comm):
    """``refinements``: every tetrahedron split in 8, every contact triangle in 4, every
    vertex of the coarse mesh kept, the volumes the same; a negative count is refused."""
    coarse, fine = (blocks3d_scene(0.1, comm=comm, refinements=k) for k in (0, 1))

    def size(mesh, dim):
        return mesh.topology.index_map(dim).size_global

    for name, body in coarse.bodies.items():
        refined = fine.bodies[name].mesh
        assert size(refined, 3) == 8 * size(body.mesh, 3)
        points = np.concatenate(comm.allgather(refined.geometry.x))
        for x in comm.allgather(body.mesh.geometry.x):
            distance = np.min(np.linalg.norm(x[:, None] - points[None], axis=2), axis=1)
            assert np.all(distance < 1e-12)  # nested: each coarse vertex is a fine one
    for name, interface in coarse.interfaces.items():
        master = fine.interfaces[name].master_mesh
        assert size(master, 2) == 4 * size(interface.master_mesh, 2)
    with pytest.raises(ValueError, match=r"blocks3d.geo: refinements = -1, not a count"):
        blocks3d_scene(0.1, comm=comm, refinements=-1)


def test_interface_drawn_twice_is_accepted_when_conforming(comm):
    scene = load_split()
    problem = sc.Problem(
        scene,
        {
            "left_plate": sc.Material(conductivity=1.0),
            "right_plate": sc.Material(conductivity=3.0),
        },
        {"contact": sc.Contact(conductance=2.0)},
        [sc.Temperature("left", 1.0), sc.Temperature("right", 0.0)],
    )
    system, _ = linear_solve(problem)
    exact = TwoPlates(1.0, 1.0, 1.0, 3.0, 2.0, 1.0, 0.0)
    # nodally exact; round-off only (the plates' direct solves: ≤ 5e-14 in test_thermal_contact)
    master = exact.temperature_a(1.0) - exact.flux / 4.0  # q = h̄ (T_A − T_m), h̄ = 4
    assert np.allclose(system.masters["contact"], master, rtol=0.0, atol=1e-10)


@pytest.mark.parametrize(
    ("parameters", "message"),
    [
        ({"rows_b": 5}, r"split_plates.geo: interface 'contact', body 'right_plate': non-conf"),
        (
            {"grading_b": 1.3},
            r"split_plates.geo: interface 'contact', body 'right_plate': non-conf",
        ),
        ({"stray": 1}, r"split_plates.geo: physical group 'stray' has no facets on any body"),
        ({"rowz": 3}, r"split_plates.geo: parameter 'rowz' does not appear in the file"),
        (
            {"overlap": 1},
            r"split_plates.geo: physical groups 'left_plate' and 'both' share surface 1",
        ),
    ],
)
def test_bad_interfaces_are_refused(parameters, message):
    with pytest.raises(ValueError, match=message):
        load_split(**parameters)


@pytest.mark.parametrize(
    ("bodies", "interfaces", "message"),
    [
        (["plate_A", "plate_C"], ["contact"], r"two_plates.geo: no physical group named 'plate_C'"),
        (["plate_A", "plate_B"], ["contakt"], r"two_plates.geo: no physical group named 'contakt'"),
        (["plate_A", "plate_B"], ["left"], r"interface 'left' must lie between exactly two"),
        (["plate_A", "contact"], [], r"group 'contact' has dimension 1, expected 2"),
        (["plate_A"], ["contact"], r"interface 'contact' touches a cell group that is not a body"),
        (
            ["plate_A", "plate_B"],
            [],
            r"two_plates.geo: bodies 'plate_A' and 'plate_B' touch \(4 facets, one at \[1\. ",
        ),
    ],
)
def test_missing_or_wrong_groups_are_refused(bodies, interfaces, message):
    with pytest.raises(ValueError, match=message):
        sc.load_scene(GEO / "two_plates.geo", bodies=bodies, interfaces=interfaces)


def test_unmeshable_file_is_refused():
    with pytest.raises(ValueError, match=r"broken.geo: gmsh could not mesh the file"):
        sc.load_scene(DATA / "broken.geo", bodies=["a"], interfaces=[])
    with pytest.raises(FileNotFoundError, match=r"nowhere.geo"):
        sc.load_scene(DATA / "nowhere.geo", bodies=["a"], interfaces=[])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"k_a": -1.0}, r"body 'plate_A': conductivity = -1.0: must be a finite number > 0"),
        ({"k_b": math.nan}, r"body 'plate_B': conductivity = nan"),
        ({"source_a": math.inf}, r"body 'plate_A': heat_source = inf: must be a finite number"),
        ({"h": -2.0}, r"interface 'contact': conductance = -2.0: must be >= 0"),
        ({"h": math.nan}, r"interface 'contact': conductance = nan: must be a finite number"),
        ({"h": 1.0, "t_left": math.nan}, r"boundary 'left': value = nan"),
    ],
)
def test_bad_coefficients_are_refused(plates, change, message):
    arguments = {"h": 1.0, **change}
    with pytest.raises(ValueError, match=message):
        two_plates(plates, **arguments)


def test_unknown_boundary_is_refused(plates):
    with pytest.raises(ValueError, match=r"two_plates.geo: no boundary group named 'lefft'"):
        sc.Problem(
            plates,
            {"plate_A": sc.Material(conductivity=1.0), "plate_B": sc.Material(conductivity=1.0)},
            {"contact": sc.Contact(conductance=1.0)},
            [sc.Temperature("lefft", 1.0)],
        )


def test_temperature_condition_touching_a_contact(plates):
    """ "bottom" fixes the end nodes of both sides of the contact: still the monolithic answer."""
    problem = sc.Problem(
        plates,
        {"plate_A": sc.Material(conductivity=1.0), "plate_B": sc.Material(conductivity=3.0)},
        {"contact": sc.Contact(conductance=2.0)},
        [sc.Temperature("left", 1.0), sc.Temperature("bottom", 0.0)],
    )
    system, _ = linear_solve(problem, rtol=1e-12)
    values, masters = snapshot(system)
    monolithic(system)
    spaces, reference = field_values(system)
    # solved to rtol 1e-12 (the fixed slaves' link form): measured 7e-16, 1e-11 leaves 1e4
    assert relative_nodal_error(spaces, values, reference) <= 1e-11
    assert np.allclose(masters["contact"], system.masters["contact"], rtol=0, atol=1e-11)


def test_diverging_iteration_stops_with_its_history(plates):
    """X far above its 1D-exact value 1.5 over-corrects: the loop must stop, not return."""
    case = two_plates(plates, h=1e6)
    corrector = sc.PartialCondensation(layers=1, factor=1.95)
    with pytest.raises(
        sc.SubdomainConvergenceError, match=r"partial: the subdomain iteration diverged"
    ) as failure:
        linear_solve(case.problem, corrector, rtol=1e-10, max_rounds=200, krylov=False)
    history = failure.value.result.history
    # the divergence rule (1e6 times the first residual) stopped it, long before max_rounds
    assert history[-1] > 1e6 * history[0] and len(history) < 200


def test_stalled_iteration_stops_with_its_history(plates):
    case = two_plates(plates, h=1e6)
    with pytest.raises(
        sc.SubdomainConvergenceError, match=r"method1: no convergence to 1e-10 in 5 rounds"
    ) as failure:
        linear_solve(case.problem, sc.Method1(), rtol=1e-10, max_rounds=5)
    assert "krylov=True" in str(failure.value)  # and it says what to try instead


def test_a_parameter_does_not_leak_into_the_next_load(comm):
    """gmsh keeps -setnumber values across initialize(): every load must start afresh."""

    def right_end(parameters):
        scene = sc.load_scene(
            GEO / "two_plates.geo",
            bodies=["plate_A", "plate_B"],
            interfaces=["contact"],
            parameters=parameters,
            comm=comm,
        )
        x = scene.bodies["plate_B"].mesh.geometry.x[:, 0]
        return comm.allreduce(x.max(initial=0.0), op=MPI.MAX)

    assert right_end({"length": 0.25}) == pytest.approx(0.5)
    assert right_end({}) == pytest.approx(2.0)


def test_a_rank_kept_waiting_by_an_iterative_body_makes_every_body_spread():
    """A rank that holds a body solved iteratively and more than SPREAD_LOAD (1.25) times the
    mean load: every body over every rank (one group), else the groups as before.

    The collector bar slot at 0.0388 m (cells measured: block 15,660, cast iron 2,586, bar
    3,338) on 2 ranks: the block alone on a rank carries 1.45 times the mean, the other rank
    0.55; on 3 ranks (one body each) 2.18 times. Four equal bodies: 2 ranks take two each
    (1.0), 3 ranks leave one rank two (1.5), 4 ranks one each.
    """
    from subdomain_contact.scene import _place

    slot = {"block": 15660, "cast_iron": 2586, "bar": 3338}
    spread = (dict.fromkeys(slot, 0), [0, 0])
    assert _place(slot, None, 2, {"block"}) == spread
    assert _place(slot, None, 2, set()) == ({"block": 0, "cast_iron": 1, "bar": 1}, [0, 1])
    assert _place(slot, None, 2, {"bar"}) == ({"block": 0, "cast_iron": 1, "bar": 1}, [0, 1])
    assert _place(slot, None, 3, {"block"}) == (dict.fromkeys(slot, 0), [0, 0, 0])
    assert _place(slot, None, 3, set()) == ({"block": 0, "cast_iron": 1, "bar": 2}, [0, 1, 2])
    row = {f"block_{i}": 1000 for i in range(4)}
    owner, ranks = _place(row, None, 2, set(row))
    assert ranks == [0, 1] and sorted(owner.values()) == [0, 0, 1, 1]
    assert _place(row, None, 3, set(row)) == (dict.fromkeys(row, 0), [0, 0, 0])
    assert _place(row, None, 4, set(row)) == ({n: i for i, n in enumerate(row)}, [0, 1, 2, 3])


def test_bodies_of_two_solvers_are_packed_kind_by_kind():
    """Fewer ranks than bodies, solved two ways: each kind's bodies shared out among the
    ranks (each rank then works in a Jacobian's factorisations and in the interface solves).

    Four blocks in a row of decreasing cells: packed by cells alone (largest first onto the
    lightest rank) the ends share rank 0 and the inner two rank 1; with the ends by the
    sweep and the inner two by AMG (the row of 3D blocks, the inner two by their option) each rank
    holds one of each. One kind packs as by cells alone. The collector bar slot's block by
    the sweep, its cast iron and bar factorised (cells as above): the light kind stays off
    the block's rank, as by cells.
    """
    from subdomain_contact.scene import _place

    row = {"block_0": 1040, "block_1": 1030, "block_2": 1020, "block_3": 1010}
    by_cells = {"block_0": 0, "block_1": 1, "block_2": 1, "block_3": 0}
    assert _place(row, None, 2) == (by_cells, [0, 1])
    assert _place(row, None, 2, solvers=dict.fromkeys(row, "split")) == (by_cells, [0, 1])
    kinds = dict.fromkeys(row, "iterative") | {"block_0": "split", "block_3": "split"}
    owner, ranks = _place(row, None, 2, set(row), kinds)
    assert ranks == [0, 1]
    for kind in ("split", "iterative"):
        assert sorted(owner[n] for n in row if kinds[n] == kind) == [0, 1]
    slot = {"block": 15660, "cast_iron": 2586, "bar": 3338}
    kinds = {"block": "split", "cast_iron": "direct", "bar": "direct"}
    assert _place(slot, None, 2, set(), kinds) == _place(slot, None, 2)
    assert _place(slot, None, 2)[0]["block"] != _place(slot, None, 2)[0]["bar"]


def test_bodies_spread_for_an_iterative_body_give_the_serial_solution(comm, monkeypatch):
    """``placement="auto"`` spreads every body where a body that may be solved iteratively
    would keep the other ranks waiting; ``"groups"`` is kept as asked. The 3D cathode slot
    (block 646 of 1,034 cells: 1.2495 times the mean on 2 ranks, just under SPREAD_LOAD, so
    1.2 here), every body made one that may be solved iteratively (SWEEP_ABOVE 0). Under
    mpiexec the spread scene holds its bodies over all ranks and its master layers on each
    (the groups' layout, one group): its Newton (T, φ, from 300 K) gives the serial solution.
    """
    monkeypatch.setattr(scene_module, "SWEEP_ABOVE", 0)
    monkeypatch.setattr(scene_module, "SPREAD_LOAD", 1.2)
    scene = cathode_slot_scene(0.06, 0.03, depth=0.04, comm=comm)
    grouped = cathode_slot_scene(0.06, 0.03, depth=0.04, comm=comm, placement="groups")
    assert scene.shared and scene.group_comm.size == comm.size  # placed when first asked
    assert all(scene.is_local(name) for name in scene.bodies)
    assert len(grouped.group_roots) == min(comm.size, 3)
    monkeypatch.undo()  # the bodies' own solvers by the default rule: factorised

    def solve(scene):
        system = make_system(cathode_slot(scene, mechanics=False))
        system.reset({"temperature": 300.0})
        sc.solve(system, sc.Subdomains(), rtol=1e-10)
        return system

    spread, serial = solve(scene), solve(cathode_slot_scene(0.06, 0.03, depth=0.04,
                                                          comm=MPI.COMM_SELF))  # fmt: skip
    for field in ("temperature", "potential"):
        spaces, values = field_values(spread, field)
        serial_spaces, serial_values = field_values(serial, field)
        worst, scale = 0.0, 0.0
        for name, V in spaces.items():
            n = V.dofmap.index_map.size_local
            x = gather_rows(V.mesh.comm, V.tabulate_dof_coordinates()[:n])
            u = gather_rows(V.mesh.comm, values[name][:n])
            order = match_points(serial_spaces[name].tabulate_dof_coordinates(), x, what=name)
            worst = max(worst, float(np.abs(u - serial_values[name][order]).max()))
            scale = max(scale, float(np.ptp(serial_values[name])))
        # both Newtons stop at rtol 1e-10 per field on quadratically converging iterates,
        # summed in other orders: measured 1.3e-12 (T) and 2.5e-14 (φ) of the range on 2
        # ranks; 1e-8 of the range is the issues' agreement between routes
        assert worst <= 1e-8 * scale, (field, worst / scale)


def test_bodies_with_large_condensations_are_spread_over_ranks():
    """Fewer ranks than bodies: bodies are packed on ranks by their factorisation work.

    The 2D preheat slice (its default mesh): the cathode block, condensed on a Schur block of
    694 contact DOFs, and the thin coke bed and cast iron (624 and 702, condensed by
    multi-column solves) have condensations (4.7 n³, 2.35 n³ flops) that outweigh every
    sparse factorisation; packed by cells they shared one of 2 ranks with the smallest
    bodies on the other. By work, no rank holds all three, and the two loads are within the
    largest body's work of each other (greedy packing, largest first).
    """
    from subdomain_contact.scene import _place, _work

    interfaces = ["anode_coke", "coke_block", "slot_top", "bar_top"]
    interfaces += ["block_paste", "iron_paste", "bar_paste"]
    scene = sc.load_scene(
        GEO / "preheat_slice.geo",
        bodies=["anode", "coke", "block", "cast_iron", "bar", "paste"],
        interfaces=interfaces,
        parameters={"size": 0.04, "fine": 0.01, "coke": 0.02},
        comm=MPI.COMM_SELF,
    )
    cells = {n: b.mesh.topology.index_map(2).size_global for n, b in scene.bodies.items()}
    work = _work(scene)
    heavy = {"block", "coke", "cast_iron"}
    assert heavy == set(sorted(work, key=work.get)[-3:])
    by_cells, _ = _place(cells, None, 2)
    assert len({by_cells[n] for n in heavy}) == 1  # the imbalance the work estimate removes
    owner, ranks = _place(cells, work, 2)
    assert ranks == [0, 1] and len({owner[n] for n in heavy}) == 2
    load = [sum(w for n, w in work.items() if owner[n] == r) for r in (0, 1)]
    assert abs(load[0] - load[1]) <= max(work.values())


def test_a_cached_mesh_is_the_mesh_gmsh_made(comm, tmp_path, monkeypatch):
    """The second load reads the ``.msh`` file of the first, without meshing again."""
    cache = Path(comm.bcast(str(tmp_path), root=0))  # one directory for every rank

    def load(size: float):
        return blocks3d_scene(size, comm=comm, mesh_cache=cache)

    def described(scene):
        out = {}
        for name, body in scene.bodies.items():
            points = body.mesh.geometry.x[: body.mesh.geometry.index_map().size_local]
            points = np.concatenate(comm.allgather(points))
            out[name] = (
                body.mesh.topology.index_map(3).size_global,
                points[np.lexsort(points.T)],
                sorted(body.boundaries),
            )
        layer = scene.interfaces["contact"].master_mesh.topology.index_map(0).size_global
        return out, layer

    made = described(load(0.1))
    assert len(list(cache.glob("blocks3d-*.msh"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("meshed again")

    monkeypatch.setattr(scene_module.gmsh.model.mesh, "generate", refuse)
    read, layer = described(load(0.1))
    assert layer == made[1]
    for name, (cells, points, boundaries) in made[0].items():
        assert read[name][0] == cells and read[name][2] == boundaries
        # the same nodes: written with 17 digits by gmsh's binary format, read back exactly
        np.testing.assert_array_equal(read[name][1], points)
    with pytest.raises(ValueError, match="meshed again"):  # other parameters: a new mesh
        load(0.12)
