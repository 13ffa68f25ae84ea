"""Fits on a Dask cluster: one fit's protocols solved there, and many subjects' fits mapped over it.

A fit whose protocols are solved on a two-worker ``LocalCluster`` is the fit solved in this
process, to the bit (every solve is single-threaded wherever it runs); the multi-subject recipe
of the guide (``client.map`` of :func:`skinkit.fit` over sessions) returns each subject's fit as
fitted alone. The virtual subjects: a two-protocol indentation of a small bilayer whose skin
modulus differs per subject, with Gaussian noise at the stated levels.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import skinkit
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations
from tests.forward._bilayer import SPEC, channels

pytestmark = pytest.mark.needs_plugins
distributed = pytest.importorskip("distributed")


def _subject(E: float, seed: int) -> Observations:
    """A session of the model with skin modulus ``E`` [Pa]: its force and points plus noise."""
    rng = np.random.default_rng(seed)
    protos = {}
    for name, direc in (("normal", (0, 0, -1)), ("oblique", (0.3, 0, -1))):
        chans = channels(direc)
        protos[name] = ProtocolObservations(Protocol(name), chans)
    obs = Observations(protos, None, f"subject E={E:g}")
    from skinkit.forward import load
    with load(SPEC, workers=1) as model:
        pred = model.predict(model.parameters().with_values({"skin.E": E}), obs)
    out = {}
    for name, po in obs.protocols.items():
        chans = dict(po.channels)
        for c in ("tip_force", "points"):
            ch, v = chans[c], pred.protocols[name][c].values
            noisy = v + rng.standard_normal(v.shape) * np.broadcast_to(ch.noise, v.shape[-1:])
            chans[c] = Channel(c, ch.time_s, noisy, noise=ch.noise, reference=ch.reference)
        out[name] = ProtocolObservations(po.protocol, chans)
    return Observations(out, None, obs.source)


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc, \
            Client(lc) as client:
        yield lc, client


def test_a_fit_on_a_cluster_is_the_fit_in_process(cluster):
    lc, _ = cluster
    obs = _subject(46e3, seed=1)
    here = skinkit.fit(SPEC, obs, free="skin.E", workers=1, progress=False)
    there = skinkit.fit(SPEC, obs, free="skin.E", scheduler=lc.scheduler_address, progress=False)
    assert there.parameters.values()["skin.E"] == here.parameters.values()["skin.E"]
    assert there.objective == here.objective
    # the fit is a fit: the truth within 4 standard errors
    assert abs(here.parameters.values()["skin.E"] - 46e3) <= 4 * here.se["skin.E"]


def test_subjects_mapped_over_a_cluster_are_each_fitted_as_alone(cluster):
    _, client = cluster
    subjects = [_subject(E, seed) for seed, E in enumerate((35e3, 52e3))]
    fit_one = functools.partial(skinkit.fit, SPEC, free="skin.E", workers=1, progress=False)
    mapped = client.gather(client.map(fit_one, subjects))
    for obs, result in zip(subjects, mapped, strict=True):
        alone = fit_one(obs)
        assert result.parameters.values()["skin.E"] == alone.parameters.values()["skin.E"]
