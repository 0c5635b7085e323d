"""What a user reads back from a solved system: integrals by group, contact fields, balances.

Every number here is a sum of the assembled numbers the residual itself holds, so that the
balance of each field closes to the solver's tolerance, not to a quadrature error:

- through a boundary group where a Dirichlet condition holds the field, the *reaction*: the
  residual assembled without the condition, summed over the DOFs the condition fixes (a DOF
  held by two conditions belongs to the first one listed), plus the group's own flux terms;
- through a group with flux or convection conditions, their assembled terms;
- through a contact interface, what leaves its first body into it per master node
  (:meth:`~subdomain_contact.body.Body.contact_outflow`, the stable form of each node),
  averaged with what enters the second.

Signs: flows are *into the bodies* through a boundary group [W, A; N for the force a support
exerts], and *from the first body of an interface to the second* (the order of
``Interface.bodies``). In 2D every integral is per metre of depth. All functions are
collective over the system's communicator.
"""

from __future__ import annotations

from collections.abc import Hashable

import dolfinx
import dolfinx.fem.petsc
import dolfinx.geometry
import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.body import Body
from subdomain_contact.laws import antiderivative
from subdomain_contact.physics import FIELD_OF, Displacement
from subdomain_contact.system import System

__all__ = [
    "average",
    "balance",
    "bulk_heat",
    "contact_fields",
    "current",
    "enthalpy",
    "force",
    "heat",
    "open_share",
    "summary",
    "value_at",
    "voltage_drop",
]

Vector = npt.NDArray[np.float64]

#: Units of the contact fields of :func:`contact_fields`.
CONTACT_UNITS = {
    "temperature jump": "K",
    "heat flux": "W/m^2",
    "contact Joule heat": "W/m^2",
    "potential jump": "V",
    "current density": "A/m^2",
    "pressure": "Pa",
    "gap": "m",
}


#: A contact node is open where its gap exceeds this share of the face's largest |gap| (open
#: or penetrated). Below it the gap's sign is the round-off of the displacements: on the
#: collector bar slot at 204k DOFs the two Newton routes, equal to 1e-15, classed 0.27 % of the
#: slot sides' area differently by the sign of a pressure at round-off alone.
OPEN_GAP = 1e-9


def open_share(gap: Vector, area: Vector) -> float:
    """The share of a contact's area that is open (nodal ``gap`` [m], ``area`` [m²]).

    Open where the gap is above :data:`OPEN_GAP` times the face's largest |gap|: a node at
    closure to round-off counts as closed on every route and rank count.
    """
    scale = float(np.max(np.abs(gap), initial=0.0))
    return float(area[gap > OPEN_GAP * scale].sum() / area.sum())


def current(system: System, group: str) -> float:
    """Current [A] into the bodies through a boundary group, or across an interface."""
    return float(_flow(_Reading(system), group, "potential", None))


def heat(system: System, group: str) -> float:
    """Heat [W] into the bodies through a boundary group, or conducted across an interface.

    Across an interface: the conducted part, the mean of what leaves the first body and
    what enters the second; the contact's Joule heat is in :func:`balance`.
    """
    return float(_flow(_Reading(system), group, "temperature", None))


def force(system: System, group: str) -> Vector:
    """Force [N] the supports or the loads of a boundary group exert on the bodies, per component.

    Across an interface: the force the first body exerts on the second, in the components
    the contact carries (the normal one alone when it slides freely).
    """
    return _force(_Reading(system), group)


def _force(reading: _Reading, group: str) -> Vector:
    dim = next(iter(reading.system.problem.scene.bodies.values())).mesh.geometry.dim
    return np.array([_flow(reading, group, "displacement", c) for c in range(dim)])


def average(system: System, group: str, field: str) -> float:
    """Mean of a scalar field [K, V] over a boundary group: ∫ f ds / ∫ ds.

    Over an interface: on its first body's side.
    """
    scene = system.problem.scene
    totals = np.zeros(2)
    for body in system.bodies.values():
        if group in scene.interfaces and body.name != scene.interfaces[group].bodies[0]:
            continue
        tag = {**scene.bodies[body.name].boundaries, **body.forms.tags}.get(group)
        if tag is None:
            continue
        ds = body.forms.ds(tag)
        one = dolfinx.fem.Constant(body.forms.W.mesh, 1.0)
        forms = (
            body.compiled(("mean", group, field), body.forms.parts()[field] * ds),
            body.compiled(("measure", group), one * ds),
        )
        local = np.array([dolfinx.fem.assemble_scalar(f) for f in forms])
        totals += _once(system, body.comm.allreduce(local, op=MPI.SUM))
    totals = system.comm.allreduce(totals, op=MPI.SUM)
    if totals[1] == 0:
        raise ValueError(f"{scene.source}: no boundary group or interface named '{group}'")
    return float(totals[0] / totals[1])


def value_at(
    system: System, body: str, field: str, point: tuple[float, ...], component: int | None = None
) -> float:
    """A field's value [K, V, m] at a point of a body (a displacement: give its component).

    Raises:
        ValueError: The point is not in the body (naming both).
    """
    found = (False, 0.0)
    if body in system.bodies:
        b = system.bodies[body]
        V, parent_of = b.forms.collapsed(field, component)
        f = dolfinx.fem.Function(V)
        f.x.array[:] = b.U.x.array[parent_of]
        mesh = V.mesh
        x = np.zeros((1, 3))
        x[0, : len(point)] = point
        tree = dolfinx.geometry.bb_tree(mesh, mesh.topology.dim)
        candidates = dolfinx.geometry.compute_collisions_points(tree, x)
        cells = dolfinx.geometry.compute_colliding_cells(mesh, candidates, x).links(0)
        if len(cells):
            found = (True, float(f.eval(x, cells[:1])[0]))
    for hit, value in system.comm.allgather(found):
        if hit:
            return value
    raise ValueError(f"{system.problem.scene.source}: the point {point} is not in body '{body}'")


def voltage_drop(system: System, high: str, low: str) -> float:
    """Mean potential of group ``high`` minus that of ``low`` [V]."""
    return average(system, high, "potential") - average(system, low, "potential")


def balance(system: System) -> dict[str, dict]:
    """Each conserved field's budget over the whole scene.

    ``"heat"`` [W]: ``groups`` (heat into the bodies through each boundary group with a
    temperature condition), ``in`` and ``out`` (their positive and negative parts),
    ``generated`` (Joule heat of the bulk and the contacts, and volume sources), ``stored``
    (the heat the bodies store per unit time over the last time step, 0 when steady),
    ``imbalance = in − out + generated − stored``, ``scale`` and ``relative = |imbalance| /
    scale``.
    ``"current"`` [A]: the same without generation. ``"force"`` [N]: the reactions of each
    group with a displacement or pressure condition (supports and loads), their ``sum`` per
    component (it must vanish), ``scale`` and ``relative``.

    The scale is the larger of the flows and of the field's *cold load*, the 1-norm of its
    residual with every unknown zero but the Dirichlet values: what the supports would carry
    if the field were held at its boundary values alone, and so the size of the round-off
    of any reaction. A scene where nothing flows (uniform temperature) then still has a
    meaningful relative imbalance.
    """
    return _balance(_Reading(system))


def _balance(reading: _Reading) -> dict[str, dict]:
    system = reading.system
    out = {}
    problem = system.problem
    cold = _cold_loads(system)
    for name, field in (("heat", "temperature"), ("current", "potential")):
        if field not in problem.fields:
            continue
        groups = {
            g: float(_flow(reading, g, field, None)) for g in _condition_groups(system, field)
        }
        flows = np.array(list(groups.values()))
        generated = _generated(system) if field == "temperature" else 0.0
        stored = _stored(system) if field == "temperature" else 0.0
        total_in, total_out = float(flows[flows > 0].sum()), float(-flows[flows < 0].sum())
        imbalance = total_in - total_out + generated - stored
        scale = max(total_in, total_out, abs(generated), abs(stored), cold[field])
        out[name] = {
            "groups": groups,
            "in": total_in,
            "out": total_out,
            "generated": float(generated),
            "stored": float(stored),
            "imbalance": float(imbalance),
            "scale": scale,
            "relative": abs(imbalance) / scale if scale > 0 else 0.0,
        }
    if "displacement" in problem.fields:
        groups = {g: _force(reading, g) for g in _condition_groups(system, "displacement")}
        total = np.sum(list(groups.values()), axis=0)
        scale = max(max(np.abs(f).sum() for f in groups.values()), cold["displacement"])
        out["force"] = {
            "groups": {g: f.tolist() for g, f in groups.items()},
            "sum": total.tolist(),
            "scale": float(scale),
            "relative": float(np.abs(total).max() / scale) if scale > 0 else 0.0,
        }
    return out


def contact_fields(system: System) -> dict[str, dict[str, Vector]]:
    """Nodal contact fields of every interface, in master order, on every rank.

    Per interface: ``"coordinates"`` [m] of the master nodes, ``"area"`` (their nodal areas
    ∫ φ_i ds [m^(d−1)]), and where the scene has the field: ``"temperature jump"``
    T₁ − T₂ [K], ``"heat flux"`` conducted from the first body to the second [W/m²],
    ``"contact Joule heat"`` [W/m²] (with temperature and potential), ``"potential jump"``
    φ₁ − φ₂ [V], ``"current density"`` from the first body to the second [A/m²],
    ``"pressure"`` [Pa] (compression positive) and ``"gap"`` [m] (open positive). Fluxes
    are nodal reactions over nodal areas: their sums times the areas are the integrals of
    :func:`heat`, :func:`current` and :func:`force` exactly.
    """
    return _contact_fields(_Reading(system))


def _contact_fields(reading: _Reading) -> dict[str, dict[str, Vector]]:
    system = reading.system
    out = {}
    for k, layer in system.layers.items():
        sides = reading.sides(k)
        first, second = (sides[name] for name in layer.interface.bodies)
        area = first["area"][: layer.nodes]
        fields: dict[str, Vector] = {"coordinates": layer.coordinates, "area": area}
        for c, (field, _) in enumerate(layer.channels):
            part = slice(c * layer.nodes, (c + 1) * layer.nodes)
            if field == "temperature":
                fields["temperature jump"] = first["values"][part] - second["values"][part]
                leaving, entering = first["outflow"][part], -second["outflow"][part]
                fields["heat flux"] = 0.5 * (leaving + entering) / area
                if "potential" in system.problem.fields:
                    fields["contact Joule heat"] = (entering - leaving) / area
            elif field == "potential":
                fields["potential jump"] = first["values"][part] - second["values"][part]
                leaving, entering = first["outflow"][part], -second["outflow"][part]
                fields["current density"] = 0.5 * (leaving + entering) / area
        if "displacement" in system.problem.fields:
            fields["pressure"], fields["gap"] = _normal_contact(system, k, first, second, area)
        out[k] = fields
    return out


def summary(system: System) -> dict:
    """Every integral a report needs, as plain numbers (for JSON).

    ``balance`` (:func:`balance`); ``groups``: per boundary group with a condition, the
    ``current`` [A], ``heat`` [W], ``force`` [N] through it and its mean ``temperature`` [K]
    and ``potential`` [V], where the scene has the field; ``contacts``: per interface, the
    current, heat and force across it, its contact Joule heat [W], and with displacements its
    ``mean pressure`` and ``max pressure`` [Pa] and its ``open share`` (the share of its
    area where the gap is open).
    """
    reading = _Reading(system)
    fields = system.problem.fields
    groups: dict[str, dict] = {}
    for group in dict.fromkeys(bc.boundary for bc in system.problem.conditions):
        row = groups.setdefault(group, {})
        if "potential" in fields:
            row["current"] = float(_flow(reading, group, "potential", None))
            row["potential"] = average(system, group, "potential")
        if "temperature" in fields:
            row["heat"] = float(_flow(reading, group, "temperature", None))
            row["temperature"] = average(system, group, "temperature")
        if "displacement" in fields:
            row["force"] = _force(reading, group).tolist()
    contacts: dict[str, dict] = {}
    nodal = _contact_fields(reading)
    for k, values in nodal.items():
        area = values["area"]
        row = contacts.setdefault(k, {})
        if "potential" in fields:
            row["current"] = float(_flow(reading, k, "potential", None))
        if "temperature" in fields:
            row["heat"] = float(_flow(reading, k, "temperature", None))
        if "contact Joule heat" in values:
            row["Joule heat"] = float(np.sum(values["contact Joule heat"] * area))
        if "displacement" in fields:
            row["force"] = _force(reading, k).tolist()
            row["mean pressure"] = float(np.sum(values["pressure"] * area) / area.sum())
            row["max pressure"] = float(values["pressure"].max())
            row["open share"] = open_share(values["gap"], area)
    return {"balance": _balance(reading), "groups": groups, "contacts": contacts}


# -- the pieces ---------------------------------------------------------------------------
class _Reading:
    """One state of a system, read once (collective).

    Each body's residual without its conditions and each interface's sides are assembled on
    first use and kept: a report asks for them many times.
    """

    def __init__(self, system: System) -> None:
        self.system = system
        self._residuals: dict[str, Vector] = {}
        self._sides: dict[str, dict[str, dict]] = {}

    def residual(self, body: Body) -> Vector:
        """The body's owned residual without its conditions (reactions at fixed DOFs)."""
        if body.name not in self._residuals:
            self._residuals[body.name] = body.residual(conditions=False)
        return self._residuals[body.name]

    def sides(self, k: str) -> dict[str, dict]:
        """Body name -> its side of interface k (:func:`_sides`), on every rank."""
        if k not in self._sides:
            gathered = _sides(self.system, [k])
            self._sides[k] = {name: side[k] for name, side in gathered.items() if k in side}
        return self._sides[k]


def _once(system: System, value):
    """A value known on every rank of a group, kept on the group's first rank only.

    A sum over the whole communicator then counts it once.
    """
    return value if system.problem.scene.group_comm.rank == 0 else 0 * value


def _dofs(body: Body, field: str, component: int | None) -> npt.NDArray[np.int32]:
    """Owned DOFs of ``W`` of one field, or of one displacement component."""
    parent_of = body.forms.collapsed(field, component)[1]
    return parent_of[parent_of < body.size]


def _assembled(body: Body, key: Hashable, form: ufl.Form) -> Vector:
    """One of the body's vector forms (compiled once, kept under ``key``), owned and ghosts."""
    b = dolfinx.fem.petsc.assemble_vector(body.compiled(key, form))
    b.ghostUpdate(PETSc.InsertMode.ADD, PETSc.ScatterMode.REVERSE)
    values = b.array.copy()
    b.destroy()
    return values


def _held(
    body: Body, group: str, field: str, component: int | None
) -> npt.NDArray[np.int32] | None:
    """Owned DOFs of the field that a condition on ``group`` fixes (the first one listed).

    None where no condition on ``group`` holds the field (the same on every rank).
    """
    taken = np.zeros(0, dtype=np.int32)
    for bc, condition in zip(body.forms.bcs, body.forms.held, strict=True):
        if FIELD_OF[type(condition)] != field:
            continue
        if isinstance(condition, Displacement) and condition.component != component:
            continue
        dofs = bc.dof_indices()[0][: bc.dof_indices()[1]]
        dofs = dofs[dofs < body.size]
        if condition.boundary == group:
            return np.setdiff1d(dofs, taken).astype(np.int32)
        taken = np.union1d(taken, dofs)
    return None


def _flow(reading: _Reading, group: str, field: str, component: int | None) -> float:
    """What enters the bodies through a boundary group, or crosses an interface."""
    system = reading.system
    if group in system.layers:
        return _across(reading, group, field, component)
    scene = system.problem.scene
    if not any(group in b.boundaries for b in scene.bodies.values()):
        raise ValueError(
            f"{scene.source}: no boundary group or interface named '{group}'; boundary groups: "
            f"{sorted(set().union(*(b.boundaries for b in scene.bodies.values())))}"
        )
    total = 0.0
    for body in system.bodies.values():
        if group not in scene.bodies[body.name].boundaries:
            continue
        dofs = _dofs(body, field, component)
        local = 0.0
        held = _held(body, group, field, component)
        if held is not None:  # (collective: the same on every rank of the body)
            local += reading.residual(body)[held].sum()
        if group in body.forms.loads:
            local -= _assembled(body, ("load", group), body.forms.loads[group])[dofs].sum()
        total += _once(system, body.comm.allreduce(local, op=MPI.SUM))
    return system.comm.allreduce(total, op=MPI.SUM)


def _across(reading: _Reading, k: str, field: str, component: int | None) -> float:
    layer = reading.system.layers[k]
    if (field, component) not in layer.channels and (field, None) not in layer.channels:
        return 0.0
    c = layer.channels.index((field, component if field == "displacement" else None))
    part = slice(c * layer.nodes, (c + 1) * layer.nodes)
    sides = reading.sides(k)
    first, second = (sides[name]["outflow"][part] for name in layer.interface.bodies)
    return float(0.5 * (first.sum() - second.sum()))


def _sides(system: System, interfaces: list[str] | None = None) -> dict[str, dict[str, dict]]:
    """Body -> interface -> the body's side of it, in master order, on every rank.

    Each side: ``values`` at the slaves, ``outflow`` (:meth:`Body.contact_outflow`), ``area``
    (nodal ∫ φ_i ds, on every channel) and ``normal`` (nodal ∫ n_c φ_i ds of the
    displacement channels).
    """
    local = {}
    for name, body in system.bodies.items():
        local[name] = {}
        for k in body.layers:
            if interfaces is not None and k not in interfaces:
                continue
            layer = body.layers[k]
            ds = body.forms.ds(body.forms.tags[k])
            v = body.forms.parts(test=True)
            first = v[body.forms.fields[0]]  # any field: each channel has the same nodes
            first = first if first.ufl_shape == () else first[0]
            area = body.compiled(("area", k), first * ds)
            side = {
                "values": body.slaves[k].gather(body.U.x.array, layer.size, body.comm),
                "outflow": body.contact_outflow(k),
                "area": body.assembled_at_slaves(area, k),
            }
            if "displacement" in body.forms.fields:
                n = ufl.FacetNormal(body.forms.W.mesh)
                form = body.compiled(("normal", k), ufl.dot(n, v["displacement"]) * ds)
                side["normal"] = body.assembled_at_slaves(form, k)
            local[name][k] = side
    return system.everywhere(local)


def _normal_contact(
    system: System, k: str, first: dict, second: dict, area: Vector
) -> tuple[Vector, Vector]:
    """Nodal pressure (mean of the two sides' reactions) and gap of interface k."""
    layer = system.layers[k]
    channels = [c for c, (f, _) in enumerate(layer.channels) if f == "displacement"]
    parts = [slice(c * layer.nodes, (c + 1) * layer.nodes) for c in channels]

    def vectors(side: dict, key: str) -> Vector:
        return np.stack([side[key][p] for p in parts], axis=1)

    pressure = np.zeros(layer.nodes)
    for side in (first, second):
        normal = vectors(side, "normal")
        unit = normal / np.linalg.norm(normal, axis=1)[:, None]
        pressure += 0.5 * np.sum(vectors(side, "outflow") * unit, axis=1) / area
    unit = vectors(first, "normal")
    unit = unit / np.linalg.norm(unit, axis=1)[:, None]
    jump = vectors(first, "values") - vectors(second, "values")
    gap = system.problem.contacts[k].gap - np.sum(jump * unit, axis=1)
    return pressure, gap


def _cold_loads(system: System) -> dict[str, float]:
    """1-norm of each field's residual at the cold state (the state is kept)."""
    f = system.create_vector()
    try:
        system.cold_residual(f)
        return system.field_sums(f)
    finally:
        f.destroy()


def _condition_groups(system: System, field: str) -> list[str]:
    """Boundary groups with a condition on ``field``, in the order first listed."""
    groups = [bc.boundary for bc in system.problem.conditions if FIELD_OF[type(bc)] == field]
    return list(dict.fromkeys(groups))


def _generated(system: System) -> float:
    """Heat [W] generated in the bulk (Joule heat, sources) and in the contacts (Joule)."""
    total = 0.0
    for body in system.bodies.values():
        dofs = _dofs(body, "temperature", None)
        forms = {k: body.forms.remainders[k] for k in body.layers}
        local = -sum(
            _assembled(body, ("remainder", k), f)[dofs].sum()
            for k, f in forms.items()
            if f is not None
        )
        total += _once(system, body.comm.allreduce(local, op=MPI.SUM))
    return system.comm.allreduce(total, op=MPI.SUM) + sum(bulk_heat(system).values())


def enthalpy(system: System, reference: float = 0.0) -> float:
    """Heat content [J] of every body that stores heat, from ``reference`` [K].

    Σ ∫ ρ ∫_reference^T c_p dT dx (2D: per metre of depth), the integral in T exact
    (:func:`~subdomain_contact.laws.antiderivative`: c_p a number or a table in T). The
    difference between two states is the heat stored between them, whatever the time steps:
    against the heat a time scheme stored step by step, it measures that scheme's error.
    Quadrature in space of degree 6, beyond the residual's: the integral's own.
    """
    local = 0.0
    for name, body in system.bodies.items():
        m = system.problem.materials[name]
        if m.density is None:
            continue
        T = body.forms.parts()["temperature"]
        content = antiderivative(m.heat_capacity, T) - antiderivative(
            m.heat_capacity, ufl.as_ufl(float(reference))
        )
        dx = ufl.dx(domain=body.forms.W.mesh, degree=6)
        form = body.compiled(("enthalpy", float(reference)), float(m.density) * content * dx)
        part = body.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)
        local += _once(system, part)
    return system.comm.allreduce(local, op=MPI.SUM)


def bulk_heat(system: System) -> dict[str, float]:
    """Heat [W] generated in each body's bulk: its Joule heat σ|∇φ|² and volume sources.

    The contacts' Joule heat is not in it (:func:`summary`, per interface). Every body, on
    every rank.
    """
    if "temperature" not in system.problem.fields:
        raise ValueError("bulk_heat: the scene has no temperature field")
    local = dict.fromkeys(system.problem.scene.bodies, 0.0)
    for name, body in system.bodies.items():
        if body.forms.sources is None:
            continue
        dofs = _dofs(body, "temperature", None)
        part = -_assembled(body, "sources", body.forms.sources)[dofs].sum()
        local[name] = _once(system, body.comm.allreduce(part, op=MPI.SUM))
    return {name: system.comm.allreduce(value, op=MPI.SUM) for name, value in local.items()}


def _stored(system: System) -> float:
    """Heat [W] the bodies store per unit time over the last step: ∫ ρ c_p (T − T_prev) / Δt."""
    total = 0.0
    for body in system.bodies.values():
        if body.forms.storage is None:
            continue
        dofs = _dofs(body, "temperature", None)
        local = _assembled(body, "storage", body.forms.storage)[dofs].sum()
        total += _once(system, body.comm.allreduce(local, op=MPI.SUM))
    return system.comm.allreduce(total, op=MPI.SUM)
