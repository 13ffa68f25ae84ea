"""The core learns plugin details from the plugins' own declarations: a
profiler's ``options``, a driver's wire cost, a law's verification cases."""

from __future__ import annotations

import pytest

from skinkit.bench.robot import link_capacity_hz
from skinkit.cli.vision import profiler_kwargs
from skinkit.errors import SkinkitError


class _Bare:
    """A plugin that declares nothing."""

    name = "bare"


def test_a_driver_without_a_declared_wire_cost_has_unknown_capacity():
    assert link_capacity_hz(_Bare(), 1e6) is None
    for bad in (0, -5, True, "305", None):
        d = _Bare()
        d.wire_bits_per_sample = bad
        assert link_capacity_hz(d, 1e6) is None, bad


@pytest.mark.needs_hardware
def test_the_hardware_drivers_declare_their_wire_cost():
    from skinkit import registry

    serial = registry.create("skinkit.drivers", "serial")
    can = registry.create("skinkit.drivers", "can")
    # serial (hardware/SERIAL_PROTOCOL.md): a 30-byte sample (u32 tick, 4 x 3 int16 channels,
    # u16 flags) in frames of 32 samples with 16 bytes around them (2 sync, 5 header, 5 samples
    # head, 4 CRC), 10 bits per byte at 8N1
    assert serial.wire_bits_per_sample == pytest.approx(10 * (30 + 16 / 32))
    assert link_capacity_hz(serial, 921_600) == pytest.approx(921_600 / 305.0)
    # CAN: five standard 8-byte frames per sample, ~125 bits each with stuffing
    assert link_capacity_hz(can, 1_000_000) == pytest.approx(1_000_000 / (5 * 125))
    assert (serial.line_rate_option, can.line_rate_option) == ("baudrate", "bitrate")


def test_profiler_options_pass_only_what_the_profiler_declares():
    given = {"spacing_px": 12, "subset_px": 31}
    assert profiler_kwargs(_Bare, given) == {}  # defaults are not forced on it
    with pytest.raises(SkinkitError, match=r"--spacing: profiler 'bare' does not take spacing_px "
                                           r"\(its options: none\)"):
        profiler_kwargs(_Bare, given, explicit=["spacing_px"])

    class Some:
        name = "some"
        options = {"subset_px": "subset side [px]"}

    assert profiler_kwargs(Some, given) == {"subset_px": 31}
    with pytest.raises(SkinkitError, match=r"--spacing: .* \(its options: subset_px\)"):
        profiler_kwargs(Some, given, explicit=["subset_px", "spacing_px"])


@pytest.mark.needs_plugins
def test_patchwork_declares_exactly_its_constructor_options():
    import inspect

    from skinkit import registry

    cls = registry.load("skinkit.profilers", "patchwork")
    assert set(cls.options) == set(inspect.signature(cls).parameters)
    assert profiler_kwargs(cls, {"spacing_px": 9, "subset_px": 21}, ["spacing_px"]) == \
        {"spacing_px": 9, "subset_px": 21}


@pytest.mark.needs_plugins
def test_verification_cases_come_from_the_laws_with_stable_names():
    from skinkit import registry
    from skinkit.fem import verify

    cases, problems = verify.law_cases()
    assert problems == {}
    # every law that declares cases, and only those (a law installed later is found the same way)
    declaring = {n for n in registry.names("skinkit.laws")
                 if callable(getattr(registry.load("skinkit.laws", n), "verification_cases", None))}
    assert {c.law for c in cases} == declaring
    # the names `skinkit verify --case` has always accepted for the built-in laws
    law_names = {f"{m}-{k}" for m in ("uniaxial", "equibiaxial")
                 for k in ("neo-hookean", "neo-hookean-ni", "mooney-rivlin", "ogden-2", "goh-along",
                           "goh-30deg", "goh-across")}
    law_names |= {f"sensitivities-{k}" for k in ("neo-hookean", "neo-hookean-ni", "neo-hookean-enu",
                                                 "mooney-rivlin", "ogden-2", "goh", "prestretch")}
    engine = {"patch-test", "prestretch-free-block", "qlv-relaxation", "sneddon-flat-punch",
              "sensitivities-qlv-history"}
    assert law_names | engine <= set(verify.names())
    assert {n for n in verify.names() if not any(n.endswith(f"-{c.name}") for c in cases)} == engine


@pytest.mark.parametrize("entry, match", [
    ("goh", "must be a mapping"),
    ({"name": "x", "stretch": 1.2}, r"unknown key\(s\) \['stretch'\]"),
    ({"options": {}}, "needs a non-empty 'name'"),
    ({"name": "x", "checks": ("homogeneous", "creep")}, "checks must be among"),
    ({"name": "x", "checks": ()}, "checks must be among"),
    ({"name": "x", "prestress": (1.1, 1.0)}, r"prestress must be \(l1, l2, angle\)"),
])
def test_a_malformed_verification_case_is_named(entry, match):
    from skinkit.fem import verify

    with pytest.raises(ValueError, match=match):
        verify._law_case("some-law", entry)
