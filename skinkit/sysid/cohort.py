"""Cohort statistics (thesis 4.1.7): coefficients of variation within and across subjects.

For one parameter and one group (site and direction): the CV within individuals is
``(1/N) sum_n sigma_n / mu_n`` over the N subjects (each with at least two trials), and
the CV across individuals is ``sigma / mu`` over every trial of every subject. Standard
deviations are sample standard deviations (ddof = 1).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from skinkit.sysid.checks import SysidError

#: the nonlinear parameters of thesis Table 9
WIENER_PARAMETERS = ("C1_m", "C2_per_N", "Is_s2", "Bs_s")


def cv_table(trials: Iterable[dict[str, Any]], parameters: Sequence[str] = WIENER_PARAMETERS,
             subject_key: str = "subject",
             group_keys: Sequence[str] = ("site", "direction")) -> list[dict[str, Any]]:
    """Tidy table of CVs: one row per group and parameter.

    ``trials`` are dicts holding ``subject_key``, the ``group_keys`` and the parameters
    (e.g. ``WienerModel.to_dict()`` plus ``subject``, ``site``, ``direction``). Rows hold
    the group values, ``parameter``, ``mean``, ``cv_within_pct``, ``cv_across_pct``,
    ``n_subjects`` (with >= 2 trials) and ``n_trials``.
    """
    rows = list(trials)
    if not rows:
        raise SysidError("cv_table: no trials")
    for i, r in enumerate(rows):
        missing = [k for k in (subject_key, *group_keys, *parameters) if k not in r]
        if missing:
            raise SysidError(f"cv_table: trial {i} lacks {', '.join(missing)}")
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in group_keys), []).append(r)
    out = []
    for gkey, members in groups.items():
        by_subject: dict[Any, list[dict[str, Any]]] = {}
        for r in members:
            by_subject.setdefault(r[subject_key], []).append(r)
        for p in parameters:
            allv = np.array([float(r[p]) for r in members])
            ratios = []
            for trials_n in by_subject.values():
                v = np.array([float(r[p]) for r in trials_n])
                if v.size >= 2 and np.mean(v) != 0:
                    ratios.append(np.std(v, ddof=1) / abs(np.mean(v)))
            mu = float(np.mean(allv))
            across = (float(np.std(allv, ddof=1) / abs(mu))
                      if allv.size >= 2 and mu != 0 else float("nan"))
            row = dict(zip(group_keys, gkey, strict=True))
            row.update({"parameter": p, "mean": mu,
                        "cv_within_pct": 100 * float(np.mean(ratios)) if ratios else float("nan"),
                        "cv_across_pct": 100 * across, "n_subjects": len(ratios),
                        "n_trials": int(allv.size)})
            out.append(row)
    return out


def write_csv(table: Sequence[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """Write a tidy table (list of dicts with the same keys) as CSV."""
    if not table:
        raise SysidError("write_csv: empty table")
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
