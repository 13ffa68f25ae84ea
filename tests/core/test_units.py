"""Units: compound units parse, convert exactly to SI, and refuse the wrong dimension."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skinkit.errors import SchemaError, UnitError
from skinkit.schemas import Parameter, ParameterSet, Protocol
from skinkit.units import (
    format_quantity,
    from_si,
    is_known,
    parse,
    same_dimension,
    si_unit,
    to_si,
    unit_suffix,
)


@pytest.mark.parametrize(("unit", "si", "factor"), [
    ("1/mm", "1/m", 1000.0),             # a curvature or a spatial frequency
    ("1/s", "1/s", 1.0),                 # a rate
    ("N/m", "N/m", 1.0),                 # a stiffness
    ("N/mm", "N/m", 1000.0),
    ("N s/m", "N s/m", 1.0),             # a viscous damping
    ("N*s/m", "N s/m", 1.0),
    ("kPa", "Pa", 1000.0),
    ("mm/s", "m/s", 1e-3),
    ("mm/kPa", "m/Pa", 1e-6),            # a compliance of a support
    ("mN m", "N m", 1e-3),               # a torque
    ("m s^-2", "m/s^2", 1.0),
    ("mm²", "m^2", 1e-6),
    ("%", "1", 1e-2),
    ("", "1", 1.0),
])
def test_compound_units_have_an_si_form_and_an_exact_factor(unit, si, factor):
    assert si_unit(unit) == si
    assert to_si(1.0, unit, si) == factor   # exact: the factor is computed in rationals, rounded once


def test_one_per_millimetre_is_exactly_a_thousand_per_metre():
    assert to_si(1.0, "1/mm", "1/m") == 1000.0
    assert to_si(np.array([0.5, 2.0]), "1/mm", "1/m").tolist() == [500.0, 2000.0]
    assert from_si(1000.0, "1/mm") == 1.0


@pytest.mark.parametrize("unit", ["1/mm", "N/mm", "N s/m", "mm/kPa", "mm/s", "kHz", "deg", "mN m", "um/N"])
def test_round_trip_through_si_is_the_identity(unit):
    x = np.array([0.1, 1.0, 7.3, 123.456])
    np.testing.assert_allclose(from_si(to_si(x, unit, si_unit(unit)), unit), x, rtol=1e-15)


def test_the_same_quantity_in_two_spellings_converts_the_same():
    # a 1 N/mm spring is 1 kN/m; a damper of 1 N s/mm is 1000 N s/m
    assert to_si(1.0, "N/mm", "N/m") == to_si(1.0, "kN/m", "N/m") == 1000.0
    assert to_si(1.0, "N s/mm", "N s/m") == 1000.0
    # the frequency of a 1 kHz sine is 1000 per second, whichever way it is written
    assert same_dimension("1/s", "Hz") and to_si(1.0, "kHz", "1/s") == 1000.0
    # a pressure is a force per area: 1 kPa is 1 mN/mm²
    assert same_dimension("Pa", "N/m^2") and to_si(1.0, "mN/mm^2", "Pa") == pytest.approx(1000.0, rel=1e-15)


@pytest.mark.parametrize(("unit", "expected"), [
    ("N/m", "Pa"),      # a line load or stiffness is not a stress: they differ by a length
    ("1/mm", "m"),      # an inverse length is not a length
    ("N", "N m"),       # a force is not a torque
    ("N s/m", "N/m"),   # a damping is not a stiffness
    ("deg", "1"),       # an angle stays an angle: never silently a pure number
    ("px", "m"),        # an image coordinate is not a length until calibrated
])
def test_a_unit_of_another_dimension_is_refused_naming_the_field(unit, expected):
    with pytest.raises(UnitError, match=rf"stiffness: unit '{unit}' is not a unit of '{expected}'"):
        to_si(1.0, unit, expected, "stiffness")


def test_an_unknown_part_is_named():
    with pytest.raises(UnitError, match=r"unknown unit 'furlong' in 'furlong/s'"):
        to_si(1.0, "furlong/s", "m/s", "speed")
    with pytest.raises(UnitError, match=r"unknown unit 'parsec'"):
        si_unit("N/parsec")
    assert not is_known("N/parsec") and is_known("N/mm") and is_known("1/mm")
    with pytest.raises(UnitError, match="more than one '/'"):
        si_unit("N/m/s")


def test_dimensions_are_powers_of_base_units():
    # a newton is kg m / s²: N/m and kg/s² are the same dimension
    assert parse("N/m").dims == parse("kg/s^2").dims == (("kg", 1), ("s", -2))
    # a compliance m/Pa is m² s² / kg
    assert dict(parse("m/Pa").dims) == {"m": 2, "kg": -1, "s": 2}
    assert parse("m/m").dims == () and si_unit("mm/m") == "1"


def test_parameters_accept_compound_units_and_store_si():
    p = Parameter("support.k", 2.0, "N/mm", lower=0.0)
    assert (p.unit, p.value, p.lower, p.upper) == ("N/m", 2000.0, 0.0, math.inf)
    c = Parameter("skin.curvature", 0.05, "1/mm")
    assert (p.unit, c.unit, c.value) == ("N/m", "1/m", 50.0)
    Protocol("p", parameters={"rate": 2.0}, units={"rate": "1/s"})   # accepted


def test_a_dimensionless_value_is_printed_bare():
    assert unit_suffix("1") == unit_suffix("") == unit_suffix(None) == ""
    assert format_quantity(0.5, "1") == "0.5"
    assert format_quantity(2000.0, "N/m") == "2000 N/m"
    assert str(Parameter("skin.k2", 0.5)) == "skin.k2 = 0.5"
    assert str(Parameter("skin.mu", 10, "kPa", free=False)) == "skin.mu = 10000 Pa (fixed)"
    pset = ParameterSet([Parameter("a", 1.5), Parameter("b", 2, "mm")])
    assert repr(pset) == "ParameterSet(a=1.5, b=0.002 m)"
    with pytest.raises(SchemaError, match=r"value: 2 is outside its bounds"):
        Parameter("skin.k2", 2.0, lower=0, upper=1)


def test_json_keeps_the_unit_key_and_says_why_a_bound_is_null():
    items = ParameterSet([Parameter("skin.k2", 0.5, lower=0.0),
                          Parameter("skin.mu", 10, "kPa", lower=1, upper=100)]).to_list()
    assert items[0]["unit"] == "1" and items[0]["upper"] is None and items[0]["upper_reason"] == "unbounded"
    assert "lower_reason" not in items[0] and "upper_reason" not in items[1]
    assert ParameterSet.from_list(items).param("skin.k2").upper == math.inf


def test_model_file_quantities_take_compound_units():
    from skinkit.fem.errors import ModelError
    from skinkit.fem.values import quantity

    assert quantity("2 1/mm", "1/m", "geometry.curvature") == 2000.0
    assert quantity("3 N s/mm", "N s/m", "support.damping") == 3000.0
    assert quantity("0.5 N/mm", "N/m", "support.k") == 500.0
    with pytest.raises(ModelError, match=r"support\.k: inconsistent units"):
        quantity("2 N/m", "Pa", "support.k")
    with pytest.raises(ModelError, match=r"unknown unit 'N/furlong'"):
        quantity("2 N/furlong", "N/m", "support.k")
