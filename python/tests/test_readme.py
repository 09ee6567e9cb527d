"""The guide's Python example (docs/guide/python.md) is examples/python/fit_ur5.py, and it runs."""

import os
import subprocess
import sys

from conftest import ROOT


def test_readme_shows_the_example_and_it_runs(tmp_path):
    script = (ROOT / "examples" / "python" / "fit_ur5.py").read_text()
    assert "```python\n" + script + "```" in (ROOT / "docs" / "guide" / "python.md").read_text()
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run([sys.executable, ROOT / "examples" / "python" / "fit_ur5.py"], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("calibrated: mean 0.065"), done.stdout
    assert (tmp_path / "ur5.blob").exists()
