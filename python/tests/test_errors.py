"""Bad inputs raise cbd.CbdError (a ValueError) with the command's message; none crashes the
interpreter (a crash would end this process, and with it the run)."""

import numpy as np
import pytest

import cbd
from conftest import UR5


def ur5_rows(ur5_train, rows=40):
    return ur5_train[:rows, :6].copy(), ur5_train[:rows, 6:].copy()


def with_nan(a, value=np.nan):
    a = a.copy()
    a[3, 2] = value
    return a


FIT_CASES = [
    # (case, q, y, options, words in the message)
    ("q too narrow", lambda q, y: (q[:, :5], y), {}, ["q must be a float64 numpy array of shape (n, 6)", "got shape (40, 5)"]),
    ("y too wide", lambda q, y: (q, np.hstack([y, y])), {}, ["y must be", "got shape (40, 6)"]),
    ("q one-dimensional", lambda q, y: (q[0], y), {}, ["got 1 dimensions"]),
    ("q three-dimensional", lambda q, y: (q[None], y), {}, ["got 3 dimensions"]),
    ("q float32", lambda q, y: (q.astype(np.float32), y), {}, ["got dtype float32", "astype(np.float64)"]),
    ("q integers", lambda q, y: (q.astype(np.int64), y), {}, ["got dtype int64"]),
    ("y complex", lambda q, y: (q, y.astype(np.complex128)), {}, ["got dtype complex128"]),
    ("q objects", lambda q, y: (q.astype(object), y), {}, ["got dtype object"]),
    ("q a list", lambda q, y: (q.tolist(), y), {}, ["got a list", "np.asarray"]),
    ("q None", lambda q, y: (None, y), {}, ["got a NoneType"]),
    ("rows differ", lambda q, y: (q, y[:-1]), {}, ["q has 40 rows and y 39"]),
    ("NaN joint", lambda q, y: (with_nan(q), y), {}, ["(q, y) row 3: column 'q3_deg': not a finite number: 'NaN'"]),
    ("infinite position", lambda q, y: (q, with_nan(y, np.inf)), {}, ["(q, y) row 3: column 'z_mm': not a finite number: 'inf'"]),
    ("joint beyond its range", lambda q, y: (q * 100, y), {}, ["(q, y) row 0: column 'q1_deg'", "outside the joint's range"]),
    ("too few rows", lambda q, y: (q[:5], y[:5]), {}, ["(q, y): 5 data rows; at least 10 needed"]),
    ("no rows", lambda q, y: (q[:0], y[:0]), {}, ["0 data rows"]),
    ("unknown option", lambda q, y: (q, y), {"sigmaa": 1.0}, ["fit(): unknown keyword `sigmaa` (did you mean `sigma`?)"]),
    ("option given as an argument", lambda q, y: (q, y), {"out": "x.blob"}, ["fit(): `out` is not an option here"]),
    ("negative sigma", lambda q, y: (q, y), {"sigma": -1.0}, ["--sigma must be a number in [1e-100, 1e100], got -1"]),
    ("bad integrator", lambda q, y: (q, y), {"integrator": "leapfrog"}, ["unknown integrator `leapfrog`"]),
    ("bad number", lambda q, y: (q, y), {"max_rows": "many"}, ["fit(): keyword `max_rows`:"]),
    ("max_rows too small", lambda q, y: (q, y), {"max_rows": 1}, ["--max-rows must be at least 2"]),
]


@pytest.mark.parametrize("case,make,options,words", FIT_CASES, ids=[c[0] for c in FIT_CASES])
def test_bad_fit_inputs_raise_cbd_errors(ur5_file, ur5_train, case, make, options, words):
    q, y = make(*ur5_rows(ur5_train))
    with pytest.raises(cbd.CbdError) as e:
        cbd.fit(ur5_file, q, y, **options)
    assert isinstance(e.value, ValueError)
    for w in words:
        assert w in str(e.value), f"{case}: {e.value}"


def test_bad_files_and_blobs_raise_cbd_errors(tmp_path, ur5_fit):
    model, _ = ur5_fit
    (tmp_path / "bad.toml").write_text('length_unit = "mm"\nangle_unit = "deg"\n[chain]\nconvention = "standard"\nlinks = 3\n')
    cases = [
        (lambda: cbd.ModelFile.load(tmp_path / "missing.toml"), ["missing.toml"]),
        (lambda: cbd.ModelFile.load(tmp_path / "bad.toml"), ["bad.toml", "links"]),
        (lambda: cbd.Model.from_bytes(b""), ["truncated"]),
        (lambda: cbd.Model.from_bytes(model.to_bytes()[:-1]), []),
        (lambda: cbd.Model.from_bytes(bytes([b ^ (i == 40) for i, b in enumerate(model.to_bytes())])), ["checksum"]),
        (lambda: cbd.Model.from_bytes(b"PK\x03\x04" + bytes(60)), ["magic"]),
        (lambda: cbd.Model.load(tmp_path / "none.blob"), ["none.blob"]),
        (lambda: model.save(tmp_path / "no" / "dir" / "m.blob"), ["m.blob"]),
    ]
    for call, words in cases:
        with pytest.raises(cbd.CbdError) as e:
            call()
        for w in words:
            assert w in str(e.value).lower() or w in str(e.value), str(e.value)


def test_bad_queries_raise_cbd_errors(ur5_fit):
    model, _ = ur5_fit
    q = np.zeros((4, 6))
    cases = [
        (lambda: model.evaluate(q[:, :5]), "q must be a float64 numpy array of shape (n, 6)"),
        (lambda: model.evaluate(with_nan(np.zeros((5, 6)))), "q row 3:"),
        (lambda: model.evaluate(q, point=1), "point 1: the model has 1 tool point(s)"),
        (lambda: model.evaluate_pose(q), "q row 0:"),
        (lambda: model.compensate(np.zeros((4, 2))), "targets must be a float64 numpy array of shape (n, 3)"),
        (lambda: model.compensate(np.zeros((4, 3)), seeds=np.zeros((3, 6))), "targets has 4 rows and seeds 3"),
        (lambda: model.compensate(np.full((1, 3), np.nan)), "targets row 0:"),
        (lambda: model.compensate(np.zeros((1, 3)), iterations=0), "iterations must be between 1 and 64"),
        # Issue 51 class 7: the CLI's bound, and a negative or huge int named, not an OverflowError.
        (lambda: model.compensate(np.zeros((1, 3)), iterations=10**8), "iterations must be between 1 and 64 (as `cbd compensate --iterations`), got 100000000"),
        (lambda: model.compensate(np.zeros((1, 3)), iterations=-3), "iterations must be between 1 and 64 (as `cbd compensate --iterations`), got -3"),
        (lambda: model.evaluate(q, point=-1), "point -1: the model has 1 tool point(s)"),
    ]
    for call, words in cases:
        with pytest.raises(cbd.CbdError) as e:
            call()
        assert words in str(e.value), str(e.value)


def test_arrays_too_large_for_memory_raise_cbd_errors(ur5_fit, ur5_file):
    # Issue 48 item 2 (issue 51 item 7): a broadcast view of 10^9 rows aborted the interpreter
    # ("memory allocation of 48000000000 bytes failed"); each call checks before it copies.
    model, _ = ur5_fit
    huge_q = np.broadcast_to(np.zeros(6), (10**9, 6))
    huge_t = np.broadcast_to(np.zeros(3), (10**9, 3))
    for call, name in [
        (lambda: model.evaluate(huge_q), "q"),
        (lambda: model.evaluate(huge_q, jacobian=True), "q"),
        (lambda: model.evaluate_pose(huge_q), "q"),
        (lambda: model.compensate(huge_t), "targets"),
        (lambda: cbd.fit(ur5_file, huge_q, huge_t), "q"),
    ]:
        with pytest.raises(cbd.CbdError) as e:
            call()
        # Checked before the allocation: a MemoryError (and a CbdError, a ValueError), never an abort.
        assert isinstance(e.value, MemoryError) and isinstance(e.value, cbd.CbdMemoryError), type(e.value)
        message = str(e.value)
        assert message.startswith(f"{name}: an array of shape (1000000000, ") and "this process may use" in message, message
        assert "pass fewer rows at a time" in message, message


def test_bad_commands_raise_cbd_errors(ur5_file, rr_dir):
    rr = cbd.ModelFile.load(rr_dir / "rr.toml")
    cases = [
        (lambda: cbd.simulate(robot="seven"), "seven"),
        (lambda: cbd.simulate(out="x.csv"), "simulate(): `out` is not an option here"),
        (lambda: cbd.compare(rr, rr_dir / "nowhere.csv", rr_dir / "test.csv"), "nowhere.csv"),
        (lambda: cbd.compare(rr, (np.zeros((3, 2)),), rr_dir / "test.csv"), "give a CSV path or a (q, y) tuple"),
        (lambda: cbd.compare(rr, (np.zeros((30, 2)), np.full((30, 2), np.nan)), rr_dir / "test.csv"), "train (q, y) row 0: column 'x': not a finite number"),
        (lambda: cbd.diagnose(rr, rr_dir / "train.csv", harmonics=99), "--harmonics"),
    ]
    for call, words in cases:
        with pytest.raises(cbd.CbdError) as e:
            call()
        assert words in str(e.value), str(e.value)
