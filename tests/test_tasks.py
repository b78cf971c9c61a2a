"""Task sets of the study, task configuration files, and the evaluation command."""
from __future__ import annotations

import json

import pytest

from jaxgrid import cases
from jaxgrid.env import EnvParams
from jaxgrid.tasks import TaskSpec, read_task_config, task_batch, task_set


@pytest.mark.parametrize("name, size", [("ieee39_train", 9), ("ieee39_test", 120),
                                        ("ieee300_train", 27), ("ieee300_test", 170)])
def test_named_task_sets_have_the_study_sizes(name, size):
    specs = task_set(name)
    assert len(specs) == size and len(set(specs)) == size
    assert len(task_set(name, operating_points=(0.9, 1.0, 1.1))) == 3 * size


def test_zero_duration_means_no_fault():
    assert TaskSpec(4, 0.0).event() is None
    event = TaskSpec(4, 0.08).event()
    assert (event.bus, event.start, event.duration) == (4, 1.0, 0.08)


def test_unknown_set_and_mixed_operating_points_are_named():
    with pytest.raises(ValueError, match="unknown task set 'ieee14_train'"):
        task_set("ieee14_train")
    model = cases.load("ieee39_fidvr").compile()
    with pytest.raises(ValueError, match=r"operating points \[0.9, 1.0\]"):
        task_batch(model, task_set("ieee39_train", (0.9, 1.0)))
    batch = task_batch(model, task_set("ieee39_train"))
    assert batch.fault_bus.shape == (9,)


def test_reads_the_pnnl_39_bus_task_file(shared_cases):
    config = read_task_config(shared_cases / "ieee39/IEEE39_RL_loadShedding_3motor_continuous_"
                              "reducedActionRange_gp.json")
    # The study's 39-bus numbers are the defaults, except that this GridPACK-era file judges
    # recovery after 8 s (the original file, below, after 4 s).
    assert config.params == EnvParams(recovery_time=8.0)
    assert config.observed_buses == (504, 507, 508, 518)
    assert config.action_buses == (504, 507, 518)
    assert (config.agent_dt, config.history) == (0.1, 10)
    assert config.fault_buses == (4, 15, 21) and config.fault_durations == (0.0, 0.05, 0.08)
    assert len(config.tasks()) == 9
    original = read_task_config(shared_cases / "ieee39/IEEE39_RL_loadShedding_3motor_continuous.json")
    assert original.params == EnvParams(action_low=-1.0)
    assert original.fault_starts == (0.05,) and original.fault_buses == (4,)
    assert original.observed_buses == cases.load("ieee39_fidvr").observed_buses


def test_reads_the_pnnl_300_bus_zone_scope(shared_cases):
    path = shared_cases / ("ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_"
                           "multipfcases_training_gp.json")
    with pytest.raises(ValueError, match="needs the case"):
        read_task_config(path)
    study = cases.load("ieee300_fidvr")
    config = read_task_config(path, study.case)
    assert config.params.c_voltage == 30.0 and config.params.unstable_penalty == 10000.0
    assert (config.params.recovery_level, config.params.recovery_time) == (0.9, 5.0)
    assert len(config.action_buses) == 34
    assert set(config.observed_buses) == set(study.observed_buses)


def test_own_format_round_trip_and_errors(tmp_path):
    path = tmp_path / "task.json"
    path.write_text(json.dumps({"observed_buses": [4, 504], "action_buses": [504],
                                "fault_buses": [4], "fault_durations": [0.05],
                                "c_voltage": 30.0}))
    config = read_task_config(path)
    assert config.params == EnvParams(c_voltage=30.0) and config.action_buses == (504,)
    path.write_text(json.dumps({"observed_buses": [4], "action_buses": ["Bus504"],
                                "fault_buses": [4], "fault_durations": [0.05], "c_volt": 1}))
    with pytest.raises(ValueError, match=r"task.json: unknown keys \['c_volt'\]"):
        read_task_config(path)
    path.write_text(json.dumps({"observed_buses": ["Node4"]}))
    with pytest.raises(ValueError, match="observed_buses: 'Node4' is not a bus"):
        read_task_config(path)
