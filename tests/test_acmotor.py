"""ACMTBLU1 against its specification (shared/specs/acmtblu1.md §11), on a one-bus test system.

The system: an infinite bus (GENCLS, H = 0) feeding bus 2 through X = 0.05 p.u.; bus 2
carries a 50 MW static load record '1' and a 100 MW record '2' with the motor (the PNNL
39-bus ACMTBLU1 data). Whole runs check the power-flow point and the stall timer under
bolted faults; the per-step logic is driven with prescribed voltages through
`Acmtblu1.update`, which is what the simulator calls after each accepted step.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import raw_v33
from experiments.simulate import main
from jaxgrid.compile import CompileOptions, compile_model, with_precision
from jaxgrid.dynamics import load_injection
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.models.acmotor import Acmtblu1, MotorOptions
from jaxgrid.models.base import ModelError
from jaxgrid.simulate import FaultEvent, make_task, simulate, simulate_batch, stack_tasks
from jaxgrid.steppers import shed

DT = 0.002  # s, the PNNL 39-bus step
# The PNNL 39-bus ACMTBLU1 CONs (IEEE39bus_3AC.dyr), in CON order.
CONS = [0.033, 0.40, 0.02, 0.05, 0, 0.98, 0.5, 0.124, 0.114, 0.3, 0.0, 1.0, 6.0, 2.0, 12.0,
        3.2, 11.0, 2.5, 0.86, 0.20, 0.95, 1.0, -3.3, 0.5, 0.4, 0.65, 0.55, 15, 1.0, 2.9, 0.0,
        0.5, 0.02, 0.90, 5.0]
C = {con.name: value for con, value in zip(Acmtblu1.cons, CONS)}
GS = C["rstall"] / (C["rstall"] ** 2 + C["xstall"] ** 2)  # 4.3705 (spec §4)
BS = C["xstall"] / (C["rstall"] ** 2 + C["xstall"] ** 2)

BUSES = ("1,'INF', 230.0, 3, 1, 1, 1, 1.00, 0.0\n"
         "2,'LOAD', 230.0, 1, 1, 1, 1, 1.00, 0.0\n")
LOADS = ("2,'1', 1, 1, 1, 50.0, 10.0, 0.0, 0.0, 0.0, 0.0, 1\n"
         "2,'2', 1, 1, 1, 100.0, 20.0, 0.0, 0.0, 0.0, 0.0, 1\n")
GEN = ("1,'1', 0.0, 0.0, 9999.0, -9999.0, 1.00, 0, 1000.0, 0.0, 0.01, 0.0, 0.0, 1.0, 1, "
       "100.0, 9999.0, -9999.0\n")
LINE = "1, 2,'1', 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1\n"


def write_system(folder: Path, cons=CONS, load_id="2", n_values=None) -> tuple[Path, Path]:
    """RAW and DYR files of the one-bus test system; `n_values` overrides the CON count NC."""
    raw = folder / "one_bus.raw"
    raw.write_text(raw_v33(BUSES, LOADS, GEN, LINE))
    dyr = folder / "one_bus.dyr"
    values = ", ".join(f"{c:g}" for c in cons)
    nc = len(cons) if n_values is None else n_values
    dyr.write_text("1 'GENCLS' 1 0.0 0.0 /\n"
                   f"2, 'USRLOD', {load_id}, 'ACMTBLU1', 12, 1, 0, {nc}, 9, 29, 16, {values} /\n")
    return raw, dyr


WHOLE_RECORD = MotorOptions(share_mode="psse_load_record")  # the spec's tests: 100 MW motor


def build(folder: Path, **kwargs):
    raw, dyr = write_system(folder, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no InitWarning: the motor starts at rest
        return compile_model(read_raw(raw), read_dyr(dyr),
                             CompileOptions(precision="float64", motors=WHOLE_RECORD))


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    return build(tmp_path_factory.mktemp("one_bus"))


@pytest.fixture(scope="module")
def motor(system):
    """(params, initial flags) of the one motor, float64 arrays of shape (1,)."""
    group = system.loads[0]
    return group.params, system.initial.load_flags[0]


def drive(params, flags, volts, dt=DT):
    """Prescribed |V| (n,) p.u. at angle 0, one accepted step each: (flags, S drawn (n,)),
    in the precision of `params` (float64 or float32).

    flags: {flag: (n,)} after each step; S: complex power (p.u. system base) drawn at V.
    """
    def step(z, pair):
        v, v_old = pair
        z = Acmtblu1.update(params, {}, z, v[None], v_old[None], dt)
        s = v * jnp.conj(Acmtblu1.current(params, {}, z, v[None]))
        return z, (z, s[0])

    x64 = np.asarray(params["tstall"]).dtype == np.float64  # else the float32 simulator's
    with jax.enable_x64(x64):
        volts = jnp.asarray(volts, dtype=jnp.float64 if x64 else jnp.float32)
        pairs = (volts.astype(jnp.complex128 if x64 else jnp.complex64),
                 jnp.concatenate([volts[:1], volts[:-1]]))
        _, (trace, s) = jax.lax.scan(step, jax.tree.map(jnp.asarray, flags), pairs)
        return {k: np.asarray(v)[:, 0] for k, v in trace.items()}, np.asarray(s)


def drawn_power(params, flags, v: complex) -> complex:
    """Complex power (p.u. system base) the motor draws at bus voltage v, float64."""
    with jax.enable_x64(True):
        return complex(v * np.conj(np.asarray(Acmtblu1.current(params, {}, flags,
                                                                np.array([v])))[0]))


def held(*segments, dt=DT):
    """Voltage samples, one per step of dt s, from (level p.u., seconds) segments."""
    return np.concatenate([np.full(int(round(t / dt)), v) for v, t in segments])


def test_steady_state_at_the_power_flow_point(system):
    traj = simulate(system, 10.0, DT, decimation=250)
    bus = system.bus_index(2)
    assert np.abs(np.asarray(traj.vm)[:, bus] - abs(system.v0[bus])).max() < 1e-9
    for name, values in traj.load_flags[0].items():
        if name not in Acmtblu1.relaxing:
            assert np.ptp(np.asarray(values)) < 1e-9, f"{name} moves in a flat run"
    # a running motor adds no heat (heating "stalled"): θ cools from I0²·Rstall with Tth
    theta = np.asarray(traj.load_flags[0]["theta_a"])[:, 0]
    expected = theta[0] * np.exp(-np.asarray(traj.t) / C["tth"])
    assert theta == pytest.approx(expected, rel=1e-9)
    group, flags = system.loads[0], system.initial.load_flags[0]
    v0 = system.v0[bus]
    s = drawn_power(group.params, flags, v0)
    # The motor takes the whole 100 MW record, at CompPF 0.98 (spec §3-4).
    assert s.real == pytest.approx(1.0, abs=1e-12)
    assert s.imag == pytest.approx(math.tan(math.acos(0.98)), abs=1e-12)
    assert any("100.00 MW motor (psse_load_record)" in n for n in system.notes)


def test_characteristic_follows_section_5(motor):
    params, flags = motor
    v0 = float(flags["vm"][0])
    q0 = math.tan(math.acos(0.98)) - 6.0 * (v0 - 0.86) ** 2  # "v0" curve offsets
    vx = math.sqrt(1.0 / GS)  # reference running-1 rule with Kp1 = 0: 0.478 (spec §4)
    assert float(params["vx"][0]) == pytest.approx(vx, abs=1e-9)
    expected = {0.95: 1.0 + 1j * (q0 + 6.0 * 0.09 ** 2),
                0.70: (1.0 + 12.0 * 0.16 ** 3.2) + 1j * (q0 + 11.0 * 0.16 ** 2.5),
                0.45: (GS + 1j * BS) * 0.45 ** 2}
    for v, s in expected.items():
        assert drawn_power(params, flags, v + 0j) == pytest.approx(s, abs=1e-12), f"V = {v}"


def test_stall_voltage_threshold_and_timer(motor):
    params, flags = motor
    vstall = float(params["vstall_adj"][0])
    above, _ = drive(params, flags, held((1.0, 0.1), (vstall + 0.005, 1.0)))
    assert above["run_a"].min() == 1.0, "a motor stalled above Vstall"
    below, _ = drive(params, flags, held((1.0, 0.1), (vstall - 0.005, 1.0)))
    first_low = int(round(0.1 / DT))
    stall_step = int(np.argmax(below["run_a"] < 0.5)) - first_low + 1
    # Tstall = 0.033 s fires on the 17th consecutive low step at dt = 2 ms (spec §6.7).
    assert stall_step == math.ceil(C["tstall"] / DT - 1e-6) == 17
    assert below["run_b"][-1] == 0.0, "parts A and B stall together"


@pytest.mark.parametrize("dt", [0.005, 0.01])  # the 300-bus step, and a coarse one
def test_timers_fire_on_the_same_step_in_float32(system, dt):
    """TRST = 0.40 s restarts part B on the 0.40/dt-th step back above Vrst, in float64 and
    in the float32 the study cases run in (summed float32 steps fall short of 0.40 by more
    than §6.7's 1e-9 s; before `timer_fires` they restarted one step late)."""
    volts = held((1.0, 0.1), (0.3, 0.5), (1.0, 1.0), dt=dt)
    back = int(round(0.6 / dt))
    for precision in ("float64", "float32"):
        motor = with_precision(system, precision)
        trace, _ = drive(motor.loads[0].params, motor.initial.load_flags[0], volts, dt)
        restart_step = int(np.argmax(trace["run_b"][back:] > 0.5)) + 1
        assert restart_step == round(C["trst"] / dt), precision


def test_bolted_fault_stalls_only_beyond_tstall(system):
    short = make_task(system, FaultEvent(2, 1.0, C["tstall"] - 0.007))
    long = make_task(system, FaultEvent(2, 1.0, C["tstall"] + 0.007))
    traj = simulate_batch(system, stack_tasks([short, long]), 3.0, DT, decimation=25)
    run_a = np.asarray(traj.load_flags[0]["run_a"])[:, :, 0]
    assert run_a[0].min() == 1.0, "a fault shorter than Tstall stalled the motor"
    assert run_a[1, -1] == 0.0, "a fault longer than Tstall did not stall the motor"
    vm = np.asarray(traj.vm)[:, -1, system.bus_index(2)]
    assert vm[0] > 0.95 > vm[1], f"recovered to {vm[0]:.3f} / stalled at {vm[1]:.3f} p.u."


def test_ramp_stall_and_partial_restart(motor):
    params, flags = motor
    ramp_down = np.linspace(1.0, 0.3, int(2.0 / DT))
    volts = np.concatenate([ramp_down, held((0.3, 0.5)), ramp_down[::-1], held((1.0, 1.0))])
    trace, s = drive(params, flags, volts)
    vstall = float(params["vstall_adj"][0])
    crossing = int(np.argmax(volts < vstall))
    stalled = int(np.argmax(trace["run_a"] < 0.5))
    assert (stalled - crossing + 1) * DT == pytest.approx(C["tstall"], abs=DT)
    back = int(np.argmax((np.arange(len(volts)) > stalled) & (volts > C["vrst"])))
    restart = int(np.argmax(trace["run_b"][stalled:] > 0.5)) + stalled
    assert (restart - back + 1) * DT == pytest.approx(C["trst"], abs=DT)
    assert trace["run_a"][-1] == 0.0, "part A must never restart"
    # At the end: part A stalled (Gs·V²), part B (Frst) on its running-1 curve, all on Sm.
    v0 = float(flags["vm"][0])
    q_run = math.tan(math.acos(0.98)) - 6.0 * (v0 - 0.86) ** 2 + 6.0 * 0.14 ** 2
    expected = (1 - C["frst"]) * (GS + 1j * BS) + C["frst"] * (1.0 + 1j * q_run)
    assert s[-1] == pytest.approx(float(params["sm"][0]) * expected, rel=1e-6)


def test_restart_and_thermal_sentinels(tmp_path):
    """VRST = 999 and TH1T = 999 (WECC "never"): read as written, each with a build note;
    after the ramp of test_ramp_stall_and_partial_restart part B stays stalled, and a stall
    at 1 p.u. for 20 s trips nothing thermally."""
    cons = list(CONS)
    names = [c.name for c in Acmtblu1.cons]
    cons[names.index("vrst")], cons[names.index("th1t")] = 999.0, 9999.0
    model = build(tmp_path, cons=cons)
    notes = [n for n in model.notes if "WECC/PSS/E sentinel" in n]
    assert [n.split(": ", 2)[2] for n in notes] == [
        "CON(21) VRST = 999 p.u. lies outside [0, 2]: read as the WECC/PSS/E sentinel: part B "
        "never restarts",
        "CON(29) TH1T = 9999 p.u. lies outside [-10, 100]: read as the WECC/PSS/E sentinel: "
        "thermal tripping never starts"], notes
    params, flags = model.loads[0].params, model.initial.load_flags[0]
    ramp_down = np.linspace(1.0, 0.3, int(2.0 / DT))
    trace, _ = drive(params, flags, np.concatenate([ramp_down, ramp_down[::-1],
                                                    held((1.0, 20.0))]))
    assert trace["run_a"][-1] == 0.0, "the ramp must stall the motors"
    assert trace["run_b"][len(ramp_down):].max() == 0.0, "part B restarted"
    assert trace["fth_a"].min() == 1.0, "thermal trip with TH1T = 9999"


def test_thermal_trip_timing(motor):
    params, flags = motor
    trace, _ = drive(params, flags, held((0.0, 0.05), (1.0, 20.0)))
    start = int(round(0.05 / DT))
    theta_start = trace["theta_a"][start - 1]
    theta_inf = GS  # stalled I²·Rstall at V = 1 (spec §6.6: 4.37)
    time_to = lambda level: C["tth"] * math.log((theta_inf - theta_start) / (theta_inf - level))  # noqa: E731
    begins = (int(np.argmax(trace["fth_a"] < 1.0)) - start + 1) * DT
    ends = (int(np.argmax(trace["fth_a"] <= 0.0)) - start + 1) * DT
    # Spec worked values: tripping starts after 3.45 s and is complete after 15.9 s.
    assert begins == pytest.approx(time_to(C["th1t"]), abs=2 * DT) and abs(begins - 3.45) < 0.02
    assert ends == pytest.approx(time_to(C["th2t"]), abs=2 * DT) and abs(ends - 15.9) < 0.05
    assert trace["fth_b"].min() == 1.0, "the restarted part B must not trip at 1 p.u."


def test_contactor_drop_out_and_reclose_with_memory(motor):
    params, flags = motor
    levels = [(1.0, 0.5), (0.45, 1.0), (0.6, 1.0), (0.5, 1.0), (0.7, 1.0)]
    trace, _ = drive(params, flags, held(*levels))
    ends = np.cumsum([int(round(t / DT)) for _, t in levels]) - 1
    x_off = (0.5 - 0.45) / (0.5 - 0.4)  # share open after the dip to 0.45 (spec §6.4)
    expected = [1.0, 1 - x_off, 1 - x_off * (1 - (0.6 - 0.55) / 0.1), 1 - x_off, 1.0]
    assert trace["kcon"][ends] == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("level, hold, trips_after", [
    (0.40, 0.2, 0.02 * math.log(0.6 / 0.1) + 0.02),  # stage 1: Vm < 0.5 for 0.02 s
    (0.85, 5.5, 0.02 * math.log(0.15 / 0.05) + 5.0),  # stage 2: Vm < 0.9 for 5 s
])
def test_under_voltage_relay_stages(motor, level, hold, trips_after):
    params, flags = motor
    params = dict(params, fuvr=np.array([0.1]))
    trace, _ = drive(params, flags, held((1.0, 0.1), (level, hold), (1.0, 1.0)))
    tripped = (int(np.argmax(trace["kuv"] < 1.0)) - int(round(0.1 / DT)) + 1) * DT
    assert tripped == pytest.approx(trips_after, abs=2 * DT)
    assert trace["kuv"][-1] == pytest.approx(0.9), "the UV trip is latched"


def test_shedding_scales_every_load_type_and_clips(system):
    x0 = system.initial
    v = np.asarray(x0.v[system.n_gen:]) * 0.9  # any voltage, here 10 % low

    def drawn(left):
        x = x0.replace(load_left=np.array([left]))
        with jax.enable_x64(True):
            injected = np.asarray(load_injection(system, x, v))
        in_matrix = system.load_y + system.loads[0].params["y_norton"]
        return in_matrix * v - injected

    left = shed(shed(jnp.ones(1), jnp.array([0]), jnp.array([0.2])), jnp.array([0]),
                jnp.array([0.2]))
    assert float(left[0]) == pytest.approx(0.6)
    assert drawn(0.6) == pytest.approx(0.6 * drawn(1.0), rel=1e-12)
    assert float(shed(left, jnp.array([0]), jnp.array([0.8]))[0]) == 0.0, "clipped at empty"


@pytest.mark.parametrize("change, message", [
    (dict(index=5, value=0.0), r"one_bus.dyr:2: ACMTBLU1 at bus 2 id '2': CON\(6\) COMPPF = 0"),
    (dict(index=7, value=0.0, index2=8), r"one_bus.dyr:2: .*RSTALL = XSTALL = 0"),
    (dict(extra=1.5), r"one_bus.dyr:2: .*CON\(36\) \(GridPACK's A/C motor share of the load "
                      r"record\) = 1.5: allowed \[0, 1\]"),
    (dict(extra=0.5, nc=37), r"one_bus.dyr:2: .*expected 35 values, found 37"),
    (dict(load_id="7"), r"one_bus.dyr:2: .*no in-service load record \(bus 2, LID '7'\)"),
])
def test_bad_motor_data_names_the_line(tmp_path, change, message):
    cons = list(CONS)
    if "index" in change:
        cons[change["index"]] = change["value"]
    if "index2" in change:
        cons[change["index2"]] = 0.0
    if "extra" in change:
        cons.append(change["extra"])
    if "nc" in change:
        cons.append(0.0)
    raw, dyr = write_system(tmp_path, cons, load_id=change.get("load_id", "2"))
    with pytest.raises(ModelError, match=message):
        compile_model(read_raw(raw), read_dyr(dyr))


@pytest.mark.parametrize("extra, share", [((), 0.43), ((0.6,), 0.6), ((0.0,), 0.43)])
def test_gridpack_share_reads_con_36(tmp_path, extra, share):
    """The default share mode takes CON(36), GridPACK's extension, else 0.43 of the record
    (GridPACK's default), of the 100 MW record '2'."""
    raw, dyr = write_system(tmp_path, CONS + list(extra))
    model = compile_model(read_raw(raw), read_dyr(dyr))
    mw = share * 100.0
    assert any(f"{mw:.2f} MW motor (gridpack)" in n for n in model.notes), model.notes


def test_gridpack_heating_heats_running_part_a_only(motor):
    """heating "gridpack": a running part A heats with the previous step's power over the
    present voltage (GridPACK as published), part B adds no heat until it stalls; the
    thermal ramp acts only once a part is stalled."""
    params, flags = motor
    gp = dict(params, heat_gridpack=np.ones(1))
    volts = held((1.0, 0.01), (1e-4, 0.004))  # two steps next to a bolted fault
    trace, _ = drive(gp, flags, volts)
    k = int(round(0.01 / DT))  # first step at 1e-4 p.u., the motor still running
    v0 = float(flags["vm"][0])
    q0 = math.tan(math.acos(0.98)) - 6.0 * (v0 - 0.86) ** 2
    s_before = 1.0 + 1j * (q0 + 6.0 * (1.0 - 0.86) ** 2)  # running-1 curve at V = 1 (§5)
    heat = abs(s_before) ** 2 / 1e-4 ** 2 * C["rstall"]
    before = trace["theta_a"][k - 1]
    theta = before + (1 - math.exp(-DT / C["tth"])) * (heat - before)
    assert trace["theta_a"][k] == pytest.approx(theta, rel=1e-9)
    assert trace["theta_b"][k] < trace["theta_b"][k - 1], "running part B must cool"
    assert trace["fth_a"][k] == 1.0, "a running part must not trip, however hot"
    stalled, _ = drive(gp, flags, held((1.0, 0.01), (1e-4, 0.05)))
    assert stalled["run_a"][-1] == 0.0 and stalled["fth_a"][-1] == 0.0, "hot and stalled: tripped"


def test_gridpack_contactor_follows_the_drop_out_line(motor):
    """contactor "gridpack": inside the drop-out band Kcon follows the present Vm (also
    while it rises), between Vc2on and Vc1on it recloses what the last in-band Vm opened,
    at and above Vc1on all are in."""
    params, flags = motor
    gp = dict(params, contactor_gridpack=np.ones(1))
    levels = [(1.0, 0.5), (0.42, 1.0), (0.47, 1.0), (0.6, 1.0), (0.7, 1.0)]
    trace, _ = drive(gp, flags, held(*levels))
    ends = np.cumsum([int(round(t / DT)) for _, t in levels]) - 1
    rising = trace["vm"][ends[2] + 1:ends[3] + 1]
    last = rising[rising < 0.5].max()  # the last measured voltage inside the band
    expected = [1.0, (0.42 - 0.4) / 0.1, (0.47 - 0.4) / 0.1,
                1 - (0.5 - last) / 0.1 * (1 - (0.6 - 0.55) / 0.1), 1.0]
    assert trace["kcon"][ends] == pytest.approx(expected, abs=1e-6)


def test_motor_options_reject_unknown_readings():
    with pytest.raises(ValueError, match="share_mode = 'bus'"):
        MotorOptions(share_mode="bus")
    with pytest.raises(ValueError, match="0 < x <= 1"):
        MotorOptions(share_mode="fraction:1.5")
    with pytest.raises(ValueError, match="vx_rule"):
        MotorOptions(vx_rule="running3")
    with pytest.raises(ValueError, match="heating = 'always': allowed stalled, gridpack"):
        MotorOptions(heating="always")
    with pytest.raises(ValueError, match="contactor = 'x': allowed memory, gridpack"):
        MotorOptions(contactor="x")


def test_cli_motor_readings_and_load_report(tmp_path, capsys):
    raw, dyr = write_system(tmp_path)
    out = str(tmp_path / "run.npz")
    common = ["--raw", str(raw), "--dyr", str(dyr), "--t-end", "0.2", "--dt", "0.002",
              "--decimation", "10", "--out", out]
    assert main(common + ["--motor-share", "fraction:0.43", "--vx-rule", "spec_running2"]) == 0
    printed = capsys.readouterr().out
    # GridPACK's reading: 43 % of the 100 MW record; the running-2 rule caps Vx at Vstall'.
    assert "ACMTBLU1 at bus 2 id '2': 43.00 MW motor (fraction:0.43)" in printed
    assert "Vx = 0.5000 p.u. (spec_running2)" in printed
    assert main(common + ["--motor-share", "interpss_bus_total"]) == 0
    assert "150.00 MW motor (interpss_bus_total)" in capsys.readouterr().out
    assert main(common + ["--motor-share", "half"]) == 2
    assert "share_mode = 'half': allowed" in capsys.readouterr().err
