"""Benchmark: a linear bulk keeps its factorisation; only the contact's dense block changes.

Two steel bars (temperature and displacement; constant conductivity, modulus and expansion)
squeezed between walls at 300 K and 800 K, their contact closing by an exponential law with
a conductance h(p, T) (``verification.cases.hot_squeezed_bars``). Each Newton step changes
the contact blocks alone: the subdomain Newton factorises each body once and then only
refactorises its dense Schur block, while the monolithic Newton refactorises the whole merged
matrix (MUMPS keeping its analysis). Printed: DOFs, Newton iterations, the bodies' sparse
factorisations, the wall time of each Newton (system set-up included) and their ratio, and
the largest relative difference between the two solutions.

Run: ``./dev python benchmarks/bench_kept_factorisations.py`` (``--sizes 64 128``); under
``mpiexec -n 2`` with ``OMP_NUM_THREADS=1`` the subdomain Newton gives each bar its own rank.
Not a test: compare ratios, not seconds.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import bars_scene, hot_squeezed_bars

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128, 256, 360])
args = parser.parse_args()
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"


def newton(scene, linear):
    """(result, seconds, DOFs, the contact's mean pressure) of one Newton from 300 K."""
    comm.barrier()
    tic = time.perf_counter()
    with sc.System(hot_squeezed_bars(scene)) as system:
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
        "| cells/bar | DOFs | Newton | factorisations | ranks | monolithic [s] "
        "| subdomain [s] | ratio | pressure difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
for layers in args.sizes:
    rows = max(2, layers // 4)
    monolithic = sc.Monolithic()
    mono, mono_seconds, dofs, p_mono = newton(bars_scene(layers, rows, comm=comm), monolithic)
    monolithic.destroy()
    scene = bars_scene(layers, rows, comm=comm, placement=placement)
    sub, sub_seconds, _, p_sub = newton(scene, sc.Subdomains())
    if comm.rank == 0:
        print(
            f"| {layers}x{rows} | {dofs['plate_A'] + dofs['plate_B']} | {sub.iterations} "
            f"| {sub.factorisations} | {comm.size} | {mono_seconds:.2f} | {sub_seconds:.2f} "
            f"| {sub_seconds / mono_seconds:.2f} | {abs(p_sub - p_mono) / abs(p_mono):.1e} |",
            flush=True,
        )
