"""Profile: where the default subdomain solve of the two plates spends its time (issue 19).

The scene of ``bench_bddc.py`` (k = 1 | 10 W/(m K), top cooled, h = 1e3 W/(m² K)), one solve
from the assembly (``sc.System``) to the solution after two warm-up solves (forms compiled),
cProfile on rank 0; phases are cumulative times of the functions that make them. Run under
``mpiexec -n 2`` for the default placement (one plate per rank), with one BLAS thread
(``OMP_NUM_THREADS=1``)::

    OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2 .venv/bin/python benchmarks/profile_subdomain.py

``--size`` sets the plates' element layers (256: 132k DOFs, 724: 1.05M DOFs).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

#: The functions whose cumulative times make the phases (file suffix, function name).
TIMED = {
    "setup": ("system.py", "__init__"),
    "residual": ("system.py", "residual"),
    "laws": ("system.py", "check_laws"),
    "bulk": ("body.py", "bulk_matrix"),
    "mumps": ("schur.py", "_build"),
    "factorise": ("body.py", "factorise"),
    "solver": ("subdomain.py", "setup"),
    "rounds": ("subdomain.py", "_round"),
}


def main() -> None:
    import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
    from mpi4py import MPI

    import subdomain_contact as sc
    from verification.cases import two_plates, two_plates_scene

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--h", type=float, default=1e3)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    scene = two_plates_scene(args.size, args.size)
    base = two_plates(scene, h=args.h, k_a=1.0, k_b=10.0).problem
    problem = sc.Problem(scene, base.materials, base.contacts,
                         [*base.conditions, sc.Convection("top", 5.0, 2.0)])  # fmt: skip

    def run() -> tuple[float, int]:
        comm.Barrier()
        tic = time.perf_counter()
        with sc.System(problem) as system:
            sc.solve(system)
            dofs = sum(system.num_dofs().values())
        return comm.allreduce(time.perf_counter() - tic, op=MPI.MAX), dofs

    run(), run()
    profile = cProfile.Profile()
    profile.enable()
    seconds, dofs = run()
    profile.disable()
    if comm.rank != 0:
        return
    stats = pstats.Stats(profile).stats
    print(f"{dofs} DOFs, {comm.size} rank(s), h = {args.h:g}: {seconds:.3f} s (slowest rank)")
    print("| phase (rank 0) | seconds | share |\n|---|---|---|")

    def spent(suffix: str, name: str) -> float:
        return sum(
            entry[3] for (path, _, function), entry in stats.items()
            if path.endswith(suffix) and function == name
        )  # fmt: skip

    t = {key: spent(*where) for key, where in TIMED.items()}
    phases = {
        "system set-up: forms, slave maps, contact DOFs, matrices": t["setup"],
        "residuals": t["residual"],
        "law checks (laws that are not constants)": t["laws"],
        "bulk matrix assembly": t["bulk"],
        "MUMPS factorisation with the Schur block (analysis included)": t["mumps"],
        "scaling, Schur block update and its dense LU": t["factorise"] - t["bulk"] - t["mumps"],
        "correctors, interface operator": t["solver"] - t["factorise"],
        "rounds: body solves, master residuals": t["rounds"],
    }
    phases["rest (Newton's bookkeeping, state written back)"] = seconds - sum(phases.values())
    for label, spent in phases.items():
        print(f"| {label} | {spent:.3f} | {spent / seconds:.0%} |")


if __name__ == "__main__":
    main()
