"""The subdomain fixed point of the paper (eqs. 5–8): bodies solved apart, masters corrected.

Each round solves every body with the master values fixed (one forward/backward substitution
with its kept factorisation), sums the two bodies' master residuals on each interface and
corrects the masters: ``U_m ← U_m − G Σ_α r^α``. Convergence is judged on each interface's
master residual relative to the flux through that interface (METHOD.md §5).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import dolfinx
import numpy as np
import numpy.typing as npt

from subdomain_contact.blocks import BodyBlocks
from subdomain_contact.correctors import Corrector, Series
from subdomain_contact.interfaces import MasterLayer, master_layer
from subdomain_contact.solvers import Reaper
from subdomain_contact.thermal import ThermalProblem, body_forms

__all__ = [
    "RoundMonitor",
    "SubdomainConvergenceError",
    "SubdomainResult",
    "ThermalSubdomains",
    "body_blocks",
    "relative_to_scale",
]

logger = logging.getLogger(__name__)


@dataclass
class SubdomainResult:
    """Solution of a subdomain solve.

    Attributes:
        temperatures: Body name -> temperature [K] (the body's own Function, updated in place),
            for the bodies that this rank's group solves.
        masters: Interface name -> master temperatures [K], replicated, in master order.
        rounds: Body-solve rounds (the last one is the check that converged).
        history: Largest master residual relative to its interface's flux scale, per round.
        seconds: Wall time of the iteration [s], set-up excluded.
    """

    temperatures: dict[str, dolfinx.fem.Function]
    masters: dict[str, npt.NDArray[np.float64]]
    rounds: int
    history: list[float] = field(default_factory=list)
    seconds: float = 0.0


class SubdomainConvergenceError(RuntimeError):
    """The fixed point diverged or did not converge; keeps the history and the last iterate."""

    def __init__(self, message: str, result: SubdomainResult) -> None:
        super().__init__(message)
        self.result = result


def body_blocks(
    problem: ThermalProblem, *, factorise: bool = True, condense: bool = False
) -> tuple[dict[str, MasterLayer], dict[str, BodyBlocks]]:
    """Every interface's master layer, and the blocks of the bodies this rank's group holds.

    ``factorise=False`` when the blocks only feed :func:`solve_monolithic`; ``condense``:
    see :class:`BodyBlocks`.
    """
    scene = problem.scene
    layers = {k: master_layer(i) for k, i in scene.interfaces.items()}
    blocks = {}
    for name, body in scene.bodies.items():
        if not scene.is_local(name):
            continue
        mine = {i.name: layers[i.name] for i in scene.interfaces_of(name)}
        halves = {k: problem.half_link(k) for k in mine}
        forms = body_forms(problem, body)
        blocks[name] = BodyBlocks(
            name, forms, body.facet_tags, mine, halves, factorise=factorise, condense=condense
        )
    return layers, blocks


#: Called after every round with its number and body name -> temperature of that round.
RoundMonitor = Callable[[int, dict[str, dolfinx.fem.Function]], None]


class ThermalSubdomains:
    """Thermal contact solved body by body through master layers.

    Set-up assembles and factorises every body once and builds each interface's corrector.

    Args:
        problem: Scene, materials, contacts and conditions.
        corrector: How the masters are corrected (default: the exact series corrector).
    """

    def __init__(self, problem: ThermalProblem, corrector: Corrector | None = None) -> None:
        start = time.perf_counter()
        Reaper.collect(problem.scene.comm)
        self.problem = problem
        self.corrector = corrector or Series()
        scene = problem.scene
        # the bodies this rank's group solves
        self.layers, self.blocks = body_blocks(problem, condense=self.corrector.condense)
        insulating = {k for k, c in problem.contacts.items() if c.conductance == 0}
        parts = self._everywhere(
            {
                (k, name): self.corrector.part(k, block)
                for name, block in self.blocks.items()
                for k in block.layers
                if k not in insulating
            }
        )
        self.operators = {  # an insulating contact's master residual is zero: no correction
            k: np.zeros((self.layers[k].size,) * 2)
            if k in insulating
            else self.corrector.combine(k, i.bodies, (parts[k, i.bodies[0]], parts[k, i.bodies[1]]))
            for k, i in scene.interfaces.items()
        }
        self.setup_seconds = time.perf_counter() - start

    def _everywhere(self, local: dict) -> dict:
        """Merge the groups' dictionaries (computed on their own bodies) on every rank."""
        scene = self.problem.scene
        if scene.shared:
            return local
        merged: dict = {}
        for part in scene.comm.allgather(local if scene.group_comm.rank == 0 else {}):
            merged.update(part)
        return merged

    def total(self, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Sum per-interface vectors of the local bodies over the groups (each counted once)."""
        scene = self.problem.scene
        if scene.shared:
            return values
        weight = 1.0 if scene.group_comm.rank == 0 else 0.0
        return {k: scene.comm.allreduce(weight * v) for k, v in values.items()}

    @property
    def num_dofs(self) -> dict[str, int]:
        """Global DOF count of every body and master layer (collective)."""
        counts = self._everywhere(
            {n: b.V.dofmap.index_map.size_global for n, b in self.blocks.items()}
        )
        counts.update({f"master:{k}": layer.size for k, layer in self.layers.items()})
        return counts

    def round(
        self, masters: dict[str, npt.NDArray[np.float64]]
    ) -> tuple[dict[str, npt.NDArray[np.float64]], dict[str, float]]:
        """Solve every body once: per interface, ``Σ_α r^α`` [W] and ``Σ_α ‖r^α‖`` [W]."""
        sums = {k: np.zeros(layer.size) for k, layer in self.layers.items()}
        pushed = dict.fromkeys(self.layers, 0.0)
        for block in self.blocks.values():
            block.solve(masters)
            for k, r in block.residuals(masters).items():
                sums[k] += r
                pushed[k] += float(np.linalg.norm(r))
        pushed_total = self.total({k: np.array([v]) for k, v in pushed.items()})
        return self.total(sums), {k: float(v[0]) for k, v in pushed_total.items()}

    def solve(
        self,
        *,
        rtol: float = 1e-10,
        max_rounds: int = 50,
        divergence: float = 1e6,
        monitor: RoundMonitor | None = None,
    ) -> SubdomainResult:
        """Iterate until ``‖Σ_α r_k^α‖ ≤ rtol · flux scale`` on every interface k.

        The flux scale of an interface is the flux [W] that its sides push into it in the
        first round (``Σ_α ‖r_k^α‖``, master values zero): a relative tolerance then means
        the same for a contact of h = 1e-8 beside a body with a 1e6 source as for h = 1e12.

        Args:
            rtol: Tolerance on the master residual relative to the flux scale.
            max_rounds: Body-solve rounds allowed.
            divergence: Stop when the relative residual grows past this multiple of its first value.
            monitor: Called after every round, before the correction (its time is the
                caller's to exclude).

        Raises:
            SubdomainConvergenceError: Diverged, non-finite or not converged in ``max_rounds``;
                its ``result`` holds the residual history and the last iterate.
        """
        start = time.perf_counter()
        masters = {k: np.zeros(layer.size) for k, layer in self.layers.items()}
        temperatures = {n: b.T for n, b in self.blocks.items()}
        result = SubdomainResult(temperatures, masters, 0)
        scales: dict[str, float] = {}
        for rounds in range(1, max_rounds + 1):
            sums, pushed = self.round(masters)
            if rounds == 1:
                scales = pushed
            relative = max(relative_to_scale(np.linalg.norm(sums[k]), scales[k]) for k in sums)
            result.rounds, result.seconds = rounds, time.perf_counter() - start
            result.history.append(relative)
            logger.info("round %d: relative master residual %.3e", rounds, relative)
            if monitor is not None:
                monitor(rounds, temperatures)
            if not np.isfinite(relative) or relative > divergence * result.history[0]:
                raise SubdomainConvergenceError(
                    f"{self.corrector.name}: the subdomain iteration diverged at round {rounds} "
                    f"(relative master residuals {_short(result.history)})",
                    result,
                )
            if relative <= rtol:
                return result
            for k, total in sums.items():
                masters[k] -= self.operators[k] @ total
        raise SubdomainConvergenceError(
            f"{self.corrector.name}: no convergence to {rtol:g} in {max_rounds} rounds "
            f"(relative master residuals {_short(result.history)})",
            result,
        )


def relative_to_scale(norm: float, scale: float) -> float:
    """``norm / scale``, or ``norm`` itself where nothing flowed (scale 0)."""
    return float(norm / scale) if scale > 0 else float(norm)


def _short(history: list[float]) -> str:
    """The first and last few residuals of a history, for error messages."""
    text = [f"{h:.2e}" for h in history]
    return ", ".join(text if len(text) <= 8 else [*text[:4], "…", *text[-3:]])
