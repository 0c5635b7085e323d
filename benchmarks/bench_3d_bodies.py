"""Benchmark: a 3D coupled scene (T, φ, u) of four bodies, the inner two floating.

Four blocks of 0.5 × 0.2 × 0.2 m in a row, tetrahedra (``geo/blocks_row3d.geo``), carbon-like
and steel-like in turn, every field through the three contacts, laws of p and T
(``verification.cases.squeezed_row``): only the end blocks carry conditions in T, φ and u_x,
so the inner two float (the interface solver's coarse space carries their constants and
their rigid translation). Both Newtons start cold and use default settings.

Printed per element size: DOFs, master DOFs, Newton iterations (subdomain, monolithic), inner
rounds, the bodies' sparse factorisations, the wall time of each Newton (system set-up included)
and their ratio measured in the same run, the peak resident set of each Newton above the one
before it (the largest over the ranks; Linux: the peak is reset through
``/proc/self/clear_refs``), and the largest difference between the two solutions over T, φ and
the three components of u, each relative to the field's range. ``--bodies iterative`` solves the
subdomain route's bodies by GMRES + GAMG per field, ``--bodies split`` by FGMRES on their (T, φ)
and u blocks factorised in single precision (``body.FACTORISED_SWEEP``; the rule's choice for
every block at 1M DOFs), and ``--no-lag`` rebuilds the
interface preconditioner at every Newton step (``sc.Subdomains(lag=False)``; kept by default);
``--no-monolithic`` leaves the monolithic Newton out where it does not fit; ``--history`` prints
each Newton's iterates, ``--progress`` a line per iterate as it comes; ``--gamg`` also runs the
monolithic Newton with GMRES + a field split of GAMG (``sc.FIELDSPLIT_GAMG``, stopping at
Newton's tolerance per field) and prints its outcome, ``--gamg-only`` that Newton alone;
``--splits direct single`` also runs the monolithic Newton by GMRES on one sweep over (T, φ),
then u, each factorised by MUMPS (``sc.FIELDSPLIT_DIRECT``; ``single``: in single precision with
block low-rank factors and FGMRES, ``sc.FIELDSPLIT_SINGLE``, the collector bar slot's route at
≥ 1M DOFs),
after the others (alone with ``--no-monolithic --no-subdomain``). ``--mumps-estimate`` runs no
Newton: it prints MUMPS's own estimate of the monolithic factorisation's memory (INFOG(16),
INFOG(17), in-core, after its analysis of the merged Jacobian at 300 K; the factorisation is
then refused by a 1 MB cap, ICNTL(23)), to set beside the measured peaks where the monolithic
Newton runs and to tell whether it fits where it does not.

Run: ``./dev python benchmarks/bench_3d_bodies.py`` (``--sizes 0.05 0.025``), and under
``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``: the monolithic MUMPS Newton spreads the blocks
over both ranks, the subdomain Newton and the field-split GAMG one give each rank two blocks
(``placement="groups"``; the field-split Newton spread them before 2026-11-29). Not a
test: compare ratios, not seconds.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import blocks_row_scene, squeezed_row
from verification.memory import mumps_estimate as estimate
from verification.memory import resident
from verification.nodal import NodalReference, error_against, field_values

#: --splits: the monolithic Newton's options for each.
SPLITS = {"direct": sc.FIELDSPLIT_DIRECT, "single": sc.FIELDSPLIT_SINGLE}
parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--sizes", type=float, nargs="+", default=[0.05, 0.025, 0.012])
parser.add_argument("--count", type=int, default=4, help="number of blocks")
parser.add_argument("--no-monolithic", action="store_true", help="no monolithic MUMPS Newton")
parser.add_argument("--no-subdomain", action="store_true", help="no subdomain Newton")
parser.add_argument(
    "--splits", nargs="+", default=[], choices=list(SPLITS),
    help="also the monolithic Newton by GMRES on a sweep over (T, φ), then u (each split "
    "factorised in double, or in single precision with block low-rank factors)",
)  # fmt: skip
parser.add_argument(
    "--bodies", default="auto", choices=["auto", "direct", "iterative", "split"],
    help="the subdomain route's body solves (sc.System's solver): auto is split for a "
    "3D body whose largest front exceeds scene.FRONT_ABOVE DOFs",
)  # fmt: skip
parser.add_argument(
    "--no-lag", action="store_true",
    help="rebuild the interface preconditioner at every Newton step (lag=False)",
)  # fmt: skip
parser.add_argument("--history", action="store_true", help="print each Newton's history")
parser.add_argument("--progress", action="store_true", help="a line per Newton iterate")
parser.add_argument(
    "--gamg", action="store_true", help="also the monolithic Newton by GMRES + field-split GAMG"
)
parser.add_argument(
    "--gamg-only", action="store_true", help="the field-split GAMG Newton alone (no reference)"
)
parser.add_argument(
    "--mumps-estimate", action="store_true",
    help="no Newton: MUMPS's estimate of the monolithic factorisation's memory",
)  # fmt: skip
args = parser.parse_args()
comm = MPI.COMM_WORLD
placement = "groups" if comm.size > 1 else "shared"
#: (field, component) pairs compared.
FIELDS = [("temperature", None), ("potential", None)] + [("displacement", i) for i in range(3)]


def newton(scene, linear, reference=None, bodies="direct"):
    """(result, seconds, GiB, DOFs, references or worst difference) of a Newton from 300 K."""
    comm.barrier()
    base = resident()
    tic = time.perf_counter()
    with sc.System(squeezed_row(scene), solver=bodies) as system:
        system.reset({"temperature": 300.0})
        result = sc.solve(system, linear, rtol=1e-12, progress=args.progress)
        seconds = comm.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        memory = comm.allreduce((resident("VmHWM") - base) / 2**20, op=MPI.MAX)
        dofs = system.num_dofs()
        if reference is None:
            compared = [NodalReference(*field_values(system, f, c)) for f, c in FIELDS]
        else:
            compared = max(
                error_against(system, ref.at(field_values(system, f, c)[0]), f, c)
                for ref, (f, c) in zip(reference, FIELDS, strict=True)
            )
    return result, seconds, memory, dofs, compared


def mumps_estimate(size: float) -> None:
    """Print MUMPS's estimate of the monolithic factorisation at 300 K [GiB]."""
    scene = blocks_row_scene(args.count, size, comm=comm, placement="shared")
    tic = time.perf_counter()
    with sc.System(squeezed_row(scene)) as system:
        system.reset({"temperature": 300.0})
        system.apply_conditions()
        system.assemble_jacobian()
        line = estimate(system)
    if comm.rank == 0:
        print(f"size {size}: {line} ({time.perf_counter() - tic:.0f} s)", flush=True)


if args.mumps_estimate:
    for size in args.sizes:
        mumps_estimate(size)
    raise SystemExit
if comm.rank == 0:
    print(
        "| size [m] | DOFs | masters | Newton (sub, mono) | inner rounds | factorisations "
        "| ranks | monolithic [s] | subdomain [s] | ratio | memory [GiB] (sub, mono) "
        "| difference |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")


def field_split(size: float, reference, against: str, split: str | None = None) -> None:
    """Print the outcome of the monolithic Newton by GMRES on a field split: of GAMG (no
    ``split``), or of MUMPS (``split``, a key of :data:`SPLITS`)."""
    if split is None:
        linear, name = sc.Monolithic(sc.FIELDSPLIT_GAMG, inexact=True), "field-split GAMG"
    else:
        linear = sc.Monolithic(SPLITS[split], splits=sc.THERMOELECTRIC_MECHANICAL)
        name = f"field split, MUMPS ({split})"
    # The subdomain Newton's placement; at 218,790 DOFs on 2 ranks the GAMG Newton took the
    # same time either way (335.2 s on groups, 340.8 s spread, 2026-11-29).
    scene = blocks_row_scene(args.count, size, comm=comm, placement=placement)
    try:
        result, seconds, memory, _, difference = newton(scene, linear, reference)
        apart = "—" if reference is None else f"{difference:.1e}"
        outcome = (
            f"{result.iterations} Newton steps ({result.line_search}), {result.rounds} GMRES "
            f"iterations, {seconds:.1f} s, {memory:.2f} GiB, difference from {against} {apart}"
        )
    except sc.NewtonConvergenceError as failure:
        outcome = f"failed: {str(failure).splitlines()[0]}"
    linear.destroy()
    if comm.rank == 0:
        print(f"size {size}, monolithic GMRES + {name}: {outcome}", flush=True)


for size in args.sizes:
    if args.gamg_only:  # where the two other routes' times are known from their own runs
        field_split(size, None, "no reference")
        continue
    mono, mono_seconds, mono_memory, reference = None, float("nan"), float("nan"), None
    if not args.no_monolithic:
        monolithic = sc.Monolithic()
        mono, mono_seconds, mono_memory, _, reference = newton(
            blocks_row_scene(args.count, size, comm=comm, placement="shared"), monolithic
        )
        monolithic.destroy()
    if args.no_subdomain:  # the monolithic routes' own
        sub = None
    else:
        scene = blocks_row_scene(args.count, size, comm=comm, placement=placement)
        sub, sub_seconds, sub_memory, dofs, difference = newton(
            scene, sc.Subdomains(lag=not args.no_lag), reference, args.bodies
        )
    if comm.rank == 0 and sub is not None:
        total = sum(v for k, v in dofs.items() if k != "masters")
        rounds = sum(s.inner_rounds for s in sub.history)
        print(
            f"| {size} | {total} | {dofs['masters']} | {sub.iterations}, "
            f"{mono.iterations if mono else '—'} | {rounds} | {sub.factorisations} "
            f"| {comm.size} | {mono_seconds:.1f} | {sub_seconds:.1f} "
            f"| {sub_seconds / mono_seconds:.2f} | {sub_memory:.2f}, {mono_memory:.2f} "
            f"| {'—' if mono is None else f'{difference:.1e}'} |",
            flush=True,
        )
        if sub.fallbacks:
            print(
                "body fallbacks (MUMPS for a failed Krylov solve, double for a short sweep, "
                f"AMG for a sweep without room): {sub.fallbacks}"
            )
        if args.history:
            print(f"subdomain Newton:\n{sub.table()}", flush=True)
            if mono is not None:
                print(f"monolithic Newton:\n{mono.table()}", flush=True)
    # the others against MUMPS's solution, else the subdomain Newton's (its references)
    if mono is None:
        reference = None if sub is None else difference
    against = "MUMPS" if mono is not None else "the subdomain Newton"
    against = against if reference is not None else "no reference"
    for split in ([None] if args.gamg else []) + args.splits:
        field_split(size, reference, against, split)
