import pytest

from wmdist.envs import EnvConfig, check_id, env_spec, list_families, make_env


def test_list_families_names_every_prefix_with_examples():
    fams = dict(list_families())
    assert set(fams) == {"gym", "dmc", "atari", "minatar", "board", "carracing", "vizdoom", "nav"}
    assert "dmc:walker-walk" in fams["dmc"] and "atari:Pong" in fams["atari"] and "minatar:Breakout" in fams["minatar"]


@pytest.mark.parametrize(
    "bad, closest",
    [
        ("dmc:walker-wlak", "dmc:walker-walk"),
        ("gym:CartPol-v1", "gym:CartPole-v1"),
        ("CartPole-v1", "gym:CartPole-v1"),  # missing family prefix
        ("atari:pong", "atari:Pong"),
        ("board:tictacto", "board:tictactoe"),
    ],
)
def test_unknown_id_is_one_line_naming_closest_match(bad, closest):
    with pytest.raises(ValueError) as err:
        check_id(bad)
    msg = str(err.value)
    assert "\n" not in msg
    assert f"unknown env id '{bad}'" in msg and f"closest match: '{closest}'" in msg
    for fam in ("gym:", "dmc:", "atari:", "board:"):
        assert fam in msg


def test_known_ids_pass_through():
    for good in ("gym:CartPole-v1", "dmc:cartpole-balance", "atari:Pong", "board:connect4"):
        assert check_id(good) == good


def test_make_env_rejects_bad_input():
    with pytest.raises(ValueError, match="unknown env id 'gym:Nope-v0'"):
        make_env(EnvConfig(id="gym:Nope-v0"), seed=0)
    with pytest.raises(ValueError, match="env.pixels applies to dmc ids only"):
        make_env(EnvConfig(pixels=True), seed=0)
    with pytest.raises(ValueError, match="seed must be an int >= 0"):
        make_env(EnvConfig(), seed=-1)
    with pytest.raises(ValueError, match="action_repeat must be 1 for board games"):
        make_env(EnvConfig(id="board:tictactoe", action_repeat=2), seed=0)


def test_env_spec_matches_a_built_env():
    cfg = EnvConfig(id="gym:Pendulum-v1", action_repeat=2)
    spec = env_spec(cfg)
    assert spec.action_low == (-2.0,) and spec.action_high == (2.0,)
    assert spec.max_episode_steps == 100  # 200 registered steps / action repeat 2
    with make_env(cfg, seed=0) as env:
        assert env.spec == spec
