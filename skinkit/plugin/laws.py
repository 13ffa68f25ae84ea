"""The stable API for authors of constitutive laws (``skinkit.laws``).

Everything in ``__all__`` is public and kept stable; the engine modules it re-exports from
(:mod:`skinkit.fem.lawkit`, :mod:`skinkit.fem.hyper`, :mod:`skinkit.fem.tensors`) may change.
Conventions (batched over leading axes): ``C`` ``(..., 3, 3)`` right Cauchy-Green tensor [1];
``S = 2 ∂W/∂C`` ``(..., 3, 3)`` second Piola-Kirchhoff stress [Pa]; ``CC = 2 ∂S/∂C``
``(..., 3, 3, 3, 3)`` material tangent [Pa].

Law machinery (any :class:`skinkit.interfaces.Law`, derived from its energy if need be):

- :func:`stress`, :func:`tangent`, :func:`response` (``(S, CC)``), :func:`tangent_from_stress`,
  :func:`energy_hessian` (second differences of the energy: an independent reference);
- :func:`stress_parameter_derivative` ``∂S/∂p`` at fixed ``C``; :func:`parameter_step`;
- :func:`check_parameters` (bounds and the law's own ``inadmissible(p)``, errors naming the
  entry), :func:`inadmissible`, :func:`require_positive` (a ready-made ``inadmissible`` test);
- :func:`default_parameters`, :func:`parameter_names`, :func:`bounds_text`,
  :func:`broadcast_param`, :func:`has_own`, :func:`is_complex_safe`.

Tensors: :data:`I3`, :data:`VOIGT`, :func:`det3`, :func:`inv3`, :func:`trace`, :func:`outer`,
:func:`sym_product`, :func:`sym_direction`.

Hyperelastic blocks: :func:`kinematics`, the isochoric invariants :func:`iso_I1`,
:func:`iso_I2`, :func:`iso_I4` and :func:`iso_hessian`, :func:`b2`, :func:`b4`, and the
volumetric energies :data:`VOLUMETRIC_KINDS`, :func:`check_volumetric`,
:func:`volumetric_energy`, :func:`volumetric_stress`, :func:`volumetric_tangent` (and its
:func:`volumetric_coefficients`, to fold into :func:`iso_hessian`).

A law is checked with :func:`skinkit.plugin.conformance.laws.check_law`.
"""

from __future__ import annotations

from skinkit.fem.lawkit import (
    I3,
    VOIGT,
    VOLUMETRIC_KINDS,
    b2,
    b4,
    bounds_text,
    broadcast_param,
    check_parameters,
    check_volumetric,
    default_parameters,
    det3,
    energy_hessian,
    has_own,
    inadmissible,
    inv3,
    is_complex_safe,
    iso_hessian,
    iso_I1,
    iso_I2,
    iso_I4,
    kinematics,
    outer,
    parameter_names,
    parameter_step,
    require_positive,
    response,
    stress,
    stress_parameter_derivative,
    sym_direction,
    sym_product,
    tangent,
    tangent_from_stress,
    trace,
    volumetric_coefficients,
    volumetric_energy,
    volumetric_stress,
    volumetric_tangent,
)

__all__ = [
    # law machinery
    "bounds_text",
    "broadcast_param",
    "check_parameters",
    "default_parameters",
    "energy_hessian",
    "has_own",
    "inadmissible",
    "is_complex_safe",
    "parameter_names",
    "parameter_step",
    "require_positive",
    "response",
    "stress",
    "stress_parameter_derivative",
    "tangent",
    "tangent_from_stress",
    # batched 3x3 tensor algebra
    "I3",
    "VOIGT",
    "det3",
    "inv3",
    "outer",
    "sym_direction",
    "sym_product",
    "trace",
    # hyperelastic building blocks
    "VOLUMETRIC_KINDS",
    "b2",
    "b4",
    "check_volumetric",
    "iso_I1",
    "iso_I2",
    "iso_I4",
    "iso_hessian",
    "kinematics",
    "volumetric_energy",
    "volumetric_stress",
    "volumetric_coefficients",
    "volumetric_tangent",
]
