"""Benchmark: Newton with the subdomain iteration inside against the monolithic Newton.

The squeezed Joule bars (every field coupled, p- and T-dependent laws;
``verification.cases.squeezed_joule_bars``) at five mesh sizes, up to about 1e5 DOFs. For
each: DOFs, Newton iterations, inner rounds, the bodies' sparse factorisations, the wall time
of each Newton (set-up of the system included: forms, blocks) and their ratio measured in
the same run, and the largest relative difference between the two solutions.

On several ranks the monolithic Newton spreads both bars over every rank (it needs
``placement="shared"``); the subdomain Newton gives each bar its own ranks
(``placement="groups"``).

Run: ``./dev python benchmarks/bench_coupled_newton.py`` (serial) or under
``.venv/bin/mpiexec -n 2``; ``--sizes 16 32`` for fewer. Not a test: timings on a shared
machine are noisy; compare ratios.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import bars_scene, squeezed_joule_bars

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64, 128, 256])
args = parser.parse_args()
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"


def newton(scene, linear):
    """(result, state as a serial array per body by coordinates, seconds) of one Newton."""
    comm.barrier()
    tic = time.perf_counter()
    with sc.System(squeezed_joule_bars(scene)) as system:
        system.reset({"temperature": 300.0})
        result = sc.solve(system, linear, rtol=1e-12)
        seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        dofs = system.num_dofs()
        pressure = system.everywhere(
            {n: b.contact_integral("contact", "pressure") for n, b in system.bodies.items()}
        )
    return result, seconds, dofs, pressure["plate_A"]


if comm.rank == 0:
    print(
        "| cells/bar | DOFs | masters | Newton | inner rounds | factorisations | ranks "
        "| monolithic [s] | subdomain [s] | ratio | pressure difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
for layers in args.sizes:
    rows = max(2, layers // 5)
    monolithic = sc.Monolithic()
    mono, mono_seconds, dofs, p_mono = newton(bars_scene(layers, rows, comm=comm), monolithic)
    monolithic.destroy()
    scene = bars_scene(layers, rows, comm=comm, placement=placement)
    sub, sub_seconds, _, p_sub = newton(scene, sc.Subdomains())
    if comm.rank == 0:
        rounds = sum(s.inner_rounds for s in sub.history)
        print(
            f"| {layers}x{rows} | {dofs['plate_A'] + dofs['plate_B']} | {dofs['masters']} "
            f"| {sub.iterations} | {rounds} | {sub.factorisations} | {comm.size} "
            f"| {mono_seconds:.2f} | {sub_seconds:.2f} | {sub_seconds / mono_seconds:.2f} "
            f"| {abs(p_sub - p_mono) / abs(p_mono):.1e} |",
            flush=True,
        )
