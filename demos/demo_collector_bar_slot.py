# # Collector bar slot of a Hall–Héroult cathode block: thermo-electro-mechanical, 3D
#
# A cathode block carries the cell's current down to a steel collector bar sealed into a slot
# of the block with cast iron. The voltage lost at the cast iron/carbon contact depends on
# the contact pressure, which comes from the thermal expansion of the bar and the cast iron
# against the carbon; the pressure changes the contact resistance, which changes the current
# path and the Joule heat, which changes the temperatures. This demo solves that loop at the
# operating current for a quarter block (`geo/collector_bar_slot.geo`, after Dupuis, Light
# Metals 2011) and reports what a slot designer reads: the cathode voltage drop, the current
# through each contact face, the contact pressures and resistances, the temperatures and the
# Joule heat of the bulk and of the contacts.
#
# ## The problem
#
# Three bodies (carbon block, cast iron, steel bar), each with T, φ and u; four contacts
# (cast iron/carbon on the V-shaped side faces and on the top face, bar/cast iron on the bar's
# side and top), unilateral in the normal direction, with the slip held by a weak spring.
# Materials and contact laws are data files under `data/` with their sources (the block is AT
# 101 synthetic graphite, standing in for a graphitized cathode grade whose tables could not
# be read); two setups of the cast iron/carbon contact:
#
# - `constant`: the constant electrical resistances of thermo-electric slot models (4 µΩ m² on
#   the vertical faces, 8 µΩ m² on the horizontal face; Dupuis 2011);
# - `pressure`: C = α σ_harm(T) (p/H)^β (Cincotti et al. 2007), for current and heat, open
#   (nothing but a floor conductance) where the pressure vanishes.
#
# The bar/cast iron contact follows the pressure law in both setups.
#
# Boundary conditions (this model's choices, documented in `report.json`): the top at the
# metal pad's temperature, the lining as convection to 323 K, the quarter block's share of
# the bar current entering through the top, φ = 0 at the bar's end; symmetry on x = 0 and
# y = 0, the block and the cast iron resting on z = 0.
#
# The first setup's solve is a nested iteration: from a cold start (a uniform 300 K) on a mesh
# 2 (or 4) times coarser, then on each finer mesh from the solution before it (`--levels`).
# The next setup starts from that solution on the run's mesh: a continuation in the contact
# law (a setup run alone climbs from the cold state as the first one does).
#
# Run `python demos/demo_collector_bar_slot.py` (`--small` for the tests, `--size` and
# `--fine` for the mesh). Output in `out_collector_bar_slot/`: `report.json`, VTK per run
# (with the contact fields), `slot_faces.png` (current density and pressure on the slot's
# faces).

import argparse
import json
import time
from functools import partial
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import matplotlib
from mpi4py import MPI
from petsc4py import PETSc

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import subdomain_contact as sc
from subdomain_contact.physics import (
    Convection,
    CurrentDensity,
    Displacement,
    Potential,
    Problem,
    Temperature,
)

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"
parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a coarse mesh, for the tests")
parser.add_argument("--size", type=float, help="element size away from the slot [m]")
parser.add_argument("--fine", type=float, help="element size on the contacts [m]")
parser.add_argument(
    "--linear",
    nargs="+",
    default=["subdomain", "monolithic"],
    choices=["subdomain", "monolithic", "split", "split_single"],
    help="linear solvers of Newton (split: the monolithic Newton by GMRES on a sweep over "
    "(T, φ), then u, each factorised; split_single: each factorised in single precision and "
    "block low-rank, less than half the memory, for ≥ 1M DOFs)",
)
parser.add_argument(
    "--setups", nargs="+", default=["constant", "pressure"], help="contact setups to run"
)
parser.add_argument(
    "--no-study", action="store_true", help="the base case only: no design or mesh study"
)
parser.add_argument(
    "--levels",
    type=int,
    help="meshes of the nested iteration, each 2 times finer (default 2 at --small, else 3; "
    "1: the cold start on the run's mesh)",
)
parser.add_argument("--out", type=Path, default=Path("out_collector_bar_slot"))
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


# Mesh sizes [m] away from the slot and on the contacts: --small (about 17k DOFs) for the
# tests, the default (about 65k DOFs) for the figures of docs/collector_bar_slot.md. Both run
# the design study (the 174 mm bar, 2 mm of cast iron above it), by the first route only.
size, fine = (0.12, 0.04) if args.small else (0.06, 0.02)
size, fine = args.size or size, args.fine or fine

# ## Data
#
# Operating point: a 300 kA cell with 28 blocks and two bars per block, 5.36 kA per bar
# (Dupuis 2011); the quarter block carries half of one bar's current.
CURRENT = 300e3 / 28 / 2 / 2  # A through the quarter block
HALF_LENGTH, HALF_WIDTH = 3.67 / 2, 0.24  # m (the .geo's block)
TOP_AREA = HALF_LENGTH * HALF_WIDTH  # m²
BATH = 960.0 + 273.15  # K, the metal pad above the block (HALL-HEROULT.md)
AMBIENT = 323.15  # K, behind the lining (this model's choice)
LINING = {  # W/(m² K): each face's lining as a heat-transfer coefficient (this model's choice)
    "bottom": 2.0,  # 0.4 m of refractory and insulation, k ≈ 0.8 W/(m K)
    "block_end": 5.0,  # side lining and ramming paste
    "bar_surface": 10.0,  # the bar through the lining and the shell
    "bar_end": 50.0,  # the bar's end, to the flexible and the busbar
}
SLIP = 1e7  # Pa/m: the spring against slip (1e-6 of the normal stiffness)

materials = {  # steady: no heat storage
    name: sc.load_material(DATA / "materials" / f"{file}.toml", storage=False)
    for name, file in (
        ("block", "graphite_at101"),  # see the file
        ("cast_iron", "grey_cast_iron"),
        ("bar", "collector_bar_steel"),
    )
}


def contacts(setup: str) -> dict[str, sc.Contact]:
    """The four contacts of a setup: ``"constant"`` or ``"pressure"``."""
    folder = DATA / "contacts"
    kw = {"tangential": "stuck", "slip_stiffness": SLIP}
    if setup == "constant":
        side = sc.load_contact(folder / "carbon_cast_iron_vertical_constant.toml", **kw)
        top = sc.load_contact(folder / "carbon_cast_iron_horizontal_constant.toml", **kw)
    else:
        side = top = sc.load_contact(folder / "carbon_cast_iron_pressure.toml", **kw)
    bar = sc.load_contact(folder / "steel_cast_iron.toml", **kw)
    return {"slot_side": side, "slot_top": top, "bar_side": bar, "bar_top": bar}


def problem(scene: sc.Scene, setup: str) -> Problem:
    conditions = [
        Temperature("top", BATH),
        CurrentDensity("top", CURRENT / TOP_AREA),
        Potential("bar_end", 0.0),
        Displacement("symmetry_x", 0, 0.0),
        Displacement("symmetry_y", 1, 0.0),
        Displacement("bottom", 2, 0.0),
    ] + [Convection(group, h, AMBIENT) for group, h in LINING.items()]
    return Problem(scene, materials, contacts(setup), conditions)


def load(
    bar_height: float,
    coarsening: float = 1.0,
    like: sc.Scene | None = None,
    refinements: int = 0,
) -> sc.Scene:
    """The scene with a bar of ``bar_height`` [m], every element size times ``coarsening``.

    Its bodies on the rank groups of ``like``'s (under mpiexec), when given; its mesh refined
    uniformly ``refinements`` times.
    """
    return sc.load_scene(
        ROOT / "geo" / "collector_bar_slot.geo",
        bodies=["block", "cast_iron", "bar"],
        interfaces=["slot_side", "slot_top", "bar_side", "bar_top"],
        parameters={"size": coarsening * size, "fine": coarsening * fine, "bar_h": bar_height},
        placement=like or "auto",
        refinements=refinements,
    )


#: Elements of the published model's refinement (HALL-HEROULT.md: solid and contact elements
#: of the quarter block, 5,225 s on a dual-core laptop): the issue's size is 100 times it.
PUBLISHED_ELEMENTS = 10_924


def elements(scene: sc.Scene) -> dict:
    """The scene's elements: tetrahedra per body, contact triangles per interface (global)."""
    tdim = scene.dim
    cells = {}
    for name, body in scene.bodies.items():
        mine = scene.is_local(name) and scene.group_comm.rank == 0  # counted once
        local = body.mesh.topology.index_map(tdim).size_global if mine else 0
        cells[name] = comm.allreduce(local, op=MPI.SUM)
    facets = {
        k: i.master_mesh.topology.index_map(tdim - 1).size_global
        for k, i in scene.interfaces.items()
    }
    total = sum(cells.values()) + sum(facets.values())
    return {
        "solid": cells,
        "contact": facets,
        "total": total,
        "times the published refinement": total / PUBLISHED_ELEMENTS,
    }


def route(name: str):
    """Newton's linear solver by name (``--linear``)."""
    if name.startswith("split"):
        options = sc.FIELDSPLIT_SINGLE if name == "split_single" else sc.FIELDSPLIT_DIRECT
        return sc.Monolithic(options, splits=sc.THERMOELECTRIC_MECHANICAL)
    return sc.Subdomains() if name == "subdomain" else sc.Monolithic()


def read(system: sc.System, result: sc.Result) -> dict:
    """What a slot designer reads off one solution."""
    summary = sc.summary(system)
    fields = sc.contact_fields(system)
    total = summary["groups"]["bar_end"]["current"]
    shares = {k: c["current"] for k, c in summary["contacts"].items()}
    joule_contacts = sum(c["Joule heat"] for c in summary["contacts"].values())
    generated = summary["balance"]["heat"]["generated"]
    t_max = {}
    for name in system.problem.scene.bodies:
        mine = name in system.bodies  # under mpiexec, a rank holds its own bodies
        local = np.max(system.bodies[name].nodal("temperature")[1], initial=0.0) if mine else 0.0
        t_max[name] = comm.allreduce(float(local), op=MPI.MAX)
    distributions = {}
    for k, f in fields.items():
        area = f["area"]
        flowing = np.abs(f["current density"]) > 0
        resistance = np.where(flowing, f["potential jump"], np.nan) / np.where(
            flowing, f["current density"], 1.0
        )
        distributions[k] = {
            "pressure [Pa]": stats(f["pressure"], area),
            "gap [m]": stats(f["gap"], area),
            "resistance [ohm m2]": stats(resistance, area),
            "current density [A/m2]": stats(f["current density"], area),
            "open area share": sc.open_share(f["gap"], area),
        }
    return {
        "voltage_drop_mV": 1e3 * sc.voltage_drop(system, "top", "bar_end"),
        "current_total_A": total,
        "contact_current_A": shares,
        "contact_current_share": {k: v / abs(total) for k, v in shares.items()},
        "max_temperature_K": t_max,
        "joule_W": {
            "total": generated,
            "contacts": joule_contacts,
            "bulk": generated - joule_contacts,
        },
        "balance": summary["balance"],
        "distributions": distributions,
        "dofs": system.num_dofs(),
        "newton_iterations": result.iterations,
        "line_search": result.line_search,
        "newton_steps_shortened": result.shortened,
        "inner_rounds": [s.inner_rounds for s in result.history[1:]],
        "residuals": result.relative_residuals().tolist(),
        # each field's residual 2-norm [W, A, N] where Newton stopped, and its scale: what
        # bounds the balances (a balance's imbalance sums that field's residual entries)
        "final_residual": dict(result.history[-1].fields),
        "newton_scale": dict(result.scale),
        "factorisations": result.factorisations,
        "seconds": result.seconds,
    }


def stats(values: np.ndarray, area: np.ndarray) -> dict:
    ok = np.isfinite(values)
    if not ok.any():
        return {"min": None, "mean": None, "max": None}
    return {
        "min": float(values[ok].min()),
        "mean": float(np.sum(values[ok] * area[ok]) / area[ok].sum()),
        "max": float(values[ok].max()),
    }


# ## Runs
#
# Each setup by Newton with the default settings: the subdomain iteration inside, then the
# monolithic Newton on the same discrete problem, each by nested iteration: Newton on a mesh
# 2^(levels-1) times coarser from the cold state (a uniform 300 K), then on each finer mesh
# from the solution before it, interpolated (`System.interpolate`). From the cold state full
# steps diverge on both routes, the iterates heating without bound, and Newton's steps are
# limited to 100 K of temperature change (`sc.newton.MAX_TEMPERATURE_STEP`): that climb, ten
# steps, is paid on the coarsest mesh alone. Measured, one rank, 65,900 DOFs, the subdomain
# Newton: from 300 K 18 steps, 178 s; nested from 5,595 and 17,335 DOFs, 8 full steps on the
# run's mesh, 82 s in all (benchmarks/bench_nested_slot.py); from the mesh 4 times coarser
# straight, full steps failed and the limited ones took 11. Then the design variant, a bar of
# 174 mm (2 mm of cast iron above it) in the same slot.
#
# The pressure setup starts from the constant one's solution on the same mesh and route (a
# continuation in the contact law), not from the cold state: its cold climb is the hardest
# solve of the demo, and on 2 ranks its path is set by the round-off of the parallel
# factorisations. Measured at --small (5,595 DOFs on the coarse mesh, the subdomain route,
# 2 ranks, 8 runs of one code): the limited steps took 24 to 36 of their 50, and in about
# one full test suite in ten more than 50, every line search failing after them (the raw
# Newton steps ask for 300 to 21,000 K where the law's slope β C/p is unbounded near an
# opening contact, each cut to 100 K). From the constant setup's state the climb is done:
# the contacts' pressures and the law's conductances are left to Newton's full steps.
START = 300.0  # K, the uniform initial temperature of the coarsest mesh
LEVELS = args.levels or (2 if args.small else 3)
#: Newton's tolerance on the run's mesh and in the mesh study, each field's residual
#: relative to its scale: the figures reported.
RTOL = 1e-10
#: Newton's tolerance on the coarser meshes of the nested iteration, whose solutions only
#: start the next mesh's Newton: their algebraic error is to stay far below the
#: discretisation error that the next mesh corrects (the voltage drop moves by 5e-4 of
#: itself from 205k to 1.14M DOFs). Newton converges quadratically there: measured, the
#: residual went 6.3e-3, 1.3e-6, 2.2e-13 at 49k DOFs and 1.3e-4, 2.5e-7, 6.2e-10, 3.7e-13
#: at 221k, so 1e-5 stops one and two steps before 1e-10 (17 s a step at 221k).
COARSE_RTOL = 1e-5


def solve_level(
    make,
    setup: str,
    coarse: sc.System | None,
    linear: str,
    rtol: float = RTOL,
    start: PETSc.Vec | None = None,
    **label,
) -> tuple:
    """Newton by ``linear`` to ``rtol`` on the system of ``make()`` (a system, or a scene to
    pose ``setup`` on): from the cold state, from the solution of ``coarse`` interpolated
    (``coarse`` destroyed then), or from ``start``, a state of another setup on the same
    scene: (system, result, entry).

    ``entry``: ``label``, then its DOFs, Newton's tolerance and steps, line search, time [s]
    (the build included) and voltage drop [mV].
    """
    tic = time.perf_counter()
    level = make()
    if isinstance(level, sc.Scene):
        level = sc.System(problem(level, setup))
    if start is not None:
        level.set_state(start)
    elif coarse is None:
        level.reset({"temperature": START})
    else:
        level.interpolate(coarse)
        coarse.destroy()
    solver = route(linear)
    result = sc.solve(level, solver, rtol=rtol, progress=True)
    solver.destroy()
    entry = label | {
        "dofs": sum(level.num_dofs().values()),
        "rtol": rtol,
        "newton_iterations": result.iterations,
        "line_search": result.line_search,
        "seconds": time.perf_counter() - tic,
        "voltage_drop_mV": 1e3 * sc.voltage_drop(level, "top", "bar_end"),
    }
    return level, result, entry


def nested(
    system: sc.System, setup: str, bar_height: float, linear: str, start: PETSc.Vec | None = None
):
    """Newton by ``linear`` on the coarser meshes, then on ``system``: (result, levels).
    From ``start`` (another setup's solution on ``system``'s scene), on ``system`` alone.

    ``levels``: per mesh, from the coarsest, its coarsening and :func:`solve_level`'s entry.
    ``split_single`` runs on the run's mesh alone, the coarser ones by ``split``: single
    precision is for the memory of the fine mesh, and from the cold state on 46k DOFs
    (--size 0.017 --fine 0.006) its GMRES broke down after 400 iterations where the limited
    steps heat the block.
    """
    levels, coarse = [], None
    if start is not None:
        _, result, entry = solve_level(lambda: system, setup, None, linear, start=start)
        say(f"  from the previous setup's solution: {result.iterations} Newton steps, "
            f"{entry['seconds']:.1f} s")  # fmt: skip
        return result, [entry | {"coarsening": 1.0, "start": "previous setup"}]
    for coarsening in [2.0**i for i in range(LEVELS - 1, 0, -1)] + [1.0]:
        like, fine = system.problem.scene, coarsening == 1.0
        make = (lambda: system) if fine else partial(load, bar_height, coarsening, like)
        here = "split" if linear == "split_single" and not fine else linear
        rtol = RTOL if fine else COARSE_RTOL
        level, result, entry = solve_level(
            make, setup, coarse, here, rtol=rtol, coarsening=coarsening
        )
        levels.append(entry)
        say(f"  mesh {coarsening:g} times coarser: {entry['dofs']} DOFs, "
            f"{result.iterations} Newton steps, {entry['seconds']:.1f} s")  # fmt: skip
        coarse = level
    return result, levels


runs: dict = {}
states: dict = {}
faces: dict = {}
HEIGHTS = (0.16,) if args.no_study else (0.16, 0.174)  # m, the bar's height
scenes = {}  # by the bar's height: the mesh study's meshes go on the base case's rank groups
for bar_height in HEIGHTS:
    scene = scenes[bar_height] = load(bar_height)
    for i, setup in enumerate(args.setups):
        system = sc.System(problem(scene, setup))
        linears = args.linear if bar_height == 0.16 else args.linear[:1]
        for linear in linears:
            tic = time.perf_counter()
            before = f"{args.setups[i - 1]}, bar {1e3 * bar_height:.0f} mm, {linear}" if i else ""
            result, levels = nested(system, setup, bar_height, linear, states.get(before))
            key = f"{setup}, bar {1e3 * bar_height:.0f} mm, {linear}"
            runs[key] = read(system, result) | {
                "wall_seconds": time.perf_counter() - tic,
                "nested": levels,
            }
            states[key] = system.state()
            say(
                f"{key}: {result.iterations} Newton steps ({result.line_search}) on the finest "
                f"mesh, {runs[key]['wall_seconds']:.1f} s in all, voltage drop "
                f"{runs[key]['voltage_drop_mV']:.2f} mV"
            )
        if bar_height == 0.16:
            faces[setup] = sc.contact_fields(system)
            sc.write_vtk(args.out / setup, system)
            if len(linears) == 2:
                a, b = (states[f"{setup}, bar 160 mm, {name}"] for name in linears)
                runs[f"{setup}, bar 160 mm, difference"] = system.difference(a, b)
        system.destroy()

for state in states.values():
    state.destroy()

# ## The design study: 174 mm against 160 mm
study = {}
for setup in args.setups if len(HEIGHTS) == 2 else ():
    base, variant = (runs[f"{setup}, bar {h} mm, {args.linear[0]}"] for h in (160, 174))
    study[setup] = {
        "voltage drop [mV]": [base["voltage_drop_mV"], variant["voltage_drop_mV"]],
        "change [mV]": variant["voltage_drop_mV"] - base["voltage_drop_mV"],
        "contact current share": {
            k: [base["contact_current_share"][k], variant["contact_current_share"][k]]
            for k in base["contact_current_share"]
        },
    }
    say(f"{setup}: voltage drop {base['voltage_drop_mV']:.2f} mV (160 mm) -> "
        f"{variant['voltage_drop_mV']:.2f} mV (174 mm)")  # fmt: skip

# ## Mesh convergence of the voltage drop
#
# The base case on nested meshes: a mesh of every element size 2^levels times the run's
# (twice as coarse as the nested iteration's coarsest) and its three uniform refinements
# (gmsh's `refine`, every tetrahedron split in 8: the sizes halve and the contacts stay
# conforming; the third has about the run's sizes), each solved from the one before, by the
# monolithic Newton with the field split (`split`: the discretisation is studied, not the
# routes, and this one needs the least time and memory: 419k DOFs in 6.2 GB a rank on 2
# ranks). Meshed anew at each size, the cast iron keeps its layers across its thickness
# and the DOFs grew 3.1 to 4.6 times per halving, too irregular for an order
# (docs/collector_bar_slot.md). The first refinement changes the cells' shapes
# (tests/test_thermal_contact.py), so the order is read on the three refined meshes:
# p = log₂((V₁ − V₂)/(V₂ − V₃)) and, where p > 0 (the differences shrink), the Richardson
# extrapolation V₃ + (V₃ − V₂)/(2^p − 1). Not at --small.
REFINEMENTS = 3
convergence = {}
for setup in () if args.no_study or args.small else args.setups:
    levels, coarse = [], None
    for refinements in range(REFINEMENTS + 1):
        make = partial(load, 0.16, 2.0**LEVELS, scenes[0.16], refinements)
        coarse, _, entry = solve_level(make, setup, coarse, "split", refinements=refinements)
        levels.append(entry)
        say(f"  mesh study, {setup}: {refinements} refinements, {entry['dofs']} DOFs, "
            f"{entry['voltage_drop_mV']:.4f} mV, {entry['seconds']:.1f} s")  # fmt: skip
    coarse.destroy()
    entry = {key: [level[key] for level in levels] for key in levels[0]}
    v1, v2, v3 = entry["voltage_drop_mV"][-3:]
    order = float(np.log2((v1 - v2) / (v2 - v3))) if (v1 - v2) * (v2 - v3) > 0 else None
    entry["observed order"] = order
    if order is not None and order > 0:  # differences that grow extrapolate nothing
        entry["extrapolated [mV]"] = v3 + (v3 - v2) / (2**order - 1)
    convergence[setup] = entry
    say(f"{setup}: voltage drop by mesh {entry['voltage_drop_mV']}, order "
        f"{entry.get('observed order')}")  # fmt: skip

# ## Time of the subdomain Newton over the monolithic one (each by its whole nested iteration,
# failed full-step attempts included)
ratios = {}
if set(args.linear) == {"subdomain", "monolithic"}:
    for setup in args.setups:
        sub, mono = (runs[f"{setup}, bar 160 mm, {n}"]["wall_seconds"] for n in args.linear)
        ratios[setup] = sub / mono if args.linear[0] == "subdomain" else mono / sub
        say(f"{setup}: subdomain / monolithic Newton time {ratios[setup]:.2f}")

# ## Current density and pressure on the slot's faces (the last setup run)
counted = elements(scenes[0.16])  # collective
say(f"elements: {counted['total']} ({counted['times the published refinement']:.1f} times the "
    f"published refinement's {PUBLISHED_ELEMENTS})")  # fmt: skip
if comm.rank == 0:
    fig, axes = plt.subplots(2, 2, figsize=(11, 6), sharex=True)
    for row, (k, across) in enumerate([("slot_side", 2), ("slot_top", 1)]):
        f = faces[args.setups[-1]][k]
        for col, (name, unit, scale) in enumerate(
            [("current density", "kA/m²", 1e-3), ("pressure", "MPa", 1e-6)]
        ):
            ax = axes[row, col]
            shown = ax.scatter(
                f["coordinates"][:, 0], f["coordinates"][:, across], c=scale * f[name], s=6
            )
            fig.colorbar(shown, ax=ax, label=f"{name} [{unit}]")
            ax.set_title(f"{k}: {name}")
            ax.set_ylabel("z [m]" if across == 2 else "y [m]")
    for ax in axes[1]:
        ax.set_xlabel("x along the block [m]")
    fig.tight_layout()
    fig.savefig(args.out / "slot_faces.png", dpi=120)
    started_from = f"uniform {START} K on the coarsest of {LEVELS} meshes (nested iteration) for "
    started_from += "; the solution of each for the next: ".join(args.setups)
    report = {
        "mesh": {"size": size, "fine": fine, "levels": LEVELS, "elements": counted},
        "ranks": comm.size,
        "boundary_conditions": {
            "top": f"T = {BATH} K, current density {CURRENT / TOP_AREA:.1f} A/m² in",
            "bar_end": "phi = 0",
            "lining (convection to 323.15 K)": LINING,
            "symmetry": "u_x = 0 on x = 0, u_y = 0 on y = 0; u_z = 0 on z = 0",
            "slip spring [Pa/m]": SLIP,
            "start": started_from,
        },
        "current_A": CURRENT,
        "runs": runs,
        "subdomain_over_monolithic_time": ratios,
        "design_study": study,
        "mesh_convergence": convergence,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1, default=float))
say(f"done in {time.perf_counter() - started:.1f} s; report in {args.out / 'report.json'}")
