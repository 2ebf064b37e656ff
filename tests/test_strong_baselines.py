"""The strong baselines and what measures learned policies against them: the saturated
PD law, the informed followers, the tuned gains and ``swarm-tune``, the lower bound on
the time to goal, residual policies, the paired difference, and the warning for a
policy evaluated off its training env."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import yaml

from agents import (
    SIMPLE,
    InformedFollowerController,
    SaturatedPDController,
    baseline_names,
    make_controller,
)
from agents.pd import saturate
from agents.tuned import load_tuned, scenario_key, tuned_gains
from swarm_envs import swarm_nav_v0
from swarm_envs.config import CONFIG_ROOT, SwarmConfig
from swarm_envs.envs import observation_size
from swarm_envs.envs.backends import make_core
from swarm_envs.physics import SocialPotentialParams
from swarm_envs.tasks import task_config
from train.benchmark.stats import paired_difference
from train.evaluate import evaluate_policies
from train.evaluate.bound import bound_of_episodes, bound_reason, time_to_goal_bound
from train.evaluate.episodes import run_episodes
from train.evaluate.policies import trained_env_differences, trained_env_record

# --------------------------------------------------------------------------- PD law


def own_obs(cfg: SwarmConfig, offset, velocity) -> np.ndarray:
    obs = np.zeros((1, observation_size(cfg)), np.float32)
    obs[0, : cfg.dim] = np.asarray(offset) / cfg.obs_goal_scale
    obs[0, cfg.dim : 2 * cfg.dim] = np.asarray(velocity) / cfg.obs_velocity_scale
    return obs


def test_pd_is_the_saturated_pd_law():
    cfg = SwarmConfig()
    ctrl = SaturatedPDController(cfg, k_p=0.5, k_d=1.5, saturation="norm")
    offset, velocity = np.array([1.0, -2.0]), np.array([0.4, 0.2])
    action, _ = ctrl.predict(own_obs(cfg, offset, velocity))
    raw = (0.5 * offset - 1.5 * velocity) / cfg.u_max
    np.testing.assert_allclose(action[0], raw, rtol=1e-5)  # inside the box: unsaturated
    far, _ = ctrl.predict(own_obs(cfg, [30.0, 40.0], [0.0, 0.0]))
    np.testing.assert_allclose(far[0], [0.6, 0.8], rtol=1e-5)  # norm 1, toward the goal


def test_box_saturation_keeps_the_direction_and_reaches_the_face():
    z = np.array([[3.0, 4.0], [-8.0, 2.0], [0.1, 0.2]])
    box = saturate(z, "box")
    assert np.allclose(np.max(np.abs(box[:2]), axis=1), 1.0)
    np.testing.assert_allclose(box[2], z[2])
    cos = np.einsum("nk,nk->n", box, z) / np.linalg.norm(box, axis=1) / np.linalg.norm(z, axis=1)
    np.testing.assert_allclose(cos, 1.0)
    assert np.all(np.linalg.norm(saturate(z), axis=1) <= 1.0 + 1e-12)


def test_pd_rejects_bad_gains_and_saturation():
    with pytest.raises(ValueError, match="k_p"):
        SaturatedPDController(SwarmConfig(), k_p=-1.0)
    with pytest.raises(ValueError, match="saturation must be one of"):
        SaturatedPDController(SwarmConfig(), saturation="bang")
    with pytest.raises(TypeError):
        SaturatedPDController(SwarmConfig(), gain=1.0)


def test_pd_beats_the_papers_controller_on_navigation():
    cfg = SwarmConfig()
    results = evaluate_policies(
        {"potential": make_controller("potential", cfg), "pd": make_controller("pd", cfg)},
        cfg,
        episodes=20,
        seed=7,
        progress=False,
    )
    pd, potential = results["policies"]["pd"], results["policies"]["potential"]
    assert pd["success_rate"] == 1.0
    assert pd["mean_return"] > potential["mean_return"] + 2.0
    assert pd["mean_time_to_goal"] < 0.5 * potential["mean_time_to_goal"]
    assert results["best_baseline"] == "pd"


# --------------------------------------------------------------------- informed task


def test_followers_match_their_informed_neighbours():
    cfg = task_config("informed", n_agents=4, n_neighbors=3)
    ctrl = InformedFollowerController(
        cfg, k_p=1.0, k_d=0.0, k_v=1.5, k_c=0.0, k_l=0.0, saturation="norm"
    )
    obs = np.zeros((1, ctrl.obs_dim), np.float32)  # an uninformed agent
    own = 2 * cfg.dim + 1
    block = (ctrl.obs_dim - own) // 3
    # neighbour 0: uninformed, moving (+1, 0) relative; neighbour 1: informed, (0, +0.5)
    obs[0, own : own + block] = [0, 0, 1 / cfg.obs_velocity_scale, 0, 1, 0]
    obs[0, own + block : own + 2 * block] = [0, 0, 0, 0.5 / cfg.obs_velocity_scale, 1, 1]
    action, _ = ctrl.predict(obs)
    np.testing.assert_allclose(action[0], [0.0, 1.5 * 0.5 / cfg.u_max], atol=1e-6)
    informed = obs.copy()
    informed[0, 2 * cfg.dim] = 1.0
    informed[0, : cfg.dim] = [0.3, 0.0]  # goal 3 ahead
    action, _ = ctrl.predict(informed)
    np.testing.assert_allclose(action[0], [1.0 * 3.0 / cfg.u_max, 0.0], atol=1e-6)


def test_followers_close_on_a_point_ahead_of_their_informed_neighbours():
    cfg = task_config("informed", n_agents=3, n_neighbors=2)
    own = 2 * cfg.dim + 1

    def follower_action(lead, neighbour_informed, own_velocity=(0.0, 0.0)):
        ctrl = InformedFollowerController(
            cfg, k_p=1.0, k_d=0.0, k_v=0.0, k_c=1.0, k_l=0.0, lead=lead, saturation="norm",
            flock_lead=0.0,
        )  # fmt: skip
        obs = np.zeros((1, ctrl.obs_dim), np.float32)  # an uninformed agent
        obs[0, cfg.dim : 2 * cfg.dim] = np.array(own_velocity) / cfg.obs_velocity_scale
        # one neighbour 1 to the left, moving (+1, 0) in absolute terms
        relative = np.array([1.0, 0.0]) - np.array(own_velocity)
        obs[0, own : own + 2] = np.array([0.0, 1.0]) / cfg.obs_neighbor_scale
        obs[0, own + 2 : own + 4] = relative / cfg.obs_velocity_scale
        obs[0, own + 4] = 1.0  # real
        obs[0, own + 5] = float(neighbour_informed)
        return ctrl.predict(obs)[0][0]

    u = cfg.u_max
    np.testing.assert_allclose(follower_action(0.0, True), [0.0, 1.0 / u], atol=1e-6)
    # λ = 2 along the neighbour's heading (+x): the target (2, 1), whatever the agent's own
    # velocity (the heading is the neighbour's absolute one)
    np.testing.assert_allclose(follower_action(2.0, True), [2.0 / u, 1.0 / u], atol=1e-6)
    np.testing.assert_allclose(
        follower_action(2.0, True, own_velocity=(0.0, -0.5)), [2.0 / u, 1.0 / u], atol=1e-6
    )
    # no informed neighbour in view: no lead, the agent closes on its neighbours
    np.testing.assert_allclose(follower_action(2.0, False), [0.0, 1.0 / u], atol=1e-6)
    with pytest.raises(ValueError, match="lead"):
        InformedFollowerController(cfg, lead=-1.0)


def test_followers_with_no_informed_neighbour_close_ahead_of_their_flock():
    cfg = task_config("informed", n_agents=3, n_neighbors=2)
    own = 2 * cfg.dim + 1
    u = cfg.u_max

    def follower_action(flock_lead, neighbour_informed, own_velocity=(0.0, 0.0), moving=True):
        ctrl = InformedFollowerController(
            cfg, k_p=1.0, k_d=0.0, k_v=0.0, k_c=1.0, k_l=0.0, lead=2.0,
            flock_lead=flock_lead, saturation="norm",
        )  # fmt: skip
        obs = np.zeros((1, ctrl.obs_dim), np.float32)  # an uninformed agent
        obs[0, cfg.dim : 2 * cfg.dim] = np.array(own_velocity) / cfg.obs_velocity_scale
        # two neighbours 1 to the left and 1 to the right of the agent, both moving
        # (0, 0.5) in absolute terms (or standing still)
        absolute = np.array([0.0, 0.5 if moving else 0.0])
        for j, side in enumerate((-1.0, 1.0)):
            block = own + j * (2 * cfg.dim + 2)
            obs[0, block : block + 2] = np.array([side, 0.0]) / cfg.obs_neighbor_scale
            obs[0, block + 2 : block + 4] = (absolute - own_velocity) / cfg.obs_velocity_scale
            obs[0, block + 4] = 1.0  # real
            obs[0, block + 5] = float(neighbour_informed and j == 0)
        return ctrl.predict(obs)[0][0]

    # No informed neighbour: the point λ_f ahead of the neighbours' mean (0, 0) along
    # their heading (+y), whatever the agent's own velocity.
    np.testing.assert_allclose(follower_action(0.0, False), [0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(follower_action(0.3, False), [0.0, 0.3 / u], atol=1e-6)
    np.testing.assert_allclose(
        follower_action(0.3, False, own_velocity=(0.2, -0.4)), [0.0, 0.3 / u], atol=1e-6
    )
    # A flock at rest has no heading: no lead.
    np.testing.assert_allclose(follower_action(0.3, False, moving=False), [0.0, 0.0], atol=1e-6)
    # An informed neighbour in view: its lead (λ = 2 ahead of it, at (-1, 0)), not the flock's.
    np.testing.assert_allclose(follower_action(0.3, True), [-1.0 / u, 2.0 / u], atol=1e-6)
    with pytest.raises(ValueError, match="flock_lead"):
        InformedFollowerController(cfg, flock_lead=-0.1)


@pytest.mark.parametrize(
    ("k_l", "behind", "expected"),
    [
        (0.0, 2.0, 1.0),  # no tether: full thrust at the goal
        (1.0, 2.0, 0.5),  # (3 − 1 · (2 − 0.5)) / 3: pulled back toward the flock
        (1.0, 0.4, 1.0),  # the flock within the tether's length: no pull
    ],
)
def test_leaders_are_tethered_to_their_flock(k_l, behind, expected):
    cfg = task_config("informed", n_agents=3, n_neighbors=2)
    ctrl = InformedFollowerController(
        cfg, k_p=1.0, k_d=0.0, k_v=1.0, k_c=1.0, k_l=k_l, tether=0.5, saturation="norm"
    )
    obs = np.zeros((1, ctrl.obs_dim), np.float32)
    own = 2 * cfg.dim + 1
    block = (ctrl.obs_dim - own) // 2
    obs[0, : cfg.dim] = [3.0 / cfg.obs_goal_scale, 0.0]  # informed, the goal 3 ahead
    obs[0, 2 * cfg.dim] = 1.0
    for j, side in enumerate((-1.0, 1.0)):  # two neighbours behind it, to either side
        start = own + j * block
        obs[0, start : start + 2] = np.array([-behind, side * 0.1]) / cfg.obs_neighbor_scale
        obs[0, start + 4] = 1.0  # real
    action, _ = ctrl.predict(obs)
    np.testing.assert_allclose(action[0], [expected, 0.0], atol=1e-6)
    with pytest.raises(ValueError, match="k_l"):
        InformedFollowerController(cfg, k_l=-1.0)


def test_a_saturated_goal_pull_lets_the_tether_hold_a_far_leader_back():
    # An informed agent 30 from the goal with its flock 2 behind: the raw PD pull (30)
    # swamps the tether (1 · 1.5); saturated to u_max first, the tether takes half of it.
    cfg = task_config("informed", n_agents=3, n_neighbors=2)
    own = 2 * cfg.dim + 1

    def leader_action(goal_pull):
        ctrl = InformedFollowerController(
            cfg, k_p=1.0, k_d=0.0, k_l=1.0, tether=0.5, saturation="norm", goal_pull=goal_pull
        )
        obs = np.zeros((1, ctrl.obs_dim), np.float32)
        block = (ctrl.obs_dim - own) // 2
        obs[0, : cfg.dim] = [30.0 / cfg.obs_goal_scale, 0.0]
        obs[0, 2 * cfg.dim] = 1.0
        for j in range(2):
            obs[0, own + j * block : own + j * block + 2] = [-2.0 / cfg.obs_neighbor_scale, 0]
            obs[0, own + j * block + 4] = 1.0
        return ctrl.predict(obs)[0][0]

    np.testing.assert_allclose(leader_action("raw"), [1.0, 0.0], atol=1e-6)
    expected = (cfg.u_max - 1.5) / cfg.u_max
    np.testing.assert_allclose(leader_action("saturated"), [expected, 0.0], atol=1e-6)
    with pytest.raises(ValueError, match=r"goal_pull must be one of \('raw', 'saturated'\)"):
        InformedFollowerController(cfg, goal_pull="capped")


def test_followers_need_the_informed_task():
    with pytest.raises(ValueError, match="task='informed'"):
        InformedFollowerController(SwarmConfig())


def test_followers_beat_leaving_the_uninformed_passive():
    cfg = task_config("informed", informed_fraction=0.3)
    names = baseline_names(cfg)
    assert names == ["potential", "pd", "follow"]
    results = evaluate_policies(
        {n: make_controller(n, cfg) for n in names}, cfg, episodes=20, seed=11, progress=False
    )
    follow, potential = results["policies"]["follow"], results["policies"]["potential"]
    assert follow["mean_return"] > potential["mean_return"]
    assert follow["success_rate"] >= potential["success_rate"]


# ------------------------------------------------------------------------ the tuning


def test_tuned_table_is_read_by_the_controllers():
    cfg = SwarmConfig()
    table = load_tuned()
    assert set(table) <= set(sum(SIMPLE.values(), ()))
    gains = tuned_gains("pd", cfg)
    assert gains, "configs/baselines/tuned.yaml holds the navigation PD gains"
    ctrl = SaturatedPDController(cfg)
    assert (ctrl.k_p, ctrl.k_d) == (gains["k_p"], gains["k_d"])
    assert ctrl.saturation == gains["saturation"]
    assert scenario_key(task_config("mill")) == "mill/social_potential"


def test_swarm_tune_writes_the_best_point_of_its_grid(tmp_path):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump(
            {"seed": 3, "episodes": 4, "grids": {"pd": {"k_p": [0.05, 4.0], "k_d": [0.25]}}}
        )
    )
    out = tmp_path / "tuned.yaml"
    assert (
        main(["--grids", str(grids), "--only", "navigation/social_potential", "--out", str(out)])
        == 0
    )
    record = yaml.safe_load(out.read_text())["baselines"]["pd"]["navigation/social_potential"]
    # A weak proportional gain crawls; the strong one wins.
    assert record["gains"] == {"k_p": 4.0, "k_d": 0.25}
    assert record["seed"] == 3 and record["episodes"] == 4 and record["points"] == 2


def test_swarm_tune_refines_past_a_coarse_grid(tmp_path):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump(
            {
                "seed": 3,
                "episodes": 4,
                "grids": {"pd": {"k_p": [0.05], "k_d": [0.25], "saturation": ["box", "norm"]}},
                "refine": {"rounds": 2, "factor": 4.0},
            }
        )
    )
    out = tmp_path / "tuned.yaml"
    assert (
        main(["--grids", str(grids), "--only", "navigation/social_potential", "--out", str(out)])
        == 0
    )
    record = yaml.safe_load(out.read_text())["baselines"]["pd"]["navigation/social_potential"]
    # The grid holds only a crawling proportional gain; the search steps it up.
    assert record["grid_gains"]["k_p"] == 0.05
    assert record["gains"]["k_p"] > 0.05
    assert record["refine_rounds"] >= 1
    assert record["mean_return"] > record["grid_return"]
    # Two grid points, then in each of the two rounds (the first moved, so the second
    # ran) k_p and k_d up and down and the other saturation.
    assert record["points"] == 2 + 2 * 5


def test_swarm_tune_refinement_skips_gains_out_of_range(tmp_path):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump(
            {
                "seed": 3,
                "episodes": 2,
                "grids": {"mill": {"approach": [1.0], "spin": [0.2]}},
                "refine": {"rounds": 1, "factor": 1.25},
            }
        )
    )
    out = tmp_path / "tuned.yaml"
    # approach 1.25 is out of the mill controller's range [0, 1]: skipped, not fatal.
    assert main(["--grids", str(grids), "--only", "mill/social_potential", "--out", str(out)]) == 0
    record = yaml.safe_load(out.read_text())["baselines"]["mill"]["mill/social_potential"]
    assert record["points"] == 1 + 3  # approach 0.8, spin 0.25 and 0.16
    assert 0 <= record["gains"]["approach"] <= 1


def test_a_fixed_informed_fraction_has_its_own_tuned_gains_else_the_tasks(monkeypatch):
    import agents.tuned

    # a range drawn per episode (the informed recipes' mix): the plain key
    mix = dataclasses.replace(task_config("informed"), informed_fraction=(0.1, 0.3))
    at = {f: dataclasses.replace(mix, informed_fraction=f) for f in (0.1, 0.3)}
    assert scenario_key(mix) == "informed/social_potential"
    assert scenario_key(at[0.1]) == "informed/social_potential/informed=0.1"
    table = {
        "pd": {
            "informed/social_potential": {"k_p": 1.0},
            "informed/social_potential/informed=0.1": {"k_p": 2.0},
        }
    }
    monkeypatch.setattr(agents.tuned, "load_tuned", lambda: table)
    assert tuned_gains("pd", at[0.1]) == {"k_p": 2.0}
    assert tuned_gains("pd", at[0.3]) == {"k_p": 1.0}  # not tuned there: the task's
    assert tuned_gains("pd", mix) == {"k_p": 1.0}
    assert tuned_gains("follow", at[0.1]) == {}


def test_swarm_tune_keys_an_entry_at_one_fraction_apart_and_tunes_a_scenario_once(
    tmp_path, monkeypatch, capsys
):
    import train.tune_baselines as tb

    tuned: list[str] = []

    def scores(name, cfg, points, seed, episodes, progress=False):
        tuned.append(scenario_key(cfg))
        return [{"mean_return": 1.0, "success_rate": 1.0} for _ in points]

    monkeypatch.setattr(tb, "_scores", scores)
    matrix = tmp_path / "matrix.yaml"
    shipped = yaml.safe_load((CONFIG_ROOT / "benchmark" / "results.yaml").read_text())
    entries = {e["name"]: e for e in shipped["entries"]}
    twin = dict(entries["informed/social_potential"], name="informed/social_potential_twin")
    picked = [entries["informed/social_potential_at_0.1"], entries["informed/social_potential"]]
    matrix.write_text(yaml.safe_dump({"entries": [*picked, twin]}))
    grids = tmp_path / "grids.yaml"
    grids.write_text(yaml.safe_dump({"grids": {"pd": {"k_p": [2.0], "k_d": [0.5]}}}))
    out = tmp_path / "tuned.yaml"
    assert tb.main(["--grids", str(grids), "--matrix", str(matrix), "--out", str(out)]) == 0
    written = yaml.safe_load(out.read_text())["baselines"]["pd"]
    keys = ["informed/social_potential/informed=0.1", "informed/social_potential"]
    assert sorted(written) == sorted(keys)
    assert tuned == keys  # the twin entry's scenario is not tuned again
    assert capsys.readouterr().out.count("pd on informed/social_potential:") == 1


def test_swarm_tune_writes_an_unmoved_winner_without_yaml_aliases(tmp_path, monkeypatch):
    import train.tune_baselines as tb

    def scores(name, cfg, points, seed, episodes, progress=False):  # the grid's point wins
        value = 1.0 if len(points) == 1 else 0.0
        return [{"mean_return": value, "success_rate": 1.0} for _ in points]

    monkeypatch.setattr(tb, "_scores", scores)
    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump({"grids": {"pd": {"k_p": [2.0], "k_d": [0.5]}}, "refine": {"rounds": 3}})
    )
    out = tmp_path / "tuned.yaml"
    assert tb.main(["--grids", str(grids), "--only", "navigation/zone", "--out", str(out)]) == 0
    text = out.read_text()
    assert "&id" not in text and "*id" not in text  # a readable file, each mapping written out
    record = yaml.safe_load(text)["baselines"]["pd"]["navigation/zone"]
    assert record["gains"] == record["grid_gains"] == {"k_p": 2.0, "k_d": 0.5}
    assert record["refine_rounds"] == 0 and record["points"] == 1 + 4


def test_swarm_tune_chooses_among_the_grid_best_on_more_episodes(tmp_path, monkeypatch):
    import train.tune_baselines as tb

    # On the grid's few episodes k_p = 4 looks best, then 2, then 1; on more episodes
    # (where the rare failure of k_p = 4 shows) k_p = 2 is best.
    few = {1.0: 1.0, 2.0: 2.0, 4.0: 3.0}
    many = {1.0: 1.5, 2.0: 2.5, 4.0: 0.5}
    calls = []

    def scores(name, cfg, points, seed, episodes, progress=False):
        calls.append((len(points), episodes))
        table = few if episodes == 4 else many
        return [{"mean_return": table[p["k_p"]], "success_rate": 1.0} for p in points]

    monkeypatch.setattr(tb, "_scores", scores)
    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump(
            {
                "seed": 3,
                "episodes": 4,
                "grids": {"pd": {"k_p": [1.0, 2.0, 4.0], "k_d": [0.5]}},
                "select": {"pd": {"top": 2, "episodes": 40}},
            }
        )
    )
    out = tmp_path / "tuned.yaml"
    args = ["--grids", str(grids), "--only", "navigation/zone", "--out", str(out)]
    assert tb.main(args) == 0
    record = yaml.safe_load(out.read_text())["baselines"]["pd"]["navigation/zone"]
    # k_p = 1 is not among the grid's two best, so it is not scored again.
    assert calls == [(3, 4), (2, 40)]
    assert record["gains"] == {"k_p": 2.0, "k_d": 0.5}
    assert record["mean_return"] == 2.5 and record["episodes"] == 40
    assert record["grid_episodes"] == 4 and record["selected_from"] == 2
    assert record["points"] == 3 + 2


def test_swarm_tune_reports_progress_through_a_long_grid(tmp_path, capsys, monkeypatch):
    import train.tune_baselines as tb

    monkeypatch.setattr(tb, "PROGRESS_POINTS", 2)
    grids = tmp_path / "grids.yaml"
    grids.write_text(
        yaml.safe_dump({"episodes": 1, "grids": {"pd": {"k_p": [1.0, 2.0, 4.0, 8.0, 16.0]}}})
    )
    out = tmp_path / "tuned.yaml"
    assert tb.main(["--grids", str(grids), "--only", "navigation/zone", "--out", str(out)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "points scored" in ln]
    # A line after every 2 points but the last chunk: 2 and 4 of the 5.
    assert [ln.split()[0] for ln in lines] == ["2/5", "4/5"]
    assert all("on 1 episode in" in ln and "s to go" in ln for ln in lines)
    assert yaml.safe_load(out.read_text())["baselines"]["pd"]["navigation/zone"]["points"] == 5


@pytest.mark.parametrize(
    "select",
    [
        {"pd": {"top": 0, "episodes": 40}},
        {"pd": {"top": 2}},
        {"pd": {"top": 2, "episodes": 40, "seed": 1}},
        {"pd": {"top": 2.5, "episodes": 40}},
        {"mill": {"top": 2, "episodes": 40}},
        [2, 40],
    ],
)
def test_swarm_tune_refuses_a_bad_selection(tmp_path, capsys, select):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(yaml.safe_dump({"grids": {"pd": {"k_p": [1.0]}}, "select": select}))
    assert main(["--grids", str(grids), "--out", str(tmp_path / "t.yaml")]) == 2
    assert "select" in capsys.readouterr().err
    assert not (tmp_path / "t.yaml").exists()


@pytest.mark.parametrize(
    "refine",
    [{"rounds": -1}, {"factor": 1.0}, {"rounds": 2, "step": 2}, [2, 1.25], {"rounds": True}],
)
def test_swarm_tune_refuses_a_bad_refinement(tmp_path, capsys, refine):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(yaml.safe_dump({"grids": {"pd": {"k_p": [1.0]}}, "refine": refine}))
    assert main(["--grids", str(grids), "--out", str(tmp_path / "t.yaml")]) == 2
    assert "refine must be a mapping {rounds: integer >= 0, factor: number > 1}" in (
        capsys.readouterr().err
    )
    assert not (tmp_path / "t.yaml").exists()


def test_swarm_tune_refuses_an_evaluation_seed(tmp_path, capsys):
    from train.tune_baselines import main

    grids = tmp_path / "grids.yaml"
    grids.write_text(yaml.safe_dump({"seed": 2026, "grids": {"pd": {"k_p": [1.0]}}}))
    assert main(["--grids", str(grids), "--out", str(tmp_path / "t.yaml")]) == 2
    assert "evaluation seed" in capsys.readouterr().err
    assert not (tmp_path / "t.yaml").exists()


# ------------------------------------------------------------------------- the bound


@pytest.mark.parametrize("dynamics", ["social_potential", "zone"])
def test_no_policy_reaches_the_goal_before_the_bound(dynamics):
    cfg = SwarmConfig(dynamics=dynamics)
    policies = {name: make_controller(name, cfg) for name in ("pd", "analytic")}
    if dynamics == "social_potential":  # full thrust on both axes: the box's corners
        policies["corner"] = SaturatedPDController(cfg, k_p=5.0, k_d=0.0, saturation="clip")
    for name, policy in policies.items():
        batch = run_episodes(policy, cfg, 16, 5, record_episode=False)
        bound = bound_of_episodes(cfg, batch.start)
        assert bound is not None and np.all(bound > 0)
        assert ("max_turn" in batch.start) == (dynamics == "zone")
        reached = batch.first_success[batch.success] * cfg.dt
        assert batch.success.any()
        assert np.all(reached >= bound[batch.success] - 1e-9), name


def test_bound_is_exact_for_one_free_agent_without_drag():
    # Two agents on top of each other, no pair forces, no drag: full thrust along the
    # axis covers ½ u_max t², and the diagonal gets √2 more thrust from the box.
    params = dataclasses.replace(
        SocialPotentialParams.navigation(), C_a=0.0, C_r=0.0, C_o=0.0, beta=0.0
    )
    cfg = SwarmConfig(physics=params)
    x, v = np.zeros((3, 2, 2)), np.zeros((3, 2, 2))
    goal = np.array([[7.5, 0.0], [7.5 / np.sqrt(2), 7.5 / np.sqrt(2)], [7.5, 1.0]])
    bound = time_to_goal_bound(cfg, x, v, goal)
    assert bound[0] == pytest.approx(2.0)  # 6 = ½ · 3 · t²
    assert bound[1] < bound[0]
    # Off the axes the box's corner gives more progress along the line to the goal
    # (its support, 1.12 u_max here) but leads past the goal's side: the reachable box
    # meets the goal's ball only when x has covered 6, as on the axis.
    assert bound[2] == pytest.approx(2.0)


def test_bound_is_reached_by_one_free_agent_off_the_axes():
    # The bound is tight: a constant action (1, 1/6) brings a free agent from rest to
    # (6, 1) in 2 s without drag, on the ball of radius 1.5 about (7.5, 1).
    params = dataclasses.replace(
        SocialPotentialParams.navigation(), C_a=0.0, C_r=0.0, C_o=0.0, beta=0.0
    )
    cfg = SwarmConfig(physics=params, n_agents=1)
    x, v, goal = np.zeros((1, 1, 2)), np.zeros((1, 1, 2)), np.array([[7.5, 1.0]])
    bound = float(time_to_goal_bound(cfg, x, v, goal)[0])
    core = make_core(cfg)
    core.reset(np.random.default_rng(0))
    core.x[...], core.v[...], core.goal[...] = x, v, goal
    steps = 0
    while np.linalg.norm(core.x[0, 0] - goal[0]) > cfg.arrival_radius:
        core.step(np.array([[[1.0, 1.0 / 6.0]]]))
        steps += 1
    assert steps * cfg.dt == pytest.approx(bound) == pytest.approx(2.0)


def _zone_agent_run(speed: float, heading: float) -> tuple[float, float, float]:
    """One zone-model agent at the origin, its own ``speed`` and start ``heading``
    (radians from the goal's direction), steered by the PD law to the goal 10 away:
    its time to goal, the bound with its turning limit and the bound without."""
    cfg = SwarmConfig(dynamics="zone", n_agents=1)
    core = make_core(cfg)
    core.reset(np.random.default_rng(0))
    core.dynamics.agent_params.speed[...] = speed  # as the model's spread may draw it
    goal = np.array([[10.0, 0.0]])
    core.x[...], core.goal[...] = 0.0, goal
    core.v[...] = speed * np.array([[[np.cos(heading), np.sin(heading)]]])
    start = (core.x.copy(), core.v.copy(), goal)
    turn = core.dynamics.agent_params.max_turn.copy()
    bound = float(time_to_goal_bound(cfg, *start, max_turn=turn)[0])
    straight = float(time_to_goal_bound(cfg, *start)[0])
    pd = make_controller("pd", cfg)
    steps = 0
    while np.linalg.norm(core.x[0, 0] - goal[0]) > cfg.arrival_radius:
        core.step(np.asarray(pd.predict(core.observe().reshape(1, -1))[0]).reshape(1, 1, 2))
        steps += 1
    return steps * cfg.dt, bound, straight


def test_zone_bound_counts_each_agents_own_speed():
    # An agent 25 % faster than the nominal speed, heading at the goal: 8.5 at 0.125 per
    # step is 68 steps. The nominal speed's 85 steps would be no bound at all.
    reached, bound, straight = _zone_agent_run(1.25, 0.0)
    assert bound == straight == pytest.approx(6.8)
    assert reached >= bound - 1e-9


def test_zone_bound_counts_the_turning_limit():
    # Heading 170° away, 30° per step: the agent turns for 5 steps, moving away, before
    # it can head for the goal. The PD law does exactly that, so it meets the bound.
    reached, bound, straight = _zone_agent_run(1.0, np.radians(170.0))
    assert straight == pytest.approx(8.5)
    assert bound == pytest.approx(reached) == pytest.approx(9.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_zone_bound_holds_with_a_wide_spread_and_is_met(dim):
    # Speeds and turning limits spread by 30 %: no episode beats the per-agent bound,
    # and the PD law meets it exactly in some (the bound is tight, not merely safe).
    from swarm_envs.physics import ZoneParams

    cfg = SwarmConfig(dynamics="zone", dim=dim, zone=ZoneParams.navigation(param_spread=0.3))
    batch = run_episodes(make_controller("pd", cfg), cfg, 60, 11, record_episode=False)
    assert "max_turn" in batch.start
    bound = bound_of_episodes(cfg, batch.start)
    slack = batch.first_success[batch.success] * cfg.dt - bound[batch.success]
    assert batch.success.sum() >= 40
    assert slack.min() >= -1e-9
    assert np.isclose(slack, 0.0).any()


def test_bound_is_undefined_where_it_would_not_hold():
    assert bound_reason(SwarmConfig(dynamics="piecewise")) is not None
    assert bound_reason(task_config("mill")) is not None
    assert bound_reason(task_config("informed")) is None  # the gathered swarm, as navigation
    assert bound_reason(SwarmConfig(success_fraction=0.5)) is not None
    assert (
        time_to_goal_bound(
            SwarmConfig(dynamics="lagrangian"), *[np.zeros((1, 2, 2))] * 2, np.ones((1, 2))
        )
        is None
    )


def test_evaluation_reports_the_bound_and_the_best_baseline():
    cfg = SwarmConfig()
    results = evaluate_policies(
        {"pd": make_controller("pd", cfg), "zero": make_controller("zero", cfg)},
        cfg,
        episodes=6,
        seed=1,
        progress=False,
    )
    assert results["time_to_goal_bound"] > 0
    assert results["best_baseline"] == "pd"
    over = results["policies"]["pd"]["time_over_bound"]
    assert over is not None and over >= 0.0


# ------------------------------------------------------------------ the comparisons


def test_paired_difference_removes_what_the_episodes_share():
    rng = np.random.default_rng(0)
    shared = rng.normal(0.0, 5.0, 200)  # the episodes' own difficulty
    baseline = shared
    learned = (shared + 0.3 + rng.normal(0.0, 0.05, 200))[None, :]
    diff = paired_difference(learned, baseline, n_resamples=2000)
    assert diff["ci"][0] > 0.2 and diff["ci"][1] < 0.4
    with pytest.raises(ValueError, match="share episodes"):
        paired_difference(learned, baseline[:10])


def test_a_policy_off_its_training_physics_is_named():
    record = trained_env_record(SwarmConfig(), "swarm_envs/SwarmNav-v0")
    params = dataclasses.replace(SocialPotentialParams.navigation(), C_r=2.0)
    diffs = trained_env_differences(record, SwarmConfig(physics=params, goal_radius=3.0))
    assert "goal_radius: trained 1.5, here 3.0" in diffs
    assert any(d.startswith("physics.C_r: trained") for d in diffs)
    assert trained_env_differences(record, SwarmConfig(n_agents=40)) == []


# ------------------------------------------------------------------------- residual


class _Zero:
    """A stand-in for a trained model: no correction."""

    def __init__(self, cfg: SwarmConfig) -> None:
        ctrl = make_controller("zero", cfg)
        self.observation_space, self.action_space = ctrl.observation_space, ctrl.action_space

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros((*np.shape(obs)[:-1], 2), np.float32), state


def test_residual_policy_without_correction_is_its_baseline():
    from train.residual import ResidualPolicy

    cfg = SwarmConfig()
    pd = make_controller("pd", cfg)
    results = evaluate_policies(
        {"pd": pd, "residual": ResidualPolicy(_Zero(cfg), pd)}, cfg, 5, 3, progress=False
    )
    a, b = results["policies"]["pd"], results["policies"]["residual"]
    assert a["per_episode"]["return"] == pytest.approx(b["per_episode"]["return"], abs=1e-4)
    assert results["best_baseline"] == "pd"  # a trained policy is never a baseline


@pytest.mark.parametrize("scale", [1.0, 0.25])
def test_residual_vec_env_steps_baseline_plus_scaled_correction(scale):
    from train.residual import ResidualVecEnv

    cfg = SwarmConfig(n_agents=5)
    pd = make_controller("pd", cfg)
    plain = swarm_nav_v0.vec_env(2, n_agents=5)
    wrapped = ResidualVecEnv(swarm_nav_v0.vec_env(2, n_agents=5), pd, scale)
    plain.seed(4)
    wrapped.seed(4)
    obs_p, obs_w = plain.reset(), wrapped.reset()
    np.testing.assert_array_equal(obs_p, obs_w)
    correction = np.full((10, 2), 0.1, np.float32)
    for _ in range(5):
        base, _ = pd.predict(obs_p)
        obs_p, r_p, _, _ = plain.step(np.clip(base + scale * correction, -1, 1))
        obs_w, r_w, _, _ = wrapped.step(correction)
        np.testing.assert_allclose(obs_p, obs_w)
        np.testing.assert_allclose(r_p, r_w)


def test_residual_scale_is_refused_outside_its_range_and_without_a_residual():
    from train.config import load_train_config
    from train.residual import ResidualVecEnv

    for bad in (0.0, 1.5, -0.2, True, "half"):
        with pytest.raises(ValueError, match=r"residual_scale must be a number in \(0, 1\]"):
            load_train_config("configs/train/demo.yaml", {"residual": "pd", "residual_scale": bad})
    with pytest.raises(ValueError, match="set residual to a baseline"):
        load_train_config("configs/train/demo.yaml", {"residual_scale": 0.5})
    pd = make_controller("pd", SwarmConfig(n_agents=5))
    with pytest.raises(ValueError, match="residual_scale"):
        ResidualVecEnv(swarm_nav_v0.vec_env(1, n_agents=5), pd, 2.0)


def test_residual_model_loads_as_the_policy_it_trained_as(tmp_path):
    from train.config import load_train_config
    from train.evaluate import load_sb3_model
    from train.residual import ResidualPolicy, as_policy
    from train.train import train

    tc = load_train_config(
        "configs/train/demo.yaml",
        {
            "total_timesteps": 2560,
            "n_swarms": 2,
            "eval_freq": 0,
            "checkpoint_freq": 0,
            "residual": "pd",
            "residual_scale": 0.5,
            "env": {"n_agents": 5},
            "hyperparams": {"n_steps": 256, "batch_size": 640, "n_epochs": 1},
        },
    )
    path = train(tc, tmp_path / "run", progress_bar=False, tensorboard=False, verbose=0)
    policy = load_sb3_model(path)
    assert isinstance(policy, ResidualPolicy)
    pd = make_controller("pd", tc.swarm_config())
    assert (policy.baseline.k_p, policy.baseline.k_d) == (pd.k_p, pd.k_d)
    assert policy.scale == 0.5  # recorded in the model, applied at evaluation
    obs = swarm_nav_v0.vec_env(1, n_agents=5).reset()
    correction, _ = policy.model.predict(obs, deterministic=True)
    base, _ = pd.predict(obs)
    expected = np.clip(base + 0.5 * np.clip(correction, -1, 1), -1, 1)
    np.testing.assert_allclose(policy.predict(obs)[0], expected, rtol=1e-6)
    # Asking a loaded policy for the policy it acts as gives it back, not the baseline
    # added a second time.
    assert as_policy(policy) is policy
    np.testing.assert_allclose(as_policy(policy).predict(obs)[0], expected, rtol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # its own env: no warning
        evaluate_policies({"learned": policy}, tc.swarm_config(), 2, 9, progress=False)


def test_residual_record_rebuilds_the_baseline_it_was_trained_on():
    from train.residual import make_baseline, residual_record

    cfg = task_config("informed")
    tethered = InformedFollowerController(
        cfg, k_l=3.0, tether=2.0, lead=1.5, goal_pull="saturated", flock_lead=0.25
    )
    record = residual_record("follow", tethered)
    assert (record["gains"]["k_l"], record["gains"]["tether"]) == (3.0, 2.0)
    assert (record["gains"]["lead"], record["gains"]["flock_lead"]) == (1.5, 0.25)
    assert record["scale"] == 1.0
    rebuilt = make_baseline("follow", cfg, record["gains"])
    assert (rebuilt.k_l, rebuilt.tether, rebuilt.k_p) == (3.0, 2.0, tethered.k_p)
    assert (rebuilt.lead, rebuilt.goal_pull, rebuilt.flock_lead) == (1.5, "saturated", 0.25)
    # A record made before the tether, the leads and the saturated goal pull existed
    # rebuilds the untethered leader, with its raw pull, and followers without a lead,
    # whatever the tuned table holds today.
    newer = ("k_l", "tether", "lead", "goal_pull", "flock_lead")
    older = {k: v for k, v in record["gains"].items() if k not in newer}
    assert make_baseline("follow", cfg, older).k_l == 0.0
    assert make_baseline("follow", cfg, older).lead == 0.0
    assert make_baseline("follow", cfg, older).flock_lead == 0.0
    assert make_baseline("follow", cfg, older).goal_pull == "raw"


def test_residual_needs_shared_mode_and_a_known_baseline():
    from train.config import load_train_config

    with pytest.raises(ValueError, match="residual must be null or one of"):
        load_train_config("configs/train/demo.yaml", {"residual": "magic"})
    with pytest.raises(ValueError, match="mode 'shared'"):
        load_train_config("configs/train/central.yaml", {"residual": "pd"})


def test_critic_warmup_needs_an_actor_critic_algorithm():
    # SAC's critics are Q-functions: there is no value function to warm up alone, so
    # the config is refused before anything is built, naming both keys.
    from train.config import load_train_config

    warm = {"residual": "pd", "residual_warmup": 1000}
    with pytest.raises(ValueError, match=r"residual_warmup = 1000 .* algo 'SAC'"):
        load_train_config("configs/train/sac_shared.yaml", warm)
    assert load_train_config("configs/train/sac_shared.yaml", {"residual": "pd"}).algo == "SAC"
    assert load_train_config("configs/train/demo.yaml", warm).residual_warmup == 1000


def test_benchmark_baselines_only_trains_nothing(tmp_path):
    import json

    from train.benchmark.cli import main

    out = tmp_path / "bench"
    argv = [
        "--baselines-only",
        "--only",
        "navigation/social_potential",
        "informed/zone",
        "--episodes",
        "4",
        "--resamples",
        "200",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(argv) == 0
    assert not (out / "models").exists()
    results = json.loads((out / "results.json").read_text())
    nav, informed = results["entries"]
    ev = nav["evaluations"][0]
    assert set(ev["policies"]) == {"analytic", "pd"} and ev["best_baseline"] == "pd"
    assert ev["time_to_goal_bound"] > 0
    assert set(informed["evaluations"][0]["policies"]) == {"analytic", "pd", "follow"}
    assert "Baselines only" in (out / "results.md").read_text()


def test_critic_warmup_holds_the_actor_and_trains_the_critic():
    import torch

    from train.config import load_train_config
    from train.residual import CriticWarmup
    from train.train import build_model, make_training_env

    tc = load_train_config(
        "configs/train/demo.yaml",
        {
            "n_swarms": 2,
            "residual": "pd",
            "env": {"n_agents": 5},
            "hyperparams": {"n_steps": 64, "batch_size": 320, "n_epochs": 2},
        },
    )
    model = build_model(tc, make_training_env(tc))
    policy = model.policy
    actor = [p.detach().clone() for p in policy.action_net.parameters()] + [
        policy.log_std.detach().clone()
    ]
    critic = [p.detach().clone() for p in policy.value_net.parameters()]
    warmup = CriticWarmup(10**9)
    model.learn(640, callback=warmup)
    after = [*policy.action_net.parameters(), policy.log_std]
    assert all(torch.equal(a, b) for a, b in zip(actor, after, strict=True))
    assert not all(
        torch.equal(a, b) for a, b in zip(critic, policy.value_net.parameters(), strict=True)
    )
    assert all(p.requires_grad for p in after)  # released at the end of training
    model.get_env().close()


def test_swarm_eval_compares_every_baseline_by_default(tmp_path):
    import json

    from train.cli_eval import main

    out = tmp_path / "eval"
    argv = ["--config", "configs/env/informed.yaml", "--episodes", "3", "--out", str(out)]
    assert main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    assert list(results["policies"]) == ["potential", "pd", "follow", "zero", "random"]
    assert results["best_baseline"] in ("potential", "pd", "follow", "zero", "random")
    assert "Lower bound on the time to goal" in (out / "summary.md").read_text()


def test_bound_line_names_every_near_optimal_baseline():
    from train.evaluate.report import bound_line

    results = {
        "time_to_goal_bound": 10.0,
        "best_baseline": "informed",
        "baselines": ["informed", "pd", "potential"],
        "policies": {
            "informed": {"time_over_bound": 0.0525},
            "pd": {"time_over_bound": 0.027},
            "potential": {"time_over_bound": 0.30},
            "learned": {"time_over_bound": 0.01},  # not a baseline: never named
        },
    }
    line = bound_line(results)
    assert "The best baseline, informed, takes +5.25% more (room to gain)." in line
    assert "pd takes +2.70% more, within 5% of it: near-optimal on time" in line
    assert "potential takes" not in line and "learned" not in line


def test_free_agent_time_bounds_a_swarm_without_pair_forces():
    # Without pair forces every agent is on its own: the estimate becomes a bound, and
    # it is tighter than the centroid's.
    from train.evaluate.bound import free_agent_time

    params = dataclasses.replace(SocialPotentialParams.navigation(), C_a=0.0, C_r=0.0, C_o=0.0)
    cfg = SwarmConfig(physics=params)
    batch = run_episodes(make_controller("pd", cfg), cfg, 12, 3, record_episode=False)
    start = (batch.start["x"], batch.start["v"], batch.start["goal"])
    alone, bound = free_agent_time(cfg, *start), time_to_goal_bound(cfg, *start)
    assert np.all(alone >= bound)
    reached = batch.first_success[batch.success] * cfg.dt
    assert batch.success.all() and np.all(reached >= alone - 1e-9)
    assert free_agent_time(SwarmConfig(dynamics="zone"), *start) is None


def test_robustness_and_transfer_mark_each_rows_best_baseline():
    from train.evaluate import (
        evaluate_robustness,
        evaluate_transfer,
        format_robustness_table,
        format_transfer_table,
    )

    cfg = SwarmConfig(n_agents=6)
    policies = {"potential": make_controller("potential", cfg), "pd": make_controller("pd", cfg)}
    policies["zero"] = make_controller("zero", cfg)
    robust = evaluate_robustness(
        policies, cfg, {"failed_fraction": [0.0, 0.5]}, 4, 1, progress=False, plots=False
    )
    for row in robust["rows"]:
        returns = {n: m["mean_return"] for n, m in row["policies"].items()}
        assert returns[row["best_baseline"]] == max(returns.values())
    assert format_robustness_table(robust).count("✓") == 2
    sizes = evaluate_transfer(policies, cfg, [4, 8], 3, 1, progress=False, plots=False)
    assert [s["best_baseline"] for s in sizes["sizes"]] == ["pd", "pd"]
    assert format_transfer_table(sizes).count("✓") == 2
