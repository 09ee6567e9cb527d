"""Model.evaluate and evaluate_pose are the runtime's, bit for bit: against `cbd-fw-host eval`, the
host twin of the firmware check (its configurations are examples/firmware/src/shared.rs's)."""

import struct

import numpy as np
import pytest

import cbd
from conftest import run

COUNT = 128


def config(i, n):
    """shared.rs's query configuration i: a 32-bit LCG, angles in [−π, π) on a grid of 2⁻²³."""
    state = (0x2545F491 ^ ((i * 0x9E3779B9) & 0xFFFFFFFF)) & 0xFFFFFFFF
    out = []
    for _ in range(n):
        state = (state * 1664525 + 1013904223) & 0xFFFFFFFF
        unit = (state >> 8) * (1.0 / 16777216.0)
        out.append(np.pi * (2.0 * unit - 1.0))
    return out


def bits(values):
    return [format(struct.unpack("<Q", struct.pack("<d", float(v)))[0], "016x") for v in values]


@pytest.fixture(scope="module")
def blobs(tmp_path_factory, fw_host):
    d = tmp_path_factory.mktemp("fw")
    run(fw_host, "make-blobs", d)
    return d


@pytest.mark.parametrize("name", ["rr.blob", "six.blob", "six-effects.blob", "rr-ws.blob", "six-ws.blob", "chain10.blob", "six-points.blob"])
def test_evaluation_is_the_runtimes_bit_for_bit(blobs, fw_host, name):
    lines = run(fw_host, "eval", blobs / name).splitlines()
    model = cbd.Model.load(blobs / name)
    q = np.array([config(i, model.n_joints) for i in range(COUNT)])
    positions, jacobians = model.evaluate(q, jacobian=True)
    results = {l.split()[0]: l for l in lines if l[:1] == "q" and l[1:2].isdigit()}
    assert len(results) == COUNT
    for i in range(COUNT):
        want = results[f"q{i:03}"].split()[1:]
        cut = want.index("|")
        assert bits(positions[i]) == want[:cut], f"{name} q{i:03} position"
        assert bits(jacobians[i].ravel()) == want[cut + 1:], f"{name} q{i:03} jacobian"
    if model.tool_point_count >= 3:
        origins, rotations, pose_jacobians = model.evaluate_pose(q, jacobian=True)
        poses = {l.split()[0]: l for l in lines if l.startswith("qp")}
        points = np.stack([model.evaluate(q, point=j) for j in range(model.tool_point_count)], axis=1)
        for i in range(COUNT):
            fields = poses[f"qp{i:03}"].split()[1:]
            first, second = fields.index("|"), len(fields) - 1 - fields[::-1].index("|")
            assert bits(points[i].ravel()) == fields[:first]
            assert bits(np.concatenate([rotations[i].ravel(), origins[i]])) == fields[first + 1:second]
            assert bits(pose_jacobians[i].ravel()) == fields[second + 1:]


def test_any_memory_layout_gives_the_same_bits(ur5_fit):
    model, _ = ur5_fit
    q = np.random.default_rng(3).uniform(-3, 3, (40, 6))
    want = model.evaluate(q, jacobian=True)
    for layout in (np.asfortranarray(q), np.ascontiguousarray(q.T).T, np.hstack([q, q])[:, :6], q[::-1][::-1]):
        got = model.evaluate(layout, jacobian=True)
        assert all(np.array_equal(a, b) for a, b in zip(got, want))


def test_compensation_reaches_the_calibrated_targets(ur5_fit, ur5_file, ur5_train):
    model, _ = ur5_fit
    q = ur5_train[1:60:2, :6]  # measured poses between the 300 trained on, in degrees as the CSV's
    targets = model.evaluate(q)  # mm
    commands, flags = model.compensate(targets, seeds=q + 3.0)  # degrees
    assert flags == ["ok"] * 30, flags
    assert np.abs(model.evaluate(commands) - targets).max() < 1e-6  # mm: the runtime's reach tolerance
    commands, flags = model.compensate(targets)  # seeds: the nearest training configuration
    assert commands.shape == (30, 6) and len(flags) == 30
