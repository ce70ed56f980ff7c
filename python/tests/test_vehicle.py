"""Vehicles: the same loader and validation as `shimmy-sim --vehicle`."""
import pytest

import shimmy_sim


def test_named_sets_differ_and_match_their_fields():
    nominal, hard = shimmy_sim.Vehicle("nominal"), shimmy_sim.Vehicle("hard")
    assert nominal != hard
    # `hard` is the nominal car with half the steering-column stiffness (docs/plant-model.md).
    assert hard.get("plant.k_d") == pytest.approx(0.5 * nominal.get("plant.k_d"))
    assert nominal.plant()["k_d"] == nominal.get("plant.k_d")


def test_file_text_and_set_agree(tmp_path):
    text = 'base = "gentle"\n[plant]\nk_d = 5000\n[damper]\nrated_current_a = 2.5\n'
    path = tmp_path / "car.toml"
    path.write_text(text)
    from_file, from_text = shimmy_sim.Vehicle(str(path)), shimmy_sim.Vehicle.from_toml(text)
    assert from_file == from_text
    by_hand = shimmy_sim.Vehicle("gentle").with_fields(
        {"plant.k_d": 5000.0, "damper.rated_current_a": 2.5})
    assert by_hand == from_file
    assert from_file.rated_current_a == 2.5


def test_fields_cover_the_field_table():
    table = shimmy_sim.field_table()
    fields = shimmy_sim.Vehicle().fields()
    assert len(table) == len(fields) > 50
    for f in table:
        value = fields[f"{f['section']}.{f['name']}"]
        assert f["lo"] <= value <= f["hi"], f


def test_bad_values_name_the_field_and_range():
    v = shimmy_sim.Vehicle()
    before = v.fields()
    with pytest.raises(ValueError, match=r"plant\.k_d.*10 <= value <= 100000000"):
        v.set("plant.k_d", -1.0)
    assert v.fields() == before  # nothing half-applied
    with pytest.raises(ValueError, match=r"plant\.kd.*no such field.*k_d"):
        v.set("plant.kd", 1.0)
    with pytest.raises(ValueError, match=r"section\.name"):
        v.get("k_d")
    with pytest.raises(ValueError, match=r"no such file.*not a named set"):
        shimmy_sim.Vehicle("no-such-vehicle.toml")
    with pytest.raises(ValueError, match=r"overrides\.sigma"):
        shimmy_sim.Vehicle.from_toml("[overrides]\nsigma = -0.6\n")
