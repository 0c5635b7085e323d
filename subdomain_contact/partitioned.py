"""Partitioned couplings, as a user of a coupling library (preCICE) would set them up.

Two bodies, one contact of conductance h: a serial-implicit Robin–Robin exchange. Body A is
solved with the contact linked to B's last interface temperature, ``q = h (T_A − T_B)``; then
B with the contact linked to A's new one. The interface temperature of B is the coupling
unknown ``x``: one iteration is ``x ↦ x̃ = B(A(x))``, two body solves. Its fixed point is the
same discrete problem as the monolithic solve and the subdomain iteration (the merged master of
the half-links is the direct link ``h M``).

Acceleration of ``x ← x + update(r)``, ``r = x̃ − x``:

- ``"constant"``: ``x ← x + ω r``;
- ``"aitken"``: ω updated from the last two residuals (Küttler and Wall 2008);
- ``"iqn-ils"``: interface quasi-Newton with least-squares Jacobian from the secant history
  of residuals and outputs (Degroote et al. 2009; Anderson mixing), as in preCICE.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from subdomain_contact.blocks import BodyBlocks
from subdomain_contact.interfaces import master_layer
from subdomain_contact.thermal import ThermalProblem, body_forms

__all__ = ["ACCELERATIONS", "PartitionedResult", "solve_robin_robin"]

#: The accelerations :func:`solve_robin_robin` offers.
ACCELERATIONS = ("constant", "aitken", "iqn-ils")


@dataclass
class PartitionedResult:
    """Outcome of a partitioned coupling.

    Attributes:
        converged: Whether the relative interface change fell below the tolerance.
        iterations: Coupling iterations (two body solves each).
        history: ``‖x̃ − x‖ / ‖x̃‖`` per iteration.
        temperatures: Body name -> the body's temperature Function [K] at the end.
        seconds: Wall time [s].
    """

    converged: bool
    iterations: int
    history: list[float] = field(default_factory=list)
    temperatures: dict = field(default_factory=dict)
    seconds: float = 0.0


def solve_robin_robin(
    problem: ThermalProblem,
    *,
    acceleration: str = "iqn-ils",
    relaxation: float = 0.5,
    rtol: float = 1e-10,
    max_iterations: int = 200,
) -> PartitionedResult:
    """Serial Robin–Robin coupling of a two-body thermal problem.

    Args:
        problem: Two bodies and one contact interface.
        acceleration: One of :data:`ACCELERATIONS`.
        relaxation: ω of constant relaxation, and the first ω of Aitken and IQN-ILS.
        rtol: Tolerance on ``‖x̃ − x‖ / ‖x̃‖`` (preCICE's relative convergence measure).
        max_iterations: Coupling iterations allowed.

    Raises:
        ValueError: Not two bodies and one interface, or an unknown acceleration.
    """
    start = time.perf_counter()
    scene = problem.scene
    if len(scene.bodies) != 2 or len(scene.interfaces) != 1 or not scene.shared:
        raise ValueError(f"{scene.source}: Robin-Robin coupling needs two bodies, one interface")
    if acceleration not in ACCELERATIONS:
        raise ValueError(f"acceleration = {acceleration!r}: one of {ACCELERATIONS}")
    ((k, interface),) = scene.interfaces.items()
    layer = master_layer(interface)
    h = problem.contacts[k].conductance
    bodies = [
        BodyBlocks(
            name,
            body_forms(problem, scene.bodies[name]),
            scene.bodies[name].facet_tags,
            {k: layer},
            {k: h},  # the partner's temperature stands where the master was: a direct link
        )
        for name in interface.bodies
    ]
    update = _Update(acceleration, relaxation)
    x = np.zeros(layer.size)
    result = PartitionedResult(False, 0)
    for iteration in range(1, max_iterations + 1):
        data = x
        for body in bodies:
            T = body.solve({k: data})
            data = body.slaves[k].gather(T.x.array, layer.size, body.comm)
        r = data - x
        change = float(np.linalg.norm(r) / max(np.linalg.norm(data), 1e-300))
        result.history.append(change)
        result.iterations = iteration
        if not np.isfinite(change):
            break
        if change <= rtol:
            result.converged = True
            break
        x = update(x, data)
    result.temperatures = {body.name: body.T for body in bodies}
    result.seconds = time.perf_counter() - start
    return result


class _Update:
    """The next coupling input from the last input ``x`` and output ``x̃``."""

    def __init__(self, acceleration: str, relaxation: float) -> None:
        self.acceleration, self.omega = acceleration, relaxation
        self.residuals: list[np.ndarray] = []
        self.outputs: list[np.ndarray] = []

    def __call__(
        self, x: npt.NDArray[np.float64], output: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        r = output - x
        self.residuals.append(r)
        self.outputs.append(output)
        if self.acceleration == "aitken" and len(self.residuals) > 1:
            dr = r - self.residuals[-2]
            self.omega = -self.omega * float(self.residuals[-2] @ dr) / float(dr @ dr)
        if self.acceleration != "iqn-ils" or len(self.residuals) == 1:
            return x + self.omega * r
        V = np.diff(np.array(self.residuals), axis=0).T  # columns: Δr
        W = np.diff(np.array(self.outputs), axis=0).T  # columns: Δx̃
        alpha, *_ = np.linalg.lstsq(V, -r, rcond=None)
        return output + W @ alpha
