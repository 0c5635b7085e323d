"""Benchmark: 3D bodies solved by CG + GAMG per body against the direct routes (issue 20).

Two 3D blocks (``geo/blocks3d.geo``, tetrahedra; ``verification.cases.heated_blocks``:
k = 1 | 10 W/(m K), 1 K on the left end, convection on the right end and the front) at
several contact conductances h, each solved by:

* the subdomain route with iterative bodies (``sc.System(problem, solver="iterative")``):
  CG + GAMG per body, the interface Krylov with the exact corrector on a strip;
* the same with the strip clamped at its cut (``sc.SparseStrip(cut="clamped")``), as it
  was until 2026-12-01, instead of the Robin cut;
* the subdomain route with direct bodies (``solver="direct"``): MUMPS with the Schur block;
* monolithic MUMPS (``sc.Monolithic()``) and CG + GAMG (``sc.CG_GAMG``).

Each method runs in a process of its own (``mpiexec -n <ranks>``), on the scene's default
placement (``"auto"``: a block per rank on two ranks). Until 2026-11-29 the monolithic
solvers ran with each block spread over every rank (``"shared"``), which made CG + GAMG 1.6
times slower on two ranks (107,608 DOFs: 1.83–2.14 s against 1.19–1.36 s at h = 1 and 1e3)
and left MUMPS as it was (3.4–4.3 s either way): the two-rank ratios measured before were
against a slow baseline. "Memory" is the peak resident set of a solve above the resident set
before it (Linux: the peak is reset before each solve through ``/proc/self/clear_refs``), the
largest over the ranks and the h values.
Times run from the assembly of the bodies (``sc.System``) to the solution, the mesh made
outside the clock. Error: max nodal |T − T_ref| / range of
T_ref, T_ref the MUMPS solve polished by two steps of iterative refinement (on one rank). For
h ≥ 1e8, where the merged matrix's round-off (eps · h) leaves even the refined MUMPS solve
1e-8 off, T_ref is extrapolated in 1/h from refined solves at 1e7 and 2e7 (Richardson:
``T(h) = T∞ + a/h + O(1/h²)``): on 19k DOFs it agrees with the series subdomain solve at
1e10 to 6.7e-11, the refined MUMPS solve at 1e10 to 1.1e-8.

Where the refined MUMPS reference is out of reach (``--mumps-estimate`` prints MUMPS's own
estimate of its memory, from its analysis alone: 0.76 GiB at 107,608 DOFs, 3.28 at 309,108,
15.19 at 939,678; the reference needs seven factorisations), ``--iterative-reference`` makes
T_ref the iterative route itself solved to ``rtol`` 1e-13 (3e-13 where its true residual
stops above 1e-13, at h ≥ 1e6). On 107,608 DOFs that solve is 4e-15 to 5.5e-15 from the
refined MUMPS solve at h ≤ 1e3, and 9.7e-13 and 2.3e-11 from it (its extrapolation) at 1e6
and 1e10, as far as the timed ``rtol`` 1e-12 is: there the MUMPS side's round-off (eps · h̄)
is what differs. The monolithic solves, timed against it, check it independently where they
reach 1e-8.

Run ``./dev python benchmarks/bench_3d_iterative.py`` (``--sizes`` element sizes [m]:
0.0068 → 106k DOFs, 0.0047 → 317k, 0.0032 → 1.0M; ``--ranks 1 2``; ``--skip MUMPS`` where it
does not fit). Prints the table and writes ``out_bench_3d_iterative.json``. Not a test:
compare ratios of one run, not seconds across runs. The meshes gmsh makes are kept in
``--mesh-cache`` (``out_bench_3d_iterative_meshes/``) and read back by every later launch
(at 0.0032 m a load took 530 s meshing and 181 s reading back, both beside a test run).
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
METHODS = (
    "subdomain iterative",
    "subdomain clamped",
    "subdomain direct",
    "MUMPS",
    "CG + GAMG",
)


def worker(
    method: str,
    size: float,
    reference: Path | None,
    out: Path,
    conductances: list[float],
    mesh_cache: Path | None = None,
) -> None:
    """One method at every h on this run's ranks; the reference run writes ``reference``."""
    import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
    from mpi4py import MPI

    import subdomain_contact as sc
    from verification.cases import blocks3d_scene, heated_blocks
    from verification.memory import resident
    from verification.nodal import NodalReference, error_against, field_values

    comm = MPI.COMM_WORLD
    scene = blocks3d_scene(size, mesh_cache=mesh_cache)
    rows = []
    if method == "iterative reference":
        for h in conductances:
            iterative_reference(scene, h, f"{reference}_{h:g}.npz")
        if comm.rank == 0:
            out.write_text("[]")
        return
    for h in conductances:
        solver = {
            "reference": lambda: sc.Monolithic(refine=2),
            "MUMPS": lambda: sc.Monolithic(),
            "CG + GAMG": lambda: sc.Monolithic(sc.CG_GAMG),
            "subdomain clamped": lambda: sc.Subdomains(sc.SparseStrip(cut="clamped")),
        }.get(method, lambda: sc.Subdomains())()
        bodies = {"subdomain iterative": "iterative", "subdomain clamped": "iterative",
                  "subdomain direct": "direct"}  # fmt: skip
        comm.Barrier()
        base = resident()
        tic = time.perf_counter()
        if method == "reference" and h >= RICHARDSON_ABOVE:
            richardson(scene, h, f"{reference}_{h:g}.npz")
            continue
        try:
            with sc.System(heated_blocks(scene, h=h), solver=bodies.get(method, "direct")) as s:
                result = sc.solve(s, solver, rtol=1e-12)
                seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
                if method == "reference":
                    NodalReference(*field_values(s)).save(f"{reference}_{h:g}.npz")
                    error = 0.0
                else:
                    error = error_against(s, NodalReference.load(f"{reference}_{h:g}.npz").at(
                        field_values(s)[0]))  # fmt: skip
                dofs = sum(v for k, v in s.num_dofs().items())
                inner = result.inner[-1]
                body_iterations = sum(i.body_iterations for i in result.inner)
                fallbacks = result.fallbacks
        except RuntimeError as failure:  # a monolithic iterative solve that broke down
            seconds, error, dofs, inner = float("nan"), float("inf"), 0, None
            body_iterations = fallbacks = 0
            if comm.rank == 0:
                print(f"{method}, h = {h:g}: {failure}", flush=True)
        if hasattr(solver, "destroy"):
            solver.destroy()
        memory = comm.allreduce((resident("VmHWM") - base) / 2**20, op=MPI.MAX)  # GiB
        rows.append({
            "method": method, "ranks": comm.size, "size": size, "h": h, "dofs": dofs,
            "seconds": seconds, "error": error, "memory_gb": memory,
            "rounds": inner.rounds if inner else 0,
            "krylov": sum(inner.krylov_iterations) if inner else 0,
            "body_iterations": body_iterations, "fallbacks": fallbacks,
        })  # fmt: skip
    if comm.rank == 0:
        out.write_text(json.dumps(rows))


#: Conductance from which the reference is extrapolated, and where from.
RICHARDSON_ABOVE, RICHARDSON_FROM = 1e8, 1e7


def richardson(scene, h: float, path: str) -> None:
    """The reference at a large h, extrapolated in 1/h from refined solves at h₁ and 2h₁."""
    import subdomain_contact as sc
    from verification.cases import heated_blocks
    from verification.nodal import extrapolated_in_conductance, field_values

    def solve(at: float):
        with sc.System(heated_blocks(scene, h=at), solver="direct") as s:
            sc.solve(s, sc.Monolithic(refine=2), rtol=1e-12)
            return field_values(s)

    extrapolated_in_conductance(solve, h, RICHARDSON_FROM).save(path)


#: The iterative reference's tolerances, tightest first: its true residual stops near 1.3e-13
#: at h ≥ 1e6 on 107,608 DOFs (round-off of the bodies' reactions).
REFERENCE_RTOLS = (1e-13, 3e-13)


def iterative_reference(scene, h: float, path: str) -> None:
    """The reference where MUMPS does not fit: the iterative route at the tightest tolerance."""
    from mpi4py import MPI

    import subdomain_contact as sc
    from verification.cases import heated_blocks
    from verification.nodal import NodalReference, field_values

    for rtol in REFERENCE_RTOLS:
        try:
            with sc.System(heated_blocks(scene, h=h), solver="iterative") as s:
                sc.solve(s, sc.Subdomains(), rtol=rtol)
                NodalReference(*field_values(s)).save(path)
        except sc.NewtonConvergenceError:
            continue
        if MPI.COMM_WORLD.rank == 0:
            print(f"reference at h = {h:g}: the iterative route to rtol {rtol:g}", flush=True)
        return
    raise RuntimeError(f"no iterative reference at h = {h:g} to rtol {REFERENCE_RTOLS[-1]:g}")


def mumps_estimate(size: float, mesh_cache: Path | None = None) -> None:
    """Print MUMPS's estimate of the monolithic factorisation's memory [GiB], no solve."""
    from mpi4py import MPI

    import subdomain_contact as sc
    from verification.cases import blocks3d_scene, heated_blocks
    from verification.memory import mumps_estimate as estimate

    scene = blocks3d_scene(size, placement="shared", mesh_cache=mesh_cache)
    with sc.System(heated_blocks(scene, h=1.0)) as system:
        system.apply_conditions()
        system.assemble_jacobian()
        line = estimate(system)
    if MPI.COMM_WORLD.rank == 0:
        print(f"size {size}: {line}", flush=True)


def cell(row: dict | None) -> str:
    """A method's time, its iterations and memory; its error where it missed the target."""
    if row is None:
        return "—"
    if row["error"] == float("inf"):
        return "fails"
    its = f", {row['krylov']} its" if row["krylov"] else ""
    mark = "" if row["error"] <= TARGET else f" (error {row['error']:.0e})"
    if row.get("fallbacks"):  # bodies whose Krylov solve failed, factorised by MUMPS
        mark += f", {row['fallbacks']} bodies factorised"
    return f"{row['seconds']:.2f} s{its}, {row['memory_gb']:.2f} GB{mark}"


def table(rows: list[dict]) -> str:
    """Times as ratios to the fastest monolithic solve that reached TARGET, and to MUMPS."""
    lines = [
        "| ranks | DOFs | h | " + " | ".join(METHODS)
        + " | iterative / best monolithic | iterative / MUMPS |",
        "|---|---|---|" + "---|" * (len(METHODS) + 2),
    ]  # fmt: skip
    keys = sorted({(r["ranks"], r["size"], r["h"]) for r in rows if r["dofs"]})
    for ranks, size, h in sorted(keys, key=lambda k: (k[0], -k[1], k[2])):
        mine = {r["method"]: r for r in rows if (r["ranks"], r["size"], r["h"]) == (ranks, size, h)}
        dofs = max(r["dofs"] for r in mine.values())
        sub = mine.get("subdomain iterative", {"seconds": float("nan")})["seconds"]
        reached = [mine[m]["seconds"] for m in ("MUMPS", "CG + GAMG")
                   if m in mine and mine[m]["error"] <= TARGET]  # fmt: skip
        mumps = mine.get("MUMPS")
        lines.append(
            f"| {ranks} | {dofs} | {h:g} | " + " | ".join(cell(mine.get(m)) for m in METHODS)
            + f" | {sub / min(reached) if reached else float('nan'):.2f}"
            + f" | {sub / mumps['seconds'] if mumps else float('nan'):.2f} |"
        )  # fmt: skip
    return "\n".join(lines)


def reference_stem(size: float) -> str:
    """Where the reference of a size is written, ``<stem>_<h>.npz`` for each h."""
    return f"out_bench_3d_iterative_reference_{size:g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.0068, 0.0047])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--skip", nargs="*", default=[], help="methods not run")
    parser.add_argument(
        "--conductances", type=float, nargs="+", default=list(CONDUCTANCES),
        help="the contact conductances h [W/(m^2 K)]",
    )  # fmt: skip
    parser.add_argument(
        "--only-at", nargs="*", default=[], metavar="METHOD=H,H",
        help="run a method at these h of --conductances only, e.g. 'MUMPS=1e6,1e10'",
    )  # fmt: skip
    parser.add_argument("--worker", help="(internal) the method a worker runs")
    parser.add_argument("--size", type=float, help="(internal)")
    parser.add_argument("--reference", type=Path, help="(internal)")
    parser.add_argument("--out", type=Path, default=Path("out_bench_3d_iterative.json"))
    parser.add_argument(
        "--mesh-cache", type=Path, default=Path("out_bench_3d_iterative_meshes"),
        help="directory of the meshes gmsh made, read back by the next launch",
    )  # fmt: skip
    parser.add_argument(
        "--iterative-reference", action="store_true",
        help="the reference by the iterative route to rtol 1e-13 (where MUMPS does not fit)",
    )  # fmt: skip
    parser.add_argument(
        "--keep-reference", action="store_true",
        help="reuse the reference files of an earlier run of the same sizes",
    )  # fmt: skip
    parser.add_argument(
        "--mumps-estimate", action="store_true",
        help="no solve: MUMPS's estimate of the monolithic factorisation's memory",
    )  # fmt: skip
    args = parser.parse_args()
    if args.mumps_estimate:
        import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)

        for size in args.sizes:
            mumps_estimate(size, args.mesh_cache)
        return
    if args.worker:
        worker(args.worker, args.size, args.reference, args.out, args.conductances, args.mesh_cache)
        return
    venv = Path(sys.executable).parent
    rows = []

    only = {m: [float(h) for h in hs.split(",")] for m, hs in (a.split("=") for a in args.only_at)}

    def launch(method: str, ranks: int, size: float) -> list[dict]:
        out = Path(f"out_bench_3d_iterative_{ranks}.json")
        command = [str(venv / "mpiexec"), "-n", str(ranks), sys.executable, __file__,
                   "--worker", method, "--size", str(size), "--out", str(out),
                   "--mesh-cache", str(args.mesh_cache),
                   "--reference", reference_stem(size),
                   "--conductances", *map(str, only.get(method, args.conductances))]  # fmt: skip
        subprocess.run(command, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
        return json.loads(out.read_text())

    for size in args.sizes:
        kept = reference_stem(size)
        if args.keep_reference and all(
            Path(f"{kept}_{h:g}.npz").is_file() for h in args.conductances
        ):
            print(f"size {size:g}: the reference of an earlier run kept", flush=True)
        else:
            launch("iterative reference" if args.iterative_reference else "reference", 1, size)
        for ranks in args.ranks:
            for method in METHODS:
                if method not in args.skip:
                    rows += launch(method, ranks, size)
                    print(table(rows), flush=True)
    args.out.write_text(json.dumps(rows, indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
