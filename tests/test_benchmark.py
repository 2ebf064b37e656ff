"""``swarm-benchmark``: the matrix file, resumable training, and the outputs end to end."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents import ANALYTIC
from swarm_envs.config import DYNAMICS
from train.benchmark import cli
from train.benchmark.matrix import (
    DEFAULT_MATRIX,
    Entry,
    Evaluation,
    load_matrix,
    matrix_from_mapping,
)
from train.benchmark.run import entry_train_config, model_folder
from train.interrupt import StopRequest, TrainingInterrupted
from train.train import train

TINY_TRAIN = {
    "algo": "PPO",
    "env": {"n_agents": 3, "max_steps": 30, "n_neighbors": 2},
    "n_swarms": 2,
    "total_timesteps": 3 * 192,  # three rollouts of 2 swarms × 3 agents × 32 steps
    "net_arch": [16, 16],
    "checkpoint_seconds": 0,
    "checkpoint_freq": 1,  # a checkpoint at every update boundary
    "hyperparams": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
}


def entry(**kw) -> dict:
    base = {"name": "nav/zone", "task": "navigation", "dynamics": "zone", "train": "demo"}
    return {**base, **kw}


def status(argv: list[str]) -> int:
    try:
        return cli.main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)


def no_nan(text: str) -> dict:
    def refuse(name: str) -> None:
        raise AssertionError(f"{name} in results.json")

    return json.loads(text, parse_constant=refuse)


# --------------------------------------------------------------------------- the matrix


def test_the_shipped_matrix_covers_every_task_and_dynamics():
    m = load_matrix(DEFAULT_MATRIX)
    navigation = [e for e in m.entries if e.task == "navigation"]
    assert [e.dynamics for e in navigation] == list(DYNAMICS)
    assert {(e.task, e.dynamics) for e in m.entries if e.task != "navigation"} == {
        ("informed", "social_potential"),
        ("informed", "zone"),
        ("mill", "social_potential"),
    }
    evaluated: dict[str, list[float]] = {}  # the informed task's fractions, per dynamics
    for e in m.entries:
        assert e.name.split("_at_")[0] == f"{e.task}/{e.dynamics}"
        assert "analytic" in e.baselines
        tc = e.train_config(seed=2)
        cfg = tc.swarm_config()
        assert tc.seed == 2 and cfg.dynamics == e.dynamics and cfg.task == e.task
        for evaluation in e.evaluations:
            ev = e.eval_config(evaluation, tc)
            assert ev.task == e.task and ev.dynamics == e.dynamics
        if e.task == "informed":
            fractions = [e.eval_config(v, tc).informed_fraction for v in e.evaluations]
            evaluated.setdefault(e.dynamics, []).extend(fractions)
            if "_at_" in e.name:  # a policy trained at the one fraction it is evaluated at
                assert [cfg.informed_fraction] == fractions == [float(e.name.split("_at_")[1])]
            else:  # trained on the task's mix of fractions
                assert cfg.informed_fraction == (0.1, 0.3)
    # both fractions of the task's statement, each in one row
    assert {k: sorted(v) for k, v in evaluated.items()} == {
        "social_potential": [0.1, 0.3],
        "zone": [0.1, 0.3],
    }


def test_an_entry_with_evaluations_and_overrides():
    e = Entry(
        **entry(
            env={"n_agents": 6},
            train_overrides={"total_timesteps": 5000},
            evaluations=[{"label": "N6"}, {"label": "N12", "env": {"n_agents": 12}}],
            baselines=["analytic", "zero"],
        )
    )
    tc = e.train_config(seed=1)
    assert tc.total_timesteps == 5000
    assert tc.env == {"n_agents": 6, "dynamics": "zone", "task": "navigation"}
    cfgs = [e.eval_config(v, tc) for v in e.evaluations]
    assert [c.n_agents for c in cfgs] == [6, 12]
    assert {c.dynamics for c in cfgs} == {"zone"}
    assert e.evaluations[1] == Evaluation("N12", {"n_agents": 12})


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"entries": [entry()], "extra": 1}, "unknown key.*extra; allowed: entries"),
        ({"entries": []}, "non-empty list"),
        ({"entries": [entry(colour="red")]}, r"entries\[0\]: unknown key.*colour; allowed: name"),
        ({"entries": [{"name": "x", "task": "t", "train": "demo"}]}, "missing key.*dynamics"),
        ({"entries": [entry(dynamics="boids")]}, "dynamics must be one of social_potential"),
        ({"entries": [entry(env={"dynamics": "piecewise"})]}, "contradicts dynamics"),
        ({"entries": [entry(env={"n_agent": 4})]}, "unknown config key 'n_agent'"),
        ({"entries": [entry(train="nope")]}, "train config not found: nope"),
        ({"entries": [entry(train_overrides={"n_swarm": 4})]}, "n_swarm"),
        ({"entries": [entry(train_overrides={"seed": 4})]}, "seeds come from --seeds"),
        ({"entries": [entry(), entry()]}, "nav/zone given twice"),
        ({"entries": [entry(name="../x")]}, "'.' or '..'"),
        ({"entries": [entry(name="a b")]}, "name must use letters"),
        ({"entries": [entry(baselines=["potentail"])]}, "unknown policy 'potentail'; known:"),
        ({"entries": [entry(baselines="analytic")]}, "list of policy names"),
        ({"entries": [entry(evaluations=[{"label": "a"}, {"label": "a"}])]}, "a given twice"),
        ({"entries": [entry(evaluations=[{"label": "a", "envs": {}}])]}, "unknown key.*envs"),
        ({"entries": [entry(evaluations=[{"env": {"dt": -1}}])]}, "evaluation 'default': env:"),
        ({"entries": [entry(evaluations=[])]}, "must not be empty"),
    ],
)
def test_matrix_mistakes_are_named(data, match):
    with pytest.raises(ValueError, match=match):
        matrix_from_mapping(data)


def test_unknown_keywords_are_type_errors():
    with pytest.raises(TypeError, match="colour"):
        Entry(**entry(colour="red"))
    with pytest.raises(TypeError, match="envs"):
        Evaluation(label="a", envs={})


def test_only_selects_entries_in_matrix_order_and_names_unknown_ones():
    m = load_matrix(DEFAULT_MATRIX)
    picked = m.select(["navigation/lagrangian", "navigation/zone"])
    assert [e.name for e in picked] == ["navigation/zone", "navigation/lagrangian"]
    with pytest.raises(ValueError, match="no entry named nav; entries: navigation/social"):
        m.select(["nav"])


# --------------------------------------------------------------------------- end to end


def check_results(out: Path, names: list[str], seeds: int, episodes: int) -> dict:
    results = no_nan((out / "results.json").read_text())
    b = results["benchmark"]
    assert b["entries"] == names and b["episodes"] == episodes and len(b["seeds"]) == seeds
    assert set(results["measures"]) == {"return", "success", "time_to_goal", "iqm_return"}
    assert [e["name"] for e in results["entries"]] == names
    rows = 0
    for e in results["entries"]:
        assert [m["seed"] for m in e["models"]] == b["seeds"]
        for m in e["models"]:
            assert Path(m["path"]).is_file() and m["timesteps"] > 0
        for ev in e["evaluations"]:
            assert ev["policies"]["learned"]["kind"] == "learned"
            for name, p in ev["policies"].items():
                rows += 1
                n_seeds = seeds if name == "learned" else 1
                assert (p["n_seeds"], p["n_episodes"]) == (n_seeds, episodes)
                assert np.shape(p["per_episode"]["return"]) == (n_seeds, episodes)
                for key in results["measures"]:
                    assert len(p["per_seed"][key]) == n_seeds
                    value, ci = p[key]["value"], p[key]["ci"]
                    if value is None:
                        assert key == "time_to_goal" and not any(
                            any(s) for s in p["per_episode"]["success"]
                        )
                    else:
                        assert ci[0] <= value + 1e-12 and value <= ci[1] + 1e-12
                success = np.array(p["per_episode"]["success"], float)
                assert p["success"]["value"] == pytest.approx(success.mean())
    table = (out / "results.md").read_text()
    body = [line for line in table.splitlines() if line.startswith("| ")]
    assert body[0].startswith("| entry | evaluation | policy | return [95% CI]")
    assert len(body) == 1 + rows
    assert (out / "results.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return results


def _suptitles(results, path):
    """The figure titles :func:`plot_results` draws for ``results``."""
    from matplotlib.figure import Figure

    from train.benchmark.report import plot_results

    titles = []
    save = Figure.savefig

    def spy(fig, *args, **kwargs):
        titles.append(fig.get_suptitle())
        return save(fig, *args, **kwargs)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(Figure, "savefig", spy)
        plot_results(results, path)
    return titles


def test_quick_run_of_two_shipped_entries(tmp_path, capsys):
    names = ["navigation/social_potential", "navigation/piecewise"]
    out = tmp_path / "bench"
    argv = ["--quick", "--only", *names, "--out", str(out), "--episodes", "4", "--no-progress"]
    assert status(argv) == 0
    results = check_results(out, names, seeds=2, episodes=4)
    for e in results["entries"]:
        ev = e["evaluations"][0]
        analytic = ev["policies"]["analytic"]
        assert analytic["controller"] == ANALYTIC[e["dynamics"]]
        assert set(ev["policies"]) == {"learned", "analytic", "pd"}  # the default baselines
        best = ev["best_baseline"]
        returns = {n: p["return"]["value"] for n, p in ev["policies"].items() if n != "learned"}
        assert returns[best] == max(returns.values())
        diff = ev["policies"]["learned"]["minus_best"]
        assert diff["baseline"] == best and diff["return"]["ci"] is not None
        assert (ev["time_to_goal_bound"] is None) == (e["dynamics"] == "piecewise")
        assert e["train_config"]["env"]["dynamics"] == e["dynamics"]
        assert {m["action"] for m in e["models"]} == {"trained"}
    assert (model_folder(out, load_matrix().select(names)[0], 1) / "model.zip").is_file()
    titles = _suptitles(results, tmp_path / "again.png")
    assert titles[0].startswith("SMOKE RUN (--quick)")  # the picture says what it is
    full = {**results, "benchmark": {**results["benchmark"], "quick": False}}
    assert "SMOKE" not in _suptitles(full, tmp_path / "full.png")[0]

    capsys.readouterr()
    assert status(argv) == 0  # again: every model reused, the same numbers
    assert capsys.readouterr().out.count("reusing") == 4
    again = no_nan((out / "results.json").read_text())
    for ea, eb in zip(again["entries"], results["entries"], strict=True):
        assert {m["action"] for m in ea["models"]} == {"reused"}
        for va, vb in zip(ea["evaluations"], eb["evaluations"], strict=True):
            va.pop("eval_seconds"), vb.pop("eval_seconds")
            assert va == vb


class StopAfter(StopRequest):
    """A stop request that turns true at its ``n``-th reading (a signal, deterministically)."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n

    @property
    def requested(self) -> bool:
        self.n -= 1
        if self.n < 0:
            self.request(signal.SIGINT)
        return self.signum is not None


@pytest.fixture
def tiny(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(TINY_TRAIN))
    matrix = {
        "entries": [
            {
                "name": "tiny/zone",
                "task": "navigation",
                "dynamics": "zone",
                "train": str(tmp_path / "tiny.yaml"),
                "evaluations": [{"label": "N3"}, {"label": "N5", "env": {"n_agents": 5}}],
                "baselines": ["analytic", "zero"],
            }
        ]
    }
    (tmp_path / "matrix.yaml").write_text(yaml.safe_dump(matrix))
    return {"train": tmp_path / "tiny.yaml", "matrix": tmp_path / "matrix.yaml"}


def test_stopped_training_resumes_and_a_changed_config_is_refused(tmp_path, tiny, capsys):
    out = tmp_path / "bench"
    e = load_matrix(tiny["matrix"]).entries[0]
    folder = model_folder(out, e, 0)
    with pytest.raises(TrainingInterrupted):  # a benchmark stopped inside seed 0's training
        train(
            entry_train_config(e, 0, quick=False),
            folder,
            progress_bar=False,
            tensorboard=False,
            verbose=0,
            stop=StopAfter(2),
        )
    assert json.loads((folder / "meta.json").read_text())["status"] == "interrupted"

    argv = ["--matrix", str(tiny["matrix"]), "--out", str(out), "--seeds", "0", "1"]
    argv += ["--episodes", "3", "--no-progress", "--resamples", "200"]
    assert status(argv) == 0
    log = capsys.readouterr().out
    assert "seed 0: resuming" in log and "seed 1: training" in log
    results = check_results(out, ["tiny/zone"], seeds=2, episodes=3)
    evs = results["entries"][0]["evaluations"]
    assert [(v["label"], v["n_agents"]) for v in evs] == [("N3", 3), ("N5", 5)]
    assert list(evs[0]["policies"]) == ["learned", "analytic", "zero"]
    assert evs[0]["policies"]["analytic"]["controller"] == "informed"
    models = results["entries"][0]["models"]
    assert [m["action"] for m in models] == ["resumed", "trained"]
    assert all(m["timesteps"] >= TINY_TRAIN["total_timesteps"] for m in models)

    tiny["train"].write_text(yaml.safe_dump({**TINY_TRAIN, "total_timesteps": 4 * 192}))
    assert status(argv) == 2
    err = capsys.readouterr().err
    assert "holds a model trained with another config: total_timesteps (576 there, 768 now)" in err
    assert status([*argv, "--overwrite"]) == 0
    assert capsys.readouterr().out.count("training PPO for 768 timesteps") == 2


def test_a_residual_model_on_gains_tuned_anew_since_is_refused(tmp_path, monkeypatch):
    from train.benchmark.run import StaleModelError, existing_run

    train_file = tmp_path / "residual.yaml"
    train_file.write_text(yaml.safe_dump({**TINY_TRAIN, "residual": "pd"}))
    matrix = {
        "entries": [
            {
                "name": "nav",
                "task": "navigation",
                "dynamics": "social_potential",
                "train": str(train_file),
            }
        ]
    }
    (tmp_path / "matrix.yaml").write_text(yaml.safe_dump(matrix))
    e = load_matrix(tmp_path / "matrix.yaml").entries[0]
    tc = entry_train_config(e, 0, quick=False)
    folder = tmp_path / "run"
    train(tc, folder, progress_bar=False, tensorboard=False, verbose=0)
    assert existing_run(tc, folder) == "reuse"
    # swarm-tune rewrote the PD law's gains since: the same config, another baseline
    import agents.tuned

    tuned = agents.tuned.tuned_gains
    monkeypatch.setattr(
        agents.tuned, "tuned_gains", lambda name, cfg: {**tuned(name, cfg), "k_p": 123.0}
    )
    with pytest.raises(StaleModelError, match=r"whose gains k_p differ from today's tuned `pd`"):
        existing_run(tc, folder)
    assert existing_run(tc, folder, overwrite=True) == "train"


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--eval-seed", "1"], "--eval-seed (1) must differ from the training seeds"),
        (["--only", "nope"], "--only: no entry named nope"),
        (["--episodes", "0"], "--episodes must be an integer >= 1"),
        (["--seeds", "1", "1"], "--seeds gives a seed twice"),
        (["--seeds", "-1"], "--seeds must be an integer in [0, 4294967295]"),
        (["--matrix", "missing.yaml"], "matrix not found: missing.yaml"),
    ],
)
def test_cli_mistakes_are_one_line_before_anything_is_written(tmp_path, capsys, extra, match):
    out = tmp_path / "bench"
    assert status(["--quick", "--out", str(out), "--seeds", "0", "1", *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("swarm-benchmark: error: ") and match in err
    assert not out.exists()


def test_an_entry_names_a_known_task_once():
    with pytest.raises(ValueError, match="task must be one of"):
        Entry(**entry(task="flock"))
    with pytest.raises(ValueError, match="contradicts task"):
        Entry(**entry(env={"task": "mill"}))
    informed = Entry(**entry(name="informed/zone", task="informed"))
    assert informed.train_config(seed=0).swarm_config().informed_fraction == 0.3


# --------------------------------------------------------------------------- --jobs


def test_parallel_training_gives_the_results_of_one_run_after_another(tmp_path, tiny, capfd):
    """Two entries, each trained with two seeds and evaluated in processes of their
    own: the same results, in the matrix's order, as everything in one process."""
    matrix = yaml.safe_load(tiny["matrix"].read_text())
    second = {**matrix["entries"][0], "name": "tiny/zone_n4", "env": {"n_agents": 4}}
    second["evaluations"] = [{"label": "N4"}]
    matrix["entries"].append(second)
    tiny["matrix"].write_text(yaml.safe_dump(matrix))
    base = ["--matrix", str(tiny["matrix"]), "--seeds", "0", "1", "--episodes", "3"]
    base += ["--no-progress", "--resamples", "200"]
    assert status([*base, "--out", str(tmp_path / "one")]) == 0
    assert status([*base, "--out", str(tmp_path / "two"), "--jobs", "2"]) == 0
    out = capfd.readouterr().out  # the processes' lines too
    assert "training 4 runs and evaluating 2 entries, 2 at once" in out
    assert "tiny/zone_n4 evaluation 'N4'" in out  # the evaluation's lines name their entry
    one = no_nan((tmp_path / "one" / "results.json").read_text())
    two = no_nan((tmp_path / "two" / "results.json").read_text())
    assert [e["name"] for e in two["entries"]] == ["tiny/zone", "tiny/zone_n4"]
    for a, b in zip(one["entries"], two["entries"], strict=True):
        assert [m["action"] for m in b["models"]] == ["trained", "trained"]
        for ea, eb in zip(a["evaluations"], b["evaluations"], strict=True):
            ea.pop("eval_seconds"), eb.pop("eval_seconds")
            assert ea == eb
    assert status(["--jobs", "0", *base, "--out", str(tmp_path / "bad")]) == 2


def test_a_signal_stops_parallel_training_which_resumes(tmp_path, tiny):
    """SIGINT to the main process reaches each training process once: they save, the
    benchmark exits with the signal's status, and running it again resumes them."""
    import subprocess
    import sys
    import time

    slow = {**TINY_TRAIN, "total_timesteps": 200 * 192}  # seconds: stopped before its end
    tiny["train"].write_text(yaml.safe_dump(slow))
    out = tmp_path / "bench"
    argv = ["--matrix", str(tiny["matrix"]), "--out", str(out), "--seeds", "0", "1"]
    argv += ["--episodes", "3", "--no-progress", "--resamples", "200", "--jobs", "2"]
    code = "import sys; from train.benchmark.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True)
    e = load_matrix(tiny["matrix"]).entries[0]
    folders = [model_folder(out, e, seed) for seed in (0, 1)]
    deadline = time.monotonic() + 120
    while not all((f / "checkpoints").is_dir() for f in folders):
        assert proc.poll() is None and time.monotonic() < deadline, "training did not start"
        time.sleep(0.2)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "stopped by SIGINT" in err and "run the same command again" in err
    for f in folders:  # each saved once and stopped (a second signal would abort unsaved)
        assert json.loads((f / "meta.json").read_text())["status"] == "interrupted"
    assert status(argv) == 0  # again: both runs resume and finish
    models = no_nan((out / "results.json").read_text())["entries"][0]["models"]
    assert [m["action"] for m in models] == ["resumed", "resumed"]
    assert [m["timesteps"] for m in models] == [200 * 192] * 2
