# # A chain of eight bodies, seven of them floating
#
# Real assemblies have many bodies, and a body often touches several others. Here eight unit
# squares sit in a chain (`geo/stack.geo`): the first is held at 1 K on its left end, the last
# is cooled by convection on its right end, the top of every body loses a little heat, and
# the seven others touch nothing but contacts (they *float*: no temperature condition of
# their own). Conductivities cycle through 1, 10 and 0.1 W/(m K).
#
# It shows
#
# * **(a)** the interface problem solved as a whole: PETSc's CG on the masters of all seven
#   interfaces, preconditioned by the per-interface correctors and a coarse correction with
#   one unknown per body, for h from 1e-4 to 1e10 and four mesh refinements: the iterations
#   barely move with the mesh, and the solution equals the monolithic solve;
# * **(b)** what the paper's per-interface fixed point does on the same chain.
#
# Run `python demos/demo_stack.py` (`--small` for the test-sized version); under
# `mpiexec -n N` every body is spread over the N ranks. Output: `out_stack/report.json`,
# `iterations.png` and VTK files.

import argparse
import json
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import matplotlib
from mpi4py import MPI

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import subdomain_contact as sc
from verification.cases import stack, stack_scene
from verification.nodal import field_values, relative_nodal_error

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a few seconds, for the tests")
parser.add_argument("--out", type=Path, default=Path("out_stack"))
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


# ## (a) CG on every interface at once
#
# A refinement r gives each body 2r element layers and 2r rows. The tolerance is a master
# residual of 1e-10 of each interface's flux scale; the error is the relative nodal
# difference from the monolithic direct solve of the same discrete system (which itself
# loses digits as h grows: see the two-plate demo).

conductances = [1e-4, 1.0, 1e4, 1e10] if args.small else [1e-4, 1e-2, 1.0, 1e2, 1e4, 1e6, 1e8, 1e10]
refinements = [1, 2] if args.small else [1, 2, 4, 8]
correctors = [sc.Exact(), sc.Method1(), sc.Method2()]
krylov = []
for refinement in refinements:
    scene = stack_scene(8, 2 * refinement, 2 * refinement)
    for h in conductances:
        for corrector in correctors:
            with sc.System(stack(scene, h=h)) as system:
                linear = sc.Subdomains(corrector, krylov=True)
                tic = time.perf_counter()
                result = sc.solve(system, linear, rtol=1e-10)
                seconds = time.perf_counter() - tic
                inner = result.inner[-1]
                spaces, values = field_values(system)
                system.reset()  # from the cold state: Newton would find it converged
                reference = sc.solve(system, sc.Monolithic())
                krylov.append(
                    {
                        "h": h,
                        "refinement": refinement,
                        "corrector": corrector.name,
                        "dofs": sum(system.num_dofs().values()),
                        "iterations": sum(inner.krylov_iterations),
                        "krylov_iterations": inner.krylov_iterations,
                        "master_dofs": sum(system.sizes.values()),
                        "rounds": inner.rounds,
                        "relative_residual": inner.history[-1],
                        "error_vs_monolithic": relative_nodal_error(
                            spaces, values, field_values(system)[1]
                        ),
                        "seconds": seconds,
                        "monolithic_seconds": reference.seconds,
                    }
                )
            row = krylov[-1]
            say(
                f"r = {refinement}, h = {h:6.0e}, {corrector.name:7s}: CG {row['iterations']:3d}"
                f" its, residual {row['relative_residual']:.1e},"
                f" vs monolithic {row['error_vs_monolithic']:.1e}, {seconds:.2f} s"
            )

# ## (b) The paper's fixed point on the same chain
#
# Each interface corrected on its own (eqs. 5–8) with the exact corrector and the paper's
# methods, 300 rounds at most, coarsest mesh.

scene = stack_scene(8, 2, 2)
fixed_point = []
for h in conductances:
    for corrector in correctors:
        with sc.System(stack(scene, h=h)) as system:
            linear = sc.Subdomains(corrector, krylov=False, max_rounds=300)
            try:
                result = sc.solve(system, linear, rtol=1e-10)
                rounds, outcome = result.rounds, "converged"
            except (sc.NewtonConvergenceError, ValueError) as failure:
                result, rounds = getattr(failure, "result", None), None
                outcome = "diverged" if "diverged" in str(failure) else "not converged"
                if isinstance(failure, ValueError):
                    outcome = f"refused: {failure}"
        fixed_point.append(
            {
                "h": h,
                "corrector": corrector.name,
                "iterations": rounds,
                "outcome": outcome,
                "last_relative_residual": result.inner[-1].history[-1] if result else None,
            }
        )
        say(f"fixed point, h = {h:6.0e}, {corrector.name:7s}: {outcome} ({rounds} rounds)")

# ## Output

with sc.System(stack(stack_scene(8, 8, 8), h=1e4)) as system:
    sc.solve(system)
    sc.write_vtk(args.out, system)
    readback = sc.summary(system)

if comm.rank == 0:
    figure, axes = plt.subplots(figsize=(7, 4))
    for refinement in refinements:
        rows = [r for r in krylov if r["refinement"] == refinement and r["corrector"] == "exact"]
        axes.semilogx(
            [r["h"] for r in rows], [r["iterations"] for r in rows], "o-", label=f"r = {refinement}"
        )
    axes.set_xlabel("contact conductance h [W/(m² K)]")
    axes.set_ylabel("CG iterations to 1e-10")
    axes.set_title("8-body chain, exact correctors + coarse space")
    axes.legend()
    figure.tight_layout()
    figure.savefig(args.out / "iterations.png", dpi=120)
    report = {
        "krylov": krylov,
        "fixed_point": fixed_point,
        "readback": readback,
        "ranks": comm.size,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
say(f"wrote {args.out}/report.json in {time.perf_counter() - started:.1f} s")
