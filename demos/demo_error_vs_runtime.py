# # Error against run time: every method on the same discrete problems
#
# A user choosing between this code, a monolithic solver and a partitioned coupling tool wants
# to see, on one problem, what accuracy each approach reaches for what time. This demo runs
# every method on the same discrete systems and records, iteration by iteration, the wall
# time and the error against the best available reference:
#
# * **monolithic MUMPS** (one direct solve of the merged system) and **monolithic CG + GAMG**;
#   under `mpiexec`, PETSc's **BDDC** with deluxe scaling on the unassembled system (one
#   subdomain per rank, the master layers its interface);
# * the **subdomain iteration** with each corrector (exact, method 1, method 2, partial
#   condensation) and **interface CG** preconditioned by partial condensation;
# * the **partitioned couplings** a preCICE user would pick: Dirichlet–Neumann and
#   Robin–Robin, each with constant relaxation (ω = 0.5), Aitken and IQN-ILS;
# * for the multiphysics scene, **Newton** with a monolithic MUMPS or GMRES + GAMG linear
#   solve, or with the subdomain iteration inside (exact or method-1 corrector).
#
# Problems: the two plates (top cooled so that the temperature varies along the contact,
# k = 1 and 10 W/(m K), h = 1e3 W/(m² K)) up to about a million DOFs; the 8-body stack
# (floating bodies); the squeezed Joule bars (temperature, potential, displacement, p- and
# T-dependent laws); and two blocks in 3D (tetrahedra).
#
# The reference of a thermal problem is the monolithic MUMPS solve polished by two steps of
# iterative refinement; of the multiphysics one, monolithic Newton to a relative residual of
# 1e-13. Error: max nodal |u − u_ref| over all bodies / range of u_ref (multiphysics: the
# worst field). Time: wall time from the assembly of the bodies to the iterate, the time
# spent measuring errors excluded. Peak memory: the growth of the resident set (VmHWM) during
# the method, summed over ranks. Under `mpiexec -n 2` the subdomain methods give each body
# its own rank (`placement="groups"`); monolithic and partitioned solves spread every body
# over both ranks.
#
# Run `python demos/demo_error_vs_runtime.py` (about an hour on one core; `--small` for
# the tests). Output in `out_error_vs_runtime/`: `iterations.csv` (every iterate),
# `summary.csv`, `results.md` (time to 1e-8 as a ratio to MUMPS, scaling exponents),
# `error_vs_time_<problem>.png`, `time_vs_dofs.png` and `report.json`. `--from-csv DIR`
# rewrites the table and the plots from the CSV of an earlier run, without running anything.

import argparse
import csv
import ctypes
import gc
import json
import time
from contextlib import contextmanager
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import matplotlib
import numpy as np
from mpi4py import MPI

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from petsc4py import PETSc

import subdomain_contact as sc
from subdomain_contact.partitioned import solve_dirichlet_neumann, solve_robin_robin
from verification.cases import (
    bars_scene,
    blocks3d_scene,
    heated_blocks,
    squeezed_joule_bars,
    stack,
    stack_scene,
    two_plates,
    two_plates_scene,
)
from verification.nodal import NodalReference, field_values, relative_nodal_error

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a minute, for the tests")
parser.add_argument("--out", type=Path, default=Path("out_error_vs_runtime"))
parser.add_argument(
    "--problems", nargs="+", default=["two_plates", "stack", "joule_bars", "blocks3d"]
)
parser.add_argument("--max-dofs", type=float, default=1.1e6, help="skip larger meshes")
parser.add_argument(
    "--from-csv", type=Path, help="no runs: rewrite the table and plots from this folder's CSV"
)
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()
TARGET = 1e-8  # the error the time ratios are quoted at
placement = "groups" if comm.size > 1 else "shared"


def say(*text: object) -> None:
    if comm.rank == 0:
        print(*text, flush=True)


# ## Measuring: a clock that stops while errors are measured, and the peak resident set


class Trace:
    """Iterates of one method: (iteration, seconds, error), the clock paused for the error.

    ``error`` maps what the method's monitor passes to the error; a method sets it once it
    knows its spaces (inside :meth:`pause`).
    """

    def __init__(self) -> None:
        self.error, self.points = None, []
        comm.Barrier()
        self.start, self.paused = time.perf_counter(), 0.0

    def now(self) -> float:
        return time.perf_counter() - self.start - self.paused

    @contextmanager
    def pause(self):
        stopped = time.perf_counter()
        yield
        self.paused += time.perf_counter() - stopped

    def record(self, iteration: int, state) -> None:
        """Keep the error of ``state()`` (the time to compute the state is not counted)."""
        seconds = self.now()
        with self.pause():
            self.points.append((iteration, seconds, self.error(state())))


def reset_peak_memory() -> float:
    """Reset this process's VmHWM to its current resident set; return that set [MB].

    What earlier methods left to petsc4py is destroyed first, and the memory it freed is
    handed back to the system (``malloc_trim``), so that a method's growth is neither hidden
    by heap the allocator kept nor offset by its predecessor's factorisations freed during it.
    """
    gc.collect()
    PETSc.garbage_cleanup(comm)
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return float("nan")
    return _status("VmRSS")


def _status(key: str) -> float:
    """A /proc/self/status entry [MB] (NaN where there is none)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key):
                return float(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


rows: list[dict] = []  # one per (problem, size, method)
readbacks: dict[str, dict] = {}  # the reference solve's integrals and balances, per size
iterates: list[dict] = []  # one per iterate


def run(problem: str, dofs: int, method: str, solve) -> None:
    """Run ``solve(trace)``; keep its iterates, its summary and its failure, if any."""
    base = reset_peak_memory()
    trace = Trace()
    try:
        note = solve(trace) or ""
    except (RuntimeError, ValueError) as failure:  # kept in the table: never silent
        note = str(failure).splitlines()[0][:100]
    seconds = trace.now()
    peak = comm.allreduce(_status("VmHWM") - base, op=MPI.SUM)
    reached = next((s for _, s, e in trace.points if e <= TARGET), None)
    last = trace.points[-1] if trace.points else (0, seconds, float("nan"))
    rows.append(
        {
            "problem": problem,
            "dofs": dofs,
            "ranks": comm.size,
            "method": method,
            "iterations": last[0],
            "seconds": seconds,
            "final_error": last[2],
            "seconds_to_target": reached,
            "peak_memory_mb": peak,
            "note": note,
        }
    )
    iterates.extend(
        {
            "problem": problem,
            "dofs": dofs,
            "method": method,
            "iteration": i,
            "seconds": s,
            "error": e,
        }
        for i, s, e in trace.points
    )
    to = "—" if reached is None else f"{reached:.3g} s"
    say(
        f"  {method:24s} {last[0]:4d} its {seconds:8.2f} s  error {last[2]:.1e}  "
        f"to {TARGET:g}: {to:>9s}  peak {peak:7.1f} MB  {note}"
    )


# ## Thermal problems: every method


class Iterates:
    """Errors of the iterates of one linear solve of a system (its bodies' temperatures).

    Newton's one step of a linear problem moves the cold state ``x0`` by ``−y``: an iterate
    ``y`` of the inner solve is the state ``x0 − y``.
    """

    def __init__(self, system: sc.System, reference: NodalReference) -> None:
        system.reset()
        system.apply_conditions()
        self.system, self.x0 = system, system.state()
        self.spaces = field_values(system)[0]
        self.reference = reference.at(self.spaces)

    def error(self, y) -> float:
        state = self.x0.array_r - y
        values = {n: state[self.system.slices[n]] for n in self.system.bodies}
        return relative_nodal_error(self.spaces, values, self.reference, comm)


def thermal_methods(name: str, make_scene, make_problem) -> None:
    """Every method on one thermal problem (partitioned couplings only for two bodies)."""
    shared = make_problem(make_scene("shared"))
    with sc.System(shared) as system:
        sc.solve(system, sc.Monolithic(refine=2))
        reference = NodalReference(*field_values(system))
        dofs, bodies = sum(system.num_dofs().values()), len(system.bodies)
    say(f"{name}: {dofs} DOFs, {bodies} bodies, {comm.size} rank(s)")

    def linear(problem, solver, trace, *, direct: bool = False):
        """The whole problem by one linear solver: one Newton step, its iterates traced.

        ``direct``: a solve without iterates, its answer recorded as iteration 1.
        """
        with sc.System(problem) as system:
            with trace.pause():
                iterates = Iterates(system, reference)
                trace.error = iterates.error
            if not direct:
                solver.monitor = lambda count, iterate: trace.record(count, iterate)
            result = sc.solve(system, solver, rtol=1e-12)
            if direct:
                state = system.state()
                final = iterates.x0.array_r - state.array_r
                state.destroy()
                trace.record(1, lambda: final)
            return result.inner[-1]

    def monolithic(options):
        def solve(trace):
            solver = sc.Monolithic(options)
            inner = linear(shared, solver, trace, direct=options is sc.DIRECT)
            solver.destroy()
            return "" if options is sc.DIRECT else f"{inner.rounds} CG iterations"

        return solve

    run(name, dofs, "monolithic MUMPS", monolithic(sc.DIRECT))
    run(name, dofs, "monolithic CG+GAMG", monolithic(sc.CG_GAMG))

    problem = make_problem(make_scene(placement))
    if comm.size > 1 and bodies >= comm.size:  # whole bodies on every rank

        def bddc(trace):
            solver = sc.Monolithic(sc.BDDC)
            inner = linear(problem, solver, trace)
            solver.destroy()
            return f"{inner.rounds} Krylov iterations"

        run(name, dofs, "monolithic BDDC deluxe", bddc)

    def subdomain(corrector, krylov):
        def solve(trace):
            solver = sc.Subdomains(corrector, krylov=krylov, max_rounds=100, dense_limit=0)
            inner = linear(problem, solver, trace)
            return f"{sum(inner.krylov_iterations)} CG iterations" if krylov else ""

        return solve

    partial = sc.PartialCondensation(layers=4)
    for corrector in [sc.Exact(), sc.Method1(), sc.Method2(), partial]:
        run(name, dofs, f"subdomain {corrector.name}", subdomain(corrector, False))
    run(name, dofs, "interface CG (partial)", subdomain(partial, True))
    if bodies != 2:
        return  # the partitioned couplings take two bodies

    def partitioned(couple, acceleration):
        def solve(trace):
            def monitor(iteration, temperatures):
                if trace.error is None:
                    with trace.pause():
                        spaces = {n: T.function_space for n, T in temperatures.items()}
                        at = reference.at(spaces)
                        trace.error = lambda values: relative_nodal_error(
                            spaces, {n: T.x.array for n, T in values.items()}, at, comm
                        )
                trace.record(iteration, lambda: temperatures)

            result = couple(
                shared,
                acceleration=acceleration,
                rtol=1e-12,
                max_iterations=100,
                monitor=monitor,
            )
            if result.diverged:
                return f"diverged at iteration {result.iterations}"
            return "" if result.converged else "no convergence in 100 iterations"

        return solve

    for label, couple in (("DN", solve_dirichlet_neumann), ("RR", solve_robin_robin)):
        for acceleration in ("constant", "aitken", "iqn-ils"):
            run(name, dofs, f"{label} {acceleration}", partitioned(couple, acceleration))


# ## The multiphysics scene: Newton outside


def newton_methods(cells: tuple[int, int]) -> None:
    """Monolithic and subdomain Newton on the squeezed Joule bars (every field)."""
    scene = bars_scene(*cells)
    with sc.System(squeezed_joule_bars(scene)) as system:
        system.reset({"temperature": 300.0})
        sc.solve(system, sc.Monolithic(), rtol=1e-13, max_it=40)
        reference = system.state()
        dofs = reference.getSize()
        readbacks[f"joule_bars {dofs}"] = sc.summary(system)
    say(f"joule_bars: {dofs} DOFs (T, φ, u), {comm.size} rank(s)")

    def newton(make_linear):
        def solve(trace):
            with sc.System(squeezed_joule_bars(scene)) as system:
                system.reset({"temperature": 300.0})
                trace.error = lambda _: max(system.difference(system.state(), reference).values())
                linear = make_linear()
                result = sc.solve(
                    system,
                    linear,
                    rtol=1e-12,
                    max_it=40,
                    monitor=lambda it: trace.record(it, lambda: None),
                )
                rounds = sum(step.inner_rounds for step in result.history)
                if isinstance(linear, sc.Monolithic):
                    linear.destroy()
                    return f"{rounds} inner solves/its"
                return f"{rounds} inner rounds"

        return solve

    gmres = {"ksp_type": "gmres", "pc_type": "gamg", "ksp_rtol": "1e-12", "ksp_max_it": "2000"}
    problem = "joule_bars"
    run(problem, dofs, "Newton, monolithic MUMPS", newton(sc.Monolithic))
    run(problem, dofs, "Newton, monolithic GMRES+GAMG", newton(lambda: sc.Monolithic(gmres)))
    run(problem, dofs, "Newton, subdomain exact", newton(sc.Subdomains))
    run(
        problem,
        dofs,
        "Newton, subdomain method1",
        newton(lambda: sc.Subdomains(sc.Method1(), max_rounds=400)),
    )


# ## The runs


def cooled_plates(scene: sc.Scene) -> sc.Problem:
    """The two plates, k = 1 and 10 W/(m K), h = 1e3 W/(m² K), the top cooled."""
    base = two_plates(scene, h=1e3, k_b=10.0).problem
    cooling = sc.Convection("top", 5.0, 2.0)
    return sc.Problem(scene, base.materials, base.contacts, [*base.conditions, cooling])


sizes = {
    "two_plates": [8, 16] if args.small else [64, 128, 256, 512, 706],
    "stack": [4] if args.small else [8, 16, 32, 64],
    "joule_bars": [(16, 3)] if args.small else [(16, 3), (32, 6), (64, 12), (128, 25)],
    "blocks3d": [0.1] if args.small else [0.05, 0.025, 0.0125],
}
plates_dofs = {n: 2 * (n + 1) ** 2 + (n + 1) for n in sizes["two_plates"]}
if args.from_csv is None:
    for problem in args.problems:
        for size in sizes[problem]:
            if problem == "two_plates":
                if plates_dofs[size] > args.max_dofs:
                    continue
                thermal_methods(
                    problem,
                    lambda where, n=size: two_plates_scene(n, n, placement=where),
                    cooled_plates,
                )
            elif problem == "stack":
                thermal_methods(
                    problem,
                    lambda where, n=size: stack_scene(8, n, n, placement=where),
                    lambda scene: stack(scene, h=1e2),
                )
            elif problem == "blocks3d":
                thermal_methods(
                    problem, lambda where, s=size: blocks3d_scene(s, placement=where), heated_blocks
                )
            else:
                newton_methods(size)


# ## Output: CSV, plots, the markdown table and the scaling exponents


def exponent(points: list[tuple[int, float]]) -> float | None:
    """Least-squares slope of log(time) against log(DOFs) (None with fewer than 3 sizes)."""
    if len(points) < 3:
        return None
    dofs, seconds = np.array(points).T
    return float(np.polyfit(np.log(dofs), np.log(seconds), 1)[0])


def read_csv(path: Path) -> list[dict]:
    """The rows of a CSV this demo wrote, numbers as numbers (an empty cell: None)."""

    def value(text: str):
        for kind in (int, float):
            try:
                return kind(text)
            except ValueError:
                pass
        return text or None

    with open(path, newline="") as stream:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(stream)]


def style(index: int, method: str) -> dict:
    """A colour per method; the line and marker tell the family (monolithic, subdomain, DN, RR)."""
    family = next((f for f in ("monolithic", "DN", "RR") if f in method), "subdomain")
    line, marker = {"monolithic": ("-", "o"), "subdomain": ("--", "s"), "DN": (":", "^")}.get(
        family, ("-.", "v")
    )
    return {"color": plt.cm.tab20(index % 20), "linestyle": line, "marker": marker}


if args.from_csv is not None:
    rows, iterates = (read_csv(args.from_csv / f) for f in ("summary.csv", "iterations.csv"))
    for r in rows:
        r["note"] = r["note"] or ""
ranks = rows[0]["ranks"] if rows else comm.size
if comm.rank == 0:
    args.out.mkdir(parents=True, exist_ok=True)
    for path, table in (("summary.csv", rows), ("iterations.csv", iterates)):
        with open(args.out / path, "w", newline="") as stream:
            writer = csv.DictWriter(stream, fieldnames=list(table[0]))
            writer.writeheader()
            writer.writerows(table)
    problems = list(dict.fromkeys(r["problem"] for r in rows))
    exponents = {}
    lines = [
        f"# Error against run time ({ranks} rank{'s' if ranks > 1 else ''})",
        "",
        f"Time to a relative error of {TARGET:g} (from assembly, errors not counted), as a",
        "ratio to the monolithic MUMPS solve of the same size in the same run; '—': never",
        "reached. Produced by `demos/demo_error_vs_runtime.py`.",
    ]
    for problem in problems:
        mine = [r for r in rows if r["problem"] == problem]
        methods = list(dict.fromkeys(r["method"] for r in mine))
        baseline = "Newton, monolithic MUMPS" if problem == "joule_bars" else "monolithic MUMPS"
        lines += [
            "",
            f"## {problem}",
            "",
            "| DOFs | method | iterations | time [s] | "
            f"to {TARGET:g} [s] | ratio | final error | peak MB | note |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for dofs in sorted({r["dofs"] for r in mine}):
            base = next(r for r in mine if r["dofs"] == dofs and r["method"] == baseline)
            for r in (r for r in mine if r["dofs"] == dofs):
                t = r["seconds_to_target"]
                ratio = (
                    "—"
                    if t is None or base["seconds_to_target"] is None
                    else f"{t / base['seconds_to_target']:.2f}"
                )
                lines.append(
                    f"| {dofs} | {r['method']} | {r['iterations']} | {r['seconds']:.3g} | "
                    f"{'—' if t is None else f'{t:.3g}'} | {ratio} | {r['final_error']:.1e} | "
                    f"{r['peak_memory_mb']:.0f} | {r['note']} |"
                )
        lines += [
            "",
            f"Scaling of the time to {TARGET:g} with DOFs (exponent of a power-law "
            "fit over the sizes where it was reached, 3 or more):",
            "",
            "| method | exponent | sizes |",
            "|---|---|---|",
        ]
        for method in methods:
            points = [
                (r["dofs"], r["seconds_to_target"])
                for r in mine
                if r["method"] == method and r["seconds_to_target"]
            ]
            exponents[problem, method] = exponent(points)
            value = exponents[problem, method]
            lines.append(
                f"| {method} | {'—' if value is None else f'{value:.2f}'} | {len(points)} |"
            )
        largest = max(r["dofs"] for r in mine)
        figure, axes = plt.subplots(figsize=(8, 5))
        for index, method in enumerate(methods):
            points = [
                (p["seconds"], p["error"])
                for p in iterates
                if p["problem"] == problem and p["dofs"] == largest and p["method"] == method
            ]
            if points:
                t, e = np.array(points).T
                look = style(index, method)
                axes.loglog(t, np.maximum(e, 1e-17), label=method, markersize=3, **look)
        axes.axhline(TARGET, color="grey", linewidth=0.8)
        axes.set_xlabel("wall time [s]")
        axes.set_ylabel("relative nodal error")
        axes.set_title(f"{problem}, {largest} DOFs, {ranks} rank(s)")
        axes.legend(fontsize=7, ncol=2)
        figure.tight_layout()
        figure.savefig(args.out / f"error_vs_time_{problem}.png", dpi=110)
        plt.close(figure)
    figure, axes = plt.subplots(1, len(problems), figsize=(5 * len(problems), 4), squeeze=False)
    for ax, problem in zip(axes[0], problems, strict=True):
        methods = dict.fromkeys(r["method"] for r in rows if r["problem"] == problem)
        for index, method in enumerate(methods):
            points = sorted(
                (r["dofs"], r["seconds_to_target"])
                for r in rows
                if r["problem"] == problem and r["method"] == method and r["seconds_to_target"]
            )
            if points:
                ax.loglog(*np.array(points).T, label=method, markersize=3, **style(index, method))
        ax.set_xlabel("DOFs")
        ax.set_ylabel(f"time to {TARGET:g} [s]")
        ax.set_title(problem)
        ax.legend(fontsize=6)
    figure.tight_layout()
    figure.savefig(args.out / "time_vs_dofs.png", dpi=110)
    (args.out / "results.md").write_text("\n".join(lines) + "\n")
    report = {
        "ranks": ranks,
        "target": TARGET,
        "rows": rows,
        "exponents": [
            {"problem": p, "method": m, "exponent": v} for (p, m), v in exponents.items()
        ],
        "readback": readbacks,
        "seconds": time.perf_counter() - started,
    }
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
say(f"wrote {args.out}/results.md in {time.perf_counter() - started:.0f} s")
