"""Benchmark: a 3D coupled scene (T, φ, u) of four bodies, the inner two floating.

Four blocks of 0.5 × 0.2 × 0.2 m in a row, tetrahedra (``geo/blocks_row3d.geo``), carbon-like
and steel-like in turn, every field through the three contacts, laws of p and T
(``verification.cases.squeezed_row``): only the end blocks carry conditions in T, φ and u_x,
so the inner two float (the interface solver's coarse space carries their constants and
their rigid translation). Both Newtons start cold and use default settings.

Printed per element size: DOFs, master DOFs, Newton iterations (subdomain, monolithic), inner
rounds, the bodies' sparse factorisations, the wall time of each Newton (system set-up
included) and their ratio measured in the same run, and the largest difference between the
two solutions over T, φ and the three components of u, each relative to the field's range.

Run: ``./dev python benchmarks/bench_3d_bodies.py`` (``--sizes 0.05 0.025``), and under
``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``: the monolithic Newton spreads the blocks over
both ranks, the subdomain Newton gives each rank two blocks (``placement="groups"``). Not a
test: compare ratios, not seconds.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import blocks_row_scene, squeezed_row
from verification.nodal import NodalReference, error_against, field_values

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--sizes", type=float, nargs="+", default=[0.05, 0.025, 0.012])
parser.add_argument("--count", type=int, default=4, help="number of blocks")
args = parser.parse_args()
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"
#: (field, component) pairs compared.
FIELDS = [("temperature", None), ("potential", None)] + [("displacement", i) for i in range(3)]


def newton(scene, linear, reference=None):
    """(result, seconds, DOFs, references or worst difference) of one Newton from 300 K."""
    comm.barrier()
    tic = time.perf_counter()
    with sc.System(squeezed_row(scene)) as system:
        system.reset({"temperature": 300.0})
        result = sc.solve(system, linear, rtol=1e-12)
        seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        dofs = system.num_dofs()
        if reference is None:
            compared = [NodalReference(*field_values(system, f, c)) for f, c in FIELDS]
        else:
            compared = max(
                error_against(system, ref.at(field_values(system, f, c)[0]), f, c)
                for ref, (f, c) in zip(reference, FIELDS, strict=True)
            )
    return result, seconds, dofs, compared


if comm.rank == 0:
    print(
        "| size [m] | DOFs | masters | Newton (sub, mono) | inner rounds | factorisations "
        "| ranks | monolithic [s] | subdomain [s] | ratio | difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
for size in args.sizes:
    monolithic = sc.Monolithic()
    mono, mono_seconds, dofs, reference = newton(
        blocks_row_scene(args.count, size, comm=comm, placement="shared"), monolithic
    )
    monolithic.destroy()
    scene = blocks_row_scene(args.count, size, comm=comm, placement=placement)
    sub, sub_seconds, _, difference = newton(scene, sc.Subdomains(), reference)
    if comm.rank == 0:
        total = sum(v for k, v in dofs.items() if k != "masters")
        rounds = sum(s.inner_rounds for s in sub.history)
        print(
            f"| {size} | {total} | {dofs['masters']} | {sub.iterations}, {mono.iterations} "
            f"| {rounds} | {sub.factorisations} | {comm.size} | {mono_seconds:.1f} "
            f"| {sub_seconds:.1f} | {sub_seconds / mono_seconds:.2f} | {difference:.1e} |",
            flush=True,
        )
