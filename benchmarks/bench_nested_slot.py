"""Benchmark: nested iteration against the cold start, on the collector bar slot.

Runs ``demos/demo_collector_bar_slot.py`` twice in this process, base case only
(``--no-study``), both Newton routes: once with ``--levels 1`` (Newton from a uniform 300 K
on the run's mesh) and once with ``--levels N`` (from 300 K on a mesh 2^(N-1) times coarser,
then on each finer mesh from the solution before it). Printed per setup and route: Newton
steps on the run's mesh, the whole solve's wall time (coarser levels included) and the
ratio nested / cold measured in the same run, and the two voltage drops. Each setup in a run
of its own: a run of both starts the second from the first one's solution.

Run: ``./dev python benchmarks/bench_nested_slot.py [--size 0.06 --fine 0.02] [--levels 3]``
(serial) or under ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2``. Not a test: timings on a
shared machine are noisy; compare ratios.
"""

import argparse
import json
import runpy
import sys
import tempfile
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from mpi4py import MPI

DEMO = Path(__file__).resolve().parent.parent / "demos" / "demo_collector_bar_slot.py"

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--size", type=float, default=0.12, help="element size away from the slot [m]")
parser.add_argument("--fine", type=float, default=0.04, help="element size on the contacts [m]")
parser.add_argument("--levels", type=int, default=2, help="meshes of the nested iteration")
parser.add_argument("--setups", nargs="+", default=["constant", "pressure"])
args = parser.parse_args()
comm = MPI.COMM_WORLD
folder = Path(comm.bcast(tempfile.mkdtemp(prefix="bench_nested_") if comm.rank == 0 else None))


def run(levels: int) -> dict:
    """The demo's runs with ``levels`` meshes, each setup from the cold state."""
    runs = {}
    for setup in args.setups:
        out = folder / f"levels_{levels}_{setup}"
        sys.argv = [str(DEMO), "--no-study", "--size", str(args.size), "--fine", str(args.fine),
                    "--levels", str(levels), "--out", str(out), "--setups", setup]  # fmt: skip
        runpy.run_path(str(DEMO), run_name="__main__")
        comm.barrier()
        runs |= json.loads((out / "report.json").read_text())["runs"]
    return runs


cold, nested = run(1), run(args.levels)
if comm.rank == 0:
    print(f"\nsize {args.size} m, fine {args.fine} m, {comm.size} rank(s), levels {args.levels}")
    print("setup      route       DOFs     steps cold/nested  seconds cold/nested  ratio  "
          "drop cold/nested [mV]")  # fmt: skip
    for setup in args.setups:
        for route in ("subdomain", "monolithic"):
            key = f"{setup}, bar 160 mm, {route}"
            a, b = cold[key], nested[key]
            print(
                f"{setup:10s} {route:10s} {sum(a['dofs'].values()):8d} "
                f"{a['newton_iterations']:5d} / {b['newton_iterations']:<5d}      "
                f"{a['wall_seconds']:8.1f} / {b['wall_seconds']:<8.1f}  "
                f"{b['wall_seconds'] / a['wall_seconds']:5.2f}  "
                f"{a['voltage_drop_mV']:.4f} / {b['voltage_drop_mV']:.4f}"
            )
            steps = [(lv["dofs"], lv["newton_iterations"]) for lv in b["nested"]]
            print(f"{'':10s} {route:10s} nested levels (DOFs, Newton steps): {steps}")
