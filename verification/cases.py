"""Ready-made verification cases: a problem together with its exact solution."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact import laws
from subdomain_contact.physics import (
    Contact,
    Convection,
    Displacement,
    ExponentialClosure,
    Material,
    Penalty,
    Potential,
    Problem,
    Schedule,
    Temperature,
)
from subdomain_contact.scene import Scene, load_scene
from verification.analytic import BlocksBetweenWalls, CompositeSlab, JouleBars, TwoPlates
from verification.nodal import error_against

__all__ = [
    "GEO",
    "TwoPlatesCase",
    "bars_scene",
    "blocks3d_scene",
    "cathode_slot",
    "cathode_slot_scene",
    "composite_slabs",
    "heated_blocks",
    "hot_squeezed_bars",
    "joule_bars",
    "slab_error",
    "squeezed_joule_bars",
    "squeezed_row",
    "stack",
    "stack_scene",
    "steel_blocks_between_walls",
    "two_plates",
    "two_plates_scene",
    "warming_joule_bars",
]

#: The repository's geometry folder.
GEO = Path(__file__).resolve().parent.parent / "geo"


@dataclass(frozen=True)
class TwoPlatesCase:
    """The two-plate problem of the paper's figure 2 and its closed-form solution."""

    problem: Problem
    exact: TwoPlates

    @property
    def exact_by_body(self) -> dict[str, Callable[[npt.NDArray[np.float64]], np.ndarray]]:
        """Body name -> exact temperature [K] as a function of node coordinates."""
        return {
            "plate_A": lambda x: self.exact.temperature_a(x[:, 0]),
            "plate_B": lambda x: self.exact.temperature_b(x[:, 0]),
        }


def two_plates_scene(
    layers: int = 4,
    rows: int = 4,
    *,
    quads: bool = True,
    length: float = 1.0,
    height: float = 1.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
) -> Scene:
    """``geo/two_plates.geo``: ``layers`` element layers per plate, ``rows`` along y.

    Each plate is ``length`` [m] along x (across the contact) and ``height`` [m] along y.
    """
    return load_scene(
        GEO / "two_plates.geo",
        bodies=["plate_A", "plate_B"],
        interfaces=["contact"],
        parameters={
            "layers": layers,
            "rows": rows,
            "quads": int(quads),
            "length": length,
            "height": height,
        },
        comm=comm,
        placement=placement,
    )


def two_plates(
    scene: Scene,
    *,
    h: float,
    k_a: float = 1.0,
    k_b: float = 1.0,
    source_a: float = 0.0,
    source_b: float = 0.0,
    t_left: float = 1.0,
    t_right: float = 0.0,
) -> TwoPlatesCase:
    """Plates of unit length between fixed end temperatures, insulated top and bottom.

    Args:
        scene: From :func:`two_plates_scene`.
        h: Contact conductance [W/(m^2 K)].
        k_a: Conductivity of plate A [W/(m K)].
        k_b: Conductivity of plate B [W/(m K)].
        source_a: Volumetric source in plate A [W/m^3].
        source_b: Volumetric source in plate B [W/m^3].
        t_left: Temperature [K] at x = 0.
        t_right: Temperature [K] at x = 2.
    """
    problem = Problem(
        scene,
        {
            "plate_A": Material(conductivity=k_a, heat_source=source_a),
            "plate_B": Material(conductivity=k_b, heat_source=source_b),
        },
        {"contact": Contact(conductance=h)},
        [Temperature("left", t_left), Temperature("right", t_right)],
    )
    exact = TwoPlates(1.0, 1.0, k_a, k_b, h, t_left, t_right, source_a, source_b)
    return TwoPlatesCase(problem, exact)


def stack_scene(
    bodies: int = 8,
    layers: int = 2,
    rows: int = 2,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
) -> Scene:
    """``geo/stack.geo``: ``bodies`` unit squares in a chain, ``layers`` × ``rows`` cells each."""
    return load_scene(
        GEO / "stack.geo",
        bodies=[f"body_{i}" for i in range(bodies)],
        interfaces=[f"contact_{i}" for i in range(bodies - 1)],
        parameters={"bodies": bodies, "layers": layers, "rows": rows},
        comm=comm,
        placement=placement,
    )


def blocks3d_scene(
    size: float = 0.1,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str = "auto",
    mesh_cache: str | Path | None = None,
    refinements: int = 0,
) -> Scene:
    """``geo/blocks3d.geo``: two 0.5 × 0.2 × 0.2 m blocks, tetrahedra of ``size`` [m].

    ``refinements``: uniform refinements of that mesh (each halves the size).
    """
    return load_scene(
        GEO / "blocks3d.geo",
        bodies=["block_A", "block_B"],
        interfaces=["contact"],
        parameters={"size": size},
        comm=comm,
        placement=placement,
        mesh_cache=mesh_cache,
        refinements=refinements,
    )


def heated_blocks(scene: Scene, *, h: float = 1e3) -> Problem:
    """The 3D thermal case: 1 K on the left end, cooled on the right end and on the front.

    Conductivities 1 and 10 W/(m K), contact conductance ``h`` [W/(m^2 K)]; the front
    convection (5 W/(m^2 K) to 0.5 K) makes the temperature vary over the contact face.
    """
    return Problem(
        scene,
        {"block_A": Material(conductivity=1.0), "block_B": Material(conductivity=10.0)},
        {"contact": Contact(conductance=h)},
        [Temperature("left", 1.0), Convection("right", 20.0, 0.0), Convection("front", 5.0, 0.5)],
    )


def stack(scene: Scene, *, h: float, cooled: bool = True) -> Problem:
    """The chain held at 1 K on its left end, cooled by convection on its right end.

    Conductivities cycle through 1, 10 and 0.1 W/(m K) and every other body has a source of
    1 W/m^3; every body but the first touches nothing but contacts (and, with ``cooled``, a
    weak convection of 0.5 W/(m^2 K) to 0.3 K on the top, which makes the field vary along
    the contacts). Only body 0 has a temperature condition: the others float.
    """
    n = len(scene.bodies)
    materials = {
        f"body_{i}": Material(conductivity=[1.0, 10.0, 0.1][i % 3], heat_source=float(i % 2))
        for i in range(n)
    }
    conditions = [Temperature("left", 1.0), Convection("right", 2.0, 0.0)]
    if cooled:
        conditions.append(Convection("top", 0.5, 0.3))
    contacts = {f"contact_{i}": Contact(conductance=h) for i in range(n - 1)}
    return Problem(scene, materials, contacts, conditions)


def bars_scene(
    layers: int = 4,
    rows: int = 2,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
) -> Scene:
    """``geo/two_plates.geo`` as two bars of 0.5 m × 0.1 m (``layers`` × ``rows`` quads each)."""
    return two_plates_scene(layers, rows, length=0.5, height=0.1, comm=comm, placement=placement)


def joule_bars(
    scene: Scene, *, voltage: float = 0.5, h: float = 2e3, g: float = 5e4
) -> tuple[Problem, JouleBars]:
    """Constant laws, heat and current through the bars of :func:`bars_scene`, and the closed form.

    Bar A: k = 10 W/(m K), σ = 1e4 S/m; bar B: k = 50, σ = 3e4; contact conductances ``h``
    [W/(m² K)] and ``g`` [S/m²]; T = 300 K at x = 0 and 320 K at x = 1 m; ``voltage`` [V]
    across.
    """
    problem = Problem(
        scene,
        {
            "plate_A": Material(conductivity=10.0, electrical_conductivity=1e4),
            "plate_B": Material(conductivity=50.0, electrical_conductivity=3e4),
        },
        {"contact": Contact(conductance=h, electrical_conductance=g)},
        [
            Temperature("left", 300.0),
            Temperature("right", 320.0),
            Potential("left", voltage),
            Potential("right", 0.0),
        ],
    )
    return problem, JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, h, g, voltage, 300.0, 320.0)


def steel_blocks_between_walls(
    scene: Scene, temperature: float, *, gap: float = 1e-4, penalty: float = 1e13
) -> tuple[Problem, BlocksBetweenWalls]:
    """The bars of :func:`bars_scene` as steel blocks between fixed walls, heated uniformly.

    Both walls at ``temperature`` [K] (reference 300 K), u_x = 0 at the walls, rollers at the
    bottom, an initial ``gap`` [m] closed by a ``penalty`` [Pa/m]. Returns the problem and
    its closed form (plane strain).
    """
    steel = Material(
        conductivity=45.0, young=200e9, poisson=0.3, expansion=1.2e-5, reference_temperature=300.0
    )
    problem = Problem(
        scene,
        {"plate_A": steel, "plate_B": steel},
        {"contact": Contact(conductance=1e4, normal=Penalty(penalty), gap=gap)},
        [
            Temperature("left", temperature),
            Temperature("right", temperature),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, 0.0),
            Displacement("bottom", 1, 0.0),
        ],
    )
    exact = BlocksBetweenWalls((0.5, 0.5), (200e9,) * 2, (0.3,) * 2, (1.2e-5,) * 2, gap, penalty)
    return problem, exact


def _squeezed_laws() -> tuple[Material, Material, Contact]:
    """A carbon-like and a steel-like material and their contact, every law of p and T.

    Carbon: k(T) a law, σ(T) a table, both growing with T; steel: σ(T) a law, falling;
    thermal expansion; an exponential closure law; h(p, T) a power law times a temperature
    factor; g(p, T) a table in p and T.
    """
    h = laws.PowerLaw(scale=5e3, hardness=1e7, exponent=0.8, floor=100.0)
    carbon = Material(
        conductivity=lambda p, T: 10.0 * (1 + 2e-3 * (T - 300.0)),
        electrical_conductivity=laws.Table((0.0,), (300.0, 400.0, 600.0), [[1e4, 1.2e4, 1.5e4]]),
        young=1e10,
        poisson=0.25,
        expansion=4e-6,
        reference_temperature=300.0,
    )
    steel = Material(
        conductivity=45.0,
        electrical_conductivity=lambda p, T: 3e4 / (1 + 1e-3 * (T - 300.0)),
        young=2e11,
        poisson=0.3,
        expansion=1.2e-5,
        reference_temperature=300.0,
    )
    contact = Contact(
        conductance=lambda p, T: h(p, T) * (1 + 1e-3 * (T - 300.0)),
        electrical_conductance=laws.Table(
            (0.0, 1e5, 1e6, 1e7),
            (300.0, 500.0),
            [[1e3, 1.5e3], [1e4, 1.3e4], [5e4, 6e4], [2e5, 2.2e5]],
        ),
        normal=ExponentialClosure(stiffness=1e12, closure=2e-5),
    )
    return carbon, steel, contact


def squeezed_joule_bars(scene: Scene, *, voltage: float = 0.5) -> Problem:
    """Every field coupled: ``voltage`` across the bars, squeezed 20 µm between walls at 300 K.

    Bar A carbon-like, bar B steel-like, with the laws of :func:`_squeezed_laws`. The bottom
    slides on rollers.
    """
    carbon, steel, contact = _squeezed_laws()
    return Problem(
        scene,
        {"plate_A": carbon, "plate_B": steel},
        {"contact": contact},
        [
            Temperature("left", 300.0),
            Temperature("right", 300.0),
            Potential("left", voltage),
            Potential("right", 0.0),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, -2e-5),
            Displacement("bottom", 1, 0.0),
        ],
    )


def composite_slabs(
    cells: int, *, comm: MPI.Comm = MPI.COMM_WORLD
) -> tuple[Problem, CompositeSlab]:
    """Two slabs of 1 m (``cells`` each, one row) heated from one end, and their series.

    k = 2 and 1 W/(m K), ρ c_p = 4e6 and 1e6 J/(m³ K), h = 10 W/(m² K); from 0 K, the left
    end at 1 K from t = 0, the right end at 0 K (:class:`~verification.analytic.CompositeSlab`).
    """
    problem = Problem(
        two_plates_scene(cells, 1, comm=comm),
        {
            "plate_A": Material(conductivity=2.0, density=4000.0, heat_capacity=1000.0),
            "plate_B": Material(conductivity=1.0, density=1000.0, heat_capacity=1000.0),
        },
        {"contact": Contact(conductance=10.0)},
        [Temperature("left", 1.0), Temperature("right", 0.0)],
    )
    return problem, CompositeSlab(1.0, 2.0, 1.0, 4e6, 1e6, 10.0, 1.0, terms=60)


def slab_error(system, series: CompositeSlab, time: float) -> float:
    """Largest nodal error [K] of the slabs' temperature against the series at ``time``.

    (Relative to the range of the series, which spans the 1 K between the ends: the same.)
    """
    return error_against(
        system,
        {
            "plate_A": lambda x: series.temperature(x[:, 0], time, "a"),
            "plate_B": lambda x: series.temperature(x[:, 0], time, "b"),
        },
    )


def warming_joule_bars(
    scene: Scene, voltage: float | Schedule = 1.0, *, gap: float = 5e-6, storage: bool = True
) -> Problem:
    """The squeezed Joule bars in time: ``voltage`` [V] across, an initial ``gap`` [m].

    The laws of :func:`_squeezed_laws`; both ends at 300 K; walls at fixed x, rollers at the
    bottom; the contact open by ``gap`` until the bars expand. With ``storage``, amorphous
    carbon ρ = 1950 kg/m³, c_p = 726 J/(kg K) and plain carbon steel (AISI 1010) ρ = 7832
    kg/m³, c_p = 434 J/(kg K), at 300 K (Incropera et al., *Fundamentals of Heat and Mass
    Transfer*, 6th ed., table A.1).
    """
    carbon, steel, contact = _squeezed_laws()
    if storage:
        carbon = replace(carbon, density=1950.0, heat_capacity=726.0)
        steel = replace(steel, density=7832.0, heat_capacity=434.0)
    return Problem(
        scene,
        {"plate_A": carbon, "plate_B": steel},
        {"contact": replace(contact, gap=gap)},
        [
            Temperature("left", 300.0),
            Temperature("right", 300.0),
            Potential("left", voltage),
            Potential("right", 0.0),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, 0.0),
            Displacement("bottom", 1, 0.0),
        ],
    )


def cathode_slot_scene(
    size: float = 0.04,
    fine: float = 0.016,
    *,
    depth: float = 0.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
) -> Scene:
    """``geo/cathode_slot.geo``: block, cast iron and bar; 2D, or a 3D slice of ``depth`` [m]."""
    return load_scene(
        GEO / "cathode_slot.geo",
        bodies=["block", "cast_iron", "bar"],
        interfaces=["slot_side", "slot_top", "bar_side", "bar_top"],
        parameters={"size": size, "fine": fine, "depth": depth},
        comm=comm,
        placement=placement,
    )


def cathode_slot(scene: Scene, *, mechanics: bool = True, voltage: float = 0.05) -> Problem:
    """The three bodies heated from the bath side, current from the top into the bar.

    Test data of the right orders of magnitude, not the sourced industrial data (the
    collector bar slot scene has those): graphitized carbon (k 100 W/(m K), σ 1e5 S/m,
    E 10 GPa, α 4e-6/K), cast iron and steel with conductivities falling with T; contacts whose
    conductances grow with the pressure (g of carbon against cast iron ≈ 1/(4 µΩ m²) at low
    pressure). T = 1230 K and ``voltage`` [V] on the top, φ = 0 under the bar, convection to
    350 K elsewhere; symmetry (u_x = 0) on x = 0, rollers under the bodies and, in 3D, on the
    slice's two faces. Every reference temperature is 300 K: a cold start is stress-free.
    """
    dim = next(iter(scene.bodies.values())).mesh.geometry.dim
    solid = {"reference_temperature": 300.0} if mechanics else {}

    def elastic(young, poisson, expansion):
        return {"young": young, "poisson": poisson, "expansion": expansion} if mechanics else {}

    materials = {
        "block": Material(
            conductivity=100.0, electrical_conductivity=1e5, **elastic(10e9, 0.2, 4e-6), **solid
        ),
        "cast_iron": Material(
            conductivity=lambda p, T: 40.0 / (1 + 5e-4 * (T - 300.0)),
            electrical_conductivity=lambda p, T: 1.2e6 / (1 + 1e-3 * (T - 300.0)),
            **elastic(100e9, 0.26, 1.1e-5),
            **solid,
        ),
        "bar": Material(
            conductivity=lambda p, T: 45.0 / (1 + 3e-4 * (T - 300.0)),
            electrical_conductivity=lambda p, T: 5e6 / (1 + 4e-3 * (T - 300.0)),
            **elastic(200e9, 0.3, 1.2e-5),
            **solid,
        ),
    }
    rough = laws.PowerLaw(scale=2e3, hardness=1e7, exponent=0.8, floor=500.0)
    normal = {"normal": Penalty(1e12)} if mechanics else {}
    slot = Contact(
        conductance=rough,
        electrical_conductance=lambda p, T: 2.5e5 * (1 + p / 1e6),
        **normal,
    )
    bar = Contact(
        conductance=5e3, electrical_conductance=lambda p, T: 1e7 * (1 + p / 1e7), **normal
    )
    contacts = {"slot_side": slot, "slot_top": slot, "bar_side": bar, "bar_top": bar}
    conditions = [
        Temperature("top", 1230.0),
        Potential("top", voltage),
        Potential("bar_bottom", 0.0),
        Convection("bottom", 5.0, 350.0),
        Convection("bar_bottom", 50.0, 350.0),
        Convection("block_side", 5.0, 350.0),
    ]
    if mechanics:
        conditions += [
            Displacement("symmetry", 0, 0.0),
            Displacement("bottom", 1, 0.0),
            Displacement("bar_bottom", 1, 0.0),
        ]
        if dim == 3:
            conditions += [Displacement("front", 2, 0.0), Displacement("back", 2, 0.0)]
    return Problem(scene, materials, contacts, conditions)


def hot_squeezed_bars(scene: Scene, *, storage: bool = False) -> Problem:
    """Temperature and displacement, a linear bulk and contact laws of pressure and temperature.

    The bars of :func:`bars_scene` as steel (constant k, E, α: the bulk's Jacobian does not
    change), squeezed 20 µm between walls at 300 K and 350 K; the contact closes by an
    exponential law (stiffening by e every 0.1 mm) and conducts
    h(p, T) = PowerLaw(p) (1 + 1e-3 (T − 300)). Only the contact blocks change from one Newton
    step to the next. With ``storage``, steel stores heat (plain carbon steel, AISI 1010:
    ρ = 7832 kg/m³, c_p = 434 J/(kg K); Incropera et al., 6th ed., table A.1): in time, the
    bulk matrices stay the same at a fixed step.
    """
    steel = Material(
        conductivity=45.0, young=2e11, poisson=0.3, expansion=1.2e-5, reference_temperature=300.0
    )
    if storage:
        steel = replace(steel, density=7832.0, heat_capacity=434.0)
    h = laws.PowerLaw(scale=5e3, hardness=1e7, exponent=0.8, floor=100.0)
    contact = Contact(
        conductance=lambda p, T: h(p, T) * (1 + 1e-3 * (T - 300.0)),
        normal=ExponentialClosure(stiffness=1e12, closure=1e-4),
    )
    return Problem(
        scene,
        {"plate_A": steel, "plate_B": steel},
        {"contact": contact},
        [
            Temperature("left", 300.0),
            Temperature("right", 350.0),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, -2e-5),
            Displacement("bottom", 1, 0.0),
        ],
    )


def blocks_row_scene(
    count: int = 4,
    size: float = 0.1,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
) -> Scene:
    """``geo/blocks_row3d.geo``: ``count`` blocks of 0.5 × 0.2 × 0.2 m in a row, tetrahedra."""
    return load_scene(
        GEO / "blocks_row3d.geo",
        bodies=[f"block_{i}" for i in range(count)],
        interfaces=[f"contact_{i}" for i in range(count - 1)],
        parameters={"count": count, "size": size},
        comm=comm,
        placement=placement,
    )


def squeezed_row(scene: Scene, *, voltage: float = 0.5) -> Problem:
    """Every field through a row of blocks, the inner ones floating in T, φ and u_x.

    The materials and contact laws of :func:`squeezed_joule_bars` (carbon-like and steel-like
    blocks in turn; h(p, T), g(p, T), an exponential closure), ``voltage`` [V] and 300 K at
    x = 0, 0 V and 320 K at the far end, the far end pushed in by 20 µm per contact, rollers on
    y = 0 and z = 0. Only the first and the last block carry conditions in T, φ and u_x.
    """
    count = len(scene.bodies)
    carbon, steel, contact = _squeezed_laws()
    materials = {f"block_{i}": (carbon if i % 2 == 0 else steel) for i in range(count)}
    return Problem(
        scene,
        materials,
        {f"contact_{i}": contact for i in range(count - 1)},
        [
            Temperature("left", 300.0),
            Temperature("right", 320.0),
            Potential("left", voltage),
            Potential("right", 0.0),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, -2e-5 * (count - 1)),
            Displacement("front", 1, 0.0),
            Displacement("bottom", 2, 0.0),
        ],
    )
