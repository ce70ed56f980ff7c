"""The Hopf window and the eigen sweep against the independent NumPy/SciPy reference
(host-sim/reference/plant_scipy.py: A(V) written from docs/plant-model.md, eigenvalues by
LAPACK, crossings by scipy's brentq), on vehicles that differ from the nominal one."""
import numpy as np
import pytest
from scipy.optimize import brentq

import shimmy_sim

VEHICLES = [
    ("nominal", {}),
    ("hard", {}),
    ("nominal", {"plant.c_a": 72000.0, "plant.sigma": 0.36}),
    ("gentle", {"plant.k_d": 6000.0}),
]


def reference_growth(reference, plant, v_kmh):
    """Largest real part of the oscillatory eigenvalues of the reference A(V), and that pair's
    frequency in Hz."""
    lam = np.linalg.eigvals(reference.linear_a(plant, v_kmh / 3.6))
    osc = lam[np.abs(lam.imag) > 1e-9]
    k = np.argmax(osc.real)
    return osc[k].real, abs(osc[k].imag) / (2 * np.pi)


def reference_crossings(reference, plant, lo=5.0, hi=150.0, step=1.0):
    grid = np.arange(lo, hi + step / 2, step)
    g = [reference_growth(reference, plant, v)[0] for v in grid]
    out = []
    for a, b, ga, gb in zip(grid[:-1], grid[1:], g[:-1], g[1:]):
        if (ga < 0) != (gb < 0):
            v = brentq(lambda x: reference_growth(reference, plant, x)[0], a, b, xtol=1e-9)
            out.append((v, "onset" if ga < 0 else "offset",
                        reference_growth(reference, plant, v)[1]))
    return out


@pytest.mark.parametrize("base,changes", VEHICLES)
def test_hopf_window_matches_scipy(reference, base, changes):
    vehicle = shimmy_sim.Vehicle(base).with_fields(changes)
    ours = shimmy_sim.hopf_window(vehicle)
    theirs = reference_crossings(reference, vehicle.plant())
    assert len(theirs) >= 1, "every test vehicle has a Hopf window"
    assert [c["kind"] for c in ours] == [k for _, k, _ in theirs]
    for c, (v_ref, _, f_ref) in zip(ours, theirs):
        assert c["converged"]
        # Rust refines to 1e-5 m/s = 3.6e-5 km/h; allow 1e-4 km/h.
        assert c["speed_kmh"] == pytest.approx(v_ref, abs=1e-4)
        assert c["freq_hz"] == pytest.approx(f_ref, abs=1e-6)


def test_no_window_on_both_sides(reference):
    stiff = shimmy_sim.Vehicle("gentle").with_fields({"plant.k_d": 14000.0})
    assert shimmy_sim.hopf_window(stiff) == []
    assert reference_crossings(reference, stiff.plant()) == []


def test_the_window_moves_with_the_vehicle():
    nominal = shimmy_sim.hopf_window(shimmy_sim.Vehicle())
    hard = shimmy_sim.hopf_window(shimmy_sim.Vehicle("hard"))
    assert hard[0]["speed_kmh"] < nominal[0]["speed_kmh"] - 1.0


def test_the_damper_closes_the_window():
    v = shimmy_sim.Vehicle()
    assert shimmy_sim.hopf_window(v)
    assert shimmy_sim.hopf_window(v, damper_current_a=0.5) == []


@pytest.mark.parametrize("base,changes", VEHICLES)
def test_eigen_sweep_matches_numpy(reference, base, changes):
    vehicle = shimmy_sim.Vehicle(base).with_fields(changes)
    speeds = np.linspace(5.0, 150.0, 30)
    s = shimmy_sim.eigen_sweep(vehicle, speeds)
    assert set(s) >= {"speed_kmh", "max_re", "critical_re", "critical_freq_hz", "shimmy_zeta"}
    np.testing.assert_array_equal(s["speed_kmh"], speeds)
    ref = np.array([reference_growth(reference, vehicle.plant(), v) for v in speeds])
    all_re = [np.max(np.linalg.eigvals(reference.linear_a(vehicle.plant(), v / 3.6)).real)
              for v in speeds]
    np.testing.assert_allclose(s["critical_re"], ref[:, 0], rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(s["critical_freq_hz"], ref[:, 1], rtol=1e-8)
    np.testing.assert_allclose(s["max_re"], all_re, rtol=1e-8, atol=1e-9)


def test_bad_ranges_are_named():
    v = shimmy_sim.Vehicle()
    with pytest.raises(ValueError, match=r"step_kmh.*0\.01 <= value <= 50"):
        shimmy_sim.hopf_window(v, step_kmh=0.0)
    with pytest.raises(ValueError, match=r"v_min_kmh 100 must be below v_max_kmh 50"):
        shimmy_sim.hopf_window(v, v_min_kmh=100.0, v_max_kmh=50.0)
    with pytest.raises(ValueError, match=r"speeds_kmh.*1 <= value <= 250"):
        shimmy_sim.eigen_sweep(v, [30.0, 400.0])
    with pytest.raises(ValueError, match=r"damper_current_a"):
        shimmy_sim.eigen_sweep(v, [30.0], damper_current_a=9.0)


def test_parallel_threads_give_the_serial_answer():
    """The functions release the GIL: a thread pool (the pattern of a Dask/Ray sweep) gives
    exactly the serial result."""
    from concurrent.futures import ThreadPoolExecutor

    speeds = np.linspace(10.0, 120.0, 12)
    k_d = [6000.0, 8000.0, 10000.0, 12000.0]

    def row(k):
        return shimmy_sim.eigen_sweep(shimmy_sim.Vehicle().with_fields({"plant.k_d": k}), speeds)["max_re"]

    serial = [row(k) for k in k_d]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(row, k_d))
    for a, b in zip(serial, parallel):
        np.testing.assert_array_equal(a, b)


def test_the_car_onset_is_supercritical_and_the_mr_damper_non_smooth():
    """The Hopf type of the nominal car: supercritical (a stable cycle grows past the onset,
    larger 1 km/h further in than at the crossing); with the MR damper in the plant there is no
    classical l1, and the reason says so."""
    onset = shimmy_sim.hopf_window(shimmy_sim.Vehicle())[0]
    assert onset["hopf_type"] == "supercritical" and onset["l1"] < 0
    assert onset["cycle_amp_deg_1kmh"] > 0 and onset["hopf_note"] is None
    damped = shimmy_sim.hopf_window(shimmy_sim.Vehicle(), damper_current_a=0.0)
    assert damped, "the car at 0 A has a Hopf window"
    assert all(c["hopf_type"] == "non-smooth" for c in damped)
    assert "damper" in damped[0]["hopf_note"]
