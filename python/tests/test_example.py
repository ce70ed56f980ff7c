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
