"""The finite-element engine: layered skin meshes of 27-node hexahedra, hyperelastic and
viscoelastic laws from plugins, rigid indenters under displacement or force control, a
Newton solver with batched assembly, and parameter sensitivities.

Modules (imported on demand so that law plugins, which use :mod:`lawkit`, :mod:`hyper`
and :mod:`tensors`, stay light):

* :mod:`~skinkit.fem.lawkit`, :mod:`~skinkit.fem.hyper`, :mod:`~skinkit.fem.conformance` —
  stress and tangent of any law (derived from its energy if need be), helpers for law
  authors, and the conformance check;
* :mod:`~skinkit.fem.mesh`, :mod:`~skinkit.fem.embed` — meshes, surface fitting, embedded
  points;
* :mod:`~skinkit.fem.problem`, :mod:`~skinkit.fem.assembly`, :mod:`~skinkit.fem.bcs`,
  :mod:`~skinkit.fem.solver`, :mod:`~skinkit.fem.linsolve`, :mod:`~skinkit.fem.viscoelastic`
  — the discrete problem and its solution;
* :mod:`~skinkit.fem.sensitivity` — direct differentiation;
* :mod:`~skinkit.fem.model`, :mod:`~skinkit.fem.run`, :mod:`~skinkit.fem.output` — TOML
  model files and results;
* :mod:`~skinkit.fem.verify`, :mod:`~skinkit.fem.homogeneous` — the verification suite.
"""
