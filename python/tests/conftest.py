"""Shared fixtures: the repository's `cbd` binary and examples, and fits reused across tests."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

import cbd

ROOT = pathlib.Path(__file__).resolve().parents[2]
UR5 = ROOT / "examples" / "ur5"
RR_MODEL = 'length_unit = "m"\nangle_unit = "rad"\n[planar]\nlengths = [1.0, 0.5]\n[measurements]\njoints = ["q1", "q2"]\npositions = ["x", "y"]\n'


def binary(env, default):
    path = pathlib.Path(os.environ.get(env, ROOT / default))
    if not path.exists():
        pytest.fail(f"{path} is missing: build it first (.ci/python.sh does), or set {env}")
    return str(path)


@pytest.fixture(scope="session")
def cbd_bin():
    return binary("CBD_BIN", "target/release/cbd")


@pytest.fixture(scope="session")
def fw_host():
    return binary("CBD_FW_HOST", "target/debug/cbd-fw-host")


def run(*args, cwd=None):
    """Runs a command; its stdout (text), or the test fails with its stderr."""
    done = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True)
    assert done.returncode == 0, f"{args}: {done.stderr}"
    return done.stdout


def read_csv(path):
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return data


@pytest.fixture(scope="session")
def ur5_file():
    return cbd.ModelFile.load(UR5 / "ur5.toml")


@pytest.fixture(scope="session")
def ur5_train():
    return read_csv(UR5 / "train.csv")


@pytest.fixture(scope="session")
def ur5_fit(tmp_path_factory, cbd_bin, ur5_file, ur5_train):
    """The UR5 example fitted with its geometry calibrated on 300 rows, from Python and by `cbd fit`."""
    d = tmp_path_factory.mktemp("ur5")
    model = cbd.fit(ur5_file, ur5_train[:, :6], ur5_train[:, 6:], dh_first=True, max_rows=300, quiet=True)
    run(cbd_bin, "fit", "--quiet", "--dh-first", "--max-rows", "300", "--model", UR5 / "ur5.toml", "--data", UR5 / "train.csv",
        "--out", d / "cli.blob", "--json", d / "cli.json")
    return model, d


@pytest.fixture(scope="session")
def rr_dir(tmp_path_factory, cbd_bin):
    """A planar RR model file and simulated data: a 6 × 6 grid to train on, 50 random rows to test."""
    d = tmp_path_factory.mktemp("rr")
    (d / "rr.toml").write_text(RR_MODEL)
    run(cbd_bin, "simulate", "--sampling", "grid", "--grid", "6", "--noise", "1e-4", "--out", d / "train.csv")
    run(cbd_bin, "simulate", "--sampling", "uniform", "--count", "50", "--seed", "2", "--noise", "1e-4", "--out", d / "test.csv")
    return d
