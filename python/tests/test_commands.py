"""compare, diagnose, check and simulate are the commands: the same JSON keys, the same data."""

import json
import logging
import subprocess
import threading
import time

import numpy as np
import pytest

import cbd
from conftest import UR5, read_csv, run


def test_simulate_returns_the_commands_rows(cbd_bin, tmp_path):
    q, y = cbd.simulate(robot="six", sampling="uniform", count=25, seed=3, noise=0.02)
    run(cbd_bin, "simulate", "--robot", "six", "--sampling", "uniform", "--count", "25", "--seed", "3", "--noise", "0.02", "--out", tmp_path / "s.csv")
    data = read_csv(tmp_path / "s.csv")
    assert np.array_equal(q, data[:, :6]) and np.array_equal(y, data[:, 6:])
    q, y = cbd.simulate(robot="six", sampling="uniform", count=4, tool_points="0,0,0;100,0,0;50,86.6,0", pose=True)
    assert q.shape == (4, 6) and y.shape == (4, 9 + 7)


def test_compare_and_diagnose_give_the_commands_json(rr_dir, cbd_bin, tmp_path):
    rr = cbd.ModelFile.load(rr_dir / "rr.toml")
    train, test = read_csv(rr_dir / "train.csv"), read_csv(rr_dir / "test.csv")
    got = cbd.compare(rr, (train[:, :2], train[:, 2:]), rr_dir / "test.csv")
    run(cbd_bin, "compare", "--model", rr_dir / "rr.toml", "--train", rr_dir / "train.csv", "--test", rr_dir / "test.csv", "--json", tmp_path / "c.json")
    want = json.loads((tmp_path / "c.json").read_text())
    assert got.keys() == want.keys()
    assert [m["method"] if "method" in m else m for m in got["methods"]] == [m["method"] if "method" in m else m for m in want["methods"]]
    got = cbd.diagnose(rr, (train[:, :2], train[:, 2:]), (test[:, :2], test[:, 2:]), no_cbd=True)
    run(cbd_bin, "diagnose", "--no-cbd", "--model", rr_dir / "rr.toml", "--data", rr_dir / "train.csv", "--test", rr_dir / "test.csv", "--json", tmp_path / "d.json")
    want = json.loads((tmp_path / "d.json").read_text())
    assert got.keys() == want.keys()


def test_check_gives_the_commands_json(rr_dir, cbd_bin, tmp_path):
    """cbd.check on a fitted Model and arrays is `cbd check` on the blob file and the CSV: the same
    JSON, value for value; a blob that does not fit the model file is a CbdError naming both."""
    rr = cbd.ModelFile.load(rr_dir / "rr.toml")
    train, test = read_csv(rr_dir / "train.csv"), read_csv(rr_dir / "test.csv")
    model = cbd.fit(rr, train[:, :2], train[:, 2:])
    got = cbd.check(rr, model, (test[:, :2], test[:, 2:]), alpha=0.05)
    blob = tmp_path / "rr.blob"
    blob.write_bytes(model.to_bytes())
    assert cbd.check(rr, blob, rr_dir / "test.csv", alpha=0.05) == got
    done = subprocess.run(
        [str(a) for a in (cbd_bin, "check", "--model", rr_dir / "rr.toml", "--blob", blob, "--data", rr_dir / "test.csv", "--alpha", "0.05", "--json", tmp_path / "c.json")],
        capture_output=True,
        text=True,
    )
    assert done.returncode == (0 if got["verdict"] == "holds" else 3), done.stderr
    assert got == json.loads((tmp_path / "c.json").read_text())
    assert got["rows"] == len(test) and 0.0 <= got["p_value"] <= 1.0 and got["alpha"] == 0.05
    six = cbd.ModelFile.load(UR5 / "ur5.toml")
    with pytest.raises(cbd.CbdError, match="does not fit"):
        cbd.check(six, model, rr_dir / "test.csv")
    with pytest.raises(cbd.CbdError, match="--alpha"):
        cbd.check(rr, model, rr_dir / "test.csv", alpha=1.5)


def test_poses_and_written_model_files_are_the_commands(rr_dir, cbd_bin, tmp_path):
    poses = tmp_path / "poses.csv"
    poses.write_text("q1,q2\n0.1,0.2\n0.3,-0.4\n")
    q, y = cbd.simulate(poses=poses, noise=0.01, seed=4)
    run(cbd_bin, "simulate", "--poses", poses, "--noise", "0.01", "--seed", "4", "--out", tmp_path / "s.csv")
    data = read_csv(tmp_path / "s.csv")
    assert np.array_equal(q, data[:, :2]) and np.array_equal(y, data[:, 2:])
    rr = cbd.ModelFile.load(rr_dir / "rr.toml")
    written = {}
    for front in ["python", "cli"]:
        (tmp_path / front).mkdir()
        path = tmp_path / front / "corrected.toml"
        if front == "python":
            cbd.diagnose(rr, rr_dir / "train.csv", rr_dir / "test.csv", no_cbd=True, write_model=path)
        else:
            run(cbd_bin, "diagnose", "--no-cbd", "--model", rr_dir / "rr.toml", "--data", rr_dir / "train.csv", "--test", rr_dir / "test.csv", "--write-model", path)
        # The header names the path written; the rest is the corrected model.
        written[front] = path.read_text().replace(str(path), "PATH")
    assert written["python"] == written["cli"]


def test_messages_go_to_logging_never_to_stdout(rr_dir, capfd, caplog):
    data = read_csv(rr_dir / "train.csv")
    with caplog.at_level(logging.INFO, logger="cbd"):
        cbd.fit(None, data[:, :2], data[:, 2:])
    out, _ = capfd.readouterr()
    assert out == ""
    messages = [r.getMessage() for r in caplog.records if r.name == "cbd"]
    assert any(m.startswith("hyperparameters") for m in messages) and any(m.startswith("fitted 36 measurements") for m in messages), messages


def test_the_gil_is_released_during_a_fit(ur5_file, ur5_train):
    ticks, done = [0], threading.Event()

    def fit():
        cbd.fit(ur5_file, ur5_train[:, :6], ur5_train[:, 6:], max_rows=200, quiet=True)
        done.set()

    worker = threading.Thread(target=fit)
    start = time.perf_counter()
    worker.start()
    while not done.is_set():
        ticks[0] += 1
        time.sleep(0.001)
    worker.join()
    # Held, the main thread would not run until the fit returned: a few ticks at most.
    assert ticks[0] > 50, f"{ticks[0]} ticks in {time.perf_counter() - start:.2f} s"


def test_keywords_are_the_commands_typed_arguments():
    # No command line between them: an unknown keyword or a value of the wrong type is named as such.
    with pytest.raises(cbd.CbdError, match=r"simulate\(\): unknown keyword `cout` \(did you mean `count`\?\)"):
        cbd.simulate(robot="six", sampling="uniform", cout=5)
    with pytest.raises(cbd.CbdError, match=r"simulate\(\): keyword `count`"):
        cbd.simulate(robot="six", sampling="uniform", count="five")
    with pytest.raises(cbd.CbdError, match=r"`out` is not an option here"):
        cbd.simulate(out="s.csv")
    # None is the flag's default; a list flag takes one value or a list.
    q, y = cbd.simulate(robot="six", sampling="uniform", count=5, seed=None, effect=[])
    assert q.shape == (5, 6) and y.shape == (5, 3)
    assert np.array_equal(q, cbd.simulate(robot="six", sampling="uniform", count=5, seed=1)[0])
