"""What :func:`skinkit.forward.load` returns is a :class:`skinkit.interfaces.ForwardModel` with a
lifecycle: ``close()`` any number of times, and ``with load(...) as model:``."""

from __future__ import annotations

import pytest

from skinkit.examples import example_model
from skinkit.forward import load
from skinkit.interfaces import ForwardModel
from skinkit.plugin.conformance import testbeds
from skinkit.schemas import Observations, Protocol, ProtocolObservations


def test_a_lumped_model_is_a_forward_model_and_a_context_manager():
    with load(example_model("extension_relaxation_lumped")) as model:
        assert isinstance(model, ForwardModel)
        pred = model.predict(model.parameters(), testbeds.lumped_session())
    model.close()
    model.close()
    # a lumped model holds nothing: it still predicts after close
    again = model.predict(model.parameters(), testbeds.lumped_session())
    assert again.protocols.keys() == pred.protocols.keys()


def test_a_with_block_closes_the_model_when_its_body_raises():
    closed = []
    with pytest.raises(RuntimeError, match="body"):
        with load(example_model("extension_relaxation_lumped")) as model:
            model.close = lambda: closed.append(True)  # type: ignore[method-assign]
            raise RuntimeError("body")
    assert closed == [True]


def _two_protocols() -> Observations:
    one = next(iter(testbeds.fe_session()))
    twin = ProtocolObservations(Protocol("oblique_again"), dict(one.channels))
    return Observations({one.name: one, twin.name: twin}, None, "test")


@pytest.mark.slow
@pytest.mark.needs_plugins
def test_an_fe_model_shuts_its_workers_down_on_exit_and_on_close():
    obs = _two_protocols()
    with load(testbeds.fe_model(), workers=2) as model:
        assert isinstance(model, ForwardModel)
        first = model.predict(model.parameters(), obs)
        assert model._pool is not None  # noqa: SLF001 - the worker pool is the resource under test
    assert model._pool is None  # noqa: SLF001
    model.close()  # idempotent
    second = model.predict(model.parameters(), obs)  # a new pool after close
    model.close()
    assert model._pool is None  # noqa: SLF001
    for (_, _, a), (_, _, b) in zip(first.items(), second.items(), strict=True):
        assert (a.values == b.values).all()
