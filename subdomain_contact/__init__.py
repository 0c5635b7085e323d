"""Multiphysics contact between solids by the subdomain method of Ramadane et al. (2005).

The package reads as the method does: ``geometry`` (gmsh bodies and master meshes) →
``thermal`` (UFL forms) → ``interfaces`` (master layers) → ``blocks`` (a body's slave/master
blocks and solves) → ``correctors`` and ``subdomain`` (the fixed point), ``krylov`` (every
interface at once) → ``monolithic`` (the reference) → ``output`` (VTK).
Import ``dolfinx_solver`` before this package.
"""

import dolfinx_solver  # noqa: F401  (must precede dolfinx and petsc4py)

from subdomain_contact.analytic import TwoPlates
from subdomain_contact.correctors import (
    Method1,
    Method2,
    PartialCondensation,
    Series,
    paper_factor,
)
from subdomain_contact.geometry import Scene, load_scene
from subdomain_contact.krylov import KrylovResult, solve_interface_krylov
from subdomain_contact.monolithic import CG_GAMG, MonolithicResult, solve_monolithic
from subdomain_contact.output import write_vtk
from subdomain_contact.subdomain import (
    SubdomainConvergenceError,
    SubdomainResult,
    ThermalSubdomains,
    body_blocks,
)
from subdomain_contact.thermal import (
    Convection,
    HeatFlux,
    Temperature,
    ThermalContact,
    ThermalMaterial,
    ThermalProblem,
)

__all__ = [
    "CG_GAMG",
    "Convection",
    "HeatFlux",
    "KrylovResult",
    "Method1",
    "Method2",
    "MonolithicResult",
    "PartialCondensation",
    "Scene",
    "Series",
    "SubdomainConvergenceError",
    "SubdomainResult",
    "Temperature",
    "ThermalContact",
    "ThermalMaterial",
    "ThermalProblem",
    "ThermalSubdomains",
    "TwoPlates",
    "body_blocks",
    "load_scene",
    "paper_factor",
    "solve_interface_krylov",
    "solve_monolithic",
    "write_vtk",
]
