"""Every demo runs in its small form, serially and under MPI, and reports sound numbers."""

import json
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

from subdomain_contact.newton import STEP_RTOL

DEMOS = sorted((Path(__file__).parents[1] / "demos").glob("demo_*.py"))
CHECKED = {
    "demo_two_plates",
    "demo_stack",
    "demo_joule_stack",
    "demo_thermal_expansion",
    "demo_error_vs_runtime",
    "demo_extreme_cases",
    "demo_transient_joule",
    "demo_collector_bar_slot",
    "demo_preheat",
}


def test_every_demo_is_checked_here():
    assert {d.stem for d in DEMOS} == CHECKED


def run_demo(path, out, monkeypatch, *extra):
    monkeypatch.setattr(sys, "argv", [str(path), "--small", "--out", str(out), *extra])
    runpy.run_path(str(path), run_name="__main__")


def assert_balanced_to_newton(run):
    """Each balance of a Newton solve within what Newton's final residual allows.

    A balance's imbalance is the sum of its field's residual entries at the free DOFs and
    masters (the flows are the entries at the supports, the heat generated and stored the
    residual's own terms, integrated alike), so |imbalance| ≤ √n ‖F_f‖₂ (Cauchy–Schwarz; n,
    every DOF of the scene, is more than the field's). The report divides it by the
    balance's own scale, not Newton's: the bound does too. On top, the round-off of summing
    n flows of at most that scale: n ε.
    """
    n = sum(run["dofs"].values())
    fields = {"heat": "temperature", "current": "potential", "force": "displacement"}
    for name, field in fields.items():
        budget = run["balance"][name]
        bound = np.sqrt(n) * run["final_residual"][field] / budget["scale"]
        assert budget["relative"] <= bound + n * np.finfo(float).eps, (name, budget, bound)


def demo(name):
    return next(d for d in DEMOS if d.stem == name)


def assert_balanced(readback, bound=1e-8):
    """Heat, current and force of a solved scene balance to Newton's tolerance.

    The imbalance is the sum of what Newton leaves at the free DOFs and masters (below rtol
    ≤ 1e-10 of each field's scale in 2-norm): over the n < 2000 DOFs of a small demo, at
    most √n rtol ≈ 4.5e-9. Measured ≤ 7e-15 on every demo (joule_stack, coupled).
    """
    balance = readback["balance"]
    assert balance, "no balance in the report"
    for name, budget in balance.items():
        assert budget["relative"] < bound, (name, budget)


def test_demo_two_plates(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_two_plates"
    run_demo(demo("demo_two_plates"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    assert_balanced(report["readback"])
    # paper's table 1: X exact for the uniform mode, one correction and the check
    assert [row["iterations"] for row in report["table1"]] == [2, 2]
    exact = [row for row in report["sweep"] if row["corrector"] == "exact"]
    assert len(exact) == 6
    assert all(row["iterations"] <= 2 for row in exact)  # one correction, then the check
    # nodally exact, round-off only (measured 1e-15; as in test_thermal_contact)
    assert max(row["max_error_vs_analytic"] for row in exact) <= 1e-9
    method1 = {
        row["h"]: row["iterations"] for row in report["sweep"] if row["corrector"] == "method1"
    }
    # method 1 contracts by h̄/(1 + h̄) = 2e-8 at h = 1e-8: two corrections reach rtol 1e-10,
    # the third round checks; at h = 1e12 it contracts by 1 − 5e-13: never in 100 rounds
    assert method1[1e-8] == 3 and method1[1e12] is None
    assert (out / "iterations_vs_h.png").stat().st_size > 10_000
    assert (out / "plate_A.pvd").exists() and (out / "master_contact.pvd").exists()
    assert report["ranks"] == comm.size
    rows = {
        (r["variant"], r["h"], r["coupling"], r["acceleration"]): r for r in report["partitioned"]
    }
    # uniform data, one scalar mode: a secant removes it, the third iteration checks
    assert rows["uniform", 1e4, "Robin-Robin", "iqn-ils"]["iterations"] == 3
    # round-off of a map that contracts by 0.96 (test_partitioned): measured 7e-13 (2e-12 on
    # 2 ranks), 1e-10 leaves 50 times that
    assert rows["uniform", 1e4, "Robin-Robin", "iqn-ils"]["max_error"] < 1e-10
    assert rows["uniform", 1e4, "Robin-Robin", "constant"]["iterations"] is None
    # Dirichlet-Neumann exchanges heat: exact to round-off at h = 1e10 where Robin-Robin is not
    # (measured 5e-16, 1.1e-15 on 2 ranks)
    assert rows["cooled", 1e10, "Dirichlet-Neumann", "aitken"]["max_error"] < 1e-12
    assert rows["cooled", 1e10, "Robin-Robin", "aitken"]["iterations"] is None
    assert (out / "partitioned.md").exists()


def test_demo_stack(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_stack"
    run_demo(demo("demo_stack"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    assert_balanced(report["readback"])
    exact = [row for row in report["krylov"] if row["corrector"] == "exact"]
    assert len(exact) == 8
    assert all(row["relative_residual"] <= 1e-10 for row in exact)  # the stopping rule
    # CG ends within as many iterations as the interface problem has unknowns
    assert all(max(row["krylov_iterations"]) <= row["master_dofs"] for row in exact)
    # the monolithic reference itself loses digits as h grows, about 8 eps h in units of
    # k/L (test_krylov): judge it at h ≤ 1e4, where that is 2e-11 (measured ≤ 4e-12)
    assert max(row["error_vs_monolithic"] for row in exact if row["h"] <= 1e4) <= 1e-9
    fixed = {(r["h"], r["corrector"]): r["outcome"] for r in report["fixed_point"]}
    assert fixed[1e-4, "exact"] == "converged" and fixed[1e4, "exact"] != "converged"
    assert (out / "iterations.png").exists() and (out / "body_3.pvd").exists()


def test_demo_joule_stack(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_joule_stack"
    run_demo(demo("demo_joule_stack"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    assert_balanced(report["constant_laws"]["readback"])
    assert_balanced(report["coupled"]["readback"])
    assert (out / "coupled.png").stat().st_size > 10_000  # the arrows picture
    constant = report["constant_laws"]
    # nodally exact, converged to rtol 1e-12 (test_multiphysics: ≤ 1.2e-14)
    assert max(constant["errors"].values()) < 1e-8
    coupled = report["coupled"]
    assert max(coupled["difference"].values()) < 1e-8  # both at rtol 1e-12: 5e-16 measured
    # the exact corrector: one correction and the check at every Newton step
    assert (
        coupled["runs"]["subdomain"]["inner_rounds"][1:]
        == [2] * coupled["runs"]["subdomain"]["iterations"]
    )
    # the exact Jacobian that makes Newton quadratic (derivation of 1.9: test_multiphysics)
    assert min(min(o.values()) for o in coupled["jacobian_taylor_orders"]) > 1.9
    assert coupled["mean_pressure"] > 1e5  # closed (2.6e6 Pa measured)
    assert (out / "newton.png").exists() and (out / "master_contact.pvd").exists()
    assert (out / "plate_A_displacement.pvd").exists()
    assert report["ranks"] == comm.size


def test_demo_thermal_expansion(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_thermal_expansion"
    run_demo(demo("demo_thermal_expansion"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    for step in report["steps"]:
        assert_balanced(step["readback"])
    assert all((out / f"{s}.png").stat().st_size > 10_000 for s in ("hot", "cold"))
    states = [row["state"] for row in report["steps"]]
    assert states == ["open", "closed", "open"]
    for row in report["steps"]:
        # uniform strain, exact for P1: round-off only (measured ≤ 7.7e-15)
        assert row["pressure_error"] < 1e-8 and row["gap_error"] < 1e-8
        if row["state"] == "open":
            assert row["pressure"] == 0.0 and row["gap"] > 0
    assert max(report["monolithic_difference"].values()) < 1e-8  # rtol 1e-12: 2e-14
    assert (out / "pressure.png").exists() and (out / "hot" / "plate_A.pvd").exists()


def test_demo_error_vs_runtime(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_error_vs_runtime"
    run_demo(demo("demo_error_vs_runtime"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    assert report["readback"]
    for readback in report["readback"].values():
        assert_balanced(readback)
    rows = {(r["problem"], r["dofs"], r["method"]): r for r in report["rows"]}
    largest = max(d for p, d, _ in rows if p == "two_plates")
    plates = {m: r for (p, d, m), r in rows.items() if p == "two_plates" and d == largest}
    # The exact methods reach the reference; the iterative ones say why when they do not.
    # Each runs to 1e-12 or its round-off floor: measured ≤ 1.4e-12 (interface CG), ≤ 1.2e-14
    # for the others; 1e-10 leaves 70 times the worst.
    for method in ("monolithic MUMPS", "monolithic CG+GAMG", "subdomain exact",
                   "interface CG (partial)", "DN aitken", "DN iqn-ils", "RR iqn-ils"):  # fmt: skip
        assert plates[method]["final_error"] < 1e-10, method
        assert plates[method]["seconds_to_target"] is not None, method
    if comm.size > 1:  # BDDC (one plate per rank) stops at 1e-12 like the other iterations
        assert plates["monolithic BDDC deluxe"]["final_error"] < 1e-10
    assert plates["subdomain exact"]["iterations"] == 2  # one correction, then the check
    assert "no convergence" in plates["subdomain method1"]["note"]
    assert "diverged" in plates["DN constant"]["note"]
    stack = {m: r for (p, _, m), r in rows.items() if p == "stack"}
    assert stack["interface CG (partial)"]["final_error"] < 1e-10  # 3.7e-14 measured
    assert "no convergence" in stack["subdomain exact"]["note"]  # floating bodies: needs CG
    newton = {m: r for (p, _, m), r in rows.items() if p == "joule_bars"}
    # Newton to rtol 1e-12 per field against Newton-MUMPS: measured ≤ 6e-16; GMRES + GAMG
    # stops at its own ksp_rtol inside: ≤ 1e-15 measured at the converged state
    assert newton["Newton, subdomain exact"]["final_error"] < 1e-12
    assert newton["Newton, monolithic GMRES+GAMG"]["final_error"] < 1e-10
    assert all(r["ranks"] == comm.size for r in report["rows"])
    for name in ("summary.csv", "iterations.csv", "results.md", "time_vs_dofs.png"):
        assert (out / name).stat().st_size > 100, name
    assert (out / "error_vs_time_two_plates.png").stat().st_size > 10_000
    # the table and plots rewritten from the CSV alone are the same table
    again = shared_tmp / "out_error_vs_runtime_again"
    monkeypatch.setattr(sys, "argv", ["demo", "--from-csv", str(out), "--out", str(again)])
    runpy.run_path(str(demo("demo_error_vs_runtime")), run_name="__main__")
    comm.barrier()
    assert (again / "results.md").read_text() == (out / "results.md").read_text()


def test_demo_extreme_cases(shared_tmp, monkeypatch, comm):
    out = shared_tmp / "out_extreme_cases"
    run_demo(demo("demo_extreme_cases"), out, monkeypatch)
    comm.barrier()
    rows = {r["case"]: r for r in json.loads((out / "report.json").read_text())["rows"]}
    assert not [r for r in rows.values() if r["verdict"] == "WRONG"]
    for row in rows.values():  # the balances of every solved case, as assert_balanced
        assert not row["balance"] or max(row["balance"].values()) < 1e-8, row
    assert rows["potential of 1e4 V: 1.2e8 A/m², T up to 1e10 K"]["balance"]
    refused = {name for name, r in rows.items() if r["verdict"] == "refused"}
    assert refused == {
        "h = -1 (negative)",
        "h = NaN",
        "method 1 at h = 1e6 (cannot converge)",
        "floating scene: no temperature anywhere",
        "Robin-Robin + Aitken at h = 1e10, top cooled",
    }
    assert "heat balance" in rows["Robin-Robin + Aitken at h = 1e10, top cooled"]["message"]
    assert (
        "defined only up to a constant"
        in rows["floating scene: no temperature anywhere"]["message"]
    )
    # nodally exact closed forms, round-off only: measured 3.8e-14 and 3.4e-14 (both rank
    # counts); the suite's own tolerance is 1e-9
    assert rows["h = 0 (insulating)"]["error"] < 1e-12
    assert rows["h = 1e+14 W/(m² K)"]["error"] < 1e-12
    assert (out / "extreme.md").exists()


def test_demo_transient_joule(shared_tmp, monkeypatch, comm):
    """The bars heat, expand and close their contact; every step balances its heat."""
    import csv

    import pyvista

    out = shared_tmp / "out_transient_joule"
    run_demo(demo("demo_transient_joule"), out, monkeypatch)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    with open(out / "history.csv") as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == report["steps"] and [int(r["step"]) for r in rows] == list(
        range(1, len(rows) + 1)
    )
    # every step's heat balance to Newton's tolerance, as assert_balanced (measured ≤ 2e-11;
    # 2.1e-4 when the link and the master equation used different quadratures)
    assert report["max heat imbalance"] < 1e-8
    assert_balanced(report["readback"])
    resistance = [float(r["contact resistance [µΩ m]"]) for r in rows]
    pressure = [float(r["mean contact pressure [MPa]"]) for r in rows]
    # open at first: R = 1 / (g(0, T) H) = 1 / (1e3 S/m² × 0.1 m) = 1e4 µΩ m, g at 300 K; the
    # first step warms the contact by well under 1e-3 K, which moves g(0, T) by < 2.5e-6
    assert pressure[0] == 0.0
    assert resistance[0] == pytest.approx(1e4, rel=1e-5)
    # closed by 2.5 h: the pressure rises and the resistance falls more than tenfold
    assert pressure[-1] > 0.1 and resistance[-1] < 1e3
    times = [float(r["time [s]"]) for r in rows]
    assert 7200.0 in times  # a step ends on the ramp's corner
    assert times[-1] == report["until"]
    # the VTK series: every 10th step, the ramp's end and the last step, at their times
    written = sorted({t for r, t in zip(rows, times, strict=True) if int(r["step"]) % 10 == 0}
                     | {7200.0, times[-1]})  # fmt: skip
    if comm.rank == 0:
        reader = pyvista.get_reader(str(out / "series.pvd"))
        assert reader.time_values == pytest.approx(written, rel=1e-12)
        reader.set_active_time_value(written[-1])
        # each bar, its displacement (a vector, a file of its own) and the master layer
        assert reader.read().n_blocks == 5
    assert (out / "history.png").exists() and (out / "end.png").exists()
    # the schemes against the series (as tests/test_transient.py: measured 0.999, 1.001 and
    # 2.35, 2.02; ±0.15 on the finer pair)
    orders = report["series"]["orders"]
    assert abs(orders["backward_euler"][-1] - 1) <= 0.15
    assert abs(orders["bdf2"][-1] - 2) <= 0.15
    assert (out / "series_error.png").exists()


# Six Newton solves from the cold start (≈ 5 min serial on the development machine, 2
# cores): the suite's 300 s guard against hangs is per test, so this one gets 3 times it.
@pytest.mark.timeout(900)
def test_demo_collector_bar_slot(shared_tmp, monkeypatch, comm, capsys):
    out = shared_tmp / "out_collector_bar_slot"
    # Each session runs four solves (CI time): serially the subdomain route with the design
    # study (the 174 mm bar); under mpiexec both routes on the base case, whose agreement is
    # asserted there (serially, the same code's agreement on the three-body cathode slot of
    # test_coupling). The study repeats the base case's code on another mesh. The constant
    # setup's by nested iteration from the cold state, the pressure setup's from its solution.
    study = comm.size == 1
    # in parallel the subdomain route against the monolithic one by the field split
    extra = ("--linear", "subdomain") if study else ("--no-study", "--linear", "subdomain", "split")
    run_demo(demo("demo_collector_bar_slot"), out, monkeypatch, *extra)
    comm.barrier()
    report = json.loads((out / "report.json").read_text())
    runs = report["runs"]
    if comm.rank == 0:  # the progress line says why full steps gave up, before the limited
        lines = capsys.readouterr().out.splitlines()
        starts = [i for i, line in enumerate(lines) if line.startswith("Newton (limited)   0:")]
        # the constant setup's climb from 300 K: the line before the limited steps, where
        # full steps gave up, says why. Mostly the runaway safeguard's verdict on a halved
        # step; on 2 ranks the full steps wander first along a path that the round-off sets
        # (one code, four runs: 4 or 12–18 steps, or converged; eight runs of 2026-12-08:
        # converged in 19–25), and ended once by GMRES breaking down on the runaway iterates
        # of the field split (PETSc reason -5): a reason either way. Where full steps
        # converge there is no such line (the chain's lines: test_coupling).
        reasons = ("lands at", "monolithic linear solve failed")
        for i in starts:
            assert lines[i - 1].startswith("Newton (basic): Newton failed after"), lines[i - 1]
            assert any(reason in lines[i - 1] for reason in reasons), lines[i - 1]
    for setup in ("constant", "pressure"):
        solved = [f"{setup}, bar 160 mm, subdomain"]
        if study:  # the design variant: a 174 mm bar, by the subdomain route
            solved += [f"{setup}, bar 174 mm, subdomain"]
        else:
            # both routes to Newton's rtol 1e-10 on each field's scale: the two solutions agree
            # to a few times that, relative to each field's largest value (measured ≤ 6e-14
            # against MUMPS on the merged matrix)
            assert max(runs[f"{setup}, bar 160 mm, difference"].values()) < 1e-8, setup
            solved += [f"{setup}, bar 160 mm, split"]
        for key in solved:
            run = runs[key]
            assert_balanced_to_newton(run)
            total = run["current_total_A"]
            # the whole current enters the top: the Neumann data, 300 kA / 28 blocks / 4,
            # integrated exactly (a constant density on plane facets)
            assert abs(total) == pytest.approx(300e3 / 28 / 4, rel=1e-12), key
            through = run["contact_current_A"]
            # every ampere crosses the cast iron/carbon faces, then the bar/cast iron faces:
            # flows read from the residual close as the current balance does (measured 3e-16)
            carbon = through["slot_side"] + through["slot_top"]
            bar = through["bar_side"] + through["bar_top"]
            assert abs(carbon) == pytest.approx(abs(total), rel=1e-8), key
            assert abs(bar) == pytest.approx(abs(total), rel=1e-8), key
            if setup == "pressure":
                # from the constant setup's solution on the same mesh: the climb is done,
                # full steps find the pressures and the law's conductances (measured 7
                # steps on both routes, 2 ranks, where from 300 K on the coarse mesh the
                # limited steps took 24–36 of 50 and, about once in ten suites, more)
                (level,) = run["nested"]
                assert level["start"] == "previous setup" and level["coarsening"] == 1.0
                assert level["line_search"] == "basic", key
                continue
            # nested iteration: from the cold start (300 K) on the mesh 2 times coarser, with
            # the default settings; where full steps diverge (the progress lines above), steps
            # limited to 100 K of temperature converge, so the hottest node's climb alone
            # takes ceil((T_max − 300 K) / 100 K) steps (10: T_max ≈ 1224 K)
            coarse, finest = run["nested"]
            assert coarse["coarsening"] == 2.0 and finest["coarsening"] == 1.0, key
            if coarse["line_search"] == "limited":
                climb = np.ceil((max(run["max_temperature_K"].values()) - 300.0) / 100.0)
                assert coarse["newton_iterations"] >= climb >= 10, key
            # the run's mesh from the coarse mesh's solution, interpolated: the climb is done,
            # Newton's own convergence and the contacts' search for their status are left, in
            # full steps (measured 10 and 10 steps at 160 mm, 7 and 8 at 174 mm; from the cold
            # start 18 and 25 at 160 mm on this mesh, 17 and 30–40 on the coarse one)
            assert finest["newton_iterations"] == run["newton_iterations"], key
            assert finest["line_search"] == "basic", key
            assert finest["newton_iterations"] < coarse["newton_iterations"], key
        if not study:
            continue
        # the design study: a taller bar (174 mm) puts steel where the more resistive cast iron
        # was (2 mm left above the bar instead of 16), so the voltage drop must fall; measured
        # -5.4 mV (constant) and -2.9 mV (pressure) at this size
        change = report["design_study"][setup]["change [mV]"]
        assert change < 0, (setup, change)
    assert report["mesh_convergence"] == {}  # at the default size only (419k DOFs at its finest)
    assert report["boundary_conditions"]["start"].startswith("uniform 300.0 K on the coarsest")
    assert (out / "slot_faces.png").stat().st_size > 10_000
    assert (out / "constant").is_dir() and (out / "pressure").is_dir()  # the VTK
    assert report["ranks"] == comm.size


def preheat(shared_tmp, monkeypatch, comm, folder: str, *extra) -> tuple:
    """The preheat demo at ``--small`` with ``extra`` into ``folder``: the folder, its report."""
    out = shared_tmp / folder
    run_demo(demo("demo_preheat"), out, monkeypatch, *extra)
    comm.barrier()
    return out, json.loads((out / "report.json").read_text())


def test_demo_preheat(shared_tmp, monkeypatch, comm):
    """The first 6 h of a coke bed preheat: both routes equal per step, every step balanced."""
    out, report = preheat(shared_tmp, monkeypatch, comm, "out_preheat")
    # subdomain and monolithic Newton, the first three steps: both to rtol 1e-10 of each
    # field's scale, so they agree to a few times that (measured ≤ 4e-15)
    routes = report["routes"]["differences"]
    assert len(routes) == 3
    assert max(max(step.values()) for step in routes) < 1e-8
    run = report["runs"]["coke 20 mm"]
    # the --small run ends at its time limit, 6 h, every step converged (a failed step
    # raises); the schedule's line current then, 20 % + 80 % × 6/24 of 300 kA, entered
    assert run["end time [h]"] == pytest.approx(6.0, rel=1e-12)
    assert run["end"]["line current [kA]"] == pytest.approx(120.0, rel=1e-12)
    assert len(run["newton"]) == run["steps"] >= 3
    # every step's heat balance to Newton's tolerance, as test_demo_transient_joule
    # (measured ≤ 5e-11)
    assert run["max heat imbalance"] < 1e-8
    # over the run, each step's balance summed: the electrical energy in (V I, the stubs'
    # mean potential times their current: exact for a uniform current density) is the Joule
    # heat of the bulk and the contacts, step by step, to Newton's tolerance (the discrete
    # energy identity); the Joule heat is what was lost plus what the scheme stored
    scheme = run["energy [J]"]["scheme"]
    assert scheme["power"] > 0 and scheme["stored"] > 0
    assert abs(scheme["power"] - scheme["generated"]) < 1e-8 * scheme["power"]
    assert abs(scheme["imbalance"]) < 1e-8 * scheme["generated"]
    # the energy balance of the run: electrical energy in − lost (trapezoidal rule in time)
    # against the enthalpy change of the bodies, off by the time integration alone: measured
    # 5.1e-3 with 8 steps of up to 2 h (local error 2 K per step); 4x margin, the steps are
    # chosen adaptively and may differ on another machine
    energy = run["energy [J]"]
    assert energy["enthalpy change"] > 0
    assert abs(energy["imbalance, relative"]) < 2e-2
    # the end state: the shares of the Joule heat are shares (the metals' is the rest)
    end = run["end"]
    shares = [end[f"{part} share"] for part in ("coke bed", "coke contacts", "carbon")]
    assert min(shares) > 0 and sum(shares) < 1
    # the current entering the anodes leaves the block through the slot's faces or the
    # ramming paste: charge conservation on the anode, the bed and the block, to Newton's
    # tolerance (1e-10 of the current's scale, the current itself here; measured 7e-15)
    for row in json.loads((out / "coke_20_mm" / "history.json").read_text())["rows"]:
        shares = row["slot faces current share"] + row["ramming paste current share"]
        assert shares == pytest.approx(1.0, abs=1e-8)
        assert row["slot faces current share"] > 0 and row["ramming paste current share"] > 0
    assert end["cathode surface min T [K]"] <= end["cathode surface mean T [K]"]
    assert end["cathode surface mean T [K]"] <= end["cathode surface max T [K]"]
    assert (out / "preheat.png").stat().st_size > 10_000
    assert (out / "coke_20_mm" / "series.pvd").exists()
    assert report["ranks"] == comm.size


def test_demo_preheat_refuses_a_slot_law_without_its_pressure(shared_tmp, monkeypatch, capsys):
    """The slot's law of pressure needs the pressure: the 3D quarter with its mechanics."""
    with pytest.raises(SystemExit):
        run_demo(demo("demo_preheat"), shared_tmp / "no", monkeypatch, "--slot-law", "pressure")
    assert "--slot-law pressure needs --quarter --mechanics" in capsys.readouterr().err


def test_demo_preheat_mechanics(shared_tmp, monkeypatch, comm):
    """The slice with its displacements, its first hour, under MPI: the routes agree in
    every field, the anodes' weight rests on the bed, the forces balance. (Serially the
    pressure load and the contact readings are tested in test_multiphysics: CI time.)"""
    if comm.size == 1:
        pytest.skip("the preheat's mechanics run under mpiexec (CI time)")
    flags = ("--mechanics", "--hours", "1")
    out, report = preheat(shared_tmp, monkeypatch, comm, "out_preheat_mechanics", *flags)
    # both routes to rtol 1e-10 of each field's scale, then polished by Newton steps until
    # one moves every field by at most 1e-9 of its largest value (the demo's routes()):
    # the bar, cast iron and paste, held along the slot by the slip spring and the open
    # contacts' ties, are loose where Newton's residual test stops (the subdomain route's
    # first step left them 1.5e-6 off on a machine with AVX-512 kernels, 9.3e-11 elsewhere).
    # The corrections contract by about 1.6e-3 a step, so a last one of 1e-9 leaves 2e-12:
    # 1e-8 is the agreement (measured 8e-16)
    differences = report["routes"]["differences"]
    assert all("displacement" in step for step in differences)
    assert max(max(step.values()) for step in differences) < 1e-8
    for last in report["routes"]["last corrections"].values():
        assert max(max(step.values()) for step in last) <= STEP_RTOL
    run = report["runs"]["coke 20 mm"]
    assert run["end time [h]"] == pytest.approx(1.0, rel=1e-12)
    assert run["max heat imbalance"] < 1e-8  # as without the mechanics
    anode = 1560.0 * 9.81 * 0.6  # Pa: the anode's weight on its top (the demo's ANODE_PRESSURE)
    for row in json.loads((out / "coke_20_mm" / "history.json").read_text())["rows"]:
        # nothing else holds the anode up, and nothing but the anode weighs on the bed (its
        # own weight and the block's are not loads): the mean pressure on both of the bed's
        # faces is the anode's weight over its footprint, to what Newton's test allows. The
        # anode's balance is a sum of residual entries, ≤ √n ‖F_u‖₂ ≤ √n 1e-10 × the
        # displacements' scale (as assert_balanced_to_newton): n = 4,596 DOFs, the scale (the
        # cold load of the thermal misfits) 1.7e4 times the weight: 1.2e-4 (measured ≤ 6e-10
        # serially over 120 h)
        for face in ("anode_coke", "coke_block"):
            assert row[f"{face} mean pressure [MPa]"] * 1e6 == pytest.approx(anode, rel=1.2e-4)
            assert 0 <= row[f"{face} open share"] < 1
        assert row["force imbalance [relative]"] < 1e-8
        assert row["slot_top max pressure [MPa]"] >= row["slot_top mean pressure [MPa]"] >= 0
    assert (out / "preheat.png").stat().st_size > 10_000


def test_demo_preheat_quarter(shared_tmp, monkeypatch, comm):
    """The 3D quarter of the slice, its first hour, under MPI: the routes agree, the balances
    close. (Serially the demo's code is the 2D slice's, tested above: CI time.)"""
    if comm.size == 1:
        pytest.skip("the 3D quarter runs under mpiexec; its code is the 2D slice's")
    flags = ("--quarter", "--hours", "1")
    _, report = preheat(shared_tmp, monkeypatch, comm, "out_preheat_quarter", *flags)
    # both routes to rtol 1e-10 of each field's scale (as the 2D slice; measured ≤ 1e-14)
    assert max(max(step.values()) for step in report["routes"]["differences"]) < 1e-8
    run = report["runs"]["coke 20 mm"]
    assert run["end time [h]"] == pytest.approx(1.0, rel=1e-12)
    # 300 kA / 28 blocks / 4 through the quarter at 20 % + 80 % × 1/24 of the line current
    assert run["end"]["line current [kA]"] == pytest.approx(300 * (0.2 + 0.8 / 24), rel=1e-12)
    assert run["max heat imbalance"] < 1e-8  # as the 2D slice
    scheme = run["energy [J]"]["scheme"]
    assert abs(scheme["power"] - scheme["generated"]) < 1e-8 * scheme["power"]
    assert abs(scheme["imbalance"]) < 1e-8 * scheme["generated"]
    assert report["ranks"] == comm.size
