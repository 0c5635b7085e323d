"""Benchmark: time steps with the subdomain iteration inside against monolithic steps.

Two bars in contact (``verification.cases.bars_scene``), BDF2 steps of a fixed length from
300 K, with one of two problems (``--problem``):

- ``hot_squeezed_bars`` (default): steel bars (T, u) between walls at 300 K and 350 K, a linear
  bulk (constant k, E, α) and a contact closing by an exponential law with h(p, T). At a fixed
  step the bulk matrices never change: the subdomain route factorises each bar once per set
  of BDF2 weights (the first step is backward Euler) and then only refactorises its dense
  contact block; the monolithic route refactorises the merged matrix at every Newton step
  (MUMPS keeping its analysis).
- ``warming_joule_bars``: every field coupled (T, φ, u; k(T), σ(T), h(p, T), g(p, T)), 1 V
  across: the bulk depends on T, both routes refactorise at every Newton step.

Printed per size: DOFs, steps, Newton iterations and inner rounds over all steps, the bodies'
sparse factorisations, the mean wall time per step of each route (set-up excluded: it is
printed apart) and their ratio measured in the same run, and the largest relative difference
of the end states per field.

On several ranks the monolithic route spreads both bars over every rank
(``placement="shared"``); the subdomain route gives each bar its own ranks
(``placement="groups"``).

Run: ``./dev python benchmarks/bench_transient.py [--problem warming_joule_bars]`` (serial)
or under ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``; ``--sizes 64 128`` for fewer. Not a
test: timings on a shared machine are noisy; compare ratios.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import numpy as np
from mpi4py import MPI

import subdomain_contact as sc
from verification import cases

#: Per problem: default cells along each bar, cells along / cells across, the problem.
PROBLEMS = {
    "hot_squeezed_bars": ([64, 128, 256], 4, lambda s: cases.hot_squeezed_bars(s, storage=True)),
    "warming_joule_bars": ([50, 100, 200], 4, lambda s: cases.warming_joule_bars(s, 1.0)),
}

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--problem", choices=sorted(PROBLEMS), default="hot_squeezed_bars")
parser.add_argument("--sizes", type=int, nargs="+", help="cells along each bar")
parser.add_argument("--steps", type=int, default=6, help="time steps")
parser.add_argument("--step", type=float, default=600.0, help="Δt [s]")
args = parser.parse_args()
sizes, aspect, make_problem = PROBLEMS[args.problem]
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"


def run(scene, linear):
    """Set-up and per-step seconds, Newton, rounds, factorisations, DOFs and the end state."""
    comm.barrier()
    tic = time.perf_counter()
    system = sc.System(make_problem(scene))
    system.reset({"temperature": 300.0})
    stepper = sc.Stepper(system, "bdf2")
    setup = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
    newton = rounds = factorisations = 0
    tic = time.perf_counter()
    for _ in range(args.steps):
        result = stepper.advance(args.step, linear, rtol=1e-10)
        newton, rounds = newton + result.iterations, rounds + result.rounds
        factorisations += result.factorisations
    per_step = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX) / args.steps
    return system, setup, per_step, newton, rounds, factorisations


def gathered(system) -> dict[str, np.ndarray]:
    """Each field's nodal values sorted by coordinates, on every rank (to compare layouts)."""
    out = {}
    for field in system.problem.fields:
        if field == "displacement":
            continue  # compared through the temperature and the potential it drives
        parts = []
        for name in sorted(system.problem.scene.bodies):
            local = system.bodies[name].nodal(field) if name in system.bodies else None
            if local is not None:
                local = np.column_stack([local[0], local[1]])
            pieces = [p for p in comm.allgather(local) if p is not None]
            rows = np.unique(np.round(np.concatenate(pieces), 12), axis=0)
            parts.append(rows[:, -1])
        out[field] = np.concatenate(parts)
    return out


if comm.rank == 0:
    print(
        f"{args.problem}, {args.steps} BDF2 steps of {args.step:g} s, {comm.size} rank(s)\n"
        "| cells/bar | DOFs | Newton sub / mono | rounds | factorisations sub / mono "
        "| set-up sub / mono [s] | per step mono [s] | per step sub [s] | ratio | difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
for layers in args.sizes or sizes:
    rows = max(2, layers // aspect)
    monolithic = sc.Monolithic()
    mono = run(cases.bars_scene(layers, rows, comm=comm, placement="shared"), monolithic)
    dofs = mono[0].num_dofs()
    mono_values = gathered(mono[0])
    mono[0].destroy()
    monolithic.destroy()
    sub = run(cases.bars_scene(layers, rows, comm=comm, placement=placement), sc.Subdomains())
    sub_values = gathered(sub[0])
    sub[0].destroy()
    difference = max(
        np.abs(sub_values[f] - mono_values[f]).max() / np.abs(mono_values[f]).max()
        for f in mono_values
    )
    if comm.rank == 0:
        print(
            f"| {layers}x{rows} | {dofs['plate_A'] + dofs['plate_B']} | {sub[3]} / {mono[3]} "
            f"| {sub[4]} | {sub[5]} / {mono[5]} | {sub[1]:.2f} / {mono[1]:.2f} "
            f"| {mono[2]:.2f} | {sub[2]:.2f} | {sub[2] / mono[2]:.2f} | {difference:.1e} |",
            flush=True,
        )
