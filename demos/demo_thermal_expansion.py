# # Two blocks between walls, heated then cooled: a contact that closes, then opens
#
# Two blocks stand in a row between two fixed walls, with a gap of 0.1 mm between them. Heated,
# they expand, close the gap and press on each other; cooled below their reference temperature
# they shrink and the contact opens again. Each block is its own mesh with a temperature and a
# displacement field; the contact's master layer carries the temperature and the normal
# displacement, with a unilateral penalty law (no tension) and free sliding.
#
# It shows the contact pressure against its closed form while closed, zero pressure and the
# right gap while open, the Newton iterations of each load step (the contact status changes
# within Newton), and Newton with the subdomain iteration inside against the monolithic
# Newton at the hottest step.
#
# ## The problem
#
# $-\nabla\cdot(k\nabla T) = 0$ with T prescribed at both walls (so T is uniform),
# $-\nabla\cdot\boldsymbol\sigma = 0$ with $\boldsymbol\sigma = \lambda\,\mathrm{tr}\,\varepsilon\,I
# + 2\mu\varepsilon - (3\lambda + 2\mu)\alpha(T - T_{ref}) I$ (plane strain), u_x = 0 at both
# walls, rollers at the bottom, free top. Blocks of 0.5 m × 0.2 m, steel-like (E = 200 GPa,
# ν = 0.3, α = 1.2e-5 /K); contact stiffness k_n = 1e13 Pa/m.
#
# Run `python demos/demo_thermal_expansion.py` (`--small` for the test-sized version). Output
# goes to `out_thermal_expansion/`: `report.json` (with each step's reactions and balances),
# `steps.md`, `pressure.png`, VTK files of the hottest and the coldest states (`hot/scene.pvd`,
# `cold/scene.pvd`) and their pictures `hot.png`, `cold.png` (displacement as arrows).

import argparse
import json
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import matplotlib
from mpi4py import MPI

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import subdomain_contact as sc
from subdomain_contact.physics import Contact, Displacement, Material, Penalty, Problem, Temperature
from verification.analytic import BlocksBetweenWalls
from verification.cases import GEO

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a few seconds, for the tests")
parser.add_argument("--out", type=Path, default=Path("out_thermal_expansion"))
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


layers, rows = (4, 2) if args.small else (40, 16)
length, height, contact_x = 0.5, 0.2, 0.5
scene = sc.load_scene(
    GEO / "two_plates.geo",
    bodies=["plate_A", "plate_B"],
    interfaces=["contact"],
    parameters={"layers": layers, "rows": rows, "length": length, "height": height},
)
E, nu, alpha, T_ref, gap, k_n = 200e9, 0.3, 1.2e-5, 300.0, 1e-4, 1e13
steel = Material(
    conductivity=45.0, young=E, poisson=nu, expansion=alpha, reference_temperature=T_ref
)
contact = Contact(conductance=1e4, normal=Penalty(k_n), gap=gap)
exact = BlocksBetweenWalls((length, length), (E, E), (nu, nu), (alpha, alpha), gap, k_n)


def problem_at(temperature: float) -> Problem:
    """Both walls at ``temperature``; u_x = 0 at the walls, rollers at the bottom."""
    return Problem(
        scene,
        {"plate_A": steel, "plate_B": steel},
        {"contact": contact},
        [
            Temperature("left", temperature),
            Temperature("right", temperature),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, 0.0),
            Displacement("bottom", 1, 0.0),
        ],
    )


def mean_at_contact(system, name: str) -> float:
    """Mean u_x [m] of a block's nodes on the contact (from the ranks that hold the block)."""
    local = np.zeros(2)
    if name in system.bodies:  # under mpiexec each block is on its own ranks
        points, values = system.bodies[name].nodal("displacement", 0)
        on = np.isclose(points[:, 0], contact_x)
        local = np.array([values[on].sum(), on.sum()])
    total = comm.allreduce(local, op=MPI.SUM)
    return total[0] / total[1]


# ## Heating, then cooling
#
# Each step changes the wall temperature and runs Newton from the previous step's state: the
# contact closes between 300 K and 325 K and opens again below about 306 K.

schedule = [300.0, 325.0, 350.0, 400.0, 350.0, 300.0, 250.0]
if args.small:
    schedule = [300.0, 350.0, 250.0]
steps = []
system = None
for temperature in schedule:
    previous = None if system is None else system.state()
    if system is not None:
        system.destroy()
    system = sc.System(problem_at(temperature))
    if previous is None:
        system.reset({"temperature": T_ref})
    else:
        system.set_state(previous)  # same layout: the same scene and fields
        previous.destroy()
    result = sc.solve(system, rtol=1e-12)
    readback = sc.summary(system)  # the discrete reactions: exact balances
    pressure = readback["contacts"]["contact"]["force"][0] / height
    closure = mean_at_contact(system, "plate_A") - mean_at_contact(system, "plate_B")
    heating = temperature - T_ref
    row = {
        "temperature": temperature,
        "pressure": pressure,
        "exact_pressure": exact.pressure(heating),
        "gap": gap - closure,
        "exact_gap": exact.gap_width(heating),
        "state": "closed" if exact.pressure(heating) > 0 else "open",
        "newton_iterations": result.iterations,
        "inner_rounds": [s.inner_rounds for s in result.history[1:]],
        "residuals": [s.residual for s in result.history],
        "seconds": result.seconds,
        "readback": readback,
    }
    row["pressure_error"] = abs(pressure - row["exact_pressure"]) / max(row["exact_pressure"], 1.0)
    row["gap_error"] = abs(row["gap"] - row["exact_gap"]) / abs(row["exact_gap"])
    steps.append(row)
    say(
        f"T = {temperature:5.1f} K ({row['state']:6s}): p = {pressure:.6e} Pa "
        f"(exact {row['exact_pressure']:.6e}), gap = {row['gap']:.6e} m "
        f"(exact {row['exact_gap']:.6e}), Newton {result.iterations}, inner rounds "
        f"{row['inner_rounds']}"
    )
    if temperature == max(schedule) and row is steps[schedule.index(temperature)]:
        sc.write_vtk(args.out / "hot", system)
sc.write_vtk(args.out / "cold", system)
system.destroy()
if comm.rank == 0:  # what ParaView shows: the hot state pressed, the cold one open
    for state in ("hot", "cold"):
        sc.plot_vtk(args.out / state / "scene.pvd", args.out / f"{state}.png", title=state)

# ## The same hot step by the monolithic Newton
#
# The subdomain Newton and the monolithic Newton solve the same discrete problem from the same
# start; they must agree to solver precision.

system = sc.System(problem_at(max(schedule)))
states = {}
for linear, solver in [("subdomain", sc.Subdomains()), ("monolithic", sc.Monolithic())]:
    system.reset({"temperature": T_ref})
    sc.solve(system, solver, rtol=1e-12)
    states[linear] = system.state()
difference = system.difference(states["subdomain"], states["monolithic"])
say(f"hot step, subdomain vs monolithic Newton, max relative difference: {difference}")
dofs = system.num_dofs()  # collective: every rank

if comm.rank == 0:
    lines = [
        "| T [K] | state | p [Pa] | exact p [Pa] | gap [m] | exact gap [m] | Newton |",
        "|---|---|---|---|---|---|---|",
    ] + [
        f"| {r['temperature']:.0f} | {r['state']} | {r['pressure']:.6e} | "
        f"{r['exact_pressure']:.6e} | {r['gap']:.6e} | {r['exact_gap']:.6e} | "
        f"{r['newton_iterations']} |"
        for r in steps
    ]
    (args.out / "steps.md").write_text("\n".join(lines) + "\n")
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(range(len(steps)), [r["pressure"] / 1e6 for r in steps], "o-", label="computed")
    ax.plot(range(len(steps)), [r["exact_pressure"] / 1e6 for r in steps], "x--", label="exact")
    ax.set_xticks(range(len(steps)), [f"{r['temperature']:.0f}" for r in steps])
    ax.set_xlabel("wall temperature [K], in load order")
    ax.set_ylabel("contact pressure [MPa]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / "pressure.png", dpi=120)
    report = {
        "steps": steps,
        "monolithic_difference": difference,
        "dofs": dofs,
        "ranks": comm.size,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
say(f"wrote {args.out}/ in {time.perf_counter() - started:.1f} s")
