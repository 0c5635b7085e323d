"""Thermo-electro-mechanical contact: closed forms, the monolithic Newton, laws and errors."""

import dataclasses
import itertools

import dolfinx
import numpy as np
import pytest
import ufl
from helpers import make_system
from mpi4py import MPI
from petsc4py import PETSc

import subdomain_contact as sc
from subdomain_contact import laws, monolithic
from subdomain_contact.physics import (
    Contact,
    Displacement,
    Material,
    Penalty,
    Potential,
    Problem,
    Temperature,
)
from verification.analytic import BlocksBetweenWalls, JouleBars, TwoPlates
from verification.cases import (
    GEO,
    bars_scene,
    joule_bars,
    squeezed_joule_bars,
    steel_blocks_between_walls,
)
from verification.taylor import jacobian_orders_toward


@pytest.fixture(scope="module")
def bars(comm):
    """Two bars of 0.5 m × 0.1 m, 4 × 2 quadrilaterals each."""
    return bars_scene(4, 2, comm=comm)


def max_nodal_error(system, truth, field, comm):
    """max |U − exact| / max |exact| over every body's owned nodes (global)."""
    worst, scale = 0.0, 0.0
    for name, body in system.bodies.items():
        points, values = body.nodal(field)
        exact = truth[name](points[:, 0])
        worst = max(worst, np.max(np.abs(values - exact), initial=0.0))
        scale = max(scale, np.max(np.abs(exact), initial=0.0))
    return comm.allreduce(worst, op=MPI.MAX) / comm.allreduce(scale, op=MPI.MAX)


LINEAR = {"subdomain": sc.Subdomains, "monolithic": sc.Monolithic}


def contact_displacements(system, comm):
    """Body name -> mean u_x [m] of its nodes on the contact plane x = 0.5 (global).

    Each body from the ranks that hold it (every rank, or its rank group).
    """
    ux = {}
    for name in system.problem.scene.bodies:
        local = np.zeros(2)
        if name in system.bodies:
            points, values = system.bodies[name].nodal("displacement", 0)
            on = np.isclose(points[:, 0], 0.5)
            local = np.array([values[on].sum(), on.sum()])
        total = comm.allreduce(local, op=MPI.SUM)
        ux[name] = total[0] / total[1]
    return ux


def test_thermal_only_scene_builds_no_potential_or_displacement(bars, comm):
    problem = Problem(
        bars,
        {
            "plate_A": Material(conductivity=2.0, heat_source=50.0),
            "plate_B": Material(conductivity=5.0),
        },
        {"contact": Contact(conductance=3.0)},
        [Temperature("left", 1.0), Temperature("right", 0.0)],
    )
    assert problem.fields == ("temperature",)
    system = make_system(problem)
    for body in system.bodies.values():
        W = body.forms.W
        assert W.num_sub_spaces == 0 and W.dofmap.index_map_bs == 1
        assert W.element.basix_element.value_size == 1
    assert system.layers["contact"].channels == (("temperature", None),)
    assert system.num_dofs()["masters"] == 3
    sc.solve(system)
    exact = TwoPlates(0.5, 0.5, 2.0, 5.0, 3.0, 1.0, 0.0, 50.0, 0.0)
    truth = {"plate_A": exact.temperature_a, "plate_B": exact.temperature_b}
    # linear: one Newton step, whose inner solve is exact (the exact corrector), so round-off
    # only: measured 1.05e-13, 1e-12 leaves 10 times that
    assert max_nodal_error(system, truth, "temperature", comm) < 1e-12


def joule_problem(scene, *, voltage=0.5, h=2e3, g=5e4):
    return joule_bars(scene, voltage=voltage, h=h, g=g)[0]


def test_joule_bars_match_the_closed_form(bars, comm):
    system = make_system(joule_problem(bars))
    system.reset({"temperature": 300.0})
    result = sc.solve(system, rtol=1e-12)
    exact = JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, 2e3, 5e4, 0.5, 300.0, 320.0)
    temperature = {"plate_A": exact.thermal.temperature_a, "plate_B": exact.thermal.temperature_b}
    potential = {"plate_A": exact.potential_a, "plate_B": exact.potential_b}
    # nodally exact (φ linear, T quadratic with P1 in 1D) and converged to rtol 1e-12:
    # measured 1.2e-14 and 1.1e-16, 1e-10 leaves 8000 times the worst
    assert max_nodal_error(system, temperature, "temperature", comm) < 1e-10
    assert max_nodal_error(system, potential, "potential", comm) < 1e-10
    # the discrete reactions: through the held ends and across the contact, in +x (measured
    # ≤ 2e-15 relative)
    for group, sign in [("left", 1.0), ("contact", 1.0), ("right", -1.0)]:
        current = sc.current(system, group)
        assert current == pytest.approx(sign * exact.current_density * 0.1, rel=1e-10)
    # the contact heat: Joule heat g Δφ² is in the closed form only if deposited half per side
    assert exact.thermal.contact_heat > 0
    # Constant laws: φ is linear and T sees it only through quadratic sources, so Newton
    # solves φ in its first step and T in its second (2 iterations, measured); a third may
    # follow where round-off leaves the second above rtol·scale.
    assert result.iterations <= 3
    # the exact corrector solves each linear system in one correction, then checks it
    assert all(step.inner_rounds == 2 for step in result.history[1:])


@pytest.mark.parametrize("linear", sorted(LINEAR))
def test_newton_steps_are_limited_in_temperature(bars, comm, linear):
    # 3 V across the bars: Joule heat lifts them to 1002 K; the full Newton takes 3 steps
    system = make_system(joule_problem(bars, voltage=3.0))
    system.reset({"temperature": 300.0})
    iterates = []

    def keep(iteration):
        local = [system.bodies[n].nodal("temperature")[1].copy() for n in sorted(system.bodies)]
        iterates.append(local)

    result = sc.solve(system, LINEAR[linear](), rtol=1e-12, line_search="limited", monitor=keep)
    moves = [
        comm.allreduce(
            max(np.max(np.abs(b - a), initial=0.0) for a, b in zip(*pair, strict=True)), MPI.MAX
        )
        for pair in itertools.pairwise(iterates)
    ]
    # no node moves more than the limit in one step (round-off of the scaled step: 1e-9 K)
    assert max(moves) <= sc.MAX_TEMPERATURE_STEP + 1e-9
    exact = JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, 2e3, 5e4, 3.0, 300.0, 320.0)
    nodes = np.linspace(0.0, 0.5, 5)  # the bars' nodes along x (4 elements each)
    hottest = max(
        exact.thermal.temperature_a(nodes).max(), exact.thermal.temperature_b(0.5 + nodes).max()
    )
    rise = hottest - 300.0
    # so climbing 702 K from the uniform 300 K takes at least ceil(rise / 100) = 8 steps, all
    # but the last shortened (the unlimited Newton: 3 steps)
    climb = int(np.ceil(rise / sc.MAX_TEMPERATURE_STEP))
    assert result.iterations >= climb == 8
    assert result.shortened >= climb - 1
    assert moves[-1] < sc.MAX_TEMPERATURE_STEP  # the last steps are Newton's own, unshortened
    temperature = {"plate_A": exact.thermal.temperature_a, "plate_B": exact.thermal.temperature_b}
    # the same root as the full Newton: nodally exact, 1e-10 as in the test above
    assert max_nodal_error(system, temperature, "temperature", comm) < 1e-10


def expansion_problem(scene, temperature, *, gap=1e-4):
    return steel_blocks_between_walls(scene, temperature, gap=gap)[0]


@pytest.mark.parametrize("temperature", [350.0, 250.0])
def test_thermal_expansion_pressure_and_gap(bars, comm, temperature):
    system = make_system(expansion_problem(bars, temperature))
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    exact = BlocksBetweenWalls((0.5, 0.5), (200e9,) * 2, (0.3,) * 2, (1.2e-5,) * 2, 1e-4, 1e13)
    heating = temperature - 300.0
    force = sc.force(system, "contact")
    ux = contact_displacements(system, comm)
    gap = 1e-4 - (ux["plate_A"] - ux["plate_B"])
    # P1 represents the uniform strain exactly: round-off only (measured 3e-15 relative)
    if heating > 0:
        assert exact.pressure(heating) > 1e8
        assert force[0] / 0.1 == pytest.approx(exact.pressure(heating), rel=1e-9)
        assert sc.summary(system)["contacts"]["contact"]["open share"] == 0.0
    else:
        # open: no force at all, to the solver's tolerance relative to the force the walls
        # would need to hold the blocks' whole contraction, E α |ΔT| / (1 − ν) × 0.1 m
        # (measured 0 across the contact, 2.1e-15 at the wall: the round-off of a reaction)
        held = 200e9 * 1.2e-5 * 50.0 / 0.7 * 0.1
        assert np.abs(force).max() <= 1e-12 * held
        assert np.abs(sc.force(system, "left")).max() <= 1e-12 * held
        # the free contraction (1 + ν) α ΔT L per block, exactly
        assert gap == pytest.approx(1e-4 + 1.3 * 1.2e-5 * 50.0, rel=1e-12)
        assert sc.summary(system)["contacts"]["contact"]["open share"] == 1.0
    assert gap == pytest.approx(exact.gap_width(heating), rel=1e-9)


def test_coupled_newton_equals_monolithic_and_its_jacobian_is_exact(bars):
    system = make_system(squeezed_joule_bars(bars))
    states, results = {}, {}
    for linear in ("subdomain", "monolithic"):
        system.reset({"temperature": 300.0})
        results[linear] = sc.solve(system, LINEAR[linear](), rtol=1e-12)
        states[linear] = system.state()
    # both stop at rtol 1e-12 per field: measured 3e-16 to 5e-16 apart
    difference = system.difference(states["subdomain"], states["monolithic"])
    assert max(difference.values()) < 1e-8
    history = results["subdomain"].history
    assert [s.inner_rounds for s in history[1:]] == [2] * (len(history) - 1)
    pressure = sc.force(system, "contact")[0] / 0.1
    assert 1e5 < pressure < 1e8  # the contact is closed and its laws see a pressure
    # The same Newton, step by step: each inner solve leaves a relative residual of at most
    # η ≤ 1e-8 of the step's (sc.newton.FORCING), so Newton's measure ρ agrees at every
    # iterate above 1e-10 (below, the two routes' round-off differs in the third digit):
    # measured 2.2e-9 of ρ at 4 × 2 cells, 3.8e-12 at 8 × 2; 1e-6 leaves 450 times that for
    # the steps' contraction (ρ falls tenfold and more a step) and another machine's round-off.
    sub = results["subdomain"].relative_residuals()
    mono = results["monolithic"].relative_residuals()
    assert len(sub) == len(mono)
    above = mono > 1e-10
    assert np.all(np.abs(sub - mono)[above] <= 1e-6 * mono[above])
    # Quadratic convergence rests on an exact Jacobian: the Taylor remainder at the solution,
    # along the way back to the 300 K start, falls 4 times per halving of ε (order 2 in every
    # field: measured 2.000 from ε = 1e-2 to 6e-4; the O(ε³) part costs ≈ cε/(2 ln 2), so 1.9
    # leaves a 14-fold margin on c·ε), and any missing or mis-scaled term makes it 1. The
    # order fitted to the Newton history itself is not asserted: from 300 K the full steps
    # wander through the kinks of the tabulated g(p, T) and land where round-off sends them
    # (measured p = 1.95 on one machine, 1.55 on another, identical on both routes).
    orders = jacobian_orders_toward(system, states["monolithic"], {"temperature": 300.0})
    assert min(min(o.values()) for o in orders) > 1.9, orders


def coupling_rows(linear):
    """Rows of T and φ where the merged matrix has a nonzero in a column of u (global count)."""
    (_, te), (_, u) = linear.splits
    block = linear.K.createSubMatrix(te, u)
    indptr, _, values = block.getValuesCSR()
    block.destroy()
    row_of = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    local = np.unique(row_of[np.abs(values) > 0]).size
    return linear.K.getComm().tompi4py().allreduce(local)


@pytest.mark.parametrize("laws_of_pressure", [True, False])
def test_the_split_monolithic_solve_is_the_direct_one(bars, laws_of_pressure):
    """``FIELDSPLIT_DIRECT``: GMRES on one sweep over (T, φ), then u, each block factorised.

    T and φ see u only through the contact's laws of the pressure, u sees T everywhere
    (expansion): the Jacobian is block lower triangular in that order but for the rows of T
    and φ on the contacts. With constant conductances it is triangular, the sweep is its
    inverse and GMRES (right-preconditioned) needs one iteration. With laws of p the
    sweep is the identity but for a block of rank at most the count of those rows, so GMRES
    ends within that count + 1 iterations (exact arithmetic). Newton then follows the direct
    solve's path to the same solution.
    """
    problem = squeezed_joule_bars(bars)
    if not laws_of_pressure:
        constant = dataclasses.replace(
            problem.contacts["contact"], conductance=5e3, electrical_conductance=1e4
        )
        problem = dataclasses.replace(problem, contacts={"contact": constant})
    system = make_system(problem)
    states, results = {}, {}
    for name, linear in (
        ("direct", sc.Monolithic()),
        ("split", sc.Monolithic(sc.FIELDSPLIT_DIRECT, splits=sc.THERMOELECTRIC_MECHANICAL)),
    ):
        system.reset({"temperature": 300.0})
        results[name] = sc.solve(system, linear, rtol=1e-12)
        states[name] = system.state()
        rows = coupling_rows(linear) if name == "split" else None
        linear.destroy()
    # both stop at rtol 1e-12 per field (as the subdomain and monolithic Newtons above)
    assert max(system.difference(states["split"], states["direct"]).values()) < 1e-8
    # GMRES's relative residual 1e-12 is below the forcing η ≤ 1e-8 of the subdomain route,
    # whose Newton measure agrees with the direct one's to 1e-6 above 1e-10 (above)
    split = results["split"].relative_residuals()
    direct = results["direct"].relative_residuals()
    assert len(split) == len(direct)
    above = direct > 1e-10
    assert np.all(np.abs(split - direct)[above] <= 1e-6 * direct[above])
    iterations = [s.inner_rounds for s in results["split"].history[1:]]
    # One iteration in exact arithmetic where the sweep is exact; a second where the step's
    # right-hand side is small against the factorisations' round-off (measured: step 2, its
    # right-hand side 5e2 against 2e6 to 2e8 at the others, 1.1e-11 of it left after the
    # first, above GMRES's 1e-12). With laws of p: 1, 2, 3, 3, 3, 4, 4, 4, 4.
    if laws_of_pressure:
        assert rows > 0 and max(iterations) > 2, iterations  # the contact's rows do couple
        assert max(iterations) <= rows + 1, (iterations, rows)
    else:
        assert rows == 0 and max(iterations) <= 2, iterations


def test_the_split_solve_in_single_precision_is_the_direct_one(bars):
    """``FIELDSPLIT_SINGLE``: the split's blocks factorised in single precision, GMRES on the
    true residual to 1e-12. The factorisations' error ``E`` (about ε_single times the
    blocks' scaled condition) makes the sweep ``I + E`` times the double one, and GMRES
    contracts that by about ‖E‖ an iteration beyond the contact rows' rank bound: Newton
    follows the direct path to the same solution, with a few more iterations a step.
    """
    system = make_system(squeezed_joule_bars(bars))
    states, results = {}, {}
    for name, options in (("double", sc.FIELDSPLIT_DIRECT), ("single", sc.FIELDSPLIT_SINGLE)):
        linear = sc.Monolithic(options, splits=sc.THERMOELECTRIC_MECHANICAL)
        system.reset({"temperature": 300.0})
        results[name] = sc.solve(system, linear, rtol=1e-12)
        states[name] = system.state()
        rows = coupling_rows(linear)
        linear.destroy()
    # both stop at rtol 1e-12 per field (as the double split against MUMPS, above)
    assert max(system.difference(states["single"], states["double"]).values()) < 1e-8
    double, single = ([s.inner_rounds for s in results[k].history[1:]] for k in results)
    # the precision is applied (MUMPS reads it when it factorises: until 2026-12-02 it was
    # dropped before then, and the counts were the double ones): measured 1, 2, 3, 3, 3, 4,
    # 4, 4, 4 in double, 3, 3, 4, 4, 4, 4, 5, 6, 5, 5 in single
    assert sum(single) > sum(double), (single, double)
    # ‖E‖ ≤ 1e-3 (ε_single 6e-8 times a scaled condition of at most 1e4; with constant
    # conductances one iteration becomes 2–4, a contraction of 1e-4 to 1e-6 each): 1e-12 is
    # reached within 4 iterations beyond the rank bound
    assert max(single) <= rows + 1 + 4, (single, rows)


def test_a_krylov_solve_stopped_short_of_its_true_residual_goes_on_from_its_iterate(
    bars, monkeypatch
):
    """A Krylov solve whose test declares it converged while its true residual ``b − J x``
    is above its tolerance (GMRES's recurrence residual, drifted) is solved on from its
    iterate (``Monolithic.restarts``), so Newton takes the exact linear steps. Here the
    test stops every solve after 2 GMRES iterations, fewer than the sweep needs with laws of
    the pressure (1–4 measured, above): the restarts make up for it, and Newton reaches the
    direct solve's solution.
    """
    system = make_system(squeezed_joule_bars(bars))
    original = monolithic.make_ksp
    reasons = PETSc.KSP.ConvergedReason

    def short(*args, **kwargs):
        ksp = original(*args, **kwargs)
        ksp.setConvergenceTest(
            lambda ksp, it, norm: reasons.CONVERGED_ITS if it >= 2 else reasons.ITERATING
        )
        return ksp

    states = {}
    for name in ("direct", "short"):
        if name == "short":
            monkeypatch.setattr(monolithic, "make_ksp", short)
            linear = sc.Monolithic(sc.FIELDSPLIT_DIRECT, splits=sc.THERMOELECTRIC_MECHANICAL)
        else:
            linear = sc.Monolithic()
        system.reset({"temperature": 300.0})
        result = sc.solve(system, linear, rtol=1e-12)
        states[name] = system.state()
        linear.destroy()
    assert linear.restarts > 0
    # each restart adds its 2 iterations to the step's count
    rounds = [s.inner_rounds for s in result.history[1:]]
    assert sum(rounds) == 2 * (len(rounds) + linear.restarts), (rounds, linear.restarts)
    # both stop at rtol 1e-12 per field (as the split against MUMPS, above)
    assert max(system.difference(states["short"], states["direct"]).values()) < 1e-8


def test_a_merge_that_would_not_fit_beside_the_factors_frees_them_first(bars, monkeypatch):
    """Where the next matrix's values would not fit beside the kept one and its factors
    (``merge_shortfall``: the plan's ``values_bytes`` against the memory left), the monolithic
    solve frees them before it writes the values, and factorises the new matrix anew (a new
    analysis): the same Newton path and solution, each step's factors made from nothing.
    """
    system = make_system(squeezed_joule_bars(bars))
    states, results, made, ksps = {}, {}, {}, []
    original = monolithic.make_ksp

    def counted(*args, **kwargs):
        ksps.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(monolithic, "make_ksp", counted)
    for name in ("kept", "freed"):
        if name == "freed":  # as if every refactorisation fell short of memory
            monkeypatch.setattr(monolithic, "merge_shortfall", lambda plan, comm: "x")
        linear = sc.Monolithic(sc.FIELDSPLIT_DIRECT, splits=sc.THERMOELECTRIC_MECHANICAL)
        before = len(ksps)
        system.reset({"temperature": 300.0})
        results[name] = sc.solve(system, linear, rtol=1e-12)
        states[name] = system.state()
        made[name] = (len(ksps) - before, linear.factorisations)
        linear.destroy()
    assert made["kept"][0] == 1 < made["kept"][1]  # one KSP, factorised again each step
    assert made["freed"][0] == made["freed"][1] == made["kept"][1]  # a KSP made each step
    assert results["freed"].iterations == results["kept"].iterations
    # the same matrices, factorised with another analysis: the same solution to Newton's stop
    assert max(system.difference(states["freed"], states["kept"]).values()) < 1e-8


def _costed(monkeypatch, factorisation: float) -> list[tuple[bool, int, int]]:
    """Replace the monolithic solve's clock by a cost model, recording each solve.

    A factorisation costs ``factorisation``, a solve its GMRES iterations (the units of
    both alike): the rule of ``keep`` then depends on the iterations alone, not on the
    machine's timing. Returns the record: per solve (on a kept factorisation, its
    iterations, its iteration limit, whether it converged).
    """
    record = []

    def clock(self, work):
        stale, limit = self._stale, self.ksp.getTolerances()[3] if self.ksp else 0
        work()
        if work.__name__ in ("make", "factorise"):
            return factorisation
        converged = self.ksp.getConvergedReason() > 0
        record.append((stale, self.ksp.getIterationNumber(), limit, converged))
        return float(self.ksp.getIterationNumber())

    monkeypatch.setattr(monolithic.Monolithic, "_clock", clock)
    return record


@pytest.mark.parametrize("factorisation", [0.0, 8.0, np.inf])
def test_a_kept_factorisation_is_replaced_once_its_extra_iterations_cost_one(
    bars, monkeypatch, factorisation
):
    """``Monolithic(keep=1)``: the split's factorisation serves later Newton steps as
    GMRES's preconditioner (the Jacobian applied by the assembled blocks) until the solves
    on it have taken, beyond its first solve's iterations each, as many iterations as a
    factorisation costs (a cost model here: a factorisation as ``factorisation``
    iterations). Each step is still solved to GMRES's
    1e-12, so Newton reaches the solution of the split factorised at every step, with fewer
    factorisations; a solve on a kept factorisation that would cost more than the rest of
    the budget is stopped and solved again on a new one.
    """
    system = make_system(squeezed_joule_bars(bars))
    states, results, linear, merges = {}, {}, {}, []
    record = _costed(monkeypatch, factorisation)
    values = monolithic.MergePlan.values
    monkeypatch.setattr(
        monolithic.MergePlan, "values", lambda plan, s: merges.append(1) or values(plan, s)
    )
    for name, keep in (("every step", None), ("kept", 1.0)):
        linear[name] = sc.Monolithic(
            sc.FIELDSPLIT_DIRECT, splits=sc.THERMOELECTRIC_MECHANICAL, keep=keep
        )
        system.reset({"temperature": 300.0})
        record.clear()
        merges.clear()
        results[name] = sc.solve(system, linear[name], rtol=1e-12)
        states[name] = system.state()
        linear[name].destroy()
    # both stop at rtol 1e-12 per field on the same system (as the split against MUMPS)
    assert max(system.difference(states["kept"], states["every step"]).values()) < 1e-8
    steps = results["kept"].iterations
    made, reused = linear["kept"].factorisations, linear["kept"].reuses
    # Replay the rule on the recorded solves. Each solve on a new factorisation (the first,
    # one made at a new Jacobian, or one made again after a failed solve) restarts the excess
    # at 0; a kept one comes only while the excess is below the budget, may take at most
    # n₀ + 1 + (budget left) iterations, and adds max(0, n − n₀) where it converged (where
    # it did not, the repeat on a new factorisation comes next).
    factorised = first = excess = 0
    for stale, iterations, limit, converged in record:
        if not stale:
            factorised, first, excess = factorised + 1, iterations, 0.0
            continue
        assert excess < factorisation, "a kept factorisation was used beyond its budget"
        assert limit <= first + 1 + (factorisation - excess), (limit, first, excess)
        if converged:
            excess += max(0, iterations - first)
    assert made == factorised, (made, factorised)  # each failure factorised again
    # one converged solve a Newton step, on a kept factorisation or a new one
    assert made + reused == steps, (made, reused, steps)
    # a kept step applies J by the blocks: a matrix is merged only to be factorised
    assert len(merges) == made, (len(merges), made)
    if factorisation == 0.0:  # nothing pays for a kept factorisation: every step its own
        assert reused == 0, reused
    else:  # measured: 9 steps; 4 on a kept factorisation (8 iterations' worth), 7 (free)
        assert 0 < reused and made < steps, (made, reused, steps)


def test_a_kept_factorisation_on_which_gmres_fails_is_made_again(bars, monkeypatch):
    """A solve on a kept factorisation that does not converge within GMRES's limit is
    solved again on the matrix factorised anew, and Newton goes on (the limit: 10
    iterations, above the 1–4 of a fresh factorisation, below the 31–412 the steps took
    on the first kept one, measured)."""
    system = make_system(squeezed_joule_bars(bars))
    record = _costed(monkeypatch, np.inf)
    options = sc.FIELDSPLIT_DIRECT | {"ksp_max_it": "10"}
    linear = sc.Monolithic(options, splits=sc.THERMOELECTRIC_MECHANICAL, keep=1.0)
    system.reset({"temperature": 300.0})
    result = sc.solve(system, linear, rtol=1e-12)
    linear.destroy()
    failed = [n for stale, n, limit, converged in record if stale and not converged]
    assert failed, record  # a kept factorisation did fail ...
    assert linear.factorisations == 1 + len(failed)  # ... and each failure factorised again
    assert result.relative_residuals()[-1] <= 1e-12


def test_a_kept_factorisation_needs_a_krylov_solve():
    with pytest.raises(ValueError, match="needs a Krylov solve"):
        sc.Monolithic(keep=1.0)


@pytest.mark.parametrize(
    ("splits", "message"),
    [
        (None, "option fieldsplit_thermoelectric_ksp_type names none of the splits"),
        ({"te": ("temperature", "potential")}, "field 'displacement' is in 0 of the splits"),
    ],
)
def test_a_field_split_that_misses_a_field_or_a_split_is_refused(bars, splits, message):
    system = make_system(squeezed_joule_bars(bars))
    options = sc.FIELDSPLIT_DIRECT if splits is None else {"pc_type": "fieldsplit"}
    with pytest.raises(ValueError, match=message):
        sc.solve(system, sc.Monolithic(options, splits=splits))


def test_method1_corrector_gives_the_same_answer_with_more_rounds(bars):
    # method 1 is the small-h corrector: soft contacts (h̄ ≈ k/Δx / 4, ḡ ≈ σ/Δx / 40)
    system = make_system(joule_problem(bars, h=10.0, g=1e3))
    states, rounds = {}, {}
    for corrector in (sc.Exact(), sc.Method1()):
        system.reset({"temperature": 300.0})
        linear = sc.Subdomains(corrector, max_rounds=400)
        result = sc.solve(system, linear, rtol=1e-12)
        states[corrector.name] = system.state()
        rounds[corrector.name] = sum(s.inner_rounds for s in result.history)
    # both converge to rtol 1e-12: measured 7e-15 apart
    assert max(system.difference(states["method1"], states["exact"]).values()) < 1e-8
    # the exact corrector takes 2 rounds a step; method 1 contracts by h̄M/(h̄M + K̂) ≈ 0.2
    # a round here, so the inner tolerance η ≤ 1e-4 takes it 6 or more (measured 39 in all
    # against 8)
    assert rounds["method1"] > 2 * rounds["exact"]


def test_newton_failure_reports_its_history(bars):
    system = make_system(squeezed_joule_bars(bars))
    system.reset({"temperature": 300.0})
    with pytest.raises(sc.NewtonConvergenceError, match="DIVERGED_MAX_IT") as caught:
        sc.solve(system, max_it=2)
    assert len(caught.value.result.history) == 3  # iterates 0, 1 and 2
    assert "inner rounds" in str(caught.value)


def test_inner_failure_names_the_corrector(bars):
    system = make_system(expansion_problem(bars, 350.0))
    system.reset({"temperature": 300.0})
    with pytest.raises(sc.NewtonConvergenceError, match="method1: no convergence"):
        sc.solve(system, sc.Subdomains(sc.Method1(), max_rounds=5))


@pytest.mark.parametrize(
    ("material", "contact", "message"),
    [
        (Material(conductivity=-1.0), Contact(conductance=1.0), "conductivity = -1.0"),
        (Material(conductivity=float("nan")), Contact(conductance=1.0), "conductivity = nan"),
        (Material(conductivity=1.0), Contact(conductance=-1.0), "conductance = -1.0: must be >="),
        (Material(conductivity=1.0), Contact(), "needs 'conductance'"),
        (Material(conductivity=1.0, poisson=0.5), Contact(conductance=1.0), "poisson"),
        (
            Material(conductivity=1.0),
            Contact(conductance=1.0, electrical_conductance=1.0),
            "has no field for 'electrical_conductance'",
        ),
    ],
)
def test_bad_data_is_refused_by_name(bars, material, contact, message):
    with pytest.raises(ValueError, match=message):
        Problem(bars, {"plate_A": material, "plate_B": material}, {"contact": contact})


def test_condition_for_a_missing_field_is_refused(bars):
    with pytest.raises(ValueError, match="'left': Potential needs the potential field"):
        Problem(
            bars,
            {"plate_A": Material(conductivity=1.0), "plate_B": Material(conductivity=1.0)},
            {"contact": Contact(conductance=1.0)},
            [Potential("left", 1.0)],
        )


def test_a_law_that_goes_negative_is_named_with_a_point(bars):
    """k(T) = T − 250 at the initial state (0 K); h(T) = 1e3 (340 − T) at the solution (the
    contact between 300 K and 400 K ends near 350 K): refused, the law and a point named."""
    fixed = [Temperature("left", 300.0), Temperature("right", 400.0)]
    negative_k = Problem(
        bars,
        {
            "plate_A": Material(conductivity=lambda p, T: T - 250.0),
            "plate_B": Material(conductivity=1.0),
        },
        {"contact": Contact(conductance=10.0)},
        fixed,
    )
    system = make_system(negative_k)
    system.reset()
    with pytest.raises(
        ValueError, match=r"at the initial state, conductivity of body 'plate_A' is negative"
    ):
        sc.solve(system)
    negative_h = Problem(
        bars,
        {"plate_A": Material(conductivity=10.0), "plate_B": Material(conductivity=10.0)},
        {"contact": Contact(conductance=lambda p, T: 1e3 * (340.0 - T))},
        fixed,
    )
    system = make_system(negative_h)
    system.reset({"temperature": 300.0})
    with pytest.raises(
        ValueError,
        match=r"solution .* conductance of interface 'contact' is negative .* near x = \(0\.5, ",
    ):
        sc.solve(system)


def test_a_body_free_to_slide_is_refused(bars):
    """Walls hold x, nothing holds y: the blocks may slide up and down."""
    steel = Material(conductivity=45.0, young=200e9)
    problem = Problem(
        bars,
        {"plate_A": steel, "plate_B": steel},
        {"contact": Contact(conductance=1e4, normal=Penalty(1e13))},
        [Temperature("left", 300.0), Displacement("left", 0, 0.0), Displacement("right", 0, 0.0)],
    )
    with pytest.raises(ValueError, match=r"no Displacement condition on component 1 \(y\)"):
        make_system(problem)


def test_a_sweep_compiles_its_forms_once(bars, monkeypatch):
    """Five contact conductances, penalties and wall temperatures: every number is a form
    coefficient, so the forms of the first scene serve the four others (no new code).

    Counted by the signatures ffcx computes for what it is asked to compile (a cached module
    is asked for, and counted, too): the later scenes ask for nothing the first did not.
    """
    import ffcx.naming

    asked: list[str] = []
    signature = ffcx.naming.compute_signature

    def record(*args, **kwargs):
        asked.append(signature(*args, **kwargs))
        return asked[-1]

    monkeypatch.setattr(ffcx.naming, "compute_signature", record)
    steel = Material(
        conductivity=45.0, young=200e9, poisson=0.3, expansion=1.2e-5, reference_temperature=300.0
    )
    signatures = []
    for h, penalty, wall in zip(
        [1e-2, 1.0, 1e3, 1e6, 1e10],
        [1e9, 1e10, 1e11, 1e12, 1e13],
        [250, 300, 320, 350, 400],
        strict=True,
    ):
        asked.clear()
        problem = Problem(
            bars,
            {"plate_A": steel, "plate_B": steel},
            {"contact": Contact(conductance=h, normal=Penalty(penalty), gap=1e-5)},
            [
                Temperature("left", float(wall)),
                Temperature("right", 300.0),
                Displacement("left", 0, 0.0),
                Displacement("right", 0, 0.0),
                Displacement("bottom", 1, 0.0),
            ],
        )
        system = make_system(problem)
        system.reset({"temperature": 300.0})
        sc.solve(system, rtol=1e-10)
        sc.summary(system)
        signatures.append(set(asked))
    assert signatures[0]  # the first scene compiled (or found in the cache) its forms
    assert all(later <= signatures[0] for later in signatures[1:])


def test_power_law_refuses_a_zero_floor():
    with pytest.raises(ValueError, match="floor"):
        laws.PowerLaw(scale=1.0, hardness=1e6, exponent=0.9, floor=0.0)


def evaluate(law, p, T, comm):
    """The law's value at constant (p, T): ∫ law dx over a unit square."""
    mesh = dolfinx.mesh.create_unit_square(comm, 1, 1)
    pc, Tc = dolfinx.fem.Constant(mesh, p), dolfinx.fem.Constant(mesh, T)
    form = dolfinx.fem.form(law(pc, Tc) * ufl.dx(domain=mesh))
    return comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)


def test_table_interpolates_bilinearly_and_holds_its_edges(comm):
    pressures, temperatures = (0.0, 1e6, 4e6), (300.0, 500.0)
    values = np.array([[1.0, 2.0], [10.0, 30.0], [40.0, 50.0]])
    table = laws.Table(pressures, temperatures, values)
    for p, T in [(0.0, 300.0), (5e5, 400.0), (2.5e6, 450.0), (1e7, 250.0), (-1.0, 900.0)]:
        pc, Tc = np.clip(p, 0.0, 4e6), np.clip(T, 300.0, 500.0)
        along_p = [np.interp(pc, pressures, values[:, j]) for j in range(2)]
        expected = np.interp(Tc, temperatures, along_p)
        # a constant integrated over the unit square by quadrature: a few roundings
        assert evaluate(table, p, T, comm) == pytest.approx(expected, rel=1e-13)


def test_power_law_values(comm):
    law = laws.PowerLaw(scale=2e3, hardness=1e7, exponent=0.8, floor=10.0)
    # a constant integrated over the unit square by quadrature: a few roundings
    assert evaluate(law, 5e6, 300.0, comm) == pytest.approx(10.0 + 2e3 * 0.5**0.8, rel=1e-13)
    # below p_min = 1e-9 H the pressure is held at p_min (a finite derivative for β < 1)
    at_zero = 10.0 + 2e3 * 1e-9**0.8
    assert evaluate(law, 0.0, 300.0, comm) == pytest.approx(at_zero, rel=1e-13)
    assert evaluate(law, -5e6, 300.0, comm) == pytest.approx(at_zero, rel=1e-13)


def test_power_law_with_a_scale_tabulated_in_temperature(comm):
    """C = floor + α k_harm(T) (p/H)^β: the scale interpolated in T, held beyond the table."""
    scale = laws.Table((0.0,), (300.0, 1300.0), [[4e3, 3e3]])
    law = laws.PowerLaw(scale=scale, hardness=2.5e9, exponent=0.35, floor=10.0)
    for T, s in [(300.0, 4e3), (800.0, 3.5e3), (2000.0, 3e3)]:
        expected = 10.0 + s * (1e6 / 2.5e9) ** 0.35
        # a constant integrated over the unit square by quadrature: a few roundings
        assert evaluate(law, 1e6, T, comm) == pytest.approx(expected, rel=1e-13)
    with pytest.raises(ValueError, match="scale"):
        laws.PowerLaw(laws.Table((0.0,), (300.0, 1300.0), [[4e3, -1.0]]), 2.5e9, 0.35, 10.0)


@pytest.fixture(scope="module")
def blocks3d(comm):
    """Two 0.5 × 0.2 × 0.2 m blocks in a row, tetrahedra of about 0.1 m."""
    return sc.load_scene(
        GEO / "blocks3d.geo",
        bodies=["block_A", "block_B"],
        interfaces=["contact"],
        parameters={"size": 0.1},
        comm=comm,
    )


@pytest.mark.parametrize("temperature", [350.0, 250.0])
def test_thermal_expansion_in_3d(blocks3d, comm, temperature):
    """Uniaxial stress in 3D (free sides, rollers on y = 0 and z = 0): pressure and gap."""
    steel = Material(
        conductivity=45.0, young=200e9, poisson=0.3, expansion=1.2e-5, reference_temperature=300.0
    )
    problem = Problem(
        blocks3d,
        {"block_A": steel, "block_B": steel},
        {"contact": Contact(conductance=1e4, normal=Penalty(1e13), gap=1e-4)},
        [
            Temperature("left", temperature),
            Temperature("right", temperature),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, 0.0),
            Displacement("front", 1, 0.0),
            Displacement("bottom", 2, 0.0),
        ],
    )
    system = make_system(problem)
    assert system.layers["contact"].channels == (("temperature", None), ("displacement", 0))
    states = {}
    for linear in ("subdomain", "monolithic"):
        system.reset({"temperature": 300.0})
        sc.solve(system, LINEAR[linear](), rtol=1e-12)
        states[linear] = system.state()
    # both converged to rtol 1e-12: measured ≤ 1.3e-14 apart
    assert max(system.difference(states["subdomain"], states["monolithic"]).values()) < 1e-8
    exact = BlocksBetweenWalls(
        (0.5, 0.5), (200e9,) * 2, (0.3,) * 2, (1.2e-5,) * 2, 1e-4, 1e13, plane_strain=False
    )
    heating = temperature - 300.0
    area = 0.2 * 0.2
    force = sc.force(system, "contact")
    fields = sc.contact_fields(system)["contact"]
    # uniaxial uniform strain, exact for P1 tetrahedra: round-off only (measured 6e-15)
    if heating > 0:
        assert exact.pressure(heating) > 5e7
        assert force[0] / area == pytest.approx(exact.pressure(heating), rel=1e-9)
        assert fields["pressure"] == pytest.approx(exact.pressure(heating), rel=1e-9)
    else:
        # open: no force, to round-off of the force that would hold the contraction
        assert np.abs(force).max() <= 1e-12 * 200e9 * 1.2e-5 * 50.0 * area
    assert fields["gap"] == pytest.approx(exact.gap_width(heating), rel=1e-9)


def test_every_field_in_3d_potential_and_current(blocks3d, comm):
    """T, φ and u together in 3D: the potential (linear, so exact on tetrahedra) and the current
    against the closed form; the mechanical contact is closed by the walls."""
    materials = {
        "block_A": Material(conductivity=10.0, electrical_conductivity=1e4, young=1e10),
        "block_B": Material(conductivity=50.0, electrical_conductivity=3e4, young=2e11),
    }
    problem = Problem(
        blocks3d,
        materials,
        {"contact": Contact(conductance=2e3, electrical_conductance=5e4, normal=Penalty(1e12))},
        [
            Temperature("left", 300.0),
            Temperature("right", 320.0),
            Potential("left", 0.5),
            Potential("right", 0.0),
            Displacement("left", 0, 0.0),
            Displacement("right", 0, -1e-5),
            Displacement("front", 1, 0.0),
            Displacement("bottom", 2, 0.0),
        ],
    )
    system = make_system(problem)
    assert [f for f, _ in system.layers["contact"].channels] == [
        "temperature",
        "potential",
        "displacement",
    ]
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    exact = JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, 2e3, 5e4, 0.5, 300.0, 320.0)
    potential = {"block_A": exact.potential_a, "block_B": exact.potential_b}
    # φ is linear, exact on tetrahedra: round-off only (measured 3e-16, current 4e-16)
    assert max_nodal_error(system, potential, "potential", comm) < 1e-10
    assert sc.current(system, "contact") == pytest.approx(exact.current_density * 0.04, rel=1e-10)
    assert sc.force(system, "contact")[0] > 0


def test_three_bodies_two_interfaces_match_the_monolithic_newton(comm):
    """A chain of three bodies: the middle one has two interfaces, corrected block by block."""
    from verification.cases import stack_scene

    scene = stack_scene(3, 3, 2, comm=comm)
    h = laws.PowerLaw(scale=50.0, hardness=1e6, exponent=1.0, floor=5.0)
    materials = {
        f"body_{i}": Material(
            conductivity=lambda p, T, k=k: k * (1 + 1e-2 * T), electrical_conductivity=s
        )
        for i, (k, s) in enumerate([(1.0, 10.0), (5.0, 2.0), (0.5, 30.0)])
    }
    contacts = {
        f"contact_{i}": Contact(
            conductance=lambda p, T: h(p, T) * (1 + 1e-2 * T),
            electrical_conductance=20.0,
            pressure=1e5,
        )
        for i in range(2)
    }
    problem = Problem(
        scene,
        materials,
        contacts,
        [
            Temperature("left", 0.0),
            Temperature("right", 1.0),
            Potential("left", 1.0),
            Potential("right", 0.0),
        ],
    )
    system = make_system(problem)
    states, rounds = {}, {}
    for name, options in [
        ("gmres", sc.Subdomains()),  # the default with several interfaces per body
        ("jacobi", sc.Subdomains(krylov=False, max_rounds=300)),
        ("monolithic", sc.Monolithic()),
    ]:
        system.reset()
        result = sc.solve(system, options, rtol=1e-12)
        states[name] = system.state()
        rounds[name] = [s.inner_rounds for s in result.history[1:]]
    for name in ("gmres", "jacobi"):
        # converged to rtol 1e-12: measured ≤ 8e-15 apart
        assert max(system.difference(states[name], states["monolithic"]).values()) < 1e-8
    # GMRES ends within as many iterations as the interface problem has unknowns (2
    # interfaces × 3 nodes × T and φ = 12), plus its first and last rounds: measured 6
    masters = system.num_dofs()["masters"]
    assert masters == 12 and max(rounds["gmres"]) <= masters + 2
    # block Jacobi across the two interfaces of the middle body contracts slowly (the middle
    # body's two sides see each other's corrections a round late): measured 63 rounds
    assert max(rounds["jacobi"]) > 20


@pytest.mark.parametrize("share", [0.8, 0.0])
def test_the_contact_joule_heat_goes_where_it_is_told(bars, comm, share):
    """``joule_to_first``: that share of g Δφ² into bar A, the rest into B, against the
    closed form with the same split (nodally exact, as the even split)."""
    problem = joule_problem(bars)
    contact = dataclasses.replace(problem.contacts["contact"], joule_to_first=share)
    problem = sc.Problem(bars, problem.materials, {"contact": contact}, problem.conditions)
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    exact = JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, 2e3, 5e4, 0.5, 300.0, 320.0, share)
    temperature = {"plate_A": exact.thermal.temperature_a, "plate_B": exact.thermal.temperature_b}
    assert max_nodal_error(system, temperature, "temperature", comm) < 1e-10  # as the first
    even = JouleBars(0.5, 0.5, 10.0, 50.0, 1e4, 3e4, 2e3, 5e4, 0.5, 300.0, 320.0)
    middle = np.array([0.5])
    shift = abs(exact.thermal.temperature_a(middle) - even.thermal.temperature_a(middle))[0]
    assert shift > 1e-3  # the split matters here: the test can tell
    assert sc.balance(system)["heat"]["relative"] < 1e-10
    with pytest.raises(ValueError, match="joule_to_first"):
        sc.Problem(
            bars,
            problem.materials,
            {"contact": dataclasses.replace(contact, joule_to_first=1.5)},
            problem.conditions,
        )


def test_young_and_expansion_may_follow_the_temperature(bars, comm):
    """E(T) and α(T) (secant from the reference temperature) at a uniform 350 K: the blocks
    between walls see the constants E(350), α(350): the closed form with those, to round-off
    as the constant case."""
    base = expansion_problem(bars, 350.0)
    steel = dataclasses.replace(
        base.materials["plate_A"],
        young=lambda p, T: 200e9 * (1 - 4e-4 * (T - 300.0)),
        expansion=lambda p, T: 1.2e-5 * (1 + 2e-3 * (T - 300.0)),
    )
    problem = sc.Problem(bars, {"plate_A": steel, "plate_B": steel}, base.contacts, base.conditions)
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    young, alpha = 200e9 * (1 - 4e-4 * 50.0), 1.2e-5 * (1 + 2e-3 * 50.0)
    exact = BlocksBetweenWalls((0.5, 0.5), (young,) * 2, (0.3,) * 2, (alpha,) * 2, 1e-4, 1e13)
    force = sc.force(system, "contact")
    assert force[0] / 0.1 == pytest.approx(exact.pressure(50.0), rel=1e-9)
    constant = BlocksBetweenWalls((0.5, 0.5), (200e9,) * 2, (0.3,) * 2, (1.2e-5,) * 2, 1e-4, 1e13)
    assert abs(exact.pressure(50.0) / constant.pressure(50.0) - 1) > 1e-2  # the laws matter


def test_a_weak_slip_spring_carries_its_own_force(bars, comm):
    """Bar A clamped on the left, bar B's right end moved up by δ, a stuck contact whose slip
    is held by a spring k_t far weaker than the bars: the shear force across the contact is
    k_t · 0.1 m · δ (per metre of depth).

    The bars give way by F / (3 E I / L³) each (cantilevers, 4e8 N/m²): 5e-7 of the slip, so
    the force is k_t · 0.1 · δ within 1e-5 (20 times that)."""
    steel = Material(conductivity=45.0, young=200e9, poisson=0.3)
    k_t, delta = 1e3, 1e-5
    problem = Problem(
        bars,
        {"plate_A": steel, "plate_B": steel},
        {
            "contact": Contact(
                conductance=1e4, normal=Penalty(1e13), tangential="stuck", slip_stiffness=k_t
            )
        },
        [
            Temperature("left", 300.0),
            Displacement("left", 0, 0.0),
            Displacement("left", 1, 0.0),
            Displacement("right", 0, 0.0),
            Displacement("right", 1, delta),
        ],
    )
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    shear = abs(sc.force(system, "contact")[1])
    assert shear == pytest.approx(k_t * 0.1 * delta, rel=1e-5)
    negative = Contact(
        conductance=1e4, normal=Penalty(1e13), tangential="stuck", slip_stiffness=-1.0
    )
    with pytest.raises(ValueError, match=r"slip_stiffness = -1\.0"):
        make_system(dataclasses.replace(problem, contacts={"contact": negative}))


@pytest.mark.parametrize("linear", ["subdomain", "monolithic"])
def test_a_pressure_load_squeezes_the_bars_uniformly(bars, comm, linear):
    """Bar A held at x = 0, both on rollers at y = 0, a pressure p on bar B's right end: plane
    strain under the uniaxial stress σ_xx = −p, so u_x(1 m) = −p (1 − ν²) / E × 1 m − p / k_n
    (the bars, and the penalty's closure δ = p / k_n); the contact carries p × 0.1 m, the
    support gives it back, and the force balance closes with the load's group in it.

    P1 holds the uniform strain exactly: what is left is the Newton tolerance (1e-12) times
    the condition of the bars' stiffness against the penalty's (k_n h / E ≈ 6), far below
    the 1e-9 asked (measured 2e-15)."""
    E, nu, k_n, p = 200e9, 0.3, 1e13, 1e7
    steel = Material(conductivity=45.0, young=E, poisson=nu)
    problem = Problem(
        bars,
        {"plate_A": steel, "plate_B": steel},
        {"contact": Contact(conductance=1e4, normal=Penalty(k_n))},
        [
            Temperature("left", 300.0),
            Displacement("left", 0, 0.0),
            Displacement("bottom", 1, 0.0),
            sc.Pressure("right", p),
        ],
    )
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, linear=LINEAR[linear](), rtol=1e-12)
    local = np.zeros(2)
    if "plate_B" in system.bodies:
        points, values = system.bodies["plate_B"].nodal("displacement", 0)
        on = np.isclose(points[:, 0], 1.0)
        local = np.array([values[on].sum(), on.sum()])
    total = comm.allreduce(local, op=MPI.SUM)
    end = total[0] / total[1]
    assert end == pytest.approx(-p * (1 - nu**2) / E - p / k_n, rel=1e-9)
    assert sc.force(system, "contact")[0] == pytest.approx(p * 0.1, rel=1e-9)
    assert sc.force(system, "left")[0] == pytest.approx(p * 0.1, rel=1e-9)
    forces = sc.balance(system)["force"]
    assert forces["groups"]["right"][0] == pytest.approx(-p * 0.1, rel=1e-9)
    assert forces["relative"] < 1e-9
    row = sc.summary(system)["contacts"]["contact"]
    assert row["mean pressure"] == pytest.approx(p, rel=1e-9)
    assert row["max pressure"] == pytest.approx(p, rel=1e-9)
    assert row["open share"] == 0.0
