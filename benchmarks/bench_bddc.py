"""Benchmark: the subdomain solve against PETSc's BDDC, MUMPS and CG + GAMG (issue 19).

The two plates (k = 1 | 10 W/(m K), ends at 1 and 0 K, top cooled by a convection of
5 W/(m² K) to 2 K) at several contact conductances h, each solved by:

* the subdomain route with every option at its default (``sc.solve(system)``);
* PCBDDC on the unassembled matrix, one subdomain per rank, deluxe scaling (``sc.BDDC``);
* monolithic MUMPS (``sc.Monolithic()``) and CG + GAMG (``sc.CG_GAMG``).

Every time runs from the assembly of the bodies (``sc.System``) to the solution, on the
same scene (meshed once, outside the clock), after one untimed warm-up solve that compiles
the forms. Error: max nodal |T − T_ref| / range of T_ref, with T_ref the MUMPS solve
polished by two steps of iterative refinement.

Run ``./dev python benchmarks/bench_bddc.py`` (it starts the 1- and 2-rank runs itself with
the venv's mpiexec and prints the ratios measured in this run); ``--sizes`` sets the plates'
element layers (256: 132k DOFs, 724: 1.05M DOFs). Not a test: timings on a shared machine
are noisy; compare ratios of one run, not seconds across runs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

TARGET = 1e-8  # the error at which the times are compared
CONDUCTANCES = (1e-2, 1.0, 1e3, 1e6, 1e10)
METHODS = ("subdomain (default)", "BDDC deluxe", "MUMPS", "CG + GAMG")


def worker(sizes: list[int]) -> list[dict]:
    """Every method at every size and h, on this run's ranks (the default placement)."""
    import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
    import numpy as np
    from mpi4py import MPI

    import subdomain_contact as sc
    from verification.cases import two_plates, two_plates_scene

    comm = MPI.COMM_WORLD
    methods = {
        "subdomain (default)": None,
        "BDDC deluxe": lambda: sc.Monolithic(sc.BDDC),
        "MUMPS": lambda: sc.Monolithic(),
        "CG + GAMG": lambda: sc.Monolithic(sc.CG_GAMG),
    }
    if comm.size == 1:
        del methods["BDDC deluxe"]  # one subdomain: a direct solve of the whole
    rows = []
    for n in sizes:
        scene = two_plates_scene(n, n)
        for h in CONDUCTANCES:
            base = two_plates(scene, h=h, k_a=1.0, k_b=10.0).problem
            problem = sc.Problem(scene, base.materials, base.contacts,
                                 [*base.conditions, sc.Convection("top", 5.0, 2.0)])  # fmt: skip

            if n == sizes[0] and h == CONDUCTANCES[0]:
                run(comm, problem, None)  # warm-up: the forms compile here, once for every h
            _, reference, _, dofs = run(comm, problem, sc.Monolithic(refine=2))
            span = comm.allreduce(max(np.ptp(v) for v in reference.values()), op=MPI.MAX)
            for label, make in methods.items():
                try:
                    seconds, values, rounds, _ = run(comm, problem, make and make())
                    gap = max(np.abs(values[b] - reference[b]).max(initial=0.0) for b in values)
                    error = comm.allreduce(gap, op=MPI.MAX) / span
                except (RuntimeError, ValueError) as failure:
                    seconds, rounds, error = float("nan"), 0, float("nan")
                    if comm.rank == 0:
                        print(f"  {label} failed: {str(failure).splitlines()[0]}", flush=True)
                row = {"ranks": comm.size, "dofs": dofs, "h": h, "method": label,
                       "seconds": seconds, "iterations": rounds, "error": error}  # fmt: skip
                rows.append(row)
                if comm.rank == 0:
                    print(
                        f"  {comm.size} rank(s) {dofs:9d} DOFs h {h:7.0e} {label:20s} "
                        f"{seconds:8.3f} s {rounds:4d} its error {error:.1e}",
                        flush=True,
                    )
    return rows


def run(comm, problem, solver) -> tuple[float, dict, int, int]:
    """Seconds from the assembly to the solution (slowest rank), values, iterations, DOFs."""
    from mpi4py import MPI

    import subdomain_contact as sc

    comm.Barrier()
    tic = time.perf_counter()
    with sc.System(problem) as system:
        result = sc.solve(system, solver) if solver else sc.solve(system)
        seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        values = {name: b.U.x.array.copy() for name, b in system.bodies.items()}
        dofs = sum(system.num_dofs().values())
    if solver is not None:
        solver.destroy()
    return seconds, values, result.inner[-1].rounds, dofs


def cell(row: dict | None) -> str:
    """A method's time and iterations; its error where it missed the target."""
    if row is None:
        return "—"
    mark = "" if row["error"] <= TARGET else f" (error {row['error']:.0e})"
    return f"{row['seconds']:.2f} s, {row['iterations']} its{mark}"


def table(rows: list[dict]) -> str:
    """Times as ratios: to BDDC, and to the fastest monolithic solve that reached TARGET."""
    lines = [
        "| ranks | DOFs | h | subdomain | BDDC deluxe | MUMPS | CG + GAMG "
        "| subdomain / BDDC | subdomain / best monolithic |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    keys = sorted({(r["ranks"], r["dofs"], r["h"]) for r in rows})
    for ranks, dofs, h in keys:
        mine = {r["method"]: r for r in rows if (r["ranks"], r["dofs"], r["h"]) == (ranks, dofs, h)}

        sub = mine["subdomain (default)"]["seconds"]
        bddc = mine.get("BDDC deluxe")
        reached = [mine[m]["seconds"] for m in ("MUMPS", "CG + GAMG") if mine[m]["error"] <= TARGET]
        cells = " | ".join(cell(mine.get(m)) for m in METHODS)
        lines.append(
            f"| {ranks} | {dofs} | {h:g} | {cells} "
            f"| {sub / bddc['seconds'] if bddc else float('nan'):.2f} "
            f"| {sub / min(reached) if reached else float('nan'):.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 724])
    parser.add_argument("--worker", action="store_true", help="(internal) run under mpiexec")
    parser.add_argument("--out", type=Path, default=Path("out_bench_bddc.json"))
    args = parser.parse_args()
    if args.worker:
        rows = worker(args.sizes)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            args.out.write_text(json.dumps(rows))
        return
    venv = Path(sys.executable).parent
    rows = []
    for ranks in (1, 2):
        out = Path(f"out_bench_bddc_{ranks}.json")
        command = [str(venv / "mpiexec"), "-n", str(ranks), sys.executable, __file__, "--worker",
                   "--out", str(out), "--sizes", *map(str, args.sizes)]  # fmt: skip
        subprocess.run(command, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
        rows += json.loads(out.read_text())
    print(table(rows))
    print()
    print("2 ranks / 1 rank, default subdomain solve:")
    for dofs in sorted({r["dofs"] for r in rows}):
        for h in CONDUCTANCES:
            one, two = (
                next(
                    r["seconds"]
                    for r in rows
                    if (r["ranks"], r["dofs"], r["h"], r["method"])
                    == (ranks, dofs, h, "subdomain (default)")
                )
                for ranks in (1, 2)
            )
            print(f"  {dofs} DOFs, h = {h:g}: {two / one:.2f}")
    args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
