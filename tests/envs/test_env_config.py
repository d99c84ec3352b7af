import pytest

from wmdist.envs import EnvConfig


def test_defaults_validate():
    cfg = EnvConfig().validate()
    assert cfg.id == "gym:CartPole-v1" and cfg.frame_skip == 4 and cfg.max_episode_frames == 108000


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("frame_skip", 0, "env.frame_skip must be >= 1, got 0"),
        ("sticky_actions", 1.5, "env.sticky_actions must be <= 1.0, got 1.5"),
        ("action_repeat", True, "env.action_repeat must be an int, got True"),
        ("pixels", "yes", "env.pixels must be a bool, got 'yes'"),
        ("time_limit", -3, "env.time_limit must be >= 0, got -3"),
    ],
)
def test_bad_values_are_one_line_errors(field, value, message):
    cfg = EnvConfig()
    setattr(cfg, field, value)
    with pytest.raises(ValueError) as err:
        cfg.validate()
    assert str(err.value) == message


def test_time_limit_none_means_family_default():
    cfg = EnvConfig(time_limit=None).validate()
    assert cfg.max_steps(500) == 500
    assert EnvConfig(time_limit=7).max_steps(500) == 7
