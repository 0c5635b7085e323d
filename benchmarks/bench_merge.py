"""Benchmark: the merged matrix of a Newton step, by COO triples and by the plan's scatter.

On the collector bar slot (constant setup, a warm state), the whole merged matrix of the
monolithic solve made three ways, each timed (the slowest rank, best of ``--repeat``) with
the bodies' matrices assembled beforehand, so that only the merge is timed:

- ``coo``: every entry as a (row, column, value) triple, summed and sorted by scipy into a new
  AIJ matrix: the route the strip corrector's restricted matrix and BDDC's unassembled one
  still take (:func:`subdomain_contact.merged._body_entries`), and the monolithic solve's
  until 2026-12-02;
- ``plan``: :class:`~subdomain_contact.merged.MergePlan` made (the pattern sorted once, a code
  for each entry) and its values written into a new matrix: a Newton step whose pattern is
  new;
- ``scatter``: the plan's :meth:`values` written into the kept matrix in place: every later
  Newton step.

Printed: the times, the ratios to ``coo`` measured in the same run, the entries, and whether
the three matrices are the same (pattern equal, values to a few ε of each row's largest).

Run: ``./dev python benchmarks/bench_merge.py [--size 0.06 --fine 0.02]`` (serial) or under
``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``. Not a test: timings on a shared machine are
noisy; compare ratios.
"""

import sys
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from slot_demo import slot_parser, warm_slot

parser = slot_parser(__doc__)
parser.add_argument("--repeat", type=int, default=3, help="timings of each, the best kept")
args = parser.parse_args()

demo, system = warm_slot(args.size, args.fine)
sc, comm = demo["sc"], MPI.COMM_WORLD
from subdomain_contact import merged

for body in system.bodies.values():
    body.whole_matrix()  # assembled here, not in the timings


def coo():
    layout, entries, masters = merged.Layout(system), [], []
    for name in system.bodies:
        rows, parts = merged._body_entries(system, layout, name)
        entries += rows
        masters += parts
    gathered = comm.gather(masters, root=0)
    if comm.rank == 0:
        entries += [part for parts in gathered for part in parts]
    r, c, v = merged._concatenate(entries)
    n = (system.local_size, PETSc.DETERMINE)
    shape = (system.local_size, layout.size)
    return merged._aij(r - layout.mine, c, v, shape, (n, n), comm)


def planned():
    plan = merged.MergePlan(system)
    return plan, plan.matrix(comm, plan.values(system))


def best(work, spent=lambda out: None) -> tuple[float, object]:
    """The best of ``--repeat`` timings of ``work()`` and its last result (the earlier ones
    handed to ``spent``)."""
    times, out = [], None
    for i in range(args.repeat):
        if i:
            spent(out)
        comm.barrier()
        start = time.perf_counter()
        out = work()
        times.append(comm.allreduce(time.perf_counter() - start, op=MPI.MAX))
    return min(times), out


t_coo, K_coo = best(coo, lambda K: K.destroy())
t_plan, (plan, K_plan) = best(planned, lambda out: out[1].destroy())
t_scatter, _ = best(lambda: plan.write(K_plan, plan.values(system)))

a, b = K_coo.getValuesCSR(), K_plan.getValuesCSR()
same = np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
scale = np.repeat(np.maximum.reduceat(np.abs(a[2]), a[0][:-1]), np.diff(a[0])) if same else 0
close = same and bool(np.all(np.abs(a[2] - b[2]) <= 8 * np.finfo(float).eps * scale))
same, close = comm.allreduce(same, op=MPI.LAND), comm.allreduce(close, op=MPI.LAND)
entries = comm.allreduce(plan.nnz)
dofs = sum(system.num_dofs().values())  # collective
if comm.rank == 0:
    print(f"collector bar slot, {dofs} DOFs, {entries} entries, {comm.size} rank(s)")
    for label, t in (("coo", t_coo), ("plan", t_plan), ("scatter", t_scatter)):
        print(f"  {label:8s} {t:7.3f} s   {t / t_coo:5.2f} x coo")
    print(f"  same pattern {same}, values within 8 eps of each row's largest {close}")
K_coo.destroy()
K_plan.destroy()
system.destroy()
