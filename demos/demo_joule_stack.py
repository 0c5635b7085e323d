# # Current through two bars and their contact: Newton outside, subdomains inside
#
# Two bars side by side carry a current from x = 0 to their far end through one contact, the
# setting of the electrical preheating of a Hall–Héroult cell in miniature. Each bar is its
# own mesh with its own fields (temperature, potential, and in part (b) displacement); they
# meet only through the master layer on the contact.
#
# It shows
#
# * **(a)** constant laws: the computed temperature, potential and total current against the
#   closed-form 1D solution (Joule heat σ|∇φ|² in the bars, g Δφ² in the contact, half into
#   each side);
# * **(b)** the fully coupled case: conductivities k(T), σ(T) (a law and a table), thermal
#   expansion, the bars squeezed between two walls, a contact pressure p from a nonlinear
#   closure law, and contact conductances h(p, T) (a power law of pressure times a
#   temperature factor) and g(p, T) (a table in p and T). Newton with the subdomain iteration
#   inside is checked against Newton with a direct solve of the merged system, and its
#   residual history shows quadratic convergence.
#
# ## The problem
#
# $-\nabla\cdot(k\nabla T) = \sigma|\nabla\phi|^2$, $-\nabla\cdot(\sigma\nabla\phi) = 0$,
# $-\nabla\cdot\boldsymbol\sigma(u, T) = 0$ (plane strain, thermal strain α(T − T_ref)).
# Bars of 0.5 m × 0.1 m; φ = 0.5 V at x = 0 and 0 V at x = 1 m; T fixed at both ends.
#
# Run `python demos/demo_joule_stack.py` (`--small` for the test-sized version). Output goes
# to `out_joule_stack/`: `report.json` (with the currents, heats, forces and balances),
# `newton.png` (residual per Newton iteration), VTK files for ParaView (`scene.pvd` opens
# the bars, their displacements and the contact with its fields) and `coupled.png`, the
# coupled state as ParaView shows it (temperature, displacement as arrows).

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
from verification.cases import GEO, joule_bars, squeezed_joule_bars
from verification.taylor import jacobian_orders_toward

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a few seconds, for the tests")
parser.add_argument("--out", type=Path, default=Path("out_joule_stack"))
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


layers, rows = (4, 2) if args.small else (64, 12)
scene = sc.load_scene(
    GEO / "two_plates.geo",
    bodies=["plate_A", "plate_B"],
    interfaces=["contact"],
    parameters={"layers": layers, "rows": rows, "length": 0.5, "height": 0.1},
)
height, voltage = 0.1, 0.5

# ## (a) Constant laws against the closed form
#
# Bar A: k = 10 W/(m K), σ = 1e4 S/m; bar B: k = 50, σ = 3e4; contact h = 2e3 W/(m² K),
# g = 5e4 S/m²; T = 300 K at x = 0 and 320 K at x = 1 m. The exact potential is piecewise
# linear and the exact temperature piecewise quadratic, both reproduced by P1 at the nodes.

constant, exact = joule_bars(scene, voltage=voltage)
system = sc.System(constant)
system.reset({"temperature": 300.0})
newton = sc.solve(system, rtol=1e-12)
truth = {
    "plate_A": {"temperature": exact.thermal.temperature_a, "potential": exact.potential_a},
    "plate_B": {"temperature": exact.thermal.temperature_b, "potential": exact.potential_b},
}
errors = {}
for field in ("temperature", "potential"):
    worst, scale = 0.0, 0.0
    for name, body in system.bodies.items():
        points, values = body.nodal(field)
        reference = truth[name][field](points[:, 0])
        worst = max(worst, np.max(np.abs(values - reference), initial=0.0))
        scale = max(scale, np.max(np.abs(reference), initial=0.0))
    errors[field] = comm.allreduce(worst, op=MPI.MAX) / comm.allreduce(scale, op=MPI.MAX)
current = sc.current(system, "contact")
exact_current = exact.current_density * height
errors["current"] = abs(current - exact_current) / exact_current
say(f"(a) Newton {newton.iterations} iterations:\n{newton.table()}")
say(f"(a) relative nodal errors {errors}; current {current:.6g} A/m (exact {exact_current:.6g})")
part_a = {
    "errors": errors,
    "current": current,
    "exact_current": exact_current,
    "newton": [s.residual for s in newton.history],
    "inner_rounds": [s.inner_rounds for s in newton.history],
    "dofs": system.num_dofs(),
    "readback": sc.summary(system),
}
sc.write_vtk(args.out / "constant", system)
system.destroy()

# ## (b) Pressure- and temperature-dependent laws, all fields coupled
#
# The walls hold x = 0 and push x = 1 m in by 20 µm; the bottom slides on rollers. Bar A is a
# carbon-like material whose k and σ grow with T; bar B a steel-like one whose σ falls. The
# closure law is stiffening; h grows with pressure (power law) and temperature, g is
# tabulated in p and T (`cases.squeezed_joule_bars`, shared with the tests and the benchmark).
# Newton starts from 300 K and everything else zero.

coupled = squeezed_joule_bars(scene)  # its laws, written out: subdomain_contact/cases.py
system = sc.System(coupled)
runs, states = {}, {}
for linear, solver in [("monolithic", sc.Monolithic()), ("subdomain", sc.Subdomains())]:
    system.reset({"temperature": 300.0})
    result = sc.solve(system, solver, rtol=1e-12)
    states[linear] = system.state()
    runs[linear] = {
        "iterations": result.iterations,
        "residuals": [s.residual for s in result.history],
        "fields": [s.fields for s in result.history],
        "inner_rounds": [s.inner_rounds for s in result.history],
        "relative_residuals": result.relative_residuals().tolist(),
        "seconds": result.seconds,
    }
    say(f"(b) {linear}: {result.iterations} Newton iterations, {result.seconds:.2f} s")
    say(result.table())
difference = system.difference(states["subdomain"], states["monolithic"])
readback = sc.summary(system)
pressure = readback["contacts"]["contact"]["mean pressure"]
current = readback["contacts"]["contact"]["current"]
T_max = comm.allreduce(
    max(np.max(b.nodal("temperature")[1], initial=0.0) for b in system.bodies.values()),
    op=MPI.MAX,
)
say(f"(b) subdomain vs monolithic, max relative difference per field: {difference}")
# Newton is quadratic where its Jacobian is exact: the Taylor remainder of the residual at
# the solution, along the way back to the 300 K start, falls 4 times per halving of ε.
taylor = jacobian_orders_toward(system, states["monolithic"], {"temperature": 300.0})
say(f"(b) Jacobian check, Taylor remainder orders per halving of ε: {taylor}")
say(f"(b) mean contact pressure {pressure:.4g} Pa, current {current:.5g} A/m, T max {T_max:.5g} K")
sc.write_vtk(args.out, system)
part_b = {
    "runs": runs,
    "difference": difference,
    "jacobian_taylor_orders": taylor,
    "mean_pressure": pressure,
    "current": current,
    "max_temperature": T_max,
    "dofs": system.num_dofs(),
    "readback": readback,
}

if comm.rank == 0:
    fig, ax = plt.subplots(figsize=(6, 4))
    for linear, run in runs.items():
        style = "o-" if linear == "subdomain" else "x--"
        ax.semilogy(run["relative_residuals"], style, label=linear)
    ax.set_xlabel("Newton iteration")
    ax.set_ylabel("max over fields of residual / its scale")
    ax.set_title("(b) coupled bars: Newton outside")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / "newton.png", dpi=120)
    sc.plot_vtk(args.out / "scene.pvd", args.out / "coupled.png", title="(b) coupled bars")
    report = {
        "constant_laws": part_a,
        "coupled": part_b,
        "ranks": comm.size,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
say(f"wrote {args.out}/ in {time.perf_counter() - started:.1f} s")
