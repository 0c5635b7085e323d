"""Partitioned couplings, as a user of a coupling library (preCICE) would set them up.

Two bodies, one contact of conductance h, solved one after the other (serial-implicit), the
second body's output fed back to the first until it stops changing:

- **Robin–Robin** (:func:`solve_robin_robin`): body A is solved with the contact linked to
  B's last interface temperature, ``q = h (T_A − T_B)``; then B with the contact linked to A's
  new one. The coupling unknown ``x`` is B's interface temperature [K].
- **Dirichlet–Neumann** (:func:`solve_dirichlet_neumann`): body A takes the heat that leaves
  it through the contact as a Neumann datum (nodal heat [W]); body B takes A's interface
  temperature through the contact (``q = h (T_A − T_B)``, the Dirichlet condition of perfect
  contact as h → ∞); B's nodal heat from the contact is the new datum. ``x`` is that nodal
  heat [W].

One iteration ``x ↦ x̃`` is two body solves. The fixed point is the same discrete problem as
the monolithic solve and the subdomain iteration (the merged master of the half-links is the
direct link ``h M``).

Acceleration of ``x ← x + update(r)``, ``r = x̃ − x``:

- ``"constant"``: ``x ← x + ω r``;
- ``"aitken"``: ω updated from the last two residuals (Küttler and Wall 2008);
- ``"iqn-ils"``: interface quasi-Newton with least-squares Jacobian from the secant history
  of residuals and outputs (Degroote et al. 2009; Anderson mixing), as in preCICE.

Convergence is preCICE's relative measure ``‖x̃ − x‖ / ‖x̃‖ ≤ rtol``: it says nothing of the
error, which at large h can stay far above rtol (demo_error_vs_runtime shows it).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import dolfinx
import numpy as np
import numpy.typing as npt

from subdomain_contact.body import Body
from subdomain_contact.masters import master_layer
from subdomain_contact.physics import Problem

__all__ = [
    "ACCELERATIONS",
    "Monitor",
    "PartitionedResult",
    "robin_robin_map",
    "solve_dirichlet_neumann",
    "solve_robin_robin",
]

#: The accelerations both couplings offer.
ACCELERATIONS = ("constant", "aitken", "iqn-ils")

#: Called after every coupling iteration with its number and body name -> its solution.
Monitor = Callable[[int, dict[str, dolfinx.fem.Function]], None]


@dataclass
class PartitionedResult:
    """Outcome of a partitioned coupling.

    Attributes:
        converged: Whether the relative interface change fell below the tolerance.
        iterations: Coupling iterations (two body solves each).
        diverged: Stopped because the exchanged data grew 1e8-fold past its size in the
            first five iterations, or stopped being finite.
        balance: Heat balance of the contact at the last iteration, relative to the heat
            through it (Dirichlet–Neumann: the relative change, which is that balance).
        history: ``‖x̃ − x‖ / ‖x̃‖`` per iteration.
        temperatures: Body name -> the body's temperature Function [K] at the end.
        data: The last coupling input ``x`` (the temperatures are its body solves).
        output: Its output ``x̃``.
        seconds: Wall time [s].
    """

    converged: bool
    iterations: int
    diverged: bool = False
    balance: float = float("nan")
    history: list[float] = field(default_factory=list)
    temperatures: dict = field(default_factory=dict)
    data: npt.NDArray[np.float64] | None = None
    output: npt.NDArray[np.float64] | None = None
    seconds: float = 0.0


class _Side:
    """One body of a partitioned coupling: solved for given master values and loads."""

    def __init__(self, problem: Problem, name: str, conductance: float) -> None:
        scene = problem.scene
        ((k, interface),) = scene.interfaces.items()
        contacts = {k: dataclasses.replace(problem.contacts[k], conductance=conductance)}
        own = Problem(scene, problem.materials, contacts, problem.conditions)
        self.k, self.layer = k, master_layer(own, interface)
        self.body = Body(own, scene.bodies[name], {k: self.layer}, prefix=f"sc_rr_{name}_")
        self.body.U.x.array[:] = 0.0
        self.body.apply_conditions()
        self.start = self.body.U.x.array.copy()
        self.body.set_masters({k: np.zeros(self.layer.size)})
        self.body.assemble()
        self.body.factorise()

    def solve(
        self, master: npt.NDArray[np.float64], load: npt.NDArray[np.float64] | None = None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Temperatures on the contact and the heat [W] the body takes from it.

        ``master``: the temperatures [K] its link sees; ``load``: nodal heat [W] put into the
        body at its slave DOFs (none at fixed ones), in master order.
        """
        body, k = self.body, self.k
        body.U.x.array[:] = self.start
        body.set_masters({k: master})
        F = body.residual()
        if load is not None:
            nodal = np.zeros(body.size)
            body.slaves[k].scatter(load, nodal)
            nodal[body.fixed_local] = 0.0
            F -= nodal
        body.U.x.array[: body.size] -= body.solve(F)  # linear: one Newton step is exact
        body.U.x.scatter_forward()
        taken = -body.contact_outflow(k, load)
        return body.slaves[k].gather(body.U.x.array, self.layer.size, body.comm), taken


def solve_robin_robin(
    problem: Problem,
    *,
    acceleration: str = "iqn-ils",
    relaxation: float = 0.5,
    rtol: float = 1e-10,
    max_iterations: int = 200,
    monitor: Monitor | None = None,
    balance_tol: float = 1e-6,
) -> PartitionedResult:
    """Serial Robin–Robin coupling of a two-body thermal problem.

    Args:
        problem: Two bodies, one contact interface, temperature alone.
        acceleration: One of :data:`ACCELERATIONS`.
        relaxation: ω of constant relaxation, and the first ω of Aitken and IQN-ILS.
        rtol: Tolerance on ``‖x̃ − x‖ / ‖x̃‖`` (preCICE's relative convergence measure).
        max_iterations: Coupling iterations allowed.
        monitor: Called after every iteration (its time is the caller's to exclude).
        balance_tol: Tolerance on the heat balance ``‖q_A + q_B‖ / ‖q‖`` of the contact, the
            nodal heats the two bodies take from it. A small change of the interface
            temperature can hide a large imbalance when h is large (the flux is h times
            it): without this check the coupling "converges" to wrong answers.

    Raises:
        ValueError: Not two bodies and one interface, or an unknown acceleration.
    """
    iterate, size, sides = _robin_robin(problem, acceleration)
    update = _Update(acceleration, relaxation)
    return _couple(iterate, update, size, sides, rtol, max_iterations, monitor, balance_tol)


def robin_robin_map(problem: Problem) -> Callable[[np.ndarray], np.ndarray]:
    """The Robin-Robin iteration ``x ↦ x̃`` itself (B's interface temperatures [K]).

    It is affine, ``x̃ = M x + c``: probing it gives the iteration matrix M, whose
    ``‖(I − M)⁻¹‖`` turns the coupling's stopping rule into a bound on its error.
    """
    iterate, _, _ = _robin_robin(problem, "constant")
    return lambda x: iterate(x)[0]


def _robin_robin(problem: Problem, acceleration: str):
    """One Robin-Robin iteration ``x ↦ (x̃, heat balance)``, the data size and the sides."""
    first, second = _sides(problem, acceleration, "Robin-Robin", neumann=False)

    def iterate(x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float]:
        data, taken = first.solve(x)  # heat A takes from the contact [W]
        output, given = second.solve(data)  # heat B takes from it
        scale = max(float(np.linalg.norm(given)), float(np.linalg.norm(taken)), 1e-300)
        return output, float(np.linalg.norm(taken + given)) / scale

    return iterate, first.layer.size, (first, second)


def solve_dirichlet_neumann(
    problem: Problem,
    *,
    acceleration: str = "iqn-ils",
    relaxation: float = 0.5,
    rtol: float = 1e-10,
    max_iterations: int = 200,
    monitor: Monitor | None = None,
    balance_tol: float = 1e-6,
) -> PartitionedResult:
    """Serial Dirichlet–Neumann coupling: heat to body A, temperature to body B.

    Arguments as :func:`solve_robin_robin`. Body A must have a temperature condition (it is
    solved with the contact as a pure Neumann boundary); a floating A fails its solve.
    """
    first, second = _sides(problem, acceleration, "Dirichlet-Neumann", neumann=True)
    size = first.layer.size

    def iterate(x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], float | None]:
        data, _ = first.solve(np.zeros(size), load=-x)  # x: heat leaving A [W]
        _, given = second.solve(data)
        # the heat B takes [W]; its change from x is the heat balance itself
        return given, None

    update = _Update(acceleration, relaxation)
    return _couple(
        iterate, update, size, (first, second), rtol, max_iterations, monitor, balance_tol
    )


def _sides(problem: Problem, acceleration: str, coupling: str, *, neumann: bool):
    """The two bodies, factorised, each linked directly to the partner's values.

    A link of conductance h to the partner's values stands where the half-link was; the
    first body has none when it takes a Neumann datum.
    """
    scene = problem.scene
    if len(scene.bodies) != 2 or len(scene.interfaces) != 1 or problem.fields != ("temperature",):
        raise ValueError(
            f"{scene.source}: {coupling} coupling needs two bodies, one interface, heat alone"
        )
    if not scene.shared:
        raise ValueError(
            f"{scene.source}: {coupling} coupling needs both bodies on the same ranks: load the "
            "scene with placement='shared' (under mpiexec the default puts them on rank groups)"
        )
    if acceleration not in ACCELERATIONS:
        raise ValueError(f"acceleration = {acceleration!r}: one of {ACCELERATIONS}")
    ((k, interface),) = scene.interfaces.items()
    h = float(problem.contacts[k].conductance)
    # a half-link of conductance h/2 is a direct link h to the partner's temperature
    return tuple(
        _Side(problem, name, 0.0 if neumann and i == 0 else h / 2)
        for i, name in enumerate(interface.bodies)
    )


def _couple(
    iterate: Callable,
    update: _Update,
    size: int,
    sides: tuple[_Side, _Side],
    rtol: float,
    max_iterations: int,
    monitor: Monitor | None,
    balance_tol: float,
) -> PartitionedResult:
    """Iterate ``x ← update(x, iterate(x))`` from x = 0 until change and balance are met."""
    start = time.perf_counter()
    x = np.zeros(size)
    result = PartitionedResult(False, 0)
    first, divergence = 0.0, 1e8
    temperatures = {side.body.name: side.body.U for side in sides}
    for iteration in range(1, max_iterations + 1):
        output, balance = iterate(x)
        change = float(np.linalg.norm(output - x) / max(np.linalg.norm(output), 1e-300))
        result.balance = change if balance is None else balance
        result.history.append(change)
        result.iterations, result.data, result.output = iteration, x, output
        if monitor is not None:
            monitor(iteration, temperatures)
        size_now = float(np.linalg.norm(output))
        first = max(first, size_now) if iteration <= 5 else first  # the data's own scale
        if not np.isfinite(change) or size_now > divergence * max(first, 1e-300):
            result.diverged = True
            break
        if change <= rtol and result.balance <= balance_tol:
            result.converged = True
            break
        x = update(x, output)
    result.temperatures = temperatures
    result.seconds = time.perf_counter() - start
    for side in sides:
        side.body.destroy()
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
        dr = r - self.residuals[-2] if len(self.residuals) > 1 else r
        if self.acceleration == "aitken" and len(self.residuals) > 1 and dr @ dr > 0:
            self.omega = -self.omega * float(self.residuals[-2] @ dr) / float(dr @ dr)
        if self.acceleration != "iqn-ils" or len(self.residuals) == 1:
            return x + self.omega * r
        V = np.diff(np.array(self.residuals), axis=0).T  # columns: Δr
        W = np.diff(np.array(self.outputs), axis=0).T  # columns: Δx̃
        alpha, *_ = np.linalg.lstsq(V, -r, rcond=None)
        return output + W @ alpha
