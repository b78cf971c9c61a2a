"""Task sets, and the PNNL task and simulation configuration files read as written."""
from __future__ import annotations

import json

import pytest

from jaxgrid.study.pnnl import read_sim_config, read_task_config
from jaxgrid.tasks import TaskSet, TaskSpec

PNNL_TASK_FILES = [  # every task JSON under ../shared/cases
    "ieee39/IEEE39_RL_loadShedding_3motor_continuous.json",
    "ieee39/IEEE39_RL_loadShedding_3motor_continuous_reducedActionRange_gp.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_FNN_multipfcases_testing_gp.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_FNN_multipfcases_training_gp.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_FNN_multipfcases_training_gp_1fault.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_FNN_multipfcases_training_gp_2fault.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_FNN_multipfcases_training_gp_3duration"
    ".json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_multipfcases_testing_gp.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_multipfcases_training_gp.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_lessfaultbuses_moreActionBuses_"
    "multipfcases.json",
    "ieee300/IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_morefaultbuses_moreActionBuses_"
    "testing.json",
    "activsg2000/Equiv_Texas2000_RL_loadShedding_zone3.json",
    "activsg2000/Texas2000_RL_loadShedding_zone3.json",
]
PNNL_SIM_FILES = ["ieee39/IEEE39_dyn_config.json", "ieee300/IEEE300_dyn_config.json",
                  "activsg2000/Texas2000_dyn_config.json"]


def test_task_set_is_the_product_grid_point_outermost():
    tasks = TaskSet((4, 15), (0.0, 0.05, 0.08), (0.5, 1.0))
    specs = tasks.specs(3)
    assert len(specs) == 3 * 2 * 2 * 3 and len(set(specs)) == len(specs)
    assert specs[0] == TaskSpec(4, 0.0, 0.5, 0) and specs[-1] == TaskSpec(15, 0.08, 1.0, 2)
    assert [s.operating_point for s in TaskSet((4,), (0.1,), operating_points=(2, 0))
            .specs(3)] == [2, 0]
    with pytest.raises(ValueError, match=r"operating_points = \[3\]: the study has 3 "):
        TaskSet((4,), (0.1,), operating_points=(3,)).specs(3)
    with pytest.raises(ValueError, match="fault_buses is empty"):
        TaskSet((), (0.1,))


def test_zero_duration_means_no_fault():
    assert TaskSpec(4, 0.0).event() is None
    event = TaskSpec(4, 0.08).event()
    assert (event.bus, event.start, event.duration) == (4, 1.0, 0.08)


@pytest.mark.parametrize("name", PNNL_TASK_FILES)
def test_every_pnnl_task_file_is_read_with_every_key_accounted_for(shared_cases, name):
    config = read_task_config(shared_cases / name)
    assert config.unknown == (), "every key of the study files is understood"
    data = json.loads((shared_cases / name).read_text())
    assert config.params["c_voltage"] == data["observationWeight"]
    assert config.params["unstable_penalty"] == -data["unstableReward"]
    assert config.fault_durations == tuple(data["faultDurationCandidates"])
    assert len(config.notes) == sum(k in data for k in ("version", "studyCaseFolder",
                                                          "actionLevels"))


def test_the_39_bus_files_read_as_written(shared_cases):
    original = read_task_config(shared_cases / PNNL_TASK_FILES[0])
    assert (original.params["action_low"], original.params["action_high"]) == (-1.0, 0.0)
    assert original.fault_starts == (0.05,) and original.fault_buses == ("Bus4",)
    assert original.observed == ("Bus4", "Bus504", "Bus7", "Bus507", "Bus8", "Bus508",
                                 "Bus18", "Bus518")
    assert (original.history, original.agent_dt, original.include_action_status) == (10, 0.1,
                                                                                      True)
    gridpack = read_task_config(shared_cases / PNNL_TASK_FILES[1])
    assert gridpack.params["recovery_time"] == 8.0 and gridpack.action_p_mw == (200.0, 93.52,
                                                                                63.2)
    zone = read_task_config(shared_cases / PNNL_TASK_FILES[8])
    assert (zone.observation_scope, zone.observed, zone.observed_min_kv) == ("Zone", ("1",), 60.0)
    assert zone.counts == {"ObservationSelfZoneVoltNum": 142, "ObservationSelfZoneLowVoltNum": 34,
                           "ObservationOtherZoneVoltNum": 0, "actionLoadSelfZoneNum": 34,
                           "actionLoadOtherZoneNum": 0}


@pytest.mark.parametrize("name", PNNL_SIM_FILES)
def test_every_pnnl_simulation_file_is_read(shared_cases, name):
    config = read_sim_config(shared_cases / name)
    data = json.loads((shared_cases / name).read_text())
    assert (config.dt, config.t_end) == (data["simuTimeStepSec"], data["totalSimuTimeSec"])
    assert config.unknown == () and config.fault_r is None, "zLG = 0: a bolted fault"
    assert any("referenceGeneratorId" in n for n in config.notes)


@pytest.mark.parametrize("change, message", [
    ({"observationWeight": "260"}, r"observationWeight = '260': must be a number"),
    ({"historyObservationSize": 2.5}, r"historyObservationSize = 2.5: must be an integer"),
    ({"actionScopeAry": "Bus504"}, r"actionScopeAry = 'Bus504': must be a non-empty list"),
    ({"actionValueRanges": [[-1, 0], [-0.2, 0], [-1, 0]]}, "one range shared by every"),
    ({"actionSpaceType": "discrete"}, r"actionSpaceType = 'discrete': must be one of"),
    ({"observationStateTypes": ["voltageMag", "frequency"]}, "observationStateTypes"),
    ({"includeActionStatusInObservations": "yes"}, "must be true or false"),
])
def test_bad_task_values_name_the_file_key_and_value(shared_cases, tmp_path, change, message):
    data = json.loads((shared_cases / PNNL_TASK_FILES[0]).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, **change}))
    with pytest.raises(ValueError, match=f"task.json: .*{message}"):
        read_task_config(path)


def test_unknown_keys_are_reported_not_dropped(shared_cases, tmp_path):
    data = json.loads((shared_cases / PNNL_TASK_FILES[0]).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, "rewardShaping": 2}))
    assert read_task_config(path).unknown == ("rewardShaping",)
    with pytest.raises(ValueError, match="missing key 'faultBusCandidates'"):
        path.write_text(json.dumps({k: v for k, v in data.items()
                                    if k != "faultBusCandidates"}))
        read_task_config(path)
