"""The model registry (``swarm_envs.models``): its entries are what the rest reads, and it
refuses an entry that would be ambiguous or incomplete."""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass

import numpy as np
import pytest

from agents import ANALYTIC, CONTROLLERS
from swarm_envs import models
from swarm_envs.config import BACKENDS, DYNAMICS, SwarmConfig
from swarm_envs.envs import dynamics as dynamics_module
from swarm_envs.envs.dynamics import Dynamics, make_dynamics
from swarm_envs.models import (
    SHIPPED,
    ModelParams,
    ModelSpec,
    model_spec,
    models_table,
    register_model,
    spec_for_params,
)
from swarm_envs.physics import simulate_zone


@pytest.fixture
def registry(monkeypatch):
    """A copy of the registry for this test: what it registers leaves no trace."""
    monkeypatch.setattr(models, "_REGISTRY", dict(models._REGISTRY))


@dataclass(frozen=True)
class ToyParams:
    k: float = 1.0


class ToyDynamics(Dynamics):
    def step(self, x, v, goal, control):
        return x + self.cfg.dt * v, v, None


def toy(**kw) -> ModelSpec:
    fields = dict(
        name="toy",
        params=ToyParams,
        section="toy",
        simulate=simulate_zone,
        adapter=ToyDynamics,
        source="a toy",
        action="nothing",
    )
    return ModelSpec(**{**fields, **kw})


def test_the_shipped_entries_are_the_config_sections_and_every_name_resolves():
    hints = typing.get_type_hints(SwarmConfig)
    assert DYNAMICS == SHIPPED == ("social_potential", "zone", "piecewise", "lagrangian")
    for name in SHIPPED:
        spec = model_spec(name)
        assert hints[spec.section] is spec.params  # a SwarmConfig field of its class
        assert set(spec.backends) <= set(BACKENDS) - {"auto"}
        assert spec.baseline in CONTROLLERS and ANALYTIC[name] == spec.baseline
        assert issubclass(spec.adapter_class(), Dynamics)
        rule = spec.substep_rule()
        assert rule is None or rule(SwarmConfig(dynamics=name)) >= 1
        assert spec_for_params(SwarmConfig(dynamics=name).dynamics_params) is spec
        adapter = make_dynamics(SwarmConfig(dynamics=name), 2, np.dtype(np.float64))
        assert type(adapter) is spec.adapter_class()


def test_the_dynamics_docstring_table_is_the_registrys():
    table = models_table(SHIPPED)
    assert table in (dynamics_module.__doc__ or "")
    for name in SHIPPED:
        assert f'``"{name}"``' in table
        assert model_spec(name).action.split()[0] in table


def test_a_user_entry_registers_once_and_a_shipped_one_is_never_replaced(registry):
    spec = register_model(toy())
    assert model_spec("toy") is spec and "toy" in models.model_names()
    with pytest.raises(ValueError, match=r"already registered.*replace=True"):
        register_model(toy())
    assert register_model(toy(source="another toy"), replace=True).source == "another toy"
    with pytest.raises(ValueError, match="'zone' is already registered \\(a shipped model\\)"):
        register_model(toy(name="zone", section="zone2"), replace=True)
    with pytest.raises(ValueError, match="section 'zone' is already the section of dynamics"):
        register_model(toy(name="toy2", section="zone"))
    with pytest.raises(TypeError, match="takes a ModelSpec"):
        register_model("toy")  # type: ignore[arg-type]


def test_a_registered_model_gets_its_section_and_adapter(registry):
    register_model(toy())
    cfg = SwarmConfig(dynamics="toy", model_params={"toy": {"k": 2.0}})
    assert cfg.dynamics_params == ToyParams(k=2.0)
    assert isinstance(cfg.model_params, ModelParams)
    assert isinstance(make_dynamics(cfg, 1, np.dtype(np.float64)), ToyDynamics)


def test_a_section_named_like_a_config_key_of_another_kind_lives_in_model_params(registry):
    register_model(toy(section="reward"))
    cfg = SwarmConfig(dynamics="toy", model_params={"reward": {"k": 3.0}})
    assert cfg.dynamics_params == ToyParams(k=3.0)
    assert cfg.reward == SwarmConfig().reward  # the reward weights untouched


def test_an_adapter_that_is_not_a_dynamics_is_refused_when_built(registry):
    register_model(toy(adapter=ToyParams))
    with pytest.raises(TypeError, match="adapter must be a subclass of"):
        make_dynamics(SwarmConfig(dynamics="toy"), 1, np.dtype(np.float64))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"name": "my model"}, "name must be a Python identifier"),
        ({"section": ""}, "section must be a Python identifier"),
        ({"params": dict}, "params must be a dataclass type"),
        ({"params": dataclass(type("Loose", (), {}))}, "must be a frozen dataclass"),
        ({"simulate": None}, "simulate must be callable"),
        ({"adapter": "no_colon"}, "adapter must be a Dynamics subclass or its path"),
        ({"substeps": 3}, "substeps must be None, a function"),
        ({"backends": ("torch",)}, "'numpy' \\(the reference\\) among them"),
        ({"baseline": 1}, "baseline must be a controller name"),
        ({"action": " "}, "action must be a non-empty description"),
        ({"check": "no"}, "check must be None or callable"),
        ({"integrators": ("velocity_verlet",)}, "'semi_implicit_euler' among them"),
        ({"integrators": ("semi_implicit_euler", "rk4")}, "integrators must name integrators"),
    ],
)
def test_an_incomplete_entry_is_refused_naming_the_field(change, message):
    with pytest.raises(ValueError, match=message):
        toy(**change)


def test_model_params_is_immutable_and_hashable():
    a = ModelParams({"toy": ToyParams()})
    assert a == {"toy": ToyParams()} and hash(a) == hash(ModelParams({"toy": ToyParams()}))
    with pytest.raises(TypeError):
        a["toy"] = ToyParams(k=2.0)  # type: ignore[index]
    assert dataclasses.replace(SwarmConfig(), n_agents=3).model_params == ModelParams()
