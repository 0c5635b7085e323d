"""Newton outside (PETSc SNES), any linear solver of the whole system inside.

SNES drives Newton's method on the whole system of :mod:`~subdomain_contact.system`, with its
line search (full steps by default, backtracking on request) and its function and Jacobian
callbacks. Each linearised system ``J y = F`` is solved by a linear solver with ``setup`` and
``solve`` under ``ksp_type preonly``: the subdomain iteration
(:class:`~subdomain_contact.subdomain.Subdomains`) or a direct solve of the merged Jacobian
(:class:`~subdomain_contact.monolithic.Monolithic`, the reference). Both run the same Newton on
the same discrete problem, so their results agree to solver precision.

A linear problem (its Jacobian independent of the state, e.g. conduction with constant laws)
takes one Newton step whose inner solve goes to ``rtol`` itself. Otherwise the inner solve
stops when each field's master residual is below ``η ‖F_f‖``, with the forcing term
``η = min(FORCING, P)``, ``P = max_g ‖F_g‖/scale_g`` the slowest field's progress: tight enough
that the inexact steps follow the exact Newton path through the contacts' states, and tighter
near the solution, which keeps Newton's quadratic convergence.

Where a body is solved iteratively, ``η`` is at most :data:`FORCING_ITERATIVE`, and a field is
asked for ``η max(‖F_f‖, P scale_f)``: the inexact Newton condition in the norm scaled field by
field, which asks a field ahead of the others (the potential, often) for ``η`` of the slowest
one's progress, not of its own small residual. That was round-off for bodies solved to a
relative tolerance (the row of four 3D blocks at 219k DOFs on 2 ranks: a potential target of
1e-14 of its scale, the interface Krylov stalled and Newton failed; now 13 steps). Factorised
bodies keep the field's own residual: the scaled rule moved the two routes of the preheated
slice with mechanics 6e-8 apart (2 ranks), where they agree to 1e-10.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.subdomain import (
    InterfaceResult,
    SubdomainConvergenceError,
    Subdomains,
    Tolerance,
)
from subdomain_contact.system import System

__all__ = [
    "AUTO",
    "EXPONENTIAL",
    "FORCING",
    "FORCING_ITERATIVE",
    "HALVINGS",
    "MAX_IT",
    "MAX_TEMPERATURE_STEP",
    "PROPORTIONAL",
    "RUNAWAY",
    "NewtonConvergenceError",
    "NewtonStep",
    "Result",
    "RunawayStepError",
    "solve",
]

_REASONS = {
    getattr(PETSc.SNES.ConvergedReason, n): n
    for n in dir(PETSc.SNES.ConvergedReason)
    if n.isupper()
}


@dataclass
class NewtonStep:
    """One Newton iterate: its residual and the inner solve that led to it.

    Attributes:
        iteration: Newton iteration (0: the initial state).
        residual: 2-norm of the whole residual.
        fields: 2-norm of each field's residual [W, A, N].
        inner_rounds: Rounds of body solves of the linear solve that produced this iterate
            (0 at iteration 0; 1 for a direct solve).
        step: The Newton step that produced this iterate relative to the state, the largest
            over the fields of ``max |δx_f| / max |x_f|`` (0 at iteration 0).
        halvings: Times that step was halved (see :data:`RUNAWAY`).
    """

    iteration: int
    residual: float
    fields: dict[str, float]
    inner_rounds: int
    step: float = 0.0
    halvings: int = 0


@dataclass
class Result:
    """Outcome of a solve: Newton's history, each inner solve, the reason and the time.

    Attributes:
        history: One :class:`NewtonStep` per iterate.
        inner: The inner solve of each Newton step (None for a direct solve).
        reason: SNES's reason.
        seconds: Wall time [s], set-up included.
        scale: Each field's residual scale [W, A, N] that the convergence test used.
        factorisations: Sparse factorisations made in this solve: the bodies' (subdomain
            iteration) or the merged matrix's (monolithic).
        jacobians: Jacobians assembled (and handed to the linear solver's ``setup``).
        line_search: The line search that converged.
        shortened: Newton steps that the ``"limited"`` line search shortened.
        fallbacks: Bodies' matrices whose Krylov solve failed and that MUMPS factorised
            instead, or took at once after such failures in a row (``body.FAILURES_IN_A_ROW``),
            whose single-precision sweep fell short and was factorised again in
            double (these among the factorisations), or whose sweep had no room to be
            factorised again and that AMG solves since.
    """

    history: list[NewtonStep] = field(default_factory=list)
    inner: list[InterfaceResult | None] = field(default_factory=list)
    reason: str = ""
    seconds: float = 0.0
    scale: dict[str, float] = field(default_factory=dict)
    factorisations: int = 0
    jacobians: int = 0
    line_search: str = ""
    shortened: int = 0
    fallbacks: int = 0

    @property
    def iterations(self) -> int:
        """Newton iterations taken."""
        return self.history[-1].iteration if self.history else 0

    @property
    def halved(self) -> int:
        """Halvings of full steps that ran away (see :data:`RUNAWAY`)."""
        return sum(s.halvings for s in self.history)

    @property
    def rounds(self) -> int:
        """Rounds of body solves over every Newton step."""
        return sum(r.rounds for r in self.inner if r is not None)

    def relative_residuals(self) -> npt.NDArray[np.float64]:
        """Newton's own measure per iterate: ``max_f ‖F_f‖ / scale_f`` (fields never mix)."""
        fields = [f for f, value in self.scale.items() if value > 0]
        return np.array([max(s.fields[f] / self.scale[f] for f in fields) for s in self.history])

    def table(self) -> str:
        """The history as text lines, one per iterate."""
        return "\n".join(
            f"  {s.iteration:3d}  |F| = {s.residual:.3e}  "
            + "  ".join(f"{n} {v:.2e}" for n, v in s.fields.items())
            + f"  inner rounds {s.inner_rounds}  step {s.step:.1e}"
            + (f"  halvings {s.halvings}" if s.halvings else "")
            for s in self.history
        )


class NewtonConvergenceError(RuntimeError):
    """Newton did not converge; ``result`` holds its history."""

    def __init__(self, message: str, result: Result) -> None:
        super().__init__(message)
        self.result = result


class RunawayStepError(RuntimeError):
    """A full Newton step lands far out of equilibrium however it is halved."""


class _Callbacks:
    """SNES callbacks: residual and Jacobian, product and inner solve as Python contexts."""

    def __init__(self, system: System, linear, rtol: float, max_it: int, monitor, lag: int) -> None:
        self.system, self.linear, self.rtol, self.max_it = system, linear, rtol, max_it
        self.monitor, self.lag, self.jacobians = monitor, lag, 0
        self.announce: str | None = None  # the line search's name, to print a line per iterate
        self.start = time.perf_counter()
        self.max_step: float | None = None  # [K]
        self.result = Result()
        self.scale: dict[str, float] = {}
        iterative = any(b.iterative for b in system.bodies.values())
        iterative = system.comm.allreduce(iterative, op=MPI.LOR)  # bodies on rank groups
        self.forcing = FORCING_ITERATIVE if iterative else FORCING
        self.scaled = iterative  # the forcing in the scaled norm (module docstring)
        self.eta = self.forcing
        self.pending: InterfaceResult | None = None
        self.pending_rounds = 0
        self.pending_halvings = 0
        self.inner_converged = False
        self.failure: Exception | None = None
        self.snes: PETSc.SNES | None = None
        self.direction: dict[str, float] = {}  # max |y_f| of the last full Newton step
        self.state: dict[str, float] = {}  # max |x_f| where it was taken
        self.relative = np.inf  # max_f ‖F_f‖/scale_f at the current iterate
        self.trial: tuple[PETSc.Vec, PETSc.Vec] | None = None  # (x − y, F(x − y))

    def function(self, snes, x, f) -> None:
        def evaluate():
            self.system.set_state(x)
            if self.trial is not None and self.trial[0].equal(x):
                self.trial[1].copy(f)  # the safeguard's, at the state the step lands on
            else:
                self.system.residual(f)
            self.drop_trial()

        self._guard(evaluate)

    def drop_trial(self) -> None:
        """Destroy the safeguard's last trial state and residual."""
        if self.trial is not None:
            for vec in self.trial:
                vec.destroy()
            self.trial = None

    def jacobian(self, snes, x, J, P) -> None:
        def assemble():
            if self.jacobians % self.lag == 0:  # modified Newton keeps the last one
                self.system.set_state(x)
                self.system.assemble_jacobian()
                self.linear.setup(self.system)
                self.result.jacobians += 1
            self.jacobians += 1

        self._guard(assemble)

    def mult(self, mat, x, y) -> None:
        self._guard(lambda: self.system.mult(x, y))

    def apply(self, pc, b, y) -> None:
        def inner():
            if self.system.is_linear:
                tolerance = Tolerance(rtol=self.rtol)
            else:
                norms = self.system.field_norms(b)
                scale = self.scale
                # iterative bodies: a field ahead of the slowest one is asked for η of the
                # slowest one's progress, not η of its own small residual
                pace = max(self.ratios(norms), default=0.0) if self.scaled else 0.0
                floor = {f: 1e-3 * self.rtol * scale[f] for f in norms}
                atol = {
                    f: max(self.eta * max(v, pace * scale[f]), floor[f]) for f, v in norms.items()
                }
                tolerance = Tolerance(atol=atol)
            delta, inner = self.linear.solve(b.array_r.copy(), tolerance)
            y.array[:] = delta
            self.direction = self.system.field_max_norms(y)
            self.state = self.system.field_max_norms(self.snes.getSolution())
            self.pending = inner
            self.pending_rounds += inner.rounds if inner is not None else 1
            self.inner_converged = inner is None or inner.converged

        self._guard(inner)

    def precheck(self, x, y) -> None:
        """The full steps' pre-check: :meth:`limit`, then :meth:`safeguard`."""
        self._guard(lambda: (self.limit(y), self.safeguard(x, y)))

    def limit(self, y) -> None:
        """No temperature moves more than ``max_step`` (``"limited"``).

        The step ``y`` is shortened, all fields alike (its direction kept). Not for a linear
        problem: its one step is exact.
        """
        if self.max_step is None or self.system.is_linear or "temperature" not in self.direction:
            return
        largest = self.direction["temperature"]  # max |y_T| of the step just solved for
        if largest > self.max_step:
            y.scale(self.max_step / largest)
            self.result.shortened += 1

    def safeguard(self, x, y) -> None:
        """Halve a full step that runs away (see :data:`RUNAWAY`); fail if that is not enough.

        The residual at ``x − y`` is evaluated; while ``max_f ‖F_f‖/scale_f`` there is above
        both :data:`RUNAWAY` and the current iterate's, ``y`` is halved, at most
        :data:`HALVINGS` times, as long as each halving lowers the landing as an exponential's
        overshoot does (:data:`EXPONENTIAL`); a landing that the first halving only halves is
        a contact's new status, and the full step is kept (:data:`PROPORTIONAL`). The last
        residual is kept for the line search, which evaluates it at the same state next. Not
        for a linear problem.

        Raises:
            RunawayStepError: The step still lands above after the last halving, or a
                halving lowered the landing too little.
        """
        if self.system.is_linear:
            return
        self.drop_trial()
        self.trial = w, f = x.duplicate(), x.duplicate()  # kept for the line search
        bound = max(RUNAWAY, self.relative)
        previous = np.inf  # ln(landing / bound) before the last halving
        full = np.inf  # the full step's landing
        for halvings in range(HALVINGS + 1):
            if halvings:
                y.scale(0.5)
                self.pending_halvings += 1
            x.copy(w)
            w.axpy(-1.0, y)
            self.system.set_state(w)
            self.system.residual(f)
            landed = max(self.ratios(self.system.field_norms(f)), default=0.0)
            if np.isfinite(landed) and landed <= bound:
                return
            if halvings == 1 and np.isfinite(landed) and full <= PROPORTIONAL * landed:
                y.scale(2.0)  # a penalty's new status: the full step
                self.pending_halvings -= 1
                x.copy(w)
                w.axpy(-1.0, y)
                self.system.set_state(w)
                self.system.residual(f)
                return
            if halvings == 0:
                full = landed
            excess = np.log(landed / bound)
            if np.isfinite(previous) and excess > EXPONENTIAL * previous:
                break  # not an exponential's overshoot: a climb Newton's model does not reach
            previous = excess
        self.drop_trial()
        raise RunawayStepError(
            f"the step from a residual of {self.relative:.1e} of its scale lands at "
            f"{landed:.1e} when cut to 1/{2**halvings}: Newton's linear model does not hold "
            "that far (a contact law's exponential, a Joule runaway)"
        )

    def ratios(self, norms: dict[str, float]) -> list[float]:
        """``‖F_f‖/scale_f`` of each field with a scale."""
        return [v / self.scale[n] for n, v in norms.items() if self.scale[n] > 0]

    def converged(self, snes, it, norms) -> int:
        reasons = PETSc.SNES.ConvergedReason
        f = snes.getFunction()[0]
        fields = self.system.field_norms(f)
        total = float(np.sqrt(sum(v**2 for v in fields.values())))
        step, full = 0.0, False
        if it > 0:
            applied = self.system.field_max_norms(snes.getSolutionUpdate())
            step = max(_ratio(self.direction[n], self.state[n]) for n in fields)
            full = all(applied[n] >= 0.999 * self.direction[n] for n in fields)
        self.result.history.append(
            NewtonStep(it, total, fields, self.pending_rounds, step, self.pending_halvings)
        )
        if it > 0:
            self.result.inner.append(self.pending)
        self.pending, self.pending_rounds, self.pending_halvings = None, 0, 0
        if self.monitor is not None:
            self.system.set_state(snes.getSolution())
            self.monitor(it)
        if not np.isfinite(total):
            return reasons.DIVERGED_FNORM_NAN
        if it == 0:  # the scale: the cold state's residual or the initial one, the larger
            for name, value in fields.items():
                self.scale[name] = max(self.scale.get(name, 0.0), value)
        progress = self.ratios(fields)
        self.relative = max(progress, default=0.0)
        if self.announce is not None:
            self._print(self.result.history[-1], self.relative)
        if self.system.is_linear and it >= 1 and self.inner_converged:
            return reasons.CONVERGED_FNORM_RELATIVE  # one exact step: the inner solve's rtol
        # the slowest field sets the pace
        self.eta = min(self.forcing, max(progress, default=self.forcing))
        if all(v <= self.rtol * self.scale[n] for n, v in fields.items()):
            return reasons.CONVERGED_FNORM_RELATIVE
        if full and self.inner_converged and step <= STEP_RTOL:
            return reasons.CONVERGED_SNORM_RELATIVE
        if it >= self.max_it:
            return reasons.DIVERGED_MAX_IT
        return reasons.ITERATING

    def _print(self, step: NewtonStep, relative: float) -> None:
        """One progress line (rank 0): the iterate, its residual relative to the scale."""
        fallbacks = _fallbacks(self.system)  # collective
        inner = self.result.inner[-1] if step.iteration and self.result.inner else None
        short = getattr(inner, "short_by", 0.0)  # the monolithic route's is None
        if self.system.comm.rank == 0:
            print(
                f"Newton ({self.announce}) {step.iteration:3d}: max_f |F_f|/scale_f "
                f"{relative:.2e}, inner rounds {step.inner_rounds}, step {step.step:.1e}"
                + (f", halvings {step.halvings}" if step.halvings else "")
                + (f", inner solve short by {short:.1f} times" if short else "")
                + (f", body fallbacks {fallbacks}" if fallbacks else "")
                + f", {time.perf_counter() - self.start:.0f} s",
                flush=True,
            )

    def _guard(self, action) -> None:
        """Run a callback; keep its exception for the error message (SNES only sees a code)."""
        try:
            action()
        except Exception as error:
            self.failure = error
            raise


#: A full Newton step below this, relative to the state in every field, ends Newton: the
#: next error is about C·step² (quadratic convergence), at round-off for any C‖x‖ < 1e2.
#: For stiff contacts this is the only test that can end it: their terms, h̄ (T_s − T_m)
#: with h̄ of 1e12 times the bulk's stiffness, leave a residual of h̄ ε |T| however exact
#: the state (the monolithic Newton's too).
STEP_RTOL = 1e-9

#: The largest temperature change [K] of one step of the ``"limited"`` line search: full
#: steps, each shortened (all fields alike, its direction kept) when its temperature part is
#: larger. Laws of T are tables, linear between points about 100 K apart (the Eurocode and
#: steel-grade tables of ``data/``): Newton's linear model of them holds over such a step but
#: for one kink, whereas a full step from a cold start (the collector bar slot at 300 K, its
#: top at 1233 K) moves temperatures by thousands of kelvin into states where the resistivity
#: of steel, 0.14 to 1.13 µΩ m over 900 K, turns the Joule heat into a runaway, and Newton
#: diverges on every route. Measured on that slot (17k DOFs): full steps diverge; limited to
#: 300 K, Newton creeps (30 steps, not converged); to 100 K it converges in 18 steps
#: (constant contact resistances) and 23 (pressure-dependent law) on both routes. Not the
#: first attempt: where full steps converge, shortened ones may cycle through the contacts'
#: states (the squeezed Joule bars: full steps take 9, limited ones cycle with period 3).
MAX_TEMPERATURE_STEP = 100.0

#: A full step (``"basic"``, ``"limited"``) that lands where ``max_f ‖F_f‖/scale_f``
#: exceeds this and the current iterate's is halved while the landing falls as an
#: exponential's (:data:`EXPONENTIAL`), at most :data:`HALVINGS` times; else the attempt
#: fails. 1e3 times the loads' residual is far outside Newton's region:
#: converging full steps land at most at 2.8 (the row of four 3D blocks, 6k DOFs) and 34
#: (the same row at 1.01M DOFs), runaways at 1e16 and beyond (that row's step 2 at 1.01M: an
#: exponential closure overshot by tens of δ₀ lands at e^(overshoot/δ₀)). The bound is not
#: free: Newton comes back down an exponential by one δ₀, a factor e of the residual, per
#: step, so a step that lands at R costs about ln R steps (measured at 1.01M: from 947 to 6
#: in 5 steps).
RUNAWAY = 1e3

#: A halving goes on only while the landing falls as an exponential's does: its excess
#: ``ln(R/B)`` over the bound ``B = max(RUNAWAY, current)`` at most this fraction of the one
#: before. A closure overshot by n δ₀ lands at about ``B e^(n - d)``, ``d ≥ 0`` (its residual
#: at no overshoot is within the bound), and half the step overshoots by less than n/2: the
#: excess falls by more than half. A residual growing as a power p of the step falls by
#: ``p ln 2`` only, a ratio above 2/3 for p ≤ 2 from an excess of 4.2 (R = 64 B) up: that
#: climb is left to the ``"limited"`` attempt at once (measured on the collector bar slot
#: from 300 K, 17k DOFs: from step 4 its landings fell by a factor of about 2.6 per halving,
#: 1.3e5, 4.8e4, 1.7e4, ..., an excess ratio of 0.8, and, allowed 10 halvings without this
#: test, its full steps were cut 5 or 6 times at every step, the residual held near 1e3 of
#: its scale for 50 steps; the row of four blocks at 1.01M DOFs: 1.1e16, 6.0e4, 0.53 at
#: step 2, a ratio of 0.14).
EXPONENTIAL = 2 / 3

#: A landing that the first halving lowers by at most this factor is proportional to the
#: step, as a contact penalty's is when Newton's step changes a contact's status (closed
#: where the Jacobian had it open): the full step is kept, and Newton's next step, with the
#: new status, corrects it (the semi-smooth Newton of unilateral contact). Halving only
#: delays that. 2 for a penalty from zero gaps; up to 2^(1/4) more for gaps closing on the
#: way; a power p ≥ 1.25 of the step (the collector bar slot's 2.6 per halving) is halved
#: as before. Measured: the preheat slice with its mechanics, its first step from the
#: cold cell: 2.37e4, 1.19e4, 5.93e3, ... of the scale (a factor 1.99-2.00 per halving).
PROPORTIONAL = 2**1.25

#: The most halvings of one step. The largest landing the residual's norm measures is about
#: 1e154 (its square overflows beyond): an overshoot of ln(1e154) = 354 δ₀, which 6 halvings
#: bring to 5.5 δ₀, below ln :data:`RUNAWAY` = 6.9; one more for a landing beyond measure
#: (an infinite norm), one spare. Measured: the row of four 3D blocks at 1.01M DOFs needed two
#: (steps 2 and 9 of 26, one at steps 4 and 6) in one cold start, and more than two in
#: another, whose step 12 overflowed; the squeezed bars of the tests with δ₀ = 0.5 µm one, at
#: 7 of 24 steps.
HALVINGS = 8

#: The largest forcing term η of an inexact inner solve (its residual relative to Newton's).
#: Newton on unilateral contacts is semi-smooth: its Jacobian jumps where a node's closure
#: changes sign, and a step off by η can put a node near closure 0 on the other side, so that
#: the inexact Newton takes another path through the contacts' states. Measured on the
#: collector bar slot (65k DOFs, constant resistances, from 300 K): with η ≤ 1e-4 the subdomain
#: Newton left the monolithic one's path at step 10 and cycled through contact states for 50
#: steps; with η ≤ 1e-8 it takes the same 18 steps, at 8.8 s a step against 8.4 (the
#: interface Krylov iterations cost little beside the factorisations).
FORCING = 1e-8

#: The largest forcing term where a body is solved iteratively (Krylov + AMG): its own
#: solves stop at a relative residual of their own, and an inner solve asked for 1e-8 of
#: Newton's residual drove them into Krylov breakdown (the iterative-bodies Newton of the
#: tests on 2 ranks, GMRES + GAMG, reason -5 after 60 iterations); 1e-4 converges there.
FORCING_ITERATIVE = 1e-4

#: Newton iterations allowed per attempt by default: a cold start climbs by at most
#: :data:`MAX_TEMPERATURE_STEP` a step (the slot: 300 K to 1233 K, ≥ 10 steps) before Newton's
#: own convergence and the contacts' search for their status. Measured on the slot at 65k DOFs
#: from 300 K with the pressure-dependent law: 30 steps on the monolithic route, 31 on the
#: subdomain route (18 and 18 with constant resistances); 50 leaves 60 % above the worst.
MAX_IT = 50

#: The line searches ``line_search="auto"`` tries, in turn, each from the initial state.
AUTO = ("basic", "limited", "bt", "l2")


def solve(
    system: System,
    linear=None,
    *,
    rtol: float = 1e-10,
    max_it: int = MAX_IT,
    line_search: str = "auto",
    lag_jacobian: int = 1,
    prefix: str = "sc_newton_",
    monitor: Callable[[int], None] | None = None,
    max_temperature_step: float = MAX_TEMPERATURE_STEP,
    progress: bool = False,
) -> Result:
    """Newton's method on the system, from its current state.

    Converged when every field's residual is below ``rtol`` times its scale: the larger of
    its initial residual and of its residual at the *cold state* (every unknown zero but the
    Dirichlet values), which measures the loads the field can see. (Not the iterates': an
    iterate that overshoots would otherwise loosen the test.) Also converged when a full
    step whose inner solve converged moved every field by at most :data:`STEP_RTOL` of its
    largest value: a stiff contact floors the residual at about h̄ ε |T|, and the step
    then measures the digits left. A linear problem is solved in one step, its inner
    solve to ``rtol``.

    Args:
        system: The system; its state is the initial guess and receives the solution.
        linear: The linear solver (``check(system)``, ``setup(system)``,
            ``solve(b, tolerance)``): default
            :class:`~subdomain_contact.subdomain.Subdomains` with the exact corrector.
        rtol: Relative tolerance per field.
        max_it: Newton iterations allowed (per attempt).
        line_search: SNES line search: ``"basic"`` (full steps: the semi-smooth Newton of
            unilateral contact, which finds the contact status in a few steps), ``"bt"``
            (backtracking on ‖F‖²), ``"l2"`` (secant minimisation of ‖F‖²), ``"limited"``
            (full steps shortened to ``max_temperature_step``), or ``"auto"``:
            each of :data:`AUTO` in turn, from the same initial state, until one converges.
            Measured on the test scenes: full steps converge where the others creep (the
            squeezed Joule bars: bt and l2 fail, full steps take 9); backtracking where full
            steps overshoot into unphysical states (the three-body cathode at 1 V from a
            cold start: full steps fail, bt takes 8), limited ones from a cold start to a hot
            state (the collector bar slot, see :data:`MAX_TEMPERATURE_STEP`). A full or
            limited step that runs away is halved while its landing falls as an
            exponential's (:data:`RUNAWAY`).
        lag_jacobian: Rebuild the Jacobian every this many steps (modified Newton above 1).
        max_temperature_step: The largest temperature change of one step [K] of the
            ``"limited"`` line search (see :data:`MAX_TEMPERATURE_STEP`).
        prefix: Options prefix of the SNES (``-<prefix>snes_*``).
        monitor: Called with the iteration number at every iterate, the system holding it
            (its time is the caller's to exclude).
        progress: Print a line per iterate on rank 0 (line search, residual relative to the
            scale, inner rounds, step, the bodies' matrices factorised so far where their
            Krylov solve failed, seconds since the attempt began), and why an attempt
            failed before the next one starts: for long runs.

    Raises:
        NewtonConvergenceError: Newton (or an inner solve) failed with every line search;
            the error holds the last attempt's history and names the others' failures.
        ValueError: A conductivity or conductance is negative or NaN at the initial state
            or at the solution (the state is kept, for a look).
    """
    start = time.perf_counter()
    own = linear is None  # made here: destroyed here
    linear = linear or Subdomains()
    linear.check(system)
    system.check_laws("at the initial state")
    made, fallen = _factorisations(system, linear), _fallbacks(system)
    initial = system.state()
    failures = []
    try:
        for attempt in AUTO if line_search == "auto" else (line_search,):
            if failures:
                system.set_state(initial)
            try:
                result = _newton(system, linear, rtol, max_it, attempt, lag_jacobian, prefix,
                                 monitor, max_temperature_step, progress)  # fmt: skip
                break
            except NewtonConvergenceError as failure:
                failures.append((attempt, failure))
                if progress and system.comm.rank == 0:
                    print(f"Newton ({attempt}): {str(failure).splitlines()[0]}", flush=True)
        else:
            attempt, last = failures[-1]
            tried = "; ".join(f"line search {a}: {str(f).splitlines()[0]}" for a, f in failures)
            raise NewtonConvergenceError(
                f"{tried}\n{last.result.table()}", last.result
            ) from last.__cause__
    finally:
        initial.destroy()
        if own:
            linear.destroy()
    system.check_laws("at the solution Newton found", at_solution=True)
    result.line_search = attempt
    result.seconds = time.perf_counter() - start
    result.factorisations = _factorisations(system, linear) - made
    result.fallbacks = _fallbacks(system) - fallen
    return result


def _bodies_total(system: System, count: str) -> int:
    """A body counter (``"factorisations"``, ``"fallbacks"``) summed over the bodies.

    Each body counts once, however many ranks share it (collective).
    """
    local = sum(getattr(b, count) for b in system.bodies.values() if b.comm.rank == 0)
    return int(system.comm.allreduce(local))


def _factorisations(system: System, linear) -> int:
    """Sparse factorisations made so far: each body's once, and the linear solver's own."""
    return _bodies_total(system, "factorisations") + getattr(linear, "factorisations", 0)


def _fallbacks(system: System) -> int:
    """Bodies' matrices factorised so far where their Krylov solve failed (collective)."""
    return _bodies_total(system, "fallbacks")


def _newton(
    system: System,
    linear,
    rtol: float,
    max_it: int,
    line_search: str,
    lag_jacobian: int,
    prefix: str,
    monitor: Callable[[int], None] | None,
    max_temperature_step: float,
    progress: bool,
) -> Result:
    """One Newton run with one line search, from the system's current state."""
    callbacks = _Callbacks(system, linear, rtol, max_it, monitor, lag_jacobian)
    callbacks.announce = line_search if progress else None
    x, f = system.create_vector(), system.create_vector()
    callbacks.scale = _cold_residuals(system, f)
    system.apply_conditions()
    system.get_state(x)
    sizes = (x.getLocalSize(), x.getSize())
    J = PETSc.Mat().createPython((sizes, sizes), context=callbacks, comm=system.comm)
    J.setUp()
    snes = PETSc.SNES().create(system.comm)
    snes.setOptionsPrefix(prefix)
    snes.setType("newtonls")
    snes.getLineSearch().setType("basic" if line_search == "limited" else line_search)
    snes.setFunction(callbacks.function, f)
    snes.setJacobian(callbacks.jacobian, J, J)
    snes.setConvergenceTest(callbacks.converged)
    if line_search == "limited":
        callbacks.max_step = max_temperature_step
    if line_search in ("basic", "limited"):
        snes.setLineSearchPreCheck(callbacks.precheck)
    callbacks.snes = snes
    snes.setTolerances(max_it=max_it + 1)
    ksp = snes.getKSP()
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(callbacks)
    snes.setFromOptions()
    result = callbacks.result
    cause: Exception | None = None
    try:
        snes.solve(None, x)
        reason = snes.getConvergedReason()
    except PETSc.Error as error:
        reason = None
        # without its traceback: its frames hold the SNES's Python contexts, a cycle through
        # petsc4py objects the garbage collector cannot see, which would keep the system
        cause = (callbacks.failure or error).with_traceback(None)
    callbacks.failure, callbacks.snes = None, None
    callbacks.drop_trial()
    system.set_state(x)
    result.scale = dict(callbacks.scale)
    for obj in (snes, J, x, f):
        obj.destroy()
    if isinstance(cause, ValueError) and result.iterations == 0:
        raise cause  # at the initial state: bad input, not a failure to converge
    if isinstance(cause, MemoryError):
        raise cause  # another line search or time step would need the same memory
    # later, an iterate far from the solution (e.g. a contact law's exponential overshooting
    # into a singular interface operator): a failure to converge, which a line search or a
    # shorter time step may avoid
    if isinstance(cause, SubdomainConvergenceError):
        result.inner.append(cause.result)  # the failed inner solve, with its history
    if reason is None or reason < 0:
        result.reason = _REASONS.get(reason, "error in a callback")
        why = f"{cause}" if reason is None else result.reason
        raise NewtonConvergenceError(
            f"Newton failed after {result.iterations} iterations: {why}\n{result.table()}",
            result,
        ) from cause
    result.reason = _REASONS[reason]
    return result


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else (0.0 if a == 0 else np.inf)


def _cold_residuals(system: System, f: PETSc.Vec) -> dict[str, float]:
    """Each field's residual norm with every unknown zero but the Dirichlet values."""
    system.cold_residual(f)
    return system.field_norms(f)
