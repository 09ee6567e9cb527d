"""One unit convention for every array in and out (issue 51 class 7): a model that came with a
model file takes and returns arrays in that file's column units, as `cbd fit`'s CSV holds them; a
blob alone is in its own units (radians, the model's length unit)."""

import json

import numpy as np
import pytest

import cbd
from conftest import run

# A planar arm in a frame of its own: degrees, positions in mm, a base, yaw and joint offsets.
FRAMED = """length_unit = "m"
angle_unit = "deg"
[planar]
lengths = [1.0, 0.5]
base = [0.3, -0.2]
yaw = 30.0
offsets = [10.0, -5.0]
[measurements]
joints = ["a_deg", "b_deg"]
positions = ["x_mm", "y_mm"]
length_unit = "mm"
"""


def framed_rows(q, y):
    """Chain rows (radians, metres, as `cbd simulate` writes the RR arm) as the framed file's columns."""
    yaw = np.deg2rad(30.0)
    turn = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    columns = np.rad2deg(q) - np.array([10.0, -5.0])
    positions = (y @ turn.T + np.array([0.3, -0.2])) * 1000.0
    return columns, positions


@pytest.fixture(scope="module")
def framed(tmp_path_factory):
    d = tmp_path_factory.mktemp("framed")
    (d / "framed.toml").write_text(FRAMED)
    model_file = cbd.ModelFile.load(d / "framed.toml")
    q, y = cbd.simulate(sampling="grid", grid=6, noise=1e-4)
    q, y = framed_rows(q, y)
    # σ as simulated (0.1 mm): the fit leaves the noise, a training error of a tenth of a millimetre.
    model = cbd.fit(model_file, q, y, quiet=True, sigma=1e-4)
    return model_file, model, q, y, d


def rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def test_fit_then_evaluate_on_the_training_arrays_gives_the_training_error(framed, cbd_bin):
    model_file, model, q, y, d = framed
    trained = model.report["fit"]["log"][-1]["train_rms"] * 1000.0  # the report is in the model's unit, m
    got = rms(model.evaluate(q), y)
    # The runtime's blob against the trainer's own figure (its flow, summed its way): within 0.1 %.
    assert got == pytest.approx(trained, rel=1e-3), (got, trained)
    # And `cbd eval` on the same rows as a CSV through the same model file: the same errors.
    rows = "\n".join(",".join(repr(float(v)) for v in row) for row in np.hstack([q, y]))
    (d / "train.csv").write_text("a_deg,b_deg,x_mm,y_mm\n" + rows + "\n")
    model.save(d / "eval.blob")
    run(cbd_bin, "eval", "--model", d / "framed.toml", "--blob", d / "eval.blob", "--data", d / "train.csv", "--json", d / "eval.json")
    cli = json.loads((d / "eval.json").read_text())["calibrated"]["mean"] * 1000.0  # eval reports in the model's unit, m
    mean = float(np.mean(np.linalg.norm(model.evaluate(q) - y, axis=1)))
    assert mean == pytest.approx(cli, rel=1e-9), (mean, cli)
    # The nominal is centimetres off: a unit or frame dropped anywhere would show.
    alone = cbd.Model.from_bytes(model.to_bytes())  # the blob's units: radians, metres, the chain's frame
    q_model, y_model = model_file.to_model(q, y)
    assert rms(alone.evaluate(q_model) * 1000.0, y_model * 1000.0) == pytest.approx(got, rel=1e-9)
    assert 0.01 < got < 0.5 and "a_deg" in model.units and "mm" in model.units


def test_a_blob_loaded_with_its_model_file_answers_in_the_columns_units(framed):
    model_file, model, q, y, d = framed
    model.save(d / "framed.blob")
    for back in (cbd.Model.load(d / "framed.blob", model_file), cbd.Model.from_bytes(model.to_bytes(), model_file)):
        assert np.array_equal(back.evaluate(q), model.evaluate(q))
    alone = cbd.Model.load(d / "framed.blob")
    assert "radians" in alone.units
    q_model, _ = model_file.to_model(q)
    # Blob units: the chain's frame, metres; the model file's: the arm's frame, mm.
    back = alone.evaluate(q_model)
    yaw = np.deg2rad(30.0)
    turn = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    assert np.allclose((back @ turn.T + np.array([0.3, -0.2])) * 1000.0, model.evaluate(q), rtol=0, atol=1e-9)


def test_jacobians_are_in_the_columns_units(framed):
    _, model, q, _, _ = framed
    rows = q[:5]
    _, jacobians = model.evaluate(rows, jacobian=True)
    h = 1e-4  # degrees
    for k in range(2):
        step = np.zeros(2)
        step[k] = h
        numeric = (model.evaluate(rows + step) - model.evaluate(rows - step)) / (2 * h)
        assert np.allclose(jacobians[:, :, k], numeric, rtol=1e-5, atol=1e-6), (jacobians[:, :, k], numeric)


def test_compensate_takes_targets_and_gives_commands_in_the_columns_units(framed):
    _, model, q, _, _ = framed
    targets = model.evaluate(q[:8])
    commands, flags = model.compensate(targets, seeds=q[:8] + 2.0)
    assert flags == ["ok"] * 8, flags
    assert np.abs(model.evaluate(commands) - targets).max() < 1e-4  # mm
    # Commands in degrees: near the seeds (2° off), not 57 × further as radians would be.
    assert np.abs(commands - q[:8]).max() < 10.0


def test_a_blob_loaded_with_another_arms_file_is_refused(framed, ur5_file):
    _, model, _, _, _ = framed
    with pytest.raises(cbd.CbdError) as e:
        cbd.Model.from_bytes(model.to_bytes(), ur5_file)
    assert "does not fit" in str(e.value) and "ur5.toml" in str(e.value), str(e.value)
