"""Closed-loop scenario runs: the simulator's loop with the firmware's controller and meter."""
import numpy as np
import pytest

import shimmy_sim

KICK = """
duration_s = {duration}
[controller]
kind = "{kind}"
[speed]
constant_kmh = 55.0
[initial]
yaw_deg = 0.5
[output]
trace_every = 5
"""


def run(kind, duration=4.0):
    return shimmy_sim.run_scenario_toml(KICK.format(kind=kind, duration=duration), name=kind)


def test_arrays_have_the_trace_shape():
    r = run("asmc")
    t = r["trace"]["t_s"]
    assert isinstance(t, np.ndarray) and t.dtype == np.float64
    assert r["trace_dt_s"] == pytest.approx(0.005)
    np.testing.assert_allclose(np.diff(t), r["trace_dt_s"], rtol=1e-9)
    assert t[-1] == pytest.approx(4.0, abs=0.01)
    for name, col in r["trace"].items():
        assert col.shape == t.shape, name
    m = r["meter"]
    assert m["t_s"].shape == m["zeta_slow"].shape and len(m["t_s"]) > 300  # 100 Hz
    np.testing.assert_allclose(r["trace"]["speed_mps"], 55.0 / 3.6)
    assert r["metrics"]["invalid_commands"] == 0
    # Peak from the full-rate series, at least the decimated trace's peak.
    assert r["metrics"]["peak_yaw_rad"] >= np.max(np.abs(r["trace"]["psi_l_rad"]))


def test_the_controller_stops_what_grows_without_a_damper():
    """Inside the Hopf window (55 km/h, nominal) the kick grows without a damper and dies out
    with the ASMC."""
    off, asmc = run("no-damper"), run("asmc")
    for r in (off, asmc):
        assert r["trace"]["psi_l_rad"][0] == pytest.approx(np.radians(0.5), rel=1e-6)
    assert np.all(off["trace"]["current_cmd_a"] == 0.0)
    assert asmc["metrics"]["peak_current_a"] > 0.1
    assert off["metrics"]["amp_end_rad"] > 10 * asmc["metrics"]["amp_end_rad"]


def test_runs_are_deterministic():
    a, b = run("asmc", 2.0), run("asmc", 2.0)
    for name in a["trace"]:
        np.testing.assert_array_equal(a["trace"][name], b["trace"][name])


def test_scenario_files_run(root):
    r = shimmy_sim.run_scenario(root / "host-sim" / "scenarios" / "pothole.toml")
    assert r["sim_s"] > 1.0 and r["metrics"]["settle_s"] is not None


def test_bad_scenarios_name_the_field():
    with pytest.raises(ValueError, match=r"duration_s"):
        shimmy_sim.run_scenario_toml(KICK.format(kind="asmc", duration=-1.0))
    with pytest.raises(ValueError, match=r"controller\.kind"):
        shimmy_sim.run_scenario_toml(KICK.format(kind="pid", duration=1.0))
    with pytest.raises(ValueError, match=r"no-such\.toml"):
        shimmy_sim.run_scenario("no-such.toml")
