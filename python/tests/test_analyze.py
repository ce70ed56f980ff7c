"""shimmy_sim.analyze: the simulator's `analyze` (mode meter, fusion, monitor on a measured log)
on logs written from simulator runs, with the column names, units and separator of the file."""
import numpy as np
import pytest

import shimmy_sim

RUN = """duration_s = {duration}
[controller]
kind = "{kind}"
[speed]
constant_kmh = 45.0
[initial]
yaw_deg = {yaw}
[output]
trace_every = 1
"""


def trace(kind, yaw, duration):
    return shimmy_sim.run_scenario_toml(RUN.format(kind=kind, yaw=yaw, duration=duration))["trace"]


def write_si(path, t):
    """The default columns of the mapping (a `shimmy-sim run` trace), SI units."""
    np.savetxt(path, np.c_[t["t_s"], t["psi_l_rad"], t["psi_r_rad"], t["speed_mps"]],
               delimiter=",", header="t_s,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps",
               comments="")


@pytest.fixture(scope="module")
def limit_cycle():
    return trace("no-damper", 0.1, 15.0)


def test_shimmy_without_a_damper_is_found(tmp_path, limit_cycle):
    log = tmp_path / "cycle.csv"
    write_si(log, limit_cycle)
    a = shimmy_sim.analyze(log)
    assert a["summary"]["max_level"] == 3  # shimmy present
    assert a["summary"]["not_judged"] is None
    assert len(a["events"]) == 1 and a["events"][0]["open"]
    linear_hz = shimmy_sim.eigen_sweep(shimmy_sim.Vehicle(), [45.0])["shimmy_freq_hz"][0]
    # The limit cycle runs near the linear shimmy mode's frequency.
    assert a["events"][0]["freq_hz"] == pytest.approx(linear_hz, rel=0.1)
    assert len(a["rows"]["t_s"]) == pytest.approx(100 * 15.0, abs=2)  # 100 Hz


def test_units_columns_and_separator_do_not_change_the_result(tmp_path, limit_cycle):
    si, other = tmp_path / "si.csv", tmp_path / "deg.csv"
    write_si(si, limit_cycle)
    t = limit_cycle
    np.savetxt(other, np.c_[t["t_s"] * 1e3, np.degrees(t["psi_l_rad"]),
                            np.degrees(t["psi_r_rad"]), t["speed_mps"] * 3.6],
               delimiter=";", header="time_ms;L;R;v", comments="")
    a = shimmy_sim.analyze(si)
    b = shimmy_sim.analyze(other, delimiter=";", time_column="time_ms", time_unit="ms",
                       yaw_left="L", yaw_right="R", yaw_unit="deg", speed_column="v",
                       speed_unit="km/h")
    assert a["events"][0]["start_s"] == pytest.approx(b["events"][0]["start_s"], abs=1e-9)
    np.testing.assert_allclose(a["rows"]["amplitude_rad"], b["rows"]["amplitude_rad"],
                               rtol=1e-5, atol=1e-9)
    np.testing.assert_array_equal(a["rows"]["level"], b["rows"]["level"])


def test_a_damped_kick_is_not_shimmy(tmp_path):
    log = tmp_path / "asmc.csv"
    write_si(log, trace("asmc", 0.5, 6.0))
    assert shimmy_sim.analyze(log)["summary"]["max_level"] < 3


def test_a_log_without_wheel_motion_is_not_judged(tmp_path):
    log = tmp_path / "flat.csv"
    t = np.arange(10000) * 1e-3
    np.savetxt(log, np.c_[t, 0 * t, 0 * t, 10 + 0 * t], delimiter=",",
               header="t_s,psi_l_meas_rad,psi_r_meas_rad,speed_meas_mps", comments="")
    s = shimmy_sim.analyze(log, model=False)["summary"]
    assert s["valid_fraction"] == 0
    assert "too little wheel yaw in the shimmy band" in s["not_judged"]


def test_bad_logs_name_the_column(tmp_path, limit_cycle):
    log = tmp_path / "cycle.csv"
    write_si(log, limit_cycle)
    with pytest.raises(ValueError, match="wheel_yaw"):
        shimmy_sim.analyze(log, yaw_column="wheel_yaw")
    with pytest.raises(ValueError, match="no-such.csv"):
        shimmy_sim.analyze(tmp_path / "no-such.csv")


def test_analyze_takes_the_models_the_command_takes(tmp_path, limit_cycle):
    """The vehicle of any model goes through: the truck's is analysed (its model tracker), the
    trailer's refused naming its model."""
    log = tmp_path / "cycle.csv"
    write_si(log, limit_cycle)
    truck = shimmy_sim.analyze(log, vehicle=shimmy_sim.Vehicle("truck-full"))
    car = shimmy_sim.analyze(log)
    assert len(truck["rows"]["t_s"]) > 0
    # the truck's pipeline (its meter slowed to the truck's mode), not the car's
    assert not np.array_equal(truck["rows"]["t_s"], car["rows"]["t_s"])
    with pytest.raises(ValueError, match=r"trailer-2dof"):
        shimmy_sim.analyze(log, vehicle=shimmy_sim.Vehicle("trailer"))
