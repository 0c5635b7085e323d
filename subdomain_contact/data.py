"""Materials and contact laws read from TOML data files, every property with its source.

A material file holds one table per property; a property is one number (``value = …``) or a
table in temperature (``temperature = [… K]``, ``value = […]``), and names its ``source``::

    name = "collector bar steel"
    [thermal_conductivity]      # W/(m K)
    temperature = [293.15, 673.15]
    value = [52.0, 45.0]
    source = "…, table 3"

Properties: ``thermal_conductivity`` [W/(m K)], ``electrical_resistivity`` [Ω m],
``young_modulus`` [Pa], ``poisson_ratio`` [-], ``thermal_strain`` [-] (ΔL/L from
``strain_reference`` K, 293.15 by default) or ``expansion`` [1/K] (the mean coefficient from
that temperature), ``stress_free_temperature`` [K], ``density`` [kg/m^3], ``heat_capacity``
[J/(kg K)]. A contact file holds ``electrical_resistance`` [Ω m^2] and ``thermal_resistance``
[m^2 K/W], each one number, a table in ``pressure`` [Pa] and ``temperature`` [K]
(``value[i][j]``), or a power law in the pressure (``scale``, one number or a table in
``temperature``, ``hardness``, ``exponent``, ``floor`` of the conductance), and an optional
``normal`` law (``stiffness`` [Pa/m]).
Tables are interpolated linearly and held at their ends (:class:`~subdomain_contact.laws.Table`).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from subdomain_contact.laws import Law, PowerLaw, Table
from subdomain_contact.physics import Contact, Material, Penalty

#: Temperature [K] from which thermal strains and mean expansion coefficients are given.
STRAIN_REFERENCE = 293.15


def read(path: str | Path) -> dict[str, Any]:
    """The file's tables, each checked to name its source.

    Raises:
        ValueError: A property without ``source``, naming the file and the property.
    """
    path = Path(path)
    with path.open("rb") as file:
        data = tomllib.load(file)
    for name, entry in data.items():
        if isinstance(entry, dict) and not entry.get("source"):
            raise ValueError(f"{path}: [{name}] has no source: every figure names where it is from")
    return data


def load_material(
    path: str | Path,
    *,
    stress_free_temperature: float | None = None,
    fields: str = "TEu",
    storage: bool = True,
) -> Material:
    """A :class:`Material` from a data file.

    Args:
        path: The TOML file.
        stress_free_temperature: Temperature [K] of zero thermal strain; default the file's
            ``stress_free_temperature``.
        fields: Which fields the material takes part in: ``T`` (temperature), ``E``
            (potential), ``u`` (displacement).
        storage: Read ``density`` and ``heat_capacity`` (heat storage, for a transient) when
            the file has them; False for a steady problem (no storage form to assemble).

    Raises:
        ValueError: A property missing for a requested field, a bad table, or a negative
            value, naming the file and the property.
    """
    data, where = read(path), str(path)
    kwargs: dict[str, Any] = {}
    if "T" in fields:
        kwargs["conductivity"] = _law(data, "thermal_conductivity", where)
        if storage and "density" in data and "heat_capacity" in data:
            kwargs["density"] = float(_scalar(data, "density", where))
            kwargs["heat_capacity"] = _law(data, "heat_capacity", where)
    if "E" in fields:
        kwargs["electrical_conductivity"] = _law(data, "electrical_resistivity", where, invert=True)
    if "u" in fields:
        kwargs["young"] = _law(data, "young_modulus", where)
        kwargs["poisson"] = float(_scalar(data, "poisson_ratio", where))
        reference = stress_free_temperature
        if reference is None:
            reference = float(_scalar(data, "stress_free_temperature", where))
        kwargs["expansion"] = _expansion(data, reference, where)
        kwargs["reference_temperature"] = reference
    return Material(**kwargs)


def load_contact(path: str | Path, **overrides: Any) -> Contact:
    """A :class:`Contact` from a data file; ``overrides`` set its other attributes.

    The file's resistances become conductances (their inverses at the table's nodes).
    """
    data, where = read(path), str(path)
    kwargs: dict[str, Any] = {}
    for key, attribute in [
        ("electrical_resistance", "electrical_conductance"),
        ("thermal_resistance", "conductance"),
    ]:
        if key in data:
            kwargs[attribute] = _contact_law(data[key], f"{where}: [{key}]")
    if "normal" in data:
        kwargs["normal"] = Penalty(float(data["normal"]["stiffness"]))
    return Contact(**(kwargs | overrides))


def _scalar(data: dict, key: str, where: str) -> float | np.ndarray:
    if key not in data:
        raise ValueError(f"{where}: no [{key}]")
    value = np.asarray(data[key]["value"], dtype=float)
    if not np.all(np.isfinite(value)) or np.any(value < 0):
        raise ValueError(f"{where}: [{key}] value = {data[key]['value']}: must be finite, >= 0")
    return value if value.ndim else float(value)


def _law(data: dict, key: str, where: str, *, invert: bool = False) -> float | Law:
    """One number or a table in T; ``invert``: the reciprocal (resistivity → conductivity)."""
    value = _scalar(data, key, where)
    if invert and np.any(np.asarray(value) == 0):
        raise ValueError(f"{where}: [{key}] holds 0: its inverse is infinite")
    value = 1.0 / value if invert else value
    if np.ndim(value) == 0:
        return float(value)
    temperature = data[key].get("temperature")
    if temperature is None or len(temperature) != len(value):
        raise ValueError(f"{where}: [{key}] needs one temperature per value")
    return Table((0.0,), tuple(map(float, temperature)), [list(map(float, value))])


def _expansion(data: dict, reference: float, where: str) -> float | Law:
    """The secant expansion coefficient from ``reference`` [1/K], as the Material takes it.

    From ε(T), the strain from :data:`STRAIN_REFERENCE` (or ᾱ(T) (T − T₀), the mean
    coefficient's): α_r(T) = (ε(T) − ε(T_r)) / (T − T_r), its slope at T_r where T is T_r.
    """
    if "thermal_strain" in data:
        key = "thermal_strain"
        strain = np.atleast_1d(_signed(data, key, where))
        temperature = np.asarray(data[key]["temperature"], dtype=float)
    elif "expansion" in data:
        key = "expansion"
        alpha = _scalar(data, key, where)
        if np.ndim(alpha) == 0 and abs(reference - STRAIN_REFERENCE) < 1e-9:
            return float(alpha)
        temperature = np.asarray(data[key].get("temperature", [STRAIN_REFERENCE, 2000.0]))
        alpha = np.broadcast_to(alpha, temperature.shape)
        strain = alpha * (temperature - STRAIN_REFERENCE)
    else:
        raise ValueError(f"{where}: neither [thermal_strain] nor [expansion]")
    if len(temperature) < 2:
        raise ValueError(f"{where}: [{key}] needs two temperatures or more")
    at_reference = float(np.interp(reference, temperature, strain))
    slope = float(np.interp(reference, temperature[1:], np.diff(strain) / np.diff(temperature)))
    distance = temperature - reference
    near = np.abs(distance) < 1e-6
    secant = np.where(near, slope, (strain - at_reference) / np.where(near, 1.0, distance))
    return Table((0.0,), tuple(map(float, temperature)), [list(map(float, secant))])


def _signed(data: dict, key: str, where: str) -> np.ndarray:
    value = np.asarray(data[key]["value"], dtype=float)
    if not np.all(np.isfinite(value)):
        raise ValueError(f"{where}: [{key}] value = {data[key]['value']}: must be finite")
    return value


def _contact_law(entry: dict, where: str) -> float | Law:
    """A contact conductance from a resistance entry: number, table in (p, T), power law."""
    if "exponent" in entry:
        scale = np.asarray(entry["scale"], dtype=float)
        if scale.ndim:  # α k_harm(T), tabulated in temperature
            temperature = entry.get("temperature")
            if temperature is None or len(temperature) != len(scale):
                raise ValueError(f"{where} scale: needs one temperature per value")
            scale = Table((0.0,), tuple(map(float, temperature)), [scale.tolist()])
        return PowerLaw(
            scale=scale if isinstance(scale, Table) else float(scale),
            hardness=float(entry["hardness"]),
            exponent=float(entry["exponent"]),
            floor=float(entry["floor"]),
        )
    value = np.asarray(entry["value"], dtype=float)
    if not np.all(np.isfinite(value)) or np.any(value <= 0):
        raise ValueError(f"{where} value = {entry['value']}: a resistance must be finite, > 0")
    if value.ndim == 0:
        return float(1.0 / value)
    pressure = tuple(map(float, entry.get("pressure", (0.0,))))
    temperature = tuple(map(float, entry.get("temperature", (0.0,))))
    values = np.reshape(1.0 / value, (len(pressure), len(temperature)))
    return Table(pressure, temperature, values.tolist())
