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
    solid = "young_modulus" in data.read(path)  # the preheat's granular and paste bodies: T, φ
    material = sc.load_material(path, fields="TEu" if solid else "TE")
    assert material.conductivity is not None and material.electrical_conductivity is not None
    assert (material.young is not None) == solid
    assert (material.reference_temperature is not None) == solid
    # every material stores heat (the preheat), unless a steady problem asks for none
    assert material.density > 0 and material.heat_capacity is not None
    steady = sc.load_material(path, fields="T", storage=False)
    assert steady.density is None and steady.heat_capacity is None


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


def graphite_resistivity(T):
    """AT 101 graphite [Ω m]: Cincotti et al. 2007's fit, as MALAMUTE writes it."""
    return -2.705e-15 * T**3 + 1.263e-11 * T**2 - 1.836e-8 * T + 1.813e-5


def test_graphite_tables_are_their_cited_fits():
    """The stand-in cathode carbon's tables are the cited fits at their nodes (4 digits)."""
    entries = data.read(DATA / "materials" / "graphite_at101.toml")
    T = np.asarray(entries["thermal_conductivity"]["temperature"])
    fits = {
        "thermal_conductivity": 1.519e-5 * T**2 - 8.007e-2 * T + 130.2,
        "electrical_resistivity": graphite_resistivity(T),
        "expansion": 1.996e-6 * np.log(4.799e-2 * T) - 4.041e-6,
    }
    for key, fit in fits.items():
        assert np.array_equal(entries[key]["temperature"], T), key
        # the file holds the fits rounded to 4-5 significant digits
        assert np.allclose(entries[key]["value"], fit, rtol=5e-4, atol=0), key


def test_carbon_cast_iron_law_gives_the_resistances_it_states():
    """C_E = 64 σ_harm(T) (p/H)^0.35 (Cincotti et al. 2007): the file's resistances at 900 °C
    and 0.01, 0.1, 1 MPa (6.34, 2.83, 1.27 µΩ m², its header), from the formula and the two
    materials' resistivities, against the file's tabulated scale interpolated at 1173.15 K."""
    law = data.read(DATA / "contacts" / "carbon_cast_iron_pressure.toml")["electrical_resistance"]
    T = 1173.15
    sigma = 1 / graphite_resistivity(T), 1 / 0.9e-6  # grey_cast_iron.toml: 0.9 µΩ m
    harmonic = 2 * sigma[0] * sigma[1] / (sigma[0] + sigma[1])
    scale = np.interp(T, law["temperature"], law["scale"])
    assert scale == pytest.approx(64 * harmonic, rel=5e-4)  # 4 digits in the file
    hardness = 2 * 3.5e9 * 1.92e9 / (3.5e9 + 1.92e9)
    assert law["hardness"] == pytest.approx(hardness, rel=1e-4)
    resistances = [1 / (scale * (p / law["hardness"]) ** law["exponent"]) for p in (1e4, 1e5, 1e6)]
    assert np.allclose(resistances, [6.34e-6, 2.83e-6, 1.27e-6], rtol=5e-3, atol=0)  # 3 digits
