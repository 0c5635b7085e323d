# # Joule heating in time: two bars heated by a current ramp until they reach steady state
#
# The electrical preheating of a Hall–Héroult cell in miniature, in time. A carbon-like bar and
# a steel-like bar, side by side between two walls, carry a current through one contact. The
# voltage across them is ramped from 0 to 1 V over two hours, then held. The bars heat by
# Joule effect (in the bulk and at the contact), expand against the walls, and the contact,
# open by 5 µm at first, closes: its pressure grows, its thermal and electrical conductances
# grow with it (laws of p and T), and the current rises. Each time step is a Newton solve of
# the whole coupled problem with the subdomain iteration inside.
#
# It shows
#
# * BDF2 with adaptive steps (a local error estimate of T, 0.5 K per step by default): short
#   steps during the ramp, long ones as the bars settle;
# * the probes against time (`history.csv`, `history.json`, `history.png`): temperatures at
#   the bars' centres, the current, the voltage drop across the contact and the contact's
#   electrical resistance, the mean contact pressure, the heat balance of every step;
# * the end state against the steady solver's answer;
# * a VTK time series (`series.pvd`: one scene, its time steps), checkpoints, and restart:
#   stop it with Ctrl-C (or SIGTERM) and run it again with `--restart`;
# * first, the schemes themselves: two slabs with a contact conductance against the series
#   solution, the error against time and against the step (`series_error.png`).
#
# ## The problem
#
# $\rho c_p \partial_t T - \nabla\cdot(k\nabla T) = \sigma|\nabla\phi|^2$,
# $-\nabla\cdot(\sigma\nabla\phi) = 0$, $-\nabla\cdot\boldsymbol\sigma(u, T) = 0$ (plane
# strain). Bars of 0.5 m × 0.1 m, T = 300 K at both ends, from 300 K everywhere at t = 0;
# u_x = 0 at both walls, rollers at the bottom (`verification.cases.warming_joule_bars`): the
# laws k(T), σ(T), h(p, T), g(p, T) and an exponential closure law; storage of amorphous
# carbon ρ = 1950 kg/m³, c_p = 726 J/(kg K), and plain carbon steel (AISI 1010) ρ = 7832
# kg/m³, c_p = 434 J/(kg K), at 300 K (Incropera et al., *Fundamentals of Heat and Mass
# Transfer*, 6th ed., table A.1). Time constants ρ c_p L²/k ≈ 9.8 h (carbon) and 5.2 h (steel).
#
# Run `python demos/demo_transient_joule.py` (`--small`: a coarse mesh and a short run, for
# the tests; `--quiet`: no progress line; `--restart`: go on from the latest checkpoint;
# `--no-series`: skip the schemes' check against the series).

import argparse
import json
import sys
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import GEO, composite_slabs, slab_error, warming_joule_bars

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a coarse mesh and a short run")
parser.add_argument("--out", type=Path, default=Path("out_transient_joule"))
parser.add_argument("--quiet", action="store_true", help="no progress line")
parser.add_argument("--restart", action="store_true", help="go on from the latest checkpoint")
parser.add_argument("--tolerance", type=float, default=0.5, help="local error per step [K]")
parser.add_argument("--no-series", action="store_true", help="skip the check against the series")
args = parser.parse_args()
comm = MPI.COMM_WORLD
started = time.perf_counter()
HOUR = 3600.0
VOLTAGE = 1.0  # [V] after the ramp


def say(*text: object) -> None:
    if comm.rank == 0 and not args.quiet:
        print(*text, flush=True)


layers, rows = (6, 2) if args.small else (64, 12)
# the small run stops at 2.5 h, once the contact has closed (the tests check balances and
# restart on it); the full one goes on for 5 days, 12 times the slower time constant: the
# steady state
until = 2.5 * HOUR if args.small else 120 * HOUR
scene = sc.load_scene(
    GEO / "two_plates.geo",
    bodies=["plate_A", "plate_B"],
    interfaces=["contact"],
    parameters={"layers": layers, "rows": rows, "length": 0.5, "height": 0.1},
)
ramp = sc.Schedule((0.0, 2 * HOUR), (0.0, VOLTAGE))  # [V]


def probes(system: sc.System) -> dict[str, float]:
    """What the history records at every step (one reading of the state)."""
    report = sc.summary(system)
    fields = sc.contact_fields(system)["contact"]
    area = fields["area"]
    jump = float(np.sum(fields["potential jump"] * area) / area.sum())
    current = report["contacts"]["contact"]["current"]
    return {
        "T centre carbon [K]": sc.value_at(system, "plate_A", "temperature", (0.25, 0.05)),
        "T centre steel [K]": sc.value_at(system, "plate_B", "temperature", (0.75, 0.05)),
        "current [A/m]": current,
        "contact voltage drop [mV]": 1e3 * jump,
        "contact resistance [µΩ m]": 1e6 * jump / current if current else float("nan"),
        "mean contact pressure [MPa]": 1e-6 * report["contacts"]["contact"]["mean pressure"],
        "heat imbalance [relative]": report["balance"]["heat"]["relative"],
    }


system = sc.System(warming_joule_bars(scene, ramp))
system.reset({"temperature": 300.0})
stepper = sc.Stepper(system, "bdf2")
history = sc.History(
    args.out,
    stepper,
    probes,
    until=until,
    vtk_every=10,
    vtk_times=[2 * HOUR] if until > 2 * HOUR else [],
    checkpoint_every=5,
    quiet=args.quiet,
)
resumed = history.start(restart=args.restart)
say(f"{system.num_dofs()} DOFs on {comm.size} rank(s); BDF2, local error {args.tolerance} K/step")
stepper.march(
    until,
    60.0,
    tolerance=args.tolerance,
    max_step=12 * HOUR,
    land_on=history.vtk_times,
    after_step=history.after_step,
    rtol=1e-10,
)
history.finish()
if history.interrupted:
    system.destroy()
    sys.exit(1)

# ## The end state against the steady solver's answer (the full run reaches steady state)
x = system.state()
to_steady = None
if not args.small:
    # Newton from the end state: 0 iterations when the steady residual of the end state is
    # already below its tolerance. (From a cold start, full Newton steps fail on this scene,
    # the contact closing under the heat; steps limited to 100 K reach it, in 27 steps at
    # 40 x 8 cells per bar.)
    steady = sc.System(warming_joule_bars(scene, VOLTAGE, storage=False))
    steady.set_state(x)  # the same layout
    steady_newton = sc.solve(steady, rtol=1e-10).iterations
    to_steady = system.difference(x, steady.state()) | {"newton": steady_newton}
    steady.destroy()
    say(f"end state vs steady solve, per field: {to_steady}")

# ## Verification: two slabs with a contact conductance against the series solution
#
# k = 2 and 1 W/(m K), ρ c_p = 4e6 and 1e6 J/(m³ K), h = 10 W/(m² K), from 0 K with the left
# end raised to 1 K at t = 0 (`verification.analytic.CompositeSlab`, the eigenfunction series
# of a composite slab with a contact resistance). The error at every step against the series,
# for both schemes and three step sizes: first and second order.


def slab_errors(scheme: str, steps: int, cells: int, end: float) -> list[tuple[float, float]]:
    """(time [s], largest nodal error [K]) at every step."""
    slabs, series = composite_slabs(cells, comm=comm)
    errors = []
    with sc.System(slabs) as slab:
        slab.reset()
        stepper = sc.Stepper(slab, scheme)
        for _ in range(steps):
            stepper.advance(end / steps, rtol=1e-12)
            errors.append((stepper.time, slab_error(slab, series, stepper.time)))
    return errors


def verify_schemes(cells: int = 128) -> dict:
    """Errors against the series at three step sizes, both schemes; ``series_error.png``.

    128 cells per slab keep P1's error below the schemes' at these steps (1D: cheap).
    """
    series = {
        scheme: {n: slab_errors(scheme, n, cells, 2e5) for n in (8, 16, 32)}
        for scheme in sc.transient.SCHEMES
    }
    orders = {
        scheme: [float(np.log2(runs[n][-1][1] / runs[2 * n][-1][1])) for n in sorted(runs)[:-1]]
        for scheme, runs in series.items()
    }
    say(f"two slabs against the series, {cells} cells each: observed orders {orders}")
    if comm.rank == 0:
        figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
        for scheme, runs in series.items():
            for n, errors in runs.items():
                t, e = zip(*errors, strict=True)
                left.semilogy(np.array(t) / HOUR, e, ".-", label=f"{scheme}, Δt = 2e5/{n} s")
            ends = [runs[n][-1][1] for n in sorted(runs)]
            right.loglog([2e5 / n for n in sorted(runs)], ends, "o-", label=scheme)
        left.set_xlabel("time [h]")
        left.set_ylabel("largest nodal error [K] (of 1 K)")
        left.legend(fontsize=7)
        right.set_xlabel("Δt [s]")
        right.set_ylabel("error at t = 2e5 s [K]")
        right.legend()
        right.grid(True, which="both", alpha=0.3)
        figure.suptitle("two slabs with a contact conductance against the series solution")
        figure.tight_layout()
        figure.savefig(args.out / "series_error.png", dpi=110)
        plt.close(figure)
    ends = {s: {n: r[-1][1] for n, r in runs.items()} for s, runs in series.items()}
    return {"cells": cells, "end errors": ends, "orders": orders}


end = history.rows[-1]
say(
    f"{stepper.steps} steps ({stepper.rejected} taken again) to t = {stepper.time / HOUR:.3g} h; "
    f"T centre carbon {end['T centre carbon [K]']:.5g} K, current {end['current [A/m]']:.5g} A/m"
)
report = {
    "dofs": system.num_dofs(),
    "ranks": comm.size,
    "steps": stepper.steps,
    "rejected": stepper.rejected,
    "resumed": resumed,
    "until": until,
    "factorisations": int(sum(row["factorisations"] for row in history.rows)),
    "newton": [row["newton"] for row in history.rows],
    "max heat imbalance": max(row["heat imbalance [relative]"] for row in history.rows),
    "end": end,
    "end_vs_steady": to_steady,
    "readback": sc.summary(system),
    "series": None if args.no_series else verify_schemes(),
    "seconds": time.perf_counter() - started,
}
if comm.rank == 0:
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
    last = sorted((args.out / "vtk").glob("step_*"))[-1]
    sc.plot_vtk(last / "scene.pvd", args.out / "end.png", title=f"t = {until / HOUR:.3g} h")
x.destroy()
system.destroy()
say(f"wrote {args.out}/ in {time.perf_counter() - started:.1f} s")
