"""Thermo-electro-mechanical bodies and contacts as UFL residual forms.

Fields per body (only those the materials ask for are built): temperature T [K], electric
potential φ [V], displacement u [m] (plane strain in 2D). Bulk couplings: Joule heating
σ(T)|∇φ|², conductivities k(T) and σ(T), thermal strain α (T − T_ref).

Each contact interface k carries master copies of the fields. On body α they are the
Function ``masters[k]`` *of the body's own space*: only its slave DOFs on Γ_k matter, and
since both meshes are conforming P1 there, its trace on Γ_k is the master field. The
half-link of body α at Γ_k (METHOD.md §2), with n the body's outward normal:

- thermal flux h̄ (T − T_m), h̄ = 2 h(p, T_m);
- current ḡ (φ − φ_m), ḡ = 2 g(p, T_m), and the Joule heat ḡ (φ − φ_m)² on the slave side;
- normal pressure p = P(⟨2δ⟩), δ = (u − u_m)·n − gap/2 (unilateral, P the closure law of the
  whole contact); tangential traction k̄_t (u − u_m)_t when stuck, none when free.

Residuals are internal minus external. The body residual holds the half-links with the body's
test function; the master residual of Γ_k holds minus the same fluxes (Joule heat excluded)
with the master test function, which on body α is the test function at the slave DOFs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import basix.ufl
import dolfinx
import numpy as np
import numpy.typing as npt
import ufl

from subdomain_contact.geometry import Body, Scene
from subdomain_contact.laws import Law, as_law, check_finite
from subdomain_contact.thermal import Convection, HeatFlux, Temperature

__all__ = [
    "FIELDS",
    "BodyPhysics",
    "Contact",
    "CoupledProblem",
    "CurrentDensity",
    "Displacement",
    "ExponentialClosure",
    "Material",
    "Penalty",
    "Potential",
    "body_physics",
]

#: Every field a body can carry, in the order of its mixed space.
FIELDS = ("temperature", "potential", "displacement")


@dataclass(frozen=True)
class Material:
    """A body's material; a field exists where its property is given.

    Attributes:
        conductivity: Thermal conductivity k(T) [W/(m K)]: a number or a law ``(p, T)``.
        electrical_conductivity: σ(T) [S/m].
        young: Young's modulus E [Pa].
        poisson: Poisson's ratio ν.
        expansion: Linear thermal expansion α [1/K].
        reference_temperature: Temperature [K] of zero thermal strain.
        heat_source: Volumetric heat source [W/m^3] (besides Joule heat).
    """

    conductivity: float | Law | None = None
    electrical_conductivity: float | Law | None = None
    young: float | None = None
    poisson: float = 0.3
    expansion: float = 0.0
    reference_temperature: float = 0.0
    heat_source: float = 0.0

    def fields(self) -> tuple[str, ...]:
        """The fields this material needs."""
        given = [self.conductivity, self.electrical_conductivity, self.young]
        return tuple(f for f, g in zip(FIELDS, given, strict=True) if g is not None)


@dataclass(frozen=True)
class Penalty:
    """Linear pressure–closure law p = k_n δ of the whole contact, k_n [Pa/m]."""

    stiffness: float

    def __call__(self, closure: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Pressure [Pa] at closure δ ≥ 0 [m]."""
        return self.stiffness * closure


@dataclass(frozen=True)
class ExponentialClosure:
    """Stiffening pressure–closure law p = k_n δ₀ (exp(δ/δ₀) − 1).

    Attributes:
        stiffness: Initial stiffness k_n [Pa/m].
        closure: Closure δ₀ [m] over which the stiffness grows by e.
    """

    stiffness: float
    closure: float

    def __call__(self, closure: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Pressure [Pa] at closure δ ≥ 0 [m]."""
        return self.stiffness * self.closure * (ufl.exp(closure / self.closure) - 1.0)


NormalLaw = Penalty | ExponentialClosure


@dataclass(frozen=True)
class Contact:
    """The laws of one contact interface (of the whole contact, never the half-link's 2×).

    Attributes:
        conductance: Thermal conductance h(p, T) [W/(m^2 K)].
        electrical_conductance: Electrical conductance g(p, T) [S/m^2].
        normal: Pressure–closure law; unilateral (no tension).
        tangential: ``"free"`` (no friction) or ``"stuck"`` (penalised slip, with the normal
            law's initial stiffness).
        gap: Initial gap [m] between the two sides (0: touching).
        pressure: Pressure [Pa] the laws see when the scene has no displacement field.
        temperature: Temperature [K] the laws see when the scene has no temperature field.
        open_stiffness: Stiffness in tension, relative to the normal law's: it keeps the master
            layer of an open contact defined; its force is this fraction of a closed one's.
    """

    conductance: float | Law | None = None
    electrical_conductance: float | Law | None = None
    normal: NormalLaw | None = None
    tangential: str = "free"
    gap: float = 0.0
    pressure: float = 0.0
    temperature: float = 0.0
    open_stiffness: float = 1e-9


@dataclass(frozen=True)
class Potential:
    """Dirichlet condition: electric potential [V] on a boundary group."""

    boundary: str
    value: float


@dataclass(frozen=True)
class CurrentDensity:
    """Neumann condition: current density [A/m^2] *into* the body through a boundary group."""

    boundary: str
    value: float


@dataclass(frozen=True)
class Displacement:
    """Dirichlet condition on one displacement component (0: x, 1: y, 2: z) [m]."""

    boundary: str
    component: int
    value: float


Condition = Temperature | HeatFlux | Convection | Potential | CurrentDensity | Displacement
_FIELD_OF = {
    Temperature: "temperature",
    HeatFlux: "temperature",
    Convection: "temperature",
    Potential: "potential",
    CurrentDensity: "potential",
    Displacement: "displacement",
}


@dataclass(frozen=True)
class CoupledProblem:
    """A scene with materials, contact laws and boundary conditions, for every field.

    Attributes:
        scene: Bodies and interfaces.
        materials: Body name -> material; every body must give the same fields.
        contacts: Interface name -> contact laws (one per field of the scene).
        conditions: Boundary conditions by boundary-group name.
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

    def _check_material(self, name: str, m: Material) -> None:
        for attr in ("conductivity", "electrical_conductivity", "young"):
            value = getattr(m, attr)
            if value is not None and not callable(value):
                check_finite(value, f"body '{name}': {attr}", positive=True)
        for attr in ("expansion", "reference_temperature", "heat_source"):
            check_finite(getattr(m, attr), f"body '{name}': {attr}")
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
                check_finite(value, f"interface '{name}': {attr}", positive=True)
        if c.normal is not None:
            check_finite(c.normal.stiffness, f"interface '{name}': normal stiffness", positive=True)
        if c.tangential not in ("free", "stuck"):
            raise ValueError(f"interface '{name}': tangential = {c.tangential!r}: free or stuck")
        for attr in ("gap", "pressure", "temperature"):
            check_finite(getattr(c, attr), f"interface '{name}': {attr}")
        check_finite(c.open_stiffness, f"interface '{name}': open_stiffness", positive=True)

    def _check_conditions(self) -> None:
        source = self.scene.source
        every = set().union(*(b.boundaries for b in self.scene.bodies.values()))
        every -= set(self.scene.interfaces)
        for bc in self.conditions:
            if bc.boundary not in every:
                raise ValueError(
                    f"{source}: no boundary group named '{bc.boundary}' on any body; "
                    f"boundary groups: {sorted(every)}"
                )
            if _FIELD_OF[type(bc)] not in self.fields:
                raise ValueError(
                    f"boundary '{bc.boundary}': {type(bc).__name__} needs the "
                    f"{_FIELD_OF[type(bc)]} field, which no material defines"
                )
            for attr in ("value", "coefficient", "ambient"):
                if hasattr(bc, attr):
                    check_finite(getattr(bc, attr), f"boundary '{bc.boundary}': {attr}")
            if isinstance(bc, Displacement) and bc.component not in range(
                self.scene.bodies[next(iter(self.scene.bodies))].mesh.geometry.dim
            ):
                raise ValueError(f"boundary '{bc.boundary}': no component {bc.component}")


@dataclass
class BodyPhysics:
    """A body's fields, its master Functions and its residual forms.

    Attributes:
        name: Body name.
        W: The body's space (mixed when it carries several fields).
        fields: The fields, in the order of ``W``'s sub-spaces.
        U: The body's solution.
        masters: Interface name -> master values on the body's space (slave DOFs only).
        residual: Body residual form (internal − external) [W, A, N by field].
        master_residuals: Interface name -> master residual form on the body's space.
        bcs: Dirichlet conditions.
        contact: Interface name -> the half-link's ``"pressure"`` [Pa], ``"current density"``
            [A/m^2] and ``"heat flux"`` [W/m^2] from the body into the master (UFL), where
            the scene has the field.
        ds: Boundary measure of the body, with its facet tags.
        tags: Interface name -> facet tag on the body.
    """

    name: str
    W: dolfinx.fem.FunctionSpace
    fields: tuple[str, ...]
    U: dolfinx.fem.Function
    masters: dict[str, dolfinx.fem.Function]
    residual: ufl.Form
    master_residuals: dict[str, ufl.Form]
    bcs: list[dolfinx.fem.DirichletBC]
    contact: dict[str, dict[str, ufl.core.expr.Expr]]
    ds: ufl.Measure
    tags: dict[str, int]

    def subspace(self, name: str, component: int | None = None) -> dolfinx.fem.FunctionSpace:
        """The sub-space of one field (or of one displacement component)."""
        V = self.W if len(self.fields) == 1 else self.W.sub(self.fields.index(name))
        return V if component is None else V.sub(component)

    def collapsed(
        self, name: str, component: int | None = None
    ) -> tuple[dolfinx.fem.FunctionSpace, npt.NDArray[np.int32]]:
        """The sub-space as a space of its own, and the index in ``W`` of each of its DOFs."""
        V = self.subspace(name, component)
        if V is self.W:
            size = self.W.dofmap.index_map.size_local + self.W.dofmap.index_map.num_ghosts
            return self.W, np.arange(size * self.W.dofmap.index_map_bs, dtype=np.int32)
        collapsed, to_parent = V.collapse()
        return collapsed, np.asarray(to_parent[0])


def _split(w: ufl.core.expr.Expr, fields: tuple[str, ...]) -> dict[str, ufl.core.expr.Expr]:
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


def body_physics(problem: CoupledProblem, body: Body) -> BodyPhysics:
    """Spaces, unknowns and residual forms of ``body`` in ``problem``."""
    mesh, fields = body.mesh, problem.fields
    W = _space(mesh, fields)
    U = dolfinx.fem.Function(W, name=body.name)
    interfaces = problem.scene.interfaces_of(body.name)
    masters = {i.name: dolfinx.fem.Function(W, name=f"master {i.name}") for i in interfaces}
    u, v = _split(U, fields), _split(ufl.TestFunction(W), fields)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=body.facet_tags)
    residual = _bulk(problem.materials[body.name], u, v, mesh.geometry.dim)
    for form in _neumann(problem, body, u, v, ds):
        residual += form
    master_residuals, contact = {}, {}
    n = ufl.FacetNormal(mesh)
    for i in interfaces:
        um = _split(masters[i.name], fields)
        fluxes, joule, contact[i.name] = _half_link(problem.contacts[i.name], u, um, v, n)
        residual += (fluxes - joule) * ds(i.tag)
        master_residuals[i.name] = -fluxes * ds(i.tag)
    bcs = _dirichlet(problem, body, W, fields)
    tags = {i.name: i.tag for i in interfaces}
    return BodyPhysics(
        body.name, W, fields, U, masters, residual, master_residuals, bcs, contact, ds, tags
    )


def _bulk(m: Material, u: dict, v: dict, dim: int) -> ufl.core.expr.Expr:
    """Conduction, Joule heating and thermoelasticity in the volume [W, A, N]."""
    T = u.get("temperature", ufl.as_ufl(m.reference_temperature))
    zero = ufl.as_ufl(0.0)
    terms = []
    if "temperature" in u:
        k = as_law(m.conductivity)(zero, T)
        terms.append(k * ufl.inner(ufl.grad(T), ufl.grad(v["temperature"])))
        terms.append(-m.heat_source * v["temperature"])
    if "potential" in u:
        sigma = as_law(m.electrical_conductivity)(zero, T)
        phi = u["potential"]
        terms.append(sigma * ufl.inner(ufl.grad(phi), ufl.grad(v["potential"])))
        if "temperature" in u:
            joule = sigma * ufl.inner(ufl.grad(phi), ufl.grad(phi))
            terms.append(-joule * v["temperature"])
    if "displacement" in u:
        E, nu = m.young, m.poisson
        lmbda, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
        strain = ufl.sym(ufl.grad(u["displacement"]))
        thermal = (3 * lmbda + 2 * mu) * m.expansion * (T - m.reference_temperature)
        stress = lmbda * ufl.tr(strain) * ufl.Identity(dim) + 2 * mu * strain
        stress -= thermal * ufl.Identity(dim)
        terms.append(ufl.inner(stress, ufl.sym(ufl.grad(v["displacement"]))))
    return sum(terms[1:], terms[0]) * ufl.dx


def _half_link(
    c: Contact, u: dict, um: dict, v: dict, n: ufl.core.expr.Expr
) -> tuple[ufl.core.expr.Expr, ufl.core.expr.Expr, dict[str, ufl.core.expr.Expr]]:
    """Flux terms (tested with ``v``), slave-side Joule heat, and the half-link's fluxes."""
    T_m = um.get("temperature", ufl.as_ufl(c.temperature))
    pressure = ufl.as_ufl(c.pressure)
    fluxes, joule = ufl.as_ufl(0.0), ufl.as_ufl(0.0)
    if "displacement" in u:
        jump = u["displacement"] - um["displacement"]
        closure = 2.0 * ufl.dot(jump, n) - c.gap  # closure of the whole contact, per side
        pressure = c.normal(ufl.max_value(closure, 0.0))
        # an open side (closure ≤ 0, the tie included) keeps a tiny stiffness
        stretch = ufl.conditional(ufl.le(closure, 0.0), closure, 0.0)
        tension = c.open_stiffness * c.normal.stiffness * stretch
        fluxes += (pressure + tension) * ufl.dot(n, v["displacement"])
        if c.tangential == "stuck":
            slip = jump - ufl.dot(jump, n) * n
            fluxes += 2.0 * c.normal.stiffness * ufl.dot(slip, v["displacement"])
    out = {"pressure": pressure}
    if "temperature" in u:
        h_bar = 2.0 * as_law(c.conductance)(pressure, T_m)
        out["heat flux"] = h_bar * (u["temperature"] - T_m)
        fluxes += out["heat flux"] * v["temperature"]
    if "potential" in u:
        g_bar = 2.0 * as_law(c.electrical_conductance)(pressure, T_m)
        drop = u["potential"] - um["potential"]
        out["current density"] = g_bar * drop
        fluxes += out["current density"] * v["potential"]
        if "temperature" in u:
            joule = g_bar * drop**2 * v["temperature"]
    return fluxes, joule, out


def _neumann(
    problem: CoupledProblem, body: Body, u: dict, v: dict, ds: ufl.Measure
) -> list[ufl.Form]:
    """Boundary fluxes and convection [W, A]."""
    forms = []
    for bc in problem.conditions:
        if bc.boundary not in body.boundaries:
            continue
        tag = body.boundaries[bc.boundary]
        if isinstance(bc, HeatFlux):
            forms.append(-bc.value * v["temperature"] * ds(tag))
        elif isinstance(bc, CurrentDensity):
            forms.append(-bc.value * v["potential"] * ds(tag))
        elif isinstance(bc, Convection):
            T = u["temperature"]
            forms.append(bc.coefficient * (T - bc.ambient) * v["temperature"] * ds(tag))
    return forms


def _dirichlet(
    problem: CoupledProblem, body: Body, W: dolfinx.fem.FunctionSpace, fields: tuple[str, ...]
) -> list[dolfinx.fem.DirichletBC]:
    bcs = []
    fdim = body.mesh.topology.dim - 1
    for bc in problem.conditions:
        if bc.boundary not in body.boundaries or not isinstance(
            bc, Temperature | Potential | Displacement
        ):
            continue
        V = W if len(fields) == 1 else W.sub(fields.index(_FIELD_OF[type(bc)]))
        if isinstance(bc, Displacement):
            V = V.sub(bc.component)
        facets = body.facet_tags.find(body.boundaries[bc.boundary])
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
        bcs.append(dolfinx.fem.dirichletbc(np.float64(bc.value), dofs, V))
    return bcs
