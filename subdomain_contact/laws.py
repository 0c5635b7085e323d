"""Phenomenological laws of pressure and temperature, evaluated as UFL expressions.

A law is any callable ``law(p, T)`` that returns a UFL expression of the contact pressure
``p`` [Pa] and the temperature ``T`` [K]: the classes here (a constant, a power law of
pressure, an interpolated table) or a function the user writes, e.g.
``lambda p, T: 1e3 * (1 + p / 1e6) * ufl.exp(-T / 500)``. Material laws of temperature use
the same signature with ``p = 0``. ``ufl.derivative`` differentiates every one of them, so
Newton's Jacobian includes the laws' derivatives.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import ufl

__all__ = ["Constant", "Law", "PowerLaw", "Table", "antiderivative", "as_law", "check_finite"]

Law = Callable[[ufl.core.expr.Expr, ufl.core.expr.Expr], ufl.core.expr.Expr]


def check_finite(value: float, name: str, *, positive: bool = False) -> None:
    """Refuse NaN, infinities and (where asked) values that are not strictly positive."""
    if not math.isfinite(value) or (positive and value <= 0.0):
        need = "a finite number > 0" if positive else "a finite number"
        raise ValueError(f"{name} = {value!r}: must be {need}")


@dataclass(frozen=True)
class Constant:
    """A law that is one number."""

    value: float

    def __call__(self, p: ufl.core.expr.Expr, T: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """The value, whatever ``p`` and ``T``."""
        return ufl.as_ufl(float(self.value))


@dataclass(frozen=True)
class PowerLaw:
    """``C = floor + scale(T) (p / hardness)^exponent``: conductances of rough contacts.

    The Hall–Héroult contact laws are of this type (C = α k_harm(T) (p/H)^β, k_harm the
    harmonic mean of the two sides' conductivities: Babu et al. 2001, Cincotti et al. 2007).
    ``floor`` is what an open contact still conducts (gas, radiation); it must be > 0, or the
    master layer of an open contact has no equation. Below ``p_min = 1e-9 hardness`` the
    pressure is held at ``p_min``, so that the derivative stays finite for exponents below one.

    Attributes:
        scale: Coefficient at p = hardness, in the law's unit: a number, or a :class:`Table`
            in temperature (one pressure) for α k_harm(T).
        hardness: Reference pressure H [Pa].
        exponent: β (dimensionless), > 0.
        floor: Value at zero pressure, in the law's unit.
    """

    scale: float | Table
    hardness: float
    exponent: float
    floor: float

    def __post_init__(self) -> None:
        values = np.ravel(self.scale.values) if isinstance(self.scale, Table) else [self.scale]
        for value in values:
            check_finite(float(value), "PowerLaw scale")
            if value < 0:
                raise ValueError(f"PowerLaw scale = {value}: must be >= 0")
        check_finite(self.hardness, "PowerLaw hardness", positive=True)
        check_finite(self.exponent, "PowerLaw exponent", positive=True)
        check_finite(self.floor, "PowerLaw floor (value of an open contact)", positive=True)

    def __call__(self, p: ufl.core.expr.Expr, T: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """``floor + scale(T) (max(p, p_min) / H)^β``."""
        ratio = ufl.max_value(p / self.hardness, 1e-9)
        scale = self.scale(p, T) if isinstance(self.scale, Table) else self.scale
        return self.floor + scale * ratio**self.exponent


@dataclass(frozen=True)
class Table:
    """Values tabulated in pressure and temperature, interpolated bilinearly.

    Outside the table the value is held at its edge. Give one pressure (or one temperature)
    for a table in the other variable alone.

    Attributes:
        pressures: Increasing pressures [Pa].
        temperatures: Increasing temperatures [K].
        values: ``values[i][j]`` at ``pressures[i]``, ``temperatures[j]``.
    """

    pressures: Sequence[float]
    temperatures: Sequence[float]
    values: Sequence[Sequence[float]]

    def __post_init__(self) -> None:
        shape = (len(self.pressures), len(self.temperatures))
        values = np.asarray(self.values, dtype=float)
        if values.shape != shape:
            raise ValueError(f"Table: values have shape {values.shape}, expected {shape}")
        for name, axis in [("pressures", self.pressures), ("temperatures", self.temperatures)]:
            if len(axis) == 0 or np.any(np.diff(axis) <= 0) or not np.all(np.isfinite(axis)):
                raise ValueError(f"Table {name} must be finite and increasing, got {axis}")
        if not np.all(np.isfinite(values)):
            raise ValueError("Table values must be finite")

    def __call__(self, p: ufl.core.expr.Expr, T: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Bilinear interpolation, as a sum of hat functions in p and T."""
        hats_p, hats_t = _hats(p, self.pressures), _hats(T, self.temperatures)
        return sum(
            float(self.values[i][j]) * hp * ht
            for i, hp in enumerate(hats_p)
            for j, ht in enumerate(hats_t)
        )


def antiderivative(law: float | Law, T: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """∫₀^T law(s) ds of a law of temperature alone: a number or a :class:`Table` in T.

    Exact: piecewise quadratic between the table's nodes, linear beyond them (the value is
    held there). E.g. the enthalpy ∫ c_p dT [J/kg] of a heat capacity.

    Raises:
        ValueError: Any other law (no closed form to integrate).
    """
    if not callable(law):
        return float(law) * T
    if isinstance(law, Constant):
        return float(law.value) * T
    if not isinstance(law, Table) or len(law.pressures) != 1:
        raise ValueError(f"antiderivative: {law!r} is not a number or a table in temperature alone")
    nodes, values = law.temperatures, [float(v) for v in law.values[0]]
    total = values[0] * ufl.min_value(T, nodes[0])
    for k in range(len(nodes) - 1):
        length = nodes[k + 1] - nodes[k]
        y = ufl.min_value(ufl.max_value(T - nodes[k], 0.0), length)
        total += values[k] * y + (values[k + 1] - values[k]) * y**2 / (2 * length)
    return total + values[-1] * ufl.max_value(T - nodes[-1], 0.0)


def _hats(x: ufl.core.expr.Expr, nodes: Sequence[float]) -> list[ufl.core.expr.Expr]:
    """Piecewise-linear hat functions of ``x`` on ``nodes``, constant beyond the ends."""
    if len(nodes) == 1:
        return [ufl.as_ufl(1.0)]
    x = ufl.min_value(ufl.max_value(x, nodes[0]), nodes[-1])
    hats = []
    for i, node in enumerate(nodes):
        hat = ufl.as_ufl(0.0)
        if i > 0:
            left = nodes[i - 1]
            rising = (x - left) / (node - left)
            hat = ufl.conditional(ufl.And(ufl.gt(x, left), ufl.le(x, node)), rising, hat)
        if i < len(nodes) - 1:
            right = nodes[i + 1]
            falling = (right - x) / (right - node)
            lower = ufl.ge(x, node) if i == 0 else ufl.gt(x, node)
            hat = ufl.conditional(ufl.And(lower, ufl.le(x, right)), falling, hat)
        hats.append(hat)
    return hats


def as_law(law: float | Law) -> Law:
    """A law from a number or a callable."""
    if callable(law):
        return law
    return Constant(float(law))
