"""Property test (issue 51 class 7): whatever array a caller passes — any shape, dtype, memory
layout, NaN or infinity, or a size beyond memory — every call that takes arrays answers with
arrays of the right shape or raises cbd.CbdError (a ValueError) naming the argument; never another
exception, never an abort of the interpreter."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cbd


@pytest.fixture(scope="module")
def rr():
    q, y = cbd.simulate(sampling="grid", grid=5, noise=1e-4)
    return cbd.fit(None, q, y, quiet=True), q, y


DTYPES = [np.float64, np.float32, np.int64, np.int32, np.bool_, np.complex128, np.uint8, object]
SPECIALS = [0.0, 1.0, -2.5, np.nan, np.inf, -np.inf, 1e300, -1e-310, 5e-324]


@st.composite
def arrays(draw, width):
    """An array of `width` columns most of the time, of any shape, dtype, layout and values."""
    size = draw(st.sampled_from(["small", "small", "small", "huge"]))
    cols = draw(st.sampled_from([width, width, width, 0, 1, width + 1]))
    if size == "huge":
        # A broadcast view of 10^9 rows: checked against memory before any copy.
        return np.broadcast_to(np.zeros(max(cols, 1)), (10**9, max(cols, 1)))
    ndim = draw(st.sampled_from([2, 2, 2, 0, 1, 3]))
    rows = draw(st.integers(0, 6))
    shape = {0: (), 1: (rows * max(cols, 1),), 2: (rows, cols), 3: (rows, cols, 1)}[ndim]
    count = int(np.prod(shape)) if shape else 1
    values = draw(st.lists(st.one_of(st.sampled_from(SPECIALS), st.floats(-4.0, 4.0)), min_size=count, max_size=count))
    a = np.array(values, dtype=np.float64).reshape(shape)
    dtype = draw(st.sampled_from(DTYPES))
    if dtype is not np.float64:
        with np.errstate(all="ignore"):
            a = a.astype(dtype) if dtype is not object else a.astype(object)
    layout = draw(st.sampled_from(["c", "fortran", "strided", "reversed", "readonly"]))
    if a.ndim == 2 and a.size:
        if layout == "fortran":
            a = np.asfortranarray(a)
        elif layout == "strided":
            a = np.repeat(a, 2, axis=1)[:, ::2]
        elif layout == "reversed":
            a = a[::-1]
        elif layout == "readonly":
            a = a.copy()
            a.flags.writeable = False
    return a


def answers_or_refuses(call, rows=None, width=None):
    try:
        out = call()
    except cbd.CbdError as e:
        assert str(e), "an empty message"
        return
    first = out[0] if isinstance(out, tuple) else out
    if rows is not None:
        assert first.shape == (rows, width), first.shape


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(q=arrays(2), jacobian=st.booleans())
def test_evaluate_answers_or_refuses(rr, q, jacobian):
    model, _, _ = rr
    rows = q.shape[0] if q.ndim == 2 and q.dtype == np.float64 and q.shape[1] == 2 else None
    answers_or_refuses(lambda: model.evaluate(q, jacobian=jacobian), rows, 2)
    answers_or_refuses(lambda: model.evaluate_pose(q))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(t=arrays(2), seeds=st.one_of(st.none(), arrays(2)), iterations=st.integers(-3, 100))
def test_compensate_answers_or_refuses(rr, t, seeds, iterations):
    model, _, _ = rr
    answers_or_refuses(lambda: model.compensate(t, seeds=seeds, iterations=iterations))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(q=arrays(2), y=arrays(2))
def test_fit_answers_or_refuses(rr, q, y):
    answers_or_refuses(lambda: cbd.fit(None, q, y, quiet=True, sigma=1e-3, gamma=1e-3, joint_b=0.5, task_width=1.0, task_gamma=1.0))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(q=arrays(6), y=st.one_of(st.none(), arrays(3)))
def test_to_model_answers_or_refuses(ur5_file, q, y):
    answers_or_refuses(lambda: ur5_file.to_model(q, y))
