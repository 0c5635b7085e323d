"""The subdomain iteration: a linear solver of the whole system that solves bodies apart.

``J y = b`` (a Newton step, or the whole problem when it is linear) is solved by rounds of
body solves with the master increments fixed (METHOD.md §3): every body solves its own
factorised system, returns its share of each master residual in the reaction form, and the
master increments are corrected.

* The paper's **fixed point** (eqs. 5–8) corrects each interface on its own,
  ``y_m,k ← y_m,k − G_k R_k``, with a corrector's G (:mod:`~subdomain_contact.correctors`).
* The **interface Krylov** solve treats every interface at once: the master residual is affine
  in the master increments, with slope ``S = Σ_α S^α`` (the primal Schur complement of the
  scene), so ``S y_m = −R(0)`` is solved by CG (a symmetric problem) or GMRES, preconditioned by
  the per-interface correctors (or the sparse strip corrector) with a balancing coarse
  correction of a few unknowns per body (its constants for T and φ, its rigid motions for
  u), as in balancing domain decomposition (Mandel 1993). ``S^α`` is applied as a dense
  matrix where the body's factorisation gives it cheaply or where the body has few master
  DOFs, else by one homogeneous body solve. A round of body solves then checks the true
  residual, and refines if round-off left it short; inside Newton, where the refinements stop
  gaining on the round-off of the body solves, its best round is an inexact Newton step
  (:data:`FLOOR_ACCEPTED`).

The solve stops when every interface's master residual is below ``rtol`` times its flux scale
(per channel: what its bodies push into it at the first round), or, inside Newton, when each
field's master residual is below its own absolute tolerance.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.correctors import Corrector, Exact, SparseStrip, StripSolve
from subdomain_contact.masters import MasterLayer
from subdomain_contact.modes import Mode, modes
from subdomain_contact.physics import FIELDS
from subdomain_contact.solvers import default_option
from subdomain_contact.system import System

__all__ = [
    "InterfaceResult",
    "SubdomainConvergenceError",
    "Subdomains",
    "Tolerance",
]

Vector = npt.NDArray[np.float64]
Matrix = npt.NDArray[np.float64]

#: Called after every round and every Krylov iteration with the running count and a function
#: that returns the iterate ``y`` (global-vector layout; for a Krylov iterate it solves the
#: bodies, a round whose time, like the monitor's, is the caller's to exclude).
Monitor = Callable[[int, Callable[[], Vector]], None]


@dataclass(frozen=True)
class Tolerance:
    """When the master residual is small enough.

    Attributes:
        rtol: Relative to each interface channel's flux scale (its bodies' pushes at the
            first round).
        atol: Field name -> absolute tolerance on the 2-norm of that field's master residual
            over every interface [W, A, N]; where given, it replaces ``rtol``.
    """

    rtol: float = 1e-10
    atol: Mapping[str, float] | None = None


@dataclass
class InterfaceResult:
    """Outcome of one linear solve by the subdomain iteration.

    Attributes:
        rounds: Rounds of body solves that checked the true residual.
        history: Largest master residual relative to its channel's flux scale, per round.
        krylov_iterations: Krylov iterations of each refinement step (empty: fixed point).
        applications: Operator applications by homogeneous body solves (matrix-free S^α).
        body_iterations: Krylov iterations of the iterative body solves, over every body.
        converged: Whether the tolerance was met.
        short_by: Where the interface Krylov stopped at the round-off of its body solves
            short of an absolute tolerance (:data:`FLOOR_ACCEPTED`): the factor by which the
            solution it returned missed it (> 1); 0 otherwise.
        seconds: Wall time [s].
    """

    rounds: int = 0
    history: list[float] = field(default_factory=list)
    krylov_iterations: list[int] = field(default_factory=list)
    applications: int = 0
    body_iterations: int = 0
    converged: bool = False
    short_by: float = 0.0
    seconds: float = 0.0


class SubdomainConvergenceError(RuntimeError):
    """The subdomain iteration diverged or did not converge; keeps its result.

    ``iterate``: the master increments an interface Krylov solve stopped at by its iteration
    limit had reached (None otherwise).
    """

    def __init__(
        self, message: str, result: InterfaceResult, iterate: dict[str, Vector] | None = None
    ) -> None:
        super().__init__(message)
        self.result, self.iterate = result, iterate


#: An iterative body solve stops at this fraction of the interface's relative tolerance: its
#: error enters the master residual the body returns, and must not decide its convergence.
BODY_RTOL_FACTOR = 1e-2

#: Inside the interface Krylov an operator application may be less exact as the residual
#: falls (relaxed inexact Krylov, van den Eshof & Sleijpen 2004): the body solves of
#: iteration j stop at ``RELAXATION / ‖W r_j‖`` (W: the weights that make the Krylov
#: target ‖W r‖ ≤ ½), never looser than :data:`RELAXED_LOOSEST`, both divided by the
#: heaviest error weight (:meth:`Subdomains._error_weights`); the true rounds that check the
#: solution keep the tight tolerance.
RELAXATION, RELAXED_LOOSEST = 5e-3, 1e-4

#: The largest weight of a master's residual (:meth:`Subdomains._error_weights`): an open
#: contact's master, held by the master equation's tie (1e-6 of the contact's stiffness,
#: ``physics.MASTER_TIE``), weighs up to about 1e8 more than its neighbours (the row of four
#: 3D blocks at 300 K: 1.4e8, and 1e11 with the ties of 1e-9 before; the collector bar slot
#: 1e10 then); a still weaker link is not to push its master's target below round-off.
MAX_ERROR_WEIGHT = 1e12

#: Singular values of a body's rows of the coarse basis (orthonormal columns, so σ ≤ 1)
#: below this add no body solve to the coarse matrix (:meth:`Subdomains._image`): what they
#: drop is below the error of the body solves (``BODY_RTOL_FACTOR`` × 1e-10 at the tightest).
COARSE_RANK = 1e-12

#: An inner solve of Newton (absolute tolerances) whose true rounds stop falling has reached
#: the round-off of its body solves: a refinement's Krylov solve meets ‖W r‖ ≤ ½ in its own
#: model, so without that round-off the true round after it meets the tolerance; where it
#: misses, and the next refinement does not halve the miss, another one only draws another
#: sample of the same noise (the row of four 3D blocks at 1.01M DOFs, 2 ranks: weighed
#: displacement residuals of 1.05, 9.2, then 0.39 times the tolerance, each after a Krylov
#: solve of 1 iteration; open contacts' masters weighed 1e9 with raw residuals of 1e-8 N,
#: the body solves' 1e-12). The best true round is then returned as an inexact Newton step
#: if it missed by at most this factor: the step's forcing is at most this times η, and η ≤
#: ``newton.FORCING_ITERATIVE`` = 1e-4 and ≤ the slowest field's progress P, so ≤ 1e-2 and
#: falling to zero with P, where inexact Newton needs < 1 to converge and a forcing that
#: falls to zero to converge superlinearly (Dembo, Eisenstat & Steihaug 1982); Newton's own
#: residual, not this step, decides when it has converged. The floor is a sample of the
#: body solves' round-off: at the second Newton step of that row (three runs) the best true
#: round missed by 11.4 and 23.9 (default settings, after 12 and 4 rounds) and 8.1
#: (``lag=True``), and 10, the factor until 2026-12-07, failed the first run's full-step
#: Newton there (the limited-step Newton that followed took 677 of its 944.6 s); 100 is
#: four times the largest miss measured.
FLOOR_ACCEPTED = 100.0

#: A kept (lagged) preconditioner is rebuilt after a solve that needed more than this many
#: times the interface Krylov iterations of its reference solve (plus one): the first solve
#: after its build (one that went on from a stopped solve counts at least the last solve that
#: began with a new build).
#: Rebuilding costs a factorisation of the strip and one application of ``S`` per coarse
#: mode (up to 8 per body), each application a solve of every body the mode touches: on
#: four 3D blocks with iterative bodies (T, φ, u) that was 3.9 s per Newton step against
#: 1.6 s for the whole interface solve.
LAG_GROWTH = 2.0

#: Kept builds found stale one after another (a solve stopped by :data:`LAG_GROWTH`'s limit,
#: or slowed past it) after which the preconditioner is rebuilt at every set-up for the
#: solver's life: where the Jacobian moves too far between steps for any kept build to
#: serve, keeping only adds a stopped solve and a round to every step. The collector bar
#: slot at 34,510 DOFs (its block by the sweep, 2 ranks, ``lag=True``) found every kept build
#: stale from its fifth step on (fresh builds 4-14 Krylov iterations, kept 48-99); the row
#: of four 3D blocks at 74,580 DOFs never two in a row (13 steps, 4 builds).
STALE_IN_A_ROW = 2


@dataclass(frozen=True)
class Kernel:
    """A body's own modes that solve it as they are (:meth:`Subdomains._find_kernels`).

    Attributes:
        traces: The modes on the body's masters (its interfaces in ``layers`` order) × modes.
        fit: The pseudo-inverse of ``traces``: master values -> the modes' amplitudes.
        values: The modes on the body's owned DOFs [K, V or m per unit amplitude].
        answers: Interface -> the body's master residuals for each mode (rows × modes).
    """

    traces: Matrix
    fit: Matrix
    values: Matrix
    answers: dict[str, Matrix]


class Subdomains:
    """The subdomain iteration as the linear solver of a system (``setup`` / ``solve``).

    Args:
        corrector: How the masters are corrected. Default: the exact corrector; where a body
            is not condensed (solved iteratively, spread over several ranks, or with many
            contact DOFs: :func:`~subdomain_contact.schur.condensation`) and more master DOFs than
            ``dense_limit`` (its exact part would cost one body solve per master DOF), the
            exact corrector on a strip (:class:`~subdomain_contact.correctors.SparseStrip`)
            as the preconditioner of the interface Krylov, which applies that body's ``S^α``
            by one body solve per iteration.
        krylov: ``True``: GMRES (CG for a symmetric problem) on every interface at once;
            ``False``: the paper's fixed point; ``None``: Krylov where some body touches
            several interfaces, floats, is solved iteratively or is spread with many master
            DOFs (above), else the fixed point.
        coarse: Add the coarse correction to the Krylov preconditioner.
        lag: Where some body is solved iteratively (by AMG or by the factorised sweep),
            keep the interface Krylov's preconditioner (the strip's factorisation, the coarse
            matrix, whose columns cost iterative body solves) from one set-up to the next
            (Newton steps, time steps) while it serves: it is rebuilt when the active master
            DOFs change, and at once when a Krylov solve with it needs more than
            :data:`LAG_GROWTH` times the iterations of its reference solve (the first after
            the build), the stopped solve then going on from its iterate with the new build,
            unless its strip's new factorisation would not fit in the memory left (kept
            then, and counted in ``kept_for_memory``; where a rebuild is needed, a
            ``MemoryError`` says so before the system kills a rank); after
            :data:`STALE_IN_A_ROW` kept builds found stale one after another it is rebuilt
            at every set-up. It only preconditions: the true rounds use the current bodies.
            With factorised bodies the rebuild costs less than the rounds and iterations a
            kept one adds (the collector bar slot at 17k DOFs, 18 Newton steps: 51.5 s
            rebuilt at every step, 58.5 s kept; four 3D blocks at 31k DOFs: 25.6 s and
            29.2 s; the slot nested to 174,240 DOFs, 2 ranks: 486.3 s and 530.5 s, 3 strip
            factorisations saved and 5 rounds added), so there it is rebuilt every time.
            With bodies by the sweep (2 ranks, 2026-12-07): the row of four 3D blocks
            (``bench_3d_bodies.py``), 632.2 s kept against 701.7 s rebuilt at 1.01M DOFs
            (the monolithic field split 628.0 and 610.4 s in the same runs), 21.5 s against
            25.0 s at 74,580; the collector bar slot at 34,510 DOFs, its block by the sweep,
            32.1 s against 34.3 s (kept until its third step, then stale twice in a row;
            79.4 s before :data:`STALE_IN_A_ROW`). ``False``: rebuilt at every set-up.
        dense_limit: A body with more master DOFs than this applies ``S^α`` by a body solve
            instead of a dense matrix. By default a body condensed on its contact DOFs
            forms it (from its Schur block, or a thin body by multi-column solves), and
            any other up to 32 master DOFs (forming it costs one body solve per master
            DOF).
        max_rounds: Rounds of the fixed point, or Krylov iterations per refinement step.
        max_refinements: Krylov refinement steps after the first.
        divergence: The fixed point stops when its residual grows past this multiple of its
            first value.
        prefix: Options prefix of the interface Krylov solver (``-<prefix>ksp_*``).
        monitor: Called after every round and Krylov iteration.
    """

    def __init__(
        self,
        corrector: Corrector | None = None,
        *,
        krylov: bool | None = None,
        coarse: bool = True,
        lag: bool = True,
        dense_limit: int | None = None,
        max_rounds: int = 100,
        max_refinements: int = 5,
        divergence: float = 1e6,
        prefix: str = "sc_interface_",
        monitor: Monitor | None = None,
    ) -> None:
        self.given, self.corrector = corrector, corrector or Exact()
        self.krylov, self.coarse, self.dense_limit = krylov, coarse, dense_limit
        self.lag = lag
        self._built: dict | None = None  # what the kept preconditioner was built for
        self._lagged = False  # whether this set-up kept it
        self._stale_in_a_row = 0  # kept builds found stale one after another
        self._fresh = 0  # iterations of the last solve that began with a new build
        self.max_rounds, self.max_refinements = max_rounds, max_refinements
        self.divergence, self.prefix, self.monitor = divergence, prefix, monitor
        self._body_rtol = BODY_RTOL_FACTOR * Tolerance().rtol
        self.error_weights: dict[str, Vector] | None = None  # set by setup
        self.system: System | None = None
        self.strip: StripSolve | None = None  # the sparse strip corrector's operator
        #: Body -> its own modes that solve it as they are (:meth:`_find_kernels`).
        self.kernels: dict[str, Kernel] = {}
        self._freed_factorisations = 0
        #: Set-ups that kept a slowing preconditioner because the sparse strip's new
        #: factorisation would not fit in memory (:meth:`StripSolve.fits`)
        self.kept_for_memory = 0

    @property
    def factorisations(self) -> int:
        """Sparse factorisations of the solver's own (the sparse strip corrector's)."""
        current = self.strip.factorisations if self.strip is not None else 0
        return self._freed_factorisations + current

    def destroy(self) -> None:
        """Free the sparse strip corrector's matrix and factorisation (collective)."""
        if self.strip is not None:
            self._freed_factorisations += self.strip.factorisations
            self.strip.destroy()
            self.strip = None
        self._built = None

    # -- set-up ---------------------------------------------------------------------------
    def check(self, system: System) -> None:
        """Nothing to refuse: the subdomain iteration takes every system."""

    def setup(self, system: System) -> None:
        """Factorise the assembled bodies; build the correctors (and Krylov's operators)."""
        if self.system is not system:
            self.destroy()
        self.system = system

        def factorise() -> None:
            for body in system.bodies.values():
                body.factorise()

        together(system.comm, factorise)
        scene = system.problem.scene
        costly = system.comm.allreduce(
            any(not (b.condensed or self._dense(b)) for b in system.bodies.values()),
            op=MPI.LOR,
        )
        if self.given is None:
            self.corrector = SparseStrip() if costly else Exact()
        if self.krylov is None:
            several = any(len(scene.interfaces_of(b)) > 1 for b in scene.bodies)
            self.use_krylov = several or any(system.floating.values()) or costly
        else:
            self.use_krylov = bool(self.krylov)
        names = list(system.sizes)
        ends = np.cumsum([0] + [system.sizes[k] for k in names])
        self.slices = {k: slice(int(ends[i]), int(ends[i + 1])) for i, k in enumerate(names)}
        self.size = int(ends[-1])
        active = np.concatenate([system.active[k] for k in names]) if names else []
        kept = self._built is not None and self._built["system"] is system
        kept = kept and type(self.corrector) is self._built["corrector"]
        kept = kept and np.array_equal(self._built["active"], active)
        self.active = active
        self._applications, self._iterations_done = 0, 0
        if self.use_krylov:
            self.dense = {
                name: body.interface_stiffness()
                for name, body in system.bodies.items()
                if self._dense(body)
            }
        self.kernels = self._find_kernels() if self.use_krylov else {}
        iterative = system.comm.allreduce(
            any(b.iterative for b in system.bodies.values()), op=MPI.LOR
        )
        weigh = self.use_krylov and iterative and not system.symmetric
        weigh = weigh and "displacement" in system.problem.fields
        self.error_weights = self._error_weights() if weigh else None
        kept_for = any(b.iterative for b in system.bodies.values())  # a build's Krylov solves
        kept_for = system.comm.allreduce(kept_for, op=MPI.LOR)
        lag = self.lag and self.use_krylov and kept_for
        tired = self._stale_in_a_row >= STALE_IN_A_ROW  # kept builds stopped serving
        self._lagged = lag and kept and not self._built["stale"] and not tired
        if lag and kept and not self._lagged and not self._room_for_strip():
            self._lagged = True  # slower, but a new factorisation of the strip would not fit
        if not self._lagged:
            self._build_preconditioner()

    def _error_weights(self) -> dict[str, Vector]:
        """Per master DOF of a displacement: ``Σ_α K_α / Σ_α S_α`` (≥ 1), else 1.

        ``S_α = (1/l_α + 1/K_α)⁻¹`` is the series law of the half-link ``l_α`` and the body
        ``K_α`` (row sums, :meth:`Body.master_stiffness`, ``l_α`` from the master's own
        block): the order of the interface operator's diagonal, which is ``Σ K_α`` where the
        links are stiff. A master held by weak links only (an open contact's, tied in the
        master equation by ``physics.MASTER_TIE`` × ``open_stiffness`` = 1e-6 of the
        contact's stiffness) answers a residual ``r`` with an error ``r / Σ S_α``, up to
        about 1e8 times that of a master between stiff links; and each half-link reads its
        closure, hence the contact's status, against that master. Its residual is
        therefore weighed by this factor, in the Krylov solve and in its stopping test, so
        that its error, not its residual, meets the tolerance (the collector bar slot with
        an iterative block: docs/iterative_bodies.md).

        Not used where every body is factorised (:meth:`setup`): the interface Krylov then
        meets the forcing of 1e-8 (``newton.FORCING``), which holds the path, and a floating
        body held by ties alone at a cold start (the row of four 3D blocks of the tests)
        makes the weighed target unreachable in round-off. Nor for a symmetric problem: CG
        takes one weight for every DOF, which this would make 1e8 times too tight for the
        others, nor without a displacement.
        """
        system = self.system
        bulk = {k: np.zeros(n) for k, n in system.sizes.items()}
        series = {k: np.zeros(n) for k, n in system.sizes.items()}

        def gather() -> None:
            for body in system.bodies.values():
                for k in body.layers:
                    link, stiff = body.master_stiffness(k)
                    bulk[k] += stiff
                    total = link + stiff
                    series[k] += np.divide(link * stiff, total, out=np.zeros_like(total),
                                           where=total > 0)  # fmt: skip

        together(system.comm, gather)
        bulk, series = system.total(bulk), system.total(series)
        displacement = FIELDS.index("displacement")
        out = {}
        for k in system.sizes:
            weights = np.ones(system.sizes[k])
            on = (system.master_fields[k] == displacement) & (series[k] > 0)
            weights[on] = np.clip(bulk[k][on] / series[k][on], 1.0, MAX_ERROR_WEIGHT)
            out[k] = weights
        return out

    def _build_preconditioner(self) -> None:
        """The correctors' operators (the sparse strip's factorisation) and the coarse space."""
        system, scene = self.system, self.system.problem.scene
        if isinstance(self.corrector, SparseStrip):
            self.strip, self.operators = self.corrector.build(system, self.strip), {}
        else:
            parts = system.everywhere(
                {
                    (k, name): self._part(k, body)
                    for name, body in system.bodies.items()
                    for k in body.layers
                }
            )
            self.operators = {
                k: self._combine(k, i.bodies, (parts[k, i.bodies[0]], parts[k, i.bodies[1]]))
                for k, i in scene.interfaces.items()
            }
        if self.use_krylov:
            self._build_coarse()
        self._lagged = False
        self._built = {"system": system, "corrector": type(self.corrector),
                       "active": self.active, "stale": False, "iterations": None}  # fmt: skip

    def _build_coarse(self) -> None:
        """The coarse space's orthonormal basis Z and matrix ``Zᵀ S Z`` (None without modes)."""
        self.coarse_basis = self._coarse_basis() if self.coarse else np.zeros((self.size, 0))
        self.coarse_matrix = self.coarse_image = None
        if self.coarse_basis.size:
            # a preconditioner's part, built with the loosest applications of the Krylov
            # solve, not with whatever tolerance the last solve left (the row of four
            # blocks at 219k DOFs: 1e-12 after a true round, 3,349 body GMRES iterations
            # and 80.8 s for one build, 10-14 s for the others)
            self._tighten(max(self._body_rtol, RELAXED_LOOSEST / self._heaviest()))
            self.coarse_image = self._image(self.coarse_basis)
            self.coarse_matrix = self.coarse_basis.T @ self.coarse_image
            self._tighten()

    def _dense(self, body) -> bool:
        masters = sum(body.master_sizes())
        if self.dense_limit is None:
            return body.condensed or masters <= 32
        return masters <= self.dense_limit

    def _part(self, k: str, body) -> Matrix:
        """The corrector's part on the active master DOFs of k (zero where insulating)."""
        active = self.system.active[k]
        if not active.any():
            return np.zeros((active.size,) * 2)
        return self.corrector.part(k, body)

    def _combine(self, k: str, bodies: tuple[str, str], parts: tuple[Matrix, Matrix]) -> Matrix:
        """G_k on the active master DOFs of k, zero on the others."""
        active = self.system.active[k]
        G = np.zeros((active.size,) * 2)
        if active.any():
            at = np.ix_(active, active)
            G[at] = self.corrector.combine(k, bodies, (parts[0][at], parts[1][at]))
        return G

    # -- rounds ---------------------------------------------------------------------------
    def _round(
        self, b: Vector | None, increments: Mapping[str, Vector]
    ) -> tuple[Vector, dict[str, Vector], dict[str, Vector]]:
        """Solve every body with master increments; the master residual and flux scale.

        Returns the solution (global-vector layout), interface -> ``Σ_α r_k^α − b_m,k`` and
        interface -> per-channel flux scale ``Σ_α ‖r_kc^α‖ + ‖b_m,kc‖``.
        """
        system = self.system
        out = np.zeros(system.local_size)
        local = {k: np.zeros(n) for k, n in system.sizes.items()}
        pushed = {k: np.zeros(len(layer.channels)) for k, layer in system.layers.items()}

        def solve_bodies() -> None:
            for name, body in system.bodies.items():
                rhs = None if b is None else b[system.slices[name]]
                masters = {k: increments[k][:, None] for k in body.layers}
                c, rest = self._off_kernel(name, body, masters)
                y, shares = body.round(rhs, {k: v[:, 0] for k, v in rest.items()})
                if c is not None:  # the body's own modes, solved as they are
                    kernel = self.kernels[name]
                    y = y + kernel.values @ c[:, 0]
                    shares = {k: r + kernel.answers[k] @ c[:, 0] for k, r in shares.items()}
                out[system.slices[name]] = y
                for k, r in shares.items():
                    local[k] += r
                    pushed[k] += self._channel_norms(k, r)

        together(system.comm, solve_bodies)
        totals, pushed = system.total(local), system.total(pushed)
        given = system.split_masters(b[system.master_slice]) if b is not None else None
        for k in totals:
            if given is not None:
                totals[k] = totals[k] - given[k]
                pushed[k] = pushed[k] + self._channel_norms(k, given[k])
            totals[k] = np.where(system.active[k], totals[k], 0.0)
        out[system.master_slice] = system.join_masters(increments)
        return out, totals, pushed

    def _flux_scales(self, pushed: dict[str, Vector]) -> dict[str, Vector]:
        """Each channel's flux scale; where nothing flowed at first, its field's largest."""
        largest: dict[str, float] = {}
        for k, layer in self.system.layers.items():
            for c, (f, _) in enumerate(layer.channels):
                largest[f] = max(largest.get(f, 0.0), float(pushed[k][c]))
        out = {}
        for k, layer in self.system.layers.items():
            fallback = np.array([largest[f] or 1.0 for f, _ in layer.channels])
            out[k] = np.where(pushed[k] > 0, pushed[k], fallback)
        return out

    def _channel_norms(self, k: str, r: Vector) -> Vector:
        layer = self.system.layers[k]
        return np.linalg.norm(np.reshape(r, (len(layer.channels), layer.nodes)), axis=1)

    def _measure(
        self, residual: dict[str, Vector], scales: dict[str, Vector], tolerance: Tolerance
    ) -> tuple[float, bool, float]:
        """Largest residual relative to its channel's scale; whether it is small enough.

        And, against absolute tolerances, the largest field's residual over its own (else inf).
        """
        relative = 0.0
        for k, r in residual.items():
            norms = self._channel_norms(k, r)
            relative = max(relative, float(np.max(norms / scales[k], initial=0.0)))
        if tolerance.atol is None:
            return relative, relative <= tolerance.rtol, np.inf
        norms, atol = self.system.master_field_norms(residual), tolerance.atol
        miss = max(norms[f] / max(atol[f], 1e-300) for f in norms)
        return relative, all(norms[f] <= atol[f] for f in norms), miss

    def _weighed(self, residual: dict[str, Vector]) -> dict[str, Vector]:
        """Each master's residual times its error weight, if any (:meth:`_error_weights`)."""
        if self.error_weights is None:
            return residual
        return {k: self.error_weights[k] * r for k, r in residual.items()}

    # -- solve ------------------------------------------------------------------------------
    def solve(self, b: Vector | None, tolerance: Tolerance) -> tuple[Vector, InterfaceResult]:
        """``y`` with ``J y = b`` (global-vector layout); raises if it does not converge.

        Args:
            b: Right-hand side in the global-vector layout (zero on fixed DOFs).
            tolerance: When to stop.

        Raises:
            SubdomainConvergenceError: Diverged, or not converged within the limits; the
                message names the corrector and what to try instead.
        """
        start = time.perf_counter()
        result = InterfaceResult()
        self._body_rtol = BODY_RTOL_FACTOR * tolerance.rtol
        self._tighten()
        before = self._body_iterations()
        try:
            if self.use_krylov:
                y = self._solve_krylov_lagged(b, tolerance, result)
            else:
                y = self._solve_fixed_point(b, tolerance, result)
        except SubdomainConvergenceError:  # collective: every rank has the same residual
            result.body_iterations = self._body_iterations() - before
            result.seconds = time.perf_counter() - start
            raise
        result.body_iterations = self._body_iterations() - before
        result.seconds = time.perf_counter() - start
        return y, result

    def _tighten(self, rtol: float | None = None) -> None:
        """Set the iterative bodies' tolerance (default: the tight one of the true rounds)."""
        for body in self.system.bodies.values():
            body.set_rtol(self._body_rtol if rtol is None else rtol)

    def _body_iterations(self) -> int:
        """Iterations of the iterative body solves so far, over every body (collective)."""
        bodies = self.system.bodies.values()
        mine = sum(b.solve_iterations for b in bodies if b.comm.rank == 0)
        return self.system.comm.allreduce(mine, op=MPI.SUM)

    def _solve_fixed_point(self, b: Vector | None, tolerance: Tolerance, result) -> Vector:
        system = self.system
        increments = {k: np.zeros(n) for k, n in system.sizes.items()}
        scales: dict[str, Vector] = {}
        for rounds in range(1, self.max_rounds + 1):
            y, residual, pushed = self._round(b, increments)
            scales = scales or self._flux_scales(pushed)
            relative, small, _ = self._measure(residual, scales, tolerance)
            result.rounds, result.converged = rounds, small
            result.history.append(relative)
            if self.monitor is not None:
                self.monitor(rounds, lambda y=y: y)
            if not np.isfinite(relative) or relative > self.divergence * result.history[0]:
                raise SubdomainConvergenceError(
                    f"{self.corrector.name}: the subdomain iteration diverged at round "
                    f"{rounds} (relative master residuals {_short(result.history)}); the "
                    "exact corrector, or krylov=True, converges where the paper's correctors "
                    "cannot",
                    result,
                )
            if small:
                return y
            flat = self.correct(np.concatenate([residual[k] for k in self.slices]))
            for k, s in self.slices.items():
                increments[k] = increments[k] - flat[s]
        raise SubdomainConvergenceError(
            f"{self.corrector.name}: no convergence to {_describe(tolerance)} in "
            f"{self.max_rounds} rounds (relative master residuals {_short(result.history)}): "
            "the fixed point corrects each interface on its own; where a body touches "
            "several interfaces or floats, use krylov=True (CG/GMRES on every interface at "
            "once, with a coarse space)",
            result,
        )

    # -- Krylov ---------------------------------------------------------------------------
    def split(self, v: Vector) -> dict[str, Vector]:
        """A concatenated master vector as interface -> values."""
        return {k: v[s] for k, s in self.slices.items()}

    def apply(self, v: Vector) -> Vector:
        """``S v`` for concatenated master increments v (identity on inactive DOFs)."""
        system, parts = self.system, self.split(v)
        local = {k: np.zeros(s.stop - s.start) for k, s in self.slices.items()}

        def respond() -> None:
            for name, body in system.bodies.items():
                own = list(body.layers)
                if name in self.dense:
                    response = self.dense[name] @ np.concatenate([parts[k] for k in own])
                    for k, at in body.master_slices().items():
                        local[k] += response[at]
                elif any(parts[k].any() for k in own):  # S^α 0 = 0: no body solve
                    columns = {k: parts[k][:, None] for k in own}
                    c, rest = self._off_kernel(name, body, columns)
                    if c is not None:
                        for k in own:
                            local[k] += self.kernels[name].answers[k] @ c[:, 0]
                    if any(v.any() for v in rest.values()):
                        for k, r in body.respond(rest).items():
                            local[k] += r[:, 0]
                        self._applications += 1

        together(system.comm, respond)
        total = system.total(local)
        out = np.concatenate([total[k] for k in self.slices])
        return np.where(self.active, out, v)

    def _image(self, Z: Matrix) -> Matrix:
        """``S Z`` for orthonormal columns Z (identity on inactive DOFs), as :meth:`apply`.

        Body α's part depends on Z's rows on its masters alone, ``Z_α = P Σ Qᵀ`` (SVD):
        ``S^α Z_α = (S^α P) Σ Qᵀ``, one body solve per singular value above
        :data:`COARSE_RANK` (``σ ≤ 1``: the part dropped is below the body solves' own
        error). The columns of Z mix every body's modes, so applied one by one each made
        every body solve: on the row of four 3D blocks (T, φ, u; 15 columns, five modes on
        each contact) 4 × 15 body solves per build, against 5 + 10 + 10 + 5 here; at 74,580
        DOFs on 2 ranks a build took 6.0–8.9 s, now 2.9–4.5 s.
        """
        system, columns = self.system, Z.shape[1]
        local = {k: np.zeros((s.stop - s.start, columns)) for k, s in self.slices.items()}

        def respond() -> None:
            for name, body in system.bodies.items():
                if not body.layers:
                    continue
                at = body.master_slices()  # where each interface sits in the body's rows
                part = np.vstack([Z[self.slices[k]] for k in at])
                if name in self.dense:
                    response = self.dense[name] @ part
                    for k, rows in at.items():
                        local[k] += response[rows]
                    continue
                c, rest = self._off_kernel(name, body, {k: part[rows] for k, rows in at.items()})
                if c is not None:
                    for k in at:
                        local[k] += self.kernels[name].answers[k] @ c
                    part = np.vstack([rest[k] for k in at])
                P, sigma, Qt = np.linalg.svd(part, full_matrices=False)
                # one count on the body's ranks, whose solves are collective
                rank = body.comm.bcast(int(np.sum(sigma > COARSE_RANK)))
                if rank == 0:  # S^α 0 = 0: no body solve
                    continue
                basis = {k: P[rows, :rank] for k, rows in at.items()}
                mix = sigma[:rank, None] * Qt[:rank]
                for k, r in body.respond(basis).items():
                    local[k] += r @ mix
                self._applications += rank

        together(system.comm, respond)
        total = system.total(local)
        out = np.vstack([total[k] for k in self.slices])
        return np.where(self.active[:, None], out, Z)

    def _find_kernels(self) -> dict[str, Kernel]:
        """Each body's own modes that solve it as they are, with their answers.

        A floating body's translation, or the potential's constant where no condition holds
        it, solves the body for master values equal to its trace: a rigid motion stretches
        no link, a constant potential drives no current (:meth:`Body.respond_by` checks the
        body's residual at the mode). A solve computes that answer as the small difference
        of two large terms, ``D z − C A⁻¹ B z``, off by the body's conditioning times its
        round-off (the row of four 3D blocks at 300 K: 2.5e-3 of the largest answer's 1.1e3,
        the floating block's solution 4.7e-7 off the translation). So master values are
        split into their part along these traces, answered by products, and the rest,
        solved (:meth:`_off_kernel`). Bodies held dense or by their Schur block keep their
        exact ``S^α``. Rotations are about the mean of the body's master nodes.
        """
        system = self.system
        found: dict[str, Kernel] = {}

        def find() -> None:
            for name, body in system.bodies.items():
                if body.schur or name in self.dense or not body.layers:
                    continue
                layers = [system.layers[k] for k in body.layers]
                dim = body.forms.W.mesh.geometry.dim
                middle, own = _mode_traces(layers, system.problem.fields, dim)
                traces, values, answers = [], [], []
                for mode, trace in own:
                    trace = {k: system.active[k] * v for k, v in trace.items()}
                    if not any(v.any() for v in trace.values()):
                        continue
                    y = body.mode_values(mode, middle)
                    answer = body.respond_by(y, trace)
                    if answer is not None:
                        traces.append(np.concatenate([trace[k] for k in body.layers]))
                        values.append(y)
                        answers.append(answer)
                if traces:
                    K = np.column_stack(traces)
                    found[name] = Kernel(
                        traces=K,
                        fit=np.linalg.pinv(K),
                        values=np.column_stack(values),
                        answers={k: np.column_stack([a[k] for a in answers]) for k in body.layers},
                    )

        together(system.comm, find)
        return found

    def _off_kernel(
        self, name: str, body, masters: dict[str, Matrix]
    ) -> tuple[Matrix | None, dict[str, Matrix]]:
        """Columns of master values on a body split as ``K c + rest``.

        Returns the amplitudes c of the body's own modes (None without them) and the rest,
        interface -> rows: what the body is solved for (:meth:`_find_kernels`).
        """
        kernel = self.kernels.get(name)
        if kernel is None:
            return None, masters
        at = body.master_slices()
        P = np.vstack([masters[k] for k in at])
        c = kernel.fit @ P
        rest = P - kernel.traces @ c
        return c, {k: rest[rows] for k, rows in at.items()}

    def correct(self, r: Vector) -> Vector:
        """``G r``: the corrector on every interface (concatenated master vectors)."""
        if self.strip is not None:
            return self.strip.apply(r)
        z = np.zeros(self.size)
        for k, s in self.slices.items():
            z[s] = self.operators[k] @ r[s]
        return z

    def precondition(self, r: Vector) -> Vector:
        """The correctors with the coarse correction, balanced (Mandel 1993).

        The coarse correction first, the correctors on the residual it leaves:
        ``z = Z c + G (r − S Z c)``, ``c = E⁻¹ Zᵀ r``, ``E = Zᵀ S Z``; for CG the corrector's
        part is then made S-orthogonal to the coarse space, which keeps the preconditioner
        symmetric. ``S Z`` is kept from the coarse matrix's build: no extra application. An
        exact G stays exact, where the sum ``G r + Z E⁻¹ Zᵀ r`` corrected the coarse modes
        twice: on the floating chain of 8 bodies (exact corrector) 3–7 CG iterations
        instead of 5–13, on two 3D blocks with iterative bodies (107k DOFs) 2–6 instead
        of 3–7 and 14–19 % fewer body iterations, on the row of four 3D blocks 32 inner
        rounds instead of 37.
        """
        if self.coarse_matrix is None:
            return np.where(self.active, self.correct(r), r)
        Z, SZ, E = self.coarse_basis, self.coarse_image, self.coarse_matrix
        c = np.linalg.solve(E, Z.T @ r)
        z = self.correct(np.where(self.active, r - SZ @ c, 0.0))
        if self.system.symmetric:
            z -= Z @ np.linalg.solve(E, SZ.T @ z)
        return np.where(self.active, z + Z @ c, r)

    def _coarse_basis(self) -> Matrix:
        """Orthonormal basis of every body's constants (T, φ) and rigid motions (u).

        Each body's mode is ½ on the masters of its interfaces, the mode's value at the
        master node for the channel's field and component. The body vectors are linearly
        dependent (a chain of n bodies has n − 1 interfaces): the span is kept. A body that
        lies whole in the sparse strip corrector's strip has none: the strip holds its exact
        ``S^α``, kernel included, and its modes would only cost their applications of ``S``
        (the collector bar slot at 17k DOFs, every body whole in the strip: 24 per Newton
        step).
        """
        system = self.system
        scene = system.problem.scene
        whole = self.strip.whole if self.strip is not None else frozenset()
        columns = []
        for body in scene.bodies:
            layers = [system.layers[i.name] for i in scene.interfaces_of(body)]
            if not layers or body in whole:
                continue
            dim = scene.bodies[body].mesh.geometry.dim
            for _, trace in _mode_traces(layers, system.problem.fields, dim)[1]:
                z = np.zeros(self.size)
                for k, values in trace.items():
                    z[self.slices[k]] = 0.5 * values
                columns.append(z * self.active)
        if not columns:
            return np.zeros((self.size, 0))
        U, sigma, _ = np.linalg.svd(np.column_stack(columns), full_matrices=False)
        return U[:, sigma > 1e-10 * max(sigma.max(), 1e-300)]

    def _room_for_strip(self) -> bool:
        """Whether the sparse strip (if any) can be factorised again in the memory left.

        If not, the kept preconditioner serves from now on without the :data:`LAG_GROWTH`
        limit.
        """
        if self.strip is None or self.strip.fits():
            return True
        self._built["unlimited"] = True
        self.kept_for_memory += 1
        return False

    def _iteration_limit(self) -> int:
        """The interface Krylov's iterations: fewer with a kept preconditioner that may slow."""
        built = self._built
        if self._lagged and built["iterations"] is not None and not built.get("unlimited"):
            return min(self.max_rounds, int(LAG_GROWTH * built["iterations"]) + 1)
        return self.max_rounds

    def _solve_krylov_lagged(self, b: Vector | None, tolerance: Tolerance, result) -> Vector:
        """The interface Krylov solve; with a strip swept over its fields, whole if it fails.

        A sweep that leaves the solve short (:meth:`StripSolve.solve_whole`) is replaced by
        the whole strip's factorisation for this Jacobian, and the solve goes on from where
        it stopped.
        """
        try:
            return self._solve_krylov_kept(b, tolerance, result)
        except SubdomainConvergenceError as error:
            if self.strip is None or not self.strip.swept:
                raise
            if not self.strip.whole_fits():
                raise SubdomainConvergenceError(
                    f"{error}; the whole strip, which would replace its sweep over the fields, "
                    "would not fit in the memory left: try a narrower strip "
                    "(SparseStrip(layers=...)) or more nodes",
                    error.result,
                    error.iterate,
                ) from error
            self.strip.solve_whole(self.system)
            return self._solve_krylov(b, tolerance, result, error.iterate)

    def _solve_krylov_kept(self, b: Vector | None, tolerance: Tolerance, result) -> Vector:
        """The interface Krylov solve; with a kept preconditioner, rebuilt if it fails or slows."""
        before, continued = 0, False
        kept = self._lagged
        try:
            y = self._solve_krylov(b, tolerance, result)
        except SubdomainConvergenceError as error:
            if not self._lagged:
                raise
            self._stale_in_a_row += 1
            before = len(result.krylov_iterations)
            slowed = self._iteration_limit() < self.max_rounds  # it stopped at the limit
            if not (slowed and not self._room_for_strip()):
                self._build_preconditioner()  # for the current bodies, then once more
                continued = error.iterate is not None
            # A solve stopped at the limit goes on from where it stopped, not from zero: on
            # the collector bar slot its iterations had cut the residual by 2 to 6 orders of
            # magnitude (docs/iterative_bodies.md, a stale preconditioner).
            y = self._solve_krylov(b, tolerance, result, error.iterate)
        built, iterations = self._built, sum(result.krylov_iterations[before:])
        if continued:
            # A solve that went on from a stopped one with the new build started
            # part-converged: the new build's reference is the larger of its count and
            # that of the last solve that began with a new build, and it does not judge
            # the build it has just made stale. (Kept with the old reference alone, the
            # row of four blocks rebuilt it at the next step, 74,580 DOFs on 2 ranks: 77
            # -> 97 s; left without a reference, a stale build ran 100 iterations
            # unchecked at 219k: 199 s; the larger of its count and the old reference,
            # until 2026-12-07, ratcheted up on the collector bar slot's hard steps to 64
            # or more, so that its kept solves ran 100 iterations before each rebuild; its
            # count alone, 0 where the true round after the rebuild met the tolerance,
            # stopped the row's next kept solve at its first iteration.)
            built["iterations"] = max(iterations, self._fresh)
        elif built["iterations"] is None:
            built["iterations"] = self._fresh = iterations
        elif iterations > LAG_GROWTH * built["iterations"] + 1:
            built["stale"] = True
            self._stale_in_a_row += 1
        elif kept:
            self._stale_in_a_row = 0  # a kept build served
        return y

    def _solve_krylov(
        self,
        b: Vector | None,
        tolerance: Tolerance,
        result,
        start: dict[str, Vector] | None = None,
    ) -> Vector:
        """True rounds and interface Krylov solves from the master increments ``start``.

        A Krylov solve stopped by its iteration limit raises with the increments it reached
        (``SubdomainConvergenceError.iterate``). Against absolute tolerances, true rounds that
        stop falling short of them return their best as an inexact step
        (:data:`FLOOR_ACCEPTED`).
        """
        system = self.system
        self._applications, self._iterations_done = 0, 0
        if start is None:
            increments = {k: np.zeros(n) for k, n in system.sizes.items()}
        else:
            increments = {k: v.copy() for k, v in start.items()}
        scales: dict[str, Vector] = {}
        symmetric = system.symmetric
        best: tuple[float, Vector] = (np.inf, np.zeros(0))  # the true round nearest the target
        miss = np.inf  # of the last true round: its residual over the tolerance
        stalled = False
        for step in range(self.max_refinements + 1):
            self._tighten()
            y, residual, pushed = self._round(b, increments)
            scales = scales or self._flux_scales(pushed)
            measured = self._weighed(residual)
            previous = miss
            relative, small, miss = self._measure(measured, scales, tolerance)
            result.rounds, result.converged = result.rounds + 1, small
            result.history.append(relative)
            if small:
                result.applications = self._applications
                return y
            best = min(best, (miss, y), key=lambda pair: pair[0])
            # the last two refinements' Krylov solves converged and their true rounds missed,
            # the second without halving the first's miss: the body solves' round-off
            stalled = stalled or (step >= 2 and miss > 0.5 * previous)
            if stalled and best[0] <= FLOOR_ACCEPTED:
                result.short_by, result.applications = best[0], self._applications
                return best[1]
            if step == self.max_refinements:
                break
            weights = self._weights(scales, tolerance, symmetric)
            flat = np.concatenate([residual[k] for k in self.slices])
            delta, iterations, reason = self._krylov(-flat, weights, symmetric, increments, b)
            result.krylov_iterations.append(iterations)
            for k, s in self.slices.items():
                increments[k] = increments[k] + delta[s]
            if reason < 0:
                result.applications = self._applications
                stopped = reason == PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT
                raise SubdomainConvergenceError(
                    f"interface {'CG' if symmetric else 'GMRES'} ({self.corrector.name} "
                    f"preconditioner) failed: PETSc reason {reason} after {iterations} "
                    f"iterations (relative master residuals {_short(result.history)})",
                    result,
                    increments if stopped else None,
                )
        result.applications = self._applications
        reached = (
            f" (reached: {_describe(Tolerance(atol=system.master_field_norms(measured)))}"
            + (", each master's residual weighed by its error" if self.error_weights else "")
            + ")"
            if tolerance.atol is not None
            else ""
        )
        floor = (
            f"; its true rounds stopped falling at {best[0]:.3g} times the tolerance, the "
            "round-off of the iterative body solves: solve the bodies with the heaviest "
            "weighed masters by MUMPS (-sc_body_<name>_solver direct)"
            if stalled
            else ""
        )
        raise SubdomainConvergenceError(
            f"interface Krylov ({self.corrector.name} preconditioner): the true residual "
            f"{result.history[-1]:.2e} is above {_describe(tolerance)}{reached} after "
            f"{self.max_refinements} refinements{floor}",
            result,
        )

    def _weights(self, scales: dict[str, Vector], tolerance: Tolerance, symmetric: bool):
        """1 / tolerance of every master DOF, so that ``‖W r‖₂ ≤ 1`` meets every check.

        CG keeps the operator symmetric: one weight, the smallest interface tolerance.
        """
        system = self.system
        pieces = []
        pairs = sum(len(layer.channels) for layer in system.layers.values())
        for k, layer in system.layers.items():
            for c, (f, _) in enumerate(layer.channels):
                if tolerance.atol is not None:
                    tol = tolerance.atol[f]
                else:
                    tol = tolerance.rtol * scales[k][c] / np.sqrt(pairs)
                pieces.append(np.full(layer.nodes, 1.0 / max(tol, 1e-300)))
        weights = np.concatenate(pieces)
        if symmetric:
            return np.full_like(weights, weights.max())
        if self.error_weights is not None:
            weights = weights * np.concatenate([self.error_weights[k] for k in system.layers])
        return weights

    def _heaviest(self) -> float:
        """The largest error weight (1 without them)."""
        weights = (self.error_weights or {}).values()
        return max((w.max(initial=1.0) for w in weights), default=1.0)

    def _krylov(
        self,
        rhs: Vector,
        weights: Vector,
        symmetric: bool,
        start: dict[str, Vector],
        b: Vector | None,
    ) -> tuple[Vector, int, int]:
        """Solve ``W S δ = W rhs`` to ``‖W r‖₂ ≤ ½`` (right preconditioning for GMRES)."""
        system = self.system
        comm = system.comm
        shell = _Shell(self, weights)
        ksp = PETSc.KSP().create(comm)
        operator = PETSc.Mat().createPython((self.size, self.size), shell, comm=comm)
        operator.setUp()
        ksp.setOptionsPrefix(self.prefix)
        ksp.setOperators(operator)
        ksp.setType("cg" if symmetric else "gmres")
        if not symmetric:
            ksp.setPCSide(PETSc.PC.Side.RIGHT)
            ksp.setGMRESRestart(max(30, min(self.max_rounds, 200)))
            # Fields of very different weights (W, A and N tolerances) make classical
            # Gram-Schmidt lose orthogonality: GMRES then stalls at 1e-5 (measured on the
            # three-body cathode at 1 V), while refined Gram-Schmidt reaches 1e-10.
            refine = f"{self.prefix}ksp_gmres_cgs_refinement_type"
            added = default_option(refine, "refine_always")
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(_Preconditioner(self, weights))
        ksp.setTolerances(rtol=0.0, atol=0.5, max_it=self._iteration_limit())
        if any(body.iterative for body in system.bodies.values()):
            # A body solve's error is relative to its own norm, blind to the error weights:
            # at a master weighed w it counts w times in ‖W r‖, so the relaxation is divided
            # by the heaviest weight (on the row of four 3D blocks the weights of 1e11 at the
            # cold start, open contacts, made the true rounds miss what the Krylov solve had
            # met under the relaxation, five times in a row, then a rebuild).
            heaviest = self._heaviest()

            def relax(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
                loose = min(RELAXED_LOOSEST, RELAXATION / max(norm, 1e-300)) / heaviest
                self._tighten(max(self._body_rtol, loose))

            ksp.setMonitor(relax)
        if self.monitor is not None:
            done = self._iterations_done

            def watch(ksp: PETSc.KSP, iteration: int, norm: float) -> None:
                if iteration == 0:
                    return
                built = ksp.buildSolution()
                step = np.concatenate(comm.allgather(built.getArray(readonly=True)))
                built.destroy()
                current = {k: start[k] + step[s] for k, s in self.slices.items()}
                self.monitor(done + iteration, lambda: self._round(b, current)[0])

            ksp.setMonitor(watch)
        ksp.setFromOptions()
        if not symmetric and added:
            PETSc.Options().delValue(refine)
        right, x = operator.createVecs()
        lo, hi = right.getOwnershipRange()
        right.setArray((weights * rhs)[lo:hi])
        ksp.solve(right, x)
        delta = np.concatenate(comm.allgather(x.getArray(readonly=True)))
        iterations, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
        for obj in (ksp, operator, right, x):
            obj.destroy()
        self._iterations_done += iterations
        return delta, iterations, reason


class _Shell:
    """PETSc context of the weighted interface operator ``W S``."""

    def __init__(self, solver: Subdomains, weights: Vector) -> None:
        self.solver, self.weights = solver, weights

    def mult(self, mat: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        full = np.concatenate(x.getComm().tompi4py().allgather(x.getArray(readonly=True)))
        start, end = x.getOwnershipRange()
        y.setArray((self.weights * self.solver.apply(full))[start:end])


class _Preconditioner:
    """PETSc context of the preconditioner, on weighted residuals: ``P W⁻¹``."""

    def __init__(self, solver: Subdomains, weights: Vector) -> None:
        self.solver, self.weights = solver, weights

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        full = np.concatenate(x.getComm().tompi4py().allgather(x.getArray(readonly=True)))
        start, end = x.getOwnershipRange()
        y.setArray(self.solver.precondition(full / self.weights)[start:end])


def _mode_traces(
    layers: Sequence[MasterLayer], fields: tuple[str, ...], dim: int
) -> tuple[npt.NDArray[np.float64], list[tuple[Mode, dict[str, Vector]]]]:
    """A body's kernel modes on the master layers of its interfaces.

    Returns the centre of the rotations (the mean of the layers' nodes) [m], and each mode
    with interface -> its values on that layer's channels.
    """
    middle = np.concatenate([layer.coordinates for layer in layers]).mean(axis=0)
    traces = [
        (
            mode,
            {
                layer.interface.name: np.concatenate(
                    [mode(f, c, layer.coordinates - middle) for f, c in layer.channels]
                )
                for layer in layers
            },
        )
        for mode in modes(fields, dim)
    ]
    return middle, traces


def together(comm: MPI.Comm, work: Callable[[], None]) -> None:
    """Run this rank's part of a collective step; if it fails on any rank, fail on every one.

    A body on a rank group fails there alone (an iterative solve that stops short); the other
    ranks would wait for it in the next collective call. Here they raise too, with its
    message, so that Newton's next line search or the caller sees one failure everywhere. A
    ``MemoryError`` stays one on every rank: Newton does not try it again.
    """
    error: Exception | None = None
    try:
        work()
    except Exception as failure:
        error = failure
    failed = None if error is None else (isinstance(error, MemoryError), str(error))
    failures = [f for f in comm.allgather(failed) if f is not None]
    if error is not None:
        raise error
    if failures:
        memory, message = failures[0]
        raise (MemoryError if memory else RuntimeError)(f"on another rank: {message}")


def _describe(tolerance: Tolerance) -> str:
    if tolerance.atol is None:
        return f"{tolerance.rtol:g}"
    return ", ".join(f"{f} {v:.2e}" for f, v in tolerance.atol.items())


def _short(history: list[float]) -> str:
    """The first and last few residuals of a history, for error messages."""
    text = [f"{h:.2e}" for h in history]
    return ", ".join(text if len(text) <= 8 else [*text[:4], "…", *text[-3:]])
