"""Benchmark: the field split (T, φ), u on the collector bar slot, against MUMPS on the whole.

Runs the nested iteration of ``demos/demo_collector_bar_slot.py`` (its code up to its runs,
executed here), bar of 160 mm, in this process for each setup: the monolithic Newton with
MUMPS on the merged matrix (the baseline), the monolithic Newton by GMRES on one sweep over
(T, φ), then u, each factorised (``sc.FIELDSPLIT_DIRECT``), and the subdomain Newton with
its sparse strip whole (``sc.SparseStrip(split=False)``) and split (the default). Printed per
route: the whole time, its ratio to the baseline's measured in the same run, the fine level's
seconds and Newton steps, the GMRES iterations (monolithic) or inner rounds (subdomain) of
its steps, and the voltage drop.

Run: ``OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2 .venv/bin/python
benchmarks/bench_slot_field_split.py`` (the demo's default mesh, 65,900 DOFs; ``--size 0.035
--fine 0.012`` for 203,925). Not a test: timings on a shared machine are noisy; compare ratios.
"""

import argparse
import time

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
from slot_demo import slot_demo

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--size", type=float, default=0.06, help="element size away from the slot")
parser.add_argument("--fine", type=float, default=0.02, help="element size on the contacts")
parser.add_argument("--setups", nargs="+", default=["constant", "pressure"])
args = parser.parse_args()

demo = slot_demo("--size", str(args.size), "--fine", str(args.fine), "--no-study")
sc, say = demo["sc"], demo["say"]

ROUTES = {
    "monolithic, MUMPS": sc.Monolithic,
    "monolithic, split": lambda: sc.Monolithic(
        sc.FIELDSPLIT_DIRECT, splits=sc.THERMOELECTRIC_MECHANICAL
    ),
    "subdomain, strip whole": lambda: sc.Subdomains(corrector=sc.SparseStrip(split=False)),
    "subdomain, strip split": sc.Subdomains,
}
demo["route"] = lambda name: ROUTES[name]()

for setup in args.setups:
    seconds = {}
    for name in ROUTES:
        system = sc.System(demo["problem"](demo["load"](0.16), setup))
        tic = time.perf_counter()
        result, levels = demo["nested"](system, setup, 0.16, name)
        seconds[name] = time.perf_counter() - tic
        inner = [s.inner_rounds for s in result.history[1:]]
        fine = levels[-1]
        say(
            f"{setup}, {name}: {seconds[name]:.1f} s "
            f"({seconds[name] / seconds['monolithic, MUMPS']:.2f} x MUMPS); fine level "
            f"{fine['dofs']} DOFs, {fine['newton_iterations']} steps in {fine['seconds']:.1f} s; "
            f"inner {inner}; drop {fine['voltage_drop_mV']:.6f} mV"
        )  # fmt: skip
        system.destroy()
