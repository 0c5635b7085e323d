"""Multiphysics contact between solids by the subdomain method of Ramadane et al. (2005).

The package reads as the method does: ``scene`` (gmsh bodies and master meshes) → ``laws``
and ``physics`` (materials, contact laws, conditions, UFL residuals per body) → ``masters``
(master layers, channels, slave maps) → ``body`` (a body's blocks, its factorisation with the
contact DOFs left as a Schur block: ``schur``) → ``system`` (every body and master, the
state and residual) → ``correctors`` and ``subdomain`` (the subdomain iteration: fixed point
or interface Krylov) or ``monolithic`` (the reference) → ``newton`` (SNES outside) →
``transient`` (backward Euler and BDF2 steps, fixed or adaptive) → ``history`` (probes per
step, VTK series, checkpoints and restart) → ``readback`` (integrals by group, contact fields,
balances) and ``io`` (VTK); ``data`` reads materials and contact laws from TOML files.
Import ``dolfinx_solver`` before this package (this module does it).
"""

import dolfinx_solver  # noqa: F401  (must precede dolfinx and petsc4py)

from subdomain_contact import laws
from subdomain_contact.correctors import (
    Exact,
    Method1,
    Method2,
    PartialCondensation,
    SparseStrip,
    paper_factor,
)
from subdomain_contact.data import load_contact, load_material
from subdomain_contact.history import History
from subdomain_contact.io import plot_vtk, write_vtk
from subdomain_contact.laws import PowerLaw, Table
from subdomain_contact.monolithic import BDDC, CG_GAMG, FIELDSPLIT_GAMG, Monolithic
from subdomain_contact.newton import (
    MAX_TEMPERATURE_STEP,
    NewtonConvergenceError,
    NewtonStep,
    Result,
    solve,
)
from subdomain_contact.physics import (
    Contact,
    Convection,
    CurrentDensity,
    Displacement,
    ExponentialClosure,
    HeatFlux,
    Material,
    Penalty,
    Potential,
    Pressure,
    Problem,
    Schedule,
    Temperature,
)
from subdomain_contact.readback import (
    average,
    balance,
    bulk_heat,
    contact_fields,
    current,
    enthalpy,
    force,
    heat,
    open_share,
    summary,
    value_at,
    voltage_drop,
)
from subdomain_contact.scene import Scene, load_scene
from subdomain_contact.solvers import (
    DIRECT,
    FIELDSPLIT_DIRECT,
    FIELDSPLIT_SINGLE,
    THERMOELECTRIC_MECHANICAL,
)
from subdomain_contact.subdomain import (
    InterfaceResult,
    SubdomainConvergenceError,
    Subdomains,
    Tolerance,
)
from subdomain_contact.system import System
from subdomain_contact.transient import StepFailedError, Stepper

__all__ = [
    "BDDC",
    "CG_GAMG",
    "DIRECT",
    "FIELDSPLIT_DIRECT",
    "FIELDSPLIT_GAMG",
    "FIELDSPLIT_SINGLE",
    "MAX_TEMPERATURE_STEP",
    "THERMOELECTRIC_MECHANICAL",
    "Contact",
    "Convection",
    "CurrentDensity",
    "Displacement",
    "Exact",
    "ExponentialClosure",
    "HeatFlux",
    "History",
    "InterfaceResult",
    "Material",
    "Method1",
    "Method2",
    "Monolithic",
    "NewtonConvergenceError",
    "NewtonStep",
    "PartialCondensation",
    "Penalty",
    "Potential",
    "PowerLaw",
    "Pressure",
    "Problem",
    "Result",
    "Scene",
    "Schedule",
    "SparseStrip",
    "StepFailedError",
    "Stepper",
    "SubdomainConvergenceError",
    "Subdomains",
    "System",
    "Table",
    "Temperature",
    "Tolerance",
    "average",
    "balance",
    "bulk_heat",
    "contact_fields",
    "current",
    "enthalpy",
    "force",
    "heat",
    "laws",
    "load_contact",
    "load_material",
    "load_scene",
    "open_share",
    "paper_factor",
    "plot_vtk",
    "solve",
    "summary",
    "value_at",
    "voltage_drop",
    "write_vtk",
]
