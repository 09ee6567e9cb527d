"""cbd.fit is `cbd fit`: the same blob bytes and report on the same data and flags."""

import json

import numpy as np

import cbd
from conftest import UR5, read_csv, run


def test_ur5_fit_gives_the_cli_blob_bytes_and_report(ur5_fit):
    model, d = ur5_fit
    assert model.to_bytes() == (d / "cli.blob").read_bytes()
    cli = json.loads((d / "cli.json").read_text())
    assert model.report.keys() == cli.keys()
    assert model.report["dh_first"] is True
    assert model.report["hyperparameters"] == cli["hyperparameters"] and model.report["scheme"] == cli["scheme"]


def test_rr_fit_without_a_model_file_and_with_flags_gives_the_cli_bytes(rr_dir, cbd_bin, tmp_path):
    data = read_csv(rr_dir / "train.csv")
    model = cbd.fit(None, data[:, :2], data[:, 2:], sigma=1e-4, steps=1, representation="kernel", quiet=True)
    run(cbd_bin, "fit", "--quiet", "--sigma", "0.0001", "--steps", "1", "--representation", "kernel", "--data", rr_dir / "train.csv",
        "--out", tmp_path / "rr.blob")
    assert model.to_bytes() == (tmp_path / "rr.blob").read_bytes()
    assert model.report["scheme"]["steps"] == 1 and model.report["hyperparameters"]["sigma"] == 1e-4
    assert (model.n_joints, model.task_dim, model.tool_point_count) == (2, 2, 1)


def test_bytes_save_and_load_round_trip(ur5_fit, ur5_file, tmp_path):
    model, _ = ur5_fit
    model.save(tmp_path / "m.blob")
    for back in (cbd.Model.load(tmp_path / "m.blob"), cbd.Model.from_bytes(model.to_bytes())):
        assert back.to_bytes() == model.to_bytes() and back.report is None
    q = np.random.default_rng(1).uniform(-170, 170, (20, 6))  # degrees, the model file's columns
    # The fitted model answers in the model file's units; the blob alone in its own (radians), the
    # same values once converted as the CSV import converts them.
    q_model, _ = ur5_file.to_model(q)
    assert np.array_equal(cbd.Model.from_bytes(model.to_bytes()).evaluate(q_model), model.evaluate(q))
    assert np.array_equal(cbd.Model.from_bytes(model.to_bytes(), ur5_file).evaluate(q), model.evaluate(q))


def test_model_file_converts_arrays_as_the_csv_import(ur5_file, ur5_train):
    q, y = ur5_file.to_model(ur5_train[:5, :6], ur5_train[:5, 6:])
    assert np.array_equal(q, ur5_train[:5, :6] * (np.pi / 180.0)) and np.array_equal(y, ur5_train[:5, 6:])
    joints, none = ur5_file.to_model(ur5_train[:5, :6])
    assert np.array_equal(joints, q) and none.shape == (5, 0)
    assert ur5_file.joint_columns == [f"q{k}_deg" for k in range(1, 7)] and ur5_file.position_columns == ["x_mm", "y_mm", "z_mm"]
    assert ur5_file.length_unit == "mm" and ur5_file.n_joints == 6 and ur5_file.task_dim == 3
