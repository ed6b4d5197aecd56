"""SGN's success rule (`DoomEnv._reached`, and the House's on its collision boxes) with more than one object within
reach (issue 66): the episode ends at the nearest object in reach, and succeeds only if that one is the target, not
whenever the target is in reach too. The agent's pose and the objects' points are set by hand on an env whose engine
never starts (`_reached` reads only them), so every distance below is exact."""

from types import SimpleNamespace

import numpy as np
import pytest

from emml.config.schema import DoomConfig, HouseConfig
from emml.envs.doom import DoomEnv
from tests.conftest import SMOKE

REACH = DoomConfig().reach_distance  # 40 map units, centre to centre


def _doom(distances: list[float], target: int) -> DoomEnv:
    """A Doom env (no engine) with the agent at the origin and object i at ``distances[i]`` along the x axis."""
    env = DoomEnv(**SMOKE)
    env.pose = (0.0, 0.0, 0.0)
    env.positions = [(d, 0.0) for d in distances]
    env.episode = SimpleNamespace(target=target)
    return env


@pytest.mark.parametrize(
    "distances, target, reached",
    [
        ([30.0, 20.0, 200.0, 300.0, 400.0], 0, False),  # the target in reach, another nearer: the nearer one decides
        ([20.0, 30.0, 200.0, 300.0, 400.0], 0, True),  # the target the nearer of two in reach
        ([200.0, 35.0, 39.0, 300.0, 400.0], 2, False),  # both in reach, the target the farther by 4 units
        ([200.0, 45.0, 35.0, 300.0, 400.0], 2, True),  # the other one just out of reach
        ([200.0, 300.0, REACH, 400.0, 500.0], 2, True),  # at reach_distance exactly: reached
        ([200.0, 300.0, REACH, REACH - 1, 500.0], 2, False),  # one unit nearer, not the target
        ([200.0, 300.0, REACH + 1, 41.0, 500.0], 2, None),  # nothing in reach: the episode goes on
    ],
)
def test_the_nearest_object_in_reach_decides(distances, target, reached):
    assert _doom(distances, target)._reached() is reached


def test_the_distance_is_the_straight_line_to_the_centre():
    """In two dimensions: (24, 32) is 40 away (in reach), (30, 30) is 42.4 (not), whatever the angle the agent faces."""
    env = _doom([0.0] * 5, 0)
    env.pose = (100.0, 100.0, 90.0)
    env.positions = [(124.0, 132.0), (70.0, 70.0), (400.0, 0.0), (0.0, 400.0), (400.0, 400.0)]
    assert env._reached() is True
    env.episode = SimpleNamespace(target=1)
    assert env._reached() is False  # the target 42.4 away: out of reach, the other in reach decides
    env.positions[0] = (131.0, 131.0)  # 43.8 away: now nothing is in reach
    assert env._reached() is None


def test_the_house_reaches_the_nearest_piece_too():
    """The House on its collision-box gaps (`HouseEnv.gaps`): the nearest piece in reach decides; either referent
    of a sentence with two (both sofas) is a success."""
    from emml.envs.house import HouseEnv

    env = HouseEnv(HouseConfig(tasks="sgn"))
    reach = env.cfg.reach_distance
    far = 500.0

    def reached(gaps: list[float], targets: tuple[int, ...]):
        env.gaps = lambda: np.array(gaps)
        env.targets = targets
        return env._reached()

    assert reached([reach - 2, reach - 1, far, far, far, far, far], (1,)) is False  # the target in reach, not nearest
    assert reached([reach - 1, reach - 2, far, far, far, far, far], (1,)) is True
    assert reached([reach - 1, reach - 2, far, far, far, far, far], (0, 3)) is False
    assert reached([reach - 2, far, far, reach - 1, far, far, far], (0, 3)) is True  # either referent
    assert reached([reach + 1, far, far, far, far, far, far], (0,)) is None


class _Moves:
    """Stands in for the engine: each action moves the agent to the next point of ``path`` (what `_read_state`
    would read back from ViZDoom), and records the buttons it was given."""

    def __init__(self, env: DoomEnv, path: list[tuple[float, float]]):
        self.env, self.path, self.buttons = env, list(path), []
        self.game = SimpleNamespace(make_action=lambda buttons, tics: self.buttons.append((buttons, tics)))

    def read_state(self):
        x, y = self.path.pop(0)
        self.env.pose = (x, y, 0.0)


def _playing(positions, target: int, path, task: int = 0, **cfg) -> tuple[DoomEnv, _Moves]:
    """An SGN (task 0) or EQA (task 1) episode mid-way, the agent at the origin, the engine faked by `_Moves`."""
    env = DoomEnv(**{**SMOKE, **cfg})
    moves = _Moves(env, path)
    env._engine, env._read_state = moves, moves.read_state
    env.positions, env.pose = list(positions), (0.0, 0.0, 0.0)
    env.episode = SimpleNamespace(target=target, sentence=SimpleNamespace(text="go to the torch"), scene=list("abcde"))
    env.task_id, env.answer_id, env.t, env.ended = task, 3, 0, False
    env.frame, env.tokens, env.aux = np.zeros((3, 60, 108), np.uint8), np.zeros(10, np.int64), None
    env._dist = env._target_distance()
    return env, moves


FAR = [(0.0, 300.0), (300.0, 300.0), (-300.0, 300.0), (-300.0, -300.0)]


def test_the_sgn_reward_by_hand():
    """Target 100 ahead: a step to 30 pays -0.001 + 0.001 · (100 - 70); the next, to 65, reaches it (35 ≤ 40):
    -0.001 + 0.001 · (70 - 35) + 1, success, terminated. The shaping follows the distance's decrease, either sign."""
    c = DoomConfig().shaping_coef
    env, moves = _playing([(100.0, 0.0), *FAR], 0, [(30.0, 0.0), (65.0, 0.0)], shaping=True)
    _, r, term, trunc, info = env.step([0, 0])
    assert r == pytest.approx(-0.001 + c * 30, rel=1e-12) and not term and not trunc and not info["success"]
    _, r, term, trunc, info = env.step([0, 0])
    assert r == pytest.approx(-0.001 + c * 35 + 1.0, rel=1e-12) and term and not trunc and info["success"]
    assert [b for b, _ in moves.buttons] == [[1, 0], [1, 0]] and {t for _, t in moves.buttons} == {5}
    env, _ = _playing([(100.0, 0.0), *FAR], 0, [(-20.0, 0.0)], shaping=True)  # away from the target
    assert env.step([0, 0])[1] == pytest.approx(-0.001 - c * 20, rel=1e-12)


def test_the_wrong_object_pays_wrong_reward_and_no_shaping_when_off():
    """Another object reached first (30 away at the agent's new point, the target 80): -0.001 + wrong_reward, no
    success; shaping off: no distance term."""
    env, _ = _playing([(100.0, 0.0), (50.0, 0.0), *FAR[:3]], 0, [(20.0, 0.0)], shaping=False, wrong_reward=-0.5)
    _, r, term, _, info = env.step([0, 0])
    assert r == pytest.approx(-0.501, rel=1e-12) and term and not info["success"]


def test_an_eqa_answer_ends_the_episode_and_pays_only_when_right():
    env, moves = _playing([(100.0, 0.0), *FAR], 0, [], task=1)
    _, r, term, _, info = env.step([3, 3])  # answer word 3: the answer
    assert r == pytest.approx(1.0 - 0.001, rel=1e-12) and term and info["success"] and moves.buttons == []
    env, _ = _playing([(100.0, 0.0), *FAR], 0, [], task=1, wrong_reward=-0.25)
    _, r, term, _, info = env.step([3, 4])
    assert r == pytest.approx(-0.251, rel=1e-12) and term and not info["success"]


def test_an_episode_in_reach_of_nothing_is_truncated_at_max_steps():
    env, _ = _playing([(100.0, 0.0), *FAR], 0, [(1.0, 0.0), (2.0, 0.0)], max_steps=2, shaping=False)
    assert env.step([1, 0])[2:4] == (False, False)
    _, r, term, trunc, _ = env.step([2, 0])
    assert (term, trunc) == (False, True) and r == pytest.approx(-0.001, rel=1e-12)


def test_each_move_presses_its_buttons_and_only_an_eqa_answer_ends_without_moving():
    """forward [1, 0], left [0, -turn], right [0, turn], and in SGN 'answer' a step that does not move ([0, 0]); in
    EQA a move is a move (the episode goes on), the answer ends it."""
    env, moves = _playing([(100.0, 0.0), *FAR], 0, [(1.0, 0.0)] * 4)
    turn = env._turn
    for move in range(4):
        assert env.step([move, 0])[2:4] == (False, False)
    assert [b for b, _ in moves.buttons] == [[1, 0], [0, -turn], [0, turn], [0, 0]] and turn > 0
    env, moves = _playing([(100.0, 0.0), *FAR], 0, [(1.0, 0.0)], task=1)
    assert env.step([0, 3])[2:4] == (False, False) and moves.buttons == [([1, 0], 5)]


def test_steps_out_of_turn_and_bad_actions_are_refused_by_name():
    env, _ = _playing([(100.0, 0.0), *FAR], 0, [(65.0, 0.0)])
    refused = (
        r"^action \[7, 0\]: expected two integers \[move, word\], move in 0\.\.3 \(forward, left, right, answer\) "
        r"and word in 0\.\.21 \(a vocabulary index, read on 'answer'\)$"
    )
    with pytest.raises(ValueError, match=refused):
        env.step([7, 0])
    assert env.step([0, 0])[2]  # reached: terminated
    with pytest.raises(RuntimeError, match=r"^step\(\) after the episode ended \(terminated or truncated\): call"):
        env.step([0, 0])
    env, _ = _playing([(100.0, 0.0), *FAR], 0, [(1.0, 0.0)], max_steps=1)
    assert env.step([1, 0])[3]  # truncated: ended too
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step([1, 0])
    fresh = DoomEnv(**SMOKE)
    with pytest.raises(RuntimeError, match=r"^call reset\(\) before step\(\)$"):
        fresh.step([0, 0])
    env._engine = None  # as close() leaves it
    with pytest.raises(RuntimeError, match=r"^step\(\) after close\(\): this env is closed; make a new one$"):
        env.step([0, 0])
