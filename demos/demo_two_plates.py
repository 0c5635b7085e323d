# # Two plates in thermal contact, solved plate by plate
#
# This demo reproduces the numerical study of Ramadane, Fafard, Marceau and Melançon (2005):
# two plates side by side (their figure 2) exchange heat through a contact of conductance
# `h`. Each plate is its own mesh and its own linear system; they meet only through a master
# layer on the contact, and the master temperatures are corrected until the heat leaving one
# plate enters the other.
#
# It shows
#
# * **(a)** the paper's table 1: method 2 with accelerated partial condensation (one condensed
#   layer, factor X), h = 1e6, on meshes of 2, 4, 8 and 16 element layers per plate;
# * **(b)** a sweep of h from 1e-8 to 1e12 with every corrector (method 1, method 2, partial
#   condensation, and the exact corrector), each checked against the closed-form
#   solution and against the monolithic solve of the same discrete system;
# * **(c)** where partial condensation stops working;
# * **(d)** partitioned Dirichlet–Neumann and Robin–Robin couplings (constant relaxation,
#   Aitken, IQN-ILS) on the same problem, for comparison.
#
# ## The problem
#
# $-\nabla\cdot(k \nabla T) = 0$ in each plate of length 1 m and height 1 m, $T = 1$ K at
# $x = 0$, $T = 0$ at $x = 2$, insulated long sides, and $q = h (T_A - T_B)$ across the
# contact. The exact temperature is piecewise linear with a jump $q/h$; P1 elements
# reproduce it at the nodes, so any error is the solver's.
#
# Run `python demos/demo_two_plates.py` (add `--small` for the test-sized version). Output
# goes to `out_two_plates/`: `report.json`, `sweep.md` (rounds per corrector and errors against
# the exact solution), `iterations_vs_h.png` and VTK files for ParaView.

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
from subdomain_contact.partitioned import (
    ACCELERATIONS,
    solve_dirichlet_neumann,
    solve_robin_robin,
)
from verification.cases import two_plates, two_plates_scene
from verification.nodal import error_against, field_values, relative_nodal_error

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a few seconds, for the tests")
parser.add_argument("--out", type=Path, default=Path("out_two_plates"))
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


def subdomains(problem, corrector=None, **options):
    """Solve by the subdomain iteration, the paper's fixed point: (system, rounds, history).

    The system holds the solution (or the last iterate); rounds is None where the corrector
    did not converge.
    """
    rtol = options.pop("rtol", 1e-10)
    system = sc.System(problem)
    linear = sc.Subdomains(corrector, krylov=False, **options)
    try:
        result = sc.solve(system, linear, rtol=rtol)
        return system, result.rounds, result.inner[-1].history
    except sc.NewtonConvergenceError as failure:
        return system, None, failure.result.inner[-1].history


# ## (a) The paper's table 1
#
# Method 2 with partial condensation on one element layer next to the contact, the DOFs
# beyond it clamped, and the condensed term scaled by X (eq. 9). The paper's X comes from its
# eq. (10) for a mesh of step H/2^n with H = half a plate, n = 0..3. A round is one solve of
# every plate; "2 rounds" is one correction and the check.

table1 = []
for n, layers in enumerate([2, 4, 8, 16][: 2 if args.small else 4]):
    X = sc.paper_factor(n, layers=1)
    case = two_plates(two_plates_scene(layers, layers), h=1e6)
    with sc.System(case.problem) as system:
        corrector = sc.PartialCondensation(layers=1, factor=X)
        result = sc.solve(system, sc.Subdomains(corrector, krylov=False), rtol=1e-6)
    history = result.inner[-1].history
    table1.append({"layers": layers, "X": X, "iterations": result.rounds, "history": history})
    say(f"table 1: {layers:2d} layers, X = {X:.4g}: {result.rounds} rounds {history}")

# ## (b) Sweep over the contact conductance
#
# One mesh, every decade of h, every corrector. Each row records the rounds to a master
# residual of 1e-10 of the flux scale (null when the corrector does not get there in 100
# rounds), the relative nodal error against the exact solution and against the monolithic
# solve, and the wall time (set-up of the corrector and iteration).

layers = 4 if args.small else 8
scene = two_plates_scene(layers, layers, placement="shared")  # the partitioned couplings too
exponents = range(-8, 13, 4) if args.small else range(-8, 13)
correctors = [
    sc.Method1(),
    sc.Method2(),
    sc.PartialCondensation(layers=1, factor=sc.paper_factor(int(np.log2(layers)) - 1)),
    sc.Exact(),
]
sweep, monolithic = [], []
for e in exponents:
    h = 10.0**e
    case = two_plates(scene, h=h)
    for corrector in correctors:
        tic = time.perf_counter()
        system, rounds, history = subdomains(case.problem, corrector, max_rounds=100)
        seconds = time.perf_counter() - tic
        spaces, values = field_values(system)
        error = error_against(system, case.exact_by_body)
        tic = time.perf_counter()
        system.reset()  # from the cold state: Newton would find it converged
        reference = sc.solve(system, sc.Monolithic())
        sweep.append(
            {
                "h": h,
                "corrector": corrector.name,
                "iterations": rounds,
                "max_error_vs_analytic": error,
                "max_error_vs_monolithic": relative_nodal_error(
                    spaces, values, field_values(system)[1]
                ),
                "seconds": seconds,
                "history": history,
            }
        )
        monolithic_error = error_against(system, case.exact_by_body)
        monolithic_seconds = time.perf_counter() - tic
        system.destroy()
        say(
            f"h = {h:7.0e} {corrector.name:8s}: rounds {rounds}, "
            f"error {sweep[-1]['max_error_vs_analytic']:.2e}, {seconds:.3f} s"
        )
    monolithic.append(
        {"h": h, "max_error_vs_analytic": monolithic_error, "seconds": monolithic_seconds}
    )

# ## (c) Where accelerated partial condensation stops working
#
# X corrects only the interface mode that is uniform along the contact. Cool the top of both
# plates by convection (5 W/(m² K) to 2 K): the master temperature now varies along the
# contact, and partial condensation needs many more rounds, while method 2 and the exact
# corrector do not notice.

limits = []
for quads in (True, False):
    scene_c = two_plates_scene(layers, layers, quads=quads)
    base = two_plates(scene_c, h=1e6).problem
    cooled = sc.Problem(
        scene_c, base.materials, base.contacts, [*base.conditions, sc.Convection("top", 5.0, 2.0)]
    )
    for corrector in correctors[1:]:
        system, rounds, _ = subdomains(cooled, corrector, max_rounds=200)
        system.destroy()
        limits.append(
            {
                "cells": "quadrilaterals" if quads else "triangles",
                "corrector": corrector.name,
                "iterations": rounds,
            }
        )
        say(f"top cooled, {limits[-1]['cells']}, {corrector.name}: {rounds} rounds")

# ## (d) Partitioned couplings, as a coupling library would run them
#
# The alternative a user would otherwise pick: the plates as two solvers exchanging interface
# data, plate A then plate B, two solves per iteration: Dirichlet–Neumann (A takes the heat
# as a Neumann datum, B takes A's temperature through the contact) and Robin–Robin (both
# take the other's temperature through the contact), each with constant relaxation ω = 0.5,
# Aitken's dynamic relaxation or IQN-ILS (quasi-Newton), to a relative interface change of
# 1e-10 and a heat balance of 1e-6. Uniform: the plates of (b), against the exact solution.
# Cooled: the top cooled as in (c), the data varying along the contact, against the exact
# corrector's solve.

partitioned = []
couplings = {"Dirichlet-Neumann": solve_dirichlet_neumann, "Robin-Robin": solve_robin_robin}
for variant in ("uniform", "cooled"):
    for e in range(-2, 11, 6 if args.small else 2):
        h = 10.0**e
        case = two_plates(scene, h=h)
        problem = case.problem
        if variant == "cooled":
            extra = [*problem.conditions, sc.Convection("top", 5.0, 2.0)]
            problem = sc.Problem(scene, problem.materials, problem.contacts, extra)
            system, _, _ = subdomains(problem, rtol=1e-12)
            reference = field_values(system)[1]
            system.destroy()
        else:
            reference = case.exact_by_body
        for coupling, couple in couplings.items():
            for acceleration in ACCELERATIONS:
                result = couple(problem, acceleration=acceleration, max_iterations=200)
                spaces = {n: T.function_space for n, T in result.temperatures.items()}
                values = {n: T.x.array for n, T in result.temperatures.items()}
                error = relative_nodal_error(spaces, values, reference)
                partitioned.append(
                    {
                        "variant": variant,
                        "h": h,
                        "coupling": coupling,
                        "acceleration": acceleration,
                        "iterations": result.iterations if result.converged else None,
                        "diverged": result.diverged,
                        "balance": result.balance,
                        "max_error": error,
                        "seconds": result.seconds,
                    }
                )
                say(
                    f"{variant} h = {h:7.0e} {coupling} + {acceleration:8s}: "
                    f"{partitioned[-1]['iterations']} iterations, error {error:.1e}, "
                    f"balance {result.balance:.1e}"
                )

# ## Output
#
# VTK of the converged solve at h = 1e6 (each plate and the master layer), the iteration
# plot, and the report.

case = two_plates(scene, h=1e6)
with sc.System(case.problem) as system:
    sc.solve(system)
    sc.write_vtk(args.out, system)
    dofs = system.num_dofs()
    readback = sc.summary(system)

if comm.rank == 0:
    figure, axes = plt.subplots(figsize=(7, 4))
    styles = ["o-", "s--", "^:", "D-"]  # method 2 and partial overlap on this uniform case
    for corrector, style in zip(correctors, styles, strict=True):
        rows = [r for r in sweep if r["corrector"] == corrector.name]
        rounds = [np.nan if r["iterations"] is None else r["iterations"] for r in rows]
        axes.semilogx([r["h"] for r in rows], rounds, style, label=corrector.name, fillstyle="none")
    axes.set_xlabel("contact conductance h [W/(m² K)]")
    axes.set_ylabel("rounds to 1e-10 (gaps: > 100)")
    axes.set_yscale("log")
    axes.set_title(f"Two plates, {layers} layers per plate")
    axes.legend()
    figure.tight_layout()
    figure.savefig(args.out / "iterations_vs_h.png", dpi=120)
    report = {
        "table1": table1,
        "sweep": sweep,
        "monolithic": monolithic,
        "partial_condensation_limits": limits,
        "partitioned": partitioned,
        "dofs": dofs,
        "readback": readback,
        "ranks": comm.size,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
    lines = [
        "| h | " + " | ".join(c.name for c in correctors) + " | exact error | monolithic error |"
    ]
    lines.append("|---" * (len(correctors) + 3) + "|")
    for m in monolithic:
        rows = {r["corrector"]: r for r in sweep if r["h"] == m["h"]}
        rounds = [str(rows[c.name]["iterations"] or "> 100") for c in correctors]
        error = rows["exact"]["max_error_vs_analytic"]
        lines.append(
            f"| {m['h']:.0e} | "
            + " | ".join(rounds)
            + f" | {error:.1e} | {m['max_error_vs_analytic']:.1e} |"
        )
    (args.out / "sweep.md").write_text("\n".join(lines) + "\n")
    lines = [
        "| variant | h | exact | "
        + " | ".join(f"{c[0]}{c.split('-')[1][0]} {a}" for c in couplings for a in ACCELERATIONS)
        + " |"
    ]
    lines.append("|---" * (3 + len(couplings) * len(ACCELERATIONS)) + "|")
    for variant in ("uniform", "cooled"):
        for h in sorted({r["h"] for r in partitioned}):
            mine = [r for r in partitioned if r["variant"] == variant and r["h"] == h]
            cells = [
                "-" if r["iterations"] is None else f"{r['iterations']} ({r['max_error']:.0e})"
                for r in mine
            ]
            exact_rounds = next(
                (r["iterations"] for r in sweep if r["corrector"] == "exact" and r["h"] == h), 2
            )
            lines.append(f"| {variant} | {h:.0e} | {exact_rounds} | " + " | ".join(cells) + " |")
    (args.out / "partitioned.md").write_text("\n".join(lines) + "\n")
say(f"wrote {args.out}/report.json in {time.perf_counter() - started:.1f} s")
