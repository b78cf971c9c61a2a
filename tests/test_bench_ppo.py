"""The PPO benchmark refuses a batch shape PPO cannot run before anything is built or compiled
(its figures are measurements, not asserted: benchmarks/h200/ppo_pnnl300.json)."""
import pytest

from experiments.bench.ppo import main, shape_config


def test_shape_is_environments_and_minibatches():
    config = shape_config("500:400")
    assert (config.envs, config.minibatches, config.batch // config.minibatches) == (500, 400, 125)


@pytest.mark.parametrize("shape, why", [("500:32", "divisor of envs·rollout_steps = 50000"),
                                        ("40", "ENVS:MINIBATCHES"), ("0:1", "envs = 0")])
def test_a_shape_ppo_refuses_is_an_error_of_the_flag(shape, why, capsys, tmp_path):
    with pytest.raises(SystemExit):
        main(["--shapes", "40:32", shape, "--out", str(tmp_path / "ppo.json")])
    err = capsys.readouterr().err
    assert "argument --shapes" in err and repr(shape) in err and why in err
    assert not (tmp_path / "ppo.json").exists()
