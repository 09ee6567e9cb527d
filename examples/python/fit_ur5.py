"""Fit the UR5 example from Python, evaluate the calibrated model on its test poses, plot the errors."""

import pathlib

import numpy as np

import cbd

ur5 = pathlib.Path(__file__).resolve().parents[1] / "ur5"
model_file = cbd.ModelFile.load(ur5 / "ur5.toml")
train = np.loadtxt(ur5 / "train.csv", delimiter=",", skiprows=1)  # q1_deg … q6_deg, x_mm, y_mm, z_mm
test = np.loadtxt(ur5 / "test.csv", delimiter=",", skiprows=1)

model = cbd.fit(model_file, train[:, :6], train[:, 6:])  # `cbd fit`: the same blob (geometry calibrated, by the evidence)
model.save("ur5.blob")

# Arrays in and out are in the model file's column units, as the CSV holds them: degrees in, mm out.
errors = np.linalg.norm(model.evaluate(test[:, :6]) - test[:, 6:], axis=1)
print(f"calibrated: mean {errors.mean():.4f} mm, max {errors.max():.4f} mm on {len(errors)} test poses")

try:
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
if plt is not None:
    plt.hist(errors, bins=10)
    plt.xlabel("position error after calibration (mm)")
    plt.ylabel("test poses")
    plt.savefig("ur5-errors.png")
    print("ur5-errors.png written")
