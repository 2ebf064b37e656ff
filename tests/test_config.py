"""Strict config loading: shipped YAMLs load; unknown keys and bad values name the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarm_envs.config import (
    CONFIG_ROOT,
    RewardWeights,
    SwarmConfig,
    as_dict,
    config_from_mapping,
    load_swarm_config,
    load_yaml,
    resolve_config_path,
)
from swarm_envs.physics import SocialPotentialParams

ENV_CONFIGS = sorted((CONFIG_ROOT / "env").glob("*.yaml"))


def test_shipped_env_configs_exist():
    names = {p.name for p in ENV_CONFIGS}
    assert {"paper_default.yaml", "paper_navigation.yaml"} <= names


@pytest.mark.parametrize("path", ENV_CONFIGS, ids=lambda p: p.name)
def test_every_shipped_env_config_loads(path: Path):
    cfg = load_swarm_config(path)
    assert isinstance(cfg, SwarmConfig)
    # Every key in the file reached the dataclass (none silently dropped).
    data = load_yaml(path)
    for key, value in data.items():
        if isinstance(value, dict):
            for sub, subval in value.items():
                assert getattr(getattr(cfg, key), sub) == pytest.approx(subval)
        elif isinstance(value, list):  # a range [low, high], held as a tuple
            assert getattr(cfg, key) == tuple(value)
        else:
            assert getattr(cfg, key) == value


def test_paper_default_matches_paper_fig1_10():
    cfg = load_swarm_config("configs/env/paper_default.yaml")
    assert cfg.n_agents == 30
    assert cfg.physics == SocialPotentialParams()  # class defaults are the Fig. 1–10 set


def test_paper_navigation_matches_paper_fig11():
    cfg = load_swarm_config("paper_navigation")
    assert cfg.n_agents == 31
    assert cfg.physics == SocialPotentialParams.navigation()
    # The analytic controller is never clipped: largest sink force C_g / l_g <= u_max.
    assert cfg.physics.C_g / cfg.physics.l_g <= cfg.u_max


def test_resolve_config_path_forms_agree():
    a = resolve_config_path("configs/env/paper_navigation.yaml")
    b = resolve_config_path("env/paper_navigation.yaml")
    c = resolve_config_path("paper_navigation")
    assert a.resolve() == b.resolve() == c.resolve()


@pytest.mark.parametrize(
    ("overrides", "fragment"),
    [
        ({"n_agent": 3}, "unknown config key 'n_agent'"),
        ({"physics": {"C_oo": 1.0}}, "unknown config key 'physics.C_oo'"),
        ({"reward": {"speed": 1.0}}, "unknown config key 'reward.speed'"),
        ({"physics": {"l_r": 0.0}}, "l_r must be in (0, inf)"),
        ({"physics": {"beta": float("nan")}}, "beta must be finite"),
        ({"physics": {"C_a": "one"}}, "C_a must be a real number"),
        ({"dt": 0}, "dt must be in (0, inf)"),
        ({"dim": 4}, "dim must be one of (2, 3)"),
        ({"n_agents": 0}, "n_agents must be an integer >= 1"),
        ({"n_agents": 2.5}, "n_agents must be an integer"),
        ({"integrator": "rk4"}, "integrator must be one of"),
        (
            {"dynamics": "zone", "integrator": "velocity_verlet"},
            "integrator='velocity_verlet' is not available with dynamics='zone'",
        ),
        (
            {"dynamics": "piecewise", "integrator": "implicit_damping_euler"},
            "not available with dynamics='piecewise': it takes 'semi_implicit_euler'",
        ),
        ({"success_fraction": 1.5}, "success_fraction must be in (0, 1]"),
        ({"goal_distance_min": 5.0, "goal_distance_max": 4.0}, "goal_distance_max"),
        ({"reward": {"effort": -1.0}}, "effort must be in [0, inf)"),
        ({"goal_in_physics": "yes"}, "goal_in_physics must be true or false"),
        ({"physics": [1, 2]}, "config section 'physics' must be a mapping"),
    ],
)
def test_bad_values_and_unknown_keys_name_the_key(overrides, fragment):
    with pytest.raises(ValueError) as info:
        load_swarm_config(None, overrides)
    assert fragment in str(info.value)


def test_nested_override_merges_into_file_section():
    cfg = load_swarm_config("paper_navigation", {"physics": {"C_o": 0.5}})
    assert cfg.physics.C_o == 0.5
    assert cfg.physics.C_g == 15.0  # the rest of the file's section is kept


def test_instances_pass_through_and_round_trip():
    params = SocialPotentialParams(C_o=0.3)
    cfg = config_from_mapping(SwarmConfig, {"physics": params, "reward": RewardWeights()})
    assert cfg.physics is params
    again = config_from_mapping(SwarmConfig, as_dict(cfg))
    assert again == cfg


def test_missing_file_and_non_mapping_yaml(tmp_path: Path):
    with pytest.raises(ValueError, match="config file not found"):
        load_swarm_config(tmp_path / "nope.yaml")
    bad = tmp_path / "list.yaml"
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="must hold a mapping"):
        load_swarm_config(bad)


# --------------------------------------------------------------------------- packaging

REPO = Path(__file__).resolve().parent.parent


def test_config_root_is_inside_the_package_and_is_the_repositorys_configs():
    import swarm_envs

    assert Path(swarm_envs.__file__).resolve().parent / "configs" == CONFIG_ROOT
    assert CONFIG_ROOT.resolve() == (REPO / "configs").resolve()


def test_every_shipped_config_matches_the_package_data_glob():
    # pyproject ships configs/ as package data "configs/*/*.yaml": a file elsewhere
    # (deeper, or .yml) would be missing from a non-editable install.
    import tomllib

    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert "configs/*/*.yaml" in pyproject["tool"]["setuptools"]["package-data"]["swarm_envs"]
    files = [p for p in (REPO / "configs").rglob("*") if p.is_file()]
    assert files
    for path in files:
        assert path.relative_to(REPO / "configs").match("*/*.yaml"), path


def test_named_configs_resolve_from_an_installed_wheel(tmp_path: Path):
    # Build the wheel (offline, from this checkout) and import it from another folder;
    # the named configs and the C step's sources must be in it.
    import shutil
    import subprocess
    import sys

    pytest.importorskip("setuptools")
    pytest.importorskip("wheel")
    # A copy of what the wheel is built from, so that the build writes nothing here.
    src, wheel_dir, site = tmp_path / "src", tmp_path / "wheel", tmp_path / "site"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__")
    for name in ("swarm_envs", "agents", "train", "configs"):
        shutil.copytree(REPO / name, src / name, symlinks=True, ignore=ignore)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    build = [*pip, "wheel", "--no-build-isolation", "--no-deps", "-w", str(wheel_dir), str(src)]
    subprocess.run(build, check=True, cwd=tmp_path)
    wheels = list(wheel_dir.glob("*.whl"))
    install = [
        *pip,
        "install",
        "--no-deps",
        "--no-compile",
        "--target",
        str(site),
        *map(str, wheels),
    ]
    subprocess.run(install, check=True, cwd=tmp_path)
    probe = (
        "import swarm_envs, swarm_envs.config as c, train.demo as d;"
        f"assert swarm_envs.__file__.startswith({str(site)!r}), swarm_envs.__file__;"
        "assert not c.CONFIG_ROOT.is_symlink() and d.DEFAULT_CONFIG.is_file();"
        "from swarm_envs.envs.cores.native import build as n;"  # the C step's sources ship too
        "assert all((n._source_dir() / f).is_file() for f in n._SOURCES);"
        "print(c.load_swarm_config('paper_navigation').n_agents)"
    )
    env = {"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", probe],
        check=True,
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert out.stdout.strip() == str(load_swarm_config("paper_navigation").n_agents)
