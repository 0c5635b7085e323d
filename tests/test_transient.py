"""Backward Euler steps: the heat balance of every step, the steady limit, reuse, both routes."""

import dataclasses

import numpy as np
import pytest
from helpers import make_system
from mpi4py import MPI

import subdomain_contact as sc
from verification.analytic import CompositeSlab
from verification.cases import bars_scene, joule_bars, two_plates_scene


def heated_plates(scene, *, capacity=True):
    """Plates of 1 m at 0 K, the left end raised to 1 K at t = 0, the right end at 0 K;
    k = 2 and 1 W/(m K), ρ c_p = 4e6 J/(m^3 K) (τ = ρ c_p L² / k ≈ 2e6 s), h = 10 W/(m² K)."""
    inertia = {"density": 4000.0, "heat_capacity": 1000.0} if capacity else {}
    return sc.Problem(
        scene,
        {
            "plate_A": sc.Material(conductivity=2.0, **inertia),
            "plate_B": sc.Material(conductivity=1.0, **inertia),
        },
        {"contact": sc.Contact(conductance=10.0)},
        [sc.Temperature("left", 1.0), sc.Temperature("right", 0.0), sc.Convection("top", 5.0, 0.5)],
    )


def test_every_step_balances_its_heat_and_keeps_the_factorisations(comm):
    """Stored heat = in − out at every BDF2 step (exactly: the stored heat is a term of the
    residual), the subdomain and monolithic steps agree, and a linear bulk at a fixed Δt is
    factorised once per set of weights."""
    scene = two_plates_scene(6, 6, comm=comm)
    routes = {"subdomain": sc.Subdomains, "monolithic": sc.Monolithic}
    states, factorisations = {}, {}
    for name, linear in routes.items():
        system = make_system(heated_plates(scene))
        system.reset()
        stepper = sc.Stepper(system, "bdf2")
        factorisations[name], states[name] = [], []
        for _ in range(4):
            result = stepper.advance(2e5, linear(), rtol=1e-12)
            factorisations[name].append(result.factorisations)
            budget = sc.balance(system)["heat"]
            # the imbalance is what Newton leaves at the free DOFs and masters (rtol 1e-12
            # of the scale, 2-norm over ~100 DOFs): measured ≤ 5e-16
            assert budget["relative"] < 1e-10
            assert budget["stored"] > 0  # the plates warm up
            states[name].append(system.state())
    # the same steps, each to rtol 1e-12: measured ≤ 3.4e-16 apart
    for a, b in zip(states["subdomain"], states["monolithic"], strict=True):
        assert max(system.difference(a, b).values()) < 1e-10
    # two bodies; again when BDF2's weights replace backward Euler's, then kept
    assert factorisations["subdomain"] == [2, 2, 0, 0]


def test_long_steps_reach_the_steady_state(comm):
    """Steps of Δt = 1e6 τ: each multiplies the distance to the steady state by about
    τ / Δt = 1e-6 (both schemes damp it), so three steps from 0 K leave round-off."""
    scene = two_plates_scene(4, 4, comm=comm)
    steady = make_system(heated_plates(scene, capacity=False))
    steady.reset()
    sc.solve(steady, rtol=1e-12)
    for scheme in sc.transient.SCHEMES:
        system = make_system(heated_plates(scene))
        system.reset()
        stepper = sc.Stepper(system, scheme)
        for _ in range(3):
            stepper.advance(2e12, rtol=1e-12)
        # measured 1.0e-13 apart (Newton's rtol 1e-12 of each solve; (1e-6)³ of the field
        # is far below): 1e-10 leaves 1000 times that
        assert max(system.difference(system.state(), steady.state()).values()) < 1e-10
        assert stepper.time == 6e12 and stepper.steps == 3


def test_bad_steps_and_inertia_are_refused(comm):
    scene = two_plates_scene(2, 2, comm=comm)
    stepper = sc.Stepper(make_system(heated_plates(scene)))
    for step in (0.0, -1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="step"):
            stepper.advance(step)
    with pytest.raises(ValueError, match="scheme"):
        sc.Stepper(stepper.system, "crank_nicolson")
    with pytest.raises(ValueError, match="density and heat_capacity together"):
        sc.Problem(
            scene,
            {n: sc.Material(conductivity=1.0, density=1.0) for n in ("plate_A", "plate_B")},
            {"contact": sc.Contact(conductance=1.0)},
            [sc.Temperature("left", 1.0)],
        )


@pytest.mark.parametrize(("scheme", "order"), [("backward_euler", 1), ("bdf2", 2)])
def test_steps_converge_to_the_series_solution_at_their_order(comm, scheme, order):
    """Two slabs (k 2 and 1 W/(m K), ρ c_p 4e6 and 1e6 J/(m³ K), h = 10 W/(m² K)) from 0 K,
    the left end at 1 K from t = 0: against the eigenfunction series (verification.analytic.
    CompositeSlab) at t = 2e5 s, with 8, 16 and 32 steps on 128 cells per slab.

    Backward Euler is first order and BDF2 second (its first step is backward Euler, whose
    local error is of the second order). Measured errors [K, of 1 K]: backward Euler 1.7e-2,
    8.5e-3, 4.2e-3 (rates 0.999, 1.001); BDF2 1.8e-3, 3.5e-4, 8.6e-5 (rates 2.35, 2.02).
    ±0.15 on the finer pair's rate holds the next term of the error expansion (0.35 on the
    coarse BDF2 pair, halving with each pair) and the spatial error (128 P1 cells).
    """
    scene = two_plates_scene(128, 1, comm=comm)
    problem = sc.Problem(
        scene,
        {
            "plate_A": sc.Material(conductivity=2.0, density=4000.0, heat_capacity=1000.0),
            "plate_B": sc.Material(conductivity=1.0, density=1000.0, heat_capacity=1000.0),
        },
        {"contact": sc.Contact(conductance=10.0)},
        [sc.Temperature("left", 1.0), sc.Temperature("right", 0.0)],
    )
    series = CompositeSlab(1.0, 2.0, 1.0, 4e6, 1e6, 10.0, 1.0, terms=60)
    end, errors = 2e5, []
    for steps in (8, 16, 32):
        system = make_system(problem)
        system.reset()
        stepper = sc.Stepper(system, scheme)
        for _ in range(steps):
            stepper.advance(end / steps, rtol=1e-12)
        worst = 0.0
        for name, body in system.bodies.items():
            points, values = body.nodal("temperature")
            exact = series.temperature(points[:, 0], end, "a" if name == "plate_A" else "b")
            worst = max(worst, float(np.abs(values - exact).max(initial=0.0)))
        errors.append(comm.allreduce(worst, op=MPI.MAX))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert order - 0.15 <= rates[-1] <= order + 0.15, (errors, rates)
    assert errors[-1] < 1e-2  # and the series is what they converge to


def test_a_voltage_ramp_drives_the_current_at_every_step(comm, shared_tmp):
    """The Joule bars (constant σ, g) heated by a voltage ramped 0 → 0.5 V over 4 h, read
    from a CSV file: the potential is quasi-static and linear, so at every step the current
    is the closed form's at that step's voltage (round-off: measured ≤ 2.3e-15 relative), while
    the temperature lags and the heat balance, stored heat included, closes."""
    if comm.rank == 0:
        (shared_tmp / "ramp.csv").write_text("time [s],voltage [V]\n0,0\n14400,0.5\n")
    comm.barrier()
    ramp = sc.Schedule.from_csv(shared_tmp / "ramp.csv")
    assert ramp.at(7200.0) == 0.25 and ramp.at(1e9) == 0.5
    scene = bars_scene(4, 2, comm=comm)
    problem, exact = joule_bars(scene)
    carbon = dataclasses.replace(problem.materials["plate_A"], density=1600.0, heat_capacity=700.0)
    steel = dataclasses.replace(problem.materials["plate_B"], density=7800.0, heat_capacity=500.0)
    problem = sc.Problem(
        scene,
        {"plate_A": carbon, "plate_B": steel},
        problem.contacts,
        [
            sc.Temperature("left", 300.0),
            sc.Temperature("right", 320.0),
            sc.Potential("left", ramp),
            sc.Potential("right", 0.0),
        ],
    )
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    stepper = sc.Stepper(system, "bdf2")
    resistance = 0.5 / (exact.current_density * 0.1)  # [Ω m] of the bars and the contact
    for _ in range(6):
        stepper.advance(3600.0, rtol=1e-12)
        voltage = ramp.at(stepper.time)
        current = sc.current(system, "left")
        assert current == pytest.approx(voltage / resistance, rel=1e-12)
        assert sc.balance(system)["heat"]["relative"] < 1e-10  # as in the first test
    assert stepper.time == 21600.0
