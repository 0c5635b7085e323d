"""Time: implicit steps of the whole coupled problem, the subdomain iteration inside.

Each step of Δt solves, by Newton (:func:`~subdomain_contact.newton.solve`), the steady
problem plus the heat each body stores, ρ c_p(T) ∂T/∂t (bodies whose material has a density
and a heat capacity); the electrical and mechanical problems are quasi-static. The time
derivative at the new time, with T₁, T₂ the states one and two steps back:

- backward Euler: ∂T/∂t ≈ (T − T₁) / Δt (first order);
- BDF2 with steps of any length, ω = Δt / Δt_prev:
  ∂T/∂t ≈ [(1 + 2ω)/(1 + ω) (T − T₁) − ω²/(1 + ω) (T₁ − T₂)] / Δt (second order; its first
  step is backward Euler).

A body's factorisation is kept from one step to the next while its bulk matrix does not
change (a linear bulk and the same weights, i.e. the same Δt): only the contact's dense
block is rebuilt.

Newton starts each step from a predictor, the line through the latest two states (masters
included) extended to the step's end, as BDF codes do: its error is of order Δt² where the
latest state's is of order Δt, so Newton needs fewer steps. Measured on the coke bed preheat
(2D slice, its first 21 steps of BDF2 from the cold cell): 47 Newton steps instead of 61,
the states equal to Newton's tolerance (1e-8 K), a quadratic predictor 45; its whole run,
140 instead of 177. Where a law is out of its range at the predicted state, the step starts
from the latest state.

:meth:`Stepper.march` runs to a time with fixed steps, or adaptive ones (``tolerance``): the
local error of the step is estimated from the scheme's error constant and the divided
differences of the latest states, and the next step is chosen to meet it; a step whose
estimate exceeds the tolerance is rejected and taken again shorter. A step whose Newton fails
(or converges to a spurious root where a law leaves its range) is taken again with half the
length, down to ``min_step``. Steps land on the breakpoints of
every ``Schedule`` (a ramp's corners, a switch) and on the times asked for.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact.newton import NewtonConvergenceError, Result, solve
from subdomain_contact.subdomain import SubdomainConvergenceError
from subdomain_contact.system import LawRangeError, System

__all__ = ["SCHEMES", "StepFailedError", "Stepper"]

#: The time schemes.
SCHEMES = ("backward_euler", "bdf2")

#: Order of each scheme.
ORDER = {"backward_euler": 1, "bdf2": 2}

Vector = npt.NDArray[np.float64]


class StepFailedError(RuntimeError):
    """A step failed at the shortest step allowed; the system holds the last accepted state."""


@dataclass
class Stepper:
    """Steps a system in time from its current state (at ``time``).

    Attributes:
        system: The system; it holds the state of the latest time.
        scheme: One of :data:`SCHEMES`.
        time: The time [s] of the system's state.
        steps: Steps taken (accepted).
        rejected: Steps taken again: Newton failed, or the error estimate was too large.
        past: The accepted states before the current one, latest first, with their times
            (for the error estimate): ``(time, {body: state array})``.
        next_step: The step [s] that :meth:`march` will try next (None: its ``step``).
        predictor: Start Newton from the extrapolated state (False: from the latest one).
        past_masters: The master values of the states in ``past``, latest first.
    """

    system: System
    scheme: str = "bdf2"
    time: float = 0.0
    steps: int = 0
    rejected: int = 0
    past: list[tuple[float, dict[str, Vector]]] = field(default_factory=list)
    next_step: float | None = None
    predictor: bool = True
    past_masters: list[dict[str, Vector]] = field(default_factory=list)
    _last: float | None = None
    _undo: tuple | None = None

    def __post_init__(self) -> None:
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme = {self.scheme!r}: one of {SCHEMES}")
        self.system.set_time(self.time)

    @property
    def order(self) -> int:
        """The scheme's order of accuracy."""
        return ORDER[self.scheme]

    @property
    def last_step(self) -> float | None:
        """The latest step [s] (None before the first)."""
        return self._last

    def clock(self) -> dict:
        """The stepper's numbers, JSON-ready (a checkpoint's), and its past states by time."""
        return {
            "scheme": self.scheme,
            "time": self.time,
            "steps": self.steps,
            "rejected": self.rejected,
            "last": self._last,
            "next_step": self.next_step,
            "past_times": [t for t, _ in self.past],
        }

    def set_clock(
        self,
        numbers: dict,
        past: list[dict[str, Vector]],
        past_masters: list[dict[str, Vector]] | None = None,
    ) -> None:
        """Go on from :meth:`clock`'s numbers and the past states (a restart).

        ``past_masters``: their master values (None: none saved; the predictor then waits
        for the next two states).

        Raises:
            ValueError: A clock of another scheme.
        """
        if numbers["scheme"] != self.scheme:
            raise ValueError(
                f"a checkpoint of scheme {numbers['scheme']!r}, this stepper's is {self.scheme!r}"
            )
        self.time, self.steps, self.rejected = (
            numbers["time"],
            numbers["steps"],
            numbers["rejected"],
        )
        self._last, self.next_step = numbers["last"], numbers["next_step"]
        self.past = list(zip(numbers["past_times"], past, strict=True))
        self.past_masters = list(past_masters or [])
        self._undo = None
        self.system.set_time(self.time)

    def advance(self, step: float, linear=None, **options) -> Result:
        """One step of ``step`` [s]; Newton starts from the current state.

        If Newton fails, or converges to a state where a law is out of its range, the system,
        its history and the clock are put back as they were before the step, and the error
        propagates.

        Args:
            step: Δt [s], > 0.
            linear: The linear solver of each Newton step (default: the subdomain iteration).
            options: Newton's options (:func:`~subdomain_contact.newton.solve`).

        Raises:
            ValueError: A step that is not a positive finite number.
        """
        if not 0.0 < step < float("inf"):
            raise ValueError(f"advance: step = {step!r} s: must be a finite number > 0")
        self._keep_for_undo()
        self.system.set_rates(self.rates(step))
        self.system.set_time(self.time + step)  # the conditions at the step's end
        self.system.keep_previous()
        if self.predictor:
            self._predict(step)
        try:
            result = solve(self.system, linear, **options)
        except (NewtonConvergenceError, SubdomainConvergenceError, LawRangeError):
            self.undo()
            raise
        self.past = [(self.time, self._undo[0]), *self.past[: self.order]]
        self.past_masters = [self._undo[1], *self.past_masters[: self.order]]
        self.time, self.steps, self._last = self.time + step, self.steps + 1, step
        return result

    def _predict(self, step: float) -> None:
        """Extend the line through the latest two states to ``self.time + step`` (collective).

        Kept only where every law is in its range at the predicted state.
        """
        if not self.past_masters:  # the first step, or a checkpoint without them
            return
        (before, states), masters = self.past[0], self.past_masters[0]
        weight = step / (self.time - before)
        system = self.system
        for name, body in system.bodies.items():
            body.U.x.array[:] += weight * (body.U.x.array - states[name])
        system.set_masters({k: v + weight * (v - masters[k]) for k, v in system.masters.items()})
        try:
            system.check_laws("at the predicted state")
        except LawRangeError:
            for name, body in system.bodies.items():
                body.U.x.array[:] = self._undo[0][name]
            system.set_masters({k: v.copy() for k, v in self._undo[1].items()})

    def undo(self) -> None:
        """Put back the state before the latest step (once)."""
        if self._undo is None:
            raise RuntimeError("undo: no step to undo")
        states, masters, history, clock = self._undo
        system = self.system
        for name, body in system.bodies.items():
            body.U.x.array[:] = states[name]  # ghosts included
            for h, values in zip(body.forms.history, history[name], strict=True):
                h.x.array[:] = values
        system.set_masters(masters)
        self.time, self.steps, self._last, self.past, self.past_masters = clock
        system.set_time(self.time)
        self._undo = None

    def _keep_for_undo(self) -> None:
        """Copy what a step changes: states, masters, histories, clock (NumPy: no PETSc)."""
        bodies = self.system.bodies
        self._undo = (
            {name: body.U.x.array.copy() for name, body in bodies.items()},
            {k: v.copy() for k, v in self.system.masters.items()},
            {name: [h.x.array.copy() for h in body.forms.history] for name, body in bodies.items()},
            (self.time, self.steps, self._last, list(self.past), list(self.past_masters)),
        )

    def rates(self, step: float) -> tuple[float, float]:
        """The weights (r₀, r₁) [1/s] of the time derivative for a step of ``step`` [s]."""
        if self.scheme == "backward_euler" or self._last is None:
            return 1.0 / step, 0.0
        return _bdf2_rates(step, self._last)

    def error_estimate(self) -> float | None:
        """Estimated local error [K] of the latest step: the largest over the temperature DOFs.

        The step's local error is ``C Δt^{p+1} T^{(p+1)}``. The constant follows from the
        weights of the step: a defect ``d T^{(p+1)}`` of the discrete derivative moves the
        solution by ``d / r₀``; backward Euler's gives ``Δt²/2 · T''``, BDF2's
        ``[r₀ Δt³ − r₁ ((Δt + Δt_prev)³ − Δt³)] / (6 r₀) · T'''`` (−2/9 Δt³ T''' for equal
        steps). The derivative is (p + 1)! times the divided difference of the latest p + 2
        states. None until there are that many (collective).
        """
        p = self.order
        if len(self.past) < p + 1:
            return None
        times = [self.time] + [t for t, _ in self.past[: p + 1]]
        step, previous = times[0] - times[1], times[1] - times[2]
        if p == 1:
            constant = step**2 / 2
        else:
            r0, r1 = _bdf2_rates(step, previous)
            constant = (r0 * step**3 - r1 * ((step + previous) ** 3 - step**3)) / (6 * r0)
        worst = 0.0
        for name, body in self.system.bodies.items():
            if body.forms.storage is None:  # no heat stored: no time derivative
                continue
            dofs = body.forms.collapsed("temperature")[1]
            dofs = dofs[dofs < body.size]
            values = [body.U.x.array[dofs]] + [s[name][dofs] for _, s in self.past[: p + 1]]
            derivative = math.factorial(p + 1) * _divided_difference(times, values)
            worst = max(worst, float(np.abs(constant * derivative).max(initial=0.0)))
        return float(self.system.comm.allreduce(worst, op=MPI.MAX))

    def march(
        self,
        until: float,
        step: float,
        *,
        tolerance: float | None = None,
        min_step: float | None = None,
        max_step: float | None = None,
        land_on: Sequence[float] = (),
        after_step: Callable[[Stepper, Result], bool] | None = None,
        linear=None,
        **options,
    ) -> None:
        """Step to time ``until`` [s].

        Args:
            until: End time [s].
            step: The step [s] (the first one, when adaptive).
            tolerance: Local error [K] per step: adaptive steps (None: fixed steps).
            min_step: Shortest step [s] (default ``step / 1024``).
            max_step: Longest step [s] (default: ``until − time``).
            land_on: Times [s] that a step must end on (output times); every ``Schedule``'s
                breakpoints are added.
            after_step: Called after every accepted step; returning True stops the march
                (e.g. on a signal, once the state is saved).
            linear: The linear solver of each Newton step.
            options: Newton's options.

        Raises:
            StepFailedError: A step failed at ``min_step``; the system holds the last
                accepted state, ``self.time`` its time.
        """
        if not 0.0 < step < float("inf"):
            raise ValueError(f"march: step = {step!r} s: must be a finite number > 0")
        min_step = step / 1024 if min_step is None else min_step
        max_step = until - self.time if max_step is None else max_step
        marks = sorted({*land_on, *self.system.breakpoints(), until})
        tiny = 1e-12 * max(abs(until), step)
        length = self.next_step or step
        while self.time < until - tiny:
            target = next(t for t in marks if t > self.time + tiny)
            trial = min(length, max_step, target - self.time)
            if self.scheme == "bdf2" and self._last is not None:
                trial = min(trial, 2 * self._last)  # ω ≤ 2 < 1 + √2: BDF2 stays zero-stable
            if target - (self.time + trial) < 0.01 * trial:  # no sliver before a mark
                trial = target - self.time
            try:
                result = self.advance(trial, linear, **options)
            except (NewtonConvergenceError, SubdomainConvergenceError, LawRangeError) as failure:
                if isinstance(failure, LawRangeError) and not failure.at_solution:
                    raise  # the step's initial state: bad data, not a step too long
                self.rejected += 1
                if trial / 2 < min_step:
                    raise StepFailedError(
                        f"at t = {self.time:.6g} s a step of {trial:.3g} s failed and half of it "
                        f"is below min_step = {min_step:.3g} s: {str(failure).splitlines()[0]}. "
                        "Try a smaller min_step, line_search='bt', or a slower ramp of the loads"
                    ) from failure
                length = trial / 2
                continue
            if tolerance is not None:
                error = self.error_estimate()
                if error is not None:
                    factor = 0.9 * (tolerance / max(error, 1e-300)) ** (1 / (self.order + 1))
                    if error > tolerance and trial > min_step:
                        self.undo()
                        self.rejected += 1
                        length = max(min_step, trial * min(0.9, max(0.2, factor)))
                        continue
                    length = trial * min(2.0, max(0.2, factor))
            else:
                length = min(step, 2 * length)  # back to the step after a halving
            self.next_step = length  # saved with the clock: a restart goes on with it
            if after_step is not None and after_step(self, result):
                return


def _bdf2_rates(step: float, previous: float) -> tuple[float, float]:
    """BDF2's weights (r₀, r₁) [1/s] for a step of ``step`` after one of ``previous`` [s]."""
    ratio = step / previous
    return (1 + 2 * ratio) / ((1 + ratio) * step), ratio**2 / ((1 + ratio) * step)


def _divided_difference(times: list[float], values: list[Vector]) -> Vector:
    """The divided difference ``f[t₀, …, t_n]`` of arrays given at ``times``."""
    table = list(values)
    for level in range(1, len(times)):
        table = [
            (table[i] - table[i + 1]) / (times[i] - times[i + level]) for i in range(len(table) - 1)
        ]
    return table[0]
