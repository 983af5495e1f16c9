"""Config objects: frozen, compared by value, pickled; ``Identifier.config`` gives back
the config object the identifier runs with."""

from __future__ import annotations

import copy
import dataclasses
import pickle

import pytest

from boucwen import HorizonConfig, Identifier, PaperConfig, Params, RpemConfig

DT = 1e-4
P = Params.paper_1hz()


@pytest.mark.parametrize(
    ("build", "given"),
    [
        (lambda c: Identifier(DT, P, config=c), HorizonConfig(memory_travel_v=450.0, max_window=9000)),
        (lambda c: Identifier.horizon(DT, P, config=c, refine="background"), HorizonConfig(ridge=1e-5)),
        (lambda c: Identifier.rpem(DT, P, config=c), RpemConfig(max_step=0.002, n_bounds=(1.05, 3.0))),
        (lambda c: Identifier.paper(DT, 300, P, config=c), PaperConfig(decomposition="line", min_points=12)),
    ],
    ids=["recommended", "horizon-background", "rpem", "paper"],
)
def test_identifier_config_is_the_config_object_given(build, given) -> None:
    ident = build(given)
    got = ident.config
    assert type(got) is type(given)
    assert got == given
    assert got is not given  # rebuilt from the identifier's own state, not kept aside
    assert pickle.loads(pickle.dumps(ident)).config == given
    assert copy.copy(ident).config == given


def test_identifier_config_without_one_is_the_methods_default() -> None:
    assert Identifier(DT, P).config == HorizonConfig()
    assert Identifier.paper(DT, 300, P).config == PaperConfig()
    assert Identifier.rpem(DT, P).config == RpemConfig()
    assert Identifier.rpem(DT, P, config=RpemConfig(p0=2e-3)).config != RpemConfig()


@pytest.mark.parametrize("config", [HorizonConfig(), RpemConfig(p0=1e-3), PaperConfig(min_r2=0.5)])
def test_config_objects_are_frozen_hashable_values_that_pickle(config) -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.margin = 1.0
    twin = pickle.loads(pickle.dumps(config))
    assert twin == config and hash(twin) == hash(config)
    assert repr(twin) == repr(config) and repr(config).startswith(type(config).__name__ + "(")
    assert config.replace() == config
    changed = config.replace(n_bounds=(1.1, 2.9))
    assert changed != config and changed.n_bounds == (1.1, 2.9)
