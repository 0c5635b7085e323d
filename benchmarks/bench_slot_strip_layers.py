"""Benchmark: the sparse strip's layers on the collector bar slot, against the monolithic Newton.

Runs the nested iteration of ``demos/demo_collector_bar_slot.py`` (its code up to its runs,
executed here), constant setup, bar of 160 mm, three times in this process: the monolithic
Newton, the subdomain Newton with the default ``SparseStrip()`` (10 layers) and with
``SparseStrip(layers=1)``. Printed per route: each level's DOFs, Newton steps and seconds,
the whole time, its ratio to the monolithic Newton's measured in the same run, the inner
rounds of the finest level's steps and the voltage drop.

Run: ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2 .venv/bin/python
benchmarks/bench_slot_strip_layers.py --size 0.0194 --levels 2`` (one element size
everywhere; 174,240 DOFs). Not a test: timings on a shared machine are noisy; compare ratios.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from slot_demo import slot_demo

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--size", type=float, default=0.0388, help="element size everywhere [m]")
parser.add_argument("--levels", type=int, default=2, help="meshes of the nested iteration")
args = parser.parse_args()

size = str(args.size)
demo = slot_demo(
    "--size", size, "--fine", size, "--no-study", "--setups", "constant",
    "--levels", str(args.levels),
)  # fmt: skip
sc, say = demo["sc"], demo["say"]

ROUTES = {
    "monolithic": sc.Monolithic,
    "strip of 10 layers": sc.Subdomains,
    "strip of 1 layer": lambda: sc.Subdomains(corrector=sc.SparseStrip(layers=1)),
}
demo["route"] = lambda name: ROUTES[name]()

seconds = {}
for name in ROUTES:
    system = sc.System(demo["problem"](demo["load"](0.16), "constant"))
    tic = time.perf_counter()
    result, levels = demo["nested"](system, "constant", 0.16, name)
    seconds[name] = time.perf_counter() - tic
    steps = ", ".join(
        f"{v['dofs']}: {v['newton_iterations']} in {v['seconds']:.1f} s" for v in levels
    )
    rounds = [s.inner_rounds for s in result.history[1:]]
    say(
        f"{name}: {seconds[name]:.1f} s ({seconds[name] / seconds['monolithic']:.2f} x "
        f"monolithic); levels {steps}; inner rounds {rounds}; "
        f"drop {levels[-1]['voltage_drop_mV']:.6f} mV; factorisations {result.factorisations}"
    )  # fmt: skip
    system.destroy()
