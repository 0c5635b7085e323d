"""Correctors of the master fixed point: ΔU_m = −G Σ_α r^α on each interface.

The paper's correctors (eqs. 5–8) blend one correction per body with β:
``ΔU_m = −[β K_C^A⁻¹ + (1 − β) K_C^B⁻¹] ½ Σ_α r^α``, with K_C the half-link ``h̄M``
(method 1), the solid's condensed stiffness ``K̂_ee`` (method 2) or its partial condensation
on a strip of element layers scaled by X (eqs. 9–10). The series corrector (METHOD.md §4)
uses the exact slope of each body's response, ``S^α = h̄M (h̄M + K̂_ee)⁻¹ K̂_ee``, and
converges in one correction on a single linear interface for any h.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from subdomain_contact.blocks import BodyBlocks, dofs_within_layers

__all__ = [
    "Corrector",
    "Method1",
    "Method2",
    "PartialCondensation",
    "Series",
    "paper_factor",
    "series_stiffness",
]

Matrix = npt.NDArray[np.float64]


class Corrector(Protocol):
    """Builds the dense operator G of one interface, one body at a time.

    ``part`` runs where the body lives (collective on its communicator) and returns a small
    dense matrix in master order; ``combine`` runs everywhere on the two parts.
    """

    name: str
    #: Whether ``part`` needs every body's condensed stiffness K̂ (bodies then factorise
    #: with their slave DOFs left as a Schur block, which gives K̂ at no extra cost).
    condense: bool

    def part(self, interface: str, body: BodyBlocks) -> Matrix:
        """The body's share: its K_C^α, or its S^α [W/K]."""
        ...

    def combine(
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        """G such that ΔU_m = −G Σ_α r^α [K/W]."""
        ...


def _inverse(K: Matrix, what: str) -> Matrix:
    if not np.all(np.isfinite(K)) or np.linalg.cond(K) > 1e15:
        raise ValueError(f"{what} is singular (a floating body?): use the series corrector")
    return np.linalg.inv(K)


@dataclass(frozen=True, kw_only=True)
class _Paper:
    """Paper eqs. (5), (7), (8): G = ½ [β K_C^A⁻¹ + (1 − β) K_C^B⁻¹]."""

    beta: float = 0.5
    name: str = "paper"
    condense: bool = False

    def combine(
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta = {self.beta}: must lie in [0, 1]")
        inverses = [
            _inverse(K, f"{self.name}: K_C of body '{b}' on '{interface}'")
            for K, b in zip(parts, bodies, strict=True)
        ]
        return 0.5 * (self.beta * inverses[0] + (1 - self.beta) * inverses[1])


@dataclass(frozen=True, kw_only=True)
class Method1(_Paper):
    """Paper method 1: K_C = K_mm = h̄M; for small h. Contracts by h̄/(h̄ + K̂) in 1D."""

    name: str = "method1"

    def part(self, interface: str, body: BodyBlocks) -> Matrix:  # noqa: D102
        return body.half_links[interface] * body.mass(interface)


@dataclass(frozen=True, kw_only=True)
class Method2(_Paper):
    """Paper method 2: K_C = K̂_ee, full condensation; for large h. Contracts by K̂/(h̄ + K̂)."""

    name: str = "method2"
    condense: bool = True

    def part(self, interface: str, body: BodyBlocks) -> Matrix:  # noqa: D102
        return body.condensed_stiffness(interface)


def paper_factor(refinement: int, layers: int = 1) -> float:
    """Paper eq. (10): X = 1 + Σ_{k=1..n} 1/(2^k N_i) for a mesh of step H/2^n, N_i layers."""
    return 1.0 + sum(1.0 / (2**k * layers) for k in range(1, refinement + 1))


@dataclass(frozen=True, kw_only=True)
class PartialCondensation(_Paper):
    """Paper §2: K̂_ee(X) = K_ee − X K_ei K_ii,strip⁻¹ K_ie on ``layers`` element layers.

    DOFs beyond the strip are clamped. X corrects the interface mode that is uniform along
    the contact; it is exact for that mode in 1D when X = (1 − 1/m)(N + 1)/N (m elements).
    """

    layers: int = 1
    factor: float = 1.0
    name: str = "partial"

    def part(self, interface: str, body: BodyBlocks) -> Matrix:  # noqa: D102
        if self.layers < 1 or not np.isfinite(self.factor) or self.factor <= 0:
            raise ValueError(f"partial condensation: layers = {self.layers}, X = {self.factor}")
        slaves = body.slaves[interface].local_dofs
        strip = dofs_within_layers(body.V, slaves, self.layers)
        K_ee, coupling = body.condensed(interface, np.setdiff1d(strip, slaves).astype(np.int32))
        return body.clamp_fixed(interface, K_ee - self.factor * coupling)


def series_stiffness(half_link_mass: Matrix, condensed: Matrix) -> Matrix:
    """S = ((h̄M)⁻¹ + K̂⁻¹)⁻¹ [W/K], computed as h̄M (h̄M + K̂)⁻¹ K̂.

    This form subtracts nothing (stable at any h̄) and allows a singular K̂ (floating body).
    """
    S = half_link_mass @ np.linalg.solve(half_link_mass + condensed, condensed)
    return 0.5 * (S + S.T)


@dataclass(frozen=True, kw_only=True)
class Series:
    """Exact corrector of METHOD.md §4: G = (S^A + S^B)⁻¹; one correction for any h."""

    name: str = "series"
    condense: bool = True

    def part(self, interface: str, body: BodyBlocks) -> Matrix:  # noqa: D102
        half_link_mass = body.half_links[interface] * body.mass(interface)
        return series_stiffness(half_link_mass, body.condensed_stiffness(interface))

    def combine(  # noqa: D102
        self, interface: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]
    ) -> Matrix:
        return _inverse(parts[0] + parts[1], f"S^A + S^B on '{interface}'")
