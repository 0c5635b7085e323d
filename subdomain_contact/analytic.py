"""Closed-form solutions used as independent truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["TwoPlates"]


@dataclass(frozen=True)
class TwoPlates:
    """Steady 1D conduction through two plates in series with a contact conductance.

    Plate A spans ``0 ≤ x ≤ length_a``, plate B ``length_a ≤ x ≤ length_a + length_b``;
    ``T(0) = t_left``, ``T(end) = t_right``; constant sources; the contact at ``x = length_a``
    passes ``q = h (T_A − T_B)``. The exact solution is piecewise quadratic with a jump q/h.
    Units: m, W/(m K), W/m^3, K, W/(m^2 K).
    """

    length_a: float
    length_b: float
    k_a: float
    k_b: float
    h: float
    t_left: float
    t_right: float
    source_a: float = 0.0
    source_b: float = 0.0

    @property
    def flux(self) -> float:
        """Heat flux [W/m^2] through the contact, in +x."""
        drive = (
            self.t_left
            - self.t_right
            + self.source_a * self.length_a**2 / (2 * self.k_a)
            - self.source_b * self.length_b**2 / (2 * self.k_b)
        )
        return drive / (self.length_a / self.k_a + 1 / self.h + self.length_b / self.k_b)

    def temperature_a(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Temperature [K] in plate A at abscissae x [m]."""
        slope = (self.source_a * self.length_a - self.flux) / self.k_a
        return self.t_left + slope * x - self.source_a * x**2 / (2 * self.k_a)

    def temperature_b(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Temperature [K] in plate B at abscissae x [m]."""
        s = x - self.length_a
        start = (
            self.t_right
            + self.flux * self.length_b / self.k_b
            + self.source_b * self.length_b**2 / (2 * self.k_b)
        )
        return start - self.flux / self.k_b * s - self.source_b * s**2 / (2 * self.k_b)
