"""Benchmark: the 8-body chain on 1 and 2 ranks, and CG iterations at 3 mesh refinements.

On 2 ranks it runs both placements: every body spread over both ranks ("shared"), and the
bodies split between the two ranks ("groups", four bodies each).

Run: `./dev python benchmarks/bench_stack_ranks.py` (it launches the 1- and 2-rank runs
itself with the venv's mpiexec). Prints the wall time of each run, the 2-rank / 1-rank
ratio measured in the same session, and the iterations per refinement. Not a test: timings
on a shared machine are noisy; compare ratios, not seconds.
"""

import json
import subprocess
import sys
import time
from pathlib import Path

WORKER = """
import json, sys, time
import dolfinx_solver
from mpi4py import MPI
import subdomain_contact as sc
from verification.cases import stack, stack_scene
rows = []
for refinement in {refinements}:
    scene = stack_scene(8, 8 * refinement, 8 * refinement, placement="{placement}")
    MPI.COMM_WORLD.barrier()
    tic = time.perf_counter()
    with sc.System(stack(scene, h=1e4)) as system:
        result = sc.solve(system)
        seconds = MPI.COMM_WORLD.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        mono = float("nan")
        if scene.shared:
            system.reset()
            tic = time.perf_counter()
            monolithic = sc.Monolithic()
            sc.solve(system, monolithic)
            monolithic.destroy()
            mono = MPI.COMM_WORLD.allreduce(time.perf_counter() - tic, op=MPI.MAX)
        dofs = sum(system.num_dofs().values())
    rows.append(dict(refinement=refinement, dofs=dofs,
                     iterations=sum(result.inner[-1].krylov_iterations), seconds=seconds,
                     monolithic_seconds=mono))
if MPI.COMM_WORLD.rank == 0:
    print("RESULT", json.dumps(rows))
"""


def run(ranks: int, refinements: list[int], placement: str = "shared") -> list[dict]:
    mpiexec = Path(sys.executable).parent / "mpiexec"
    code = WORKER.format(refinements=refinements, placement=placement)
    out = subprocess.run(
        [
            str(mpiexec),
            "-n",
            str(ranks),
            "-env",
            "OMP_NUM_THREADS",
            "1",
            sys.executable,
            "-c",
            code,
        ],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(next(line for line in out.splitlines() if line.startswith("RESULT"))[7:])


if __name__ == "__main__":
    refinements = [1, 2, 4]
    started = time.perf_counter()
    one = run(1, refinements)
    shared, groups = run(2, refinements), run(2, refinements, "groups")
    print(
        f"{'refinement':>10} {'DOFs':>7} {'CG its':>6} {'1 rank [s]':>10} {'2 shared':>9}"
        f" {'ratio':>6} {'2 groups':>9} {'ratio':>6} {'monolithic [s]':>14} {'1 rank/mono':>11}"
    )
    for a, b, c in zip(one, shared, groups, strict=True):
        print(
            f"{a['refinement']:>10} {a['dofs']:>7} {a['iterations']:>6} {a['seconds']:>10.3f}"
            f" {b['seconds']:>9.3f} {b['seconds'] / a['seconds']:>6.2f}"
            f" {c['seconds']:>9.3f} {c['seconds'] / a['seconds']:>6.2f}"
            f" {a['monolithic_seconds']:>14.3f} {a['seconds'] / a['monolithic_seconds']:>11.1f}"
        )
    print(f"(total {time.perf_counter() - started:.0f} s)")
