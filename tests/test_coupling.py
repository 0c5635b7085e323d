"""The coupling layer on every field: many bodies, floating bodies, stiff contacts, defaults
that converge from a cold start, kept factorisations, modified Newton, rank groups."""

import dataclasses

import numpy as np
import pytest
from helpers import make_system, preconditioned_condition, same_pattern
from mpi4py import MPI
from petsc4py import PETSc

import subdomain_contact as sc
from subdomain_contact import merged, newton, readback
from subdomain_contact import schur as schur_module
from subdomain_contact.merged import MergePlan, merged_matrix
from subdomain_contact.physics import FIELDS
from subdomain_contact.solvers import destroy
from verification.cases import (
    bars_scene,
    blocks_row_scene,
    cathode_slot,
    cathode_slot_scene,
    hot_squeezed_bars,
    joule_bars,
    squeezed_joule_bars,
    squeezed_row,
    stack_scene,
    steel_blocks_between_walls,
    two_plates,
    two_plates_scene,
)
from verification.nodal import NodalReference, error_against, field_values

#: Every scalar field and displacement component of a 3D coupled scene.
FIELDS_3D = [("temperature", None), ("potential", None)] + [("displacement", i) for i in range(3)]


def newton_and_reference(problem, linear=None, *, rtol=1e-10, schur=True, **options):
    """(subdomain result, monolithic result, per-field difference) from the same cold start."""
    system = make_system(problem, schur=schur)
    system.reset({"temperature": 300.0})
    result = sc.solve(system, linear, rtol=rtol, **options)
    state = system.state()
    system.reset({"temperature": 300.0})
    reference = sc.solve(system, sc.Monolithic(), rtol=rtol)
    assert reference.iterations >= 1
    difference = system.difference(state, system.state())
    state.destroy()
    return result, reference, difference


# -- defaults that converge ---------------------------------------------------------------


@pytest.mark.parametrize("mechanics", [False, True], ids=["thermal-electric", "with-mechanics"])
@pytest.mark.parametrize("depth", [0.0, 0.04], ids=["2d", "3d"])
def test_cathode_slot_converges_from_a_cold_start_with_defaults(comm, depth, mechanics):
    """Block, cast iron and collector bar (four contacts; the cast iron touches all four)
    from a uniform 300 K, every solver option at its default."""
    scene = cathode_slot_scene(0.06, 0.03, depth=depth, comm=comm)
    linear = sc.Subdomains()
    result, reference, difference = newton_and_reference(cathode_slot(scene, mechanics=mechanics),
                                                         linear)  # fmt: skip
    # the cast iron touches two interfaces: the default is the interface Krylov
    assert linear.use_krylov
    # Both Newtons stop at rtol 1e-10 per field on quadratically converging iterates:
    # measured ≤ 3.7e-13 apart; 1e-8 (the agreement) leaves 2.7e4 times that
    assert max(difference.values()) < 1e-8
    # the same Newton (measured 4 steps without mechanics, 6 with, both routes); the last
    # step may fall either side of rtol
    assert abs(result.iterations - reference.iterations) <= 1
    assert result.relative_residuals()[-1] <= 1e-10


@pytest.mark.parametrize("depth", [0.0, 0.04], ids=["2d", "3d"])
def test_the_newton_matrix_is_the_derivative_of_the_residual(comm, depth):
    """``J v`` (the assembled blocks' product) against the central difference
    ``(F(x + εv) − F(x − εv)) / 2ε`` at the cathode slot's solution (T, φ, u; conductances of
    the pressure and the temperature, penalty contacts, Joule heat), for a random probe in
    each field, zero on the Dirichlet DOFs (Newton moves none), over every body's and
    master's rows. An exact Jacobian keeps Newton quadratic; a missing or wrong coupling term
    shows here as an error of the size of that term, whatever its effect on convergence.
    """
    system = make_system(cathode_slot(cathode_slot_scene(0.06, 0.03, depth=depth, comm=comm)))
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-10)
    x = system.state()
    rng = np.random.default_rng(comm.rank)
    eps = 1e-3
    # the probe's size per field: 1e-3 K, 1e-7 V and 1e-10 m at ε, far from every
    # contact's kink at this solution (measured: the errors fall as 1/ε from 1e-2 to 1e-4,
    # the differences' round-off, but for u -> T: 1e-8 to 2e-8 at 1e-2, falling as ε², the
    # truncation)
    scales = {"temperature": 1.0, "potential": 1e-4, "displacement": 1e-7}
    vecs = [x.duplicate() for _ in range(4)]
    v, jv, plus, minus = vecs
    for probe, scale in scales.items():
        v.set(0.0)
        mask = system.field_of == FIELDS.index(probe)
        v.array[mask] = scale * rng.standard_normal(np.count_nonzero(mask))
        for name, body in system.bodies.items():
            v.array[system.slices[name].start + body.fixed_local] = 0.0
        system.set_state(x)
        system.assemble_jacobian()
        system.mult(v, jv)
        for sign, f in ((1.0, plus), (-1.0, minus)):
            x.copy(f)
            f.axpy(sign * eps, v)
            system.set_state(f)
            system.residual(f)
        plus.axpy(-1.0, minus)
        plus.scale(1.0 / (2.0 * eps))
        plus.axpy(-1.0, jv)
        error, norm = system.field_norms(plus), system.field_norms(jv)
        for field in system.problem.fields:
            if norm[field] == 0.0:  # u does not depend on φ: no term to compare, none found
                assert error[field] == 0.0, (probe, field)
                continue
            # measured ≤ 1.1e-9 at ε = 1e-3 (2D on 1 and 2 ranks, 3D on 1): 1e-7 leaves 90 times
            # that for other round-off, and a wrong term of 1e-7 of the field's coupling fails
            # (the bulk Jacobian scaled by 1 + 1e-6 failed at 8.5e-7)
            assert error[field] <= 1e-7 * norm[field], (probe, field, error[field] / norm[field])
    system.set_state(x)
    destroy(x, *vecs)


def test_newtons_residual_sees_an_open_contacts_master(comm):
    """The cathode slot (2D) with a gap of 0.3 mm on every contact: at the solution three of
    the bar side's seven nodes are open. Each master, open or closed, sits at the mean of its
    two slaves' normal displacements (both sides' ties are alike here, as their pressures
    are), so each half-link reads the contact's own closure. And Newton's residual sees an
    open master: the widest open, moved by a tenth of its gap, leaves a displacement
    residual above Newton's tolerance (the master equation's tie, ``physics.MASTER_TIE``;
    with the bodies' tie there, 1e-9 of the contact's stiffness, it stayed far below it)."""
    problem = cathode_slot(cathode_slot_scene(0.06, 0.03, comm=comm))
    gap = 3e-4  # m
    contacts = {k: dataclasses.replace(c, gap=gap) for k, c in problem.contacts.items()}
    system = make_system(dataclasses.replace(problem, contacts=contacts))
    system.reset({"temperature": 300.0})
    rtol = 1e-10
    result = sc.solve(system, rtol=rtol)
    sides = readback._sides(system)
    opened = {}
    for k, layer in system.layers.items():
        first, second = (sides[name][k] for name in layer.interface.bodies)
        parts = [
            slice(c * layer.nodes, (c + 1) * layer.nodes)
            for c, (f, _) in enumerate(layer.channels)
            if f == "displacement"
        ]

        def nodal(values, parts=parts):
            return np.stack([values[p] for p in parts], axis=1)

        unit = nodal(first["normal"])
        unit /= np.linalg.norm(unit, axis=1)[:, None]
        u_a, u_b = nodal(first["values"]), nodal(second["values"])
        off = np.sum((nodal(system.masters[k]) - 0.5 * (u_a + u_b)) * unit, axis=1)
        # the ties' equation is linear in u: Newton's last step puts the master at the mean
        # to the round-off of u (ε max|u| = 2e-19 m; measured 3e-18 m against max|u| 8.5e-4)
        assert np.abs(off).max() <= 1e-12 * np.abs(u_a).max(), k
        gaps = gap - np.sum((u_a - u_b) * unit, axis=1)
        opened[k] = [(gaps[i], [p.start + i for p in parts], unit[i])
                     for i in np.flatnonzero(gaps > 0)]  # fmt: skip
    assert [k for k, nodes in opened.items() if nodes] == ["bar_side"]  # measured: 3 of 7 nodes
    x, f = system.state(), system.create_vector()
    tolerance = rtol * result.scale["displacement"]  # Newton's stopping test on u [N]
    node_gap, at, normal = max(opened["bar_side"], key=lambda node: node[0])  # 65 µm
    masters = {k: v.copy() for k, v in system.masters.items()}
    masters["bar_side"][at] += 0.1 * node_gap * normal
    system.set_masters(masters)
    system.residual(f)
    # Newton does not stop there: measured 16 times its tolerance, and 1/61 of it with the
    # bodies' tie in the master equation (MASTER_TIE = 1), the tie's ratio of 1e3
    assert system.field_norms(f)["displacement"] > tolerance
    system.set_state(x)
    destroy(x, f)


def test_a_full_step_that_runs_away_is_halved_and_newton_converges(comm, monkeypatch):
    """The squeezed Joule bars with the exponential closure 40 times as steep (δ₀ = 0.5 µm):
    plain full steps overshoot the closure and diverge; halved while they land above
    RUNAWAY, they converge, to the monolithic Newton's solution."""
    problem = squeezed_joule_bars(bars_scene(8, 2, comm=comm))
    contact = dataclasses.replace(
        problem.contacts["contact"], normal=sc.ExponentialClosure(stiffness=1e12, closure=5e-7)
    )
    problem = dataclasses.replace(problem, contacts={"contact": contact})
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    residual, evaluations = system.residual, []
    monkeypatch.setattr(system, "residual", lambda f: (evaluations.append(1), residual(f)))
    result = sc.solve(system, line_search="basic")
    state = system.state()
    # measured serially: 7 steps of 24 halved once
    assert result.halved >= 1
    # the cold and the initial state, then one per trial of a step: the line search takes
    # the safeguard's residual where the step lands (without it, one more per step)
    assert len(evaluations) == 2 + result.iterations + result.halved
    monkeypatch.undo()
    system.reset({"temperature": 300.0})
    monolithic = sc.Monolithic()
    sc.solve(system, monolithic, line_search="basic")
    monolithic.destroy()
    # both converged to rtol 1e-10 per field: 1e-8 is the agreement
    assert max(system.difference(state, system.state()).values()) < 1e-8
    state.destroy()
    # the same full steps without the safeguard: measured 1.4e18 of the scale at step 50
    monkeypatch.setattr(newton, "RUNAWAY", np.inf)
    system.reset({"temperature": 300.0})
    with pytest.raises(sc.NewtonConvergenceError, match="basic"):
        sc.solve(system, line_search="basic")


def test_each_line_search_that_fails_says_why_before_the_next_begins(comm, capsys):
    """``progress``: under ``"auto"`` each failed attempt prints its error's first line before
    the next line search's first iterate, and the error names every attempt. The squeezed
    Joule bars take 9 full steps (measured): allowed one, each line search fails."""
    system = make_system(squeezed_joule_bars(bars_scene(8, 2, comm=comm)))
    system.reset({"temperature": 300.0})
    with pytest.raises(sc.NewtonConvergenceError) as failure:
        sc.solve(system, max_it=1, progress=True)
    for attempt in newton.AUTO:
        assert f"line search {attempt}: Newton failed after 1 iterations" in str(failure.value)
    lines = capsys.readouterr().out.splitlines()
    if comm.rank == 0:  # the progress lines are rank 0's
        said = [i for i, line in enumerate(lines) if line.startswith("Newton (")]
        lines = [lines[i] for i in said]
        expected = []
        for attempt in newton.AUTO:  # iterates 0 and 1, then why it stopped
            expected += [f"Newton ({attempt})   0:", f"Newton ({attempt})   1:"]
            expected += [f"Newton ({attempt}): Newton failed after 1 iterations: DIVERGED_MAX_IT"]
        assert len(lines) == len(expected), lines
        for line, start in zip(lines, expected, strict=True):
            assert line.startswith(start), (line, start)


class _Landing:
    """A one-unknown system whose residual, relative to its scale, is ``law(x)``."""

    is_linear, bodies, comm = False, {}, MPI.COMM_SELF

    def __init__(self, law) -> None:
        self.law, self.x = law, 0.0

    def set_state(self, w) -> None:
        self.x = w.array[0]

    def residual(self, f) -> None:
        with np.errstate(over="ignore"):  # an infinite landing, as an overflowing norm gives
            f.array[0] = self.law(self.x)

    def field_norms(self, f) -> dict[str, float]:
        return {"temperature": float(f.array[0])}


@pytest.mark.parametrize(
    ("law", "overshoot", "halvings"),
    [
        (np.exp, 40.0, 3),  # e^40, e^20 and e^10 run away; e^5 = 148 is in
        (np.exp, 1000.0, 8),  # beyond measure (inf), then e^500 ... e^7.8: HALVINGS exactly
        (lambda x: 1e4 * x**2, 40.0, None),  # 1.6e7, 4e6: ln(R/1e3) falls to 0.86 of it, a climb
        # 4e5, 2e5: proportional to the step, a penalty's new contact status: the full step
        (lambda x: 1e4 * np.abs(x), 40.0, 0),
        # two norms beyond measure are not a proportional landing: e^10, e^5 = 148 is in
        (lambda x: np.where(np.abs(x) > 10, np.inf, np.exp(np.abs(x))), 40.0, 3),
    ],
    ids=["exponential", "overflow", "power", "penalty", "infinite"],
)
def test_a_step_is_halved_while_its_landing_falls_as_an_exponentials(law, overshoot, halvings):
    """The safeguard halves an exponential's overshoot, however far (the bound HALVINGS is
    the overflow's), gives a power-law climb up after one halving, and keeps a full step whose
    landing is proportional to it (a contact penalty's)."""
    system = _Landing(law)
    callbacks = newton._Callbacks(system, None, 1e-10, 10, None, 1)
    callbacks.scale, callbacks.relative = {"temperature": 1.0}, 1.0
    x, y = (PETSc.Vec().createSeq(1, comm=MPI.COMM_SELF) for _ in range(2))
    x.set(0.0)
    y.set(-overshoot)  # the state x − y lands at the overshoot
    if halvings is None:
        with pytest.raises(newton.RunawayStepError, match="1/2:"):
            callbacks.safeguard(x, y)
        assert callbacks.pending_halvings == 1 and callbacks.trial is None
    else:
        callbacks.safeguard(x, y)
        assert callbacks.pending_halvings == halvings
        assert y.array[0] == -overshoot / 2**halvings
        assert callbacks.trial[0].array[0] == overshoot / 2**halvings
        assert callbacks.trial[1].array[0] == law(overshoot / 2**halvings)
        assert (law(overshoot / 2**halvings) <= newton.RUNAWAY) == (halvings > 0)
        callbacks.drop_trial()
    destroy(x, y)


@pytest.mark.parametrize("depth", [0.0, 0.04], ids=["2d", "3d"])
def test_sparse_strip_corrector_with_bodies_factorised_whole(comm, depth):
    """The cathode slot with mechanics, no Schur block (each S^α applied by a body solve) and
    the sparse strip corrector: nothing dense but the coarse space; the monolithic Newton's
    solution."""
    scene = cathode_slot_scene(0.06, 0.03, depth=depth, comm=comm)
    linear = sc.Subdomains(sc.SparseStrip())
    result, reference, difference = newton_and_reference(cathode_slot(scene), linear, schur=False)
    assert linear.use_krylov and linear.strip is not None and not linear.dense
    # as in the test above: both stop at rtol 1e-10 on quadratically converging iterates
    assert max(difference.values()) < 1e-8
    assert abs(result.iterations - reference.iterations) <= 1
    # one sparse factorisation of the strips per Jacobian, beside the bodies' own (with
    # factorised bodies the strip is rebuilt at every set-up: Subdomains' lag)
    bodies = len(scene.bodies)
    assert result.factorisations == result.jacobians * (bodies + 1)
    linear.destroy()


# -- coarse spaces for every field --------------------------------------------------------


def chain(scene, field):
    """A chain of bodies held at the left end of body 0 only: the others float in ``field``.

    Potential: σ cycling 1e4, 1e5, 1e3 S/m, g = 1e8 S/m² (ḡ = g Δx / σ ≈ 1e4 as the thermal
    chain's h̄). Displacement: E cycling 1, 10, 0.1 GPa, stuck contacts closed by 1 µm of
    interference under a penalty of 1e13 Pa/m (k_n Δx / E ≈ 1e4), body 0 clamped on x = 0.
    """
    n = len(scene.bodies)
    cycle = [1.0, 10.0, 0.1]
    if field == "potential":
        materials = {
            f"body_{i}": sc.Material(electrical_conductivity=1e4 * cycle[i % 3]) for i in range(n)
        }
        contact = sc.Contact(electrical_conductance=1e8)
        conditions = [sc.Potential("left", 1.0)]
    else:
        materials = {
            f"body_{i}": sc.Material(young=1e9 * cycle[i % 3], poisson=0.3) for i in range(n)
        }
        contact = sc.Contact(normal=sc.Penalty(1e13), tangential="stuck", gap=-1e-6)
        conditions = [sc.Displacement("left", 0, 0.0), sc.Displacement("left", 1, 0.0)]
    contacts = {f"contact_{i}": contact for i in range(n - 1)}
    return sc.Problem(scene, materials, contacts, conditions)


@pytest.mark.parametrize("field", ["potential", "displacement"])
def test_coarse_space_keeps_a_floating_chain_fast_in_every_field(comm, field):
    """Chains of 8 and 32 bodies floating in φ (constants) or u (2D rigid motions).

    As for the temperature (test_krylov): without the coarse correction a chain of floating
    bodies is a 1D problem over the bodies whose condition grows like n² (16 times from 8 to
    32 bodies); with it, balancing domain decomposition bounds the condition independently
    of n. Measured: φ 592 → 18751 without (32 times), 3.096 → 3.100 with; u 1.1e4 → 9.7e6
    without (the rotations grow like n⁴), 3.469 → 3.472 with. The bounds keep the thermal
    test's margins: 8 (half the theory) and 10 % of growth.
    """
    kappa = {}
    for n in (8, 32):
        problem = chain(stack_scene(n, 2, 2, comm=comm), field)
        for coarse in (True, False):
            kappa[n, coarse] = preconditioned_condition(problem, coarse=coarse)
    assert kappa[32, True] <= 1.1 * kappa[8, True]
    assert kappa[32, False] >= 8 * kappa[8, False]


def test_floating_3d_blocks_in_every_field_match_the_monolithic_newton(comm):
    """Four 3D blocks in a row, the inner two floating in T, φ and u_x, every law of p and T."""
    problem = squeezed_row(blocks_row_scene(4, 0.1, comm=comm))
    result, reference, difference = newton_and_reference(problem, rtol=1e-12)
    # converged to rtol 1e-12: measured 3.3e-15 apart; 1e-8 is the agreement
    assert max(difference.values()) < 1e-8
    # the exact corrector inside GMRES with the coarse space: an exact Newton step (same
    # iterations as the monolithic Newton)
    assert result.iterations == reference.iterations


# -- stiff contacts: the reaction form of the master residual, every field -----------------


@pytest.mark.parametrize("stiffness", [1.0, 1e6, 1e12])
def test_stiff_joule_contact_matches_the_closed_form(comm, stiffness):
    """h̄ = h Δx / k and ḡ = g Δx / σ of bar A up to 1e12 (Δx = 0.125 m on 4 × 2 cells).

    The link form of the master residual, ḡ (φ_s − φ_m), loses its digits as ḡ grows
    (φ_s − φ_m is 1e-13 V at 1e12, all round-off); the inner iteration takes each stiff
    master DOF's residual from the body's own equation instead (reaction form), and Newton
    ends on its step when the residual itself cannot fall below ḡ ε |φ|.
    """
    scene = bars_scene(4, 2, comm=comm)
    problem, exact = joule_bars(scene, h=stiffness * 10.0 / 0.125, g=stiffness * 1e4 / 0.125)
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    result = sc.solve(system, rtol=1e-12)
    truth = {
        "temperature": (exact.thermal.temperature_a, exact.thermal.temperature_b),
        "potential": (exact.potential_a, exact.potential_b),
    }
    for field, (a, b) in truth.items():
        along_x = {"plate_A": lambda x, f=a: f(x[:, 0]), "plate_B": lambda x, f=b: f(x[:, 0])}
        # nodally exact (1D P1), so round-off: measured ≤ 1.8e-13 of the range at every
        # stiffness; 1e-10 leaves 500 times that
        assert error_against(system, along_x, field) < 1e-10, field
    # φ in one step, T in the next, then a step at round-off (measured 4e-16 relative)
    # ends it: the residual stalls at 2e-10 of its scale at 1e6, 1e-4 at 1e12
    assert result.iterations <= 3


@pytest.mark.parametrize("stiffness", [1.0, 1e6, 1e12])
def test_stiff_penalty_matches_the_closed_form(comm, stiffness):
    """Penalty k_n Δx / E up to 1e12 (E = 200 GPa, Δx = 0.125 m): blocks heated by 50 K
    between walls close a gap of 0.1 mm; u_x against the closed form (uniform strains)."""
    scene = bars_scene(4, 2, comm=comm)
    problem, exact = steel_blocks_between_walls(scene, 350.0, penalty=stiffness * 200e9 / 0.125)
    system = make_system(problem)
    system.reset({"temperature": 300.0})
    sc.solve(system, rtol=1e-12)
    a, b = exact.displacement_x(50.0)
    along_x = {"plate_A": lambda x: a(x[:, 0]), "plate_B": lambda x: b(x[:, 0])}
    # P1 represents uniform strains exactly: round-off only, measured 3.9e-15, 7.3e-15 and
    # 1.5e-14 of the range at 1, 1e6, 1e12
    assert error_against(system, along_x, "displacement", 0) < 1e-10
    assert exact.pressure(50.0) > 1e8  # the contact is closed and loaded


# -- kept factorisations and modified Newton ------------------------------------------------


def test_a_linear_bulk_is_factorised_once(comm):
    """Linear bulk, contact laws of p and T: each body is factorised once for the whole Newton.

    Under MPI the bars sit on rank groups: a body spread over several ranks is factorised
    whole, contact blocks included, so it is factorised again when they change.
    """
    system = make_system(hot_squeezed_bars(bars_scene(8, 2, comm=comm, placement="groups")))
    system.reset({"temperature": 300.0})
    result = sc.solve(system, rtol=1e-12)
    serial = make_system(hot_squeezed_bars(bars_scene(8, 2, comm=MPI.COMM_SELF)))
    serial.reset({"temperature": 300.0})
    sc.solve(serial, sc.Monolithic(), rtol=1e-12)
    assert result.iterations >= 3  # the contact's laws make it nonlinear
    assert result.factorisations == 2  # one sparse factorisation per bar
    assert result.jacobians == result.iterations  # every step's contact blocks, though
    worst = 0.0
    for field, component in [("temperature", None), ("displacement", 0), ("displacement", 1)]:
        reference = NodalReference(*field_values(serial, field, component))
        spaces = field_values(system, field, component)[0]
        worst = max(worst, error_against(system, reference.at(spaces), field, component))
    # both at rtol 1e-12: measured 1.1e-15 of the range apart, on 1 and on 2 ranks
    assert worst < 1e-8


def test_the_merged_matrix_keeps_its_pattern_from_state_to_state(comm):
    """A factorisation is reused on the same stored entries: they must not follow the state.

    At the cold state (φ = 0) the contact's Joule heat and its derivatives vanish; at the
    solution they do not. A sparse sum of the link's parts dropped the entries that vanished,
    and the count of entries could then stay while the pattern changed: the collector bar
    slot (65k DOFs) factorised a matrix on another's analysis and Newton's step was 1e9 m.
    """
    system = make_system(squeezed_joule_bars(bars_scene(8, 2, comm=comm)))
    system.reset({"temperature": 300.0})
    system.assemble_jacobian()
    cold = merged_matrix(system)
    sc.solve(system, sc.Monolithic(), rtol=1e-10)
    system.assemble_jacobian()
    warm = merged_matrix(system)
    assert same_pattern(cold, warm)
    cold.axpy(-1.0, warm)
    assert cold.norm() > 1e-3 * warm.norm()  # the values did change
    destroy(cold, warm)


def test_the_merged_values_of_a_new_state_written_in_place_are_the_new_matrix(comm, monkeypatch):
    """The monolithic solve plans the merged matrix's pattern once (:class:`MergePlan`) and
    scatters a new Newton step's block values into it. Cold and warm states of the squeezed
    Joule bars: the plan made at the cold state takes the warm values (one digest on every
    rank), and the cold matrix with them written in is the matrix of a plan made at the warm
    state, entry for entry: the scatter is the sort it replaces (the master rows' parts
    summed in the same order: equal to the bit). A block with another pattern is refused.
    """
    system = make_system(squeezed_joule_bars(bars_scene(8, 2, comm=comm)))
    system.reset({"temperature": 300.0})
    system.assemble_jacobian()
    plan = MergePlan(system)
    cold = plan.values(system)
    K = plan.matrix(comm, cold)
    sc.solve(system, sc.Monolithic(), rtol=1e-10)
    system.assemble_jacobian()
    warm = plan.values(system)
    assert warm is not None and len(plan.pattern) == comm.size
    assert not np.array_equal(warm, cold)  # the values did change
    plan.write(K, warm)
    fresh = MergePlan(system)
    assert fresh.pattern == plan.pattern
    expected = fresh.matrix(comm, fresh.values(system))
    a, b = K.getValuesCSR(), expected.getValuesCSR()
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    # one entry fewer in rank 0's B_k P_k rows: every rank refuses the plan
    original = merged._to_masters

    def fewer(*args):
        rows, columns, values = original(*args)
        if comm.rank == 0 and rows.size:
            return rows[:-1], columns[:-1], values[:-1]
        return rows, columns, values

    monkeypatch.setattr(merged, "_to_masters", fewer)
    assert plan.values(system) is None
    destroy(K, expected)


def test_entries_spliced_by_chunks_are_numpys_insert(monkeypatch):
    """The whole-matrix build's insertion (moved by chunks, not by an index of every entry)
    is ``np.insert``: repeated and boundary positions, chunks shorter than the arrays."""
    monkeypatch.setattr(merged, "_CHUNK", 7)
    rng = np.random.default_rng(3)
    a, b = np.arange(50, dtype=np.int32), rng.random(50)
    at = np.sort(rng.integers(0, 51, size=20))
    at[:3] = 0  # before the first entry, repeated
    at[-2:] = 50  # after the last
    values = (100 + np.arange(20)).astype(np.int32), rng.random(20)
    got = merged._spliced((a, b), at, values)
    assert np.array_equal(got[0], np.insert(a, at, values[0]))
    assert np.array_equal(got[1], np.insert(b, at, values[1]))


def test_the_merged_matrix_restricted_to_rows_is_its_submatrix(comm, monkeypatch):
    """Built on some rows alone (the sparse strip's), the merged matrix is the whole one's
    submatrix on those rows and columns: the same stored entries, their values to the
    round-off of summing an entry's parts in another order (scipy's sort of duplicates
    against the plan's sum in the entries' order). Every third row of each rank (masters
    included on rank 0), warm state. Its plan (:class:`RestrictedPlan`), made at the cold
    state, takes the warm values: the matrix of a plan made at the warm state, to the bit;
    a block with another pattern is refused.
    """
    system = make_system(squeezed_joule_bars(bars_scene(8, 2, comm=comm)))
    system.reset({"temperature": 300.0})
    system.assemble_jacobian()
    local = system.local_size  # this rank's rows of the merged matrix, from first
    first = comm.exscan(local) or 0
    rows = np.arange(first, first + local, 3, dtype=np.int64)
    cold = merged.plan(system, rows)
    assert isinstance(cold, merged.RestrictedPlan)
    K = cold.matrix(comm, cold.values(system))
    sc.solve(system, sc.Monolithic(), rtol=1e-10)
    system.assemble_jacobian()
    warm = cold.values(system)
    assert warm is not None
    cold.write(K, warm)
    whole = merged_matrix(system)
    assert whole.getOwnershipRange() == (first, first + local)
    index = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=comm)
    expected = whole.createSubMatrix(index, index)
    restricted = merged_matrix(system, rows)
    assert restricted.getSize() == expected.getSize()
    assert restricted.getOwnershipRange() == expected.getOwnershipRange()
    a, b = restricted.getValuesCSR(), expected.getValuesCSR()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert a[2].size > 0 and np.any(a[2] != 0.0)
    # an entry sums a few parts (the body's, the links'), each of about the row's largest
    # entry at most: in another order it moves by a few ε of that (measured 6.7e-6 ε serially,
    # where parts cancel to nearly zero; 0 on 2 ranks)
    scale = np.maximum.reduceat(np.abs(b[2]), b[0][:-1]) if b[2].size else b[2]
    scale = np.repeat(np.where(np.diff(b[0]) > 0, scale, 0.0), np.diff(b[0]))
    assert np.all(np.abs(a[2] - b[2]) <= 4 * np.finfo(float).eps * scale)
    c = K.getValuesCSR()
    assert all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))
    original = merged._restricted

    def fewer(*args):  # one kept entry fewer on rank 0: every rank refuses
        parts = original(*args)
        if comm.rank == 0 and parts and parts[0][0].size:
            parts[0] = tuple(x[:-1] for x in parts[0])
        return parts

    monkeypatch.setattr(merged, "_restricted", fewer)
    assert cold.values(system) is None
    destroy(whole, index, expected, restricted, K)


def test_the_merged_matrix_of_a_symmetric_system_with_fixed_slaves_is_symmetric_definite(comm):
    """The masters' columns of fixed DOFs are left out as the fixed rows' entries are, so the
    merged matrix keeps the system's symmetry: GAMG and CG need it. Two plates, linear
    thermal, the top's fixed temperature reaching an end node of the contact on each side.
    With those columns kept it was 0.146 of its norm away from symmetric, and its symmetric
    part had an eigenvalue of −3.3 (measured): an indefinite matrix for CG.
    """
    scene = two_plates_scene(6, 5, quads=False, comm=comm)
    base = two_plates(scene, h=1e2, k_b=3.0).problem
    conditions = [*base.conditions, sc.Temperature("top", 2.0)]
    system = make_system(sc.Problem(scene, base.materials, base.contacts, conditions))
    assert system.symmetric
    fixed_slaves = sum(len(body.fixed_kept) for body in system.bodies.values())
    assert comm.allreduce(fixed_slaves) > 0
    system.assemble_jacobian()
    K = merged_matrix(system)
    transposed = K.duplicate(copy=True)
    transposed.transpose()
    transposed.axpy(-1.0, K)
    # each entry and its mirror are sums of the same parts (measured: equal to the bit);
    # a few ε of the norm allow another order of summation
    assert transposed.norm() <= 10 * np.finfo(float).eps * K.norm()
    indptr, indices, values = K.getValuesCSR()
    first = K.getOwnershipRange()[0]
    rows = first + np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    parts = comm.gather((rows, indices, values), root=0)
    if comm.rank == 0:
        r, c, v = (np.concatenate([part[i] for part in parts]) for i in range(3))
        dense = np.zeros(K.getSize())
        np.add.at(dense, (r, c), v)
        eigenvalues = np.linalg.eigvalsh(dense)
        # definite beyond round-off (a computed eigenvalue moves by about ε ‖K‖): measured
        # 0.18 of 115, where the columns kept gave −3.3
        assert eigenvalues[0] > 1e6 * np.finfo(float).eps * eigenvalues[-1]
    destroy(K, transposed)


def test_a_pattern_is_its_entries_not_their_count():
    def matrix(columns):  # 2 × 2, one stored entry per row
        csr = ([0, 1, 2], columns, [1.0, 1.0])
        return PETSc.Mat().createAIJ(size=(2, 2), csr=csr, comm=MPI.COMM_SELF)

    a, b, c = matrix([0, 1]), matrix([1, 1]), matrix([0, 1])
    assert not same_pattern(a, b)
    assert same_pattern(a, c)
    destroy(a, b, c)


def test_a_nonlinear_bulk_is_factorised_every_step(comm):
    problem = squeezed_joule_bars(bars_scene(8, 2, comm=comm))
    result, _, difference = newton_and_reference(problem, rtol=1e-12)
    assert result.factorisations == 2 * result.iterations  # k(T), σ(T): two bars a step
    assert max(difference.values()) < 1e-8  # measured 1.8e-16


def test_modified_newton_reuses_the_jacobian(comm):
    """``lag_jacobian=2``: the Jacobian (and the bodies' dense blocks) every other step."""
    problem = hot_squeezed_bars(bars_scene(8, 2, comm=comm))
    full, _, _ = newton_and_reference(problem, rtol=1e-12)
    # backtracking: the lagged Jacobian's full first step overshoots to NaN, and steps
    # limited in T take 25 (measured; bt: 7), so "auto" would test the limiter, not the lag
    lagged, _, difference = newton_and_reference(
        problem, rtol=1e-12, lag_jacobian=2, line_search="bt"
    )
    # built at steps 0, 2, 4, …
    assert lagged.jacobians == -(-lagged.iterations // 2) < full.jacobians
    assert max(difference.values()) < 1e-8  # the same solution: measured 1.2e-14


# -- rank groups for the coupled problem -----------------------------------------------------


def test_coupled_rank_groups_equal_serial(comm):
    """placement="groups": each block Newton-solved by its own ranks; the serial numbers."""
    grouped = blocks_row_scene(4, 0.1, comm=comm, placement="groups")
    system = make_system(squeezed_row(grouped))
    system.reset({"temperature": 300.0})
    result = sc.solve(system, rtol=1e-12)
    serial = make_system(squeezed_row(blocks_row_scene(4, 0.1, comm=MPI.COMM_SELF)))
    serial.reset({"temperature": 300.0})
    expected = sc.solve(serial, rtol=1e-12)
    assert result.iterations == expected.iterations
    # A round ends where the interface Krylov meets its own tolerance, by a factor that its
    # iterates set, and they differ in round-off between the two orders of summation: a
    # step's last round can land on either side of the step's threshold (step 9, measured on
    # one machine: 1.2e-9 grouped, 3.6e-9 serial, one round more; equal on the one before),
    # so a step's rounds may differ by one; the Newton path must not.
    pairs = zip(result.history, expected.history, strict=True)
    rounds = [(s.inner_rounds, t.inner_rounds) for s, t in pairs]
    assert all(abs(a - b) <= 1 for a, b in rounds), rounds
    worst = 0.0
    for field, component in FIELDS_3D:
        reference = NodalReference(*field_values(serial, field, component))
        spaces = field_values(system, field, component)[0]
        worst = max(worst, error_against(system, reference.at(spaces), field, component))
    # the same solves summed in another order: measured 1.6e-15 on 2 ranks
    assert worst <= 1e-12


def test_a_thin_body_is_factorised_whole(comm, monkeypatch):
    """Above SCHUR_SMALL contact DOFs, a body whose contact DOFs are more than SCHUR_FRACTION
    of its DOFs gets no dense Schur block (the cast iron, a thin layer between contacts)."""
    monkeypatch.setattr(schur_module, "SCHUR_SMALL", 0)  # the test mesh's bodies are small
    scene = cathode_slot_scene(0.06, 0.03, comm=comm)
    with sc.System(cathode_slot(scene)) as system:
        shares = {n: len(b.kept) / b.size for n, b in system.bodies.items()}
        for name, body in system.bodies.items():
            assert body.schur == (shares[name] <= schur_module.SCHUR_FRACTION), shares
        if "cast_iron" in shares:
            assert shares["cast_iron"] > 0.5 and not system.bodies["cast_iron"].schur
        if "block" in shares:
            assert system.bodies["block"].schur


def test_a_3d_schur_block_dearer_than_the_factorisation_is_not_kept():
    """Above SCHUR_SMALL, a 3D body within the share keeps a Schur block only where its dense
    algebra (4.7 n³ flops) costs at most its sparse factorisation (8 N²); 2D as before.

    The collector bar slot's block at 34,510 DOFs: 19,140 DOFs, 2,620 on contacts (14 %),
    4.7 · 2620³ = 8.45e10 against 8 · 19140² = 2.93e9: factorised whole (a Newton from 300
    K in 176 s instead of 326 s). The same contact on 200,000 DOFs: 3.2e11 ≥ 8.45e10."""
    assert schur_module.condensation(2620, 19_140, 3) == ""
    assert schur_module.condensation(2620, 19_140, 2) == "block"
    assert schur_module.condensation(2620, 200_000, 3) == "block"
    # the threshold: 4.7 n³ = 8 N² at N = (4.7 / 8)^½ n^1.5 = 102,791 for n = 2620
    assert schur_module.condensation(2620, 102_700, 3) == ""
    assert schur_module.condensation(2620, 102_900, 3) == "block"
    # at most SCHUR_SMALL contact DOFs, a Schur block in 3D too (cheap: under 0.1 s)
    assert schur_module.condensation(schur_module.SCHUR_SMALL, 4000, 3) == "block"


# -- nested iteration: a coarse mesh's solution as the fine mesh's initial guess ------------


def _linear_field(field: str, x: np.ndarray) -> np.ndarray:
    """A field linear in x [m] (nodes × 3): P1 interpolates it exactly. Displacement: 3 columns."""
    if field == "temperature":
        return 300.0 + 100.0 * x[:, 0] + 50.0 * x[:, 1]
    if field == "potential":
        return 0.01 + 0.02 * x[:, 0] - 0.03 * x[:, 1]
    return 1e-4 * np.outer(x[:, 0] + 2.0 * x[:, 1], [1.0, 2.0, 3.0])


def test_a_state_linear_in_space_is_interpolated_exactly(comm):
    """System.interpolate on the 2D cathode slot (T, φ, u): body fields linear in space are
    reproduced at every node of the finer mesh, and each master value, the mean of its two
    bodies' traces, is the field at its node."""
    coarse = make_system(cathode_slot(cathode_slot_scene(0.06, 0.03, comm=comm)))
    placement = coarse.problem.scene  # under mpiexec, each body on the same rank group
    fine = make_system(
        cathode_slot(cathode_slot_scene(0.03, 0.015, comm=comm, placement=placement))
    )
    dim = 2
    for body in coarse.bodies.values():
        for field in coarse.problem.fields:
            V, dofs = body.forms.collapsed(field)
            values = _linear_field(field, V.tabulate_dof_coordinates())
            body.U.x.array[dofs] = values[:, :dim].ravel() if values.ndim == 2 else values
    fine.interpolate(coarse)
    for field in fine.problem.fields:
        worst, scale = 0.0, 0.0
        for body in fine.bodies.values():
            V, dofs = body.forms.collapsed(field)
            values = _linear_field(field, V.tabulate_dof_coordinates())
            expected = values[:, :dim].ravel() if values.ndim == 2 else values
            worst = max(worst, np.abs(body.U.x.array[dofs] - expected).max(initial=0.0))
            scale = max(scale, np.abs(expected).max(initial=0.0))
        worst = comm.allreduce(worst, op=MPI.MAX) / comm.allreduce(scale, op=MPI.MAX)
        # the reference-cell pull-back of an affine map and the P1 basis: round-off of a
        # few operations on values of order 1 (1e-12 leaves a margin of 1e3 over 1e-15)
        assert worst < 1e-12, field
    for k, layer in fine.layers.items():
        for c, (field, component) in enumerate(layer.channels):
            values = np.atleast_2d(_linear_field(field, layer.coordinates).T)[component or 0]
            channel = slice(c * layer.nodes, (c + 1) * layer.nodes)
            expected = values * fine.active[k][channel]
            given = fine.masters[k][channel]
            # the mean of two such traces: the same round-off, relative to the channel
            assert np.abs(given - expected).max() <= 1e-12 * np.abs(values).max(), (k, c)


def test_the_solution_of_a_coarse_mesh_starts_newton_near_the_fine_one(comm):
    """Nested iteration on the 2D cathode slot with mechanics: Newton on the fine mesh from
    the coarse mesh's solution converges to the cold start's solution, in fewer steps."""
    coarse = make_system(cathode_slot(cathode_slot_scene(0.06, 0.03, comm=comm)))
    coarse.reset({"temperature": 300.0})
    sc.solve(coarse, rtol=1e-10)
    problem = cathode_slot(
        cathode_slot_scene(0.03, 0.015, comm=comm, placement=coarse.problem.scene)
    )
    fine = make_system(problem)
    fine.reset({"temperature": 300.0})
    cold = sc.solve(fine, sc.Monolithic(), rtol=1e-10)
    reference = fine.state()
    fine.interpolate(coarse)
    nested = sc.solve(fine, rtol=1e-10)
    state = fine.state()
    difference = fine.difference(state, reference)
    destroy(state, reference)
    # both stop at rtol 1e-10 on quadratically converging iterates, as the cold-start tests
    # above (measured 3.6e-14 apart): 1e-8 is the issues' agreement
    assert max(difference.values()) < 1e-8
    # measured 3 steps from the coarse solution (860 DOFs to 1,904), 6 from 300 K
    assert nested.iterations < cold.iterations


def test_a_mesh_of_another_geometry_or_placement_is_refused(comm):
    """Nodes outside the other mesh by more than its largest cell: no silent extrapolation.
    A scene placed like one of other bodies; under mpiexec, bodies on other rank groups."""
    short = two_plates_scene(2, 2, comm=comm)
    long = two_plates_scene(2, 2, length=2.0, comm=comm, placement=short)
    given = make_system(two_plates(short, h=1.0).problem)
    with pytest.raises(ValueError, match=r"plate_A.*outside the other mesh"):
        make_system(two_plates(long, h=1.0).problem).interpolate(given)
    with pytest.raises(ValueError, match=r"placed like a scene of other bodies"):
        cathode_slot_scene(0.06, 0.03, comm=comm, placement=short)
    if comm.size > 1:  # the plates on a rank group each, and both on every rank
        shared = make_system(
            two_plates(two_plates_scene(2, 2, comm=comm, placement="shared"), h=1.0).problem
        )
        with pytest.raises(ValueError, match="other rank groups"):
            shared.interpolate(given)
