"""Time: backward Euler steps of the whole coupled problem, the subdomain iteration inside.

Each step of Δt solves, by Newton (:func:`~subdomain_contact.newton.solve`), the steady
problem plus the heat each body stores, ρ c_p(T) (T − T_prev) / Δt (bodies whose material
has a density and a heat capacity); the electrical and mechanical problems are quasi-static.
A body's factorisation is kept from one step to the next while its bulk matrix does not
change (a linear bulk and the same Δt): only the contact's dense block is rebuilt.
"""

from __future__ import annotations

from subdomain_contact.newton import Result, solve
from subdomain_contact.system import System

__all__ = ["advance"]


def advance(system: System, step: float, linear=None, **options) -> Result:
    """One backward Euler step of ``step`` [s] from the system's current state.

    The current state becomes the previous time's and the initial guess of Newton; the
    system holds the new state afterwards.

    Args:
        system: The system, at the state of the previous time.
        step: Δt [s], > 0.
        linear: The linear solver of each Newton step (default: the subdomain iteration).
        options: Newton's options (:func:`~subdomain_contact.newton.solve`).

    Raises:
        ValueError: A step that is not a positive finite number.
    """
    if not 0.0 < step < float("inf"):
        raise ValueError(f"advance: step = {step!r} s: must be a finite number > 0")
    system.set_time_step(step)
    system.keep_previous()
    return solve(system, linear, **options)
