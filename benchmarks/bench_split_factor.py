"""Benchmark: the field split's two factorisations by LU and by Cholesky, double and single.

On the collector bar slot (constant setup, a warm state), the monolithic Jacobian merged and
cut into the splits of ``sc.THERMOELECTRIC_MECHANICAL``: (T, φ) and u. u's block is symmetric
and definite at every state; (T, φ)'s is not where current flows (Joule heat, σ(T)), but is at
this uniform state, where the potential is zero, so its Cholesky figures hold for this state
only. Each block is factorised by MUMPS's LU and, where it is symmetric, by its Cholesky
(flagged definite: LDLᵀ without pivoting, MUMPS's SYM=1), in double and in single precision
(``pc_precision``): a new factorisation (analysis and numerical factorisation), then the same
values factorised again in place (what a later Newton step pays). Each timed on the slowest
rank, best of ``--repeat``.

Printed per block and variant: both times, the ratio of each to LU in double on the same
block measured in the same run, MUMPS's flops (RINFOG(3)), its memory on all ranks
(INFOG(22), MB) and the factors' entries (INFOG(29)), and the residual of one solve against
a random right-hand side (relative, to show the precision).

Run: ``./dev python benchmarks/bench_split_factor.py [--size 0.06 --fine 0.02]`` (serial) or
under ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``. Not a test: compare ratios.
"""

import sys
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI
from petsc4py import PETSc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from slot_demo import slot_parser, warm_slot

parser = slot_parser(__doc__)
parser.add_argument("--repeat", type=int, default=2, help="timings of each, the best kept")
args = parser.parse_args()

demo, system = warm_slot(args.size, args.fine)
sc, comm = demo["sc"], MPI.COMM_WORLD
from subdomain_contact import merged
from subdomain_contact.monolithic import field_splits
from subdomain_contact.solvers import destroy, make_ksp, set_up

plan = merged.MergePlan(system)
K = plan.matrix(comm, plan.values(system))
splits = field_splits(system, sc.THERMOELECTRIC_MECHANICAL)
dofs = sum(system.num_dofs().values())  # collective


def clocked(work, *args) -> tuple[float, object]:
    """``work(*args)`` (collective): its wall-clock time on the slowest rank [s], its result."""
    comm.barrier()
    start = time.perf_counter()
    out = work(*args)
    return comm.allreduce(time.perf_counter() - start, op=MPI.MAX), out


def factorised(A: PETSc.Mat, options: dict, spd: bool) -> PETSc.KSP:
    """A new KSP on ``A`` set up from ``options`` (analysis and factorisation)."""
    A.setOption(PETSc.Mat.Option.SPD, spd)  # Cholesky: MUMPS's LDLᵀ without pivoting
    return make_ksp(A, "bench_split_", options)


def refactorised(A: PETSc.Mat, ksp: PETSc.KSP, csr: tuple) -> None:
    """``A``'s values written again, as at a later Newton step, and factorised in place."""
    A.setValuesCSR(*csr)
    A.assemble()
    ksp.setOperators(A)
    set_up(ksp)


def figures(A: PETSc.Mat, ksp: PETSc.KSP) -> dict:
    """MUMPS's flops, memory, factor entries and negative pivots; one solve's residual."""
    F = ksp.getPC().getFactorMatrix()
    b, x = A.createVecs()
    b.setRandom()
    ksp.solve(b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    out = {
        "flops": F.getMumpsRinfog(3),
        "memory MB": F.getMumpsInfog(22),
        "factor entries": F.getMumpsInfog(29),
        "negative pivots": F.getMumpsInfog(12),  # of an LDLᵀ (LU: off-diagonal pivots)
        "residual": r.norm() / b.norm(),
    }
    destroy(b, x, r)
    return out


def variant(A: PETSc.Mat, factor: str, precision: str) -> dict:
    """Factorise ``A`` anew and again in place, ``--repeat`` times each: the best times."""
    options = dict(sc.DIRECT) | {"pc_type": factor}
    if precision == "single":
        options["pc_precision"] = "single"
    new, again, csr = [], [], A.getValuesCSR()
    for _ in range(args.repeat):
        seconds, ksp = clocked(factorised, A, options, factor == "cholesky")
        new.append(seconds)
        again.append(clocked(refactorised, A, ksp, csr)[0])
        found = figures(A, ksp)
        destroy(ksp)
    return {"new": min(new), "again": min(again)} | found


results = {}
for name, rows in splits:
    A = K.createSubMatrix(rows, rows)
    frobenius = PETSc.NormType.FROBENIUS
    At = A.transpose(PETSc.Mat())
    At.axpy(-1.0, A)
    asymmetry = At.norm(frobenius) / A.norm(frobenius)
    At.destroy()
    factors = ("lu", "cholesky") if asymmetry <= 1e-12 else ("lu",)
    results[name] = {(f, p): variant(A, f, p) for f in factors for p in ("double", "single")} | {
        "asymmetry": asymmetry,
        "rows": A.getSize()[0],
    }
    A.destroy()

if comm.rank == 0:
    print(f"collector bar slot, {dofs} DOFs, {comm.size} rank(s), warm state (1000 K)")
    for name, by in results.items():
        base = by[("lu", "double")]
        print(f"  split {name}: {by['rows']} rows, ‖A - Aᵀ‖_F/‖A‖_F = {by['asymmetry']:.1e}")
        for key, r in by.items():
            if not isinstance(key, tuple):
                continue
            print(
                f"    {key[0]:8s} {key[1]:6s}"
                f" new {r['new']:7.2f} s ({r['new'] / base['new']:4.2f}x)"
                f"  again {r['again']:7.2f} s ({r['again'] / base['again']:4.2f}x)"
                f"  flops {r['flops']:.3g}  memory {r['memory MB']} MB"
                f"  entries {r['factor entries']:.3g}  residual {r['residual']:.1e}"
                + (f"  negative pivots {r['negative pivots']}" if key[0] == "cholesky" else "")
            )
destroy(K, *(iset for _, iset in splits))
system.destroy()
