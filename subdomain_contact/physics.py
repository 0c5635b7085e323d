"""Materials, contact laws and boundary conditions of a scene, and each body's UFL residuals.

Fields per body, only those the materials ask for: temperature T [K], electric potential φ
[V], displacement u [m] (plane strain in 2D). A thermal problem is the one-field case. Bulk
couplings: Joule heating σ(T)|∇φ|², conductivities k(T) and σ(T), thermal strain α (T − T_ref).

Each contact interface k carries master copies of the fields. On body α they are the
Function ``masters[k]`` *of the body's own space*: only its slave DOFs on Γ_k matter, and since
both meshes are conforming P1 there, its trace on Γ_k is the master field. The half-link of
body α at Γ_k (METHOD.md §2), with n the body's outward normal and the jump ``j = U − U_m``:

- thermal flux h̄ j_T, h̄ = 2 h(p, T_m);
- current ḡ j_φ, ḡ = 2 g(p, T_m), and the Joule heat ḡ j_φ² deposited on the slave side;
- normal pressure p = P(⟨2 j_u·n − gap⟩) (unilateral, P the closure law of the whole contact);
  tangential traction 2 k_n j_t when stuck, none when free. An open side transmits nothing to
  the body; a tiny tie in the body's Newton matrix (``ties``) and a stiffer one in the master
  equation (:data:`MASTER_TIE`) hold its master to the slave.

Residuals are internal minus external. The body residual holds the half-links tested with the
body's test function; the master residual of Γ_k holds minus the same fluxes (Joule heat
excluded, the master's tie included), tested with the master test function, which on body α
is the test function at the slave DOFs. The two differ by the Joule heat the half-link
deposits on the body (``remainders``) and the tie, both small beside a closed link: the master
residual can therefore be taken from the body's own equation without subtracting two
h̄-sized numbers (:mod:`subdomain_contact.body`).

Numbers in materials, contacts and conditions become ``dolfinx.fem.Constant`` coefficients, so
that a sweep over them compiles each form once.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import basix.ufl
import dolfinx
import numpy as np
import numpy.typing as npt
import ufl
import ufl.algorithms
from ufl.algorithms.compute_form_data import preprocess_form

from subdomain_contact.laws import Law, check_finite
from subdomain_contact.scene import Body, Scene

__all__ = [
    "FIELDS",
    "BodyForms",
    "Condition",
    "Contact",
    "Convection",
    "CurrentDensity",
    "Displacement",
    "ExponentialClosure",
    "HeatFlux",
    "Material",
    "Penalty",
    "Potential",
    "Pressure",
    "Problem",
    "Schedule",
    "Temperature",
    "body_forms",
    "split_fields",
]

#: Every field a body can carry, in the order of its mixed space.
FIELDS = ("temperature", "potential", "displacement")

Expr = ufl.core.expr.Expr


@dataclass(frozen=True, kw_only=True)
class Material:
    """A body's material; a field exists where its property is given.

    Attributes:
        conductivity: Thermal conductivity k(T) [W/(m K)]: a number or a law ``(p, T)``.
        electrical_conductivity: σ(T) [S/m].
        young: Young's modulus E(T) [Pa]: a number or a law ``(p, T)``.
        poisson: Poisson's ratio ν.
        expansion: Linear thermal expansion α(T) [1/K], secant from the reference
            temperature (thermal strain α(T) (T − T_ref)): a number or a law ``(p, T)``.
        reference_temperature: Temperature [K] of zero thermal strain; required with
            ``expansion``.
        heat_source: Volumetric heat source [W/m^3] (besides Joule heat): a number, or a
            function ``(x, t)`` of the spatial coordinate and the time that returns UFL.
        density: ρ [kg/m^3], with ``heat_capacity``: the body stores heat in a transient
            (:mod:`subdomain_contact.transient`); without them it has no thermal inertia.
        heat_capacity: c_p(T) [J/(kg K)]: a number or a law ``(p, T)``.
    """

    conductivity: float | Law | None = None
    electrical_conductivity: float | Law | None = None
    young: float | Law | None = None
    poisson: float = 0.3
    expansion: float | Law = 0.0
    reference_temperature: float | None = None
    heat_source: float | SpaceTime = 0.0
    density: float | None = None
    heat_capacity: float | Law | None = None

    def fields(self) -> tuple[str, ...]:
        """The fields this material needs."""
        given = [self.conductivity, self.electrical_conductivity, self.young]
        return tuple(f for f, g in zip(FIELDS, given, strict=True) if g is not None)


@dataclass(frozen=True)
class Penalty:
    """Linear pressure–closure law p = k_n δ of the whole contact, k_n [Pa/m]."""

    stiffness: float

    def __call__(self, closure: Expr, constant: Callable[[float], Expr] = float) -> Expr:
        """Pressure [Pa] at closure δ ≥ 0 [m]; ``constant`` makes its numbers coefficients."""
        return constant(self.stiffness) * closure


@dataclass(frozen=True)
class ExponentialClosure:
    """Stiffening pressure–closure law p = k_n δ₀ (exp(δ/δ₀) − 1).

    Attributes:
        stiffness: Initial stiffness k_n [Pa/m].
        closure: Closure δ₀ [m] over which the stiffness grows by e.
    """

    stiffness: float
    closure: float

    def __call__(self, closure: Expr, constant: Callable[[float], Expr] = float) -> Expr:
        """Pressure [Pa] at closure δ ≥ 0 [m]; ``constant`` makes its numbers coefficients."""
        k, d = constant(self.stiffness), constant(self.closure)
        return k * d * (ufl.exp(closure / d) - 1.0)


NormalLaw = Penalty | ExponentialClosure


@dataclass(frozen=True, kw_only=True)
class Contact:
    """The laws of one contact interface (of the whole contact, never the half-link's 2×).

    Attributes:
        conductance: Thermal conductance h(p, T) [W/(m^2 K)]; 0: an insulating contact.
        electrical_conductance: Electrical conductance g(p, T) [S/m^2]; 0: insulating.
        normal: Pressure–closure law; unilateral (no tension).
        tangential: ``"free"`` (no friction) or ``"stuck"`` (slip penalised by
            ``slip_stiffness``).
        slip_stiffness: Stiffness [Pa/m] of the spring against the slip of a stuck contact;
            default the normal law's initial stiffness (bonded). A small one lets the sides
            slide against a weak spring that still holds their rigid motions along the
            contact.
        gap: Initial gap [m] between the two sides (0: touching).
        pressure: Pressure [Pa] the laws see when the scene has no displacement field.
        temperature: Temperature [K] the laws see when the scene has no temperature field.
        joule_to_first: Share of the contact's Joule heat g Δφ² deposited on the interface's
            first body (``Interface.bodies[0]``), the rest on the second; default one half.
        open_stiffness: Stiffness, relative to the normal law's (capped at 1e6 E / h, h the
            body's cell size at the contact), that ties the slaves of an open contact to its
            master in the bodies' Newton matrix, as a regularisation, never in their
            residual (an open contact transmits no force). At most 1e-9, so that the Newton
            matrix stays exact to 1e-3 where it holds. The master equation's tie is
            :data:`MASTER_TIE` times this one.
    """

    conductance: float | Law | None = None
    electrical_conductance: float | Law | None = None
    normal: NormalLaw | None = None
    tangential: str = "free"
    slip_stiffness: float | None = None
    gap: float = 0.0
    pressure: float = 0.0
    temperature: float = 0.0
    joule_to_first: float = 0.5
    open_stiffness: float = 1e-9


@dataclass(frozen=True)
class Schedule:
    """A value that changes in time: piecewise linear through (time [s], value) points.

    Held at its first and last values outside them (a current ramp, a measured history).
    A time given twice is a switch: the value jumps there (a step that ends on it takes the
    value before, the next step the value after). Give it as the value of a condition (or a
    convection's ambient); each time step takes its value at the step's end
    (:class:`~subdomain_contact.transient.Stepper`, whose steps land on every time listed).
    """

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        times, values = np.asarray(self.times, float), np.asarray(self.values, float)
        if times.ndim != 1 or times.shape != values.shape or times.size == 0:
            raise ValueError("Schedule: as many times as values, at least one")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values))):
            raise ValueError("Schedule: times and values must be finite")
        steps = np.diff(times)
        if np.any(steps < 0) or np.any((steps[:-1] == 0) & (steps[1:] == 0)):
            raise ValueError(
                f"Schedule: times must increase (a time given twice is a switch, never three "
                f"times), got {self.times}"
            )

    def at(self, time: float) -> float:
        """The value at ``time`` [s] (at a switch, the value before it)."""
        times, values = np.asarray(self.times, float), np.asarray(self.values, float)
        hits = np.flatnonzero(times == time)
        if hits.size:
            return float(values[hits[0]])
        i = int(np.searchsorted(times, time, side="right"))
        if i == 0 or i == len(times):
            return float(values[min(i, len(times) - 1)])
        weight = (time - times[i - 1]) / (times[i] - times[i - 1])
        return float(values[i - 1] + weight * (values[i] - values[i - 1]))

    @classmethod
    def from_csv(cls, path: str | Path) -> Schedule:
        """Read ``time,value`` rows (times in s; a first line that is not numbers is a header).

        Raises:
            ValueError: A row that is not two numbers, naming the file and the line.
        """
        rows = []
        lines = Path(path).read_text().splitlines()
        for number, line in enumerate(lines, start=1):
            if not line.strip():
                continue
            try:
                time, value = (float(field) for field in line.split(","))
            except ValueError:
                if number == 1:
                    continue  # a header
                raise ValueError(f"{path}:{number}: expected 'time,value', got {line!r}") from None
            rows.append((time, value))
        if not rows:
            raise ValueError(f"{path}: no 'time,value' rows")
        times, values = zip(*rows, strict=True)
        return cls(times, values)


#: Data that vary in space and time: a function ``(x, t)`` of the spatial coordinate
#: (``ufl.SpatialCoordinate``) and the time (a form coefficient [s]) that returns UFL, e.g.
#: ``lambda x, t: 300 + 1e-3 * t * x[0]`` (a manufactured solution's data).
SpaceTime = Callable[[Expr, Expr], Expr]


def is_space_time(value: object) -> bool:
    """Whether ``value`` is data of ``(x, t)``: a callable of two positional parameters."""
    if not callable(value) or isinstance(value, Schedule):
        return False
    try:
        parameters = inspect.signature(value).parameters.values()
    except (TypeError, ValueError):
        return False
    positional = [p for p in parameters if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) == 2


#: Dirichlet data: a number, or a function of the points ``x`` that returns the values: of
#: numpy arrays (``x`` of shape ``(3, n)`` [m], dolfinx's interpolation convention) or of UFL
#: (``x`` the spatial coordinate, e.g. ``lambda x: 300 + 20 * ufl.sin(ufl.pi * x[1])``).
#: Or a :class:`Schedule` of time, or a function ``(x, t)`` (:data:`SpaceTime`).
Data = float | Schedule | Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]] | SpaceTime


@dataclass(frozen=True)
class Temperature:
    """Dirichlet condition: temperature [K] on a boundary group (a number or a function of x)."""

    boundary: str
    value: Data


@dataclass(frozen=True)
class HeatFlux:
    """Neumann condition: heat flux [W/m^2] *into* the body through a boundary group."""

    boundary: str
    value: float | Schedule


@dataclass(frozen=True)
class Convection:
    """Robin condition q = coefficient (ambient − T): coefficient [W/(m^2 K)], ambient [K].

    Either may follow a :class:`Schedule` (a coefficient that switches from 0 at a time: a
    boundary uncovered during a run).
    """

    boundary: str
    coefficient: float | Schedule
    ambient: float | Schedule


@dataclass(frozen=True)
class Potential:
    """Dirichlet condition: electric potential [V] on a boundary group (number or function)."""

    boundary: str
    value: Data


@dataclass(frozen=True)
class CurrentDensity:
    """Neumann condition: current density [A/m^2] *into* the body through a boundary group."""

    boundary: str
    value: float | Schedule


@dataclass(frozen=True)
class Displacement:
    """Dirichlet condition on one displacement component (0: x, 1: y, 2: z) [m].

    ``value``: a number or a function of x, as for :class:`Temperature`.
    """

    boundary: str
    component: int
    value: Data


@dataclass(frozen=True)
class Pressure:
    """Neumann condition: a normal pressure [Pa] on a boundary group, the traction −p n.

    Positive pushes into the body (a weight resting on it); a number or a :class:`Schedule`.
    """

    boundary: str
    value: float | Schedule


Condition = (
    Temperature | HeatFlux | Convection | Potential | CurrentDensity | Displacement | Pressure
)
FIELD_OF: Mapping[type, str] = {
    Temperature: "temperature",
    HeatFlux: "temperature",
    Convection: "temperature",
    Potential: "potential",
    CurrentDensity: "potential",
    Displacement: "displacement",
    Pressure: "displacement",
}
#: The contact law that couples each field across an interface.
_LAW_OF = {"temperature": "conductance", "potential": "electrical_conductance"}


@dataclass(frozen=True)
class Problem:
    """A scene with materials, contact laws and boundary conditions, for every field it needs.

    Attributes:
        scene: Bodies and interfaces.
        materials: Body name -> material; every body gives the same fields.
        contacts: Interface name -> contact laws (one per field of the scene).
        conditions: Boundary conditions by boundary-group name; a group that spans several
            bodies applies to each of them.

    Raises:
        ValueError: A missing or unknown entry, a coefficient that is not finite or not
            positive, a condition on a field no material defines, or a body whose temperature
            or potential nothing fixes (through conducting contacts included); the message
            names the body, interface or boundary.
    """

    scene: Scene
    materials: Mapping[str, Material]
    contacts: Mapping[str, Contact]
    conditions: Sequence[Condition] = ()
    fields: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        source = self.scene.source
        self.scene.check_entries(self.materials, self.contacts)
        fields = {name: m.fields() for name, m in self.materials.items()}
        first = next(iter(fields.values()))
        for name, f in fields.items():
            if f != first or not f:
                raise ValueError(
                    f"{source}: body '{name}' has fields {f}, others {first}: every body "
                    "needs the same non-empty set of conductivity, electrical_conductivity, young"
                )
        object.__setattr__(self, "fields", first)
        for name, m in self.materials.items():
            self._check_material(name, m)
        for name, c in self.contacts.items():
            self._check_contact(name, c)
        self._check_conditions()
        for f in ("temperature", "potential"):
            if f in self.fields:
                self._check_anchored(f)

    def _check_material(self, name: str, m: Material) -> None:
        for attr in ("conductivity", "electrical_conductivity", "young"):
            value = getattr(m, attr)
            if value is not None and not callable(value):
                check_finite(value, f"body '{name}': {attr}", positive=True)
        if not callable(m.expansion):
            check_finite(m.expansion, f"body '{name}': expansion")
        if not is_space_time(m.heat_source):
            check_finite(m.heat_source, f"body '{name}': heat_source")
        if m.reference_temperature is not None:
            check_finite(m.reference_temperature, f"body '{name}': reference_temperature")
        elif (callable(m.expansion) or m.expansion != 0) and m.young is not None:
            raise ValueError(
                f"body '{name}': expansion = {m.expansion} needs reference_temperature, the "
                "temperature [K] of zero thermal strain (for cast parts, their solidus)"
            )
        if (m.density is None) != (m.heat_capacity is None):
            raise ValueError(f"body '{name}': give density and heat_capacity together")
        if m.density is not None:
            check_finite(m.density, f"body '{name}': density", positive=True)
            if m.conductivity is None:
                raise ValueError(f"body '{name}': heat_capacity needs a conductivity (heat)")
        if m.heat_capacity is not None and not callable(m.heat_capacity):
            check_finite(m.heat_capacity, f"body '{name}': heat_capacity", positive=True)
        if not -1.0 < m.poisson < 0.5:
            raise ValueError(f"body '{name}': poisson = {m.poisson}: must lie in (-1, 0.5)")

    def _check_contact(self, name: str, c: Contact) -> None:
        needed = {
            "temperature": "conductance",
            "potential": "electrical_conductance",
            "displacement": "normal",
        }
        for f, attr in needed.items():
            value = getattr(c, attr)
            if (f in self.fields) != (value is not None):
                state = "needs" if f in self.fields else "has no field for"
                raise ValueError(f"interface '{name}': the scene {state} '{attr}' ({f})")
            if isinstance(value, float | int):
                what = f"interface '{name}': {attr}"
                check_finite(value, what)
                if value < 0:
                    raise ValueError(f"{what} = {value!r}: must be >= 0 (0: insulating)")
        if c.normal is not None:
            check_finite(c.normal.stiffness, f"interface '{name}': normal stiffness", positive=True)
        if c.tangential not in ("free", "stuck"):
            raise ValueError(f"interface '{name}': tangential = {c.tangential!r}: free or stuck")
        if c.slip_stiffness is not None:
            check_finite(c.slip_stiffness, f"interface '{name}': slip_stiffness", positive=True)
        for attr in ("gap", "pressure", "temperature", "joule_to_first"):
            check_finite(getattr(c, attr), f"interface '{name}': {attr}")
        if not 0 <= c.joule_to_first <= 1:
            raise ValueError(
                f"interface '{name}': joule_to_first = {c.joule_to_first}: a share, in [0, 1]"
            )
        check_finite(c.open_stiffness, f"interface '{name}': open_stiffness", positive=True)
        if c.open_stiffness > 1e-9:
            raise ValueError(
                f"interface '{name}': open_stiffness = {c.open_stiffness}: at most 1e-9 (the "
                "tie of an open contact regularises the Newton matrix, not the residual)"
            )

    def _check_conditions(self) -> None:
        source = self.scene.source
        every = set().union(*(b.boundaries for b in self.scene.bodies.values()))
        every -= set(self.scene.interfaces)
        dim = next(iter(self.scene.bodies.values())).mesh.geometry.dim
        for bc in self.conditions:
            if bc.boundary not in every:
                raise ValueError(
                    f"{source}: no boundary group named '{bc.boundary}' on any body; "
                    f"boundary groups: {sorted(every)}"
                )
            if FIELD_OF[type(bc)] not in self.fields:
                raise ValueError(
                    f"boundary '{bc.boundary}': {type(bc).__name__} needs the "
                    f"{FIELD_OF[type(bc)]} field, which no material defines"
                )
            for attr in ("value", "coefficient", "ambient"):
                value = getattr(bc, attr, None)
                if value is not None and not callable(value) and not isinstance(value, Schedule):
                    check_finite(getattr(bc, attr), f"boundary '{bc.boundary}': {attr}")
            value = getattr(bc, "value", None)
            if (
                callable(value)
                and not is_space_time(value)
                and not isinstance(bc, Temperature | Potential | Displacement)
            ):
                raise ValueError(
                    f"boundary '{bc.boundary}': {type(bc).__name__} takes a number, a Schedule "
                    "or a function (x, t); functions of x alone are for Temperature, "
                    "Potential and Displacement"
                )
            if isinstance(bc, Convection) and (_least(bc.coefficient) or 0.0) < 0:
                raise ValueError(f"boundary '{bc.boundary}': coefficient must be >= 0")
            if isinstance(bc, Displacement) and bc.component not in range(dim):
                raise ValueError(f"boundary '{bc.boundary}': no component {bc.component}")

    def insulating(self, interface: str, field_name: str) -> bool:
        """Whether the contact passes nothing of a scalar field (its law is the number 0)."""
        law = getattr(self.contacts[interface], _LAW_OF.get(field_name, "normal"), None)
        return isinstance(law, float | int) and law == 0

    def _check_anchored(self, field_name: str) -> None:
        """Refuse bodies whose temperature (or potential) nothing fixes, even through contacts.

        A group of bodies joined by conducting contacts needs a Dirichlet (or, for heat, a
        convection) condition somewhere: without one its level is defined only up to a
        constant and every solver would return an arbitrary one.
        """
        scene = self.scene
        anchors = {
            bc.boundary
            for bc in self.conditions
            if (FIELD_OF[type(bc)] == field_name and isinstance(bc, Temperature | Potential))
            or (
                isinstance(bc, Convection)
                and (_least(bc.coefficient) or 0.0) > 0
                and field_name == "temperature"
            )
        }
        joining = [k for k in scene.interfaces if not self.insulating(k, field_name)]
        members = scene.unanchored(joining, anchors)
        if members is not None:
            condition = "temperature or convection" if field_name == "temperature" else "potential"
            raise ValueError(
                f"{scene.source}: bodies {members} have no {condition} condition and no "
                f"conducting contact leads to one: their {field_name} is defined only up to "
                "a constant"
            )


@dataclass
class BodyForms:
    """A body's fields, its master Functions and its residual forms.

    Attributes:
        name: Body name.
        W: The body's space (mixed when it carries several fields).
        fields: The fields, in the order of ``W``'s sub-spaces.
        U: The body's solution.
        masters: Interface name -> master values on the body's space (slave DOFs only).
        bulk: Residual of the volume and the boundary conditions of flux type [W, A, N].
        links: Interface name -> residual of its half-link on the body's side.
        fluxes: Interface name -> the half-link's fluxes tested with the body's test function:
            the master residual of the interface is minus this form at the slave DOFs.
        remainders: Interface name -> the Joule heat deposited on the body's side (a term
            of ``links``, not of ``fluxes``), or None where the scene has no temperature and
            potential together.
        ties: Interface name -> the open side's tie in the body's Jacobian, ``κ
            min(closure, 0) n·v`` with κ its stiffness (see :class:`Contact`): it keeps a
            body that an opening contact frees from being singular in a Newton step; never
            in the body's residual; or None without displacement. ``fluxes`` hold the
            master's own tie instead (:data:`MASTER_TIE`), which keeps the master of an open
            contact defined, at the mean of its slaves.
        master_only: Interface name -> the terms by which minus ``fluxes`` differs from
            minus the body's linearised link (``links`` and ``ties``): the Joule heat
            deposited on the body's side and the body's tie less the master's; or None.
        bcs: Dirichlet conditions.
        ds: Boundary measure of the body, with its facet tags.
        tags: Interface name -> facet tag on the body.
        sources: The heat sources' residual term −(σ|∇φ|² + Q) v_T (in ``bulk``), or None.
        loads: Boundary group -> residual term of its flux and convection conditions (in
            ``bulk``).
        held: The condition of each of ``bcs``.
        history: The body's states at the two previous times, latest first (transients).
        rates: The time derivative's weights (r₀, r₁) [1/s]: ∂T/∂t ≈ r₀ (T − T₁) −
            r₁ (T₁ − T₂) with T₁, T₂ the history (backward Euler: 1/Δt, 0; BDF2: see
            :mod:`subdomain_contact.transient`); both 0 for a steady state.
        storage: The stored heat's residual term ρ c_p(T) ∂T/∂t v_T (in ``bulk``), or None
            for a body without thermal inertia.
        timed: The coefficients that follow a :class:`Schedule` of time, with it.
        time: The time [s] the data of ``(x, t)`` are at (None: the body has none).
        moving: Dirichlet data of ``(x, t)``: the Function of each and the expression it is
            interpolated from again at every time.
        laws: The conductivities and conductances (W/(m K), S/m, W/(m² K), S/m²) as UFL of
            the state, by name, each with the measure where it holds; they must stay ≥ 0.
    """

    name: str
    W: dolfinx.fem.FunctionSpace
    fields: tuple[str, ...]
    U: dolfinx.fem.Function
    masters: dict[str, dolfinx.fem.Function]
    bulk: ufl.Form
    links: dict[str, ufl.Form]
    fluxes: dict[str, ufl.Form]
    remainders: dict[str, ufl.Form | None]
    ties: dict[str, ufl.Form | None]
    master_only: dict[str, ufl.Form | None]
    bcs: list[dolfinx.fem.DirichletBC]
    ds: ufl.Measure
    tags: dict[str, int]
    sources: ufl.Form | None
    loads: dict[str, ufl.Form]
    held: list[Condition]
    laws: dict[str, tuple[Expr, ufl.Measure]]
    history: tuple[dolfinx.fem.Function, dolfinx.fem.Function]
    rates: tuple[dolfinx.fem.Constant, dolfinx.fem.Constant]
    storage: ufl.Form | None
    timed: list[tuple[dolfinx.fem.Constant, Schedule]]
    time: dolfinx.fem.Constant | None
    moving: list[tuple[dolfinx.fem.Function, dolfinx.fem.Expression]]
    _collapsed: dict = field(default_factory=dict, repr=False)
    _nodes: DofNodes | None = field(default=None, repr=False)
    _parts: dict = field(default_factory=dict, repr=False)

    def parts(self, test: bool = False) -> dict[str, Expr]:
        """``U`` (or, with ``test``, a test function of ``W``) by field name; made once.

        UFL's split builds the sub-spaces again at every call (about 3 ms; a report's
        integrals asked for it 750 times in 15 steps of the 3D preheat quarter).
        """
        if test not in self._parts:
            w = ufl.TestFunction(self.W) if test else self.U
            self._parts[test] = split_fields(w, self.fields)
        return self._parts[test]

    def subspace(self, name: str, component: int | None = None) -> dolfinx.fem.FunctionSpace:
        """The sub-space of one field (or of one displacement component)."""
        V = self.W if len(self.fields) == 1 else self.W.sub(self.fields.index(name))
        return V if component is None else V.sub(component)

    def collapsed(
        self, name: str, component: int | None = None
    ) -> tuple[dolfinx.fem.FunctionSpace, npt.NDArray[np.int32]]:
        """The sub-space as a space of its own, and the index in ``W`` of each of its DOFs.

        Made once per field (and component), then reused: the caller must not modify it.
        """
        if (name, component) not in self._collapsed:
            V = self.subspace(name, component)
            if V is self.W:
                size = self.W.dofmap.index_map.size_local + self.W.dofmap.index_map.num_ghosts
                parent_of = np.arange(size * self.W.dofmap.index_map_bs, dtype=np.int32)
                self._collapsed[name, component] = (self.W, parent_of)
            else:
                collapsed, to_parent = V.collapse()
                self._collapsed[name, component] = (collapsed, np.asarray(to_parent[0]))
        return self._collapsed[name, component]

    def nodes(self) -> DofNodes:
        """Each local DOF's node, component and the node's coordinates (made once)."""
        if self._nodes is None:
            dim = self.W.mesh.geometry.dim
            parts = [(f, c) for f in self.fields
                     for c in (range(dim) if f == "displacement" else [None])]  # fmt: skip
            index_map = self.W.dofmap.index_map
            size = (index_map.size_local + index_map.num_ghosts) * self.W.dofmap.index_map_bs
            node = np.full(size, -1, dtype=np.int64)
            component = np.full(size, -1, dtype=np.int64)
            dof_at = np.full((size, len(parts)), -1, dtype=np.int64)
            points = np.zeros((size, 3))
            first = None
            for c, (f, d) in enumerate(parts):
                V, parent_of = self.collapsed(f, d)
                dofs = parent_of[V.dofmap.list.ravel()]  # cell by cell, as the first's
                if first is None:
                    first = dofs
                    points[dofs] = V.tabulate_dof_coordinates()[V.dofmap.list.ravel()]
                node[dofs], component[dofs] = first, c
                dof_at[first, c] = dofs
            self._nodes = DofNodes(node, component, dof_at, points, parts)
        return self._nodes


@dataclass(frozen=True)
class DofNodes:
    """Where a body's local DOFs (owned and ghosts, unrolled) sit.

    Attributes:
        node: Each DOF's node, named by the node's DOF of the first field (component).
        component: Each DOF's field component (the fields in order, u by component).
        dof_at: ``dof_at[n, c]``: the DOF of component c at node n (n a node's name).
        points: Each node's coordinates [m], at its name.
        parts: Each component's (field, component of u or None), in ``component``'s order.
    """

    node: npt.NDArray[np.int64]
    component: npt.NDArray[np.int64]
    dof_at: npt.NDArray[np.int64]
    points: npt.NDArray[np.float64]
    parts: list[tuple[str, int | None]]


def split_fields(w: Expr, fields: tuple[str, ...]) -> dict[str, Expr]:
    """The parts of a Function or test function of a body's space, by field name."""
    if len(fields) == 1:
        return {fields[0]: w}
    return dict(zip(fields, ufl.split(w), strict=True))


def _space(mesh: dolfinx.mesh.Mesh, fields: tuple[str, ...]) -> dolfinx.fem.FunctionSpace:
    cell = mesh.basix_cell()
    scalar = basix.ufl.element("Lagrange", cell, 1)
    vector = basix.ufl.element("Lagrange", cell, 1, shape=(mesh.geometry.dim,))
    elements = [vector if f == "displacement" else scalar for f in fields]
    element = elements[0] if len(elements) == 1 else basix.ufl.mixed_element(elements)
    return dolfinx.fem.functionspace(mesh, element)


def _constant(mesh: dolfinx.mesh.Mesh) -> Callable[[float], dolfinx.fem.Constant]:
    return lambda value: dolfinx.fem.Constant(mesh, dolfinx.default_scalar_type(value))


def _least(value: float | Schedule | SpaceTime) -> float | None:
    """A number, the least value a schedule takes, or None for a function (x, t)."""
    if isinstance(value, Schedule):
        return min(value.values)
    return None if callable(value) else value


def _law(value: float | Law, constant: Callable[[float], Expr]) -> Law:
    """A law from a callable, or a constant law whose value is a form coefficient."""
    if callable(value):
        return value
    c = constant(float(value))
    return lambda p, T: c


def body_forms(problem: Problem, body: Body) -> BodyForms:
    """Spaces, unknowns and residual forms of ``body`` in ``problem``."""
    mesh, fields = body.mesh, problem.fields
    constant = _constant(mesh)
    W = _space(mesh, fields)
    U = dolfinx.fem.Function(W, name=body.name)
    interfaces = problem.scene.interfaces_of(body.name)
    masters = {i.name: dolfinx.fem.Function(W, name=f"master {i.name}") for i in interfaces}
    u, v = split_fields(U, fields), split_fields(ufl.TestFunction(W), fields)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=body.facet_tags)
    clock: list[dolfinx.fem.Constant] = []  # the time, made on first use

    def time() -> dolfinx.fem.Constant:
        if not clock:
            clock.append(constant(0.0))
        return clock[0]

    x = ufl.SpatialCoordinate(mesh)
    bulk, sources, material_laws = _bulk(
        problem.materials[body.name], u, v, mesh.geometry.dim, constant, x, time
    )
    laws = {f"{name} of body '{body.name}'": (law, ufl.dx) for name, law in material_laws.items()}
    timed: list[tuple[dolfinx.fem.Constant, Schedule]] = []

    def data(value: float | Schedule | SpaceTime) -> Expr:
        """A form coefficient; a schedule's follows the time (starting at t = 0)."""
        if is_space_time(value):
            return value(x, time())
        if not isinstance(value, Schedule):
            return constant(value)
        timed.append((constant(value.at(0.0)), value))
        return timed[-1][0]

    loads = _neumann(problem, body, u, v, ds, data)
    history = tuple(dolfinx.fem.Function(W, name=f"{body.name} at t-{i}") for i in (1, 2))
    rates = (constant(0.0), constant(0.0))
    past = [split_fields(f, fields) for f in history]
    storage = _storage(problem.materials[body.name], u, past, v, rates, constant)
    for form in [sources, storage, *loads.values()]:
        if form is not None:
            bulk += form
    # UFL sums the cell integrals of one form into one before it estimates their quadrature
    # degree: give every cell term that sum's degree, so that the heat sources and storage,
    # assembled alone for the balances, are the very numbers the residual holds (and the
    # Jacobian, derived from the residual, its exact derivative)
    lowered = preprocess_form(bulk, False)  # as UFL estimates: lowered and differentiated
    degree = max(
        ufl.algorithms.estimate_total_polynomial_degree(i.integrand())
        for i in lowered.integrals_by_type("cell")
    )
    bulk, sources, storage = (_with_degree(f, degree) for f in (bulk, sources, storage))
    links, fluxes, remainders, ties, master_only = {}, {}, {}, {}, {}
    n = ufl.FacetNormal(mesh)
    material = problem.materials[body.name]
    at_reference = constant(material.reference_temperature or 0.0)
    young = _law(material.young or 0.0, constant)(ufl.as_ufl(0.0), at_reference)
    stiffness = young / ufl.CellDiameter(mesh)  # the bulk's, per area [Pa/m]
    for i in interfaces:
        Um = masters[i.name]
        jump = {f: u[f] - um for f, um in split_fields(Um, fields).items()}
        contact = problem.contacts[i.name]
        share = contact.joule_to_first if i.bodies[0] == body.name else 1 - contact.joule_to_first
        link, joule, tie, contact_laws = _half_link(
            contact, jump, split_fields(Um, fields), v, n, constant, stiffness, share
        )
        # one quadrature for every term of the half-link (its link, flux, Joule heat and ties),
        # that of the whole: the master equation then sums exactly what the bodies feel
        whole = link if tie is None else link + tie
        dS = ds(i.tag, degree=ufl.algorithms.estimate_total_polynomial_degree(whole))
        for name, law in contact_laws.items():
            laws[f"{name} of interface '{i.name}'"] = (law, dS)
        links[i.name] = link * dS
        remainders[i.name] = None if joule is None else joule * dS
        ties[i.name] = None if tie is None else tie * dS
        flux = link if joule is None else link - joule
        fluxes[i.name] = (flux if tie is None else flux + MASTER_TIE * tie) * dS
        # minus the fluxes is minus the body's linearised link (``links`` and ``ties``) plus
        # the Joule heat and the body's tie less the master's
        extra = joule
        if tie is not None:
            excess = (1.0 - MASTER_TIE) * tie
            extra = excess if extra is None else extra + excess
        master_only[i.name] = None if extra is None else extra * dS
    bcs, held, moving = _dirichlet(problem, body, W, fields, data, time)
    tags = {i.name: i.tag for i in interfaces}
    return BodyForms(
        body.name, W, fields, U, masters, bulk, links, fluxes, remainders, ties, master_only,
        bcs,
        ds, tags, sources, loads, held, laws, history, rates, storage, timed,
        clock[0] if clock else None, moving,
    )  # fmt: skip


def _with_degree(form: ufl.Form | None, degree: int) -> ufl.Form | None:
    """``form`` with the quadrature degree of its cell integrals set to ``degree``."""
    if form is None:
        return None
    return ufl.Form(
        [
            i.reconstruct(metadata={**i.metadata(), "quadrature_degree": degree})
            if i.integral_type() == "cell"
            else i
            for i in form.integrals()
        ]
    )


def _bulk(
    m: Material,
    u: dict,
    v: dict,
    dim: int,
    constant: Callable[[float], Expr],
    x: Expr,
    time: Callable[[], Expr],
) -> tuple[ufl.Form, ufl.Form | None, dict[str, Expr]]:
    """Conduction and thermoelasticity in the volume [W, A, N], and the heat sources apart.

    The sources (Joule heat and ``heat_source``) are a form of their own, −(σ|∇φ|² + Q) v_T,
    so that the heat generated is the sum of the same assembled numbers the residual holds
    (with the residual's quadrature: :func:`body_forms`). Also returns the material's laws of
    T by name.
    """
    reference = constant(m.reference_temperature or 0.0)
    T = u.get("temperature", reference)
    zero = ufl.as_ufl(0.0)
    terms, sources, laws = [], [], {}
    if "temperature" in u:
        k = laws["conductivity"] = _law(m.conductivity, constant)(zero, T)
        terms.append(k * ufl.inner(ufl.grad(T), ufl.grad(v["temperature"])))
        if is_space_time(m.heat_source):
            sources.append(-m.heat_source(x, time()) * v["temperature"])
        elif m.heat_source != 0:
            sources.append(-constant(m.heat_source) * v["temperature"])
    if "potential" in u:
        sigma = laws["electrical_conductivity"] = _law(m.electrical_conductivity, constant)(zero, T)
        phi = u["potential"]
        terms.append(sigma * ufl.inner(ufl.grad(phi), ufl.grad(v["potential"])))
        if "temperature" in u:
            joule = sigma * ufl.inner(ufl.grad(phi), ufl.grad(phi))
            sources.append(-joule * v["temperature"])
    if "displacement" in u:
        E, nu = _law(m.young, constant)(zero, T), constant(m.poisson)
        if callable(m.young) and "temperature" in u:
            laws["young"] = E
        lmbda, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
        strain = ufl.sym(ufl.grad(u["displacement"]))
        stress = lmbda * ufl.tr(strain) * ufl.Identity(dim) + 2 * mu * strain
        if callable(m.expansion) or m.expansion != 0:
            alpha = _law(m.expansion, constant)(zero, T)
            thermal = (3 * lmbda + 2 * mu) * alpha * (T - reference)
            stress -= thermal * ufl.Identity(dim)
        terms.append(ufl.inner(stress, ufl.sym(ufl.grad(v["displacement"]))))
    bulk = sum((t * ufl.dx for t in terms[1:]), terms[0] * ufl.dx)
    heat = sum((t * ufl.dx for t in sources[1:]), sources[0] * ufl.dx) if sources else None
    return bulk, heat, laws


def _storage(
    m: Material,
    u: dict,
    past: list[dict],
    v: dict,
    rates: tuple[Expr, Expr],
    constant: Callable[[float], Expr],
) -> ufl.Form | None:
    """ρ c_p(T) [r₀ (T − T₁) − r₁ (T₁ − T₂)] v_T [W/m^3], or None without thermal inertia."""
    if m.density is None:
        return None
    T, (T1, T2) = u["temperature"], (p["temperature"] for p in past)
    capacity = _law(m.heat_capacity, constant)(ufl.as_ufl(0.0), T)
    change = rates[0] * (T - T1) - rates[1] * (T1 - T2)
    return constant(m.density) * capacity * change * v["temperature"] * ufl.dx


#: The stiffness of an open contact's tie in the master equation, relative to the tie the
#: body's Newton matrix holds (``open_stiffness`` of the normal law's, 1e-9 by default: the
#: master's is then 1e-6 of it). Both sides' ties scaled alike, the master of an open node
#: balances where it did (the mean of its two slaves where the sides' ties are equal), so
#: the root moves only where a node's facets are partly closed, by the ties' share beside
#: the pressures there. What it sets is how well Newton's residual knows an open master
#: (an error of r / κ): with the bodies' tie a master 10 % of its gap off left a residual 60
#: times below Newton's tolerance (the cathode slot of the tests), and the collector bar
#: slot's open masters moved 5 µm at a late step at 1.2M DOFs. Not stiffer: where a body is
#: held by its ties alone (floating, a cold start), its interface response ``D − C A⁻¹ B``
#: subtracts two numbers of the master's tie's size to leave one of the body's, and loses
#: the digits of their ratio (the row of four 3D blocks' exact interface Krylov fell short
#: of the forcing by 8 at 1e5).
MASTER_TIE = 1e3


def _half_link(
    c: Contact,
    jump: dict,
    um: dict,
    v: dict,
    n: Expr,
    constant: Callable[[float], Expr],
    bulk_stiffness: Expr,
    share: float = 0.5,
) -> tuple[Expr, Expr | None, Expr | None, dict[str, Expr]]:
    """The half-link's terms tested with ``v``.

    ``share`` of the contact's Joule heat is deposited on this side: the half-link's own,
    2 g (φ_s − φ_m)² (half of g Δφ² when φ_m sits midway), times 2 ``share``. Returns the
    terms the body feels (the fluxes minus the contact's Joule heat deposited on its side),
    that Joule heat term (or None), the open side's tie in the body's Newton matrix (or
    None; the master equation's is :data:`MASTER_TIE` times it), and the contact's
    conductances h(p, T_m), g(p, T_m) by name (UFL). The tie's stiffness is
    ``open_stiffness`` times the normal law's, capped at 1e6 ``bulk_stiffness`` (the body's
    E / h at the facet) [Pa/m].
    """
    T_m = um.get("temperature", constant(c.temperature))
    pressure: Expr = constant(c.pressure)
    body: Expr = ufl.as_ufl(0.0)
    joule: Expr | None = None
    tie: Expr | None = None
    if "displacement" in jump:
        j = jump["displacement"]
        closure = 2.0 * ufl.dot(j, n) - constant(c.gap)  # of the whole contact, per side
        pressure = c.normal(ufl.max_value(closure, 0.0), constant)
        body += pressure * ufl.dot(n, v["displacement"])
        stretch = ufl.conditional(ufl.le(closure, 0.0), closure, 0.0)
        # at most 1e-3 of the body's own stiffness (open_stiffness ≤ 1e-9): a Newton matrix
        # that holds it where the residual does not is still exact to 1e-3 on open nodes
        kappa = constant(c.open_stiffness) * ufl.min_value(
            1e6 * bulk_stiffness, constant(c.normal.stiffness)
        )
        tie = kappa * stretch * ufl.dot(n, v["displacement"])
        if c.tangential == "stuck":
            slip = j - ufl.dot(j, n) * n
            spring = c.normal.stiffness if c.slip_stiffness is None else c.slip_stiffness
            body += constant(2.0 * spring) * ufl.dot(slip, v["displacement"])
    laws = {}
    if "temperature" in jump:
        laws["conductance"] = _law(c.conductance, constant)(pressure, T_m)
        body += 2.0 * laws["conductance"] * jump["temperature"] * v["temperature"]
    if "potential" in jump:
        laws["electrical_conductance"] = _law(c.electrical_conductance, constant)(pressure, T_m)
        current = 2.0 * laws["electrical_conductance"] * jump["potential"]
        body += current * v["potential"]
        if "temperature" in jump:
            joule = -constant(2 * share) * current * jump["potential"] * v["temperature"]
            body += joule
    return body, joule, tie, laws


def _neumann(
    problem: Problem,
    body: Body,
    u: dict,
    v: dict,
    ds: ufl.Measure,
    constant: Callable[[float | Schedule], Expr],
) -> dict[str, ufl.Form]:
    """Boundary fluxes, convection and pressures [W, A, N], by boundary group."""
    forms: dict[str, ufl.Form] = {}
    for bc in problem.conditions:
        if bc.boundary not in body.boundaries:
            continue
        dS = ds(body.boundaries[bc.boundary])
        if isinstance(bc, HeatFlux):
            form = -constant(bc.value) * v["temperature"] * dS
        elif isinstance(bc, CurrentDensity):
            form = -constant(bc.value) * v["potential"] * dS
        elif isinstance(bc, Convection):
            T, hc = u["temperature"], constant(bc.coefficient)  # a number or a Schedule
            form = hc * (T - constant(bc.ambient)) * v["temperature"] * dS
        elif isinstance(bc, Pressure):  # the traction −p n, tested: −∫ t·v = ∫ p n·v
            n = ufl.FacetNormal(body.mesh)
            form = constant(bc.value) * ufl.dot(n, v["displacement"]) * dS
        else:
            continue
        forms[bc.boundary] = form if bc.boundary not in forms else forms[bc.boundary] + form
    return forms


def _dirichlet(
    problem: Problem,
    body: Body,
    W: dolfinx.fem.FunctionSpace,
    fields: tuple[str, ...],
    constant: Callable[[float | Schedule], Expr],
    time: Callable[[], dolfinx.fem.Constant],
) -> tuple[list[dolfinx.fem.DirichletBC], list[Condition], list]:
    """The body's Dirichlet conditions, the condition of each, and the moving data.

    Moving data: those of ``(x, t)``, with the expressions they are interpolated from again
    at every time.
    """
    bcs, held, moving = [], [], []
    fdim = body.mesh.topology.dim - 1
    for bc in problem.conditions:
        if bc.boundary not in body.boundaries or not isinstance(
            bc, Temperature | Potential | Displacement
        ):
            continue
        V = W if len(fields) == 1 else W.sub(fields.index(FIELD_OF[type(bc)]))
        if isinstance(bc, Displacement):
            V = V.sub(bc.component)
        facets = body.facet_tags.find(body.boundaries[bc.boundary])
        if isinstance(bc.value, Schedule):
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            bcs.append(dolfinx.fem.dirichletbc(constant(bc.value), dofs, V))
            held.append(bc)
            continue
        if not callable(bc.value):
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            bcs.append(dolfinx.fem.dirichletbc(np.float64(bc.value), dofs, V))
            held.append(bc)
            continue
        Vc = V if V is W else V.collapse()[0]
        if is_space_time(bc.value):
            x = ufl.SpatialCoordinate(Vc.mesh)
            points = Vc.element.interpolation_points
            expression = dolfinx.fem.Expression(bc.value(x, time()), points)
            data = dolfinx.fem.Function(Vc)
            data.interpolate(expression)
            moving.append((data, expression))
        else:
            what = f"{problem.scene.source}: boundary '{bc.boundary}'"
            data = _interpolated(bc.value, Vc, what)
        if V is W:
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            where, values = dofs, data.x.array[dofs]
            bcs.append(dolfinx.fem.dirichletbc(data, dofs))
        else:
            dofs = dolfinx.fem.locate_dofs_topological((V, Vc), fdim, facets)
            where, values = dofs[1], data.x.array[dofs[1]]
            bcs.append(dolfinx.fem.dirichletbc(data, dofs, V))
        held.append(bc)
        bad = ~np.isfinite(values)
        first = (
            (values[bad][0], Vc.tabulate_dof_coordinates()[where[bad][0]]) if bad.any() else None
        )
        found = [item for item in body.mesh.comm.allgather(first) if item is not None]
        if found:  # on every rank of the body
            raise ValueError(
                f"{problem.scene.source}: boundary '{bc.boundary}' of body '{body.name}': "
                f"{type(bc).__name__} data = {found[0][0]} at x = {found[0][1]}: must be finite"
            )
    return bcs, held, moving


def _interpolated(value: Callable, V: dolfinx.fem.FunctionSpace, what: str) -> dolfinx.fem.Function:
    """A function of the points as a Function on V.

    As numpy (dolfinx's interpolation convention) or, where that fails, as UFL of the
    spatial coordinate.
    """
    data = dolfinx.fem.Function(V)
    try:
        data.interpolate(value)
        return data
    except Exception as numpy_error:
        try:
            expr = value(ufl.SpatialCoordinate(V.mesh))
            data.interpolate(dolfinx.fem.Expression(expr, V.element.interpolation_points))
            return data
        except Exception as ufl_error:
            raise ValueError(
                f"{what}: Dirichlet data must be a number or a function of the points x, of "
                f"numpy arrays (shape (3, n)) or of ufl.SpatialCoordinate; as numpy: "
                f"{numpy_error!r}; as UFL: {ufl_error!r}"
            ) from ufl_error
