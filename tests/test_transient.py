"""Backward Euler steps: the heat balance of every step, the steady limit, reuse, both routes."""

import dataclasses

import numpy as np
import pytest
from helpers import make_system
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import (
    bars_scene,
    composite_slabs,
    joule_bars,
    slab_error,
    two_plates_scene,
    warming_joule_bars,
)


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
    problem, series = composite_slabs(128, comm=comm)
    end, errors = 2e5, []
    for steps in (8, 16, 32):
        system = make_system(problem)
        system.reset()
        stepper = sc.Stepper(system, scheme)
        for _ in range(steps):
            stepper.advance(end / steps, rtol=1e-12)
        errors.append(slab_error(system, series, end))
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


@pytest.mark.parametrize(("scheme", "order"), [("backward_euler", 1), ("bdf2", 2)])
def test_the_error_estimate_and_the_adaptive_steps_follow_the_order(comm, scheme, order):
    """The local error estimate scales as Δt^{p+1} at fixed steps; adaptive steps that hold
    it at a tolerance take N ∝ tol^{-1/(p+1)} steps and reach a global error ∝ tol^{p/(p+1)}
    (N steps of local error tol), against the series solution.

    Measured on 64 cells per slab. Estimate at t = 1e5 s, Δt = 4e3, 2e3, 1e3 s: backward
    Euler ratios 4.23, 4.11 (slopes 2.08, 2.04), BDF2 8.85, 8.39 (3.15, 3.07); ±0.15 on the
    finer pair holds the next term. Adaptive, tol = 1e-3, 1e-4, 1e-5 K to t = 2e5 s:
    backward Euler 89, 260, 801 steps (slope 0.477 of 0.5), errors 4.6e-3, 1.6e-3, 5.1e-4
    (0.48 of 0.5); BDF2 40, 75, 149 steps (0.286 of 0.333), errors 1.2e-3, 3.6e-4, 9.1e-5
    (0.565 of 0.667). The start from a discontinuity (the left end jumps to 1 K) costs a
    number of short steps that does not depend on tol, which flattens both slopes: ±0.07 on
    the step count, ±0.12 on the error.
    """
    problem, series = composite_slabs(64, comm=comm)
    estimates = []
    for step in (4e3, 2e3, 1e3):
        system = make_system(problem)
        system.reset()
        stepper = sc.Stepper(system, scheme)
        for _ in range(round(1e5 / step)):
            stepper.advance(step, rtol=1e-12)
        estimates.append(stepper.error_estimate())
    slopes = np.log2(np.array(estimates[:-1]) / np.array(estimates[1:]))
    assert abs(slopes[-1] - (order + 1)) <= 0.15, (estimates, slopes)
    tolerances, steps, errors = np.array([1e-3, 1e-4, 1e-5]), [], []
    for tolerance in tolerances:
        system = make_system(problem)
        system.reset()
        stepper = sc.Stepper(system, scheme)
        stepper.march(2e5, 1e3, tolerance=tolerance, rtol=1e-12)
        assert stepper.time == 2e5
        steps.append(stepper.steps)
        errors.append(slab_error(system, series, 2e5))
    step_slope = -np.polyfit(np.log10(tolerances), np.log10(steps), 1)[0]
    error_slope = np.polyfit(np.log10(tolerances), np.log10(errors), 1)[0]
    assert abs(step_slope - 1 / (order + 1)) <= 0.07, (steps, step_slope)
    assert abs(error_slope - order / (order + 1)) <= 0.12, (errors, error_slope)


def test_a_failed_newton_halves_the_step_and_leaves_no_trace(comm):
    """The warming Joule bars with steps of 1 h and at most 3 Newton iterations: the steps
    over which the contact closes fail and are taken again at half the length. Replaying the
    accepted steps one by one on a fresh system gives the same state to round-off: a failed
    attempt leaves nothing behind (state, history, clock, weights). A step that fails at the
    shortest length allowed is refused with a message, the last accepted state kept."""
    scene = bars_scene(6, 2, comm=comm)
    ramp = sc.Schedule((0.0, 7200.0), (0.0, 1.0))
    system = make_system(warming_joule_bars(scene, ramp))
    system.reset({"temperature": 300.0})
    stepper = sc.Stepper(system, "bdf2")
    lengths = []
    stepper.march(
        9000.0, 3600.0, after_step=lambda s, r: lengths.append(s.last_step), max_it=3, rtol=1e-10
    )
    assert stepper.rejected >= 1 and stepper.time == 9000.0
    assert min(lengths) < 3600.0 / 1.9  # some were halved (or more)
    again = make_system(warming_joule_bars(scene, ramp))
    again.reset({"temperature": 300.0})
    replay = sc.Stepper(again, "bdf2")
    for length in lengths:
        replay.advance(length, max_it=3, rtol=1e-10)
    # the same operations in the same order: measured identical; 1e-12 for a reduction order
    assert max(system.difference(again.state(), system.state()).values()) <= 1e-12
    before = system.state()
    with pytest.raises(sc.StepFailedError, match="min_step") as failure:
        stepper.march(20000.0, 3600.0, min_step=3600.0, max_it=0)
    assert "line_search='bt'" in str(failure.value)
    assert stepper.time == 9000.0
    assert max(system.difference(system.state(), before).values()) == 0.0


def test_a_flux_switched_on_at_a_time(comm):
    """A heat flux of 10 W/m² switched on at t = 5e5 s (a Schedule with that time twice): a
    step ends on the switch and takes the value before it; the next takes the value after.
    The flux through the group is the assembled load (exact: 10 W/m² × 1 m)."""
    scene = two_plates_scene(4, 2, comm=comm)
    switch = sc.Schedule((0.0, 5e5, 5e5, 1e6), (0.0, 0.0, 10.0, 10.0))
    assert (switch.at(5e5), switch.at(5e5 + 1e-3), switch.at(2e6)) == (0.0, 10.0, 10.0)
    problem = sc.Problem(
        scene,
        {n: sc.Material(conductivity=1.0, density=1e3, heat_capacity=1e3) for n in scene.bodies},
        {"contact": sc.Contact(conductance=10.0)},
        [sc.HeatFlux("left", switch), sc.Temperature("right", 0.0)],
    )
    system = make_system(problem)
    system.reset()
    stepper = sc.Stepper(system, "backward_euler")
    seen = {}

    def record(s, result):
        seen[s.time] = sc.heat(system, "left")
        assert sc.balance(system)["heat"]["relative"] < 1e-10  # as in the first test

    stepper.march(1e6, 2e5, after_step=record, rtol=1e-12)
    assert sorted(seen) == [2e5, 4e5, 5e5, 7e5, 9e5, 1e6]
    assert [seen[t] for t in sorted(seen)] == pytest.approx([0, 0, 0, 10, 10, 10], abs=1e-12)
    with pytest.raises(ValueError, match="never three"):
        sc.Schedule((0.0, 1.0, 1.0, 1.0), (0.0, 1.0, 2.0, 3.0))


@pytest.mark.parametrize("given", ["schedule", "function of (x, t)"])
def test_a_boundary_uncovered_at_a_time(comm, given):
    """A convection coefficient switched from 0 to 50 W/(m² K) at t = 4e5 s (ambient 0 K,
    the plates held at 1 K on the left), as a Schedule or as a function (x, t): no heat
    leaves the top before the switch, and after it the heat through the group is its
    assembled load, h ∫ (T_amb − T) ds; the balance of every step closes, stored heat
    included (the bodies' matrices hold the coefficient: they are factorised again)."""
    import ufl

    scene = two_plates_scene(4, 2, comm=comm)
    uncovered = (
        sc.Schedule((0.0, 4e5, 4e5), (0.0, 0.0, 50.0))
        if given == "schedule"
        else lambda x, t: 50.0 * ufl.conditional(ufl.gt(t, 4e5), 1.0, 0.0)
    )
    problem = sc.Problem(
        scene,
        {n: sc.Material(conductivity=1.0, density=1e3, heat_capacity=1e3) for n in scene.bodies},
        {"contact": sc.Contact(conductance=10.0)},
        [sc.Temperature("left", 1.0), sc.Convection("top", uncovered, 0.0)],
    )
    system = make_system(problem)
    system.reset()
    stepper = sc.Stepper(system, "backward_euler")
    top = {}

    def record(s, result):
        top[s.time] = sc.heat(system, "top")
        assert sc.balance(system)["heat"]["relative"] < 1e-10  # as in the first test

    stepper.march(8e5, 2e5, after_step=record, rtol=1e-12)
    assert sorted(top) == [2e5, 4e5, 6e5, 8e5]
    assert top[2e5] == 0.0 and top[4e5] == 0.0
    # after: heat leaves through the top, 50 W/(m² K) × ∫ (0 − T) ds < 0, a few W
    expected = -50.0 * sc.average(system, "top", "temperature") * 2.0  # the top is 2 m long
    assert top[8e5] == pytest.approx(expected, rel=1e-12)
    assert top[6e5] < -1e-3
    with pytest.raises(ValueError, match="coefficient must be >= 0"):
        sc.Problem(
            scene,
            problem.materials,
            problem.contacts,
            [sc.Temperature("left", 1.0), sc.Convection("top", sc.Schedule((0, 1), (1, -1)), 0)],
        )


@pytest.mark.parametrize(("scheme", "order"), [("backward_euler", 1), ("bdf2", 2)])
def test_a_manufactured_solution_in_time_with_a_contact(comm, scheme, order):
    """Data that vary in space and time (sc.Temperature, sc.HeatFlux and the heat source as
    functions (x, t)), through a contact: T linear in x and y in each slab, its coefficients
    sines of t, the contact's jump and flux continuity exact:

        T_A = p + q x + r y,  T_B = p_B + q_B x + r y,  k_A q = k_B q_B,
        −k_A q = h (T_A − T_B) at x = 1  ⇒  p_B = p + q − q_B + k_A q / h,

    with the source ρc ∂T/∂t, the temperature held at both ends and the flux ±k r through
    the top and bottom. P1 holds T exactly in space, so the error at t = 2e5 s is the time
    scheme's alone; measured with 32, 64, 128 steps: backward Euler 7.7e-2, 3.9e-2, 1.9e-2
    (rates 0.995, 0.997), BDF2 1.8e-3, 4.2e-4, 1.0e-4 (2.08, 2.04: the excess over 2, from
    the next term of the expansion and the backward Euler first step, halves with each
    step; 2.22 and 2.14 on the coarser pairs). ±0.1 on the finer pair's rate leaves more
    than twice the excess left.
    """
    import ufl

    tau, h, k_a, k_b, rc_a, rc_b = 1e5, 10.0, 2.0, 1.0, 4e6, 1e6
    ratio = k_a / k_b

    def coefficients(t, sin, cos):
        p, q, r = sin(t / tau), 0.5 * cos(t / tau), 0.3 * sin(2 * t / tau)
        dp, dq, dr = cos(t / tau) / tau, -0.5 * sin(t / tau) / tau, 0.6 * cos(2 * t / tau) / tau
        pb = p + q - ratio * q + k_a * q / h
        dpb = dp + dq - ratio * dq + k_a * dq / h
        return (p, q, r, dp, dq, dr, pb, dpb)

    def exact(x, t, sin, cos, side):
        p, q, r, *_, pb, _ = coefficients(t, sin, cos)
        return (p + q * x[0] if side == "a" else pb + ratio * q * x[0]) + r * x[1]

    def both(x, t, value_a, value_b):  # plate A is x < 1 (the contact's point has no measure)
        return ufl.conditional(ufl.lt(x[0], 1.0), value_a, value_b)

    def source(rc, side):
        def f(x, t):
            _, _, _, dp, dq, dr, _, dpb = coefficients(t, ufl.sin, ufl.cos)
            rate = dp + dq * x[0] if side == "a" else dpb + ratio * dq * x[0]
            return rc * (rate + dr * x[1])

        return f

    def flux(sign):
        def g(x, t):
            r = coefficients(t, ufl.sin, ufl.cos)[2]
            return sign * both(x, t, k_a * r, k_b * r)

        return g

    scene = two_plates_scene(4, 3, comm=comm)
    problem = sc.Problem(
        scene,
        {
            "plate_A": sc.Material(
                conductivity=k_a, density=rc_a, heat_capacity=1.0, heat_source=source(rc_a, "a")
            ),
            "plate_B": sc.Material(
                conductivity=k_b, density=rc_b, heat_capacity=1.0, heat_source=source(rc_b, "b")
            ),
        },
        {"contact": sc.Contact(conductance=h)},
        [
            sc.Temperature("left", lambda x, t: exact(x, t, ufl.sin, ufl.cos, "a")),
            sc.Temperature("right", lambda x, t: exact(x, t, ufl.sin, ufl.cos, "b")),
            sc.HeatFlux("top", flux(1.0)),
            sc.HeatFlux("bottom", flux(-1.0)),
        ],
    )
    end, errors = 2e5, []
    for steps in (32, 64, 128):
        system = make_system(problem)
        system.reset()
        for name, body in system.bodies.items():  # the exact state at t = 0
            V, parent_of = body.forms.collapsed("temperature")
            side = "a" if name == "plate_A" else "b"
            points = V.tabulate_dof_coordinates().T
            body.U.x.array[parent_of] = exact(points, 0.0, np.sin, np.cos, side)
        stepper = sc.Stepper(system, scheme)
        for _ in range(steps):
            stepper.advance(end / steps, rtol=1e-12)
        worst = 0.0
        for name, body in system.bodies.items():
            points, values = body.nodal("temperature")
            side = "a" if name == "plate_A" else "b"
            reference = exact(points.T, end, np.sin, np.cos, side)
            worst = max(worst, float(np.abs(values - reference).max(initial=0.0)))
        errors.append(comm.allreduce(worst, op=MPI.MAX))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert abs(rates[-1] - order) <= 0.1, (errors, rates)


def test_a_checkpoint_moves_between_placements(comm, shared_tmp):
    """A checkpoint keys each body's values by the mesh file's node numbers and the master
    values by their coordinates (the past ones of the predictor too): written by bodies
    spread over every rank, it loads into bodies on rank groups, and back, to the same value
    at every node (exactly)."""
    from subdomain_contact import checkpoint
    from subdomain_contact.scene import match_points
    from verification.nodal import NodalReference, error_against, field_values

    def stepped(placement):
        scene = two_plates_scene(6, 6, comm=comm, placement=placement)
        system = make_system(heated_plates(scene))
        system.reset()
        return system

    spread = stepped("shared")
    stepper = sc.Stepper(spread, "bdf2")
    for _ in range(2):
        stepper.advance(2e5, rtol=1e-12)
    clock = {"steps": 2, "time": stepper.time}
    past = {"past": stepper.past_masters}
    assert len(stepper.past_masters) == 2  # the masters of t = 0 and of the first step
    first = checkpoint.save(shared_tmp / "a", spread, clock, {}, past)
    reference = NodalReference(*field_values(spread))
    grouped = stepped("groups")
    loaded, _, grouped_past = checkpoint.load(first, grouped)
    assert loaded == clock
    assert error_against(grouped, reference.at(field_values(grouped)[0])) == 0.0
    again = stepped("shared")
    _, _, again_past = checkpoint.load(
        checkpoint.save(shared_tmp / "b", grouped, clock, {}, grouped_past), again
    )
    assert error_against(again, reference.at(field_values(again)[0])) == 0.0
    for k, layer in spread.layers.items():
        index = match_points(layer.coordinates, again.layers[k].coordinates, what=k)
        assert np.array_equal(again.masters[k], spread.masters[k][index])
        for i, masters in enumerate(stepper.past_masters):
            assert np.array_equal(again_past["past"][i][k], masters[k][index])
    for name, body in again.bodies.items():  # the previous times too
        assert np.array_equal(
            body.forms.history[0].x.array, spread.bodies[name].forms.history[0].x.array
        )
    assert checkpoint.latest(shared_tmp / "b", comm).name == "step_000002"


def test_a_run_resumes_from_any_step(comm, shared_tmp):
    """A run stopped after its first step (one past state of the three BDF2's estimate
    uses) or its third, then resumed to the end from its final checkpoint, ends where an
    uninterrupted run ends, row for row. To round-off: the stopped run lands its last step
    on the uninterrupted run's time, t₂ + (t₃ − t₂), which may differ from t₃ by one ulp
    (measured: identical from step 1, 2e-14 relative from step 3)."""
    scene = two_plates_scene(4, 2, comm=comm)

    def run(directory, until, restart):
        system = make_system(heated_plates(scene))
        system.reset()
        stepper = sc.Stepper(system, "bdf2")
        history = sc.History(
            directory,
            stepper,
            lambda s: {"T [K]": sc.value_at(s, "plate_A", "temperature", (0.5, 0.5))},
            until=until,
            quiet=True,
        )
        history.start(restart=restart)
        stepper.march(until, 1e5, tolerance=1e-3, after_step=history.after_step, rtol=1e-12)
        history.finish()  # saves a checkpoint at the end
        return system, history.rows

    whole, rows = run(shared_tmp / "whole", 1e6, False)
    for first in (1, 3):
        cut = shared_tmp / f"cut{first}"
        run(cut, rows[first - 1]["time [s]"], False)
        resumed, again = run(cut, 1e6, True)
        assert [r["step"] for r in again] == [r["step"] for r in rows]
        assert [r["T [K]"] for r in again] == pytest.approx([r["T [K]"] for r in rows], rel=1e-12)
        assert max(whole.difference(resumed.state(), whole.state()).values()) <= 1e-12


def test_the_predictor_starts_newton_nearer_and_ends_where_newton_ends(comm):
    """The warming Joule bars (laws of T and p, the contact closing at the seventh step),
    twelve BDF2 steps of 900 s from 300 K, with and without the predictor: the same states to
    Newton's tolerance, in fewer Newton steps."""
    scene = bars_scene(6, 2, comm=comm)
    ramp = sc.Schedule((0.0, 7200.0), (0.0, 1.0))
    runs = {}
    for predictor in (False, True):
        system = make_system(warming_joule_bars(scene, ramp))
        system.reset({"temperature": 300.0})
        stepper = sc.Stepper(system, "bdf2", predictor=predictor)
        results, states = [], []
        for _ in range(12):
            results.append(stepper.advance(900.0, rtol=1e-12))
            states.append(system.state())
        runs[predictor] = results, states
    (plain, plain_states), (predicted, predicted_states) = runs[False], runs[True]
    # both to rtol 1e-12 of each field's scale: measured ≤ 2.6e-13 apart
    for a, b in zip(plain_states, predicted_states, strict=True):
        assert max(system.difference(a, b).values()) < 1e-8
    # the first step has no past: the same start
    assert predicted[0].relative_residuals()[0] == plain[0].relative_residuals()[0]
    # while the contact is open (steps 2 to 6) the latest state is off by the step's change,
    # of order Δt, the predicted one by its second difference, Δt / τ times less with τ the
    # bars' heating time (hours): initial residuals measured 1.7e-4 to 4.9e-4 of their scale
    # against 0.17 to 0.5, i.e. 3e-4 to 3e-3 as large; 0.1 leaves a margin of 30
    for a, b in zip(plain[1:6], predicted[1:6], strict=True):
        assert b.relative_residuals()[0] < 0.1 * a.relative_residuals()[0]
    # Newton's steps: measured 43 against 81 (the closing step 11 against 34)
    assert sum(r.iterations for r in predicted) < sum(r.iterations for r in plain)


def test_the_enthalpy_is_the_heat_the_steps_stored(comm):
    """sc.enthalpy against closed forms, and against the heat that backward Euler stored.

    A uniform state: ρ V ∫ c_p dT in closed form (the table's integral is piecewise
    quadratic). Constant c_p: backward Euler's stored heat ρ c_p (Tⁿ − Tⁿ⁻¹) telescopes, so
    its sum over the steps is the enthalpy change to round-off. c_p(T) a table: the scheme
    takes c_p at the step's end, off from ∫ c_p dT by at most ½ max|c_p'| (ΔTⁿ)² per node
    and step: the bound, with the largest nodal ΔT of each step (≤ 1 K here)."""
    scene = two_plates_scene(6, 6, comm=comm)  # two 1 m × 1 m plates
    table = sc.Table((0.0,), (0.0, 0.5, 1.0), [[800.0, 1200.0, 1300.0]])  # J/(kg K)
    slope = 800.0  # max |c_p'| [J/(kg K²)], on the first segment
    for capacity, exact in ((1000.0, True), (table, False)):
        problem = dataclasses.replace(
            heated_plates(scene),
            materials={
                name: dataclasses.replace(m, heat_capacity=capacity)
                for name, m in heated_plates(scene).materials.items()
            },
        )
        system = make_system(problem)
        # a uniform state, T = 0.8 K: ρ V ∫₀^0.8 c_p over both plates (ρ = 4000, V = 1)
        system.reset({"temperature": 0.8})
        if exact:
            closed = 2 * 4000.0 * 1000.0 * 0.8
        else:  # the trapezoids of the piecewise-linear c_p to 0.5 K, then to 0.8 K
            closed = 2 * 4000.0 * ((800 + 1200) / 2 * 0.5 + (1200 + 1260) / 2 * 0.3)
        assert sc.enthalpy(system) == pytest.approx(closed, rel=1e-12)
        system.reset()
        before = sc.enthalpy(system)
        stepper = sc.Stepper(system, "backward_euler")
        stored, bound = 0.0, 0.0
        for _ in range(5):
            previous = {n: b.nodal("temperature")[1] for n, b in system.bodies.items()}
            stepper.advance(4e4, rtol=1e-12)
            stored += 4e4 * sc.balance(system)["heat"]["stored"]
            change = max(
                np.abs(b.nodal("temperature")[1] - previous[n]).max(initial=0.0)
                for n, b in system.bodies.items()
            )
            change = comm.allreduce(change, op=MPI.MAX)
            bound += 0.5 * slope * change**2 * 2 * 4000.0  # ρ V over both plates
        error = abs(stored - (sc.enthalpy(system) - before))
        if exact:  # telescoping: round-off of 5 sums of ~1e5 J
            assert error < 1e-9 * abs(stored)
        else:
            assert 0 < error <= bound
