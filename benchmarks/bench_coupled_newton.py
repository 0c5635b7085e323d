"""Benchmark: Newton with the subdomain iteration inside against the monolithic Newton.

The squeezed Joule bars (every field coupled, p- and T-dependent laws;
``cases.squeezed_joule_bars``) at four mesh sizes. For each: DOFs, Newton iterations, inner
rounds, wall time of each Newton and their ratio measured in the same run, and the largest
relative difference between the two solutions.

Run: `./dev python benchmarks/bench_coupled_newton.py` (serial) or under
`.venv/bin/mpiexec -n 2`. Not a test: timings on a shared machine are noisy; compare ratios.
"""

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

from subdomain_contact.cases import bars_scene, squeezed_joule_bars
from subdomain_contact.coupled import CoupledSystem
from subdomain_contact.newton import solve_newton

comm = MPI.COMM_WORLD
if comm.rank == 0:
    print(
        "| cells/bar | DOFs | masters | Newton | inner rounds | monolithic [s] | subdomain [s] "
        "| ratio | max difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
for layers in (16, 32, 64, 128):
    rows = max(2, layers // 5)
    system = CoupledSystem(squeezed_joule_bars(bars_scene(layers, rows, comm=comm)))
    results, states = {}, {}
    for linear in ("monolithic", "subdomain"):
        system.reset({"temperature": 300.0})
        results[linear] = solve_newton(system, linear=linear, rtol=1e-12)
        states[linear] = system.state()
    difference = max(system.difference(states["subdomain"], states["monolithic"]).values())
    dofs = system.num_dofs()
    mono, sub = results["monolithic"], results["subdomain"]
    if comm.rank == 0:
        rounds = sum(s.inner_rounds for s in sub.history)
        print(
            f"| {layers}x{rows} | {dofs['plate_A'] + dofs['plate_B']} | {dofs['masters']} "
            f"| {sub.iterations} | {rounds} | {mono.seconds:.2f} | {sub.seconds:.2f} "
            f"| {sub.seconds / mono.seconds:.2f} | {difference:.1e} |",
            flush=True,
        )
