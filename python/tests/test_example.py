"""The README's example runs as it is."""
import runpy


def test_the_example_runs(root, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # it may write kick.png
    runpy.run_path(str(root / "python" / "examples" / "hopf_and_sweep.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert "nominal: onset 29.35 km/h" in out
    assert "with 0.5 A: no crossing" in out
