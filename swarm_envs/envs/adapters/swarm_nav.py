"""SwarmNav: goal-sink navigation of a social-potential swarm (PettingZoo and Gymnasium).

Both classes are adapters over one core (:func:`~swarm_envs.envs.backends.make_core`)
with one swarm (B = 1). The shared docstring below follows Gymnasium's sections; its
reward table, statistics and episode ends are made from the task registry's
declarations (:func:`env_doc_sections`), so that they are written once.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from swarm_envs.envs.adapters.inputs import (
    as_action,
    check_reset_options,
    check_seed,
    make_config,
    stack_agent_actions,
)
from swarm_envs.envs.adapters.swarm_view import Rendering, SwarmState
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.task import OBS_BOUND
from swarm_envs.envs.task.agent_status import ACTIVE

RENDER_MODES = ("rgb_array", "human")

_SWARM_NAV_DOC = """
    ## Description

    A swarm of ``N`` agents obeys the social potential model of Mabrouk & McInnes
    (Morse cohesion eqs. 9–10, alignment eq. 11, dissipation eq. 12; docs/models.md §1) and
    must gather inside a goal radius around a goal sink ``G``. The passive physics is
    always on; each agent's action is a bounded force added to its passive force, so a
    zero action leaves the paper's model untouched. The sink ``C_g, l_g`` (eq. 19)
    defines the task and what the analytic baseline controller applies; with
    ``goal_in_physics=True`` it also acts passively (the paper's eq. 21) and actions
    are residuals on top of it.

    ``dynamics`` selects another model of the seeds as the passive physics, each with
    its own parameter section and analytic baseline (``agents.ANALYTIC``):

    | ``dynamics``         | model (config section)               | action ``u = u_max a``  |
    |----------------------|--------------------------------------|-------------------------|
    | ``social_potential`` | Mabrouk & McInnes (``physics``)      | force added to ``F_i``  |
    | ``zone``             | Couzin, Naterop §4.1 (``zone``)      | desired-direction bias  |
    | ``piecewise``        | Viscido, Naterop §4.2 (``piecewise``)| force added             |
    | ``lagrangian``       | Vanualailai & Sharma (``lagrangian``)| velocity added          |

    Details, and what ``goal_in_physics`` means for each, in ``swarm_envs.envs.dynamics``.

    ## Tasks

    ``task`` (one registered id each; ``swarm_envs.tasks``, docs/tasks.md) says what
    the swarm must do; each brings its defaults, which the given values override:

    - ``"navigation"`` (``swarm_envs/SwarmNav-v0``): gather inside the goal radius.
    - ``"informed"`` (``swarm_envs/SwarmInformed-v0``): the same, when only a fraction
      ``informed_fraction`` of each swarm (default 0.3; a ``[low, high]`` range is
      drawn per episode; ``f·N`` agents rounded, at least one, drawn per episode) observes
      the goal. The others read zeros for the goal offset; every agent observes its
      own informed flag and each neighbour's (below). Couzin's informed individuals
      (Naterop §4.1): the analytic baselines act through the informed agents only.
      Runs on every ``dynamics``, with the numpy and cut-off backends.
    - ``"mill"`` (``swarm_envs/SwarmMill-v0``): reach the goal and circle it, on the
      self-propelled social potential (``physics.alpha > 0``: the friction becomes
      the Rayleigh term ``(α − β|v|²) v``, cruise speed ``v₀ = √(α/β)``; default α = β
      = 0.5, ``v₀ = 1``) with the sink acting passively (``goal_in_physics``); it is
      rewarded by the ``mill`` term and holds its success (below).

    A task of one's own is a ``swarm_envs.tasks.TaskSpec`` registered with
    ``swarm_envs.tasks.register_task`` (docs/tasks.md): ``task="<its name>"`` then runs
    it here, with its reward terms, statistics and observation features.

    ## Action Space

    Per agent ``Box(-1, 1, (d,), float32)``; the control is ``u_i = u_max · a_i`` (a
    force, a direction bias or a velocity, by ``dynamics``). The Gymnasium env takes
    all agents' actions as one flat ``Box(-1, 1, (N·d,))`` (agent-major).

    The input rule (docs/inputs.md, the same for every API and backend): an action is
    a real numeric array (float or integer dtype) of exactly the declared shape, rank
    included, or a list of numbers that converts to it, or a ``torch.Tensor`` (detached;
    ``requires_grad`` is fine). Finite values outside the box are clipped; NaN/inf,
    bool, complex, object or string dtypes and any other shape raise ``ValueError``
    naming the rule and what was given; nothing is reshaped or cast silently.
    ``reset(seed=...)`` takes ``None`` or a non-negative integer (Python or numpy:
    ``np.int64(3)`` seeds as ``3``); anything else raises ``ValueError``.

    ## Observation Space

    Per agent ``Box(-10, 10, (2d + k(2d + 1),), float32)``; every entry is clipped to
    [−10, 10]. The Gymnasium env concatenates all agents' observations (agent-major).
    The PettingZoo env's global ``state()`` is the same concatenation, in
    ``state_space = Box(-10, 10, (N(2d + k(2d + 1)),), float32)`` (for a centralised
    critic).

    | index (d = 2, k neighbours)   | observation                                        |
    |-------------------------------|----------------------------------------------------|
    | 0 – 1                         | goal offset ``(r_g − r_i) / obs_goal_scale``        |
    | 2 – 3                         | own velocity ``v_i / obs_velocity_scale``           |
    | 4 + 5m – 5 + 5m               | m-th nearest neighbour ``(r_j − r_i) / obs_neighbor_scale`` |
    | 6 + 5m – 7 + 5m               | its relative velocity ``(v_j − v_i) / obs_velocity_scale``  |
    | 8 + 5m                        | mask: 1 for a real neighbour, 0 for padding (N − 1 < k) |

    With ``observe_status=True`` each neighbour block has a sixth entry (blocks of
    ``2d + 2``): 1 when that neighbour is active, 0 when it has failed; the Gymnasium
    env then ends its observation with every agent's flag (``N`` more entries).

    With ``task="informed"`` the goal offset of an agent that is not informed is zero,
    the own features end with the agent's informed flag (``2d + 1`` entries), and each
    neighbour block ends with that neighbour's informed flag (one more entry, after the
    status flag if any). The layout is ``swarm_envs.envs.task.observation``'s.

    ## Rewards

    {rewards}

    ## Starting State

    Positions uniform in a disc (ball) of radius ``init_radius`` about the origin,
    velocities uniform in a disc of radius ``init_speed``; the goal at a uniform random
    bearing, at a distance uniform in ``[goal_distance_min, goal_distance_max]``.

    ## Episode End

    {episode_end}

    Truncated after ``max_steps`` steps (``max_cycles`` in PettingZoo) where not
    terminated. The members are every agent, unless ``perturbations`` fail some: then
    the agents that still move (active, or failed passively). ``gym.make`` adds no
    ``TimeLimit``: ``max_steps`` is the only episode length (a ``max_episode_steps``
    given to ``gym.make`` adds one).

    ## Arguments

    Every field of :class:`swarm_envs.config.SwarmConfig` is a keyword argument
    (``n_agents``, ``dim``, ``dt``, ``dynamics``, ``physics={...}``, ``zone={...}``,
    ``reward={...}``, ...; a partial section changes only the keys it names), and
    ``config="configs/env/paper_navigation.yaml"`` loads a YAML first (keywords then
    override it). An unknown keyword raises ``swarm_envs.config.UnknownKeyError`` — a
    ``TypeError``, as Python raises for an unexpected keyword argument, and also a
    ``ValueError`` — naming it and the allowed keys. An invalid value (an unknown key
    inside a section such as ``physics={...}`` included) raises ``ValueError`` naming
    it, when the env is built (a Lagrangian ``init_radius`` too small for its bins
    included).
    ``render_mode`` is ``None``, ``"rgb_array"`` or ``"human"``.
    ``info_kinematics`` (``False`` by default; ``True`` or ``False``, else
    ``ValueError``) adds each agent's kinematics to the info (below).
    ``reset(seed=..., options=...)``: ``options`` is ``None`` or a dict, whose entries
    are not read (SwarmNav has no reset options; PettingZoo's API tests pass arbitrary
    entries); anything else raises ``ValueError``.

    ## Info

    Per agent in PettingZoo, one dict in Gymnasium, as Python floats: the statistics
    (over the members; a task's own statistics follow these)

    {statistics}

    ``energy`` is eq. 16 with the sink for the social potential, ``L`` for the
    Lagrangian model and the kinetic energy for the zone and piecewise models. With
    ``info_kinematics=True`` also ``pos`` (``r_i``), ``vel``
    (``v_i``) and ``goal_offset`` (``r_g − r_i``), float32 in world units (unscaled,
    unclipped): ``(d,)`` in each agent's info in PettingZoo, ``(N, d)`` in Gymnasium —
    the node positions and velocities a graph policy builds its edges from.

    ## Perturbations

    ``perturbations={...}`` (docs/perturbations.md): agents that fail
    (``failed_fraction``, ``failure_mode`` ``"passive"``/``"removed"``/``"frozen"``,
    ``failure_time``), are absent (``absent_fraction``) or join (``join_fraction``,
    ``join_time``), and ``obs_noise``, ``action_noise``, ``neighbor_dropout``; numbers
    or ``[low, high]`` ranges drawn per episode from the env's generator. A failed agent
    no longer acts: PettingZoo terminates it and it leaves ``env.agents`` (a joining
    agent enters it, with reward 0 for the step it joined in); the Gymnasium env ignores
    its actions. The statistics in the info are over the members. An agent does not
    observe its own failure.

    ## State accessors

    ``positions`` ``(N, d)``, ``velocities`` ``(N, d)``, ``goal`` ``(d,)`` (float64
    copies), ``active`` ``(N,)`` bool (the agents that act) and ``status`` ``(N,)`` int8
    (0 active, 1 failed, 2 frozen, 3 absent),
    on both envs (``gym.make(...).unwrapped.positions``; the AEC env's
    ``.unwrapped`` is the parallel env); defined after the first ``reset()``, else
    ``RuntimeError``.

    ## Version History

    * v0: initial release; ``dynamics`` (zone, piecewise, Lagrangian) and the informed
      and mill tasks (their own ids) added without changing the default
      social-potential navigation env.
"""


def _number(value: float) -> str:
    return f"{value:g}"


def env_doc_sections() -> dict[str, str]:
    """The env docstring's generated sections, from the package's tasks
    (:mod:`~swarm_envs.envs.task.shipped`): ``rewards`` (every reward term's sign, value and default
    weight per task), ``statistics`` (every statistic of ``info``) and ``episode_end``
    (each task's success and whether it terminates)."""
    from swarm_envs.envs.task.shipped import SHIPPED_TASKS
    from swarm_envs.envs.task.statistics import STATISTICS

    specs = SHIPPED_TASKS
    terms = list(dict.fromkeys(t.name for spec in specs for t in spec.reward_terms))
    by_name = {t.name: t for spec in specs for t in spec.reward_terms}
    weights = [spec.reward_defaults() for spec in specs]
    rows = [
        "| term | sign | value | " + " | ".join(f"``{s.name}``" for s in specs) + " |",
        "|---|---|---|" + "---|" * len(specs),
    ]
    for name in terms:
        term = by_name[name]
        sign = "+" if term.sign > 0 else "−"
        cells = " | ".join(_number(w[name]) for w in weights)
        rows.append(f"| ``{name}`` | {sign} | {term.doc} | {cells} |")
    rewards = (
        "Cooperative: every agent receives its swarm's reward each step, ``r = Σ sign · "
        "w · value`` over the task's terms, with the weights ``w`` of ``reward`` in the "
        "config (by term name; the columns: each task's defaults)\n\n" + "\n".join(rows)
    )
    statistics = "\n".join(f"- ``{s.name}``: {s.doc}" for s in STATISTICS)
    ends = []
    for spec in specs:
        success = spec.success_doc or (
            "at least ``success_fraction`` of the members are within ``goal_radius`` of "
            "the goal at once"
        )
        how = "terminated on success" if spec.terminates_on_success else "never terminated"
        ends.append(f"- ``{spec.name}``: {how}; success: {success}.")
    return {"rewards": rewards, "statistics": statistics, "episode_end": "\n".join(ends)}


def _indented(text: str) -> str:
    return text.replace("\n", "\n    ")


SWARM_NAV_DOC = _SWARM_NAV_DOC
for _key, _text in env_doc_sections().items():
    SWARM_NAV_DOC = SWARM_NAV_DOC.replace("{" + _key + "}", _indented(_text))


#: The info keys that ``info_kinematics=True`` adds (float32, in world units).
KINEMATICS_INFO_KEYS = ("pos", "vel", "goal_offset")


def _check_info_kinematics(value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"info_kinematics must be True or False, got {value!r}")
    return bool(value)


def _check_render_mode(render_mode: str | None) -> str | None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}")
    return render_mode


class SwarmNavParallelEnv(SwarmState, Rendering, ParallelEnv):
    __doc__ = "PettingZoo ParallelEnv of SwarmNav (the source of truth).\n" + SWARM_NAV_DOC

    metadata: ClassVar[dict[str, Any]] = {
        "name": "swarm_nav_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": 20,
        "is_parallelizable": True,
    }

    #: The constructor's own keyword arguments, besides the config fields.
    KEYWORDS: ClassVar[tuple[str, ...]] = (
        "config",
        "render_mode",
        "max_cycles",
        "info_kinematics",
    )

    def __init__(
        self,
        config: str | None = None,
        render_mode: str | None = None,
        max_cycles: int | None = None,
        info_kinematics: bool = False,
        **kwargs: Any,
    ) -> None:
        if max_cycles is not None:
            kwargs["max_steps"] = max_cycles
        self.cfg = make_config(
            config, kwargs, owner="SwarmNavParallelEnv()", keywords=self.KEYWORDS
        )
        self.render_mode = _check_render_mode(render_mode)
        self.info_kinematics = _check_info_kinematics(info_kinematics)
        self.core = make_core(self.cfg, batch=1)
        n, d = self.cfg.n_agents, self.cfg.dim
        self.possible_agents = [f"agent_{i}" for i in range(n)]
        self.agents: list[str] = []
        self._agent_index = {a: i for i, a in enumerate(self.possible_agents)}
        obs_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (self.core.obs_dim,), np.float32)
        act_space = spaces.Box(-1.0, 1.0, (d,), np.float32)
        self.observation_spaces = dict.fromkeys(self.possible_agents, obs_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, act_space)
        #: The space of :meth:`state`: every agent's observation, concatenated.
        self.state_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (n * self.core.obs_dim,), np.float32)
        self._np_random, _ = seeding.np_random(None)
        self._needs_reset = True

    @property
    def max_cycles(self) -> int:
        """Episode length before truncation (``max_steps`` of the config)."""
        return self.cfg.max_steps

    @max_cycles.setter
    def max_cycles(self, value: int) -> None:
        self.cfg = dataclasses.replace(self.cfg, max_steps=value)
        self.core.cfg = self.cfg

    def observation_space(self, agent: str) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self.action_spaces[agent]

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """Start an episode; ``options`` is ``None`` or a dict, whose entries are not read."""
        seed = check_seed(seed)
        check_reset_options(options)
        if seed is not None:
            self._np_random, _ = seeding.np_random(seed)
        self.core.reset(self._np_random)
        self._has_state = True
        active = self._status() == ACTIVE
        self.agents = [a for a, on in zip(self.possible_agents, active, strict=True) if on]
        self._needs_reset = False
        obs = self.core.observe()[0]
        stats = {k: float(v[0]) for k, v in self.core.stats().items()}
        self._after_reset_render()
        return (
            {a: obs[i] for i, a in enumerate(self.agents)},
            self._agent_infos(self.agents, stats),
        )

    def _agent_infos(self, agents: list[str], stats: dict[str, float]) -> dict[str, dict]:
        """Each agent's info: the statistics, plus its kinematics if ``info_kinematics``."""
        if not self.info_kinematics:
            return {a: dict(stats) for a in agents}
        kin = self._kinematics()
        infos = {}
        for a in agents:
            i = self._agent_index[a]
            infos[a] = {**stats, **{k: value[i] for k, value in kin.items()}}
        return infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if self._needs_reset or not self.agents:
            raise RuntimeError("step() called before reset() or after the episode ended")
        live = set(self.agents)
        if not (isinstance(actions, Mapping) and actions.keys() == live):
            unknown, missing = set(actions) - live, live - set(actions)
            if unknown or missing:
                raise ValueError(
                    f"actions must hold exactly the live agents; missing {sorted(missing)}, "
                    f"unknown {sorted(unknown)}"
                )
        n, d = self.cfg.n_agents, self.cfg.dim
        agents = self.agents
        if len(agents) == n:
            stacked = stack_agent_actions(actions, self.possible_agents, d)  # docs/inputs.md
        else:  # agents that do not act take no action (the core ignores theirs)
            stacked = np.zeros((n, d))
            rows = [self._agent_index[a] for a in agents]
            stacked[rows] = stack_agent_actions(actions, agents, d)
        reward, terminated, truncated, stats = self.core.step(stacked.reshape(1, n, d))
        obs = self.core.observe()[0]
        r, term, trunc = float(reward[0]), bool(terminated[0]), bool(truncated[0])
        info = {k: float(v[0]) for k, v in stats.items()}
        active = self._status() == ACTIVE
        if len(agents) == n and active.all():  # every agent acted and acts on
            ended, joined = [], []
        else:
            live = set(agents)
            ended = [a for a in agents if not active[self._agent_index[a]]]  # failed, removed
            acting = zip(self.possible_agents, active, strict=True)
            joined = [a for a, on in acting if on and a not in live]
            agents = agents + joined
        if agents == self.possible_agents:  # every agent, in the rows' order
            agent_obs = dict(zip(agents, obs, strict=True))
        else:
            agent_obs = {a: obs[self._agent_index[a]] for a in agents}
        result = (
            agent_obs,
            dict.fromkeys(agents, r),
            dict.fromkeys(agents, term),
            dict.fromkeys(agents, trunc),
            self._agent_infos(agents, info),
        )
        for a in ended:
            result[2][a] = True
        for a in joined:  # it took no part in this step
            result[1][a] = 0.0
        if term or trunc:
            self.agents = []
            self._needs_reset = True
        elif ended:
            gone = set(ended)
            self.agents = [a for a in agents if a not in gone]
        else:
            self.agents = agents
        self._after_step_render()
        return result

    def state(self) -> np.ndarray:
        """Global state for a centralised critic: every agent's observation, concatenated
        in agent order, ``(N · obs_dim,)`` float32 in :attr:`state_space`."""
        return self.core.observe()[0].reshape(-1)


# gymnasium types Env.render's frames with a type variable that no concrete frame type
# (Rendering.render's array) matches.
class SwarmNavEnv(SwarmState, Rendering, gymnasium.Env):  # type: ignore[misc]
    __doc__ = "Gymnasium SwarmNav with one central controller for the whole swarm.\n" + (
        SWARM_NAV_DOC
    )

    # A class constant; gymnasium annotates it as an instance variable of Env.
    metadata: ClassVar[dict[str, Any]] = {  # type: ignore[misc]
        "render_modes": list(RENDER_MODES),
        "render_fps": 20,
    }

    #: The constructor's own keyword arguments, besides the config fields.
    KEYWORDS: ClassVar[tuple[str, ...]] = ("config", "render_mode", "info_kinematics")

    def __init__(
        self,
        config: str | None = None,
        render_mode: str | None = None,
        info_kinematics: bool = False,
        **kwargs: Any,
    ) -> None:
        self.cfg = make_config(config, kwargs, owner="SwarmNavEnv()", keywords=self.KEYWORDS)
        self.render_mode = _check_render_mode(render_mode)
        self.info_kinematics = _check_info_kinematics(info_kinematics)
        self.core = make_core(self.cfg, batch=1)
        n, d = self.cfg.n_agents, self.cfg.dim
        size = n * self.core.obs_dim + (n if self.cfg.observe_status else 0)
        self.observation_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (size,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (n * d,), np.float32)
        self._needs_reset = True

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Start an episode; ``options`` is ``None`` or a dict, whose entries are not read."""
        seed = check_seed(seed)  # gymnasium itself refuses numpy integers
        check_reset_options(options)
        super().reset(seed=seed)
        self.core.reset(self.np_random)
        self._has_state = True
        self._needs_reset = False
        self._after_reset_render()
        return self._observe(), self._info(self.core.stats())

    def _observe(self) -> np.ndarray:
        """Every agent's observation, concatenated; with ``observe_status``, then every
        agent's flag (1 active, 0 not)."""
        obs = self.core.observe().reshape(-1)
        if not self.cfg.observe_status:
            return obs
        return np.concatenate([obs, (self._status() == ACTIVE).astype(np.float32)])

    def _info(self, stats: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """The statistics, plus every agent's kinematics ``(N, d)`` if ``info_kinematics``."""
        info: dict[str, Any] = {k: float(v[0]) for k, v in stats.items()}
        if self.info_kinematics:
            info.update(self._kinematics())
        return info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._needs_reset:
            raise RuntimeError(
                "step() called before reset() or after the episode ended (terminated or "
                "truncated); call reset()"
            )
        n, d = self.cfg.n_agents, self.cfg.dim
        # The rule of docs/inputs.md; the core refuses NaN/inf and clips.
        a = as_action(action, (n * d,)).reshape(1, n, d)
        reward, terminated, truncated, stats = self.core.step(a)
        self._needs_reset = bool(terminated[0] or truncated[0])
        obs = self._observe()
        self._after_step_render()
        return (
            obs,
            float(reward[0]),
            bool(terminated[0]),
            bool(truncated[0]),
            self._info(stats),
        )
