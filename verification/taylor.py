"""Taylor test of a system's Jacobian: the independent check that Newton can be quadratic.

For an exact Jacobian J of the residual F, the remainder ``R(ε) = ‖F(x + ε d) − F(x) − ε J d‖``
is ``½ ε² ‖dᵀ F'' d‖ + O(ε³)``: it falls 4 times when ε is halved, an order ``log₂ R(ε) /
R(ε/2)`` of 2 per field. A Jacobian that misses or mis-scales any term leaves an ``O(ε)``
part: order 1. Unlike the order fitted to a Newton history, it does not depend on the path
Newton takes from its start (a path that crosses the kinks of tabulated laws differently on
another machine's round-off).
"""

from __future__ import annotations

import itertools

import numpy as np
from petsc4py import PETSc


def jacobian_orders(
    system, direction: PETSc.Vec, *, step: float = 1e-2, halvings: int = 4
) -> list[dict[str, float]]:
    """Per field, the Taylor remainder's order between successive halvings of ``step``.

    Args:
        system: An ``sc.System``; its state is the expansion point and is kept.
        direction: The perturbation d (a global vector of the system), zero on fixed DOFs.
        step: The first ε (relative to d).
        halvings: How many times ε is halved.

    Returns:
        One dict field -> ``log₂ R(ε) / R(ε/2)`` per halving (collective).
    """
    x = system.state()
    f0, jd, f = (system.create_vector() for _ in range(3))
    try:
        system.residual(f0)
        system.assemble_jacobian()
        system.mult(direction, jd)
        remainders = []
        for i in range(halvings + 1):
            eps = step * 0.5**i
            shifted = x.copy()
            shifted.axpy(eps, direction)
            system.set_state(shifted)
            shifted.destroy()
            system.residual(f)
            f.axpy(-1.0, f0)
            f.axpy(-eps, jd)
            remainders.append(system.field_norms(f))
    finally:
        system.set_state(x)
        for v in (x, f0, jd, f):
            v.destroy()
    return [{k: float(np.log2(a[k] / b[k])) for k in a} for a, b in itertools.pairwise(remainders)]


def jacobian_orders_toward(
    system, solution: PETSc.Vec, initial: dict[str, float], **kwargs
) -> list[dict[str, float]]:
    """:func:`jacobian_orders` at ``solution``, along the way back to a uniform start.

    The direction is the start ``initial`` (``system.reset``, with the conditions applied, so
    it is zero on fixed DOFs) minus the solution; the system is left at ``solution``.
    """
    system.reset(initial)
    system.apply_conditions()
    direction = system.state()
    direction.axpy(-1.0, solution)
    system.set_state(solution)
    try:
        return jacobian_orders(system, direction, **kwargs)
    finally:
        direction.destroy()
