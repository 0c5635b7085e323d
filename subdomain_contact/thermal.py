"""Steady heat conduction per body as UFL forms, and the thermal contact half-link.

Units: temperature K, conductivity W/(m K), volumetric source W/m^3, heat flux W/m^2,
convection and contact conductance W/(m^2 K).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import dolfinx
import ufl

from subdomain_contact.geometry import Body, Scene
from subdomain_contact.laws import check_finite

__all__ = [
    "BodyForms",
    "Convection",
    "HeatFlux",
    "Temperature",
    "ThermalContact",
    "ThermalMaterial",
    "ThermalProblem",
    "body_forms",
]


@dataclass(frozen=True)
class ThermalMaterial:
    """A body's conductivity k [W/(m K)] and volumetric heat source [W/m^3]."""

    conductivity: float
    source: float = 0.0


@dataclass(frozen=True)
class ThermalContact:
    """Thermal contact conductance h [W/(m^2 K)] of a whole interface (never h̄ = 2h).

    h = 0 is an insulating contact: the bodies do not exchange heat and the master
    temperatures, which nothing defines, are left at 0.
    """

    conductance: float


@dataclass(frozen=True)
class Temperature:
    """Dirichlet condition: temperature [K] on a boundary group."""

    boundary: str
    value: float


@dataclass(frozen=True)
class HeatFlux:
    """Neumann condition: heat flux [W/m^2] *into* the body through a boundary group."""

    boundary: str
    value: float


@dataclass(frozen=True)
class Convection:
    """Robin condition q = coefficient (ambient - T): coefficient [W/(m^2 K)], ambient [K]."""

    boundary: str
    coefficient: float
    ambient: float


BoundaryCondition = Temperature | HeatFlux | Convection


@dataclass(frozen=True)
class ThermalProblem:
    """A scene with materials, contact conductances and boundary conditions.

    Attributes:
        scene: Bodies and interfaces.
        materials: Body name -> material.
        contacts: Interface name -> contact.
        conditions: Boundary conditions by boundary-group name; a group that spans several
            bodies applies to each of them.
    """

    scene: Scene
    materials: Mapping[str, ThermalMaterial]
    contacts: Mapping[str, ThermalContact]
    conditions: Sequence[BoundaryCondition] = ()

    def __post_init__(self) -> None:
        source = self.scene.source
        self.scene.check_entries(self.materials, self.contacts)
        for name, m in self.materials.items():
            check_finite(m.conductivity, f"body '{name}': conductivity", positive=True)
            check_finite(m.source, f"body '{name}': source")
        for name, c in self.contacts.items():
            check_finite(c.conductance, f"interface '{name}': conductance h")
            if c.conductance < 0:
                raise ValueError(
                    f"interface '{name}': conductance h = {c.conductance!r}: must be >= 0 "
                    "(0: an insulating contact)"
                )
        every = set().union(*(b.boundaries for b in self.scene.bodies.values()))
        for bc in self.conditions:
            if bc.boundary not in every or bc.boundary in self.scene.interfaces:
                raise ValueError(
                    f"{source}: no boundary group named '{bc.boundary}' on any body; "
                    f"boundary groups: {sorted(every - set(self.scene.interfaces))}"
                )
            for field in ("value", "coefficient", "ambient"):
                if hasattr(bc, field):
                    check_finite(getattr(bc, field), f"boundary '{bc.boundary}': {field}")
            if isinstance(bc, Convection) and bc.coefficient < 0:
                raise ValueError(f"boundary '{bc.boundary}': coefficient must be >= 0")
        self._check_anchored()

    def _check_anchored(self) -> None:
        """Refuse bodies whose temperature no condition fixes, even through contacts.

        A group of bodies joined by conducting contacts (h > 0) needs a temperature or a
        convection condition somewhere; without one its temperature is defined only up to
        a constant and every solver would return an arbitrary level.
        """
        scene = self.scene
        anchors = {
            bc.boundary
            for bc in self.conditions
            if isinstance(bc, Temperature) or (isinstance(bc, Convection) and bc.coefficient > 0)
        }
        group = {name: {name} for name in scene.bodies}
        for k, interface in scene.interfaces.items():
            if self.contacts[k].conductance > 0:
                merged = group[interface.bodies[0]] | group[interface.bodies[1]]
                for name in merged:
                    group[name] = merged
        for members in {frozenset(g) for g in group.values()}:
            if not any(anchors & set(scene.bodies[n].boundaries) for n in members):
                raise ValueError(
                    f"{scene.source}: bodies {sorted(members)} have no temperature or "
                    "convection condition and no conducting contact (h > 0) leads to one: "
                    "their temperature is defined only up to a constant"
                )

    def half_link(self, interface: str) -> float:
        """Half-link coefficient h̄ = 2 h [W/(m^2 K)] of an interface (METHOD.md §2)."""
        return 2.0 * self.contacts[interface].conductance


@dataclass(frozen=True)
class BodyForms:
    """A body's forms on its P1 temperature space ``V``.

    Attributes:
        V: Temperature space.
        solid: Bilinear form of the solid alone (conduction and convection) [W/K].
        load: Linear form of sources, fluxes and convection [W].
        contact_mass: Interface name -> ``∫ T v ds`` on the body's side of it [m^(d-1)].
        bcs: Dirichlet conditions.
    """

    V: dolfinx.fem.FunctionSpace
    solid: ufl.Form
    load: ufl.Form
    contact_mass: Mapping[str, ufl.Form]
    bcs: list[dolfinx.fem.DirichletBC]


def body_forms(problem: ThermalProblem, body: Body) -> BodyForms:
    """UFL forms of steady conduction in ``body``: -div(k grad T) = f with its conditions."""
    mesh = body.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
    T, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=body.facet_tags)
    material = problem.materials[body.name]
    k = dolfinx.fem.Constant(mesh, float(material.conductivity))
    f = dolfinx.fem.Constant(mesh, float(material.source))
    solid = k * ufl.inner(ufl.grad(T), ufl.grad(v)) * ufl.dx
    load = f * v * ufl.dx
    bcs = []
    fdim = mesh.topology.dim - 1
    for bc in problem.conditions:
        if bc.boundary not in body.boundaries:
            continue
        tag = body.boundaries[bc.boundary]
        if isinstance(bc, Temperature):
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, body.facet_tags.find(tag))
            value = dolfinx.fem.Constant(mesh, float(bc.value))
            bcs.append(dolfinx.fem.dirichletbc(value, dofs, V))
        elif isinstance(bc, HeatFlux):
            load += dolfinx.fem.Constant(mesh, float(bc.value)) * v * ds(tag)
        else:
            hc = dolfinx.fem.Constant(mesh, float(bc.coefficient))
            solid += hc * T * v * ds(tag)
            load += hc * dolfinx.fem.Constant(mesh, float(bc.ambient)) * v * ds(tag)
    contact_mass = {i.name: T * v * ds(i.tag) for i in problem.scene.interfaces_of(body.name)}
    return BodyForms(V, solid, load, contact_mass, bcs)
