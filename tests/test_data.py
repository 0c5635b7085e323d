"""Materials and contact laws from the data files: every figure with its source."""

from pathlib import Path

import numpy as np
import pytest

import subdomain_contact as sc
from subdomain_contact import data
from subdomain_contact.laws import Table

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.mark.parametrize("path", sorted((DATA / "materials").glob("*.toml")), ids=lambda p: p.stem)
def test_every_material_file_loads_with_its_sources(path):
    material = sc.load_material(path)
    assert material.conductivity is not None and material.young is not None
    assert material.reference_temperature is not None


@pytest.mark.parametrize("path", sorted((DATA / "contacts").glob("*.toml")), ids=lambda p: p.stem)
def test_every_contact_file_loads_with_its_sources(path):
    contact = sc.load_contact(path, tangential="stuck")
    assert contact.electrical_conductance is not None and contact.tangential == "stuck"


def test_secant_expansion_from_a_strain_table(tmp_path):
    """ε(T) = b (T − T₀)² from T₀ = 293.15 K: the material's strain α_r(T) (T − T_r) from a
    stress-free T_r equals ε(T) − ε(T_r) at every node of the table.

    Where T_r is a node this is exact to round-off; between nodes ε(T_r) is interpolated
    linearly, off by at most b (Δ/2)² (Δ = 300 K here): the bound."""
    b, t0 = 1e-8, data.STRAIN_REFERENCE
    nodes = np.array([293.15, 500.0, 800.0, 1100.0, 1400.0])
    (tmp_path / "m.toml").write_text(
        "[thermal_strain]\n"
        f"temperature = {nodes.tolist()}\nvalue = {(b * (nodes - t0) ** 2).tolist()}\n"
        'source = "a test"\n'
    )
    for reference in (293.15, 800.0, 950.0):
        law = data._expansion(data.read(tmp_path / "m.toml"), reference, "m.toml")
        assert isinstance(law, Table)
        strain = np.asarray(law.values[0]) * (nodes - reference)
        exact = b * ((nodes - t0) ** 2 - (reference - t0) ** 2)
        bound = 1e-20 if reference in nodes else b * 150.0**2
        assert np.abs(strain - exact).max() <= bound + 1e-15 * np.abs(exact).max()
    # a constant mean coefficient from T₀ is the law itself when T_r = T₀
    (tmp_path / "c.toml").write_text('[expansion]\nvalue = 1.1e-5\nsource = "a test"\n')
    assert data._expansion(data.read(tmp_path / "c.toml"), t0, "c.toml") == 1.1e-5


def test_a_figure_without_source_or_below_zero_is_refused(tmp_path):
    bad = tmp_path / "nosource.toml"
    bad.write_text("[thermal_conductivity]\nvalue = 45.0\n")
    with pytest.raises(ValueError, match=r"nosource.toml: \[thermal_conductivity\] has no source"):
        sc.load_material(bad)
    negative = tmp_path / "negative.toml"
    negative.write_text('[thermal_conductivity]\nvalue = -1.0\nsource = "x"\n')
    with pytest.raises(ValueError, match=r"negative.toml: \[thermal_conductivity\] value = -1.0"):
        sc.load_material(negative, fields="T")
    zero = tmp_path / "zero.toml"
    zero.write_text('[electrical_resistance]\nvalue = 0.0\nsource = "x"\n')
    with pytest.raises(ValueError, match="resistance must be finite, > 0"):
        sc.load_contact(zero)
