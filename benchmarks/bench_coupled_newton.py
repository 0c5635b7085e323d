"""Benchmark: Newton with the subdomain iteration inside against the monolithic Newton.

Two bars in contact (``verification.cases.bars_scene``) at five mesh sizes, with one of two
problems (``--problem``):

- ``squeezed_joule_bars`` (default): every field coupled, k(T), σ(T), h(p, T), g(p, T),
  an exponential closure; the bulk depends on T, so both routes refactorise every step.
- ``hot_squeezed_bars``: two steel bars (T, u) squeezed between walls at 300 K and 800 K,
  a linear bulk and a contact closing by an exponential law with h(p, T): the subdomain
  Newton factorises each bar once and then refactorises only its dense contact block; the
  monolithic Newton refactorises the merged matrix every step (MUMPS keeping its analysis).

Printed per size: DOFs, master DOFs, Newton iterations, inner rounds, the bodies' sparse
factorisations, the wall time of each Newton (set-up of the system included: forms, blocks)
and their ratio measured in the same run, and the relative difference of the contact's
normal force between the two solutions (from the reactions).

On several ranks the monolithic Newton spreads both bars over every rank (it needs
``placement="shared"``); the subdomain Newton gives each bar its own ranks
(``placement="groups"``).

Run: ``./dev python benchmarks/bench_coupled_newton.py [--problem hot_squeezed_bars]``
(serial) or under ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``; ``--sizes 16 32`` for
fewer. Not a test: timings on a shared machine are noisy; compare ratios.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

import subdomain_contact as sc
from verification import cases

#: Per problem: default cells along each bar, and cells along / cells across.
PROBLEMS = {"squeezed_joule_bars": ([16, 32, 64, 128, 256], 5),
            "hot_squeezed_bars": ([32, 64, 128, 256, 360], 4)}  # fmt: skip

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--problem", choices=sorted(PROBLEMS), default="squeezed_joule_bars")
parser.add_argument("--sizes", type=int, nargs="+", help="cells along each bar")
args = parser.parse_args()
sizes, aspect = PROBLEMS[args.problem]
make_problem = getattr(cases, args.problem)
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"


def newton(scene, linear):
    """(result, seconds, DOFs, the contact's normal force) of one Newton from 300 K."""
    comm.barrier()
    tic = time.perf_counter()
    with sc.System(make_problem(scene)) as system:
        system.reset({"temperature": 300.0})
        result = sc.solve(system, linear, rtol=1e-12)
        seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        dofs = system.num_dofs()
        force = sc.force(system, "contact")[0]  # the contact's force [N/m], from reactions
    return result, seconds, dofs, force


if comm.rank == 0:
    print(
        f"{args.problem}\n| cells/bar | DOFs | masters | Newton | inner rounds | factorisations "
        "| ranks | monolithic [s] | subdomain [s] | ratio | force difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
for layers in args.sizes or sizes:
    rows = max(2, layers // aspect)
    monolithic = sc.Monolithic()
    mono_scene = cases.bars_scene(layers, rows, comm=comm, placement="shared")
    mono, mono_seconds, dofs, p_mono = newton(mono_scene, monolithic)
    monolithic.destroy()
    scene = cases.bars_scene(layers, rows, comm=comm, placement=placement)
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
