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
"""

from __future__ import annotations

from dataclasses import dataclass

from subdomain_contact.newton import Result, solve
from subdomain_contact.system import System

__all__ = ["SCHEMES", "Stepper"]

#: The time schemes.
SCHEMES = ("backward_euler", "bdf2")


@dataclass
class Stepper:
    """Steps a system in time from its current state (at ``time``).

    Attributes:
        system: The system; it holds the state of the latest time.
        scheme: One of :data:`SCHEMES`.
        time: The time [s] of the system's state.
        steps: Steps taken.
    """

    system: System
    scheme: str = "bdf2"
    time: float = 0.0
    steps: int = 0
    _last: float | None = None

    def __post_init__(self) -> None:
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme = {self.scheme!r}: one of {SCHEMES}")
        self.system.set_time(self.time)

    def advance(self, step: float, linear=None, **options) -> Result:
        """One step of ``step`` [s]; Newton starts from the current state.

        Args:
            step: Δt [s], > 0.
            linear: The linear solver of each Newton step (default: the subdomain iteration).
            options: Newton's options (:func:`~subdomain_contact.newton.solve`).

        Raises:
            ValueError: A step that is not a positive finite number.
        """
        if not 0.0 < step < float("inf"):
            raise ValueError(f"advance: step = {step!r} s: must be a finite number > 0")
        self.system.set_rates(self.rates(step))
        self.system.set_time(self.time + step)  # the conditions at the step's end
        self.system.keep_previous()
        result = solve(self.system, linear, **options)
        self.time, self.steps, self._last = self.time + step, self.steps + 1, step
        return result

    def rates(self, step: float) -> tuple[float, float]:
        """The weights (r₀, r₁) [1/s] of the time derivative for a step of ``step`` [s]."""
        if self.scheme == "backward_euler" or self._last is None:
            return 1.0 / step, 0.0
        ratio = step / self._last
        return (1 + 2 * ratio) / ((1 + ratio) * step), ratio**2 / ((1 + ratio) * step)
