"""Every vehicle model through the module: the mining truck's Hopf window and eigen sweep against
the independent NumPy/SciPy reference (host-sim/reference/plant_scipy.py, `truck_linear_a`
written from docs/mining-truck.md), the trailer's and the dual-axle truck's crossings against
the same file and against `shimmy-sim stability`, and the car-only functions refusing the
others by name."""
import csv
import math
import subprocess

import numpy as np
import pytest
from scipy.optimize import brentq

import shimmy_sim

TRUCK = "mining-truck-5dof"


def section(vehicle, name):
    """The model's own section of `fields()` by the field names (those of the reference)."""
    prefix = name + "."
    return {k[len(prefix):]: x for k, x in vehicle.fields().items() if k.startswith(prefix)}


def linear_a(reference, vehicle):
    """A(V) of the reference for the vehicle's model, V in m/s."""
    if vehicle.model == TRUCK:
        t = section(vehicle, "truck")
        return lambda v: reference.truck_linear_a(t, v)
    if vehicle.model == "trailer-2dof":
        t = section(vehicle, "trailer")
        return lambda v: reference.trailer_linear_a(t, v, 0.0)
    if vehicle.model == "dual-axle-truck-8dof":
        d = section(vehicle, "dual_axle")
        return lambda v: reference.dual_linear_a(d, v)
    raise AssertionError(vehicle.model)


def growth(a, v_kmh):
    """Largest real part of the oscillatory eigenvalues of A(V) and that pair's frequency, Hz."""
    lam = np.linalg.eigvals(a(v_kmh / 3.6))
    osc = lam[np.abs(lam.imag) > 1e-9]
    k = np.argmax(osc.real)
    return osc[k].real, abs(osc[k].imag) / (2 * np.pi)


def reference_crossings(a, lo=5.0, hi=150.0, step=1.0):
    grid = np.arange(lo, hi + step / 2, step)
    g = [growth(a, v)[0] for v in grid]
    out = []
    for x0, x1, g0, g1 in zip(grid[:-1], grid[1:], g[:-1], g[1:]):
        if (g0 < 0) != (g1 < 0):
            v = brentq(lambda x: growth(a, x)[0], x0, x1, xtol=1e-9)
            out.append((v, "onset" if g0 < 0 else "offset", growth(a, v)[1]))
    return out


def assert_crossings_match(ours, theirs):
    assert [c["kind"] for c in ours] == [k for _, k, _ in theirs]
    for c, (v_ref, _, f_ref) in zip(ours, theirs):
        assert c["converged"]
        assert c["speed_kmh"] == pytest.approx(v_ref, abs=1e-3)
        assert c["freq_hz"] == pytest.approx(f_ref, abs=1e-6)


TRUCKS = [
    ("truck-full", {}),
    ("truck-empty", {}),
    ("truck-full", {"truck.c_k": 3000.0}),
]


def test_truck_sets_load_as_the_truck():
    full, empty = shimmy_sim.Vehicle("truck-full"), shimmy_sim.Vehicle("truck-empty")
    assert full.model == empty.model == TRUCK
    assert shimmy_sim.Vehicle().model == "car-4dof"
    assert full != empty
    assert full.get("truck.payload_kg") > empty.get("truck.payload_kg")
    # the truck's file takes its own section and the shared ones, not the car's `[plant]`
    assert {k.split(".")[0] for k in full.fields()} == {
        "truck", "damper", "damper_model", "sensors", "controller", "thresholds"}


@pytest.mark.parametrize("base,changes", TRUCKS)
def test_truck_eigen_sweep_matches_scipy(reference, base, changes):
    truck = shimmy_sim.Vehicle(base).with_fields(changes)
    a = linear_a(reference, truck)
    speeds = np.linspace(1.0, 150.0, 40)
    s = shimmy_sim.eigen_sweep(truck, speeds)
    np.testing.assert_array_equal(s["speed_kmh"], speeds)
    max_re = np.array([np.max(np.linalg.eigvals(a(v / 3.6)).real) for v in speeds])
    ref = np.array([growth(a, v) for v in speeds])
    np.testing.assert_allclose(s["max_re"], max_re, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(s["critical_re"], ref[:, 0], rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(s["critical_freq_hz"], ref[:, 1], rtol=1e-8)
    assert np.max(s["max_re"]) == pytest.approx(np.max(max_re), rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("base,changes", TRUCKS)
def test_truck_hopf_window_matches_scipy(reference, base, changes):
    truck = shimmy_sim.Vehicle(base).with_fields(changes)
    ours = shimmy_sim.hopf_window(truck, v_min_kmh=1.0)
    theirs = reference_crossings(linear_a(reference, truck), lo=1.0)
    # the empty truck has no window up to 150 km/h on either side: both lists empty
    assert_crossings_match(ours, theirs)


def test_a_truck_file_with_a_field_changed_moves_the_onset(tmp_path, reference):
    path = tmp_path / "truck.toml"
    path.write_text('model = "mining-truck-5dof"\nbase = "truck-full"\n[truck]\nc_k = 3000.0\n')
    changed, full = shimmy_sim.Vehicle(str(path)), shimmy_sim.Vehicle("truck-full")
    assert changed == full.with_fields({"truck.c_k": 3000.0})
    assert changed != full
    on_changed = shimmy_sim.hopf_window(changed, v_min_kmh=1.0)[0]
    on_full = shimmy_sim.hopf_window(full, v_min_kmh=1.0)[0]
    assert on_full["kind"] == on_changed["kind"] == "onset"
    assert abs(on_changed["speed_kmh"] - on_full["speed_kmh"]) > 0.1
    v_ref = reference_crossings(linear_a(reference, changed), lo=1.0)[0][0]
    assert on_changed["speed_kmh"] == pytest.approx(v_ref, abs=1e-3)


def test_truck_fields_are_checked_like_a_file():
    truck = shimmy_sim.Vehicle("truck-full")
    before = truck.fields()
    with pytest.raises(ValueError, match=r"truck\.k_d.*outside"):
        truck.set("truck.k_d", -1.0)
    with pytest.raises(ValueError, match=r"truck\.kd.*no such field.*k_d"):
        truck.set("truck.kd", 1.0)
    with pytest.raises(ValueError, match=r"section `plant`.*mining-truck-5dof.*truck"):
        truck.get("plant.k_d")
    assert truck.fields() == before
    truck.set("damper.rated_current_a", 2.5)
    assert truck.rated_current_a == 2.5


@pytest.mark.parametrize("name,model,own", [
    ("trailer", "trailer-2dof", "trailer"),
    ("dual-axle", "dual-axle-truck-8dof", "dual_axle"),
])
def test_trailer_and_dual_axle_crossings_match_scipy(reference, name, model, own):
    v = shimmy_sim.Vehicle(name)
    assert v.model == model
    assert {k.split(".")[0] for k in v.fields()} == {own}
    ours = shimmy_sim.hopf_window(v)
    theirs = reference_crossings(linear_a(reference, v))
    assert theirs, f"{name} without damper has a Hopf crossing"
    assert_crossings_match(ours, theirs)


@pytest.mark.parametrize("name", ["trailer", "dual-axle", "truck-full", "nominal"])
def test_crossings_are_those_of_the_stability_command(root, tmp_path, name):
    """`shimmy-sim stability --vehicle NAME` of the host build: its crossings.csv."""
    exe = root / "target" / "debug" / "shimmy-sim"
    if not exe.exists():
        pytest.skip(f"no {exe} (the host build makes it)")
    subprocess.run([str(exe), "stability", "--vehicle", name, "--out", str(tmp_path)],
                   check=True, capture_output=True)
    with open(tmp_path / "crossings.csv") as f:
        rows = list(csv.DictReader(f))
    ours = shimmy_sim.hopf_window(shimmy_sim.Vehicle(name))
    assert rows
    assert [(c["kind"], c["shape"]) for c in ours] == [(r["kind"], r["shape"]) for r in rows]
    for c, r in zip(ours, rows):
        # the file has 6 decimals of km/h and Hz
        assert c["speed_kmh"] == pytest.approx(float(r["speed_kmh"]), abs=1e-6)
        assert c["freq_hz"] == pytest.approx(float(r["freq_hz"]), abs=1e-6)
        # the Hopf type: l1 with 10 digits, the cycle with 6 decimals of deg
        assert c["hopf_type"] == r["hopf_type"]
        if r["l1"]:
            assert c["l1"] == pytest.approx(float(r["l1"]), rel=1e-8)
        else:
            assert math.isnan(c["l1"]) and c["hopf_note"]
        if r["cycle_amp_deg_1kmh"]:
            assert c["cycle_amp_deg_1kmh"] == pytest.approx(float(r["cycle_amp_deg_1kmh"]), abs=1e-5)


def test_car_only_functions_name_the_model():
    truck, trailer = shimmy_sim.Vehicle("truck-full"), shimmy_sim.Vehicle("trailer")
    with pytest.raises(ValueError, match=r"plant\(\).*mining-truck-5dof.*car-4dof"):
        truck.plant()
    with pytest.raises(ValueError, match=r"damper\(\).*trailer-2dof.*no MR damper"):
        trailer.damper()
    with pytest.raises(ValueError, match=r"damper_current_a.*trailer-2dof.*no MR damper"):
        shimmy_sim.hopf_window(trailer, damper_current_a=0.5)
    with pytest.raises(ValueError, match=r"trailer-2dof"):
        trailer.set("plant.k_d", 5000.0)


def test_the_damper_moves_the_trucks_window():
    truck = shimmy_sim.Vehicle("truck-full")
    bare = shimmy_sim.hopf_window(truck, v_min_kmh=1.0)
    damped = shimmy_sim.hopf_window(truck, v_min_kmh=1.0, damper_current_a=truck.rated_current_a)
    assert bare
    assert [(c["kind"], round(c["speed_kmh"], 3)) for c in damped] != [
        (c["kind"], round(c["speed_kmh"], 3)) for c in bare]


@pytest.mark.parametrize("name", ["nominal", "truck-full", "truck-empty", "dual-axle", "trailer"])
def test_fields_are_the_models_table(name):
    """`fields()` lists exactly the rows of the model's `field_table`, each inside its range."""
    v = shimmy_sim.Vehicle(name)
    table = shimmy_sim.field_table(v)
    fields = v.fields()
    assert sorted(f"{f['section']}.{f['name']}" for f in table) == sorted(fields)
    for f in table:
        assert f["lo"] <= fields[f"{f['section']}.{f['name']}"] <= f["hi"], f
    # a value past the row's range is refused naming the field
    f = table[0]
    with pytest.raises(ValueError, match=rf"{f['section']}\.{f['name']}"):
        v.set(f"{f['section']}.{f['name']}", f["hi"] * 2 + 1)
