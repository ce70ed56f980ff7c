"""The README's example runs as it is."""
import runpy

import shimmy_sim


def test_the_example_runs(root, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # it may write kick.png
    runpy.run_path(str(root / "python" / "examples" / "hopf_and_sweep.py"), run_name="__main__")
    out = capsys.readouterr().out
    onset = shimmy_sim.hopf_window(shimmy_sim.Vehicle())[0]
    assert f"nominal: onset {onset['speed_kmh']:.2f} km/h ({onset['freq_hz']:.2f} Hz)" in out
    assert "with 0.5 A: no crossing" in out


def test_the_tolerance_study_on_a_local_dask_cluster_is_the_serial_study(root, capsys):
    """The Dask run returns what a plain loop over the same samples returns, in order."""
    study = runpy.run_path(str(root / "python" / "examples" / "tolerance_study.py"))
    onsets = study["main"](["--samples", "24", "--threads", "--design-speed-kmh", "29.35"])
    serial = [study["onset_kmh"](f) for f in study["samples"](24, 1)]
    assert list(onsets) == serial
    out = capsys.readouterr().out
    assert "24 cars" in out and "shimmy onset: min" in out
    # The spread straddles the nominal onset (29.35 km/h): some cars start below it.
    nominal = shimmy_sim.hopf_window(shimmy_sim.Vehicle())[0]["speed_kmh"]
    assert min(serial) < nominal < max(serial)
