"""The collector bar slot scene (``geo/collector_bar_slot.geo``): its geometry, exactly."""

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

import subdomain_contact as sc
from verification.cases import GEO

HALF_LENGTH, HALF_WIDTH, HEIGHT = 3.67 / 2, 0.24, 0.48
SLOT_H, BAR_W, THIN, THICK, X0, BAR_LENGTH = 0.176, 0.08, 0.015, 0.025, 0.1, 2.175
INTERFACES = ["slot_side", "slot_top", "bar_side", "bar_top"]


def measure(body: sc.scene.Body, group: str | None = None) -> float:
    """Volume of a body, or area of one of its facet groups [m³, m²] (global)."""
    mesh = body.mesh
    if group is None:
        integrand = dolfinx.fem.Constant(mesh, 1.0) * ufl.dx(domain=mesh)
    else:
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=body.facet_tags)
        integrand = dolfinx.fem.Constant(mesh, 1.0) * ds(body.boundaries[group])
    local = dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand))
    return mesh.comm.allreduce(local, op=MPI.SUM)


@pytest.mark.parametrize("bar_h", [0.16, 0.174])
def test_slot_scene_has_the_published_dimensions(comm, bar_h):
    """Volumes and areas against the dimensions of Dupuis (Light Metals 2011): a mesh of
    plane faces is exact, so they agree to round-off (1e-12 relative: sums of ~1e4 cells)."""
    scene = sc.load_scene(
        GEO / "collector_bar_slot.geo",
        bodies=["block", "cast_iron", "bar"],
        interfaces=INTERFACES,
        parameters={"size": 0.12, "fine": 0.04, "bar_h": bar_h},
        comm=comm,
        placement="shared",
    )
    slot = SLOT_H * (BAR_W + THIN) + 0.5 * SLOT_H * (THICK - THIN)  # half the cross-section
    assert slot == pytest.approx(SLOT_H * 0.1, rel=1e-12)  # 200 mm wide on average
    inside = HALF_LENGTH - X0
    expected = {
        "block": HALF_LENGTH * HALF_WIDTH * HEIGHT - slot * HALF_LENGTH,
        "cast_iron": (slot - BAR_W * bar_h) * inside,
        "bar": BAR_W * bar_h * BAR_LENGTH,
    }
    for name, volume in expected.items():
        assert measure(scene.bodies[name]) == pytest.approx(volume, rel=1e-12), name
    flank = np.hypot(SLOT_H / 2, THICK - THIN)  # each plane of the V
    areas = {
        ("block", "slot_side"): 2 * flank * inside,
        ("block", "slot_top"): (BAR_W + THIN) * inside,
        ("bar", "bar_side"): bar_h * inside,
        ("bar", "bar_top"): BAR_W * inside,
        ("block", "top"): HALF_LENGTH * HALF_WIDTH,
        ("bar", "bar_end"): BAR_W * bar_h,
    }
    for (body, group), area in areas.items():
        assert measure(scene.bodies[body], group) == pytest.approx(area, rel=1e-12), group
    assert [scene.interfaces[k].bodies for k in INTERFACES] == [
        ("block", "cast_iron"),
        ("block", "cast_iron"),
        ("cast_iron", "bar"),
        ("cast_iron", "bar"),
    ]
