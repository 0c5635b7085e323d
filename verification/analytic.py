"""Closed-form solutions used as independent truth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.integrate import simpson
from scipy.optimize import brentq

__all__ = ["BlocksBetweenWalls", "CompositeSlab", "JouleBars", "TwoPlates", "WavyPlates"]


@dataclass(frozen=True)
class TwoPlates:
    """Steady 1D conduction through two plates in series with a contact conductance.

    Plate A spans ``0 ≤ x ≤ length_a``, plate B ``length_a ≤ x ≤ length_a + length_b``;
    ``T(0) = t_left``, ``T(end) = t_right``; constant sources; the contact at ``x = length_a``
    passes ``q = h (T_A − T_B)`` and releases ``contact_heat`` [W/m^2], ``share_a`` of it into
    plate A and the rest into B (the contact's Joule heat). The exact solution is piecewise
    quadratic with a jump q/h.
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
    contact_heat: float = 0.0
    share_a: float = 0.5

    @property
    def flux(self) -> float:
        """Heat flux [W/m^2] through the contact, in +x."""
        drive = (
            self.t_left
            - self.t_right
            + self.source_a * self.length_a**2 / (2 * self.k_a)
            - self.source_b * self.length_b**2 / (2 * self.k_b)
        )
        drive += self.contact_heat * (
            self.share_a * self.length_a / self.k_a - (1 - self.share_a) * self.length_b / self.k_b
        )
        if self.h == 0:  # insulating: no heat crosses
            return 0.0
        return drive / (self.length_a / self.k_a + 1 / self.h + self.length_b / self.k_b)

    def temperature_a(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Temperature [K] in plate A at abscissae x [m]."""
        deposited = self.share_a * self.contact_heat
        slope = (self.source_a * self.length_a - self.flux + deposited) / self.k_a
        return self.t_left + slope * x - self.source_a * x**2 / (2 * self.k_a)

    def temperature_b(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Temperature [K] in plate B at abscissae x [m]."""
        s = x - self.length_a
        leaving = self.flux + (1 - self.share_a) * self.contact_heat  # into B at the contact
        start = (
            self.t_right
            + leaving * self.length_b / self.k_b
            + self.source_b * self.length_b**2 / (2 * self.k_b)
        )
        return start - leaving / self.k_b * s - self.source_b * s**2 / (2 * self.k_b)


@dataclass(frozen=True)
class JouleBars:
    """Steady 1D current and heat through two bars in series and their contact.

    Bar A spans ``0 ≤ x ≤ length_a``, bar B the next ``length_b``; potential ``voltage`` at
    x = 0 and 0 at the far end; temperatures ``t_left`` and ``t_right`` there. Constant
    conductivities k [W/(m K)], σ [S/m] and contact conductances h [W/(m^2 K)], g [S/m^2].
    The potential is piecewise linear with a jump j/g; Joule heat j²/σ warms the bars and
    j²/g the contact (``share_a`` of it into bar A, the rest into B).
    """

    length_a: float
    length_b: float
    k_a: float
    k_b: float
    sigma_a: float
    sigma_b: float
    h: float
    g: float
    voltage: float
    t_left: float
    t_right: float
    share_a: float = 0.5

    @property
    def current_density(self) -> float:
        """Current density j [A/m^2] in +x."""
        return self.voltage / (
            self.length_a / self.sigma_a + 1 / self.g + self.length_b / self.sigma_b
        )

    def potential_a(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Potential [V] in bar A."""
        return self.voltage - self.current_density * x / self.sigma_a

    def potential_b(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Potential [V] in bar B."""
        end = self.length_a + self.length_b
        return self.current_density * (end - x) / self.sigma_b

    @property
    def thermal(self) -> TwoPlates:
        """The heat problem, with the Joule heat as its sources."""
        j2 = self.current_density**2
        return TwoPlates(
            self.length_a, self.length_b, self.k_a, self.k_b, self.h, self.t_left,
            self.t_right, j2 / self.sigma_a, j2 / self.sigma_b, j2 / self.g, self.share_a,
        )  # fmt: skip


@dataclass(frozen=True)
class BlocksBetweenWalls:
    """Two blocks in a row between fixed walls, uniformly heated, in plane strain or in 3D.

    Each block may expand freely across (traction-free sides, rollers), so the stress is
    uniaxial, σ_xx = −p, and its strain is ε_xx = −p (1 − ν²)/E + (1 + ν) α ΔT in plane strain
    (ε_zz = 0), ε_xx = −p/E + α ΔT in 3D (``plane_strain=False``). The
    contact between the blocks has an initial gap and a penalty law p = k_n ⟨closure − gap⟩;
    an open contact transmits nothing. Units: m, Pa, 1/K, K, Pa/m.
    """

    lengths: tuple[float, float]
    young: tuple[float, float]
    poisson: tuple[float, float]
    expansion: tuple[float, float]
    gap: float
    stiffness: float
    plane_strain: bool = True

    def free_closure(self, heating: float) -> float:
        """Closure [m] the blocks would make without contact, heated by ``heating`` [K]."""
        return sum(
            L * (1 + nu if self.plane_strain else 1.0) * a * heating
            for L, nu, a in zip(self.lengths, self.poisson, self.expansion, strict=True)
        )

    def pressure(self, heating: float) -> float:
        """Contact pressure [Pa] (0 when open)."""
        compliance = sum(
            L * (1 - nu**2 if self.plane_strain else 1.0) / E
            for L, nu, E in zip(self.lengths, self.poisson, self.young, strict=True)
        )
        closure = self.free_closure(heating) - self.gap
        return max(self.stiffness * closure / (1 + self.stiffness * compliance), 0.0)

    def strain(self, heating: float) -> tuple[float, float]:
        """ε_xx of each block under the contact's pressure (compressive: negative stress)."""
        p = self.pressure(heating)
        return tuple(
            -p * (1 - nu**2 if self.plane_strain else 1.0) / E
            + (1 + nu if self.plane_strain else 1.0) * a * heating
            for nu, E, a in zip(self.poisson, self.young, self.expansion, strict=True)
        )

    def displacement_x(self, heating: float) -> tuple[Callable, Callable]:
        """u_x [m] of each block as a function of x: the walls at 0 and L_a + L_b hold u_x = 0."""
        (e_a, e_b), end = self.strain(heating), sum(self.lengths)
        return (lambda x: e_a * x), (lambda x: -e_b * (end - x))

    def gap_width(self, heating: float) -> float:
        """Gap [m] between the blocks (negative: the penalty's interpenetration)."""
        p = self.pressure(heating)
        return -p / self.stiffness if p > 0 else self.gap - self.free_closure(heating)


@dataclass(frozen=True)
class WavyPlates:
    """Two plates in series whose temperature also varies along the contact (no sources).

    ``T = T₁(x) + m cos(κ y) X(x)``: ``T₁`` the 1D solution of :class:`TwoPlates` (``plates``)
    and a harmonic mode, κ = π / ``width`` (so that ∂T/∂y = 0 on y = 0 and y = width:
    insulated sides), ``X_A = e^{κ(x − L_a)}`` in plate A and ``X_B = β e^{κ(x − L_a)} +
    γ e^{−κ(x − L_a)}`` in plate B, with β, γ from the contact's two conditions (the same flux
    on both sides, a jump of flux / h). Dirichlet data on the two ends are functions of
    x and y. Units: m, K.
    """

    plates: TwoPlates
    width: float
    amplitude: float

    @property
    def wavenumber(self) -> float:
        """κ [1/m]."""
        return np.pi / self.width

    def _coefficients(self) -> tuple[float, float]:
        p, kappa = self.plates, self.wavenumber
        total = 1 + p.k_a * kappa / p.h  # β + γ
        difference = p.k_a / p.k_b  # β − γ
        return (total + difference) / 2, (total - difference) / 2

    def temperature(self, x, y, module=np):
        """Exact temperature [K] at (x, y) (arrays, or UFL with ``module=ufl``)."""
        p, kappa, m = self.plates, self.wavenumber, self.amplitude
        beta, gamma = self._coefficients()
        s = x - p.length_a
        on_b = module.exp(kappa * s)
        mode_a = m * module.cos(kappa * y) * module.exp(kappa * s)
        mode_b = m * module.cos(kappa * y) * (beta * on_b + gamma * module.exp(-kappa * s))
        return (p.temperature_a(x) + mode_a), (p.temperature_b(x) + mode_b)


@dataclass(frozen=True)
class CompositeSlab:
    """Two slabs in series with a contact conductance, heated from one end: the series.

    From 0 K, the left end raised to ``t_left`` at t = 0, the right end held at 0 K. Slab A
    on 0 ≤ x ≤ L, slab B on L ≤ x ≤ 2L, diffusivities α = k / (ρ c_p). T = T_s(x) +
    Σ c_n X_n(x) e^{−λ_n² t}: X_n = sin(λ x / √α_A) in A, b_n sin(λ (2L − x) / √α_B) in B,
    with the same flux at x = L and the jump flux / h there; the X_n are orthogonal with
    weight ρ c_p, and c_n makes T(x, 0) = 0: the classical eigenfunction expansion of
    conduction in composite media (as in M. N. Özışık, *Heat Conduction*, Wiley), derived here
    with a contact conductance between the layers; eigenvalues by bracketing the sign changes
    of the interface determinant on a fine grid, overlaps by Simpson's rule on 4001 nodes per
    slab. Units: m, W/(m K), J/(m^3 K), W/(m^2 K), K, s.
    """

    length: float
    k_a: float
    k_b: float
    capacity_a: float  # ρ c_p [J/(m^3 K)]
    capacity_b: float
    h: float
    t_left: float
    terms: int = 200

    def _roots(self) -> np.ndarray:
        """The first ``terms`` eigenvalues λ_n [1/√s], roots of the interface determinant."""
        ra, rb = np.sqrt(self.k_a / self.capacity_a), np.sqrt(self.k_b / self.capacity_b)

        def det(lam):
            a, b = lam * self.length / ra, lam * self.length / rb
            return -(self.k_a / ra) * np.cos(a) * np.sin(b) - (self.k_b / rb) * np.cos(b) * (
                np.sin(a) + self.k_a * lam * np.cos(a) / (self.h * ra)
            )

        grid = np.linspace(1e-9, 1.0, 400001) * (self.terms + 2) * np.pi * max(ra, rb) / self.length
        values = det(grid)
        change = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
        return np.array([brentq(det, grid[i], grid[i + 1], xtol=1e-15) for i in change])[
            : self.terms
        ]

    def temperature(self, x: np.ndarray, t: float, side: str) -> np.ndarray:
        """T [K] at abscissae x [m] of slab ``side`` ("a" or "b") and time t [s] > 0."""
        L = self.length
        ra, rb = np.sqrt(self.k_a / self.capacity_a), np.sqrt(self.k_b / self.capacity_b)
        steady = TwoPlates(L, L, self.k_a, self.k_b, self.h, self.t_left, 0.0)
        s = np.linspace(0.0, L, 4001)  # quadrature nodes of each slab (Simpson)
        on_a = side == "a"
        total = steady.temperature_a(x) if on_a else steady.temperature_b(x)
        for lam in self._roots():
            a, b = lam * L / ra, lam * L / rb
            if abs(np.sin(b)) > abs(np.cos(b)):  # the jump condition, better conditioned
                amplitude = (np.sin(a) + self.k_a * lam * np.cos(a) / (self.h * ra)) / np.sin(b)
            else:  # the flux condition
                amplitude = -(self.k_a / ra) * np.cos(a) / ((self.k_b / rb) * np.cos(b))

            def mode_a(y, lam=lam):
                return np.sin(lam * y / ra)

            def mode_b(y, lam=lam, amplitude=amplitude):
                return amplitude * np.sin(lam * (2 * L - y) / rb)

            xa, xb = s, L + s
            weight = self.capacity_a * simpson(mode_a(xa) ** 2, x=xa)
            weight += self.capacity_b * simpson(mode_b(xb) ** 2, x=xb)
            overlap = self.capacity_a * simpson(steady.temperature_a(xa) * mode_a(xa), x=xa)
            overlap += self.capacity_b * simpson(steady.temperature_b(xb) * mode_b(xb), x=xb)
            mode = mode_a(x) if on_a else mode_b(x)
            total = total - overlap / weight * mode * np.exp(-(lam**2) * t)
        return total
